"""The live dataset browser: a viser server with filters, an object picker and grasp stepping.

    browser = Browser(open_source("jobs/default"), host="127.0.0.1", port=8080)
    print(browser.url)   # open it in a browser; orbit with the left mouse button, zoom with the wheel

The page's panel: filters (verdict, failure reason, task, hand, scale), the object picker,
the grasp number with previous / next buttons, the pose slider (pregrasp, grasp, squeeze,
simulated: see `datagen.view.posing`), layer switches, and the row's numbers
(`datagen.view.panel`). The GUI is shared by every connected browser tab. Only pages the
server itself served may open its WebSocket (`same_origin`).
"""

from __future__ import annotations

import contextlib
import threading

import numpy as np

from .draw import GraspDrawing, camera_for
from .panel import row_markdown
from .posing import STATES, SceneCache
from .source import VERDICTS, GraspSource

__all__ = ["Browser", "ANY", "same_origin"]

ANY = "(any)"


_SERVE_LOCK = threading.Lock()


def same_origin(process_request=None):
    """A websockets ``process_request`` hook refusing (403) a WebSocket upgrade whose ``Origin``
    is not the page's own (``http://`` + its ``Host``): another site open in the user's browser
    cannot drive the viewer or read the dataset through it (cross-site WebSocket hijacking).
    A request without ``Origin`` (not a browser) is let through; others go to ``process_request``."""
    import http

    def check(connection, request):
        if request.headers.get("Upgrade", "").lower() == "websocket":
            origin, host = request.headers.get("Origin"), request.headers.get("Host", "")
            if origin is not None and origin not in (f"http://{host}", f"https://{host}"):
                return connection.respond(http.HTTPStatus.FORBIDDEN, f"cross-origin WebSocket from {origin} refused\n")
            return None
        return process_request(connection, request) if process_request is not None else None
    return check


@contextlib.contextmanager
def _same_origin_websockets():
    """While a viser server starts (it binds in ``ViserServer()``), its websockets ``serve`` gets
    the `same_origin` check in front of viser's own request hook (viser has no option for it)."""
    import websockets.asyncio.server as ws_server

    with _SERVE_LOCK:
        real = ws_server.serve

        def serve(*args, **kwargs):
            kwargs["process_request"] = same_origin(kwargs.get("process_request"))
            return real(*args, **kwargs)

        ws_server.serve = serve
        try:
            yield
        finally:
            ws_server.serve = real


def _options(labels: list[str]) -> tuple[str, ...]:
    return (ANY, *sorted(labels))


class Browser:
    """A running viser server showing ``source`` (see module docstring). ``stop()`` ends it."""

    def __init__(self, source: GraspSource, host: str = "127.0.0.1", port: int = 8080) -> None:
        import viser

        self.source = source
        self.cache = SceneCache(source.eval_config, base=source.base)
        with _same_origin_websockets():
            self.server = viser.ViserServer(host=host, port=port, verbose=False, label="datagen view")
        self.server.scene.set_up_direction("+z")
        self.drawing = GraspDrawing(self.server.scene)
        self._lock = threading.RLock()
        self.rows = np.arange(len(source))    # rows passing the filters
        self.object_rows = self.rows          # rows of the picked object among them
        self.current: int | None = None       # the row shown
        self._framed = None                   # (object, scale) the camera was last placed for
        self._build_gui()
        self._apply_filters()

    @property
    def url(self) -> str:
        host = self.server.get_host()
        return f"http://{'127.0.0.1' if host in ('0.0.0.0', '') else host}:{self.server.get_port()}/"

    def stop(self) -> None:
        self.server.stop()

    # ------------------------------------------------------------------ GUI
    def _build_gui(self) -> None:
        gui, s = self.server.gui, self.source
        gui.configure_theme(control_width="large", show_logo=False)
        gui.main_panel.dock_right()
        gui.add_markdown(f"**datagen view**: `{s.where}`, {len(s)} grasps")
        with gui.add_folder("Filters"):
            self.f_verdict = gui.add_dropdown("verdict", (ANY, *[v for v in VERDICTS if v in s.options("verdict")]))
            self.f_reason = gui.add_dropdown("failure reason", _options(s.options("reason")))
            self.f_task = gui.add_dropdown("task", _options(s.options("task")))
            self.f_hand = gui.add_dropdown("hand", _options(s.options("hand")))
            self.f_scale = gui.add_dropdown("scale", (ANY, *sorted(s.options("scale"))))
            self.matches = gui.add_markdown("")
        with gui.add_folder("Grasp"):
            self.g_object = gui.add_dropdown("object", (ANY,))
            self.g_index = gui.add_number("grasp", initial_value=1, min=1, max=1, step=1)
            self.g_prev = gui.add_button("Previous grasp")
            self.g_next = gui.add_button("Next grasp")
            self.g_state = gui.add_slider("pose", min=0, max=len(STATES) - 1, step=1, initial_value=1,
                                          marks=tuple((k, n) for k, n in enumerate(STATES)))
            self.g_where = gui.add_markdown("")
        with gui.add_folder("Layers"):
            self.layers = {role: gui.add_checkbox(label, initial_value=self.drawing.visible[role])
                           for role, label in (("object", "object (convex pieces)"), ("hand", "hand meshes"),
                                               ("collision", "hand collision geoms"), ("table", "the table (tabletop rows)"),
                                               ("contacts", "contact points and normals"))}
        with gui.add_folder("Row"):
            self.panel = gui.add_markdown("")

        for f in (self.f_verdict, self.f_reason, self.f_task, self.f_hand, self.f_scale):
            f.on_update(lambda _: self._apply_filters())
        self.g_object.on_update(lambda _: self._pick_object())
        self.g_index.on_update(lambda _: self._show())
        self.g_prev.on_click(lambda _: self._step(-1))
        self.g_next.on_click(lambda _: self._step(+1))
        self.g_state.on_update(lambda _: self._show())
        for role, box in self.layers.items():
            box.on_update(lambda ev, role=role: self.drawing.set_visible(role, ev.target.value))

    @staticmethod
    def _value(dropdown) -> str | None:
        return None if dropdown.value == ANY else dropdown.value

    def _apply_filters(self) -> None:
        with self._lock:
            self.rows = self.source.select(verdict=self._value(self.f_verdict), reason=self._value(self.f_reason),
                                           task=self._value(self.f_task), hand=self._value(self.f_hand),
                                           scale=self._value(self.f_scale))
            objects = self.source.options("object_id", self.rows)
            self.matches.content = f"{len(self.rows)} grasps of {len(objects)} objects match"
            keep = self.g_object.value if self.g_object.value in objects else (objects[0] if objects else ANY)
            self.g_object.options = tuple(objects) if objects else (ANY,)
            self.g_object.value = keep
            self._pick_object()

    def _pick_object(self) -> None:
        with self._lock:
            codes, labels = self.source.categories("object_id")
            want = labels.index(self.g_object.value) if self.g_object.value in labels else -2
            self.object_rows = self.rows[codes[self.rows] == want]
            n = max(1, len(self.object_rows))
            self.g_index.max = n
            if self.g_index.value != 1:
                self.g_index.value = 1  # triggers _show
            else:
                self._show()

    def _step(self, delta: int) -> None:
        with self._lock:
            n = len(self.object_rows)
            if n:
                self.g_index.value = (int(self.g_index.value) - 1 + delta) % n + 1

    def select_row(self, i: int) -> None:
        """Show row ``i`` of the source (clearing filters that hide it)."""
        with self._lock:
            if i not in self.rows:
                for f in (self.f_verdict, self.f_reason, self.f_task, self.f_hand, self.f_scale):
                    f.value = ANY
                self._apply_filters()
            self.g_object.value = self.source.value("object_id", i)
            self._pick_object()
            self.g_index.value = int(np.flatnonzero(self.object_rows == i)[0]) + 1

    # ------------------------------------------------------------------ drawing
    def _show(self) -> None:
        with self._lock:
            if len(self.object_rows) == 0:
                self.current = None
                self.drawing.clear()
                self.panel.content = "No grasp matches the filters."
                self.g_where.content = ""
                return
            k = min(max(int(self.g_index.value), 1), len(self.object_rows)) - 1
            i = int(self.object_rows[k])
            s = self.source
            state = STATES[int(self.g_state.value)]
            self.g_where.content = f"grasp {k + 1} / {len(self.object_rows)} of this object, pose **{state}**"
            try:
                hand, task, scale = s.value("hand", i), s.value("task", i) or "", s.scale(i)
                posed = self.cache.posed(hand, s.object_dir(i), scale, task, s.poses(i), s.table(i))
                key = (hand, str(s.object_dir(i)), scale, task, s.table(i))
                self.server.scene.set_up_direction(tuple(key[4][:3]) if key[4] else "+z")  # the table's up
                self.drawing.show(posed, s.value("contact_points", i), s.value("contact_normals", i), state, key)
            except (ValueError, OSError) as exc:
                self.panel.content = f"**cannot show row {i}**: {exc}"
                return
            self.current = i
            self.panel.content = row_markdown(s, i)
            if key[1:3] != self._framed:  # a new object or scale: frame it
                self._framed = key[1:3]
                pos, look = camera_for(posed)
                self.server.initial_camera.position = tuple(pos)
                self.server.initial_camera.look_at = tuple(look)
                for client in self.server.get_clients().values():
                    client.camera.position = tuple(pos)
                    client.camera.look_at = tuple(look)
