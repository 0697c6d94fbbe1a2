"""`datagen view --export`: self-contained pages with the scene embedded, and an index."""

import base64
import re

import pytest

from datagen.cli import main

pytest.importorskip("viser")


def test_export_pages_and_index(job_dir, source, tmp_path):
    out = tmp_path / "pages"
    assert main(["view", str(job_dir), "--export", str(out), "--rows", "0", "1"]) == 0
    pages = sorted(out.glob("grasp-*.html"))
    assert [p.name[:11] for p in pages] == ["grasp-00000", "grasp-00001"]
    for page in pages:
        text = page.read_text()
        data = re.search(r'window.__VISER_EMBED_DATA__="([A-Za-z0-9+/=]+)"', text)
        assert data and len(base64.b64decode(data.group(1))) > 50_000  # the hand and object meshes
        # self-contained: no script, stylesheet or image fetched from anywhere
        assert not re.search(r'<(script|link|img)[^>]+(src|href)="(https?:)?//', text)
    index = (out / "index.html").read_text()
    for i, page in enumerate(pages):
        assert f"href='{page.name}'" in index
        assert source.verdicts()[i] in index


def test_export_refuses_bad_rows(job_dir, tmp_path, capsys):
    assert main(["view", str(job_dir), "--export", str(tmp_path), "--rows", "999"]) == 2
    assert "out of range" in capsys.readouterr().err
    assert main(["view", str(job_dir), "--export", str(tmp_path), "--hand", "nope"]) == 2
    assert "no row matches" in capsys.readouterr().err
