"""A small finished job (shards run in-process, no Ray) shared by the viewer tests: two objects
(a box and a ball), two scales, two grasps each, evaluated in MuJoCo."""

import pytest

from tests.workers.conftest import cache_dir, mesh_source, tiny_config  # noqa: F401 - fixtures
from tests.workers.test_shard import run_all


@pytest.fixture(scope="session")
def job_dir(tmp_path_factory, mesh_source, cache_dir):  # noqa: F811
    cfg = tiny_config(mesh_source, grasps_per_object=2, scales=(0.06, 0.08))
    return run_all(tmp_path_factory.mktemp("viewjob") / "job", cfg, cache_dir).path


@pytest.fixture(scope="session")
def source(job_dir):
    from datagen.view import open_source

    return open_source(job_dir)
