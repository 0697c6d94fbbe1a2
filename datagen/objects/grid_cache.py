"""Content-addressed cache of the distance grids of a surface: the SDF grid
(:class:`~datagen.objects.grid_sdf.GridSDF`) and the exact SDF's candidate-culling grid
(:class:`~datagen.objects.sdf.MeshSDF`), one of each per surface and build parameters.

A grid is in normalized units, so one grid serves every scale of an object (a signed distance
scales linearly with a uniform scale: sdf_s(x) = s * sdf_1(x / s)), every shard, CLI call and
job. The key is what determines the grid's values: the sha256 of the surface mesh's vertices
and faces (float64 / int64 bytes), the build parameters (resolution, margin, samples, seed,
dtype) and ``GRID_VERSION`` (bump it when ``GridSDF.from_mesh`` changes what it computes).

Layout: ``<root>/grids/<key[:2]>/<key>.npz`` with ``values`` (R, R, R), ``lo`` (3,), ``hi``
(3,) and ``check`` (the key and the sha256 of the three arrays' bytes). ``root`` is the objects
cache root (``$DATAGEN_CACHE``, ``~/.cache/datagen``). Written through ``datagen._atomic`` (a
reader sees no file or a complete one); a file that fails its check (shape, dtype, key or
digest) is rebuilt and replaced. A cache that cannot be written (read-only) only costs the
rebuild: the grid is still returned.

    grid, built = load_or_build(vertices, faces, resolution=64, root=None, exact=sdf)
    sdf, built = load_or_build_mesh_sdf(vertices, faces, root=None)

The MeshSDF's culling grid is stored compactly (``MeshSDF.candidate_grid``: each cell's
candidates up to its count, int32, compressed) under ``<root>/grids/<key[:2]>/<key>.sdf.npz``.
"""

from __future__ import annotations

import hashlib
import json
import logging
import time
from pathlib import Path

import numpy as np
import torch

from datagen._atomic import atomic_path

from .cache import cache_root
from .grid_sdf import GridSDF

log = logging.getLogger(__name__)

__all__ = ["GRID_VERSION", "grid_key", "grid_path", "load_grid", "load_or_build", "load_or_build_keyed",
           "load_or_build_mesh_sdf"]

GRID_VERSION = 1  #: bump when GridSDF.from_mesh computes different values for the same inputs


def grid_key(vertices, faces, *, resolution: int, margin: float, samples: int, seed: int,
             dtype: torch.dtype) -> str:
    """sha256 hex of the mesh ``(V, 3)`` / ``(T, 3)`` and the grid's build parameters."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(np.asarray(vertices, np.float64)).tobytes())
    h.update(b"|faces|")
    h.update(np.ascontiguousarray(np.asarray(faces, np.int64)).tobytes())
    params = {"version": GRID_VERSION, "resolution": int(resolution), "margin": float(margin),
              "samples": int(samples), "seed": int(seed), "dtype": str(dtype)}
    h.update(json.dumps(params, sort_keys=True).encode())
    return h.hexdigest()


def grid_path(root: str | Path | None, key: str) -> Path:
    """File of grid ``key`` under the cache ``root`` (None: ``$DATAGEN_CACHE`` or the default)."""
    return cache_root(root) / "grids" / key[:2] / f"{key}.npz"


def _digest(values: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in (values, lo, hi):
        h.update(str(a.dtype).encode() + str(a.shape).encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def load_grid(path: Path, key: str, resolution: int, dtype: torch.dtype) -> GridSDF | None:
    """The grid stored at ``path`` if it passes its check for ``key``, else None (with the reason logged)."""
    if not path.is_file():
        return None
    np_dtype = torch.empty((), dtype=dtype).numpy().dtype
    try:
        with np.load(path, allow_pickle=False) as z:
            values, lo, hi = z["values"], z["lo"], z["hi"]
            check = json.loads(str(z["check"]))
    except Exception as exc:  # noqa: BLE001 - any unreadable file is rebuilt
        log.warning("SDF grid %s unreadable (%s: %s); rebuilding it", path, type(exc).__name__, exc)
        return None
    problems = []
    if check.get("key") != key:
        problems.append("key differs")
    if values.shape != (resolution,) * 3 or lo.shape != (3,) or hi.shape != (3,):
        problems.append(f"shape {values.shape} != {(resolution,) * 3}")
    if values.dtype != np_dtype or lo.dtype != np_dtype or hi.dtype != np_dtype:
        problems.append(f"dtype {values.dtype} != {np_dtype}")
    if not problems and check.get("sha256") != _digest(values, lo, hi):
        problems.append("content digest differs")
    if problems:
        log.warning("SDF grid %s fails its check (%s); rebuilding it", path, "; ".join(problems))
        return None
    return GridSDF(torch.from_numpy(values.copy()), torch.from_numpy(lo.copy()), torch.from_numpy(hi.copy()))


def _store(path: Path, key: str, grid: GridSDF) -> None:
    values, lo, hi = (t.detach().cpu().numpy() for t in (grid.values, grid.lo, grid.hi))
    check = json.dumps({"key": key, "sha256": _digest(values, lo, hi)})
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, values=values, lo=lo, hi=hi, check=np.array(check))
    except OSError as exc:
        log.warning("SDF grid cache %s not written (%s); the grid will be rebuilt next time", path, exc)


def load_or_build(vertices, faces, *, resolution: int = 64, margin: float = 0.25, samples: int = 200_000,
                  seed: int = 0, dtype: torch.dtype = torch.float32, root: str | Path | None = None,
                  exact=None) -> tuple[GridSDF, bool]:
    """The grid of a closed mesh ``(V, 3)`` / ``(T, 3)`` in normalized units, from the cache under
    ``root`` or built (:meth:`GridSDF.from_mesh`, same parameters) and stored there.

    Returns ``(grid, built)``: ``built`` is True when it was computed here. ``exact``: a
    :class:`~datagen.objects.sdf.MeshSDF` of the same mesh, or a callable returning one (called
    only when the grid is built).
    """
    key = grid_key(vertices, faces, resolution=resolution, margin=margin, samples=samples, seed=seed, dtype=dtype)
    path = grid_path(root, key)
    grid = load_grid(path, key, resolution, dtype)
    if grid is not None:
        log.debug("SDF grid %s loaded from %s", key[:12], path)
        return grid, False
    t0 = time.perf_counter()
    grid = GridSDF.from_mesh(vertices, faces, resolution=resolution, margin=margin, samples=samples, seed=seed,
                             dtype=dtype, exact=exact() if callable(exact) else exact)
    log.info("SDF grid %s built in %.2f s (resolution %d)", key[:12], time.perf_counter() - t0, resolution)
    _store(path, key, grid)
    return grid, True


def load_or_build_keyed(key: str, resolution: int, dtype: torch.dtype, build, root: str | Path | None = None,
                        what: str = "grid") -> tuple[GridSDF, bool]:
    """A grid whose ``key`` the caller derived from everything that determines its values (and
    ``GRID_VERSION``), from the cache under ``root`` or ``build()`` (a `GridSDF` of ``dtype`` and
    resolution ``resolution``) and stored there, in this module's layout and checks. Returns
    ``(grid, built)``."""
    path = grid_path(root, key)
    grid = load_grid(path, key, resolution, dtype)
    if grid is not None:
        log.debug("%s %s loaded from %s", what, key[:12], path)
        return grid, False
    t0 = time.perf_counter()
    grid = build()
    log.info("%s %s built in %.2f s (resolution %d)", what, key[:12], time.perf_counter() - t0, resolution)
    _store(path, key, grid)
    return grid, True


def _sdf_key(vertices, faces, params: dict) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(np.asarray(vertices, np.float64)).tobytes())
    h.update(b"|faces|")
    h.update(np.ascontiguousarray(np.asarray(faces, np.int64)).tobytes())
    h.update(json.dumps({"kind": "mesh_sdf_candidates", "version": GRID_VERSION, **params}, sort_keys=True).encode())
    return h.hexdigest()


def load_or_build_mesh_sdf(vertices, faces, *, grid_resolution: int = 32, max_candidates: int = 128,
                           margin: float = 0.25, dtype: torch.dtype = torch.float32,
                           root: str | Path | None = None):
    """A :class:`~datagen.objects.sdf.MeshSDF` of the mesh ``(V, 3)`` / ``(T, 3)`` whose
    candidate-culling grid comes from the cache under ``root`` (or is built and stored).

    Returns ``(sdf, built)``; the SDF answers exactly as ``MeshSDF(vertices, faces, ...)`` does."""
    from .sdf import MeshSDF

    params = {"grid_resolution": int(grid_resolution), "max_candidates": int(max_candidates),
              "margin": float(margin), "dtype": str(dtype)}
    key = _sdf_key(vertices, faces, params)
    path = cache_root(root) / "grids" / key[:2] / f"{key}.sdf.npz"
    sdf = MeshSDF(vertices, faces, grid_resolution=0, dtype=dtype)
    if grid_resolution <= 0:
        return sdf, False
    if path.is_file():
        try:
            with np.load(path, allow_pickle=False) as z:
                g = {k: z[k] for k in ("counts", "cand", "lo", "cell_size")}
                check = json.loads(str(z["check"]))
            g["res"], g["max_candidates"] = int(check["res"]), int(check["max_candidates"])
            ok = (check.get("key") == key and check.get("sha256") == _digest(g["counts"], g["cand"], g["lo"])
                  and g["res"] == grid_resolution and g["max_candidates"] == max_candidates)
            if ok:
                sdf.set_candidate_grid(g)
                log.debug("exact-SDF culling grid %s loaded from %s", key[:12], path)
                return sdf, False
            log.warning("exact-SDF culling grid %s fails its check; rebuilding it", path)
        except Exception as exc:  # noqa: BLE001 - any unreadable or inconsistent file is rebuilt
            log.warning("exact-SDF culling grid %s unreadable (%s: %s); rebuilding it", path, type(exc).__name__, exc)
    t0 = time.perf_counter()
    sdf = MeshSDF(vertices, faces, grid_resolution=grid_resolution, max_candidates=max_candidates, margin=margin,
                  dtype=dtype)
    log.info("exact-SDF culling grid %s built in %.2f s", key[:12], time.perf_counter() - t0)
    g = sdf.candidate_grid()
    check = json.dumps({"key": key, "sha256": _digest(g["counts"], g["cand"], g["lo"]), "res": g["res"],
                        "max_candidates": g["max_candidates"]})
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, counts=g["counts"], cand=g["cand"], lo=g["lo"], cell_size=g["cell_size"],
                                check=np.array(check))
    except OSError as exc:
        log.warning("exact-SDF culling grid %s not written (%s); it will be rebuilt next time", path, exc)
    return sdf, True
