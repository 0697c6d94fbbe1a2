"""A small finished job shared by the reader tests (shards run in-process, no Ray)."""

import pytest

from tests.workers.conftest import cache_dir, mesh_source, tiny_config  # noqa: F401 - fixtures
from tests.workers.test_shard import run_all

OBSERVATIONS = {"points": 256, "views": 2, "view_points": 100, "image_width": 48, "image_height": 36}


@pytest.fixture(scope="session")
def job_dir(tmp_path_factory, mesh_source, cache_dir):  # noqa: F811
    # test_fraction 0.5 puts b_ball in the test split and a_box in train (sha256 of the ids)
    # observations: 256 surface points, 2 small depth views (MuJoCo's where a GL backend works, else ray cast)
    cfg = tiny_config(mesh_source, grasps_per_object=3, scales=(0.06, 0.08), test_fraction=0.5,
                      observations=OBSERVATIONS)
    return run_all(tmp_path_factory.mktemp("iojob") / "job", cfg, cache_dir).path
