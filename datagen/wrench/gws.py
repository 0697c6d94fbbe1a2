"""Grasp wrench space (GWS) boundary estimator (paper Sec. IV-A, eq. 4).

The support mapping of the GWS is the sum of the contacts' support mappings,

    s_Wg(u) = sum_i G_i s_Fi(G_i^T u),

with ``G_i`` the contact's 6x3 (PCF) or 6x4 (SFC) grasp matrix. Mapping ``K`` unit directions
gives ``K`` points on the grasp wrench boundary in ``O(K m)``. Both products with ``G`` are
batched matrix multiplications, so the cost is two GEMMs plus elementwise work on ``(..., K, m)``.

Conventions: ``points (..., m, 3)`` metres in the object frame; ``normals (..., m, 3)`` unit
vectors pointing INTO the object; wrenches are ``[force (3), torque (3)]``. With
``normalize=True`` (CPN) torques are taken about the contact centroid with positions divided
by their mean distance to it, so wrenches are dimensionless and frame invariant.
"""

from __future__ import annotations

import math

import torch

from datagen.wrench._geometry import normalize_contact_positions, safe_normalize, tangent_basis
from datagen.wrench.cone import MAX_DELTA_DEG, cone_support, cone_support_value

__all__ = ["CONTACT_MODELS", "boundary_from_matrix", "grasp_matrix", "grasp_wrench_boundary", "sample_directions",
           "support_from_matrix", "support_value"]

CONTACT_MODELS = ("pcf", "sfc")


def sample_directions(
    K: int,
    *,
    generator: torch.Generator | None = None,
    device: torch.device | str | None = None,
    dtype: torch.dtype | None = None,
) -> torch.Tensor:
    """``K`` directions uniform on the unit 5-sphere, ``(K, 6)``.

    Drawn as normalized standard normals on the generator's device (CPU by default) in
    float64, then cast, so a seeded generator gives the same directions on every device.
    """
    if K <= 0:
        raise ValueError(f"sample_directions: K must be positive, got {K}")
    gen_device = generator.device if generator is not None else torch.device("cpu")
    x = torch.randn(K, 6, generator=generator, device=gen_device, dtype=torch.float64)
    x = x / x.norm(dim=-1, keepdim=True).clamp_min(1e-300)
    return x.to(device=device if device is not None else gen_device, dtype=dtype or torch.get_default_dtype())


def _check_inputs(points: torch.Tensor, normals: torch.Tensor, mu, contact_model: str, torsional_mu: float):
    if points.shape[-1] != 3 or points.dim() < 2:
        raise ValueError(f"points must have shape (..., m, 3), got {tuple(points.shape)}")
    if normals.shape != points.shape:
        raise ValueError(f"normals {tuple(normals.shape)} must match points {tuple(points.shape)}")
    if contact_model not in CONTACT_MODELS:
        raise ValueError(f"contact_model must be one of {CONTACT_MODELS}, got {contact_model!r}")
    if torsional_mu < 0:
        raise ValueError(f"torsional_mu must be >= 0, got {torsional_mu}")
    if not torch.is_tensor(mu) and not (mu > 0):
        raise ValueError(f"friction coefficient mu must be positive, got {mu}")


def _mu_tensor(mu, ref: torch.Tensor) -> torch.Tensor:
    """mu as a tensor broadcastable to ``(..., K, m)`` (scalar or batch-shaped ``(...)``)."""
    m = torch.as_tensor(mu, dtype=ref.dtype, device=ref.device)
    return m[..., None, None] if m.dim() else m


def grasp_matrix(
    points: torch.Tensor,
    normals: torch.Tensor,
    *,
    normalize: bool = True,
    contact_model: str = "pcf",
    weights: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Stacked grasp matrices ``G = [G_1 ... G_m]`` and the CPN length scale.

    Args:
        points: ``(..., m, 3)`` contact positions, metres.
        normals: ``(..., m, 3)`` inward unit normals (renormalized here).
        normalize: apply contact position normalization first.
        contact_model: ``"pcf"`` (``G_i`` 6x3) or ``"sfc"`` (6x4, last column ``[0; n]``).
        weights: ``(..., m)`` >= 0, optional: each contact's normal-force bound (1: the paper's
            L-infinity bound; 0: the contact carries nothing, as if it were absent). ``G_i`` is
            scaled by it, so the GWS is the Minkowski sum of the cones scaled by their bounds;
            under CPN the centroid and length are the weighted means.
    Returns:
        ``(G (..., 6, m*c), scale (...))`` with ``c`` 3 or 4 columns per contact in the order
        ``(n, d, e[, torsion])``; ``scale`` is the CPN length in metres (1 without CPN).
    """
    n = safe_normalize(normals)
    if normalize:
        p, scale = normalize_contact_positions(points, weights)
    else:
        p, scale = points, torch.ones(points.shape[:-2], dtype=points.dtype, device=points.device)
    d, e = tangent_basis(n)
    forces = torch.stack([n, d, e], dim=-1)  # (..., m, 3, 3): columns n, d, e
    torques = torch.linalg.cross(p[..., None].expand_as(forces), forces, dim=-2)
    if contact_model == "sfc":
        zeros = torch.zeros_like(n)[..., None]
        forces = torch.cat([forces, zeros], dim=-1)
        torques = torch.cat([torques, n[..., None]], dim=-1)
    G = torch.cat([forces, torques], dim=-2)  # (..., m, 6, c)
    if weights is not None:
        G = G * weights.to(G.dtype)[..., None, None]
    m, c = G.shape[-3], G.shape[-1]
    G = G.movedim(-3, -2).reshape(*G.shape[:-3], 6, m * c)
    return G, scale


def _local_queries(G: torch.Tensor, directions: torch.Tensor, m: int) -> torch.Tensor:
    """``G_i^T u`` for every contact and direction: ``(..., K, m, c)``."""
    q = torch.matmul(directions, G)
    return q.reshape(*q.shape[:-1], m, q.shape[-1] // m)


def grasp_wrench_boundary(
    points: torch.Tensor,
    normals: torch.Tensor,
    directions: torch.Tensor,
    mu,
    *,
    delta_deg: float = 15.0,
    normalize: bool = True,
    contact_model: str = "pcf",
    torsional_mu: float = 0.0,
    weights: torch.Tensor | None = None,
) -> torch.Tensor:
    """Points on the grasp wrench boundary, ``s_Wg(u_k)`` for each direction (eq. 4).

    Args:
        points: ``(..., m, 3)`` contact positions, metres, object frame.
        normals: ``(..., m, 3)`` unit normals pointing into the object.
        directions: ``(K, 6)`` or ``(..., K, 6)`` unit directions ``u_k``.
        mu: friction coefficient (float, or tensor of batch shape ``(...)``).
        delta_deg: approximation angle of eq. 6, degrees; ``0`` is the exact eq. 5.
        normalize: contact position normalization (CPN).
        contact_model: ``"pcf"`` point contact with friction, ``"sfc"`` soft finger.
        torsional_mu: SFC torsional coefficient, metres (divided by the CPN scale when
            ``normalize`` so the model stays frame invariant).
        weights: ``(..., m)`` each contact's normal-force bound (see :func:`grasp_matrix`).
    Returns:
        ``(..., K, 6)`` boundary wrenches ``[f, tau]`` (dimensionless under CPN).
    """
    _check_inputs(points, normals, mu, contact_model, torsional_mu)
    if not 0.0 <= delta_deg <= MAX_DELTA_DEG:
        raise ValueError(f"delta_deg must lie in [0, {MAX_DELTA_DEG}], got {delta_deg}")
    G, scale = grasp_matrix(points, normals, normalize=normalize, contact_model=contact_model, weights=weights)
    return boundary_from_matrix(
        G, scale, directions, mu, points.shape[-2], math.radians(delta_deg),
        contact_model=contact_model, torsional_mu=torsional_mu, normalize=normalize,
    )


def boundary_from_matrix(
    G: torch.Tensor,
    scale: torch.Tensor,
    directions: torch.Tensor,
    mu,
    m: int,
    delta_rad: float,
    *,
    contact_model: str = "pcf",
    torsional_mu: float = 0.0,
    normalize: bool = True,
) -> torch.Tensor:
    """:func:`grasp_wrench_boundary` from a precomputed :func:`grasp_matrix` (``(..., K, 6)``).

    Lets iterative callers (the epsilon refinement) build ``G`` once.
    """
    q = _local_queries(G, directions.to(G.dtype), m)
    mu_q = _mu_tensor(mu, q)
    if contact_model == "sfc":
        mu_tor = _torsion(torsional_mu, scale, normalize, q)
        f = cone_support(q[..., 0], q[..., 1:3], mu_q, delta_rad, b=q[..., 3], mu_t=mu_tor)
    else:
        f = cone_support(q[..., 0], q[..., 1:3], mu_q, delta_rad)
    f = f.reshape(*f.shape[:-2], -1)  # (..., K, m*c)
    return torch.matmul(f, G.transpose(-1, -2))


def _torsion(torsional_mu: float, scale: torch.Tensor, normalize: bool, ref: torch.Tensor):
    if not normalize:
        return torsional_mu
    s = torch.where(scale > 0, scale, torch.ones_like(scale))
    return (torsional_mu / s)[..., None, None].to(ref.dtype)


def support_value(
    points: torch.Tensor,
    normals: torch.Tensor,
    directions: torch.Tensor,
    mu,
    *,
    normalize: bool = True,
    contact_model: str = "pcf",
    torsional_mu: float = 0.0,
) -> torch.Tensor:
    """Exact support function ``h(u) = max_{w in GWS} u.w = sum_i max(0, a_i + mu |t_i|)``.

    Same arguments as :func:`grasp_wrench_boundary`; returns ``(..., K)``. ``h`` is convex and
    positively homogeneous, and ``min_{|u|=1} h(u)`` is the epsilon metric.
    """
    _check_inputs(points, normals, mu, contact_model, torsional_mu)
    G, scale = grasp_matrix(points, normals, normalize=normalize, contact_model=contact_model)
    return support_from_matrix(G, scale, directions, mu, points.shape[-2], contact_model=contact_model,
                               torsional_mu=torsional_mu, normalize=normalize)


def support_from_matrix(
    G: torch.Tensor,
    scale: torch.Tensor,
    directions: torch.Tensor,
    mu,
    m: int,
    *,
    contact_model: str = "pcf",
    torsional_mu: float = 0.0,
    normalize: bool = True,
) -> torch.Tensor:
    """:func:`support_value` from a precomputed :func:`grasp_matrix`, ``(..., K)``: the values
    alone, without the support points (no cone geometry, no second product with ``G``)."""
    q = _local_queries(G, directions.to(G.dtype), m)
    mu_q = _mu_tensor(mu, q)
    if contact_model == "sfc":
        mu_tor = _torsion(torsional_mu, scale, normalize, q)
        h = cone_support_value(q[..., 0], q[..., 1:3], mu_q, b=q[..., 3], mu_t=mu_tor)
    else:
        h = cone_support_value(q[..., 0], q[..., 1:3], mu_q)
    return h.sum(-1)
