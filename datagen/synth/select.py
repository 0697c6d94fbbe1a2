"""Choosing among the seeds of a multi-start synthesis (``SynthConfig.seeds_per_grasp``).

Whether a pose ends in force closure is settled when its fingers first touch the object (in the
first ~50 iterations; later iterations refine contacts but rarely change the closure), so every
seed runs the first ``seed_select_iter`` iterations and the most promising seed of each grasp
goes on. Promising means, for force closure, the largest epsilon of the contacts the *whole*
hand makes: every link with a collision sphere within ``gap_m`` of the surface contributes its
deepest sphere's nearest surface point and normal. On the real-object set that epsilon separates
the grasps that hold in MuJoCo from those that do not better than the fingertips' own epsilon
(AUC 0.85 vs 0.76 on 224 Shadow grasps; benchmarks/results/quality.md), because phalanges and the
palm also take load once the hand closes. Other tasks (gamma < 180 deg) keep, when the task
energy is on (``weights.task > 0``), the seed whose whole-hand contacts resist the task best: the
task epsilon (eq. 3, the smallest GWS radius over the TWS sector) of the same link contacts. With
the task energy off (the paper's baseline) nothing task-specific is used, for force closure's
sphere (the precision grasps) as for a sector: the lowest energy wins.

With ``seed_max_depth_m`` (a grasp type's setting) a seed whose deepest collision sphere sinks
further than that into the object's surface ranks below every seed that does not, whatever its
epsilon: a fingertip pushed through a thin wall (a mug's, from the claw's start) reads contacts on
both sides of it, scores the highest epsilon of its grasp's seeds, and stays there (E3M5's mug at
0.08 m on a table: 7 of 16 seeds 13-14 mm deep after 120 iterations, two of them chosen, 13 mm
deep at the end; benchmarks/results/tabletop.md).
"""

from __future__ import annotations

import torch

from datagen.synth.energies import _query_targets, hand_object_state
from datagen.wrench import epsilon_metric, task_epsilon
from datagen.wrench.tws import task_wrench_at_contacts

__all__ = ["DEEP_PENALTY", "best_seeds", "link_contacts", "link_epsilon", "seed_scores", "top_seeds"]

#: subtracted from the score of a seed deeper than ``seed_max_depth_m``: more than any epsilon
#: (<= 2 x 1e3 here) or energy term can add, so it ranks below every seed that is not
DEEP_PENALTY = 1e6


def link_contacts(hand, targets, index: torch.Tensor, root: torch.Tensor, joints: torch.Tensor,
                  gap_m: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per link, its collision sphere nearest the object and that sphere's contact.

    root ``(B, 7)``, joints ``(B, J)`` (coupled). Returns ``points (B, L, 3)`` m (nearest surface
    points), ``normals (B, L, 3)`` inward unit, ``touching (B, L)`` bool (sphere within ``gap_m`` of
    the surface, or inside it), for the L links that carry spheres."""
    centres, radii = hand.spheres(root, joints)
    dist, closest, outward = _query_targets(targets, index, centres, exact=False)
    gap = dist - radii  # (B, S)
    links = hand.sphere_link_index.unique()
    member = hand.sphere_link_index[None, :] == links[:, None]  # (L, S)
    big = torch.finfo(gap.dtype).max
    gap_l, pick = torch.where(member[None], gap[:, None, :], torch.full_like(gap[:, None, :], big)).min(-1)  # (B, L)
    rows = torch.arange(gap.shape[0], device=gap.device)[:, None]
    return closest[rows, pick], -outward[rows, pick], gap_l <= gap_m


def link_epsilon(points: torch.Tensor, normals: torch.Tensor, touching: torch.Tensor, mu: float, *,
                 task: tuple | None = None, task_origin: torch.Tensor | None = None, **kw) -> torch.Tensor:
    """(B,) epsilon of each sample's touching contacts (0 with fewer than two); ``kw`` as
    :func:`datagen.wrench.epsilon_metric`; ``task = (w_t, gamma_deg)``: the task epsilon
    (:func:`datagen.wrench.task_epsilon`) instead, with ``task_origin`` ``(B, 3)`` m the point
    ``w_t`` acts at (:func:`datagen.wrench.tws.task_wrench_at_contacts`; None: the contacts'
    centroid). Samples are batched by their number of contacts."""
    count = touching.sum(-1)
    eps = torch.zeros(points.shape[0], dtype=torch.float64, device=points.device)
    order = torch.argsort((~touching).to(torch.int8), dim=-1, stable=True)  # touching links first
    for m in count.unique().tolist():
        if m < 2:
            continue
        sel = (count == m).nonzero().squeeze(-1)
        idx = order[sel, :m]
        p = torch.gather(points[sel], 1, idx[..., None].expand(-1, -1, 3))
        n = torch.gather(normals[sel], 1, idx[..., None].expand(-1, -1, 3))
        if task is None:
            eps[sel] = epsilon_metric(p.double(), n.double(), mu, **kw)
            continue
        w_t = task[0] if task_origin is None else task_wrench_at_contacts(
            task[0], p.double(), task_origin[sel].double(), normalize=kw.get("normalize", True))
        eps[sel] = task_epsilon(p.double(), n.double(), mu, w_t, task[1], **kw)
    return eps


def seed_scores(hand, targets, seed_index: torch.Tensor, root: torch.Tensor, joints: torch.Tensor,
                energy: torch.Tensor, tip_spheres: torch.Tensor, task, cfg,
                task_origin: torch.Tensor | None = None) -> torch.Tensor:
    """``(N,)`` how promising each pose is (higher is better): with the task energy on, the
    whole-hand epsilon of poses whose task fingertips are in contact -- force closure's (gamma 180
    deg), or the task epsilon over the task's TWS sector -- ties (e.g. none covering it) broken by
    the lower energy; with the task energy off: minus the energy; with ``cfg.seed_max_depth_m``,
    poses with a sphere deeper than that in the object lowered by `DEEP_PENALTY`. ``root (N, 7)``,
    ``joints (N, J)`` coupled, ``energy (N,)``; ``seed_index (N,)`` each pose's target;
    ``task_origin`` ``(N, 3)``: where the task wrench acts (:func:`link_epsilon`)."""
    cfg = cfg.for_hand(hand)
    with torch.no_grad():
        score = -energy.clamp(-1e2, 1e2) / 1e3
        closure = task.gamma_deg >= 180
        scored = cfg.weights.task > 0 and tip_spheres.numel() >= (2 if closure else 1)
        tips = None
        if scored or cfg.seed_max_depth_m is not None:  # one hand-object state for both uses
            tips = hand_object_state(hand, targets, seed_index, root, joints, tip_spheres,
                                     sphere_margin=cfg.sphere_margin_m, self_collision=False)
        if scored:
            usable = tips.tip_distance.abs().amax(-1) <= cfg.contact_threshold_m
            p, n, touching = link_contacts(hand, targets, seed_index, root, joints, cfg.seed_contact_gap_m)
            # the epsilon of the usable poses only (the others' is not used): per pose, so the same values
            rows = usable.nonzero().squeeze(-1)
            eps = torch.zeros_like(score)
            if rows.numel():
                origin = None if closure or task_origin is None else task_origin[rows]
                eps = eps.index_copy(0, rows, link_epsilon(
                    p[rows], n[rows], touching[rows], cfg.contact.mu, normalize=cfg.contact.normalize,
                    task=None if closure else (task.w_t, task.gamma_deg), task_origin=origin).to(energy.dtype))
            score = score + 1e3 * eps
        if cfg.seed_max_depth_m is not None:
            score = torch.where(tips.max_penetration > cfg.seed_max_depth_m, score - DEEP_PENALTY, score)
        return score


def top_seeds(score: torch.Tensor, S: int) -> torch.Tensor:
    """``(B,)`` row of the best of each grasp's ``S`` seeds (rows ``b S .. b S + S - 1`` of
    ``score (B S,)``)."""
    return score.reshape(-1, S).argmax(-1) + torch.arange(score.shape[0] // S, device=score.device) * S


def best_seeds(hand, targets, seed_index: torch.Tensor, root: torch.Tensor, joints: torch.Tensor,
               energy: torch.Tensor, tip_spheres: torch.Tensor, task, cfg, S: int) -> torch.Tensor:
    """(B,) row of the best of each grasp's ``S`` seeds by :func:`seed_scores`."""
    return top_seeds(seed_scores(hand, targets, seed_index, root, joints, energy, tip_spheres, task, cfg), S)
