import sys
import types

import numpy as np
import pytest
import trimesh

from datagen.objects import procedural
from datagen.objects.errors import SourceError
from datagen.objects.manifest import build_manifest, load_manifest, split_of, write_manifest
from datagen.objects.process import process_object
from datagen.objects.sources import canonical_source, iter_source


def _box(extents=(0.1, 0.06, 0.04)):
    return trimesh.creation.box(extents=extents)


def test_dir_source_reads_every_format(tmp_path, cache, fast_cfg):
    root = tmp_path / "meshes"
    (root / "sub").mkdir(parents=True)
    for ext in ("obj", "stl", "ply", "off", "glb"):
        _box().export(root / "sub" / f"box.{ext}")
    (root / "notes.txt").write_text("not a mesh")
    refs = list(iter_source(f"dir:{root}"))
    assert [r.path for r in refs] == [f"sub/box.{e}" for e in ("glb", "obj", "off", "ply", "stl")]
    assert len({r.object_id for r in refs}) == 5
    for r in refs:
        out = process_object(r, fast_cfg)
        assert out.ok, (r.path, out.message)
        assert len(out.piece_volumes) == 1  # a box is one convex piece
        # every format gives the same normalized box: volume of a 10x6x4 box scaled to half-diagonal 1
        f = 2 / np.linalg.norm([0.1, 0.06, 0.04])
        assert sum(out.piece_volumes) == pytest.approx(0.1 * 0.06 * 0.04 * f**3, rel=1e-3)
    assert len(list(iter_source(f"dir:{root}", count=2))) == 2


def test_dexgraspnet_layout_reuses_its_pieces(tmp_path, cache, fast_cfg):
    root = tmp_path / "meshdata"
    for code, shift in (("core-bottle-1a", 0.0), ("sem-Box-2b", 0.5)):
        d = root / code / "coacd"
        d.mkdir(parents=True)
        a, b = _box((1, 1, 1)), _box((1, 1, 1))
        a.apply_translation((shift, 0, 0))
        b.apply_translation((shift + 1, 0, 0))
        trimesh.util.concatenate([a, b]).export(d / "decomposed.obj")
        a.export(d / "coacd_convex_piece_0.obj")
        b.export(d / "coacd_convex_piece_1.obj")
    refs = list(iter_source(f"dexgraspnet:{root}"))
    assert [r.object_id for r in refs] == ["core-bottle-1a", "sem-Box-2b"]
    assert [p.name for p in refs[0].piece_files()] == ["coacd_convex_piece_0.obj",
                                                         "coacd_convex_piece_1.obj"]
    out = process_object(refs[0], fast_cfg)
    assert out.ok, out.message
    meta = out.meta
    assert meta["pieces_origin"] == "reused" and len(out.piece_volumes) == 2
    # both unit cubes, normalized by the 2x1x1 box's half-diagonal
    f = 2 / np.linalg.norm([2, 1, 1])
    assert out.piece_volumes == pytest.approx((f**3, f**3), rel=1e-6)


def test_pybullet_source_uses_random_urdfs(tmp_path, monkeypatch, cache):
    data = tmp_path / "pybullet_data"
    for n in ("000", "001"):
        d = data / "random_urdfs" / n
        d.mkdir(parents=True)
        _box().export(d / f"{n}.obj")
        _box().export(d / f"{n}_coll.obj")  # collision copies are skipped
    fake = types.ModuleType("pybullet_data")
    fake.getDataPath = lambda: str(data)
    monkeypatch.setitem(sys.modules, "pybullet_data", fake)
    assert [r.path for r in iter_source("pybullet")] == ["000/000.obj", "001/001.obj"]


def test_pybullet_missing_is_a_named_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "pybullet_data", None)
    with pytest.raises(SourceError, match="pybullet is not installed"):
        canonical_source("pybullet")


def test_procedural_manifest(tmp_path):
    entries = build_manifest("procedural:7", 40)
    assert [e.id for e in entries] == [procedural.object_id(7, i) for i in range(40)]
    assert all(e.scales == (0.06, 0.08, 0.10, 0.12) for e in entries)
    assert {e.family for e in entries} <= set(procedural.FAMILIES)
    e = entries[3]
    import hashlib

    assert e.sha256 == hashlib.sha256(procedural.generate(7, 3).obj_bytes).hexdigest()
    assert e.ref().read_bytes() == procedural.generate(7, 3).obj_bytes
    splits = [split_of(f"obj-{i}") for i in range(2000)]
    assert 0.07 < splits.count("test") / 2000 < 0.13  # ~10% test, by hash
    assert [x.split for x in entries] == [split_of(x.id) for x in entries]
    path = write_manifest(entries, tmp_path / "m.jsonl")
    assert load_manifest(path) == entries


def test_unknown_source_is_named():
    with pytest.raises(SourceError, match="unknown_source"):
        list(iter_source("s3://bucket"))


def test_pkg_source_finds_an_installed_packages_files():
    """``pkg:MODULE/SUBDIR`` roots a source where the package is installed: gymnasium_robotics
    (a dependency) carries the Shadow hand's STL meshes; each ref reads that very file."""
    import importlib.util
    from pathlib import Path

    from datagen.objects.sources import resolve

    uri = "pkg:gymnasium_robotics/envs/assets/stls/hand"
    root = Path(importlib.util.find_spec("gymnasium_robotics").submodule_search_locations[0]) / "envs/assets/stls/hand"
    refs = list(iter_source(uri, 3))
    assert canonical_source(uri) == uri and len(refs) == 3
    for r in refs:
        assert r.file == root / r.path and r.read_bytes() == (root / r.path).read_bytes()
        assert resolve(uri, r.path, r.object_id).file == r.file
    with pytest.raises(SourceError, match="no_such_pkg_xyz.*not installed"):
        list(iter_source("pkg:no_such_pkg_xyz", 1))
