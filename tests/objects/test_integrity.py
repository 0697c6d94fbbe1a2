"""Every object keeps its own id and its own failure: same bytes under two names, the same bytes
as two file types, ids a folder's names sanitise to, and entries that are not usable files."""

import json

import pytest

from datagen.objects.config import ProcessConfig, read_yaml
from datagen.objects.errors import ManifestError, MeshProcessingError, Reason
from datagen.objects.manifest import build_manifest, load_manifest, write_manifest
from datagen.objects.process import process_object
from datagen.objects.sources import iter_source


def test_same_bytes_as_two_file_types_fail_each_in_its_own_name(tmp_path, cache, fast_cfg):
    root = tmp_path / "src"
    root.mkdir()
    junk = b"glTF\x02\x00\x00\x00" + bytes(range(64))  # a broken glb header, and no OBJ statement
    (root / "junk.glb").write_bytes(junk)
    (root / "junk.obj").write_bytes(junk)
    refs = {r.object_id: r for r in iter_source(f"dir:{root}")}
    first = process_object(refs["junk.glb"], fast_cfg)
    second = process_object(refs["junk.obj"], fast_cfg)
    assert first.status == second.status == "failed"
    assert first.message.startswith("junk.glb:")
    assert second.message.startswith("junk.obj:") and "junk.glb" not in second.message
    assert first.entry != second.entry  # the file type is part of the cache key


def test_same_bytes_under_two_names_keep_their_names(tmp_path, cache, fast_cfg, box_obj):
    root = tmp_path / "src"
    root.mkdir()
    (root / "a.obj").write_bytes(box_obj)
    (root / "b.obj").write_bytes(box_obj)
    (root / "bad_a.obj").write_bytes(b"v 0 0 0\n")
    (root / "bad_b.obj").write_bytes(b"v 0 0 0\n")
    got = {r.object_id: process_object(r, fast_cfg) for r in iter_source(f"dir:{root}")}
    assert got["a.obj"].ok and got["b.obj"].ok and got["b.obj"].cache_hit
    assert got["a.obj"].entry == got["b.obj"].entry  # one cache entry serves both
    assert [got[k].object_id for k in ("a.obj", "b.obj")] == ["a.obj", "b.obj"]
    assert got["bad_b.obj"].message.startswith("bad_b.obj: empty_mesh")


def test_dir_ids_are_unique_valid_and_the_manifest_reloads(tmp_path, box_obj):
    root = tmp_path / "src"
    (root / "sub").mkdir(parents=True)
    long_name = "x" * 240 + ".obj"
    for name in (long_name, "a b.obj", "a_b.obj", "sub/c.obj", "sub__c.obj"):
        (root / name).write_bytes(box_obj)
    (tmp_path / "outside.obj").write_bytes(box_obj)
    (root / "escape.obj").symlink_to(tmp_path / "outside.obj")
    rejected = []
    entries = build_manifest(f"dir:{root}", None, rejected=rejected)
    ids = [e.id for e in entries]
    assert len(ids) == 5 and len(set(ids)) == 5
    assert all(len(i) <= 200 for i in ids)
    assert "a_b.obj" in ids and "sub__c.obj" in ids  # the first of a clash keeps the plain id
    assert [(r.path, r.reason) for r in rejected] == [("escape.obj", "path_escapes_root")]
    path = write_manifest(entries, tmp_path / "m.jsonl")
    assert [e.id for e in load_manifest(path)] == ids  # what the builder writes, the loader reads
    again = build_manifest(f"dir:{root}", None, rejected=[])
    assert [e.id for e in again] == ids  # deterministic


@pytest.mark.parametrize("kind", ["directory", "device", "loop", "dangling"])
def test_unusable_entries_are_rejected_with_a_reason(kind, tmp_path, box_obj):
    root = tmp_path / "src"
    root.mkdir()
    (root / "good.obj").write_bytes(box_obj)
    bad = root / "bad.obj"
    if kind == "directory":
        bad.mkdir()
    elif kind == "device":
        (root / "sub").mkdir()
        bad = root / "sub" / "bad.obj"
        bad.symlink_to("/dev/zero")
    elif kind == "loop":
        bad.symlink_to(bad)
    else:
        bad.symlink_to(root / "gone.obj")
    rejected = []
    entries = build_manifest(f"dir:{root}", None, rejected=rejected)
    assert [e.id for e in entries] == ["good.obj"]
    (r,) = rejected
    want = {"directory": "not_a_regular_file", "device": "path_escapes_root", "loop": "not_a_regular_file",
            "dangling": "missing_file"}[kind]
    assert r.reason == want and r.id in r.message, r.message


def test_reading_a_device_is_refused_not_attempted(tmp_path):
    root = tmp_path / "src"
    root.mkdir()
    (root / "z.obj").symlink_to("/dev/zero")
    (ref,) = iter_source(f"dir:{root}")
    with pytest.raises(MeshProcessingError) as info:
        ref.read_bytes()
    assert info.value.reason == Reason.NOT_A_FILE


def test_deeply_nested_manifest_json_is_a_manifest_error(tmp_path):
    path = tmp_path / "m.jsonl"
    path.write_text("[" * 100_000 + "]" * 100_000 + "\n")
    with pytest.raises(ManifestError, match="malformed_line.*nested too deeply"):
        load_manifest(path)


def test_duplicate_scales_are_refused(tmp_path, box_obj):
    root = tmp_path / "src"
    root.mkdir()
    (root / "a.obj").write_bytes(box_obj)
    (line,) = [json.loads(e.to_json()) for e in build_manifest(f"dir:{root}", None)]
    line["scales"] = [0.08, 0.08]
    (tmp_path / "m.jsonl").write_text(json.dumps(line) + "\n")
    with pytest.raises(ManifestError, match="distinct"):
        load_manifest(tmp_path / "m.jsonl")
    with pytest.raises(ValueError, match="distinct"):
        build_manifest(f"dir:{root}", None, scales=(0.08, 0.08))


def test_config_yaml_refuses_tags_aliases_and_wrong_types(tmp_path):
    cases = {"tag.yaml": ("a: !!python/object/apply:os.getcwd []\n", "constructor"),
             "alias.yaml": ("a: &x [1, 2]\nb: [*x, *x, *x]\n", "aliases"),
             "deep.yaml": ("a: " + "[" * 5000 + "]" * 5000 + "\n", "nested too deeply")}
    for name, (text, match) in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(ValueError, match=match):
            read_yaml(tmp_path / name)
    (tmp_path / "typed.yaml").write_text("coacd_threshold: lots\n")
    with pytest.raises(ValueError, match=r"typed.yaml.coacd_threshold: must be a number, got 'lots'"):
        ProcessConfig.from_yaml(tmp_path / "typed.yaml")


def test_a_rejected_entry_does_not_take_an_objects_place(tmp_path, box_obj):
    root = tmp_path / "src"
    (root / "a_dir.obj").mkdir(parents=True)  # sorts first
    for name in ("b.obj", "c.obj", "d.obj"):
        (root / name).write_bytes(box_obj)
    rejected = []
    entries = build_manifest(f"dir:{root}", 2, rejected=rejected)
    assert [e.id for e in entries] == ["b.obj", "c.obj"]
    assert [r.id for r in rejected] == ["a_dir.obj"]
