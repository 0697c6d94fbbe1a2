"""Atomic writes: the target is the old file or the complete new one; no temporary file is left."""

import pytest

from datagen._atomic import atomic_path, atomic_write_text


def test_write_replaces_and_a_failed_write_keeps_the_old_file(tmp_path):
    p = tmp_path / "f.txt"
    atomic_write_text(p, "old")
    atomic_write_text(p, "new")
    assert p.read_text() == "new"
    with pytest.raises(RuntimeError):
        with atomic_path(p) as tmp:
            tmp.write_text("half")
            raise RuntimeError("writer crashed")
    assert p.read_text() == "new"
    assert [q.name for q in tmp_path.iterdir()] == ["f.txt"]


def test_a_folder_is_replaced_whole_or_not_at_all(tmp_path):
    from datagen._atomic import atomic_dir

    d = tmp_path / "obj"
    with atomic_dir(d) as tmp:
        (tmp / "a.txt").write_text("1")
    with atomic_dir(d) as tmp:  # a new version replaces the old one, files it no longer has included
        (tmp / "b.txt").write_text("2")
    assert sorted(p.name for p in d.iterdir()) == ["b.txt"]
    with pytest.raises(KeyboardInterrupt):
        with atomic_dir(d) as tmp:
            (tmp / "c.txt").write_text("half")
            raise KeyboardInterrupt
    assert sorted(p.name for p in d.iterdir()) == ["b.txt"]
    assert [q.name for q in tmp_path.iterdir()] == ["obj"]


def test_written_files_and_folders_get_the_usual_permissions(tmp_path):
    import os

    from datagen._atomic import atomic_dir

    old = os.umask(0o027)
    try:
        atomic_write_text(tmp_path / "f.txt", "x")
        with atomic_dir(tmp_path / "d"):
            pass
    finally:
        os.umask(old)
    assert (tmp_path / "f.txt").stat().st_mode & 0o777 == 0o640  # as open() makes it, not mkstemp's 0600
    assert (tmp_path / "d").stat().st_mode & 0o777 == 0o750
