"""Energy terms of the synthesis objective (paper Sec. IV-C), each ``(B,)`` per hand pose.

``E = w_t E_task + w_d E_dist + w_p E_pen + w_s E_self + w_j E_joint``:

* ``E_task``: the cosine task energy of :func:`datagen.wrench.task_energy`, averaged over the K
  directions, on the task fingertips' nearest object points and inward normals; for a
  two-finger task at gamma = 180 deg plus ``cfg.pinch_antipodal`` times the pinch's antipodal
  error (:func:`datagen.wrench.pinch_antipodal_error`, not in the paper);
* ``E_dist``: ``sum_i d_i^2`` (m^2), ``d_i`` the signed gap between fingertip ``i``'s contact
  sphere (the distal-link collision sphere nearest the pad point) and the object: the same
  sphere the penetration term pushes out, so the two terms agree on where contact is;
* ``E_pen``: ``sum_s max(0, r_s - d(c_s))^2`` (m^2), hand collision spheres against the object's
  SDF grid (exact mesh distances are kept for the few fingertip contacts), plus the same against
  a mounted task object's static scenery (`datagen.synth.scenery`);
* ``E_self``: summed squared overlap of the self-collision sphere pairs (m^2);
* ``E_joint``: summed joint-limit violation (rad).

The penetration terms are squared hinges: a plain hinge has a kink exactly where the hand
touches the object, its gradient there ignores the obstacle, and a line search stalls on it
(every step that closes a finger crosses the kink). Squared hinges are C1, so poses slide
along contact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from datagen.synth.links import LinkContacts, link_contacts
from datagen.synth.penetration import sphere_penetration
from datagen.synth.scenery import Scenery
from datagen.synth.self_collision import SelfPairList, self_overlap_energy
from datagen.synth.stacked import grid_query
from datagen.wrench import pinch_antipodal_error
from datagen.wrench.tws import task_wrench_at_contacts

__all__ = ["EnergyTerms", "HandObjectState", "evaluate_state"]


@dataclass
class HandObjectState:
    """Everything the terms read, computed once per evaluation (B hand poses)."""

    tips: torch.Tensor  # (B, F, 3) centres of the task fingertips' contact spheres, m
    tip_distance: torch.Tensor  # (B, F) signed gap between contact sphere and object, m
    contact_points: torch.Tensor  # (B, F, 3) nearest object points, m
    contact_normals: torch.Tensor  # (B, F, 3) inward unit normals
    sphere_penetration: torch.Tensor  # (B,) summed squared sphere penetration, m^2
    max_penetration: torch.Tensor  # (B,) deepest sphere penetration, m
    self_penetration: torch.Tensor  # (B,) summed squared pair overlap, m^2
    joint_violation: torch.Tensor  # (B,) rad
    links: LinkContacts | None = None  # a grasp type's extra contact links (palm, phalanges), L of them
    link_pull: torch.Tensor | None = None  # (L,) bool: pulled onto the surface by E_dist (else GWS candidates only)


@dataclass
class EnergyTerms:
    """Unweighted terms ``(B,)`` and the weighted total."""

    task: torch.Tensor
    distance: torch.Tensor
    penetration: torch.Tensor
    self_penetration: torch.Tensor
    joint_limits: torch.Tensor
    total: torch.Tensor
    link_distance: torch.Tensor | None = None  # a grasp type's pulled links' summed squared gap, m^2

    def as_dict(self) -> dict[str, torch.Tensor]:
        out = {k: getattr(self, k) for k in ("task", "distance", "penetration", "self_penetration", "joint_limits", "total")}
        if self.link_distance is not None:
            out["link_distance"] = self.link_distance
        return out


def _query_targets(targets, object_index: torch.Tensor, points: torch.Tensor, exact: bool = True):
    """SDF of per-sample objects: points ``(B, N, 3)`` -> distance ``(B, N)``, closest, normal.

    ``exact=False`` uses the objects' SDF grids (fast, ~0.2 mm) instead of the exact mesh.
    """
    if not exact:
        stacked = grid_query(targets, object_index, points)  # one call for all targets (same values)
        if stacked is not None:
            return stacked
    B, N, _ = points.shape
    dist = points.new_zeros(B, N)
    closest = torch.zeros_like(points)
    normal = torch.zeros_like(points)
    for k, target in enumerate(targets):
        sel = (object_index == k).nonzero().squeeze(-1)
        if sel.numel() == 0:
            continue
        if exact:
            res = target.query(points[sel])
            d, c, n = res.distance, res.closest, res.normal
        else:
            d, c, n = target.approx_query(points[sel])
        dist = dist.index_copy(0, sel, d.to(points.dtype))
        closest = closest.index_copy(0, sel, c.to(points.dtype))
        normal = normal.index_copy(0, sel, n.to(points.dtype))
    return dist, closest, normal


def contact_sphere_index(hand) -> torch.Tensor:
    """(F,) index of each fingertip's contact sphere: the one its spec names (`Fingertip.sphere`),
    else its link's sphere whose surface is nearest the pad point."""
    out = []
    for f, link in enumerate(hand.fingertip_link_index.tolist()):
        if hand.fingertip_spheres[f] is not None:
            out.append(torch.tensor(hand.fingertip_spheres[f], device=hand.sphere_link_index.device))
            continue
        cand = (hand.sphere_link_index == link).nonzero().squeeze(-1)
        if cand.numel() == 0:
            raise ValueError(f"hand {hand.name!r}: fingertip {hand.fingertip_names[f]!r} has no collision sphere on its link")
        gap = (hand.sphere_centres_local[cand] - hand.fingertip_points_local[f]).norm(dim=-1) - hand.sphere_radii[cand]
        out.append(cand[gap.abs().argmin()])
    return torch.stack(out)


def hand_object_state(hand, targets, object_index, root_pose, joints, tip_spheres,
                      exact_contacts: bool = True, sphere_margin: float = 0.0,
                      self_collision: bool = True, self_pairs: SelfPairList | None = None,
                      scenery: Scenery | None = None, links: torch.Tensor | None = None,
                      link_pull: torch.Tensor | None = None, pieces=None) -> HandObjectState:
    """FK, fingertip contacts and penetration for ``B`` poses (root ``(B, 7)``, joints ``(B, J)``).

    ``tip_spheres`` ``(F',)`` are the task fingertips' contact-sphere indices; ``exact_contacts``
    picks the exact mesh SDF (default) or the SDF grid for the contacts. ``sphere_margin`` (m) is
    how far collision spheres may sink into the object before they count as penetrating.
    ``self_collision=False`` skips the sphere-pair overlap (zero) when its weight is 0;
    ``self_pairs`` reuses its pair lists across calls on the same batch (an optimizer run);
    ``scenery``: static boxes the spheres must also stay out of (penetration terms);
    ``links`` ``(L,)``: a grasp type's extra contact links, the palm and phalanges, at their
    nearest points (`datagen.synth.links.link_contacts`); ``link_pull`` ``(L,)`` bool: those the
    distance term pulls; ``pieces``: the targets' convex pieces (`GraspTarget.pieces`, same
    order), each sphere's penetration the deeper of the surface's and the pieces' (None: the
    surface's).
    """
    T = hand.link_transforms(root_pose, joints)
    centres, radii = hand.spheres(root_pose, joints, transforms=T)
    centres_all, radii_all = centres, radii
    tips = centres[:, tip_spheres]
    d_c, closest, outward = _query_targets(targets, object_index, tips, exact=exact_contacts)
    d_tip = d_c - radii[tip_spheres]
    pen = sphere_penetration(targets, object_index, centres, radii - sphere_margin)  # (B, S) m
    if pieces is not None:  # what MuJoCo collides: the pieces stick out of a concave surface
        pen = torch.maximum(pen, sphere_penetration(pieces, object_index, centres, radii - sphere_margin))
    pen_sq = (pen * pen).sum(-1)
    if scenery is not None:
        env = scenery.penetration(object_index, centres, radii - sphere_margin)  # (B, S) m
        pen_sq = pen_sq + (env * env).sum(-1)
        pen = torch.maximum(pen, env)
    lo, hi = hand.joint_lower, hand.joint_upper
    violation = (torch.relu(joints - hi) + torch.relu(lo - joints)).sum(-1)
    return HandObjectState(
        tips=tips, tip_distance=d_tip, contact_points=closest, contact_normals=-outward,
        sphere_penetration=pen_sq, max_penetration=pen.amax(-1) if pen.shape[-1] else pen.sum(-1),
        self_penetration=(self_overlap_energy(hand, centres_all, radii_all, self_pairs, T[:, hand.palm_link])
                          if self_collision
                          else centres_all.new_zeros(centres_all.shape[0])),
        joint_violation=violation,
        links=(link_contacts(hand, targets, object_index, centres, radii, links)
               if links is not None and links.numel() else None),
        link_pull=link_pull,
    )


def task_origins(task, targets, object_index: torch.Tensor, cfg) -> torch.Tensor | None:
    """``(B, 3)`` m: each sample's object's centre of mass, where the task wrench acts
    (``cfg.task_wrench_at_com``), for a task with a sector (gamma < 180 deg) on free objects;
    None otherwise: force closure covers every wrench wherever it acts, and a mounted object's
    joint (`datagen.tasks.task_test_from_spec`) takes every load but the one along its motion."""
    if not cfg.task_wrench_at_com or task.gamma_deg >= 180 or cfg.weights.task <= 0:
        return None
    from datagen.tasks import task_object, task_test_from_spec

    if task_object(task) is not None:
        test = task_test_from_spec(task)
        if test is not None and test.joint != "free":
            return None
    com = torch.as_tensor(np.stack([t.centre_of_mass for t in targets]), dtype=torch.float64)
    return com.to(object_index.device)[object_index]


def contact_bounds(gap: torch.Tensor, cfg) -> torch.Tensor:
    """``(...)`` normal-force bound of an extra contact link in the GWS from its gap ``(...)`` m:
    1 when touching (gap at most ``-cfg.sphere_margin_m``, the sink the penetration term allows),
    falling linearly to 0 at ``cfg.link_activation_m`` beyond that."""
    return (1.0 - torch.relu(gap + cfg.sphere_margin_m) / cfg.link_activation_m).clamp(0.0, 1.0)


def contact_set(state: HandObjectState, cfg) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
    """``(points (B, m, 3), inward normals (B, m, 3), bounds (B, m) or None)``: the grasp's
    contacts for the GWS, the task fingertips (bound 1) then a grasp type's extra links (bound
    :func:`contact_bounds`); None: fingertips only, every bound 1."""
    if state.links is None:
        return state.contact_points, state.contact_normals, None
    tips = state.contact_points.new_ones(state.contact_points.shape[:2])
    return (torch.cat([state.contact_points, state.links.points], 1),
            torch.cat([state.contact_normals, state.links.normals], 1),
            torch.cat([tips, contact_bounds(state.links.gap, cfg)], 1))


def evaluate_state(state: HandObjectState, cfg, task, directions: torch.Tensor,
                   task_origin: torch.Tensor | None = None) -> EnergyTerms:
    """Weighted energy of a :class:`HandObjectState` for a task and K directions ``(K, 6)``.

    ``task_origin`` ``(B, 3)`` m: where the task wrench acts on each sample's object (its centre of
    mass, :func:`task_origins`); it is then moved to the contacts (:func:`task_wrench_at_contacts`).
    None: ``task.w_t`` as given, i.e. at the contact centroid under CPN.

    ``E_dist`` aims each contact sphere at a gap of ``-cfg.sphere_margin_m`` (sunk by the margin
    the penetration term allows, since the spheres overshoot the hand's collision shapes).
    """
    w = cfg.weights
    if cfg.sphere_margin_m is None:
        raise ValueError("evaluate_state needs a SynthConfig resolved for its hand (SynthConfig.for_hand)")
    points, normals, bounds = contact_set(state, cfg)
    if w.task > 0:
        w_t = list(task.w_t) if task_origin is None else task_wrench_at_contacts(
            task.w_t, points, task_origin.to(points.dtype), normalize=cfg.contact.normalize)
        e_task = cfg.contact.task_energy(points, normals, w_t, task.gamma_deg, directions,
                                         kind=cfg.task_energy_kind, weights=bounds) / directions.shape[0]
        if cfg.pinch_antipodal > 0 and task.gamma_deg >= 180 and state.contact_points.shape[-2] == 2:
            # a two-finger pinch: E_t cannot see how far its normals turn from its axis (wrench/antipodal.py)
            e_task = e_task + cfg.pinch_antipodal * pinch_antipodal_error(state.contact_points, state.contact_normals)
    else:
        e_task = state.tip_distance.new_zeros(state.tip_distance.shape[0])
    e_dist = ((state.tip_distance + cfg.sphere_margin_m) ** 2).sum(-1)
    e_link = e_dist.new_zeros(e_dist.shape)
    if state.links is not None and state.link_pull is not None and bool(state.link_pull.any()):
        e_link = ((state.links.gap[:, state.link_pull] + cfg.sphere_margin_m) ** 2).sum(-1)
    total = (w.task * e_task + w.distance * e_dist + w.link_distance * e_link + w.penetration * state.sphere_penetration
             + w.self_penetration * state.self_penetration + w.joint_limits * state.joint_violation)
    return EnergyTerms(e_task, e_dist, state.sphere_penetration, state.self_penetration, state.joint_violation, total,
                       link_distance=e_link if state.links is not None else None)
