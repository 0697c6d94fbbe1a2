"""The browser's logic without a browser: filters, object picker, stepping, poses, layers."""

import numpy as np
import pytest

pytest.importorskip("viser")


@pytest.fixture(scope="module")
def browser(source):
    from datagen.view.app import Browser

    b = Browser(source, host="127.0.0.1", port=0)
    yield b
    b.stop()


def test_filters_pick_and_step(browser, source):
    from datagen.view.app import ANY

    assert browser.url.startswith("http://127.0.0.1:")
    assert browser.current == int(browser.object_rows[0])
    browser.f_scale.value = source.scales()[0]
    want = source.select(scale=source.scales()[0])
    assert list(browser.rows) == list(want)
    second = sorted({source.values("object_id")[i] for i in want})[-1]
    browser.g_object.value = second
    rows = [i for i in want if source.values("object_id")[i] == second]
    assert list(browser.object_rows) == rows and browser.current == rows[0]
    browser._step(+1)
    assert browser.current == rows[1 % len(rows)]
    browser._step(-1)
    assert browser.current == rows[0]
    assert "grasp 1 / " in browser.g_where.content
    browser.f_hand.value = ANY
    browser.f_scale.value = ANY
    browser.f_task.value = ANY
    browser.f_verdict.value = ANY
    assert len(browser.rows) == len(source)


def test_select_row_shows_its_numbers_and_poses(browser, source):
    from datagen.view import verdict_line

    last = len(source) - 1
    browser.select_row(last)
    assert browser.current == last
    assert verdict_line(source, last) in browser.panel.content
    nodes = [n for n in browser.drawing.nodes if n is not None]
    roles = [r for n, r in zip(browser.drawing.nodes, browser.drawing.roles) if n is not None]
    hand = [n for n, r in zip(nodes, roles) if r == "hand"]
    browser.g_state.value = 0  # pregrasp
    pre = np.array([n.position for n in hand])
    browser.g_state.value = 1  # grasp
    grasp = np.array([n.position for n in hand])
    posed = browser.cache.posed(source.values("hand")[last], source.object_dir(last),
                                source.scale(last), source.values("task")[last], source.poses(last))
    k = [i for i, g in enumerate(posed.geoms) if browser.drawing.nodes[i] is not None and g.part == "hand"
         and browser.drawing.roles[i] == "hand"]
    np.testing.assert_allclose(grasp, posed.state("grasp")[0][k], atol=1e-6)
    np.testing.assert_allclose(pre, posed.state("pregrasp")[0][k], atol=1e-6)
    for role in ("object", "hand", "collision", "contacts"):
        browser.layers[role].value = False
    assert not any(n.visible for n in nodes) and not browser.drawing.contacts.visible
    browser.layers["collision"].value = True
    assert all(n.visible == (r == "collision") for n, r in zip(nodes, roles))


def test_no_match_clears_the_scene(browser):
    browser.f_reason.value = browser.f_reason.options[-1]
    browser.f_verdict.value = "success" if browser.f_reason.value != "ok" else "failure"
    assert len(browser.rows) == 0 and browser.current is None
    assert "No grasp matches" in browser.panel.content


def test_the_websocket_takes_only_pages_of_its_own_origin(browser):
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    port = browser.server.get_port()
    url = f"ws://127.0.0.1:{port}/"
    for origin in ("http://evil.example", f"http://127.0.0.1:{port + 1}", "null"):
        with pytest.raises(InvalidStatus) as info:  # another site open in the user's browser
            connect(url, origin=origin, open_timeout=20)
        assert info.value.response.status_code == 403
    with connect(url, origin=f"http://127.0.0.1:{port}", open_timeout=20) as ws:  # the page it served
        assert ws.response.status_code == 101


@pytest.mark.slow
def test_ctrl_c_stops_the_viewer_with_one_line_and_130(job_dir):
    import os
    import signal
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "datagen.cli", "view", str(job_dir), "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        for line in proc.stdout:  # viser's banner first
            if line.startswith("datagen view: "):  # serving
                break
        os.kill(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1].startswith("datagen view: interrupted; the viewer stopped"), err
    assert "Traceback" not in err
