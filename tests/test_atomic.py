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
