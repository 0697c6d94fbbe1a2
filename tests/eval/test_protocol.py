"""``EvalConfig.protocol``: whose hand gains the evaluation scene gives the position actuators.

Reference: the compiled scene itself (MuJoCo's actuator parameters), the values typed from
DexGraspBench's hand files (assets/hand/allegro/right_hand.xml kp 5, no forcerange; shadow kp 5,
forcerange -3 3; LEAP: Menagerie's kp 3, kv 0.01) and, with DEXGRASPBENCH_DIR naming a checkout,
those files compiled by MuJoCo."""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np
import pytest

from datagen.eval import EvalConfig, EvalError, build_scene
from datagen.eval.scene import HAND_PREFIX
from datagen.hands import load_hand
from datagen.hands.load import available_hands
from tests.eval.grasps import box_pieces

pytestmark = pytest.mark.mujoco
# hand -> (kp, kv, force limit or None) of DexGraspBench's file
PEER = {"leap": (3.0, 0.01, None), "allegro": (5.0, 0.0, None), "shadow_e3m5": (5.0, 0.0, 3.0)}


def _gains(scene) -> list[tuple]:
    m = scene.model
    out = []
    for a in scene.actuators:
        limited = bool(m.actuator_forcelimited[a])
        out.append((float(m.actuator_gainprm[a, 0]), float(-m.actuator_biasprm[a, 2]),
                    float(m.actuator_forcerange[a, 1]) if limited else None, float(-m.actuator_biasprm[a, 1])))
    return out


@pytest.mark.parametrize("name", [h for h in ("leap", "allegro", "shadow_e3m5", "shadow") if h in available_hands()])
def test_gains_by_protocol(name, box_dir):
    hand = load_hand(name)
    pieces = box_pieces((0.03, 0.02, 0.03), box_dir)
    peer = build_scene(hand, pieces, EvalConfig())
    uniform = build_scene(hand, pieces, EvalConfig(protocol="uniform"))
    assert len(_gains(peer)) == hand.mj_model.nu
    for kp, kv, limit, bias in _gains(uniform):
        assert (kp, limit, bias) == (5.0, 3.0, 5.0) and 0 <= kv <= 0.5 + 1e-12
    if name not in PEER:  # the gymnasium Shadow: the same scene under both
        assert _gains(peer) == _gains(uniform)
        return
    kp, kv, limit = PEER[name]
    for g in _gains(peer):
        assert g[0] == kp and g[1] == pytest.approx(kv) and g[2] == limit
        assert g[3] == g[0]  # still a position actuator: bias -kp q
    if name == "shadow_e3m5":  # DexGraspBench's Shadow gains are the uniform ones: the same scene
        assert _gains(peer) == _gains(uniform)


def test_unknown_protocol_is_refused():
    with pytest.raises(EvalError, match="protocol"):
        EvalConfig(protocol="menagerie")
    assert EvalConfig.from_dict({"protocol": "uniform"}).protocol == "uniform"


@pytest.mark.parametrize("name", [h for h in PEER if h in available_hands()])
def test_gains_are_the_peers_files(name, box_dir):
    """Each actuator's kp, kv and force limit in the default scene equal those of the peer's own
    hand file, compiled by MuJoCo (the Shadow E3M5's wrist actuators the peer lacks aside)."""
    root = os.environ.get("DEXGRASPBENCH_DIR")
    if not root:
        pytest.skip("set DEXGRASPBENCH_DIR to a DexGraspBench checkout (with its Menagerie submodule)")
    xml = Path(root) / "assets" / "hand" / ("shadow" if name == "shadow_e3m5" else name) / "right_hand.xml"
    try:
        peer = mujoco.MjModel.from_xml_path(str(xml))
    except ValueError as exc:
        pytest.skip(f"{xml}: {exc}")
    hand = load_hand(name)
    scene = build_scene(hand, box_pieces((0.03, 0.02, 0.03), box_dir), EvalConfig())
    m = scene.model
    by_joint = {}
    for a in range(peer.nu):
        if peer.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT:
            by_joint[peer.joint(peer.actuator_trnid[a, 0]).name] = a
        else:
            by_joint[peer.tendon(peer.actuator_trnid[a, 0]).name] = a
    checked = 0
    for a in scene.actuators:
        trn = m.actuator_trnid[a, 0]
        target = (m.joint(trn).name if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT else m.tendon(trn).name)
        p = by_joint.get(target.removeprefix(HAND_PREFIX))
        if p is None:
            continue  # E3M5's wrist
        assert np.allclose(m.actuator_gainprm[a, :3], peer.actuator_gainprm[p, :3])
        assert np.allclose(m.actuator_biasprm[a, :3], peer.actuator_biasprm[p, :3])
        assert bool(m.actuator_forcelimited[a]) == bool(peer.actuator_forcelimited[p])
        if peer.actuator_forcelimited[p]:
            assert np.allclose(m.actuator_forcerange[a], peer.actuator_forcerange[p])
        checked += 1
    assert checked == peer.nu
