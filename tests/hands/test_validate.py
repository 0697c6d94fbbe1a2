"""`datagen hand init` / `datagen hand check`: a proposed spec validates; broken specs are refused
with the link, joint or finger and the reason; the asset hash and the URDF import details."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml

from datagen.cli import main as cli
from datagen.hands import load_hand, load_spec
from datagen.hands.asset import asset_files, asset_sha256
from datagen.hands.mjcf import detect_couplings, flatten_hand
from datagen.hands.spec import Coupling, Fingertip, dump_spec
from datagen.hands.validate import validate_hand

from .test_spec import write_toy_urdf

MIMIC = """
  <link name="c_tip">
    <inertial><mass value="0.01"/><inertia ixx="1e-6" iyy="1e-6" izz="1e-6" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><box size="0.01 0.01 0.01"/></geometry></collision>
  </link>
  <joint name="c_j0" type="revolute">
    <parent link="palm"/><child link="c_tip"/><origin xyz="0 0.02 0.05"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="1" effort="1" velocity="1"/><mimic joint="a_j0" multiplier="0.5" offset="0.1"/>
  </joint>
</robot>"""


@pytest.fixture(scope="module")
def toy(tmp_path_factory) -> Path:
    """`datagen hand init` of the two-finger toy URDF (root body and fingers found by itself)."""
    root = tmp_path_factory.mktemp("toyhand")
    write_toy_urdf(root)
    assert cli(["hand", "init", str(root / "toy.urdf"), "--out", str(root / "toy.yaml"), "--no-render"]) == 0
    return root / "toy.yaml"


def test_init_proposes_a_spec_that_checks_clean(toy, capsys):
    spec = load_spec(toy)
    assert spec.name == "toy" and spec.root_body == "palm" and len(spec.fingertips) == 2
    assert 0.0003 <= spec.sphere_margin_m <= 0.0015  # derived from the fit, not the 1.5 mm default
    assert "sphere_margin_m:" in toy.read_text()  # the header says how it was derived
    capsys.readouterr()
    assert cli(["hand", "check", str(toy)]) == 0
    assert "toy: 4 joints, 2 fingers" in capsys.readouterr().out


def _broken(toy: Path, tmp_path: Path, **changes) -> Path:
    spec = load_spec(toy)
    spec = dataclasses.replace(spec, **{k: v(spec) for k, v in changes.items()})
    out = tmp_path / "broken.yaml"
    data = spec.to_dict()
    data["mjcf"] = {"path": str(toy.parent / "toy.urdf")}
    out.write_text(yaml.safe_dump(data))
    return out


def _tip(spec, **kw):
    name, tip = next(iter(spec.fingertips.items()))
    return {**spec.fingertips, name: dataclasses.replace(tip, **kw)}


@pytest.mark.parametrize("change,needle", [
    ({"fingertips": lambda s: _tip(s, point=tuple(np.asarray(next(iter(s.fingertips.values())).point) + [0, 0, 0.02]))},
     "mm off the link's collision surface"),
    ({"fingertips": lambda s: _tip(s, normal=tuple(-np.asarray(next(iter(s.fingertips.values())).normal)))},
     "does not point out of the link"),
    ({"spheres": lambda s: {**s.spheres, "a_prox": ()}}, "link 'a_prox': has collision geometry but no spheres"),
    ({"spheres": lambda s: {**s.spheres, "a_prox": ((0.0, 0.0, 0.02, 0.03),)}}, "reaches"),
    ({"palm": lambda s: dataclasses.replace(s.palm, approach=tuple(-np.asarray(s.palm.approach)))},
     "approach axis points away"),
])
def test_check_refuses_broken_specs_naming_the_part(toy, tmp_path, capsys, change, needle):
    path = _broken(toy, tmp_path, **change)
    capsys.readouterr()
    assert cli(["hand", "check", str(path)]) == 2
    err = capsys.readouterr().err
    assert needle in err and "error:" in err


def test_a_missing_coupling_is_named_with_the_remedy(tmp_path, capsys):
    urdf = write_toy_urdf(tmp_path)
    urdf.write_text(urdf.read_text().replace("</robot>", MIMIC))
    hand_flat = flatten_hand(urdf, "palm", write=False)
    assert [(c.joint, c.leader, round(c.ratio, 6), round(c.offset, 6)) for c in detect_couplings(hand_flat.model)] \
        == [("c_j0", "a_j0", 0.5, 0.1)]  # the URDF mimic joint, imported by MuJoCo as a joint equality
    assert cli(["hand", "init", str(urdf), "--out", str(tmp_path / "m.yaml"), "--no-render"]) == 0
    spec = load_spec(tmp_path / "m.yaml")
    assert [c.joint for c in spec.couplings] == ["c_j0"]
    dump_spec(dataclasses.replace(spec, couplings=()), tmp_path / "m.yaml")
    capsys.readouterr()
    assert cli(["hand", "check", str(tmp_path / "m.yaml")]) == 2
    err = capsys.readouterr().err
    assert "joint 'c_j0'" in err and "couples it to 'a_j0'" in err and "add couplings" in err


def test_validation_of_the_builtin_hands_finds_no_error():
    hand = load_hand("shadow")
    assert [f.line() for f in validate_hand(hand) if f.level == "error"] == []


def test_asset_hash_covers_every_file_and_only_their_bytes(tmp_path):
    urdf = write_toy_urdf(tmp_path)
    files = asset_files(urdf)
    assert files[0] == urdf.resolve() and [f.name for f in files[1:]] == ["tip.stl"]
    h = asset_sha256(urdf)
    moved = tmp_path / "moved"
    moved.mkdir()
    write_toy_urdf(moved)
    assert asset_sha256(moved / "toy.urdf") == h  # the same files elsewhere: the same hash
    (moved / "meshes" / "tip.stl").write_bytes((moved / "meshes" / "tip.stl").read_bytes() + b"\0")
    assert asset_sha256(moved / "toy.urdf") != h


def test_glb_meshes_of_a_urdf_are_converted(tmp_path):
    import trimesh

    urdf = write_toy_urdf(tmp_path)
    tip = trimesh.creation.capsule(height=0.02, radius=0.008)
    tip.apply_translation([0, 0, 0.018])
    tip.export(tmp_path / "meshes" / "tip.glb")
    urdf.write_text(urdf.read_text().replace("tip.stl", "tip.glb"))
    flat = flatten_hand(urdf, "palm", write=False)  # MuJoCo reads no .glb: trimesh's OBJ of it is used
    (tmp_path / "stl").mkdir()
    stl = flatten_hand(write_toy_urdf(tmp_path / "stl"), "palm", write=False)
    assert flat.model.nmesh == stl.model.nmesh >= 1
    assert np.allclose(np.sort(flat.model.mesh_vert, axis=0), np.sort(stl.model.mesh_vert, axis=0), atol=1e-5)


def test_bad_fingertip_link_in_a_spec_names_it(toy, tmp_path):
    spec = load_spec(toy)
    tips = {**spec.fingertips, "extra": Fingertip(link="nowhere", point=(0, 0, 0), normal=(0, 0, 1))}
    path = _broken(toy, tmp_path, fingertips=lambda s: tips)
    with pytest.raises(ValueError, match="fingertips names unknown link 'nowhere'"):
        load_hand(path)
    path = _broken(toy, tmp_path, couplings=lambda s: (Coupling("a_j1", "no_joint", 1.0),))
    with pytest.raises(ValueError, match="couplings names unknown joint 'no_joint'"):
        load_hand(path)
