"""The page in a real browser: headless Chromium (Debian's ``chromium``; ``make browser``)
loads the live page from a loopback server, selects a grasp, and the screenshot shows the
object and the hand; the page shows the row's verdict; nothing is fetched from the network.
An exported page opened from disk draws the same way. Skipped without /usr/bin/chromium."""

from __future__ import annotations

import io
import time

import numpy as np
import pytest

from tests.view.cdp import CHROMIUM, Chromium

pytest.importorskip("viser")
Image = pytest.importorskip("PIL.Image")  # Pillow: a dependency of viser's imageio
pytestmark = pytest.mark.skipif(not CHROMIUM.exists(), reason="no /usr/bin/chromium (make browser)")

LOAD_S = 90.0


def _shot(c: Chromium, settle_s: float = 12.0) -> np.ndarray:
    """A screenshot once two consecutive ones agree (the renderer has caught up)."""
    last = None
    end = time.monotonic() + settle_s
    while True:
        time.sleep(0.5)
        img = np.asarray(Image.open(io.BytesIO(c.screenshot())).convert("RGB")).astype(np.int16)
        if (last is not None and np.array_equal(img, last)) or time.monotonic() > end:
            return img
        last = img


def _canvas(c: Chromium) -> tuple[slice, slice]:
    r = c.eval("(() => { const b = document.querySelector('canvas').getBoundingClientRect();"
               " return [b.left, b.top, b.right, b.bottom]; })()")
    x0, y0, x1, y1 = (int(round(v)) for v in r)
    return slice(y0, y1), slice(x0, x1)


def _toggle(c: Chromium, label: str) -> None:
    """Click the GUI checkbox whose row reads ``label``."""
    found = c.eval(f"""(() => {{
        for (const box of document.querySelectorAll('input[type=checkbox]')) {{
            let e = box;
            for (let k = 0; k < 6 && e; k++) {{ e = e.parentElement; if (e && e.innerText.trim()) break; }}
            if (e && e.innerText.trim().startsWith({label!r})) {{ box.click(); return true; }}
        }}
        return false; }})()""")
    assert found, f"no checkbox {label!r} on the page"


def _changed(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(a - b).max(axis=-1) > 30


def _only_loopback(urls: list[str]) -> list[str]:
    ok = ("http://127.0.0.1", "ws://127.0.0.1", "data:", "blob:", "file://", "about:")
    return [u[:80] for u in urls if not u.startswith(ok)]


def test_live_page_shows_the_selected_grasp(source, tmp_path):
    from datagen.view.app import Browser
    from datagen.view.panel import verdict_line

    browser = Browser(source, host="127.0.0.1", port=0)
    try:
        with Chromium() as c:
            c.goto(browser.url)
            c.wait_for("document.body && document.body.innerText.includes('Verdict:')", LOAD_S, "the row panel")
            c.eval("[...document.querySelectorAll('button')].find(b => b.innerText.trim() == 'Next grasp').click()")
            c.wait_for("document.body.innerText.includes('grasp 2 /')", 30, "the second grasp")
            expected = int(browser.object_rows[1])
            assert browser.current == expected
            c.wait_for(f"document.body.innerText.includes({verdict_line(source, expected)!r})", 30, "the verdict")
            rows, cols = _canvas(c)
            full = _shot(c)[rows, cols]
            Image.fromarray(full.astype(np.uint8)).save(tmp_path / "grasp.png")
            _toggle(c, "hand meshes")
            no_hand = _shot(c)[rows, cols]
            _toggle(c, "object (convex pieces)")
            _toggle(c, "contact points and normals")
            empty = _shot(c)[rows, cols]
            assert browser.drawing.visible == {"object": False, "hand": False, "collision": False,
                                               "contacts": False}
        hand = _changed(full, no_hand)
        obj = _changed(no_hand, empty)
        h, w = obj.shape
        assert obj.sum() > 300, "no object pixels"
        assert hand.sum() > 2000, "no hand pixels"
        ys, xs = np.nonzero(obj)
        # the camera looks at the object's centre: its pixels surround the canvas centre
        assert abs(xs.mean() - w / 2) < 0.2 * w and abs(ys.mean() - h / 2) < 0.2 * h
        colour = no_hand[obj].mean(axis=0)
        assert colour[0] > colour[2] + 40  # orange-brown object, not the grey hand or white background
        assert not _only_loopback(c.requests), "the page fetched from the network"
    finally:
        browser.stop()


def test_exported_page_draws_offline(source, tmp_path):
    from datagen.view.export import export_html

    (page,) = export_html(source, [0], tmp_path)
    with Chromium() as c:
        c.goto(page.as_uri())
        c.wait_for("document.querySelector('canvas') !== null", LOAD_S, "the canvas")
        rows, cols = _canvas(c)
        img = _shot(c)[rows, cols]
        Image.fromarray(img.astype(np.uint8)).save(tmp_path / "export.png")
        assert not _only_loopback(c.requests), "the exported page fetched from the network"
    background = np.median(img.reshape(-1, 3), axis=0)
    drawn = np.abs(img - background).max(axis=-1) > 30
    assert drawn.mean() > 0.01  # hand and object cover part of the view
    orange = (img[..., 0] > img[..., 2] + 60) & drawn
    assert orange.sum() > 100  # the object
