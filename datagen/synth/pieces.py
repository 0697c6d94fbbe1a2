"""The object's convex pieces as a distance grid: the geometry MuJoCo collides the hand with.

Synthesis measures penetration against the object's watertight surface; the evaluation (and its
penetration metric) collides the hand with the convex pieces of the decomposition. Where the
surface is concave the pieces' hulls stick out of it (the real development objects at 0.12 m:
p90 2.0-2.3 mm, p99 4-5 mm of the pieces' surface outside the duck's, bunny's and a mug's
surface; benchmarks/results/sizes.md), so a pose that only touches the surface can sit millimetres
deep in a piece. With ``SynthConfig.penetration_pieces`` the penetration terms take, per collision
sphere, the deeper of the two (`datagen.synth.energies.hand_object_state`).

`pieces_grid` samples the signed distance of the pieces on the grid of the surface's `GridSDF`
(the same box and resolution, so the batch's grids stack): inside a piece, minus the largest
depth in any one piece (exact for convex pieces: the least distance to its face planes; MuJoCo's
penetration is per piece too); outside every piece, the distance to the nearest of dense samples on
the pieces' surfaces (their union's distance, to the sample spacing).
"""

from __future__ import annotations

import hashlib
import json
import threading
from collections import OrderedDict

import numpy as np
import torch
import trimesh
from scipy.spatial import cKDTree

from datagen._interrupt import sigint_deferred
from datagen.objects import grid_cache
from datagen.objects.grid_sdf import GridSDF

__all__ = ["piece_planes", "pieces_grid"]

_GRIDS: OrderedDict = OrderedDict()  # (piece paths, box, resolution) -> GridSDF; the last few objects
_LOCK = threading.Lock()


def piece_planes(vertices: np.ndarray) -> np.ndarray:
    """(P, 4) ``[n, b]`` of the convex hull of ``vertices (V, 3)``: inside where ``n . x <= b``."""
    hull = trimesh.convex.convex_hull(np.asarray(vertices, dtype=np.float64))
    n = hull.face_normals
    return np.concatenate([n, (n * hull.vertices[hull.faces[:, 0]]).sum(-1, keepdims=True)], axis=1)


def _signed_distance(hulls: list[trimesh.Trimesh], nodes: np.ndarray, samples: int, seed: int) -> np.ndarray:
    """(N,) signed distance of ``nodes (N, 3)`` to the convex ``hulls`` (see the module docstring)."""
    depth = np.full(len(nodes), -np.inf)
    for h in hulls:  # only the nodes in a piece's bounding box can be inside it
        lo, hi = h.vertices.min(0), h.vertices.max(0)
        sel = np.flatnonzero(((nodes >= lo) & (nodes <= hi)).all(axis=1))
        planes = piece_planes(h.vertices)
        d = (planes[:, 3] - nodes[sel] @ planes[:, :3].T).min(axis=1)
        depth[sel] = np.maximum(depth[sel], d)
    area = np.array([h.area for h in hulls])
    pts = [trimesh.sample.sample_surface(h, max(64, int(samples * a / area.sum())), seed=seed + i)[0]
           for i, (h, a) in enumerate(zip(hulls, area))]
    pts = np.concatenate(pts + [h.vertices for h in hulls])
    with sigint_deferred():  # as GridSDF.from_mesh: an interrupted query crashes the interpreter
        dist, _ = cKDTree(pts).query(nodes, k=1, workers=-1)
    return np.where(depth > 0, -depth, dist)


def _disk_key(paths, lo: np.ndarray, hi: np.ndarray, R: int, samples: int, seed: int, dtype: torch.dtype) -> str:
    """sha256 hex of the pieces' files (their bytes, in order) and the grid's box and parameters."""
    h = hashlib.sha256()
    for p in paths:
        with open(p, "rb") as fh:  # the processed object's own pieces (the objects cache), not a user's path
            h.update(hashlib.sha256(fh.read()).digest())
    params = {"kind": "pieces", "version": grid_cache.GRID_VERSION, "lo": lo.tolist(), "hi": hi.tolist(),
              "resolution": int(R), "samples": int(samples), "seed": int(seed), "dtype": str(dtype)}
    h.update(json.dumps(params, sort_keys=True).encode())
    return h.hexdigest()


def pieces_grid(paths, like: GridSDF, samples: int = 200_000, seed: int = 0, root=None) -> GridSDF:
    """The pieces' (OBJ files, normalized units) signed distance on ``like``'s box and resolution,
    in its dtype; kept for the last few objects (a job synthesizes an object at every scale) and,
    with ``root`` (an objects cache root), in that cache's grids (`datagen.objects.grid_cache`: the
    same values, 1.3-5.6 s CPU per object saved on a warm cache)."""
    R = like.values.shape[0]
    lo, hi = like.lo.detach().cpu().double().numpy(), like.hi.detach().cpu().double().numpy()
    key = (tuple(str(p) for p in paths), tuple(lo.round(9)), tuple(hi.round(9)), R, samples, seed, root)
    with _LOCK:
        hit = _GRIDS.get(key)
        if hit is not None:
            _GRIDS.move_to_end(key)
            return hit

    def build() -> GridSDF:
        hulls = [trimesh.convex.convex_hull(trimesh.load(p, force="mesh", process=False).vertices) for p in paths]
        axes = [np.linspace(lo[i], hi[i], R) for i in range(3)]
        nodes = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        values = torch.as_tensor(_signed_distance(hulls, nodes, samples, seed).reshape(R, R, R), dtype=like.values.dtype)
        return GridSDF(values, like.lo.detach().cpu().clone(), like.hi.detach().cpu().clone())

    if root is None:
        built = build()
    else:
        disk_key = _disk_key(paths, lo, hi, R, samples, seed, like.values.dtype)
        built, _ = grid_cache.load_or_build_keyed(disk_key, R, like.values.dtype, build, root, what="pieces grid")
    grid = GridSDF(built.values.to(like.values.device), like.lo.clone(), like.hi.clone())
    with _LOCK:
        _GRIDS[key] = grid
        while len(_GRIDS) > 4:
            _GRIDS.popitem(last=False)
    return grid
