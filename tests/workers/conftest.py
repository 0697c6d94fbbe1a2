"""Tiny jobs for the pipeline tests: two small meshes and one unreadable file in a `dir:` source,
a cheap CoACD, 2 grasps per object, 20 synthesis iterations, a short hold test."""

from __future__ import annotations

import math
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import trimesh

from workers.job import JobConfig

TINY_EVAL = {"waypoints": 2, "steps_per_waypoint": 5, "hold_steps": 50, "check_every": 25, "epsilon_samples": 64}


@pytest.fixture(scope="session")
def mesh_source(tmp_path_factory) -> str:
    root = tmp_path_factory.mktemp("meshes")
    trimesh.creation.box((1.0, 0.7, 0.5)).export(root / "a_box.obj")
    trimesh.creation.icosphere(subdivisions=2).export(root / "b_ball.obj")
    (root / "c_bad.obj").write_text("this is not a mesh\n")
    return f"dir:{root}"


@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory) -> str:
    return str(tmp_path_factory.mktemp("cache"))


def tiny_config(source: str, **kw) -> JobConfig:
    base = dict(source=source, count=3, scales=(0.08,), grasps_per_object=2, objects_per_shard=1,
                grid_resolution=16, synth={"iters": 20, "num_directions": 16, "seeds_per_grasp": 1},
                eval=dict(TINY_EVAL),
                object_timeout_s=120.0)
    base.update(kw)
    return JobConfig(**base)


@pytest.fixture
def tiny(mesh_source) -> JobConfig:
    return tiny_config(mesh_source)


def comparable_rows(job_dir: str | Path) -> list[dict]:
    """Every row of a job's shards, sorted by grasp id, NaN replaced so rows compare with ==."""
    rows = []
    for p in sorted((Path(job_dir) / "shards").glob("part-*.parquet")):
        rows += pq.read_table(p).to_pylist()

    def clean(v):
        if isinstance(v, float) and math.isnan(v):
            return "nan"
        if isinstance(v, list):
            return [clean(x) for x in v]
        return v

    return sorted(({k: clean(v) for k, v in r.items()} for r in rows), key=lambda r: r["grasp_id"])
