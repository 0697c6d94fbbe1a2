"""Static scenery in synthesis (a door behind the lever, a cabinet round the drawer): box
distances against trimesh's own signed distance, the penetration term against an independent
per-sphere sum, generic initial palms kept out of the scenery, and a short synthesis that ends
with the hand outside the door by MuJoCo's geometry."""

import numpy as np
import pytest
import torch
import trimesh

from datagen.hands import load_hand
from datagen.objects import task_objects as T
from datagen.pipeline import resolve
from datagen.synth import GraspTarget, SynthConfig, synthesize
from datagen.synth.energies import contact_sphere_index, hand_object_state
from datagen.synth.init import SCENERY_CLEARANCE_M, initial_poses
from datagen.synth.scenery import Scenery, box_distance
from datagen.tasks import InitConfig, load_task


def _box_mesh(lo, hi) -> trimesh.Trimesh:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    m = trimesh.creation.box(extents=hi - lo)
    m.apply_translation((lo + hi) / 2)
    return m


def test_box_distance_matches_trimesh_signed_distance():
    lo, hi = (-0.03, -0.02, -0.05), (0.04, 0.01, 0.0)
    pts = np.random.default_rng(0).uniform(-0.06, 0.06, size=(1000, 3))
    got = box_distance(torch.as_tensor(pts), torch.tensor([lo]), torch.tensor([hi]))[:, 0].numpy()
    ref = -trimesh.proximity.signed_distance(_box_mesh(lo, hi), pts)  # trimesh: positive inside
    assert (got < 0).sum() > 20 and (got > 0).sum() > 20  # both sides sampled
    assert np.allclose(got, ref, atol=1e-9)


def test_box_distance_gradient_is_finite_and_the_nearest_face_normal():
    lo, hi = torch.tensor([[-1.0, -1.0, -1.0]]), torch.tensor([[1.0, 1.0, 1.0]])
    p = torch.tensor([[0.2, 0.1, 0.7], [0.0, 0.0, 1.5], [1.5, 1.5, 0.0], [0.0, 0.0, 0.0]], requires_grad=True)
    box_distance(p, lo, hi).sum().backward()
    assert torch.isfinite(p.grad).all()
    assert torch.allclose(p.grad[0], torch.tensor([0.0, 0.0, 1.0]))  # inside, nearest face +z
    assert torch.allclose(p.grad[1], torch.tensor([0.0, 0.0, 1.0]))  # above the +z face
    assert torch.allclose(p.grad[2], torch.tensor([1.0, 1.0, 0.0]) / 2 ** 0.5)  # off an edge


@pytest.fixture(scope="module")
def lever():
    obj = T.build("lever_handle")
    mesh = obj.mesh.copy()
    mesh.apply_scale(1.0 / obj.scale_m)
    return GraspTarget.from_mesh(mesh, obj.scale_m, T.object_id("lever_handle"), grid_resolution=32)


@pytest.fixture(scope="module")
def shadow():
    torch.set_num_threads(1)
    return load_hand("shadow")


def test_scenery_belongs_to_the_task_object_only(lever):
    task = load_task("turn_handle")
    sc = Scenery.for_task(task, [lever], torch.device("cpu"), torch.float32)
    door_lo, door_hi = T.build("lever_handle").scenery_m[0]
    assert sc is not None and torch.allclose(sc.lo[0], torch.tensor(door_lo)) and torch.allclose(sc.hi[0], torch.tensor(door_hi))
    other = GraspTarget(object_id="something-else", scale=lever.scale, sdf=lever.sdf, hull_points=lever.hull_points,
                        hull_normals=lever.hull_normals, grid=lever.grid)
    assert Scenery.for_task(task, [other], torch.device("cpu"), torch.float32) is None
    assert Scenery.for_task(load_task("precision_key"), [lever], torch.device("cpu"), torch.float32) is None
    both = Scenery.for_task(task, [other, lever], torch.device("cpu"), torch.float32)
    d = both.distance(torch.tensor([0, 1]), torch.tensor([[[0.0, 0.0, -0.05]]] * 2))
    assert d[0, 0] == float("inf") and d[1, 0] < 0  # the other object's samples see no door


def test_penetration_term_adds_each_sphere_inside_the_door(shadow, lever):
    task = load_task("turn_handle")
    sc = Scenery.for_task(task, [lever], torch.device("cpu"), torch.float32)
    # palm down over the door, 2 cm to the side of the lever, lowered until the hand is in the door
    init = InitConfig(kind="approach", approach=(0, 0, -1), target_m=(0.0, 0.2, 0.0), roll_deg=0.0, tilt_deg=0.0,
                      offset_m=0.0, distance_m=(0.0, 0.0))
    root, joints = initial_poses(shadow, [lever], torch.zeros(1, dtype=torch.long), init, torch.Generator().manual_seed(0))
    root = root.clone()
    root[:, 2] -= 0.03
    tips = contact_sphere_index(shadow)[:2]
    idx = torch.zeros(1, dtype=torch.long)
    with_door = hand_object_state(shadow, [lever], idx, root, joints, tips, scenery=sc)
    without = hand_object_state(shadow, [lever], idx, root, joints, tips)
    centres, radii = shadow.spheres(root, joints)
    door = _box_mesh(*T.build("lever_handle").scenery_m[0])
    sd = -trimesh.proximity.signed_distance(door, centres[0].double().numpy())
    pen = np.maximum(0.0, radii.double().numpy() - sd)
    assert pen.max() > 0.005  # the test pose really is in the door
    assert float(with_door.sphere_penetration - without.sphere_penetration) == pytest.approx(float((pen ** 2).sum()), rel=1e-4)
    assert float(with_door.max_penetration) == pytest.approx(max(float(without.max_penetration), pen.max()), rel=1e-4)


def test_generic_initial_palms_start_outside_the_scenery(shadow, lever):
    task = load_task("turn_handle")
    sc = Scenery.for_task(task, [lever], torch.device("cpu"), torch.float32)
    init = InitConfig(offset_m=0.0)  # the generic (force closure) regime, no lateral jitter
    idx = torch.zeros(256, dtype=torch.long)

    def start(scenery):
        root, joints = initial_poses(shadow, [lever], idx, init, torch.Generator().manual_seed(0), scenery=scenery)
        centres, radii = shadow.spheres(root, joints)
        door = _box_mesh(*T.build("lever_handle").scenery_m[0])
        sd = -trimesh.proximity.signed_distance(door, centres.reshape(-1, 3).double().numpy()).reshape(centres.shape[:2])
        return shadow.palm_frame(root, joints).origin[:, None], (radii.double().numpy() - sd).max(-1)

    palm, depth = start(None)
    assert (sc.distance(idx, palm)[:, 0] < 0).float().mean() > 0.1  # without the door, palms start behind it
    assert (depth > 0.01).mean() > 0.2  # and hands more than 1 cm into it
    palm, depth = start(sc)
    assert (sc.distance(idx, palm)[:, 0] >= SCENERY_CLEARANCE_M - 1e-6).all()
    assert depth.max() <= 1e-6  # every collision sphere outside the door (trimesh's distance)


@pytest.mark.slow
def test_short_synthesis_keeps_the_hand_out_of_the_door_by_mujoco(shadow, lever, tmp_path):
    import mujoco

    from datagen.eval import EvalConfig
    from datagen.eval.metrics import scenery_penetration, set_static_pose
    from datagen.eval.scene import ObjectPieces, build_scene

    task = load_task("turn_handle")
    generic = task.__class__(**{**task.__dict__, "init": InitConfig()})
    cfg = resolve("shadow", "turn_handle", preset="paper", flags={"synth": {"iters": 150, "seeds_per_grasp": 2, "seed": 0}}).synth
    res = synthesize(shadow, [lever], generic, cfg, 6)
    part = tmp_path / "lever.obj"
    obj = T.build("lever_handle")
    m = obj.mesh.copy()
    m.apply_scale(1.0 / obj.scale_m)
    m.export(part)
    scene = build_scene(shadow, ObjectPieces(lever.object_id, (part,), (1.0,), obj.scale_m), EvalConfig(),
                        EvalConfig().task_test("turn_handle"))
    data = mujoco.MjData(scene.model)
    depths = []
    for row in res.grasp.double().numpy():
        set_static_pose(scene, data, row)
        depths.append(scenery_penetration(scene, data))
    assert max(depths) < 0.002, depths  # MuJoCo's own geometry: the hand stays (within 2 mm) out of the door
