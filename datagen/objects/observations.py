"""What a learner sees of an object: surface point clouds with normals, single-view clouds.

One row per object and scale (schema ``observations``, schemas/observations.json), in the grasp
rows' object frame and metres: ``observations.points`` points sampled uniformly by area on the
processed object's watertight surface (``surface.obj``) with their outward normals, its bounding
box, and ``observations.views`` partial clouds, each the back-projected depth image of a camera
``camera_distance_m`` from the object's centre looking at it (`datagen.objects.views`). The
surface sample and the camera directions are the object's (the same at every scale); the depth
images are the scale's. Everything random is drawn from the job's seed and the object's id, so the
same job gives the same rows (renders included, on the same machine and Mesa build).

    rows = observe_object(processed, scales=(0.06, 0.08), cfg=ObservationConfig(), seed=0)
    rows = observe_isolated(...)   # the same, in a worker process with a time limit and a GL backend

The depth images come from MuJoCo's renderer, which needs an offscreen OpenGL backend
(``MUJOCO_GL``, `datagen.gl`); where none works, ``renderer: auto`` (the default) casts the same
cameras' pixel rays with trimesh instead (`datagen.objects.views.raycast_depth`: the same pixels
within 1e-4 of the camera distance, but at occluding edges; slower), and each row names the
renderer that made it (``depth_renderer``). With ``views: 0`` nothing is rendered. Cost on this
project's 2-core machine: docs/learning.md.
"""

from __future__ import annotations

import hashlib
import os
import sys
from dataclasses import dataclass

import numpy as np

from datagen.config import Config, check_types
from datagen.errors import ConfigError

__all__ = ["ObservationConfig", "ObservationError", "observation_table", "observe_isolated", "observe_object",
           "resolve_renderer"]

_RENDERER_CHOICES = ("auto", "mujoco", "raycast")


class ObservationError(RuntimeError):
    """An object whose observations could not be made: ``reason`` (a failure row's reason code)
    and the message naming the object."""

    def __init__(self, reason: str, message: str) -> None:
        self.reason = reason
        super().__init__(message)


@dataclass(frozen=True)
class ObservationConfig(Config):
    """A job's object observations (`JobConfig.observations`). Points and depth pixels are drawn
    from the job's seed and the object's id."""

    points: int = 2048               #: surface points (with normals) per object and scale; 0 with views 0: no
                                     #: observations at all
    views: int = 4                   #: single-view depth clouds per object and scale (0: none); the defaults
                                     #: take ~85 KiB per object and scale on disk
    renderer: str = "auto"           #: depth images: mujoco (needs an offscreen GL: MUJOCO_GL=egl or osmesa,
                                     #: `python -m datagen.gl`), raycast (trimesh, no GL), auto (mujoco where
                                     #: a GL backend works, else raycast)
    view_points: int = 1024          #: at most this many points kept per view (a uniform random subset of its pixels)
    image_width: int = 160           #: depth image size, pixels
    image_height: int = 120
    fovy_deg: float = 45.0           #: the cameras' vertical field of view
    camera_distance_m: float = 0.4   #: from the object's centre (its bounding-box centre), metres

    def __post_init__(self):
        check_types(self)
        bad = []
        if not 0 <= self.points <= 1_000_000:
            bad.append(f"points must be in 0..1000000, got {self.points}")
        if not 0 <= self.views <= 64:
            bad.append(f"views must be in 0..64, got {self.views}")
        if self.renderer not in _RENDERER_CHOICES:
            bad.append(f"renderer must be one of {', '.join(_RENDERER_CHOICES)}, got {self.renderer!r}")
        if not 1 <= self.view_points <= 1_000_000:
            bad.append(f"view_points must be in 1..1000000, got {self.view_points}")
        if not (8 <= self.image_width <= 2048 and 8 <= self.image_height <= 2048):
            bad.append(f"image_width and image_height must be in 8..2048, got {self.image_width} x {self.image_height}")
        if not 1.0 <= self.fovy_deg <= 170.0:
            bad.append(f"fovy_deg must be in [1, 170], got {self.fovy_deg}")
        if not 0.0 < self.camera_distance_m <= 100.0:
            bad.append(f"camera_distance_m must be in (0, 100], got {self.camera_distance_m}")
        if bad:
            raise ConfigError.make("observations", "; ".join(bad))

    @property
    def enabled(self) -> bool:
        """Whether a job writes observations at all."""
        return self.points > 0 or self.views > 0


def _streams(seed: int, object_id: str) -> list[np.random.Generator]:
    """Independent generators for the surface sample, the camera directions and the pixel subsets."""
    key = int(hashlib.sha256(object_id.encode()).hexdigest()[:15], 16)
    return [np.random.default_rng(s) for s in np.random.SeedSequence([int(seed), key]).spawn(3)]


def _subset(n: int, k: int, rng: np.random.Generator) -> np.ndarray:
    """min(n, k) distinct indices of range(n), uniform, in random order."""
    return rng.permutation(n)[:k]


_resolved: dict[str, str] = {}  # this process's answer of resolve_renderer (GL probes cost seconds)


def resolve_renderer(renderer: str) -> str:
    """The depth renderer ``renderer`` means in this process: ``mujoco`` (the GL backend chosen
    first, `datagen.gl.select_backend`: it sets ``MUJOCO_GL`` for child processes; raises
    `datagen.gl.GLUnavailable` when none works), ``raycast``, or for ``auto`` the first of them
    that works here."""
    if renderer == "raycast":
        return renderer
    if renderer not in _resolved:
        from datagen.gl import GLUnavailable, select_backend

        try:
            select_backend()
            _resolved[renderer] = "mujoco"
        except GLUnavailable:
            if renderer == "mujoco":
                raise
            _resolved[renderer] = "raycast"
    return _resolved[renderer]


def observe_object(processed, scales, cfg: ObservationConfig, seed: int, *, object_id: str = "",
                   object_path: str = "", split: str = "", mesh_sha256: str = "",
                   renderer: str = "mujoco") -> list[dict]:
    """The ``observations`` rows of a processed object (``datagen.objects.ProcessedObject``, ok)
    at each of ``scales`` (metres per normalized unit), in ``scales`` order, the depth images
    made by ``renderer`` (``mujoco`` or ``raycast``, `datagen.objects.views.render`). What the
    rows record of the object defaults to the processed object's own (as
    `datagen.pipeline.BatchObject`)."""
    import trimesh

    from .views import back_project, intrinsics, look_at_poses, random_directions, render

    object_id = object_id or processed.object_id
    mesh = trimesh.load(processed.surface_path, process=False, force="mesh")
    surface_rng, camera_rng, pixel_rng = _streams(seed, object_id)
    if cfg.points:
        pts, face = trimesh.sample.sample_surface(mesh, cfg.points, seed=surface_rng)
        normals = mesh.face_normals[face]
    else:
        pts, normals = np.zeros((0, 3)), np.zeros((0, 3))
    directions = random_directions(cfg.views, camera_rng)
    intr = intrinsics(cfg.image_width, cfg.image_height, cfg.fovy_deg)
    lo, hi = mesh.bounds
    rows = []
    for s in (float(x) for x in scales):
        poses_m = look_at_poses(directions, cfg.camera_distance_m)
        views, pixels = [], []
        if cfg.views:
            # rendered in normalized units (cameras at distance / s) and scaled back: the same rays
            poses_n = np.concatenate([poses_m[:, :3] / s, poses_m[:, 3:]], axis=1)
            far = 2.0 * (cfg.camera_distance_m / s + 1.0)
            depth = render(renderer, mesh.vertices, mesh.faces, poses_n, cfg.image_width, cfg.image_height,
                           cfg.fovy_deg, far)
            for k in range(cfg.views):
                p, _ = back_project(depth[k], poses_n[k], intr, 0.999 * far)
                views.append((p[_subset(len(p), cfg.view_points, pixel_rng)] * s).astype(np.float32))
                pixels.append(len(p))
        rows.append({
            "object_id": object_id, "object_scale_m": s, "split": split,
            "object_path": object_path or str(processed.entry), "mesh_sha256": mesh_sha256 or processed.mesh_sha256,
            "surface_origin": processed.surface_origin or "mesh",
            "bbox_min_m": (lo * s).astype(np.float32), "bbox_max_m": (hi * s).astype(np.float32),
            "surface_points_m": (pts * s).astype(np.float32), "surface_normals": normals.astype(np.float32),
            "camera_poses": poses_m.astype(np.float32), "camera_intrinsics": intr.astype(np.float32),
            "image_width": cfg.image_width, "image_height": cfg.image_height,
            "view_points_m": views, "view_pixels": pixels, "depth_renderer": renderer if cfg.views else "",
            "seed": int(seed)})
    return rows


def _lists(arrays: list, inner) -> "pyarrow.Array":  # noqa: F821
    """A list array of ``inner`` arrays built from a list of numpy arrays (rows of the list)."""
    import pyarrow as pa

    offsets = np.concatenate([[0], np.cumsum([len(a) for a in arrays])]).astype(np.int32)
    return pa.ListArray.from_arrays(pa.array(offsets), inner(arrays))


def _points(arrays: list, width: int = 3) -> "pyarrow.Array":  # noqa: F821
    import pyarrow as pa

    flat = (np.concatenate([np.asarray(a, np.float32).reshape(-1) for a in arrays]) if arrays
            else np.zeros(0, np.float32))
    return pa.FixedSizeListArray.from_arrays(pa.array(flat, pa.float32()), width)


def observation_table(rows: list[dict]) -> "pyarrow.Table":  # noqa: F821
    """The rows of `observe_object` as a table of the ``observations`` schema (no file metadata
    beyond the schema's name and version)."""
    import pyarrow as pa

    from schemas import arrow_schema

    schema = arrow_schema("observations")
    cols = {}
    for f in schema:
        values = [r[f.name] for r in rows]
        if f.name in ("surface_points_m", "surface_normals"):
            cols[f.name] = _lists(values, _points)
        elif f.name == "camera_poses":
            cols[f.name] = _lists(values, lambda a: _points(a, 7))
        elif f.name == "view_points_m":
            cols[f.name] = _lists(values, lambda views: _lists([v for vs in views for v in vs], _points))
        elif pa.types.is_fixed_size_list(f.type):
            cols[f.name] = _points(values, f.type.list_size)
        else:
            cols[f.name] = pa.array(values, f.type)
    return pa.Table.from_arrays([cols[f.name].cast(f.type) for f in schema], schema=schema)


def _gl_backend_loaded() -> str | None:
    """The offscreen backend this process's mujoco was imported with (None: not imported yet;
    "" another one, e.g. GLFW, which needs a display)."""
    if "mujoco" not in sys.modules:
        return None
    return next((b for b in ("egl", "osmesa") if f"mujoco.{b}" in sys.modules), "")


def _observe_step(entry: str, scales: list, cfg_dict: dict, seed: int, labels: dict, renderer: str) -> tuple:
    """`observe_object` in a worker (`call_isolated`): ``("ok", rows)``, ``("gl", why)`` when
    this worker's mujoco cannot render (imported before a backend was chosen), or
    ``("failed", message)``."""
    from .process import load_processed

    cfg = ObservationConfig.from_dict(cfg_dict)
    if cfg.views and renderer == "mujoco":
        loaded = _gl_backend_loaded()
        if loaded is not None and loaded != os.environ.get("MUJOCO_GL", "").lower():
            return ("gl", f"this worker's mujoco was imported with the GL backend {loaded or 'glfw'!r}")
    try:
        return ("ok", observe_object(load_processed(entry), scales, cfg, seed, renderer=renderer, **labels))
    except Exception as exc:  # noqa: BLE001 - a failure of this object, said in one line
        return ("failed", f"{type(exc).__name__}: {' '.join(str(exc).split())}")


def observe_isolated(processed, scales, cfg: ObservationConfig, seed: int, timeout_s: float, *,
                     object_id: str = "", object_path: str = "", split: str = "", mesh_sha256: str = "",
                     children=None) -> list[dict]:
    """`observe_object` in a worker interpreter killed after ``timeout_s`` (`isolate.call_isolated`:
    a renderer that hangs or crashes costs this object only). With views, the renderer is
    resolved first (`resolve_renderer`: for mujoco the GL backend, set in ``MUJOCO_GL`` for the
    worker; `datagen.gl.GLUnavailable` when ``renderer: mujoco`` and none works). Raises
    `ObservationError` (reason ``timeout``, ``crashed`` or ``error``) naming the object."""
    from . import isolated_worker
    from .isolate import IsolatedFailure, call_isolated

    object_id = object_id or processed.object_id
    renderer = resolve_renderer(cfg.renderer) if cfg.views else ""
    labels = {"object_id": object_id, "object_path": object_path, "split": split, "mesh_sha256": mesh_sha256}
    args = (str(processed.entry), [float(s) for s in scales], cfg.to_dict(), int(seed), labels, renderer)
    try:
        kind, reply = call_isolated(_observe_step, args, timeout_s, what="observation", children=children,
                                    remedy="raise object_timeout_s and rerun")
        if kind == "gl":  # idle workers older than the backend choice: ended; one started now has it
            isolated_worker.close_idle()
            kind, reply = call_isolated(_observe_step, args, timeout_s, what="observation", children=children,
                                        remedy="raise object_timeout_s and rerun", fresh=True)
    except IsolatedFailure as exc:
        raise ObservationError(exc.reason, f"{object_id}: {exc.detail}") from None
    if kind != "ok":
        raise ObservationError("error", f"{object_id}: observations: {reply}")
    return reply
