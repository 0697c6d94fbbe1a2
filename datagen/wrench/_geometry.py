"""Small differentiable geometry helpers shared by the wrench modules.

Shape legend used throughout ``datagen.wrench``: ``...`` batch dimensions, ``m`` contacts,
``K`` sampled 6-D directions. Positions are in metres unless contact position normalization
(CPN) made them dimensionless.
"""

from __future__ import annotations

import torch

__all__ = ["tiny_for", "safe_norm", "safe_normalize", "tangent_basis", "normalize_contact_positions"]


def tiny_for(dtype: torch.dtype) -> float:
    """Smallest length treated as non-zero (~1e-16 in float32, ~1e-151 in float64).

    Its square is still a normal float, so squares and reciprocals stay finite.
    """
    return float(torch.finfo(dtype).tiny) ** 0.5 * 1e3


def _tiny(x: torch.Tensor) -> float:
    return tiny_for(x.dtype)


def safe_norm(x: torch.Tensor, dim: int = -1, keepdim: bool = False) -> torch.Tensor:
    """Euclidean norm with a finite (zero) gradient at ``x == 0``.

    The squared norm is clamped from below before the square root, so the value differs from
    the true norm only below ~1e-16 (float32) and the backward pass never divides by zero.
    """
    sq = (x * x).sum(dim=dim, keepdim=keepdim)
    return sq.clamp_min(_tiny(x) ** 2).sqrt()


def safe_normalize(x: torch.Tensor, dim: int = -1) -> torch.Tensor:
    """``x / |x|`` along ``dim``; zero vectors map to zero with finite gradients."""
    n = safe_norm(x, dim=dim, keepdim=True)
    return torch.where(n > _tiny(x), x / n, torch.zeros_like(x))


def tangent_basis(normals: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Two unit tangents ``(d, e)`` with ``n = d x e`` for unit normals ``(..., 3)``.

    Branchless construction (Frisvad's basis with the sign fix of Duff et al. 2017): smooth
    everywhere except across the plane ``n_z = 0``, where the basis rotates about ``n``. Every
    quantity the wrench code returns is invariant to that rotation, so values and gradients
    are continuous.
    """
    nx, ny, nz = normals.unbind(-1)
    sign = torch.where(nz >= 0, torch.ones_like(nz), -torch.ones_like(nz))
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    d = torch.stack([1.0 + sign * nx * nx * a, sign * b, -sign * nx], dim=-1)
    e = torch.stack([b, sign + ny * ny * a, -ny], dim=-1)
    return d, e


def normalize_contact_positions(points: torch.Tensor, weights: torch.Tensor | None = None
                                ) -> tuple[torch.Tensor, torch.Tensor]:
    """Contact position normalization (CPN, paper Sec. IV-A).

    ``p'_i = (p_i - mean_j p_j) / d`` with ``d = mean_i |p_i - mean_j p_j|``.

    Args:
        points: ``(..., m, 3)`` contact positions, metres.
        weights: ``(..., m)`` >= 0, optional: the means are weighted (a contact of weight 0 does
            not move the centroid or the scale: the normalization of the other contacts alone).
    Returns:
        ``(normalized (..., m, 3) dimensionless, d (...,) metres)``. Coincident contacts give
        ``d = 0`` and all-zero normalized positions (finite gradients).
    """
    if weights is None:
        centred = points - points.mean(dim=-2, keepdim=True)
        d = safe_norm(centred, dim=-1).mean(dim=-1)
    else:
        w = weights.to(points.dtype)
        total = w.sum(-1, keepdim=True).clamp_min(_tiny(points))  # (..., 1)
        centred = points - (w[..., None] * points).sum(-2, keepdim=True) / total[..., None]
        d = (w * safe_norm(centred, dim=-1)).sum(-1) / total[..., 0]
    scale = torch.where(d > _tiny(points), d, torch.ones_like(d))
    normalized = centred / scale[..., None, None]
    return normalized, torch.where(d > _tiny(points), d, torch.zeros_like(d))
