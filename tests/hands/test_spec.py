"""Specs, user hands (URDF/MJCF), the generator CLI, and the errors users see."""

import os
import subprocess
import sys
import ctypes.util
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch
import trimesh
import yaml

from datagen.hands import BUILTIN_HANDS, HandSpec, HandSpecError, builtin_spec_path, load_hand, load_spec
from datagen.hands import make_spec


REPO = Path(__file__).resolve().parents[2]

URDF = """<?xml version="1.0"?>
<robot name="toy">
  <link name="palm">
    <inertial><mass value="0.2"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><box size="0.08 0.02 0.08"/></geometry></collision>
  </link>
{fingers}
</robot>
"""
FINGER = """
  <link name="{n}_prox">
    <inertial><mass value="0.02"/><inertia ixx="1e-6" iyy="1e-6" izz="1e-6" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 0.02"/><geometry><cylinder radius="0.008" length="0.04"/></geometry></collision>
  </link>
  <link name="{n}_tip">
    <inertial><mass value="0.01"/><inertia ixx="1e-6" iyy="1e-6" izz="1e-6" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><mesh filename="{mesh}"/></geometry></collision>
  </link>
  <joint name="{n}_j0" type="revolute">
    <parent link="palm"/><child link="{n}_prox"/><origin xyz="{x} 0 {z}"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="1.5" effort="1" velocity="1"/>
  </joint>
  <joint name="{n}_j1" type="revolute">
    <parent link="{n}_prox"/><child link="{n}_tip"/><origin xyz="0 0 0.04"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="1.5" effort="1" velocity="1"/>
  </joint>
"""


def write_toy_urdf(tmp: Path, mesh_name: str = "meshes/tip.stl", make_mesh: bool = True) -> Path:
    """A two-finger toy hand: box palm, cylinder proximal links, mesh fingertips (an STL we write)."""
    if make_mesh:
        (tmp / "meshes").mkdir(exist_ok=True)
        tip = trimesh.creation.capsule(height=0.02, radius=0.008)
        tip.apply_translation([0, 0, 0.018])
        tip.export(tmp / "meshes" / "tip.stl")
    fingers = "".join(FINGER.format(n=n, x=x, z=0.04, mesh=mesh_name) for n, x in (("a", 0.025), ("b", -0.025)))
    path = tmp / "toy.urdf"
    path.write_text(URDF.format(fingers=fingers))
    return path


def test_urdf_hand_end_to_end(tmp_path):
    urdf = write_toy_urdf(tmp_path)
    out = tmp_path / "toy.yaml"
    code = make_spec.main([str(urdf), "--name", "toy", "--root-body", "palm", "--finger", "a_tip=index",
                           "--finger", "b_tip=thumb", "--out", str(out)])
    assert code == 0
    spec = load_spec(out)
    assert spec.mjcf.path == "toy.urdf" and spec.mjcf.package == ""  # relative to the spec, not copied
    hand = load_hand(out, dtype=torch.float64)
    assert hand.joint_names == ["a_j0", "a_j1", "b_j0", "b_j1"]
    assert hand.actuator_names and len(hand.actuator_names) == 4  # position actuators were added
    assert set(hand.spec.spheres) == {"palm", "a_prox", "a_tip", "b_prox", "b_tip"}
    model = mujoco.MjModel.from_xml_path(str(hand.mjcf_path))
    data = mujoco.MjData(model)
    q = torch.tensor([0.3, 0.7, 1.1, 0.2], dtype=torch.float64)
    data.qpos[:] = hand.joints_to_qpos(q)
    mujoco.mj_forward(model, data)
    T = hand.link_transforms(torch.tensor([0, 0, 0, 1, 0, 0, 0.0], dtype=torch.float64), q)
    for i, link in enumerate(hand.link_names):
        assert np.allclose(T[i, :3, 3].numpy(), data.xpos[model.body(link).id], atol=1e-7)
    assert np.allclose(hand.joints_to_ctrl(q).numpy(), data.actuator_length, atol=1e-9)
    tips = hand.fingertip_points(torch.tensor([0, 0, 0, 1, 0, 0, 0.0], dtype=torch.float64), hand.open_pose)
    assert tips.shape == (2, 3) and hand.fingertip_names == ["index", "thumb"]


def test_missing_mesh_in_urdf_names_the_file(tmp_path):
    urdf = write_toy_urdf(tmp_path, mesh_name="meshes/nowhere.stl", make_mesh=False)
    with pytest.raises(HandSpecError) as err:
        make_spec.propose_spec(urdf, name="toy", root_body="palm", asset=make_spec.AssetRef(path=str(urdf)))
    assert str(urdf) in str(err.value) and "nowhere.stl" in str(err.value)


def test_missing_mesh_in_mjcf_names_the_file(tmp_path):
    mjcf = tmp_path / "hand.xml"
    mjcf.write_text("""<mujoco><asset><mesh name="m" file="gone.stl"/></asset><worldbody>
      <body name="palm"><geom type="mesh" mesh="m"/></body></worldbody></mujoco>""")
    spec_path = tmp_path / "hand.yaml"
    data = yaml.safe_load(builtin_spec_path("shadow").read_text())
    data.update(name="broken", mjcf={"path": "hand.xml"}, root_body="palm")
    spec_path.write_text(yaml.safe_dump(data))
    with pytest.raises(HandSpecError) as err:
        load_hand(spec_path)
    assert str(mjcf) in str(err.value) and "gone.stl" in str(err.value)


def _shadow_spec_dict():
    return yaml.safe_load(builtin_spec_path("shadow").read_text())


@pytest.mark.parametrize("mutate,needle", [
    (lambda d: d.pop("palm"), "missing required key 'palm'"),
    (lambda d: d.update(colour="red"), "unknown keys"),
    (lambda d: d["spheres"].update({"robot0:palm": [[0, 0, 0]]}), "4 finite numbers"),
    (lambda d: d["spheres"].update({"robot0:palm": [[0, 0, 0, -0.01]]}), "radius must be > 0"),
    (lambda d: d["fingertips"]["ff"].update(normal=[0, 0, 0]), "non-zero direction"),
    (lambda d: d["palm"].update(thumb=d["palm"]["approach"]), "orthogonal"),
    (lambda d: d.update(version=99), "version"),
    (lambda d: d["sphere_fit"].update(overshoot=0.5), "overshoot"),
    (lambda d: d.update(thumb_finger="thumb"), "thumb_finger 'thumb' is not one of the fingertips"),
    (lambda d: d["fingertips"]["ff"].update(sphere=10_000), "fingertips.ff.sphere 10000 is out of range"),
])
def test_malformed_spec_names_the_file(tmp_path, mutate, needle):
    data = _shadow_spec_dict()
    mutate(data)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(HandSpecError) as err:
        load_spec(path)
    assert str(path) in str(err.value) and needle in str(err.value)


def test_invalid_yaml_and_unknown_names(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("name: [unclosed\n")
    with pytest.raises(HandSpecError, match="not valid YAML") as err:
        load_spec(path)
    assert str(path) in str(err.value)
    with pytest.raises(HandSpecError, match="built-in hands"):
        load_hand("no_such_hand")
    with pytest.raises(HandSpecError, match="not found"):
        load_hand(tmp_path / "absent.yaml")
    data = _shadow_spec_dict()
    data["fingertips"]["ff"]["link"] = "robot0:nolink"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(HandSpecError, match="unknown link 'robot0:nolink'") as err:
        load_hand(path)
    assert str(path) in str(err.value)


def test_missing_package_says_how_to_install(tmp_path):
    data = _shadow_spec_dict()
    data["mjcf"] = {"package": "datagen_no_such_package", "path": "hand.xml"}
    path = tmp_path / "pkg.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(HandSpecError, match="not installed") as err:
        load_hand(path)
    assert str(path) in str(err.value) and "pip install datagen_no_such_package" in str(err.value)


@pytest.mark.parametrize("name", list(BUILTIN_HANDS))
def test_builtin_specs_round_trip_and_reference_registry_assets(name):
    spec = load_spec(builtin_spec_path(name))
    assert spec.mjcf.package == BUILTIN_HANDS[name][1]  # referenced inside the registry package
    again = HandSpec.from_dict(spec.to_dict())
    assert again.to_dict() == spec.to_dict()
    assert again.spheres == spec.spheres and again.self_collision_pairs == spec.self_collision_pairs
    assert builtin_spec_path(name).stat().st_size < 1_000_000
    # load_spec reads with libyaml where available: the same spec as PyYAML's pure-Python safe_load
    pure = HandSpec.from_dict(yaml.safe_load(builtin_spec_path(name).read_text()), source_file=builtin_spec_path(name))
    assert pure.to_dict() == spec.to_dict()


def test_no_vendored_assets_in_the_package():
    hands = REPO / "datagen" / "hands"
    vendored = [p for p in hands.rglob("*") if p.suffix.lower() in {".stl", ".obj", ".xml", ".urdf", ".msh", ".png"}]
    assert vendored == []


@pytest.mark.skipif(ctypes.util.find_library("OSMesa") is None, reason="libosmesa6 not installed")
def test_make_spec_cli_renders_a_picture(tmp_path):
    urdf = write_toy_urdf(tmp_path)
    env = dict(os.environ, MUJOCO_GL="osmesa")
    png = tmp_path / "toy.png"
    result = subprocess.run(
        [sys.executable, "-m", "datagen.hands.make_spec", str(urdf), "--name", "toy", "--root-body", "palm",
         "--out", str(tmp_path / "toy.yaml"), "--render", str(png)],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000


def test_unsupported_kinematics_is_caught_at_load(tmp_path):
    """pytorch-kinematics ignores a hinge's pos; load_hand compares with MuJoCo and refuses."""
    (tmp_path / "h.xml").write_text("""<mujoco><worldbody><body name="palm"><geom type="box" size=".02 .02 .02"/>
      <body name="f" pos="0 0 0.03"><joint name="j" axis="1 0 0" pos="0 0.01 0" range="0 1.5"/>
      <geom type="capsule" size=".008 .01" pos="0 0 .015"/></body></body></worldbody></mujoco>""")
    spec = {"name": "offset", "mjcf": {"path": "h.xml"}, "root_body": "palm",
            "spheres": {"palm": [[0, 0, 0, 0.02]], "f": [[0, 0, 0.015, 0.01]]},
            "fingertips": {"a": {"link": "f", "point": [0, -0.008, 0.015], "normal": [0, -1, 0]}},
            "palm": {"link": "palm", "origin": [0, -0.02, 0], "approach": [0, -1, 0], "thumb": [1, 0, 0]}}
    path = tmp_path / "h.yaml"
    path.write_text(yaml.safe_dump(spec))
    with pytest.raises(HandSpecError, match="disagrees with MuJoCo") as err:
        load_hand(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize("name", list(BUILTIN_HANDS))
def test_builtin_couplings_are_the_ones_the_mjcf_implies(name):
    """Every built-in spec's couplings come from its MJCF: Shadow's tight J0/J1 tendons (ratio
    1.14), Shadow E3M5's actuated J1 + J2 tendons (equal shares: 1.0), none on Allegro and LEAP."""
    import mujoco

    from datagen.hands.mjcf import detect_couplings, flatten_hand, resolve_asset

    spec = load_spec(builtin_spec_path(name))
    flat = flatten_hand(resolve_asset(spec.mjcf, spec.source_file), spec.root_body, name=spec.name,
                        position_kp=spec.position_actuator_kp)
    found = detect_couplings(mujoco.MjModel.from_xml_path(str(flat.path)))
    assert {(c.joint, c.leader, round(c.ratio, 6)) for c in found} == \
        {(c.joint, c.leader, round(c.ratio, 6)) for c in spec.couplings}
    expected = {"shadow": 4, "shadow_e3m5": 4, "allegro": 0, "leap": 0}[name]
    assert len(spec.couplings) == expected


def test_urdf_links_overlapping_at_rest_are_excluded_from_collision(tmp_path):
    """A URDF cannot exclude contacts: finger a's tip link reaches back 2 cm into the palm at rest
    (its grandparent, which MuJoCo's parent filter does not cover), finger b's tip stays clear. The
    flat model excludes palm/a_tip only, so the resting hand has no self-contact; an MJCF hand's
    contacts are its own (the built-in Shadow gets no exclude)."""
    from datagen.hands.mjcf import flatten_hand, resolve_asset

    write_toy_urdf(tmp_path)
    text = (tmp_path / "toy.urdf").read_text()
    reach_back = '<collision><origin xyz="0 0 -0.07"/><geometry><box size="0.01 0.01 0.02"/></geometry></collision>'
    a_tip = text.index('<link name="a_tip">')
    end = text.index("</link>", a_tip)
    (tmp_path / "toy.urdf").write_text(text[:end] + reach_back + text[end:])
    flat = flatten_hand(tmp_path / "toy.urdf", "palm", write=False)
    m = flat.model
    pairs = {tuple(sorted((m.body(m.exclude_signature[e] >> 16).name, m.body(m.exclude_signature[e] & 0xFFFF).name)))
             for e in range(m.nexclude)}
    assert pairs == {("a_tip", "palm")}
    data = mujoco.MjData(m)
    mujoco.mj_forward(m, data)
    assert data.ncon == 0
    shadow = load_spec(builtin_spec_path("shadow"))
    assert flatten_hand(resolve_asset(shadow.mjcf, shadow.source_file), shadow.root_body, write=False).model.nexclude == 0


THUMB_AT_WRIST = FINGER.format(n="th", x=0.05, z=-0.035, mesh="meshes/tip.stl")  # a thumb at the wrist


def test_thumb_axis_is_across_the_fingers_when_the_thumb_sits_at_the_wrist(tmp_path):
    """A thumb mounted near the wrist (as the Schunk SVH's): the direction to its base runs 35 deg
    along the fingers; the palm's thumb axis is across them (perpendicular to the line from the palm
    origin to the other fingertips, as MuJoCo's kinematics places them), on the thumb's side."""
    urdf = write_toy_urdf(tmp_path)
    urdf.write_text(urdf.read_text().replace("</robot>", THUMB_AT_WRIST + "</robot>"))
    out = tmp_path / "toy.yaml"
    assert make_spec.main([str(urdf), "--name", "toy", "--root-body", "palm", "--finger", "a_tip=index",
                           "--finger", "b_tip=ring", "--finger", "th_tip=th", "--thumb", "th", "--out", str(out)]) == 0
    spec = load_spec(out)
    hand = load_hand(out, dtype=torch.float64)
    model = mujoco.MjModel.from_xml_path(str(hand.mjcf_path))
    data = mujoco.MjData(model)
    data.qpos[:] = hand.joints_to_qpos(hand.open_pose)
    mujoco.mj_kinematics(model, data)
    palm = model.body(spec.palm.link).id
    R, x = data.xmat[palm].reshape(3, 3), data.xpos[palm]
    origin = x + R @ np.asarray(spec.palm.origin)
    a, t = R @ np.asarray(spec.palm.approach), R @ np.asarray(spec.palm.thumb)

    def pad(name):  # the fingertip pad point in the world, from MuJoCo's link pose
        tip = spec.fingertips[name]
        b = model.body(tip.link).id
        return data.xpos[b] + data.xmat[b].reshape(3, 3) @ np.asarray(tip.point)

    fingers = 0.5 * (pad("index") + pad("ring")) - origin
    fingers -= (fingers @ a) * a
    base = data.xpos[model.body("th_prox").id] - origin
    assert abs(float(fingers @ base)) / (np.linalg.norm(fingers) * np.linalg.norm(base)) > 0.4  # the old axis' error
    assert abs(float(t @ fingers)) < 1e-4 * np.linalg.norm(fingers)
    assert abs(float(t @ a)) < 1e-4
    assert float(t @ (pad("th") - origin)) > 0.01 and float(t @ base) > 0.01  # towards the thumb


def test_the_derived_thumb_is_recorded_and_gives_the_pinch_axis(tmp_path):
    """Fingers named after their links, no --thumb: `hand init` detects the thumb (the pad facing
    the others) and records it, and the wrap / rim starts' pinch axis is that fingertip minus the
    other two, as MuJoCo's kinematics places the pads. A spec without the key: "th" if a finger
    has that name, else no thumb (no pinch axis)."""
    from datagen.synth.init import _pinch_vector

    urdf = write_toy_urdf(tmp_path)
    text = urdf.read_text().replace("</robot>", THUMB_AT_WRIST + "</robot>")
    urdf.write_text(text.replace('<origin xyz="0.05 0 -0.035"/><axis xyz="1 0 0"/>',  # the thumb faces the fingers
                                 '<origin xyz="0.05 0 -0.035" rpy="0 0 3.14159"/><axis xyz="1 0 0"/>'))
    out = tmp_path / "toy.yaml"
    assert make_spec.main([str(urdf), "--name", "toy", "--root-body", "palm", "--out", str(out)]) == 0
    spec = load_spec(out)
    assert spec.thumb_finger == "th_tip" and "thumb_finger: th_tip" in out.read_text()
    hand = load_hand(out, dtype=torch.float64)
    model = mujoco.MjModel.from_xml_path(str(hand.mjcf_path))
    data = mujoco.MjData(model)
    data.qpos[:] = hand.joints_to_qpos(hand.open_pose)
    mujoco.mj_kinematics(model, data)

    def pad(name):
        tip = spec.fingertips[name]
        b = model.body(tip.link).id
        return data.xpos[b] + data.xmat[b].reshape(3, 3) @ np.asarray(tip.point)

    want = pad("th_tip") - 0.5 * (pad("a_tip") + pad("b_tip"))
    got = _pinch_vector(hand, hand.open_pose, None).numpy()
    assert np.allclose(got, want, atol=1e-6)
    data_no_key = yaml.safe_load(out.read_text())
    data_no_key.pop("thumb_finger")
    assert HandSpec.from_dict(data_no_key).thumb_finger is None
    assert load_spec(builtin_spec_path("shadow")).thumb_finger == "th"
    assert "thumb_finger" not in yaml.safe_load(builtin_spec_path("shadow").read_text())


def test_pad_point_is_the_middle_of_a_flat_pad(tmp_path):
    """A box fingertip 16 mm wide: the pad's contact point is on the pad face's centre line
    (hand-computed: x = 0 in the link frame, the face at y = -6 mm), 70% along the link, and its
    normal is the face's (0, -1, 0); the most padward sample alone lands anywhere on the face."""
    write_toy_urdf(tmp_path)
    box = trimesh.creation.box(extents=(0.016, 0.012, 0.03))
    box.apply_translation([0, 0, 0.015])
    box.export(tmp_path / "meshes" / "tip.stl")
    out = tmp_path / "toy.yaml"
    assert make_spec.main([str(tmp_path / "toy.urdf"), "--name", "toy", "--root-body", "palm", "--finger",
                           "a_tip=index", "--finger", "b_tip=thumb", "--out", str(out)]) == 0
    spec = load_spec(out)
    hand = load_hand(out, dtype=torch.float64)
    from datagen.synth.energies import contact_sphere_index
    for f, (tip, i) in enumerate(zip(spec.fingertips.values(), contact_sphere_index(hand).tolist())):
        x, y, z = tip.point
        assert abs(x) < 0.001 and abs(y + 0.006) < 1e-4 and abs(z - 0.7 * 0.03) < 0.0025
        assert np.allclose(tip.normal, (0, -1, 0), atol=1e-3)
        # the recorded contact sphere reaches the pad face within a millimetre across it of the point
        c, r = hand.sphere_centres_local[i].numpy(), float(hand.sphere_radii[i])
        assert i == hand.fingertip_spheres[f] and c[1] - r <= -0.006 and np.hypot(c[0] - x, c[2] - z) < 0.003


def test_contact_sphere_is_the_one_reaching_the_pad_at_its_point():
    """Hand-computed: a pad at y = -1 (outward normal -y), its point at the origin's foot (0, -1, 0).
    Sphere 0 reaches y = -1.2 straight below the point; sphere 1 reaches further but 0.5 aside;
    sphere 2's surface is nearest the point (0.05 away) but stops short of the pad (y = -0.95):
    sphere 0 carries the contact, where the nearest-surface rule took sphere 2."""
    spheres = np.array([[0, 0, 0, 1.2], [0.5, 0, 0, 1.5], [0, -0.6, 0, 0.35]])
    point, normal = np.array([0, -1.0, 0]), np.array([0, -1.0, 0])
    assert make_spec._contact_sphere(spheres, point, normal) == 0
    assert make_spec._contact_sphere(spheres[2:], point, normal) == 0  # none reaches: the deepest-reaching
    assert make_spec._contact_sphere(np.zeros((0, 4)), point, normal) is None
    for name in BUILTIN_HANDS:  # the built-in specs name no sphere: the nearest-surface rule, their rows as before
        assert all(t.sphere is None for t in load_spec(builtin_spec_path(name)).fingertips.values())
