"""Task wrench space (TWS) and the task-oriented energy (paper Sec. IV-B, eqs. 7-8).

The TWS is the hyper-spherical sector ``W_t(w_t, gamma) = {t : |t| = 1, angle(t, w_t) <= gamma}``.
``gamma = 180 deg`` is the whole sphere (force closure).
"""

from __future__ import annotations

import math

import torch

from datagen.wrench._geometry import normalize_contact_positions, safe_norm, safe_normalize, tiny_for
from datagen.wrench.gws import grasp_wrench_boundary

__all__ = ["TASK_ENERGY_KINDS", "task_wrench_support", "task_support_cosine", "task_energy", "task_wrench_at_contacts"]

TASK_ENERGY_KINDS = ("cos", "l2")


def _as_batch(x, ref: torch.Tensor) -> torch.Tensor:
    return torch.as_tensor(x, dtype=ref.dtype, device=ref.device)


def _sector_geometry(directions: torch.Tensor, w_t, gamma_deg):
    """Unit ``w`` (..., 1, 6), gamma (..., 1) radians, cos/sin of angle(u, w) (..., K)."""
    w = safe_normalize(_as_batch(w_t, directions))
    if w.shape[-1] != 6:
        raise ValueError(f"w_t must have shape (..., 6), got {tuple(w.shape)}")
    if float(safe_norm(w.detach()).min()) == 0.0:
        raise ValueError("w_t must be a non-zero 6-D wrench direction")
    gamma = torch.deg2rad(_as_batch(gamma_deg, directions))
    if bool(((gamma < 0) | (gamma > math.pi)).any()):
        raise ValueError(f"gamma_deg must lie in [0, 180], got {gamma_deg}")
    return w[..., None, :], gamma[..., None]


def task_wrench_at_contacts(w_t, points: torch.Tensor, origin: torch.Tensor, *, normalize: bool = True) -> torch.Tensor:
    """``(..., 6)`` unit task wrench ``w_t`` ``[f, tau]`` acting at ``origin`` ``(..., 3)`` m (e.g. the
    object's centre of mass, where a task test applies its disturbance), expressed in the
    coordinates of the grasp wrench space of contacts ``points`` ``(..., m, 3)`` m: with CPN
    (``normalize``) torques about the contact centroid ``c`` over the contacts' mean distance
    ``d`` from it, ``[f, (tau + (origin - c) x f) / d]``; without, torques about the frame origin,
    ``[f, tau + origin x f]``. A pure torque keeps its direction; a force gains the moment of its
    lever arm from the grasp, which the contacts must then resist as well.
    """
    w = safe_normalize(torch.as_tensor(w_t, dtype=points.dtype, device=points.device))
    w = w.expand(*points.shape[:-2], 6)
    f, tau = w[..., :3], w[..., 3:]
    if normalize:  # the grasp matrix's own CPN: its centroid and length (0 for coincident contacts)
        centre = points.mean(dim=-2)
        _, d = normalize_contact_positions(points)
        d = torch.where(d > 0, d, torch.ones_like(d))[..., None]
    else:
        centre, d = torch.zeros_like(origin), 1.0
    return safe_normalize(torch.cat([f, (tau + torch.linalg.cross(origin - centre, f)) / d], -1))


def task_support_cosine(directions: torch.Tensor, w_t, gamma_deg) -> torch.Tensor:
    """``max_{t in W_t} u.t`` for unit ``u``: ``cos(max(0, angle(u, w_t) - gamma))``, ``(..., K)``."""
    w, gamma = _sector_geometry(directions, w_t, gamma_deg)
    u = safe_normalize(directions)
    cos_phi = (u * w).sum(-1).clamp(-1.0, 1.0)
    sin_phi = safe_norm(u - cos_phi[..., None] * w)
    phi = torch.atan2(sin_phi, cos_phi)
    return torch.cos((phi - gamma).clamp_min(0.0))


def task_wrench_support(directions: torch.Tensor, w_t, gamma_deg) -> torch.Tensor:
    """Support mapping of the TWS sector (eq. 7 mapped as eq. 1), ``(..., K, 6)``.

    Inside the sector (``angle(u, w_t) <= gamma``) ``u`` maps to itself; outside, to the point
    of the sector's rim at angle ``gamma`` from ``w_t`` in the plane of ``u`` and ``w_t``.
    ``gamma = 180`` is the identity. For ``u = -w_t`` exactly (no defined plane) the rim point
    uses a fixed axis orthogonal to ``w_t``.

    Args:
        directions: ``(K, 6)`` or ``(..., K, 6)`` unit directions.
        w_t: ``(6,)`` or ``(..., 6)`` task wrench direction (normalized here).
        gamma_deg: sector half-angle, degrees, scalar or ``(...)``.
    """
    w, gamma = _sector_geometry(directions, w_t, gamma_deg)
    u = safe_normalize(directions)
    cos_phi = (u * w).sum(-1, keepdim=True).clamp(-1.0, 1.0)
    perp = u - cos_phi * w
    sin_phi = safe_norm(perp, keepdim=True)
    phi = torch.atan2(sin_phi, cos_phi)
    fallback = _orthogonal_axis(w).expand_as(perp)
    e = torch.where(sin_phi > tiny_for(u.dtype) * 1e3, perp / sin_phi.clamp_min(tiny_for(u.dtype)), fallback)
    g = gamma[..., None]
    rim = torch.cos(g) * w + torch.sin(g) * e
    return torch.where(phi <= g, u, rim)


def _orthogonal_axis(w: torch.Tensor) -> torch.Tensor:
    """A unit vector orthogonal to each unit ``w (..., 6)`` (Gram-Schmidt on the least-aligned axis)."""
    idx = w.abs().argmin(dim=-1, keepdim=True)
    axis = torch.zeros_like(w).scatter(-1, idx, 1.0)
    return safe_normalize(axis - (axis * w).sum(-1, keepdim=True) * w)


def task_energy(
    points: torch.Tensor,
    normals: torch.Tensor,
    mu,
    w_t,
    gamma_deg,
    directions: torch.Tensor,
    *,
    kind: str = "cos",
    delta_deg: float = 15.0,
    normalize: bool = True,
    contact_model: str = "pcf",
    torsional_mu: float = 0.0,
    weights: torch.Tensor | None = None,
) -> torch.Tensor:
    """Task-oriented energy ``E_t = -sum_k cos angle(s_Wt(u_k), s_Wg(u_k))`` (eq. 8), ``(...)``.

    ``kind="l2"`` is the paper's L2 ablation, ``sum_k |s_Wt(u_k) - s_Wg(u_k)|^2``. A GWS support
    point at the origin (the direction is not covered at all) contributes cosine 0 with a finite
    gradient. Arguments as :func:`grasp_wrench_boundary` (``weights (..., m)``: each contact's
    normal-force bound) and :func:`task_wrench_support`.
    """
    if kind not in TASK_ENERGY_KINDS:
        raise ValueError(f"kind must be one of {TASK_ENERGY_KINDS}, got {kind!r}")
    s_g = grasp_wrench_boundary(
        points, normals, directions, mu, delta_deg=delta_deg, normalize=normalize,
        contact_model=contact_model, torsional_mu=torsional_mu, weights=weights,
    )
    s_t = task_wrench_support(directions.to(s_g.dtype), w_t, gamma_deg)
    if kind == "l2":
        return ((s_t - s_g) ** 2).sum(-1).sum(-1)
    cos = (s_t * safe_normalize(s_g)).sum(-1)
    return -cos.sum(-1)
