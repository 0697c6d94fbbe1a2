"""datagen.pipeline: processed objects -> evaluated rows, without Ray or a job directory.

Checked: one row per object x scale x grasp with what the caller says of each object; a broken
object becomes a failure record naming it while the others keep their rows; a task bound to
another object yields nothing; rescaled targets match targets built at their own scale; evaluation in a pool gives one
process's rows. (The entry points' agreement: tests/pipeline/test_recipe.py.)
"""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch
import trimesh

from datagen.eval import EvalConfig
from datagen.objects.config import ProcessConfig
from datagen.objects.process import process_object
from datagen.objects.sources import resolve
from datagen.pipeline import BatchObject, build_targets, resolve as resolve_recipe, run_batch
from datagen.synth import GraspTarget, SynthConfig
from schemas import arrow_schema

pytestmark = pytest.mark.mujoco

FAST = ProcessConfig(coacd_threshold=0.1, coacd_preprocess_resolution=30, coacd_mcts_iterations=60,
                     coacd_mcts_nodes=10, coacd_resolution=1000)
TINY_EVAL = {"waypoints": 2, "steps_per_waypoint": 5, "hold_steps": 50, "check_every": 25, "epsilon_samples": 64}


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """Two processed meshes (a box, a ball) in a fresh cache, and the Shadow hand."""
    from datagen.hands import load_hand

    root, cache = tmp_path_factory.mktemp("meshes"), tmp_path_factory.mktemp("cache")
    trimesh.creation.box((1.0, 0.7, 0.5)).export(root / "box.obj")
    trimesh.creation.icosphere(subdivisions=2).export(root / "ball.obj")
    done = {}
    for name in ("box.obj", "ball.obj"):
        p = process_object(resolve(f"dir:{root}", name, name), FAST, root=cache)
        assert p.ok, p.message
        done[name] = p
    torch.set_num_threads(1)
    return done, str(cache), load_hand("shadow")


def _clean(rows):
    def c(v):
        if isinstance(v, float) and math.isnan(v):
            return "nan"
        return [c(x) for x in v] if isinstance(v, list) else v

    return [{k: c(v) for k, v in r.items()} for r in rows]


def test_rows_failures_and_task_pairing(world, tmp_path):
    objs, cache, hand = world
    entry = objs["box.obj"].entry  # rows name it relative to `base`, as a job's rows do
    box = BatchObject(objs["box.obj"], (0.07, 0.09), object_id="box-1", object_path=entry.name, split="test")
    broken = BatchObject(dataclasses.replace(objs["ball.obj"], entry=tmp_path / "gone"), (0.08,), object_id="ball-1")
    seen = []
    layer = {"synth": {"iters": 10, "num_directions": 16, "seeds_per_grasp": 1}, "eval": TINY_EVAL,
             "grid_resolution": 16}
    recipes = [resolve_recipe("shadow", t, config=layer) for t in ("force_closure", "turn_knob2")]
    out = run_batch([box, broken], hand, recipes, grasps_per_object=2, seed=5, cache=cache,
                    base=entry.parent, progress=lambda d, t: seen.append((d, t)))
    assert out.rows.schema.equals(arrow_schema("evaluated", nq=7 + hand.num_joints).remove_metadata())
    rows = out.rows.to_pylist()
    # the box: 2 scales x 2 grasps, force closure only (turn_knob2 runs on its own object, absent here)
    assert sorted((r["object_id"], round(r["object_scale_m"], 3), r["grasp_index"]) for r in rows) == [
        ("box-1", 0.07, 0), ("box-1", 0.07, 1), ("box-1", 0.09, 0), ("box-1", 0.09, 1)]
    assert {(r["task"], r["split"], r["object_path"], r["seed"]) for r in rows} == {
        ("force_closure", "test", entry.name, 5)}
    assert all(r["success"] in (True, False) and r["reason"] for r in rows)  # every row was evaluated
    assert len({r["grasp_id"] for r in rows}) == 4
    (f,) = out.failures  # the broken object, and only it
    assert (f["object_id"], f["stage"], f["reason"]) == ("ball-1", "target", "error")
    assert f["message"].startswith("ball-1: ") and "gone" in f["message"]
    assert seen[-1][0] == seen[-1][1] and all(a[0] <= b[0] for a, b in zip(seen, seen[1:]))  # monotone, to the end


def test_rescaled_targets_match_targets_built_at_their_scale(world):
    objs, cache, _ = world
    t7, t9 = build_targets([BatchObject(objs["box.obj"], (0.07, 0.09))], grid_resolution=16, cache=cache)
    ref = GraspTarget.from_processed(objs["box.obj"], 0.09, grid_resolution=16, cache=cache)
    assert (t7.scale, t9.scale) == (0.07, 0.09)
    torch.testing.assert_close(t9.hull_points, ref.hull_points, rtol=1e-6, atol=1e-9)
    torch.testing.assert_close(t9.hull_normals, ref.hull_normals)
    assert t9.sdf is t7.sdf  # the normalized-unit SDF is built once per object
    with pytest.raises(ValueError, match="boom.obj"):
        build_targets([BatchObject(dataclasses.replace(objs["box.obj"], object_id="boom.obj", entry=None), (0.08,))])


def test_evaluation_in_a_pool_gives_the_same_rows_and_finds_a_failing_target(world, tmp_path):
    """``eval_workers`` > 1 (a shard with several CPUs): the rows of all targets go to one pool,
    with the same verdicts as one process; when the pool's call raises, each target is evaluated
    on its own and only the bad one becomes a failure. The caller's torch threads are kept."""
    from datagen.pipeline import evaluate_rows, synthesize_rows
    from datagen.tasks import load_task

    objs, cache, hand = world
    box, ball = BatchObject(objs["box.obj"], (0.07, 0.09), object_id="box"), BatchObject(objs["ball.obj"], (0.08,),
                                                                                        object_id="ball")
    targets = build_targets([box, ball], grid_resolution=16, cache=cache)
    _, table = synthesize_rows(hand, targets, load_task("force_closure"), SynthConfig(iters=10, num_directions=16), 2)
    table = table.set_column(table.schema.get_field_index("object_path"), "object_path",
                             [[str(objs[r["object_id"] + ".obj"].entry) for r in table.select(["object_id"]).to_pylist()]])
    cfg = EvalConfig.from_dict(TINY_EVAL)
    torch.set_num_threads(2)
    try:
        one = evaluate_rows(table, targets, "force_closure", cfg, workers=1)
        assert torch.get_num_threads() == 2
        pool = evaluate_rows(table, targets, "force_closure", cfg, workers=2)
        assert [t.num_rows for t in pool] == [2, 2, 2]
        assert [_clean(t.to_pylist()) for t in pool] == [_clean(t.to_pylist()) for t in one]
        # the ball's object file is gone: its rows fail in the pool, then alone, and only they
        broken = table.set_column(table.schema.get_field_index("object_path"), "object_path",
                                  [[p if "ball" not in o else str(tmp_path / "gone")
                                    for o, p in zip(table["object_id"].to_pylist(), table["object_path"].to_pylist())]])
        fails = []
        got = evaluate_rows(broken, targets, "force_closure", cfg, workers=2, failures=fails)
        assert [_clean(t.to_pylist()) for t in got] == [_clean(t.to_pylist()) for t in one[:2]]
        assert [(f["object_id"], f["stage"]) for f in fails] == [("ball", "eval")]
        # a process that has used CUDA spawns its workers (a fork cannot carry autograd's device
        # threads): the spawned pool gives the same rows (CUDA's state is faked: no GPU needed)
        import datagen.eval.table as et

        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(torch.cuda, "is_initialized", lambda: True)
            assert et.pool_context().get_start_method() == "spawn"
            spawned = evaluate_rows(table, targets, "force_closure", cfg, workers=2)
        assert [_clean(t.to_pylist()) for t in spawned] == [_clean(t.to_pylist()) for t in one]
    finally:
        torch.set_num_threads(1)


def test_one_evaluator_for_every_target_gives_each_targets_own_rows(world, monkeypatch):
    """`evaluate_rows` keeps one `Evaluator` (the hand loaded once, its scenes) across its targets:
    every target's rows equal those of `evaluate_table` on that target alone."""
    import datagen.hands as hands_pkg
    from datagen.eval.table import evaluate_table
    from datagen.pipeline import evaluate_rows, synthesize_rows
    from datagen.tasks import load_task

    objs, cache, hand = world
    targets = build_targets([BatchObject(objs["box.obj"], (0.07, 0.09), object_id="box"),
                             BatchObject(objs["ball.obj"], (0.08,), object_id="ball")], grid_resolution=16, cache=cache)
    _, table = synthesize_rows(hand, targets, load_task("force_closure"), SynthConfig(iters=10, num_directions=16), 2)
    table = table.set_column(table.schema.get_field_index("object_path"), "object_path",
                             [[str(objs[r["object_id"] + ".obj"].entry) for r in table.select(["object_id"]).to_pylist()]])
    cfg = EvalConfig.from_dict(TINY_EVAL)
    alone = [evaluate_table(t, cfg) for t in evaluate_rows(table, targets, "force_closure", cfg)]  # re-evaluated fresh
    loads = []
    real = hands_pkg.load_hand
    monkeypatch.setattr(hands_pkg, "load_hand", lambda *a, **k: loads.append(a) or real(*a, **k))
    shared = evaluate_rows(table, targets, "force_closure", cfg)
    assert len(loads) == 1  # one hand for the three targets
    assert [_clean(t.to_pylist()) for t in shared] == [_clean(t.to_pylist()) for t in alone]
