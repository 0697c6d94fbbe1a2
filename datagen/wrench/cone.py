"""Support mapping of one finite friction cone (paper eqs. 5, 6 and the appendix).

A contact's force set under the L-infinity bound is the cone of height 1 around the inward
normal ``c = (1, 0, 0)`` in contact-local coordinates ``(normal, tangent d, tangent e)``:

* PCF: ``{f : 0 <= f1 <= 1, f2^2 + f3^2 <= mu^2 f1^2}``;
* SFC: ``{f : 0 <= f1 <= 1, (f2^2 + f3^2) / mu^2 + f4^2 / mu_t^2 <= f1^2}``, ``f4`` the
  torsional moment about the normal.

Given a (not necessarily unit) query ``u'`` with normal part ``a``, tangential part ``t`` and,
for SFC, torsional part ``b``, the cone's support point is a combination of ``c`` and the rim
point ``v`` in the plane of ``c`` and ``u'`` (Cauchy-Schwarz):

    rho = sqrt(mu^2 |t|^2 + mu_t^2 b^2),  v = (1, mu^2 t / rho, mu_t^2 b / rho),
    theta = angle(c, u'),  alpha = angle(c, v) + pi/2   (= atan(mu) + pi/2 for PCF).

For SFC ``v`` is generally not in the plane of ``c`` and ``u'``; the angle ``theta`` is then
measured after projecting ``u'`` onto the plane of ``c`` and ``v``, which contains every candidate
support point, so the planar construction of the paper applies unchanged.

``delta = 0`` reproduces eq. 5 (``c`` at theta = 0, ``v`` for 0 < theta < alpha, the apex
otherwise); ``delta > 0`` is the interpolation of eq. 6. Both are written as

    f = s * (c + r * (v - c)),  r = clip(theta / delta, 0, 1),  s = clip((alpha - theta) / delta, 0, 1)

with ``r = [theta > 0]`` and ``s = [theta < alpha]`` in the limit ``delta = 0``. For SFC with
``mu_t = 0`` the result is exactly the PCF mapping.
"""

from __future__ import annotations

import math

import torch

from datagen.wrench._geometry import safe_norm, tiny_for

__all__ = ["MAX_DELTA_DEG", "cone_support", "cone_support_value"]

#: Largest accepted approximation angle. alpha >= 90 deg for every cone, so delta <= 45 deg
#: keeps the two interpolation bands of eq. 6 from overlapping.
MAX_DELTA_DEG = 45.0


def _rho(t: torch.Tensor, b: torch.Tensor | None, mu: torch.Tensor, mu_t) -> torch.Tensor:
    """Tangential reach ``max over the rim of (t, b) . v_tan`` per unit normal force."""
    if b is None:
        return mu * safe_norm(t, dim=-1)
    sq = mu * mu * (t * t).sum(-1) + (mu_t * mu_t) * b * b
    return sq.clamp_min(tiny_for(t.dtype) ** 2).sqrt()


def cone_support_value(
    a: torch.Tensor, t: torch.Tensor, mu: torch.Tensor, *, b: torch.Tensor | None = None, mu_t: float = 0.0
) -> torch.Tensor:
    """Exact support value ``max_{f in F} u'.f = max(0, a + rho)``.

    Args:
        a: ``(...)`` normal component of the query.
        t: ``(..., 2)`` tangential components.
        mu: friction coefficient, broadcastable to ``a``.
        b: ``(...)`` torsional component (SFC only).
        mu_t: torsional friction coefficient (SFC; same length unit as the contact positions).
    """
    return torch.relu(a + _rho(t, b, mu, mu_t))


def cone_support(
    a: torch.Tensor,
    t: torch.Tensor,
    mu: torch.Tensor,
    delta_rad: float,
    *,
    b: torch.Tensor | None = None,
    mu_t=0.0,
) -> torch.Tensor:
    """Support point of the finite friction cone, eq. 5 (``delta_rad = 0``) or eq. 6.

    Args:
        a: ``(...)`` normal component of the query ``u' = G^T u``.
        t: ``(..., 2)`` tangential components.
        mu: friction coefficient, broadcastable to ``a``.
        delta_rad: approximation angle, radians, in ``[0, pi/4]``.
        b: ``(...)`` torsional component (SFC) or ``None`` (PCF).
        mu_t: torsional friction coefficient (SFC).
    Returns:
        ``(..., 3)`` local force (PCF) or ``(..., 4)`` force and torsional moment (SFC).
    """
    if b is None:
        return _pcf_support(a, t, mu, delta_rad)
    tiny = tiny_for(a.dtype)
    rho = _rho(t, b, mu, mu_t)
    inv_rho = torch.where(rho > tiny, 1.0 / rho.clamp_min(tiny), torch.zeros_like(rho))
    v_t = (mu * mu * inv_rho)[..., None] * t  # (..., 2) rim point, tangential part
    # The support point lies in the plane spanned by c and v; theta is measured there, so the
    # 2-D picture of eq. 5/6 holds exactly (and reduces to PCF for mu_t = 0).
    v_b = (mu_t * mu_t) * inv_rho * b
    v_len = ((v_t * v_t).sum(-1) + v_b * v_b).clamp_min(tiny * tiny).sqrt()
    lateral = torch.where(v_len > tiny, rho / v_len, torch.zeros_like(rho))
    alpha = torch.atan(v_len) + math.pi / 2
    theta = torch.atan2(lateral.clamp_min(tiny), a.contiguous())  # see _pcf_support
    r, s = _weights(theta, alpha, delta_rad, tiny)
    return torch.cat([s[..., None], (s * r)[..., None] * v_t, (s * r * v_b)[..., None]], dim=-1)


def _weights(theta: torch.Tensor, alpha, delta_rad: float, tiny: float):
    """Interpolation weights ``r`` (towards the rim) and ``s`` (away from the apex) of eq. 6."""
    if delta_rad == 0.0:
        return (theta > tiny).to(theta.dtype), (theta < alpha).to(theta.dtype)
    inv = 1.0 / delta_rad
    return (theta * inv).clamp(0.0, 1.0), ((alpha - theta) * inv).clamp(0.0, 1.0)


def _pcf_support(a: torch.Tensor, t: torch.Tensor, mu, delta_rad: float) -> torch.Tensor:
    """PCF fast path: ``f = (s, s r mu t / |t|)`` with ``|t|`` floored (``t = 0`` gives ``f = (s, 0)``)."""
    tiny = tiny_for(a.dtype)
    t1, t2 = t[..., 0], t[..., 1]
    tn = (t1 * t1 + t2 * t2).clamp_min(tiny * tiny).sqrt()
    # a is usually a strided view (the normal component of (..., 3) queries): torch's atan2 runs
    # its scalar loop on strided input, ~10x slower than its vectorized one on a contiguous copy
    theta = torch.atan2(tn, a.contiguous())
    alpha = torch.atan(mu) + math.pi / 2 if torch.is_tensor(mu) else math.atan(mu) + math.pi / 2
    r, s = _weights(theta, alpha, delta_rad, tiny)
    k = s * r * mu / tn
    return torch.stack([s, k * t1, k * t2], dim=-1)
