"""Which way a hand's joints close (`datagen.hands.closing`), and what `hand init` derives from it for
a claw: three box fingertips round a palm, joints with symmetric ranges (as the D'Claw's +-1.57 rad),
one finger's axis flipped, every pad facing the others."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from datagen.cli import main as cli
from datagen.hands import load_hand, load_spec
from datagen.hands.closing import closing_signs, link_centre
from datagen.hands.geometry import link_shapes
from datagen.hands.validate import validate_hand

ANGLES_DEG = (90.0, 210.0, 330.0)  # the fingers round the palm's z axis
FLIPPED = 1                         # this finger's joints turn about -y: positive closes it
CLAW = """<?xml version="1.0"?>
<robot name="claw">
  <link name="palm">
    <inertial><mass value="0.2"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><box size="0.1 0.1 0.02"/></geometry></collision>
  </link>
{fingers}
</robot>
"""
CLAW_FINGER = """
  <link name="f{i}_prox">
    <inertial><mass value="0.02"/><inertia ixx="1e-6" iyy="1e-6" izz="1e-6" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 0.02"/><geometry><cylinder radius="0.006" length="0.04"/></geometry></collision>
  </link>
  <link name="f{i}_tip">
    <inertial><mass value="0.01"/><inertia ixx="1e-6" iyy="1e-6" izz="1e-6" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 0.015"/><geometry><box size="0.012 0.016 0.03"/></geometry></collision>
  </link>
  <joint name="f{i}_j0" type="revolute">
    <parent link="palm"/><child link="f{i}_prox"/><origin xyz="{x} {y} 0.01" rpy="0 0 {yaw}"/><axis xyz="0 {ay} 0"/>
    <limit lower="-1.5" upper="1.5" effort="1" velocity="1"/>
  </joint>
  <joint name="f{i}_j1" type="revolute">
    <parent link="f{i}_prox"/><child link="f{i}_tip"/><origin xyz="0 0 0.04"/><axis xyz="0 {ay} 0"/>
    <limit lower="-1.5" upper="1.5" effort="1" velocity="1"/>
  </joint>
"""


def write_claw(tmp: Path) -> Path:
    """Each finger's frame has x pointing radially out of the palm's centre; turning about +y by a
    positive angle tips the finger outwards (away from the others), about -y inwards."""
    fingers = "".join(CLAW_FINGER.format(i=i, x=0.03 * np.cos(np.radians(a)), y=0.03 * np.sin(np.radians(a)),
                                         yaw=np.radians(a), ay=-1 if i == FLIPPED else 1)
                      for i, a in enumerate(ANGLES_DEG))
    path = tmp / "claw.urdf"
    path.write_text(CLAW.format(fingers=fingers))
    return path


@pytest.fixture(scope="module")
def claw(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("claw")
    urdf = write_claw(root)
    assert cli(["hand", "init", str(urdf), "--out", str(root / "claw.yaml"), "--no-render"]) == 0  # no error
    return root / "claw.yaml"


def test_symmetric_joints_close_towards_the_other_fingers():
    """Hand-computed: a joint about +y closes with a negative angle, one about -y with a positive
    one (its range says nothing); an asymmetric range closes towards its larger side."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        model = mujoco.MjModel.from_xml_path(str(write_claw(Path(tmp))))
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    tips = [model.body(f"f{i}_tip").id for i in range(3)]
    signs = closing_signs(model, data, tips, [link_centre(data, b, link_shapes(model, b)) for b in tips])
    want = {f"f{i}_j{k}": (1.0 if i == FLIPPED else -1.0) for i in range(3) for k in range(2)}
    assert {model.joint(j).name: float(signs[j]) for j in range(model.njnt)} == want
    model.jnt_range[model.joint("f0_j1").id] = (-0.2, 1.5)  # hyperextension 0.2, flexion 1.5: the range says
    assert closing_signs(model, data, tips, [data.xpos[b] for b in tips])[model.joint("f0_j1").id] == 1.0


def test_claw_pads_face_the_grasp_centre_and_the_palm_faces_the_fingers(claw):
    """Each box fingertip's pad is the middle of its inner face (hand-computed in the link frame:
    x = -6 mm, y = 0 of the 16 mm wide face to the surface samples' spacing, 70% of the 30 mm box
    along z; normal -x), the flipped finger's too; the palm's approach is the palm's normal +z
    (the pads, facing one another, say nothing about it: from the palm's centre to the grasp
    centre); `hand check` finds no error."""
    spec = load_spec(claw)
    assert len(spec.fingertips) == 3
    for tip in spec.fingertips.values():
        x, y, z = tip.point
        assert abs(x + 0.006) < 1e-4 and abs(y) < 0.0015 and abs(z - 0.7 * 0.03) < 0.0025, tip  # edges: 8 mm off
        assert np.allclose(tip.normal, (-1, 0, 0), atol=1e-3), tip
    approach = np.asarray(spec.palm.approach)  # the palm link is the root: its frame is the world's
    assert np.degrees(np.arccos(approach[2])) < 5.0
    hand = load_hand(claw)
    assert [f.line() for f in validate_hand(hand) if f.level == "error"] == []


def test_a_claw_with_its_approach_flipped_is_refused(claw, tmp_path, capsys):
    import dataclasses

    import yaml

    spec = load_spec(claw)
    flipped = dataclasses.replace(spec.palm, approach=tuple(-np.asarray(spec.palm.approach)))
    spec = dataclasses.replace(spec, palm=flipped)
    data = spec.to_dict()
    data["mjcf"] = {"path": str(claw.parent / "claw.urdf")}
    out = tmp_path / "flipped.yaml"
    out.write_text(yaml.safe_dump(data))
    capsys.readouterr()
    assert cli(["hand", "check", str(out)]) == 2
    assert "palm: the approach axis points away from where the fingers close" in capsys.readouterr().err
