"""The hand and object the page draws are posed as simulated: checked against the project's FK
(pytorch-kinematics, `HandModel.link_transforms`) and the processed object's piece files."""

import mujoco
import numpy as np
import pytest
import torch
import trimesh

from datagen.hands import load_hand
from datagen.view import STATES, SceneCache
from datagen.view.posing import HAND_PREFIX


def _mat(q) -> np.ndarray:
    out = np.zeros(9)
    mujoco.mju_quat2Mat(out, np.asarray(q, dtype=np.float64))
    return out.reshape(3, 3)


@pytest.fixture(scope="module")
def posed(source):
    i = 0
    return SceneCache(source.eval_config).posed(source.values("hand")[i], source.object_dir(i),
                                                source.scale(i), source.values("task")[i],
                                                source.poses(i)), source.poses(i)


@pytest.mark.parametrize("state", ["pregrasp", "grasp", "squeeze"])
def test_hand_geoms_follow_the_fk(posed, state):
    posed_grasp, poses = posed
    hand = load_hand("shadow", dtype=torch.float64)
    row = torch.as_tensor(poses[STATES.index(state)])
    T = hand.link_transforms(row[:7], row[7:]).numpy()  # (L, 4, 4) world = object frame
    m = posed_grasp.scene.model
    pos, quat, opos, oquat = posed_grasp.state(state)
    checked = 0
    for k, g in enumerate(posed_grasp.geoms):
        if g.part != "hand":
            continue
        link = m.body(m.geom_bodyid[g.index]).name[len(HAND_PREFIX):]
        Tl = T[hand.link_names.index(link)]
        want_p = Tl[:3, 3] + Tl[:3, :3] @ m.geom_pos[g.index]
        want_R = Tl[:3, :3] @ _mat(m.geom_quat[g.index])
        assert np.abs(pos[k] - want_p).max() < 1e-5, g.name
        assert np.abs(_mat(quat[k]) - want_R).max() < 1e-5, g.name
        checked += 1
    assert checked >= 40  # Shadow: visual meshes and collision geoms
    np.testing.assert_allclose(opos, 0.0, atol=1e-12)
    np.testing.assert_allclose(np.abs(oquat), [1, 0, 0, 0], atol=1e-12)


def test_object_is_the_scaled_convex_pieces(posed, source):
    posed_grasp, _ = posed
    pos, quat, _, _ = posed_grasp.state("grasp")
    scale = source.scale(0)
    pieces = sorted((source.object_dir(0) / "coacd").glob("coacd_convex_piece_*.obj"))
    drawn = [(g, k) for k, g in enumerate(posed_grasp.geoms) if g.part == "object"]
    assert len(drawn) == len(pieces) > 0
    world = np.concatenate([g.vertices @ _mat(quat[k]).T + pos[k] for g, k in drawn])
    files = np.concatenate([trimesh.load(p, force="mesh").vertices * scale for p in pieces])
    np.testing.assert_allclose(world.min(0), files.min(0), atol=1e-6)
    np.testing.assert_allclose(world.max(0), files.max(0), atol=1e-6)
    for (g, k), p in zip(drawn, pieces):
        piece = trimesh.load(p, force="mesh")
        hull = trimesh.Trimesh(g.vertices @ _mat(quat[k]).T + pos[k]).convex_hull
        assert hull.volume == pytest.approx(piece.convex_hull.volume * scale ** 3, rel=1e-4)


def test_simulated_state_holds_the_hand_at_the_squeeze_root(posed):
    posed_grasp, poses = posed
    m = posed_grasp.scene.model
    pos_sim, _, opos, _ = posed_grasp.state("simulated")
    pos_sq, _, _, _ = posed_grasp.state("squeeze")
    hand = [k for k, g in enumerate(posed_grasp.geoms) if g.part == "hand"]
    # the root is welded to the mocap target, which ends at the squeeze root pose
    base = m.body_weldid[m.body("hand_base").id]  # bodies rigidly attached to the hand root
    root_geoms = [k for k in hand if m.body_weldid[m.geom_bodyid[posed_grasp.geoms[k].index]] == base]
    assert root_geoms and np.abs(pos_sim[root_geoms] - pos_sq[root_geoms]).max() < 2e-3
    assert np.isfinite(opos).all() and np.linalg.norm(opos) < 0.05  # the object stays in the hand's reach
    with pytest.raises(ValueError, match="unknown state"):
        posed_grasp.state("closed")


@pytest.mark.parametrize("name", ["leap", "allegro", "shadow_e3m5"])
def test_other_hands_follow_their_fk(name, source):
    from datagen.hands import available_hands

    if name not in available_hands():
        pytest.skip(f"{name} needs `make hands`")
    hand = load_hand(name, dtype=torch.float64)
    g = torch.Generator().manual_seed(0)
    joints = hand.apply_couplings(hand.random_joints((3,), generator=g))
    root = torch.tensor([[0.02, -0.01, 0.12, 0.9, 0.1, -0.3, 0.2]], dtype=torch.float64).expand(3, 7)
    poses = torch.cat([root, joints], dim=-1).numpy()
    posed = SceneCache(source.eval_config).posed(name, source.object_dir(0), 0.06, "force_closure", poses)
    m = posed.scene.model
    for state in ("pregrasp", "grasp", "squeeze"):
        row = torch.as_tensor(poses[STATES.index(state)])
        T = hand.link_transforms(row[:7], row[7:]).numpy()
        pos, quat, _, _ = posed.state(state)
        hand_geoms = [(k, geom) for k, geom in enumerate(posed.geoms) if geom.part == "hand"]
        assert len(hand_geoms) > 10
        for k, geom in hand_geoms:
            Tl = T[hand.link_names.index(m.body(m.geom_bodyid[geom.index]).name[len(HAND_PREFIX):])]
            assert np.abs(pos[k] - (Tl[:3, 3] + Tl[:3, :3] @ m.geom_pos[geom.index])).max() < 1e-5
            assert np.abs(_mat(quat[k]) - Tl[:3, :3] @ _mat(m.geom_quat[geom.index])).max() < 1e-5


def test_a_tabletop_row_shows_its_table_and_the_lift(source):
    """With a support plane the scene gets the table: a slab whose top face is the plane (every
    corner at height 0 by the row's plane), and the simulated state is the lift test's end."""
    i = 0
    plane = (0.0, 0.6, 0.8, 0.03)  # the table's up direction (object frame) and offset, m
    posed = SceneCache(source.eval_config).posed(source.values("hand")[i], source.object_dir(i), source.scale(i),
                                                 source.values("task")[i], source.poses(i), table=plane)
    tables = [k for k, g in enumerate(posed.geoms) if g.part == "table"]
    assert len(tables) == 1 and sum(g.part == "object" for g in posed.geoms) >= 1
    g = posed.geoms[tables[0]]
    pos, quat, _, _ = posed.state("grasp")
    corners = g.vertices @ _mat(quat[tables[0]]).T + pos[tables[0]]
    height = corners @ np.array(plane[:3]) + plane[3]
    assert height.max() == pytest.approx(0.0, abs=1e-6) and height.min() == pytest.approx(-0.002, abs=1e-6)
    _, _, opos, _ = posed.state("simulated")
    # the object ends on the table (left there) or lifted with the hand, never below the table
    assert float(np.asarray(plane[:3]) @ opos) > -0.005
