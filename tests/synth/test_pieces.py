"""`datagen.synth.pieces`: the convex pieces' distance grid against MuJoCo's own distances to the
same pieces (mesh geoms, a small probe sphere), inside and outside, and its use by the
penetration terms (`hand_object_state(..., pieces=...)`: the deeper of surface and pieces)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import torch
import trimesh

from datagen.objects.grid_sdf import GridSDF
from datagen.synth.pieces import piece_planes, pieces_grid

PROBE_M = 0.001


def _pieces(tmp_path):
    """Two overlapping boxes (normalized units) as OBJ files, and a 'surface' sphere the grid box comes from."""
    a = trimesh.creation.box(extents=(0.8, 0.3, 0.3))
    b = trimesh.creation.box(extents=(0.3, 0.8, 0.3))
    b.apply_translation((0.25, 0.25, 0.0))
    paths = []
    for i, m in enumerate((a, b)):
        p = tmp_path / f"piece_{i}.obj"
        m.export(p)
        paths.append(p)
    like = GridSDF.from_mesh(*(lambda s: (s.vertices, s.faces))(trimesh.creation.icosphere(3, 0.6)), resolution=40, samples=50_000)
    return paths, (a, b), like


def _mujoco_distances(meshes, scale, points):
    """(N,) signed distance (m) of ``points`` (N, 3) m to the union of the pieces at ``scale``: a
    probe sphere's least mj_geomDistance to any piece, plus its radius (minus the deepest
    penetration inside)."""
    spec = mujoco.MjSpec()
    for i, m in enumerate(meshes):
        mesh = spec.add_mesh(name=f"p{i}")
        mesh.uservert = (np.asarray(m.vertices) * scale).reshape(-1).tolist()
        spec.worldbody.add_geom(name=f"g{i}", type=mujoco.mjtGeom.mjGEOM_MESH, meshname=f"p{i}")
    body = spec.worldbody.add_body(name="probe", mocap=True)
    body.add_geom(name="probe", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[PROBE_M, 0, 0])
    model = spec.compile()
    data = mujoco.MjData(model)
    probe = model.geom("probe").id
    out = []
    for x in points:
        data.mocap_pos[0] = x
        mujoco.mj_kinematics(model, data)
        out.append(min(mujoco.mj_geomDistance(model, data, probe, model.geom(f"g{i}").id, 0.05, None)
                       for i in range(len(meshes))) + PROBE_M)
    return np.array(out)


def test_pieces_grid_matches_mujoco_distances(tmp_path):
    paths, meshes, like = _pieces(tmp_path)
    grid = pieces_grid(paths, like, samples=50_000)
    assert grid.values.shape == like.values.shape and torch.equal(grid.lo, like.lo)  # stacks with the surface's
    scale = 0.1
    rng = np.random.default_rng(0)
    surf = np.concatenate([trimesh.sample.sample_surface(m, 200, seed=i)[0] for i, m in enumerate(meshes)])
    pts = (surf + rng.normal(0, 0.03, surf.shape)) * scale  # within ~3 mm of some piece's surface
    ref = _mujoco_distances(meshes, scale, pts)
    got = grid.distance(torch.as_tensor(pts, dtype=torch.float32), scale).numpy()
    near = np.abs(ref) < 0.008
    assert near.sum() > 200 and (ref[near] < 0).sum() > 50 and (ref[near] > 0).sum() > 50
    err = np.abs(got - ref)[near]
    cell = float((like.hi - like.lo).max()) / 39 * scale
    assert np.percentile(err, 90) < 0.25 * cell and err.max() < cell  # to the grid's interpolation (cell 3.1 mm)
    # the concave corner between the boxes: outside both pieces, a plain plane bound would say inside
    corner = np.array([[0.4 + 0.02, 0.15 + 0.02, 0.0]]) * scale
    assert float(grid.distance(torch.as_tensor(corner, dtype=torch.float32), scale)) > 0
    assert pieces_grid(paths, like, samples=50_000) is grid  # kept for the object's next scale


def test_piece_planes_hold_the_piece():
    box = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
    planes = piece_planes(box.vertices)
    inside = np.array([[0.9, 0.4, 0.2], [0, 0, 0]])
    outside = np.array([[1.1, 0, 0], [0, 0, 0.3]])
    assert (inside @ planes[:, :3].T <= planes[:, 3] + 1e-9).all()
    assert ((outside @ planes[:, :3].T > planes[:, 3] + 1e-9).any(axis=1)).all()
    d = (planes[:, 3] - np.array([0.9, 0.0, 0.0]) @ planes[:, :3].T).min()  # depth of an inner point
    assert abs(d - 0.1) < 1e-9


@pytest.mark.slow
def test_penetration_pieces_keeps_the_hand_out_of_pieces_that_stick_out(tmp_path):
    """A ball whose one convex 'piece' is 4% larger than its surface (as a decomposition's hull
    sticks out of a concave surface): from the same starts, synthesis with ``penetration_pieces``
    ends with the hand's collision spheres less deep in the piece (exact sphere-sphere depths,
    the margin allowed) than without."""
    import dataclasses

    from datagen.hands import load_hand
    from datagen.synth import GraspTarget, SynthConfig, synthesize
    from datagen.tasks import load_task

    ball = trimesh.creation.icosphere(3)
    ball.apply_scale(1 / np.sqrt(3))
    R = 1.04 / np.sqrt(3)
    piece = trimesh.creation.icosphere(3, radius=R)
    piece.export(tmp_path / "piece.obj")
    t = dataclasses.replace(GraspTarget.from_mesh(ball, 0.1, "ball", grid_resolution=32),
                            piece_paths=(str(tmp_path / "piece.obj"),))
    hand = load_hand("shadow")
    cfg = SynthConfig(iters=80, seeds_per_grasp=1, num_directions=16, seed=2)  # precision: no type settings
    task = load_task("force_closure")
    depth = {}
    for on in (False, True):
        res = synthesize(hand, [t], task, dataclasses.replace(cfg, penetration_pieces=on), 4)
        c, r = hand.spheres(res.grasp[:, :7], res.grasp[:, 7:])
        d = torch.relu(r - hand.sphere_margin_m - (c.norm(dim=-1) - R * 0.1))  # (B, S) m, in the piece
        depth[on] = d.amax(-1)
    assert float(depth[False].median()) > 0.002  # the piece's 2.3 mm overhang: sunk into it
    assert bool((depth[True] < depth[False]).all()) and float(depth[True].max()) < 0.001


def test_pieces_grid_from_the_objects_cache_is_the_built_one(tmp_path, monkeypatch):
    """With an objects cache root the pieces' grid is stored there once and read back with the
    same values (a second process, here a cleared memory cache, does not rebuild it); a changed
    piece file is a different key."""
    from datagen.synth import pieces as P

    paths, _, like = _pieces(tmp_path)
    fresh = pieces_grid(paths, like, samples=20_000)
    P._GRIDS.clear()
    first = pieces_grid(paths, like, samples=20_000, root=tmp_path / "cache")
    stored = list((tmp_path / "cache" / "grids").rglob("*.npz"))
    P._GRIDS.clear()
    real = P._signed_distance
    monkeypatch.setattr(P, "_signed_distance", lambda *a: pytest.fail("rebuilt although stored"))
    again = pieces_grid(paths, like, samples=20_000, root=tmp_path / "cache")
    assert len(stored) == 1 and torch.equal(first.values, fresh.values) and torch.equal(again.values, fresh.values)
    assert torch.equal(again.lo, like.lo) and torch.equal(again.hi, like.hi)
    monkeypatch.setattr(P, "_signed_distance", real)
    trimesh.creation.box(extents=(0.7, 0.3, 0.3)).export(paths[0])
    P._GRIDS.clear()
    other = pieces_grid(paths, like, samples=20_000, root=tmp_path / "cache")
    assert len(list((tmp_path / "cache" / "grids").rglob("*.npz"))) == 2 and not torch.equal(other.values, fresh.values)
