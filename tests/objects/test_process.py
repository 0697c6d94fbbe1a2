import io
import json

import numpy as np
import pytest
import trimesh

from datagen.objects import layout, procedural
from datagen.objects import process as process_mod
from datagen.objects.cache import entry_dir
from datagen.objects.mjcf import check_mjcf
from datagen.objects.process import object_key, process_object
from datagen.objects.sources import iter_source

_real_surface = process_mod.watertight_surface
MUG = next(i for i in range(100) if procedural.family_of(0, i) == "mug")


def _ref(index):
    return next(r for r in iter_source("procedural:0", index + 1) if r.path == str(index))


def test_mug_end_to_end(cache, fast_cfg):
    r = process_object(_ref(MUG), fast_cfg)
    assert r.ok, r.message
    assert not r.cache_hit
    assert r.entry == entry_dir(cache, object_key(_ref(MUG), r.mesh_sha256), fast_cfg.hash())
    assert len(r.piece_volumes) >= 2  # a mug is not convex
    assert all(v > fast_cfg.min_part_volume for v in r.piece_volumes)
    assert all(p.is_file() for p in r.piece_paths)
    assert (r.entry / layout.PIECES_DIR / layout.DECOMPOSED).is_file()
    # normalized units: bounding-box centre at 0, half-diagonal 1
    norm = trimesh.load(r.entry / layout.NORMALIZED, process=False)
    lo, hi = norm.bounds
    assert np.allclose((lo + hi) / 2, 0, atol=1e-6)
    assert np.linalg.norm(hi - lo) / 2 == pytest.approx(1.0, abs=1e-6)
    # raw -> normalized map recorded
    raw = trimesh.load(io.BytesIO(procedural.generate(0, MUG).obj_bytes), file_type="obj",
                       process=False)
    assert np.allclose(raw.bounds.mean(0), r.centre, atol=1e-6)
    # simplified surface: watertight, within the tolerance of the input (independent check)
    surf = trimesh.load(r.surface_path, process=False)
    assert surf.is_watertight and surf.volume > 0
    assert len(surf.faces) <= fast_cfg.surface_max_faces
    dev = np.abs(trimesh.proximity.signed_distance(norm, surf.vertices)).max()
    assert dev <= 2 * fast_cfg.surface_tolerance
    # MuJoCo model: compiles, one free body of total mass 0.1 kg at any scale
    assert check_mjcf(r.mjcf_path) == pytest.approx(0.1, rel=1e-6)
    xml = r.entry / "scaled.xml"
    xml.write_text(r.mjcf(0.08))
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(xml))
    assert model.nbody == 2 and model.njnt == 1 and model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    assert model.body_mass[1] == pytest.approx(0.1, rel=1e-6)
    assert model.ngeom == len(r.piece_volumes)
    # mesh scale applied: compiled piece vertices, back in the body frame, span 0.08 * pieces
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    world = []
    for g in range(model.ngeom):
        m = model.geom_dataid[g]
        v = model.mesh_vert[model.mesh_vertadr[m]:model.mesh_vertadr[m] + model.mesh_vertnum[m]]
        world.append(v @ data.geom_xmat[g].reshape(3, 3).T + data.geom_xpos[g] - data.xpos[1])
    world = np.concatenate(world)
    pieces = np.concatenate([trimesh.load(p, process=False).vertices for p in r.piece_paths])
    assert np.allclose(world.max(0) - world.min(0), 0.08 * (pieces.max(0) - pieces.min(0)), atol=1e-6)
    meta = json.loads((r.entry / layout.META).read_text())
    assert meta["status"] == "ok" and meta["pieces_origin"] == "coacd"


def test_second_run_is_a_cache_hit(cache, fast_cfg):
    ref = _ref(0)
    first = process_object(ref, fast_cfg)
    stamp = (first.entry / layout.META).stat().st_mtime_ns
    second = process_object(ref, fast_cfg)
    assert second.cache_hit and second.ok
    assert second.entry == first.entry
    assert (second.entry / layout.META).stat().st_mtime_ns == stamp  # not rewritten
    other = process_object(ref, fast_cfg.__class__(**{**fast_cfg.to_dict(), "coacd_seed": 1}))
    assert not other.cache_hit and other.entry != first.entry  # config is part of the key


@pytest.mark.slow
def test_pieces_are_identical_byte_for_byte_across_runs(tmp_path, fast_cfg):
    a = process_object(_ref(MUG), fast_cfg, tmp_path / "a")
    b = process_object(_ref(MUG), fast_cfg, tmp_path / "b")
    assert a.ok and b.ok and not b.cache_hit
    names = sorted(p.relative_to(a.entry) for p in a.entry.rglob("*.obj"))
    assert names == sorted(p.relative_to(b.entry) for p in b.entry.rglob("*.obj"))
    for n in names:
        assert (a.entry / n).read_bytes() == (b.entry / n).read_bytes(), n
    assert (a.entry / layout.MJCF).read_bytes() == (b.entry / layout.MJCF).read_bytes()


def test_interrupted_build_leaves_no_entry(cache, fast_cfg, monkeypatch):
    ref = _ref(0)

    def killed(*args, **kw):
        raise KeyboardInterrupt  # what a Ctrl-C / kill in the middle looks like in-process

    monkeypatch.setattr(process_mod, "watertight_surface", killed)
    with pytest.raises(KeyboardInterrupt):
        process_object(ref, fast_cfg, cache)
    assert not list((cache / "objects").rglob(layout.META))
    assert not any((cache / "tmp").iterdir())
    monkeypatch.setattr(process_mod, "watertight_surface", _real_surface)
    r = process_object(ref, fast_cfg, cache)
    assert r.ok and not r.cache_hit


def test_sha_mismatch_is_a_status(cache, fast_cfg):
    r = process_object(_ref(0), fast_cfg, expected_sha256="0" * 64)
    assert r.status == "failed" and r.reason == "sha256_mismatch"


def _dir_ref(tmp_path, name, mesh):
    root = tmp_path / "src"
    root.mkdir(exist_ok=True)
    mesh.export(root / name)
    return next(r for r in iter_source(f"dir:{root}") if r.path == name)


def test_open_mesh_is_repaired_or_closed_by_the_pieces(tmp_path, cache, fast_cfg):
    box = trimesh.creation.box(extents=(0.1, 0.06, 0.04))
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-1], process=False)  # one face missing
    r = process_object(_dir_ref(tmp_path, "open.obj", open_box), fast_cfg)
    assert r.ok, r.message
    surf = trimesh.load(r.surface_path, process=False)
    assert surf.is_watertight
    f = 2 / np.linalg.norm([0.1, 0.06, 0.04])
    assert surf.volume == pytest.approx(0.1 * 0.06 * 0.04 * f**3, rel=1e-3)


@pytest.mark.slow
def test_overlapping_parts_become_one_solid(tmp_path, cache, fast_cfg):
    a = trimesh.creation.box(extents=(0.1, 0.04, 0.04))
    b = trimesh.creation.box(extents=(0.04, 0.1, 0.04))  # a plus sign, as a soup of two boxes
    r = process_object(_dir_ref(tmp_path, "plus.obj", trimesh.util.concatenate([a, b])), fast_cfg)
    assert r.ok and r.surface_origin == "mesh", r.message
    surf = trimesh.load(r.surface_path, process=False)
    f = 2 / np.linalg.norm([0.1, 0.1, 0.04])
    union = (0.1 * 0.04 + 0.04 * 0.1 - 0.04 * 0.04) * 0.04
    assert surf.is_watertight and surf.volume == pytest.approx(union * f**3, rel=1e-3)


def test_mesh_with_a_large_hole_falls_back_to_the_union_of_pieces(fast_cfg):
    from datagen.objects.coacd_step import pieces_from_meshes
    from datagen.objects.surface import watertight_surface

    cyl = trimesh.creation.cylinder(radius=0.3, height=1.0, sections=16)
    side = np.abs(cyl.face_normals[:, 2]) < 0.5
    tube = trimesh.Trimesh(cyl.vertices, cyl.faces[side | (cyl.triangles_center[:, 2] < 0)],
                           process=False)  # the top cap is missing: a 16-gon hole
    assert not tube.is_watertight
    a, b = trimesh.creation.box(extents=(1, 1, 1)), trimesh.creation.box(extents=(1, 1, 1))
    b.apply_translation((0.5, 0, 0))  # two overlapping convex pieces
    pieces = pieces_from_meshes([(a.vertices, a.faces), (b.vertices, b.faces)], fast_cfg, "t")
    v, f, origin = watertight_surface(tube, pieces, fast_cfg, "t")
    surf = trimesh.Trimesh(v, f, process=False)
    assert origin == "pieces_union"
    assert surf.is_watertight and surf.volume == pytest.approx(1.5, rel=1e-6)
