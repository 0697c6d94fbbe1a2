"""A headless Chromium driven over the Chrome DevTools Protocol (CDP), for the browser tests.

Only the distribution's ``chromium`` package and the ``websockets`` client (a viser dependency)
are used: no browser download, no driver. The browser runs with a fresh profile, loopback
debugging only, no background networking, and no name resolution except for 127.0.0.1 (a page
that needs a CDN fails to draw); every request of the page itself is recorded in ``requests``
so a test can check that nothing leaves the machine (a worker's requests are not recorded, but
are blocked all the same).
"""

from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

CHROMIUM = Path("/usr/bin/chromium")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--remote-debugging-address=127.0.0.1",
         "--remote-debugging-port=0",
         # offline: every host name but loopback fails to resolve, so a page that draws needed no network
         "--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE 127.0.0.1"]


class Chromium:
    """``with Chromium() as c: c.goto(url); c.eval(js); png = c.screenshot()``."""

    def __init__(self, width: int = 1280, height: int = 800, timeout_s: float = 60.0) -> None:
        from websockets.sync.client import connect

        self.profile = tempfile.mkdtemp(prefix="dg-chromium-")
        self.proc = subprocess.Popen([str(CHROMIUM), *FLAGS, f"--user-data-dir={self.profile}",
                                      f"--window-size={width},{height}", "about:blank"],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        self.stderr: list[str] = []
        port = self._debug_port(timeout_s)
        pages = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10).read())
        page = next(p for p in pages if p.get("type") == "page")
        self.ws = connect(page["webSocketDebuggerUrl"], max_size=None, open_timeout=timeout_s)
        self._id = 0
        self.requests: list[str] = []
        self.console: list[str] = []
        for domain in ("Page", "Runtime", "Network"):
            self.call(f"{domain}.enable")
        self.call("Emulation.setDeviceMetricsOverride", width=width, height=height, deviceScaleFactor=1,
                  mobile=False)

    def _debug_port(self, timeout_s: float) -> int:
        found: list[int] = []

        def read() -> None:
            for line in self.proc.stderr:
                self.stderr.append(line)
                m = re.search(r"DevTools listening on ws://[^:]+:(\d+)/", line)
                if m and not found:
                    found.append(int(m.group(1)))

        threading.Thread(target=read, daemon=True).start()
        end = time.monotonic() + timeout_s
        while not found:
            if self.proc.poll() is not None or time.monotonic() > end:
                raise RuntimeError("chromium did not start: " + "".join(self.stderr[-20:]))
            time.sleep(0.05)
        return found[0]

    def call(self, method: str, timeout_s: float = 60.0, **params) -> dict:
        """Send one CDP command and return its result (events that arrive meanwhile are recorded)."""
        self._id += 1
        mine = self._id
        self.ws.send(json.dumps({"id": mine, "method": method, "params": params}))
        end = time.monotonic() + timeout_s
        while True:
            msg = json.loads(self.ws.recv(timeout=max(0.1, end - time.monotonic())))
            if msg.get("method") == "Network.requestWillBeSent":
                self.requests.append(msg["params"]["request"]["url"])
            elif msg.get("method") == "Network.webSocketCreated":
                self.requests.append(msg["params"]["url"])
            elif msg.get("method") == "Runtime.consoleAPICalled":
                self.console.append(" ".join(str(a.get("value", "")) for a in msg["params"]["args"]))
            if msg.get("id") == mine:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg["result"]

    def goto(self, url: str) -> None:
        self.call("Page.navigate", url=url)

    def eval(self, expression: str):
        """The value of a JavaScript expression in the page (promises awaited)."""
        out = self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in out:
            raise RuntimeError(f"{expression}: {out['exceptionDetails']}")
        return out["result"].get("value")

    def wait_for(self, expression: str, timeout_s: float = 60.0, what: str = "") -> object:
        """Poll a JavaScript expression until it is truthy; raise TimeoutError naming ``what``."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            value = self.eval(expression)
            if value:
                return value
            time.sleep(0.25)
        raise TimeoutError(f"waited {timeout_s} s for {what or expression}")

    def screenshot(self) -> bytes:
        """The viewport as PNG bytes."""
        return base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])

    def close(self) -> None:
        try:
            self.ws.close()
        finally:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)
            shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self) -> "Chromium":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
