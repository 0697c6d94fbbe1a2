"""Collision-sphere fitting: a small set of spheres per link covering its collision surface.

Each candidate centre c is an interior point with depth d(c) (distance to the surface, from
`geometry.union_depth`); its radius is d(c) + overshoot. The ball of radius d(c) lies inside the
geometry, so the sphere reaches at most ``overshoot`` beyond it, anywhere. Candidates are medial
points: for sampled surface points p with outward normal n, the centre p - rho n of the largest
inscribed ball touching p (and two smaller ones on the same ray). A (lazy) greedy set cover then
picks spheres until ``coverage`` of the surface samples is covered or ``max_spheres_per_link`` is
hit; rounds of new candidates are seeded from the samples still uncovered.
"""

from __future__ import annotations

import heapq

import numpy as np
from scipy.spatial import cKDTree

from .geometry import Shape, sample_link_surface, union_depth
from .spec import SphereFitConfig

__all__ = ["fit_link_spheres", "sphere_coverage"]

_COVER_MARGIN = 0.0003  # m: a sample counts as covered during the fit only this far inside a sphere
_SAMPLE_AREA = 1.0e-6  # m^2 of surface per sample on large links (1 sample per mm^2)
_MAX_SAMPLES = 30000


def _medial_radius(shapes: list[Shape], p: np.ndarray, n: np.ndarray, r_max: float) -> np.ndarray:
    """(N,) largest rho <= r_max with the ball B(p - rho n, rho) inside the geometry (bisection)."""
    lo = np.zeros(len(p))
    hi = np.full(len(p), r_max)
    for _ in range(20):
        mid = (lo + hi) / 2
        inside = union_depth(shapes, p - mid[:, None] * n) >= mid * (1 - 1e-3) - 1e-7
        lo = np.where(inside, mid, lo)
        hi = np.where(inside, hi, mid)
    return lo


def sphere_coverage(spheres: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) bool: point (N, 3) lies in at least one sphere (S, 4) [x, y, z, r]."""
    if len(spheres) == 0:
        return np.zeros(len(points), dtype=bool)
    d2 = (points**2).sum(1)[:, None] + (spheres[:, :3] ** 2).sum(1)[None, :] - 2 * points @ spheres[:, :3].T
    return np.any(d2 <= (spheres[None, :, 3] + 1e-9) ** 2, axis=1)


def fit_link_spheres(shapes: list[Shape], config: SphereFitConfig, rng: np.random.Generator) -> np.ndarray:
    """(S, 4) spheres [x, y, z, r] in the link frame (m) covering the union of ``shapes``.

    Surface samples: at least ``config.samples_per_link``, more for large links (one per
    ``_SAMPLE_AREA``, at most ``_MAX_SAMPLES``). Lazy greedy set cover over sparse cover lists.
    """
    if not shapes:
        return np.zeros((0, 4))
    area = sum(s.mesh.area for s in shapes)
    n_samples = int(np.clip(area / _SAMPLE_AREA, config.samples_per_link, _MAX_SAMPLES))
    points, normals = sample_link_surface(shapes, n_samples, rng)
    tree = cKDTree(points)
    extent = float(np.max(np.ptp(np.concatenate([s.mesh.bounds for s in shapes]), axis=0)))
    uncovered = np.ones(len(points), dtype=bool)
    centres_all, radii_all, covers = [], [], []
    heap: list[tuple[int, int]] = []
    chosen: list[int] = []
    for _ in range(8):  # candidate rounds, each seeded from the points still uncovered
        todo = np.flatnonzero(uncovered)
        if len(todo) == 0:
            break
        probe = rng.choice(todo, size=min(len(todo), 1000), replace=False)
        rho = _medial_radius(shapes, points[probe], normals[probe], extent)
        centres = np.concatenate([points[probe] - f * rho[:, None] * normals[probe] for f in (1.0, 0.6, 0.3)])
        depth = union_depth(shapes, centres)
        ok = depth > 1e-6
        centres, radii = centres[ok], depth[ok] + config.overshoot
        reach = np.maximum(radii - _COVER_MARGIN, 0.5 * radii)  # robust to gaps between samples
        for c, r, q in zip(centres, radii, reach):
            idx = np.asarray(tree.query_ball_point(c, q), dtype=np.int64)
            k = len(covers)
            centres_all.append(c)
            radii_all.append(r)
            covers.append(idx)
            gain = int(uncovered[idx].sum())
            if gain:
                heapq.heappush(heap, (-gain, k))
        while heap and len(chosen) < config.max_spheres_per_link and uncovered.mean() > 1 - config.coverage:
            neg, k = heapq.heappop(heap)
            gain = int(uncovered[covers[k]].sum())
            if gain == 0:
                continue
            if heap and gain < -heap[0][0]:  # stale: re-queue with its current gain
                heapq.heappush(heap, (-gain, k))
                continue
            chosen.append(k)
            uncovered[covers[k]] = False
        if len(chosen) >= config.max_spheres_per_link or uncovered.mean() <= 1 - config.coverage:
            break
    if not chosen:
        return np.zeros((0, 4))
    return np.concatenate([np.asarray(centres_all)[chosen], np.asarray(radii_all)[chosen, None]], axis=1)
