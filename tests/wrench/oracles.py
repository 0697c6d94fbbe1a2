"""Slow, independent references for the wrench tests (NumPy, Clarabel SOCP, Qhull).

Nothing here calls datagen: grasp maps are built from an SVD null-space tangent basis,
CPN is re-derived from its definition, and every GWS question is answered by a convex solver
or a convex hull.
"""

from __future__ import annotations

import clarabel
import numpy as np
from scipy import sparse
from scipy.spatial import ConvexHull


def cpn(points: np.ndarray) -> np.ndarray:
    c = points - points.mean(axis=0)
    return c / np.linalg.norm(c, axis=1).mean()


def contact_frames(normals: np.ndarray) -> np.ndarray:
    """(m, 3, 3) columns n, d, e with n = d x e, tangents from the SVD null space of n."""
    frames = []
    for n in normals:
        n = n / np.linalg.norm(n)
        _, _, vt = np.linalg.svd(n[None, :])
        d = vt[1]
        e = np.cross(n, d)
        frames.append(np.stack([n, d, e], axis=1))
    return np.array(frames)


def grasp_maps(points: np.ndarray, normals: np.ndarray, soft: bool = False) -> list[np.ndarray]:
    """Per-contact 6x3 (PCF) or 6x4 (SFC) maps from local force to object wrench."""
    maps = []
    for p, F in zip(points, contact_frames(normals)):
        top = F
        bottom = np.stack([np.cross(p, F[:, k]) for k in range(3)], axis=1)
        G = np.vstack([top, bottom])
        if soft:
            G = np.hstack([G, np.concatenate([np.zeros(3), F[:, 0]])[:, None]])
        maps.append(G)
    return maps


def _solve(P_cols: int, c: np.ndarray, rows: list, b: list, cones: list):
    A = sparse.csc_matrix(np.vstack(rows))
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = 1e-10
    settings.tol_feas = 1e-10
    solver = clarabel.DefaultSolver(sparse.csc_matrix((P_cols, P_cols)), c, A, np.concatenate(b), cones, settings)
    sol = solver.solve()
    return sol


def _cone_rows(maps, mu, mu_t, offset, n_vars, bounds=None):
    """Rows/cones of each contact's finite friction cone (0 <= f1 <= bound, 1 by default; SOC)."""
    rows, b, cones = [], [], []
    col = offset
    for i, G in enumerate(maps):
        c = G.shape[1]
        r = np.zeros((1, n_vars)); r[0, col] = 1.0  # f1 <= bound
        rows.append(r); b.append(np.full(1, 1.0 if bounds is None else float(bounds[i])))
        cones.append(clarabel.NonnegativeConeT(1))
        soc = np.zeros((c, n_vars))
        soc[0, col] = -1.0
        soc[1, col + 1] = -1.0 / mu
        soc[2, col + 2] = -1.0 / mu
        if c == 4:
            soc[3, col + 3] = -1.0 / mu_t
        rows.append(soc); b.append(np.zeros(c)); cones.append(clarabel.SecondOrderConeT(c))
        col += c
    return rows, b, cones


def radial_scale(maps, mu: float, w: np.ndarray, mu_t: float = 1.0) -> float:
    """max q such that q * w lies in the GWS (Minkowski sum of finite cones): an SOCP."""
    widths = [G.shape[1] for G in maps]
    n_vars = 1 + sum(widths)
    Gcat = np.hstack(maps)
    eq = np.zeros((6, n_vars)); eq[:, 0] = w; eq[:, 1:] = -Gcat
    rows, b, cones = [eq], [np.zeros(6)], [clarabel.ZeroConeT(6)]
    r2, b2, c2 = _cone_rows(maps, mu, mu_t, 1, n_vars)
    c = np.zeros(n_vars); c[0] = -1.0
    sol = _solve(n_vars, c, rows + r2, b + b2, cones + c2)
    if str(sol.status) not in ("Solved", "AlmostSolved"):
        raise RuntimeError(f"SOCP status {sol.status}")
    return float(sol.x[0])


def support_socp(maps, mu: float, u: np.ndarray, mu_t: float = 1.0, bounds=None) -> float:
    """max_{w in GWS} u.w by SOCP; ``bounds`` (m,): each contact's normal-force bound (None: 1)."""
    widths = [G.shape[1] for G in maps]
    n_vars = sum(widths)
    Gcat = np.hstack(maps)
    rows, b, cones = _cone_rows(maps, mu, mu_t, 0, n_vars, bounds)
    sol = _solve(n_vars, -(Gcat.T @ u), rows, b, cones)
    return float(-sol.obj_val)


def pyramid_hull_epsilon(maps, mu: float, d: int) -> float:
    """Epsilon of the L-inf GWS with each cone replaced by a d-edge pyramid (Qhull).

    Inscribed pyramids (rim radius mu) give a lower bound of the true epsilon; pyramids with
    rim radius mu / cos(pi / d) contain the cone and give an upper bound.
    """
    phis = 2 * np.pi * np.arange(d) / d
    verts = []
    for G in maps:
        local = np.stack([np.ones(d), mu * np.cos(phis), mu * np.sin(phis)], axis=1)
        v = np.vstack([np.zeros(6), local @ G[:, :3].T])
        verts.append(v)
    pts = verts[0]
    for v in verts[1:]:
        pts = (pts[:, None, :] + v[None, :, :]).reshape(-1, 6)
    hull = ConvexHull(pts)
    offsets = hull.equations[:, -1]  # n.x + off <= 0 inside
    return float(max(0.0, -offsets.max()))


def sample_surface_contacts(rng: np.random.Generator, m: int, kind: str = "sphere"):
    """m contacts on a unit-ish primitive (metres scaled to 5 cm) with inward normals."""
    if kind == "sphere":
        x = rng.normal(size=(m, 3)); x /= np.linalg.norm(x, axis=1, keepdims=True)
        return 0.05 * x, -x
    if kind == "box":
        half = np.array([0.04, 0.03, 0.05])
        faces = rng.integers(0, 6, size=m)
        p = rng.uniform(-1, 1, size=(m, 3)) * half
        n = np.zeros((m, 3))
        for i, f in enumerate(faces):
            ax, sgn = f // 2, 1 if f % 2 == 0 else -1
            p[i, ax] = sgn * half[ax]
            n[i, ax] = -sgn
        return p, n
    raise ValueError(kind)


def support_numpy(maps, mu: float, U: np.ndarray) -> np.ndarray:
    """h(u) for rows of U from the per-contact maps: sum_i max(0, a_i + mu |t_i|)."""
    h = np.zeros(len(U))
    for G in maps:
        q = U @ G[:, :3]
        h += np.maximum(0.0, q[:, 0] + mu * np.linalg.norm(q[:, 1:3], axis=1))
    return h


def epsilon_by_nelder_mead(maps, mu: float, rng: np.random.Generator, samples: int = 4000, starts: int = 24) -> float:
    """Independent epsilon: min of h(u)/|u| by scipy Nelder-Mead from the best random samples."""
    from scipy.optimize import minimize

    U = rng.normal(size=(samples, 6))
    U /= np.linalg.norm(U, axis=1, keepdims=True)
    h = support_numpy(maps, mu, U)
    best = float(h.min())
    for k in np.argsort(h)[:starts]:
        res = minimize(
            lambda x: support_numpy(maps, mu, (x / np.linalg.norm(x))[None])[0],
            U[k], method="Nelder-Mead", options=dict(xatol=1e-9, fatol=1e-10, maxiter=4000),
        )
        best = min(best, float(res.fun))
    return best


def sample_cap(rng: np.random.Generator, w: np.ndarray, gamma_rad: float, count: int) -> np.ndarray:
    """Unit vectors in the spherical cap of half-angle gamma around unit w (rim included)."""
    perp = rng.normal(size=(count, 6))
    perp -= (perp @ w)[:, None] * w
    perp /= np.linalg.norm(perp, axis=1, keepdims=True)
    ang = gamma_rad * np.sqrt(rng.uniform(size=count))
    ang[: count // 4] = gamma_rad
    return np.cos(ang)[:, None] * w + np.sin(ang)[:, None] * perp
