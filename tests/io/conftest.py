"""A small finished job shared by the reader tests (shards run in-process, no Ray)."""

import pytest

from tests.workers.conftest import cache_dir, mesh_source, tiny_config  # noqa: F401 - fixtures
from tests.workers.test_shard import run_all


@pytest.fixture(scope="session")
def job_dir(tmp_path_factory, mesh_source, cache_dir):  # noqa: F811
    # test_fraction 0.5 puts b_ball in the test split and a_box in train (sha256 of the ids)
    cfg = tiny_config(mesh_source, grasps_per_object=3, scales=(0.06, 0.08), test_fraction=0.5)
    return run_all(tmp_path_factory.mktemp("iojob") / "job", cfg, cache_dir).path
