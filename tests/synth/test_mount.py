"""The joint a mounted task object moves on, as the squeeze sees it (`datagen.synth.synthesize._mount`
and `datagen.synth.squeeze.joint_mobility`): the velocity of contact points under the joint's unit
motion equals MuJoCo's own point Jacobian of the object's joint in the task's evaluation scene;
free objects and force closure have no mount."""

from types import SimpleNamespace

import mujoco
import numpy as np
import pytest
import torch

from datagen.eval import EvalConfig
from datagen.eval.scene import build_scene, pieces_from_processed
from datagen.hands import load_hand
from datagen.objects import task_objects as T
from datagen.objects.process import process_object
from datagen.objects.sources import resolve
from datagen.pipeline import resolve as resolve_recipe
from datagen.synth.squeeze import joint_mobility
from datagen.synth.synthesize import _mount
from datagen.tasks import load_task

MOUNTED = {"turn_handle": "lever_handle", "turn_knob3": "knob3", "pull_drawer": "drawer"}


@pytest.mark.parametrize("task", sorted(MOUNTED))
def test_mobility_is_mujocos_point_jacobian_of_the_object_joint(task, tmp_path):
    name = MOUNTED[task]
    spec = load_task(task)
    targets = [SimpleNamespace(object_id="other"), SimpleNamespace(object_id=T.object_id(name))]
    object_index = torch.tensor([0, 1, 1, 0])
    kind, axis, anchor, mounted = _mount(spec, targets, object_index)
    assert mounted.tolist() == [False, True, True, False]

    pieces = pieces_from_processed(process_object(resolve("tasks", name, T.object_id(name)), root=tmp_path),
                                   T.build(name).scale_m)
    cfg = EvalConfig()
    scene = build_scene(load_hand("shadow"), pieces, cfg, cfg.task_test(task))
    m = scene.model
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    points = np.random.default_rng(0).uniform(-0.08, 0.08, size=(6, 3))  # object frame = world frame
    u = joint_mobility(torch.tensor(points), kind, axis, anchor).numpy()
    for p, up in zip(points, u):
        jacp = np.zeros((3, m.nv))
        mujoco.mj_jac(m, d, jacp, None, p, scene.object_body)
        np.testing.assert_allclose(up, jacp[:, scene.object_dof], atol=1e-9)


def test_free_objects_and_force_closure_have_no_mount():
    idx = torch.zeros(2, dtype=torch.long)
    for task, name in (("lift_plate", "plate"), ("precision_key", "key")):
        assert _mount(load_task(task), [SimpleNamespace(object_id=T.object_id(name))], idx) is None
    assert _mount(load_task("force_closure"), [SimpleNamespace(object_id="anything")], idx) is None
    # a mounted task whose object is not in the batch
    assert _mount(load_task("turn_knob2"), [SimpleNamespace(object_id="other")], idx) is None


def test_centre_of_mass_is_mujocos_and_task_origins_follow_the_config(tmp_path):
    """The handbag's centre of mass from its surface (`GraspTarget.centre_of_mass`) against
    MuJoCo's, whose mass is split over the convex pieces by volume; the task wrench acts there
    only for a free object with a sector and ``task_wrench_at_com`` (the handbag's YAML sets it)."""
    from datagen.synth import GraspTarget, SynthConfig
    from datagen.synth.energies import task_origins

    name = "handbag"
    processed = process_object(resolve("tasks", name, T.object_id(name)), root=tmp_path)
    scale = T.build(name).scale_m
    target = GraspTarget.from_processed(processed, scale, cache_grid=False, grid_resolution=16)
    cfg = EvalConfig()
    scene = build_scene(load_hand("shadow"), pieces_from_processed(processed, scale), cfg, cfg.task_test("lift_handbag"))
    d = mujoco.MjData(scene.model)
    mujoco.mj_forward(scene.model, d)
    np.testing.assert_allclose(target.centre_of_mass, d.xipos[scene.object_body], atol=3e-3)
    assert abs(target.centre_of_mass[2]) > 0.02  # well below the bounding box's centre: the strap is light

    idx = torch.tensor([0, 0, 0])
    bag = load_task("lift_handbag")
    on = resolve_recipe("shadow", "lift_handbag", preset="paper").synth
    assert on.task_wrench_at_com
    origin = task_origins(bag, [target], idx, on)
    np.testing.assert_allclose(origin.numpy(), np.tile(target.centre_of_mass, (3, 1)))
    assert task_origins(bag, [target], idx, SynthConfig()) is None  # the default: at the contacts
    assert task_origins(bag, [target], idx, SynthConfig.from_dict({"task_wrench_at_com": True, "weights": {"task": 0.0}})) is None
    for task in ("turn_knob2", "precision_key"):  # mounted; force closure's whole sphere
        assert task_origins(load_task(task), [target], idx, SynthConfig(task_wrench_at_com=True)) is None
