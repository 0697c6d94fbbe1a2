"""The tabletop scene through the one resolved configuration: `scene` resolves like every recipe
part (a name or a mapping, a flag on top), a task with its own test is refused, floating rows
say so; a tiny tabletop job through `datagen run` writes rows of the evaluated schema that name
their stable pose and from which the scene can be rebuilt (the object on z = 0 in the table frame,
the plane giving every point its height), each tested by the lift."""

import numpy as np
import pyarrow.parquet as pq
import pytest
import trimesh
import yaml

from datagen.errors import ConfigError
from datagen.objects.tabletop import SceneConfig, stable_poses
from datagen.pipeline import resolve
from schemas import arrow_schema, check_version

LIFT_REASONS = {"ok", "penetration", "no_contact", "hand_in_table", "object_left_on_table", "object_dropped",
                "object_slipped", "unstable"}


def test_scene_resolves_like_a_recipe_part():
    assert resolve("shadow").scene == SceneConfig()
    by_name = resolve("shadow", config={"scene": "tabletop"})
    assert by_name.scene == SceneConfig(kind="tabletop", stable_poses=1)
    both = resolve("shadow", config={"scene": {"kind": "tabletop", "stable_poses": 3}}, flags={"scene": {"stable_poses": 2}})
    assert both.scene == SceneConfig(kind="tabletop", stable_poses=2)
    assert by_name.hash() != resolve("shadow").hash()
    with pytest.raises(ConfigError, match="scene.kind"):
        resolve("shadow", config={"scene": "table"})
    with pytest.raises(ConfigError, match="scene must be a scene's name"):
        resolve("shadow", config={"scene": 3})
    with pytest.raises(ConfigError, match="has its own test"):
        resolve("shadow", "turn_handle", config={"scene": "tabletop"})


def test_floating_rows_say_they_float(tmp_path):
    import datagen

    trimesh.creation.box((1.0, 0.7, 0.5)).export(tmp_path / "box.obj")
    rows = datagen.synthesize("shadow", tmp_path / "box.obj", n=2, evaluate=False, cache=str(tmp_path / "cache"),
                              config={"synth": {"iters": 5, "seeds_per_grasp": 1}, "grid_resolution": 16}).to_pylist()
    assert [r["scene"] for r in rows] == ["floating"] * 2 and [r["stable_pose"] for r in rows] == [-1, -1]
    assert rows[0]["object_pose_table"] == [0, 0, 0, 1, 0, 0, 0] and rows[0]["support_plane"] == [0, 0, 0, 0]


@pytest.mark.slow
@pytest.mark.mujoco
@pytest.mark.ray
def test_a_tiny_tabletop_job_end_to_end(tmp_path):
    from datagen.cli import main
    from datagen.io import read_job
    from datagen.objects import load_processed

    root, cache = tmp_path / "meshes", str(tmp_path / "cache")
    root.mkdir()
    trimesh.creation.box((1.0, 0.7, 0.4)).export(root / "box.obj")
    cfg = {"scales": [0.08], "grid_resolution": 16, "synth": {"iters": 30, "seeds_per_grasp": 2, "num_directions": 16},
           "eval": {"epsilon_samples": 64}}
    (tmp_path / "job.yaml").write_text(yaml.safe_dump(cfg))
    assert main(["run", "--out", str(tmp_path / "job"), "--source", f"dir:{root}", "--objects", "1", "--grasps", "2",
                 "--config", str(tmp_path / "job.yaml"), "--cache", cache, "--num-cpus", "1", "--no-progress",
                 "--scene", "tabletop", "--stable-poses", "2"]) == 0
    shard = next((tmp_path / "job" / "shards").glob("*.parquet"))
    check_version(pq.read_schema(shard), "evaluated")
    table = read_job(tmp_path / "job")
    assert table.schema.remove_metadata().equals(arrow_schema("evaluated", nq=table.schema.field("grasp_qpos").type.list_size)
                                                 .remove_metadata())
    rows = table.to_pylist()
    assert len(rows) == 4 and {r["stable_pose"] for r in rows} == {0, 1} and len({r["grasp_id"] for r in rows}) == 4
    assert all(r["scene"] == "tabletop" and r["eval_test"] == "tabletop_lift" and r["reason"] in LIFT_REASONS
               and len(r["dir_success"]) == 1 and r["table_penetration_m"] >= 0 for r in rows)
    # a reader rebuilds the scene: the rows' plane and pose are the processed surface's stable poses
    processed = load_processed(tmp_path / "job" / rows[0]["object_path"])
    mesh = trimesh.load(processed.surface_path, force="mesh", process=False)
    poses = stable_poses(mesh.vertices, mesh.faces, mesh.center_mass, 2)
    for r in rows:
        s, p = r["object_scale_m"], poses[r["stable_pose"]]
        assert np.allclose(r["support_plane"], p.plane(s), atol=1e-6)
        pos, quat = np.array(r["object_pose_table"][:3]), np.array(r["object_pose_table"][3:])
        R = trimesh.transformations.quaternion_matrix(quat)[:3, :3]
        table_z = (mesh.vertices * s) @ R.T @ np.array([0, 0, 1.0]) + pos[2]
        assert table_z.min() == pytest.approx(0.0, abs=1e-6)  # resting on the table
        n, d = np.array(r["support_plane"][:3]), r["support_plane"][3]
        assert np.allclose((mesh.vertices * s) @ n + d, table_z, atol=1e-6)  # the plane gives heights
