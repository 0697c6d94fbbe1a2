"""Every bad input ends in its reason code: processing failures are statuses, manifest
problems are ManifestErrors naming the line."""

import json

import pytest

from datagen.objects.errors import ManifestError
from datagen.objects.manifest import build_manifest, load_manifest, write_manifest
from datagen.objects.process import process_object
from datagen.objects.sources import iter_source

TRI = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"

# name -> (file name, bytes or None for "do not create", expected reason)
MESH_CASES = {
    "empty file": ("a.obj", b"", "empty_mesh"),
    "whitespace only": ("a.obj", b"\n \n", "empty_mesh"),
    "vertices but no faces": ("a.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "empty_mesh"),
    "NaN vertices": ("a.obj", TRI.replace(b"v 1 0 0", b"v nan 0 0"), "non_finite_vertices"),
    "inf vertices": ("a.obj", TRI.replace(b"v 1 0 0", b"v inf 0 0"), "non_finite_vertices"),
    "missing file": ("a.obj", None, "missing_file"),
    "non-mesh garbage text": ("a.obj", b"hello, this is not a mesh\n", "unreadable_mesh"),
    "binary garbage stl": ("a.stl", bytes(range(256)) * 8, "unreadable_mesh"),
    "truncated ply": ("a.ply", b"ply\nformat ascii 1.0\nelement vertex 3\n", "unreadable_mesh"),
    "zero-volume flat sheet": ("a.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n",
                               "degenerate_mesh"),
    "all vertices coincide": ("a.obj", b"v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n", "degenerate_mesh"),
    "collinear vertices": ("a.obj", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "degenerate_mesh"),
    "huge coordinates": ("a.obj", TRI.replace(b"v 1 0 0", b"v 1e9 0 0"), "huge_coordinates"),
}


@pytest.mark.parametrize("case", sorted(MESH_CASES))
def test_bad_mesh_ends_in_its_reason(case, tmp_path, cache, fast_cfg, box_obj):
    name, data, reason = MESH_CASES[case]
    root = tmp_path / "meshes"
    root.mkdir()
    (root / "keep.obj").write_bytes(box_obj)  # a good neighbour: the batch goes on
    if data is not None:
        (root / name).write_bytes(data)
    refs = list(iter_source(f"dir:{root}"))
    if data is None:  # a file deleted after enumeration
        refs.append(refs[0].__class__("a.obj", refs[0].source, name, "obj"))
    results = {r.object_id: process_object(r, fast_cfg) for r in refs}
    assert results["keep.obj"].ok
    bad = results[name]
    assert bad.status == "failed"
    assert bad.reason == reason, bad.message
    assert name in bad.message and reason in bad.message  # names the thing and the reason


def _good_line(tmp_path, box_obj):
    root = tmp_path / "src"
    root.mkdir(exist_ok=True)
    (root / "box.obj").write_bytes(box_obj)
    [entry] = build_manifest(f"dir:{root}", None)
    return json.loads(entry.to_json()), root


def _write(path, lines):
    path.write_text("".join((ln if isinstance(ln, str) else json.dumps(ln)) + "\n" for ln in lines))
    return path


def _mutated(line, **changes):
    out = dict(line)
    for k, v in changes.items():
        if v is None:
            out.pop(k)
        else:
            out[k] = v
    return out


MANIFEST_CASES = {
    "path escaping root (..)": (lambda g: [_mutated(g, path="../outside.obj")], "path_escapes_root"),
    "absolute path": (lambda g: [_mutated(g, path="/etc/passwd")], "path_escapes_root"),
    "duplicate ids": (lambda g: [g, _mutated(g, path="box.obj")], "duplicate_id"),
    "malformed line": (lambda g: [g, '{"id": "x", '], "malformed_line"),
    "not an object": (lambda g: ["[1, 2, 3]"], "malformed_line"),
    "missing field": (lambda g: [_mutated(g, sha256=None)], "schema"),
    "unknown field": (lambda g: [_mutated(g, colour="red")], "schema"),
    "bad sha": (lambda g: [_mutated(g, sha256="abc")], "schema"),
    "negative scale": (lambda g: [_mutated(g, scales=[0.06, -1])], "schema"),
    "bad split": (lambda g: [_mutated(g, split="val")], "schema"),
    "unknown source": (lambda g: [_mutated(g, source="ftp:/x")], "unknown_source"),
}


@pytest.mark.parametrize("case", sorted(MANIFEST_CASES))
def test_bad_manifest_ends_in_its_reason(case, tmp_path, box_obj):
    good, root = _good_line(tmp_path, box_obj)
    (tmp_path / "outside.obj").write_bytes(box_obj)
    make, reason = MANIFEST_CASES[case]
    path = _write(tmp_path / "m.jsonl", make(good))
    with pytest.raises(ManifestError) as info:
        load_manifest(path)
    assert info.value.reason.value == reason
    assert str(path) in str(info.value) and reason in str(info.value)


def test_symlink_escaping_root_is_rejected(tmp_path, box_obj):
    good, root = _good_line(tmp_path, box_obj)
    (tmp_path / "outside.obj").write_bytes(box_obj)
    (root / "link.obj").symlink_to(tmp_path / "outside.obj")
    path = _write(tmp_path / "m.jsonl", [_mutated(good, path="link.obj", id="link")])
    with pytest.raises(ManifestError, match="path_escapes_root"):
        load_manifest(path)


def test_good_manifest_round_trips(tmp_path, box_obj):
    good, _ = _good_line(tmp_path, box_obj)
    entries = load_manifest(_write(tmp_path / "m.jsonl", [good]))
    assert write_manifest(entries, tmp_path / "n.jsonl").read_text() == (tmp_path / "m.jsonl").read_text()


def test_a_mesh_over_its_size_cap_is_refused_unread(tmp_path, fast_cfg, box_obj):
    import dataclasses
    import resource

    from datagen.objects.isolate import process_isolated

    root = tmp_path / "meshes"
    root.mkdir()
    (root / "a_box.obj").write_bytes(box_obj)
    with open(root / "huge.obj", "wb") as fh:  # 1 GiB that takes no disk: refused from its size
        fh.truncate(1 << 30)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    rejected = []
    entries = build_manifest(f"dir:{root}", None, (0.08,), rejected=rejected)
    assert [e.id for e in entries] == ["a_box.obj"]
    (r,) = rejected
    assert (r.id, r.reason) == ("huge.obj", "file_too_large")
    assert r.message == (f"huge.obj: file_too_large: {root / 'huge.obj'} is 1 GiB, over its limit of 256 MiB (raise "
                         "ProcessConfig.max_mesh_bytes, the job's process: {max_mesh_bytes: N}, to allow it)")
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss < 100 << 10  # KiB: nothing read
    # the cap is a processing setting, outside the cache key: a small cap refuses a cached object too
    small = dataclasses.replace(fast_cfg, max_mesh_bytes=100)
    assert small.hash() == fast_cfg.hash()
    p = process_isolated(entries[0], small, tmp_path / "cache", 120)
    assert (p.status, p.reason) == ("failed", "file_too_large"), p.message
    assert process_isolated(entries[0], fast_cfg, tmp_path / "cache", 120).ok
