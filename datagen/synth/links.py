"""Contact candidates beyond the fingertips: the palm and the phalanges (power grasps).

A grasp type's contact set (`datagen.tasks.GraspType`) names link *roles*, derived here from the
hand's kinematic tree so that one YAML serves every hand:

* ``palm``: the palm link (where the object sits in a power grasp);
* ``phalanges``: every link with collision spheres on a fingertip's chain strictly between the
  palm and the fingertip link (Shadow: proximal and middle phalanges, the thumb's base and hub;
  Allegro: base, proximal, medial, distal; LEAP: the four links above each tip).

The palm and each phalanx are one contact candidate at their *nearest point*: of the link's collision spheres, the
one with the smallest gap to the object (sphere centre's signed distance minus its radius), its
nearest surface point and inward normal, as the whole-hand epsilon of the seed choice reads them
(`datagen.synth.select.link_contacts`). The choice of sphere is discrete (made without gradient);
the gap, point and normal of the chosen sphere are differentiable in the pose like a fingertip's.
(The palm frame's origin was tried as the palm's contact: pulled onto the object it brought the
palm within 1 mm of it in MuJoCo (median; the nearest sphere: 5 mm), but the grasps held less:
42% / 33% at 0.10 / 0.12 m on the Shadow hand against 69% / 44%, benchmarks/results/quality.md.)
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from datagen.synth.stacked import grid_distance

__all__ = ["LinkContacts", "contact_links", "finger_chains", "link_contacts"]


def finger_chains(hand) -> list[list[int]]:
    """Per fingertip (``hand.fingertip_names`` order), the links (``hand.link_names`` indices)
    with collision spheres on its chain strictly between the palm and the fingertip link, from the
    palm outwards."""
    m = hand.mj_model
    body_link = {i + 1: i for i in range(len(hand.link_names))}  # MuJoCo body id -> link index
    carries = set(hand.sphere_link_index.unique().tolist())
    palm_body = hand.palm_link + 1
    chains = []
    for tip in hand.fingertip_link_index.tolist():
        chain, body = [], int(m.body_parentid[tip + 1])
        while body > 0 and body != palm_body:
            link = body_link.get(body)
            if link is not None and link in carries:
                chain.append(link)
            body = int(m.body_parentid[body])
        chains.append(chain[::-1])
    return chains


def contact_links(hand, fingers: list[int] | None = None) -> list[int]:
    """Link indices of the phalanges (each finger's, from the palm outwards); ``fingers``: the
    fingertips whose chains count (None: all)."""
    out: list[int] = []
    for f, chain in enumerate(finger_chains(hand)):
        if fingers is None or f in fingers:
            out += [link for link in chain if link not in out]
    return out


@dataclass
class LinkContacts:
    """A grasp type's extra contacts for B poses: each link's nearest point, L in all."""

    gap: torch.Tensor  # (B, L) m, signed gap of the link's nearest sphere (< 0: sunk into the object)
    points: torch.Tensor  # (B, L, 3) m, nearest object points
    normals: torch.Tensor  # (B, L, 3) inward unit normals
    sphere: torch.Tensor  # (B, L) index of each link's chosen sphere (into the hand's spheres)


def _distances(targets, object_index: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """``(B, N)`` m: the distances ``GraspTarget.approx_query`` gives for points ``(B, N, 3)`` m
    (the stacked grids', else each target's ``distance``), without the six shifted grid samples
    per point it takes for the normals (LEAP's power synthesis: 10.0 of its 25.5 s CPU)."""
    d = grid_distance(targets, object_index, points)
    if d is not None:
        return d
    d = points.new_zeros(points.shape[:2])
    for k, target in enumerate(targets):
        sel = (object_index == k).nonzero().squeeze(-1)
        if sel.numel():
            d = d.index_copy(0, sel, target.distance(points[sel]).to(points.dtype))
    return d


def link_contacts(hand, targets, object_index: torch.Tensor, centres: torch.Tensor, radii: torch.Tensor,
                  links: torch.Tensor) -> LinkContacts:
    """:class:`LinkContacts` of ``links (L,)`` (hand link indices: the palm, phalanges) at their
    nearest spheres, given every sphere's centre ``(B, S, 3)`` m and radius ``(S,)`` m at the
    poses of ``object_index (B,)``. Distances are the objects' SDF grids' (``GraspTarget.approx_query``,
    ~0.2 mm near the surface)."""
    from datagen.synth.energies import _query_targets

    B = centres.shape[0]
    member = hand.sphere_link_index[None, :] == links[:, None]  # (L, S)
    cand = member.any(0).nonzero().squeeze(-1)  # spheres on any of the links
    with torch.no_grad():
        gap = _distances(targets, object_index, centres.detach()[:, cand]) - radii[cand]  # (B, S')
        big = torch.finfo(gap.dtype).max
        on = member[:, cand]  # (L, S')
        pick = torch.where(on[None], gap[:, None, :], torch.full_like(gap[:, None, :], big)).argmin(-1)  # (B, L)
        sphere = cand[pick]
    rows = torch.arange(B, device=centres.device)[:, None]
    chosen = centres[rows, sphere]  # (B, L, 3), differentiable
    dist, closest, outward = _query_targets(targets, object_index, chosen, exact=False)
    return LinkContacts(dist - radii[sphere], closest, -outward, sphere)
