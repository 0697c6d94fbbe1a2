"""Choosing MuJoCo's offscreen OpenGL backend (``MUJOCO_GL``) before mujoco is imported.

MuJoCo reads ``MUJOCO_GL`` once, when ``mujoco`` is first imported, and a value it cannot load
breaks the import itself (``MUJOCO_GL=osmesa`` without libOSMesa raises inside ``import mujoco``).
Two entry points keep that from hurting:

- :func:`drop_unusable` (run by the ``datagen`` command before anything imports mujoco, cheap: no subprocess, nothing at all when the
  variable is unset) removes a ``MUJOCO_GL`` that would make ``import mujoco`` fail, with a
  warning, so simulation and every non-rendering command keep working;
- :func:`select_backend` (run by the rendering commands before they import mujoco, or before
  they start a rendering child process) keeps a
  usable ``MUJOCO_GL`` as the user set it, else tries ``egl`` then ``osmesa``, each by rendering
  one small frame in a subprocess, sets the first that works, and raises :class:`GLUnavailable`
  naming what each backend lacks when none does.

On a CPU-only Linux machine Mesa's software EGL (``libegl1``) renders; ``libosmesa6`` is the
alternative. ``python -m datagen.gl`` prints the backend it would use (exit status 1 if none).
"""

from __future__ import annotations

import ctypes.util
import importlib.util
import os
import subprocess
import sys

__all__ = ["BACKENDS", "GLUnavailable", "drop_unusable", "missing_library", "probe", "select_backend"]

BACKENDS = ("egl", "osmesa")  # tried in this order when MUJOCO_GL is unset
# values mujoco accepts on Linux (mujoco/rendering/classic/gl_context.py); others raise at import
_ACCEPTED = {"", "enable", "enabled", "on", "true", "1", "glfw", "glx", "egl", "osmesa",
             "disable", "disabled", "off", "false", "0"}
_LIBRARY = {"egl": ("EGL", "apt-get install -y libegl1"), "osmesa": ("OSMesa", "apt-get install -y libosmesa6"),
            "glx": ("GL", "apt-get install -y libgl1")}
_PROBE = ("import mujoco\n"
          "m = mujoco.MjModel.from_xml_string('<mujoco><worldbody><geom size=\".1\"/></worldbody></mujoco>')\n"
          "r = mujoco.Renderer(m, 16, 16)\n"
          "r.render()\n"
          "r.close()\n")
_selected: str | None = None
_dropped: str = ""  # why drop_unusable removed the user's MUJOCO_GL (told again by select_backend)


class GLUnavailable(RuntimeError):
    """No offscreen OpenGL backend works on this machine (the message says what each one lacks)."""


def missing_library(backend: str) -> str:
    """'' if ``backend``'s system library and PyOpenGL are found, else what is missing and how to
    install it (a cheap check: the library may still fail to open a context)."""
    if backend not in _LIBRARY:
        return ""
    lib, remedy = _LIBRARY[backend]
    if ctypes.util.find_library(lib) is None:
        return f"lib{lib} not found ({remedy})"
    if importlib.util.find_spec("OpenGL") is None:
        return "PyOpenGL is not installed (pip install PyOpenGL)"
    return ""


def drop_unusable() -> str:
    """Remove ``MUJOCO_GL`` from the environment if ``import mujoco`` would fail with it (a value
    mujoco rejects, or a backend whose library is missing) and mujoco is not imported yet; returns
    the reason ('' when nothing was done). Warns on stderr, naming the variable and the remedy."""
    global _dropped
    value = os.environ.get("MUJOCO_GL")
    if value is None or "mujoco" in sys.modules:
        return ""
    v = value.lower().strip()
    reason = (f"MUJOCO_GL={value!r} is not a backend mujoco knows" if v not in _ACCEPTED
              else missing_library(v) and f"MUJOCO_GL={value!r} cannot be used: {missing_library(v)}")
    if reason:
        del os.environ["MUJOCO_GL"]
        _dropped = reason
        print(f"datagen: warning: {reason}; ignoring it (rendering picks a working backend itself)",
              file=sys.stderr)
    return reason


def probe(backend: str, timeout: float = 120.0) -> str:
    """'' if mujoco renders a 16x16 frame with ``MUJOCO_GL=backend`` (in a subprocess), else why not."""
    missing = missing_library(backend)
    if missing:
        return missing
    env = {**os.environ, "MUJOCO_GL": backend}
    try:
        res = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True,
                             timeout=timeout)
    except subprocess.TimeoutExpired:
        return f"no frame within {timeout:.0f} s"
    if res.returncode == 0:
        return ""
    lines = [ln for ln in res.stderr.strip().splitlines() if ln.strip()]
    return lines[-1] if lines else f"exit status {res.returncode}"


def select_backend() -> str:
    """The ``MUJOCO_GL`` backend for rendering in this process, set in ``os.environ`` (so child
    processes inherit it). A ``MUJOCO_GL`` the user set is kept; unset, ``egl`` then ``osmesa``
    are probed. If mujoco is already imported, this process keeps the backend it was imported with
    (render in a child process then). Raises :class:`GLUnavailable` when no backend renders."""
    global _selected
    if "MUJOCO_GL" in os.environ:
        return os.environ["MUJOCO_GL"]
    if _selected is None:
        reasons = {b: probe(b) for b in BACKENDS[:1]}
        for b in BACKENDS[1:]:
            if any(reasons.values()):
                reasons[b] = probe(b)
        ok = [b for b, why in reasons.items() if not why]
        if not ok:
            detail = "; ".join(f"{b}: {why}" for b, why in reasons.items())
            dropped = f" ({_dropped})" if _dropped else ""
            raise GLUnavailable(f"no offscreen OpenGL backend works here{dropped}: {detail}. Install one "
                                f"(Mesa's software EGL: {_LIBRARY['egl'][1]}; or {_LIBRARY['osmesa'][1]}) "
                                "or set MUJOCO_GL to a backend that works")
        _selected = ok[0]
        if _dropped:
            print(f"datagen: warning: {_dropped}; rendering with MUJOCO_GL={_selected}", file=sys.stderr)
    os.environ["MUJOCO_GL"] = _selected
    return _selected


def main() -> int:
    try:
        print(select_backend())
    except GLUnavailable as exc:
        print(f"datagen.gl: {exc}", file=sys.stderr)
        return 1
    return 0

