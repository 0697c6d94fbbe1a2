"""Epsilon metrics (paper eq. 3): distance from the origin to the grasp wrench boundary.

``epsilon = min_{w in dW_g} |w|``. For a convex set containing the origin this equals the
minimum of the support function over unit directions, ``min_{|u|=1} h(u)``, and it is 0 when
the origin is on the boundary (the contacts are not force closure). The task version
``epsilon_t = min_{t in W_t} rho(t)`` (``rho`` the radial function of the GWS) equals
``min_u h(u) / max_{t in W_t} u.t`` over directions with a positive denominator.

Taking the smallest norm among sampled boundary points overestimates badly in 6-D (most of the
boundary is far from the origin). Here the minimum is refined: the best of ``num_samples``
uniform directions seed ``num_starts`` Riemannian subgradient descents on the 5-sphere, using
the exact support point ``s(u)``, which is the gradient of ``h``. The value returned is
recomputed with autograd enabled at the (detached) minimizer. The minimum usually sits where
some contact's term ``max(0, a_i + mu |t_i|)`` is at its kink, so plain Danskin (the gradient of
``h(u*)``) is wrong there; instead each kink term gets the weight ``lambda_i in [0, 1]`` that
makes ``u*`` stationary (a small box-constrained least-squares problem), and the gradient is
that of ``sum_i lambda_i (a_i + mu |t_i|)``: the saddle-point sensitivity of the min-max.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from datagen.wrench._geometry import safe_normalize
from datagen.wrench.gws import (
    _check_inputs,
    _local_queries,
    _mu_tensor,
    _torsion,
    boundary_from_matrix,
    grasp_matrix,
    sample_directions,
    support_from_matrix,
)
from datagen.wrench.cone import _rho
from datagen.wrench.tws import task_support_cosine

__all__ = ["EpsilonSearch", "epsilon_metric", "task_epsilon"]


@dataclass(frozen=True)
class EpsilonSearch:
    """Settings of the minimization over the 5-sphere (defaults reach <1% error in tests)."""

    num_samples: int = 2048  #: uniform seed directions
    num_starts: int = 8  #: descents started from the best seeds
    iters: int = 200  #: subgradient iterations per descent
    step0_rad: float = 0.15  #: first geodesic step
    step_final_rad: float = 1e-4  #: last geodesic step (geometric decay)
    zero_tol: float = 1e-4  #: epsilon below zero_tol * (largest sampled h) is reported as 0
    kink_tol: float = 2e-3  #: |a_i + mu|t_i|| below kink_tol * epsilon marks a contact at its kink
    seed: int = 0  #: seed of the sampled directions when no generator is passed

    def __post_init__(self):
        if self.num_samples < 1 or self.num_starts < 1 or self.iters < 0:
            raise ValueError(f"EpsilonSearch: counts must be positive, got {self}")
        if self.num_starts > self.num_samples:
            raise ValueError("EpsilonSearch: num_starts cannot exceed num_samples")
        if not 0 < self.step_final_rad <= self.step0_rad:
            raise ValueError("EpsilonSearch: need 0 < step_final_rad <= step0_rad")


#: (samples x seed directions x contacts) per chunk of the seed evaluation: bounds its memory
#: (float64, a few tensors of this size) while keeping each chunk large enough to be FLOP-bound
SEED_CHUNK_ELEMENTS = 1 << 22


def _minimize(points, normals, mu, *, normalize, contact_model, torsional_mu, search, generator, denom):
    """Minimize ``h(u) / denom(u)`` over unit ``u``; returns the minimizer ``(..., 6)``, the scale
    of ``h`` and the minimum found.

    Samples whose best seed direction is already at or below ``zero_tol`` x the scale are reported
    as 0 by the callers whatever the descent finds (it can only lower the minimum), so with one
    batch dimension they skip the descent (their minimizer is that seed direction)."""
    with torch.no_grad():
        p, n = points.detach(), normals.detach()
        G, scale = grasp_matrix(p, n, normalize=normalize, contact_model=contact_model)
        m = p.shape[-2]
        kw = dict(contact_model=contact_model, torsional_mu=torsional_mu, normalize=normalize)

        def objective_and_grad(u, G=G, scale=scale, rows=None):
            s = boundary_from_matrix(G, scale, u, mu, m, 0.0, **kw)  # exact support point = grad h
            h = (u * s).sum(-1)
            if denom is None:
                return h, s
            with torch.enable_grad():
                uu = u.detach().requires_grad_(True)
                c = denom(uu) if rows is None else denom(uu, rows)
                (gc,) = torch.autograd.grad(c.sum(), uu)
            valid = c > 1e-6
            c_safe = torch.where(valid, c, torch.ones_like(c))
            val = torch.where(valid, h / c_safe, torch.full_like(h, math.inf))
            grad = (s * c_safe[..., None] - h[..., None] * gc) / (c_safe**2)[..., None]
            return val, torch.where(valid[..., None], grad, torch.zeros_like(grad))

        gen = generator if generator is not None else torch.Generator().manual_seed(search.seed)
        seeds = sample_directions(search.num_samples, generator=gen, device=p.device, dtype=p.dtype)
        one_batch_dim = p.dim() == 3 and not (torch.is_tensor(mu) and mu.dim() > 0)

        if denom is not None:  # the task cosine of each seed direction, (K,) or per sample (B, K)
            c_seeds = denom(seeds)
            covered = c_seeds > 1e-6  # directions with a positive task cosine
            c_seeds = torch.where(covered, c_seeds, torch.ones_like(c_seeds))

        def starts(Gc, sc, part=slice(None)):  # the best seed directions of samples ``part``: (u, values, h's scale)
            h = support_from_matrix(Gc, sc, seeds, mu, m, **kw)  # (..., K): values only, no support points
            if denom is not None:  # a task cosine per sample (one task wrench each) or shared
                cov, cs = (covered[part], c_seeds[part]) if c_seeds.dim() > 1 else (covered, c_seeds)
            vals = h if denom is None else torch.where(cov, h / cs, torch.full_like(h, math.inf))
            best, idx = vals.topk(search.num_starts, dim=-1, largest=False)  # (..., S)
            u = seeds[idx] if seeds.dim() == 2 else torch.gather(seeds, -2, idx[..., None].expand(*idx.shape, 6))
            return u, best, h.amax(-1)

        rows_per_chunk = max(1, SEED_CHUNK_ELEMENTS // (search.num_samples * m))
        if one_batch_dim and p.shape[0] > rows_per_chunk:  # per sample, so chunks give the same values
            parts = [starts(G[i:i + rows_per_chunk], scale[i:i + rows_per_chunk], slice(i, i + rows_per_chunk))
                     for i in range(0, p.shape[0], rows_per_chunk)]
            u, best, h_scale = (torch.cat(x) for x in zip(*parts))
        else:
            u, best, h_scale = starts(G, scale)
        best_u, best_v = u.clone(), best
        if one_batch_dim:
            rows = (best_v.amin(-1) > search.zero_tol * h_scale).nonzero().squeeze(-1)
            if rows.numel() < p.shape[0]:  # descend only where the minimum can still be > 0
                if rows.numel():
                    Gr, sr = G[rows], scale[rows]
                    ur, vr = _descend(lambda x: objective_and_grad(x, Gr, sr, rows), u[rows], best_u[rows], best_v[rows],
                                      search)
                    best_u, best_v = best_u.index_copy(0, rows, ur), best_v.index_copy(0, rows, vr)
                return _best(best_u, best_v, h_scale)
        best_u, best_v = _descend(objective_and_grad, u, best_u, best_v, search)
        return _best(best_u, best_v, h_scale)


def _descend(objective_and_grad, u, best_u, best_v, search: EpsilonSearch):
    """Riemannian subgradient descents from the starts ``u (..., S, 6)``; the best point and value
    of each start, ``best_u (..., S, 6)``, ``best_v (..., S)`` (updated from the given ones)."""
    decay = (search.step_final_rad / search.step0_rad) ** (1.0 / max(search.iters, 1))
    step = search.step0_rad
    for _ in range(search.iters):
        val, grad = objective_and_grad(u)
        better = val < best_v
        best_v = torch.where(better, val, best_v)
        best_u = torch.where(better[..., None], u, best_u)
        g_r = grad - (grad * u).sum(-1, keepdim=True) * u
        u = safe_normalize(u - step * safe_normalize(g_r))
        step *= decay
    val, _ = objective_and_grad(u)
    better = val < best_v
    return torch.where(better[..., None], u, best_u), torch.where(better, val, best_v)


def _best(best_u, best_v, h_scale):
    """The best start of each sample: ``(u* (..., 6), h_scale (...), minimum (...))``."""
    k = best_v.argmin(dim=-1, keepdim=True)
    u_star = torch.gather(best_u, -2, k[..., None].expand(*k.shape, 6)).squeeze(-2)
    return u_star, h_scale, torch.gather(best_v, -1, k).squeeze(-1)


def epsilon_metric(
    points: torch.Tensor,
    normals: torch.Tensor,
    mu,
    *,
    normalize: bool = True,
    contact_model: str = "pcf",
    torsional_mu: float = 0.0,
    search: EpsilonSearch = EpsilonSearch(),
    generator: torch.Generator | None = None,
    return_direction: bool = False,
):
    """Epsilon metric: distance from the origin to the grasp wrench boundary, ``(...)``.

    Args:
        points: ``(..., m, 3)`` contact positions, metres, object frame.
        normals: ``(..., m, 3)`` inward unit normals.
        mu: friction coefficient (float or batch-shaped tensor).
        normalize: contact position normalization (wrenches then dimensionless).
        contact_model, torsional_mu: as :func:`datagen.wrench.grasp_wrench_boundary`.
        search: settings of the sphere minimization.
        generator: source of the seed directions (default: ``search.seed``).
        return_direction: also return the minimizing direction ``u* (..., 6)``, the outward
            normal of the GWS at its point closest to the origin (the weakest wrench).
    Returns:
        ``(...)`` epsilon (exactly 0 for sets that are not force closure), differentiable with
        respect to points and normals; with ``return_direction``, ``(epsilon, u*)``.
    """
    _check_inputs(points, normals, mu, contact_model, torsional_mu)
    u_star, h_scale, best = _minimize(
        points, normals, mu, normalize=normalize, contact_model=contact_model,
        torsional_mu=torsional_mu, search=search, generator=generator, denom=None,
    )
    eps = _stationary_value(points, normals, mu, u_star, best, None, normalize, contact_model, torsional_mu, search)
    eps = torch.where(best > search.zero_tol * h_scale, eps, torch.zeros_like(eps))
    return (eps, u_star) if return_direction else eps


def task_epsilon(
    points: torch.Tensor,
    normals: torch.Tensor,
    mu,
    w_t,
    gamma_deg,
    *,
    normalize: bool = True,
    contact_model: str = "pcf",
    torsional_mu: float = 0.0,
    search: EpsilonSearch = EpsilonSearch(),
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Task epsilon ``epsilon_t`` of eq. 3: the smallest GWS radius over the TWS sector, ``(...)``.

    ``epsilon_t = min_{t in W_t(w_t, gamma)} max{q : q t in GWS}``; 0 when some task direction
    is not covered by the GWS. ``gamma_deg = 180`` gives :func:`epsilon_metric`. ``w_t``: ``(6,)``,
    or ``(B, 6)`` one per sample of points ``(B, m, 3)``.
    """
    _check_inputs(points, normals, mu, contact_model, torsional_mu)

    w_rows = torch.is_tensor(w_t) and w_t.dim() > 1  # one task wrench per sample

    def denom(u, rows=None):  # rows: the samples u belongs to (a subset of the batch)
        return task_support_cosine(u, w_t[rows] if rows is not None and w_rows else w_t, gamma_deg)

    u_star, h_scale, best = _minimize(
        points, normals, mu, normalize=normalize, contact_model=contact_model,
        torsional_mu=torsional_mu, search=search, generator=generator, denom=denom,
    )
    c = task_support_cosine(u_star[..., None, :].detach(), w_t, gamma_deg).squeeze(-1).clamp_min(1e-6)
    eps = _stationary_value(points, normals, mu, u_star, best * c, (w_t, gamma_deg), normalize, contact_model,
                            torsional_mu, search) / c
    return torch.where(best > search.zero_tol * h_scale, eps, torch.zeros_like(eps))


def _contact_terms(points, normals, mu, u, normalize, contact_model, torsional_mu):
    """Per-contact support terms ``phi_i = a_i + rho_i`` at directions ``u (..., 6)``: ``(..., m)``."""
    G, scale = grasp_matrix(points, normals, normalize=normalize, contact_model=contact_model)
    q = _local_queries(G, u[..., None, :].to(G.dtype), points.shape[-2]).squeeze(-3)  # (..., m, c)
    mu_q = _mu_tensor(mu, q[..., None, :, 0]).squeeze(-2) if torch.is_tensor(mu) and mu.dim() else _mu_tensor(mu, q)
    if contact_model == "sfc":
        mu_tor = _torsion(torsional_mu, scale, normalize, q).squeeze(-1)
        return q[..., 0] + _rho(q[..., 1:3], q[..., 3], mu_q, mu_tor)
    return q[..., 0] + _rho(q[..., 1:3], None, mu_q, 0.0)


def _stationary_value(points, normals, mu, u_star, value, task, normalize, contact_model, torsional_mu, search):
    """``sum_i lambda_i phi_i(u*)`` with kink weights that make ``u*`` stationary, ``(...)``.

    Equals ``h(u*)`` up to the kink terms (each ~0); its gradient with respect to points and
    normals is the sensitivity of the minimum. ``value`` is the minimum found (for the
    kink tolerance); ``task`` is ``(w_t, gamma_deg)`` for the task metric (``h / c`` objective).
    """
    kw = dict(normalize=normalize, contact_model=contact_model, torsional_mu=torsional_mu)
    u = u_star.detach()
    with torch.no_grad():
        with torch.enable_grad():
            uu = u.clone().requires_grad_(True)
            phi = _contact_terms(points.detach(), normals.detach(), mu, uu, **kw)  # (..., m)
            grads = torch.stack(
                [torch.autograd.grad(phi[..., i].sum(), uu, retain_graph=True)[0] for i in range(phi.shape[-1])], -2
            )  # (..., m, 6): grad_u phi_i
            if task is not None:
                c = task_support_cosine(uu[..., None, :], *task).squeeze(-1)
                (gc,) = torch.autograd.grad(c.sum(), uu)
                # stationarity of h/c: grad h - (h/c) grad c must be parallel to u
                extra = -(value / c.detach().clamp_min(1e-6))[..., None] * gc
            else:
                extra = torch.zeros_like(u)
        phi = phi.detach()
        tol = search.kink_tol * value.clamp_min(1e-12)[..., None]
        active = (phi > tol).to(phi.dtype)
        kink = (phi.abs() <= tol).to(phi.dtype)
        proj = lambda v: v - (v * u[..., None, :] if v.dim() > u.dim() else v * u).sum(-1, keepdim=True) * (
            u[..., None, :] if v.dim() > u.dim() else u)
        A = proj(grads)  # (..., m, 6) tangential gradients
        b = proj((active[..., None] * grads).sum(-2) + extra)  # (..., 6) fixed part
        lam = torch.full_like(phi, 0.5) * kink
        lipschitz = (A * A).sum((-1, -2)).clamp_min(1e-30)[..., None]
        for _ in range(200):  # projected gradient on 0.5 |b + sum_j lam_j A_j|^2 over the box
            r = b + (lam[..., None] * A).sum(-2)
            lam = ((lam - (A * r[..., None, :]).sum(-1) / lipschitz).clamp(0.0, 1.0)) * kink
        weights = active + lam
    phi_live = _contact_terms(points, normals, mu, u, **kw)
    return (weights * phi_live).sum(-1)
