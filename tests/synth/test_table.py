"""The table in synthesis: the plane term against MuJoCo's own sphere-plane distance, only tabletop
targets see it, initial palms start above it (and from above or the side), and a short synthesis
on a box lying on the table ends with every collision sphere clear of the table."""

import mujoco
import numpy as np
import pytest
import torch
import trimesh

from datagen.hands import load_hand
from datagen.objects.tabletop import stable_poses
from datagen.synth import GraspTarget, SynthConfig, synthesize
from datagen.synth.init import SCENERY_CLEARANCE_M, initial_poses
from datagen.synth.scenery import TABLE_CLEARANCE_M, Scenery, plane_distance
from datagen.tasks import load_task

CPU = torch.device("cpu")


@pytest.fixture(scope="module")
def shadow():
    torch.set_num_threads(1)
    return load_hand("shadow")


@pytest.fixture(scope="module")
def box_targets():
    """A 0.06 x 0.04 x 0.02 m box (normalized: half-diagonal 1), floating and on its largest face."""
    ext = np.array([3.0, 2.0, 1.0])
    mesh = trimesh.creation.box(ext / np.linalg.norm(ext / 2))
    scale = 0.02 * np.linalg.norm(ext / 2)
    floating = GraspTarget.from_mesh(mesh, scale, "box", grid_resolution=24)
    pose = stable_poses(mesh.vertices, mesh.faces, mesh.center_mass, 1)[0]
    return floating, floating.on_table(pose)


def _mujoco_sphere_plane_distance(plane: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """MuJoCo's signed distance between sphere geoms and a plane geom through -d n facing n."""
    spec = mujoco.MjSpec()
    n = plane[:3] / np.linalg.norm(plane[:3])
    quat = np.zeros(4)
    mujoco.mju_quatZ2Vec(quat, n)
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, pos=list(-plane[3] * n), quat=list(quat), size=[1, 1, 1])
    for c, r in zip(centres, radii):
        spec.worldbody.add_body(pos=list(c)).add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[r, 0, 0])
    m = spec.compile()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    return np.array([mujoco.mj_geomDistance(m, d, 0, 1 + i, 1.0, None) for i in range(len(centres))])


def test_plane_term_is_the_exact_sphere_plane_penetration(box_targets):
    floating, on_table = box_targets
    rng = np.random.default_rng(0)
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    plane = np.array([*n, 0.013])
    table = GraspTarget(**{**on_table.__dict__, "support_plane": tuple(plane)})
    margin = 0.001
    sc = Scenery.for_task(load_task("force_closure"), [floating, table], CPU, torch.float64, sphere_margin_m=margin)
    centres = rng.uniform(-0.05, 0.05, size=(40, 3))
    radii = rng.uniform(0.005, 0.02, size=40)
    ref = _mujoco_sphere_plane_distance(plane, centres, radii)  # sphere surface above the plane, m
    c = torch.as_tensor(centres)[None].repeat(2, 1, 1)
    reach = torch.as_tensor(radii) - margin  # as the energy passes it: the object's margin taken off
    pen = sc.penetration(torch.tensor([0, 1]), c, reach).numpy()
    assert (ref < 0).sum() > 5 and (ref > 0).sum() > 5  # spheres on both sides
    assert np.all(pen[0] == 0)  # the floating target has no table
    # the table takes no margin and keeps TABLE_CLEARANCE_M: max(0, clearance - distance)
    assert np.allclose(pen[1], np.maximum(0.0, TABLE_CLEARANCE_M - ref), atol=1e-9)
    assert torch.allclose(plane_distance(torch.as_tensor(centres), torch.as_tensor(plane)),
                          torch.as_tensor(ref + radii), atol=1e-9)


def test_plane_term_gradient_points_up_the_table(box_targets):
    _, on_table = box_targets
    sc = Scenery.for_task(load_task("force_closure"), [on_table], CPU, torch.float64)
    c = torch.tensor([[[0.0, 0.0, -0.02], [0.01, 0.0, 0.0]]], dtype=torch.float64, requires_grad=True)
    pen = sc.penetration(torch.tensor([0]), c, torch.tensor([0.01, 0.01], dtype=torch.float64))
    pen.square().sum().backward()
    n = torch.tensor(on_table.support_plane[:3], dtype=torch.float64)
    for k in range(2):  # descending the squared penetration moves a sphere along +n, or not at all
        g = -c.grad[0, k]
        if pen[0, k] > 0:
            assert torch.allclose(g / g.norm(), n, atol=1e-9)
        else:
            assert torch.all(g == 0)


def test_initial_palms_start_above_the_table_from_above_or_the_side(shadow, box_targets):
    _, on_table = box_targets
    task = load_task("force_closure")
    sc = Scenery.for_task(task, [on_table], CPU, torch.float32, sphere_margin_m=0.0)
    idx = torch.zeros(64, dtype=torch.long)
    root, joints = initial_poses(shadow, [on_table], idx, task.init, torch.Generator().manual_seed(0),
                                 scenery=sc)
    plane = torch.tensor(on_table.support_plane)
    palm = shadow.palm_frame(root, joints)
    height = plane_distance(palm.origin.double(), plane.double())
    assert torch.all(height >= SCENERY_CLEARANCE_M - 1e-6)
    # the palm faces down or sideways, never up from under the table (the hull's tilt allowed)
    assert torch.all((palm.approach.double() @ plane[:3].double()) < np.sin(np.radians(20)))
    centres, radii = shadow.spheres(root, joints)
    below = sc.penetration(idx, centres, radii).amax(-1)
    assert (below == 0).float().mean() > 0.8  # redrawn until the whole hand is clear, for most starts


def test_synthesis_on_the_table_keeps_the_hand_above_it(shadow, box_targets):
    _, on_table = box_targets
    cfg = SynthConfig(iters=200, num_directions=16, seed=0)
    res = synthesize(shadow, [on_table], load_task("force_closure"), cfg, 4)
    plane = torch.tensor(on_table.support_plane).double()
    for pose in (res.grasp, res.pregrasp):  # the pregrasp too (pulled back where it would go deeper)
        centres, radii = shadow.spheres(pose[:, :7], pose[:, 7:])
        height = plane_distance(centres.double(), plane) - radii.double()
        assert height.amin() > 0  # every sphere above the table (it keeps TABLE_CLEARANCE_M beyond its margin)
    assert float(res.tip_distance.abs().amax(-1).min()) < 0.01  # while reaching for the box


def test_edge_pinch_starts_straddle_a_flat_box_from_above(shadow, box_targets):
    """The edge pinch's ``rim`` starts on a 6 x 4 x 2 cm box lying flat: the pinch axis (thumb tip
    minus the other tips) across the box's 4 cm width within the roll jitter, the tips' centre
    over the box's centre at its mid-height (plus distance_m), the thumb and the fingers outside
    opposite rims, the palm above the box's top."""
    from datagen.synth.init import fingertip_centre
    from datagen.tasks import load_grasp_type

    _, on_table = box_targets
    task = load_task("force_closure")
    kind = load_grasp_type("edge_pinch")
    init = kind.apply_init(task.init)
    sc = Scenery.for_task(task, [on_table], CPU, torch.float32, sphere_margin_m=0.0)
    idx = torch.zeros(64, dtype=torch.long)
    root, joints = initial_poses(shadow, [on_table], idx, init, torch.Generator().manual_seed(0), scenery=sc)
    fp = on_table.footprint
    assert fp.height == pytest.approx(0.02, abs=1e-5) and fp.width == pytest.approx(0.04, abs=1e-5)
    up, axis, centre = (torch.tensor(v, dtype=torch.float32) for v in (fp.up, fp.axis, fp.centre))
    tips = shadow.fingertip_points(root, joints)  # (B, 5, 3), the thumb first
    pinch = tips[:, 0] - tips[:, 1:].mean(1)
    p = pinch / pinch.norm(dim=-1, keepdim=True)
    assert torch.all((p @ up).abs() < 1e-4)  # horizontal
    assert torch.all((p @ axis).abs() > np.cos(np.radians(init.roll_deg)) - 1e-4)  # across the width
    mid = fingertip_centre(shadow, root, joints, None)
    lift = (mid - centre) @ up - fp.height / 2
    assert torch.all(lift > init.distance_m[0] - 1e-4) and torch.all(lift < init.distance_m[1] + 1e-4)
    side = (mid - centre) - ((mid - centre) @ up)[:, None] * up
    assert torch.all(side.norm(dim=-1) < init.offset_m + 1e-4)
    assert torch.all(((tips[:, 0] - centre) * p).sum(-1) > fp.width / 2)  # the thumb beyond one rim
    assert torch.all(((tips[:, 1:].mean(1) - centre) * p).sum(-1) < -fp.width / 2)  # the fingers beyond the other
    palm = shadow.palm_frame(root, joints)
    assert torch.all(plane_distance(palm.origin, torch.tensor(on_table.support_plane)) > fp.height)


def test_a_flat_object_on_the_table_gets_the_flat_band_and_floating_the_bands(box_targets):
    """The job's choice per target (`datagen.pipeline.batch`): the 2 cm high box on the table is
    flat (the dataset preset's edge pinch), the same box floating not; under a lower flat limit it
    takes its size band's tabletop mix (the preset's: the edge pinch too), without one the band's mix."""
    from datagen.pipeline.batch import _grasp_groups
    from datagen.pipeline.recipe import resolve

    floating, on_table = box_targets
    task = load_task("force_closure")
    mix = resolve("shadow", "force_closure").grasp_types
    groups = _grasp_groups(task, [floating, on_table], 2, mix, "precision")
    assert [(name, count, [t.scene for t in ts]) for name, count, ts in groups] == [
        ("precision", 2, ["floating"]), ("edge_pinch", 2, ["tabletop"])]
    low = type(mix).from_dict({**mix.to_dict(), "flat": {"max_height_m": 0.019, "mix": {"edge_pinch": 1}}})
    assert [name for name, _, _ in _grasp_groups(task, [on_table], 2, low, "precision")] == ["edge_pinch"]
    bare = type(mix).from_dict({**low.to_dict(), "bands": [{"mix": {"precision": 1}}]})
    assert [name for name, _, _ in _grasp_groups(task, [on_table], 2, bare, "precision")] == ["precision"]


def test_wrap_starts_on_the_table_are_the_tasks_surround_starts(shadow, box_targets):
    """The power type's ``wrap`` start (from the side of the object) on a table is the task's
    ``surround`` start with its random roll, draw for draw, so tabletop power grasps start as
    before; floating ones do not."""
    import dataclasses

    from datagen.tasks import load_grasp_type

    floating, on_table = box_targets
    task = load_task("force_closure")
    init = load_grasp_type("power").apply_init(task.init)
    assert init.kind == "wrap" and init.roll_deg != task.init.roll_deg
    surround = dataclasses.replace(init, kind="surround", roll_deg=task.init.roll_deg)
    sc = Scenery.for_task(task, [on_table], CPU, torch.float32, sphere_margin_m=0.0)
    idx = torch.zeros(16, dtype=torch.long)
    starts = [initial_poses(shadow, [on_table], idx, c, torch.Generator().manual_seed(0), scenery=sc) for c in (init, surround)]
    assert all(torch.equal(a, b) for a, b in zip(*starts))
    palm = shadow.palm_frame(*starts[0])
    assert torch.all(plane_distance(palm.origin.double(), torch.tensor(on_table.support_plane).double()) > 0)
    free = [initial_poses(shadow, [floating], idx, c, torch.Generator().manual_seed(0)) for c in (init, surround)]
    assert not torch.equal(free[0][0], free[1][0])


def test_allegro_edge_pinch_starts_also_pinch_along_the_length(box_targets):
    """Allegro's edge pinch (its ``hands:`` block: roll up to 90 deg) starts on the flat box with
    pinch axes from across its 4 cm width to along its 6 cm length, every one horizontal; the
    type's own roll (20 deg, the other hands') keeps them across the width."""
    from datagen.tasks import load_grasp_type

    allegro = load_hand("allegro")
    _, on_table = box_targets
    task = load_task("force_closure")
    sc = Scenery.for_task(task, [on_table], CPU, torch.float32, sphere_margin_m=0.0)
    up, axis = (torch.tensor(v, dtype=torch.float32) for v in (on_table.footprint.up, on_table.footprint.axis))
    idx = torch.zeros(64, dtype=torch.long)
    angles = {}
    for name, kind in (("allegro", load_grasp_type("edge_pinch").for_hand("allegro")), ("type", load_grasp_type("edge_pinch"))):
        init = kind.apply_init(task.init)
        root, joints = initial_poses(allegro, [on_table], idx, init, torch.Generator().manual_seed(0), scenery=sc)
        tips = allegro.fingertip_points(root, joints)  # the thumb first
        pinch = tips[:, 0] - tips[:, 1:].mean(1)
        p = pinch / pinch.norm(dim=-1, keepdim=True)
        assert torch.all((p @ up).abs() < 1e-4)  # horizontal
        angles[name] = torch.rad2deg(torch.acos((p @ axis).abs().clamp(max=1.0)))  # from the width's direction
    assert float(angles["type"].max()) <= 20.0 + 0.1
    assert float(angles["allegro"].max()) <= 90.0 + 0.1 and float(angles["allegro"].max()) > 70.0
    assert float((angles["allegro"] > 45).float().mean()) > 0.3  # about half the starts nearer the length
