"""Scale "native": a mesh given in metres keeps its real size (the manifest, the resolution
against a processed object, the error for a mesh that is not in metres)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from datagen.objects.errors import ManifestError, Reason
from datagen.objects.manifest import build_manifest, load_manifest, resolve_scales, write_manifest
from datagen.objects.process import process_object
from datagen.objects.sources import resolve


def test_native_keeps_the_mesh_size_in_metres(tmp_path, cache, fast_cfg, box_obj):
    (tmp_path / "box.obj").write_bytes(box_obj)  # a 10 x 6 x 4 cm box
    entries = build_manifest(f"dir:{tmp_path}", None, scales=("native", 0.08))
    path = write_manifest(entries, tmp_path / "m.jsonl")
    (e,) = load_manifest(path)
    assert e.scales == ("native", 0.08)
    p = process_object(resolve(e.source, e.path, e.id), fast_cfg)
    assert p.ok, p.message
    native, fixed = resolve_scales(e.scales, p.factor, e.id)
    assert fixed == 0.08
    # at the native scale the processed surface has the raw box's extents (hand-computed: 10, 6, 4 cm)
    surface = trimesh.load(p.surface_path, force="mesh")
    extents = np.sort(surface.extents * native)
    assert extents == pytest.approx([0.04, 0.06, 0.10], abs=1e-3)
    assert native == pytest.approx(np.sqrt(0.1 ** 2 + 0.06 ** 2 + 0.04 ** 2) / 2, rel=1e-6)


def test_native_rejects_a_mesh_not_in_metres():
    with pytest.raises(ManifestError) as info:  # a 10 cm box written in millimetres: diagonal 123 "m"
        resolve_scales(("native",), 2.0 / 123.0, "mm_box")
    assert info.value.reason == Reason.NATIVE_SIZE
    assert "mm_box" in str(info.value) and "numeric scales" in str(info.value)


def test_manifest_line_accepts_native_and_refuses_other_words(tmp_path):
    line = {"id": "x", "source": "procedural:0", "path": "0", "family": "box", "sha256": "0" * 64,
            "scales": ["native", 0.06], "split": "train"}
    (tmp_path / "ok.jsonl").write_text(json.dumps(line) + "\n")
    assert load_manifest(tmp_path / "ok.jsonl")[0].scales == ("native", 0.06)
    (tmp_path / "bad.jsonl").write_text(json.dumps({**line, "scales": ["real"]}) + "\n")
    with pytest.raises(ManifestError, match="native"):
        load_manifest(tmp_path / "bad.jsonl")
