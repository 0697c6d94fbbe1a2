"""Contact candidates beyond the fingertips: the palm and the phalanges (power grasps).

A grasp type's contact set (`datagen.tasks.GraspType`) names link *roles*, derived here from the
hand's kinematic tree so that one YAML serves every hand:

* ``palm``: the centre of the palm's face (the hand spec's palm frame origin), inward normal
  against the palm's approach axis: where the object sits in a power grasp;
* ``phalanges``: every link with collision spheres on a fingertip's chain strictly between the
  palm and the fingertip link (Shadow: proximal and middle phalanges, the thumb's base and hub;
  Allegro: base, proximal, medial, distal; LEAP: the four links above each tip).

Each phalanx is one contact candidate at its *nearest point*: of the link's collision spheres, the
one with the smallest gap to the object (sphere centre's signed distance minus its radius), its
nearest surface point and inward normal, as the whole-hand epsilon of the seed choice reads them
(`datagen.synth.select.link_contacts`). The choice of sphere is discrete (made without gradient);
the gap, point and normal of the chosen sphere are differentiable in the pose like a fingertip's.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from datagen.synth.stacked import grid_distance

__all__ = ["LinkContacts", "contact_links", "finger_chains", "link_contacts", "palm_centre_contact"]


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
    """A grasp type's extra contacts for B poses: the palm's (first, when it takes part) and
    each phalanx's nearest point, L in all."""

    gap: torch.Tensor  # (B, L) m, signed gap (< 0: sunk into the object): a phalanx's nearest sphere's; the palm
    #                    centre's distance minus the sphere margin (so the distance term aims it at the surface)
    points: torch.Tensor  # (B, L, 3) m, nearest object points
    normals: torch.Tensor  # (B, L, 3) inward unit normals
    sphere: torch.Tensor  # (B, L') index of each phalanx's chosen sphere (into the hand's spheres)
    palm: bool = False  # the first contact is the palm centre's


def palm_centre_contact(hand, targets, object_index: torch.Tensor, T: torch.Tensor, margin_m: float):
    """``(gap (B, 1), point (B, 1, 3), inward normal (B, 1, 3))`` of the palm centre (the palm
    frame's origin, on the palm's face) at link transforms ``T (B, links, 4, 4)``; the gap is its
    distance minus ``margin_m`` (the sink the distance term adds back)."""
    from datagen.synth.energies import _query_targets

    Tp = T[:, hand.palm_link]
    o = (Tp[:, :3, :3] @ hand.palm_local[0].to(T.dtype)) + Tp[:, :3, 3]  # (B, 3)
    d, c, n = _query_targets(targets, object_index, o[:, None], exact=False)
    return d - margin_m, c, -n


def link_contacts(hand, targets, object_index: torch.Tensor, centres: torch.Tensor, radii: torch.Tensor,
                  links: torch.Tensor | None, *, T: torch.Tensor | None = None, palm: bool = False,
                  margin_m: float = 0.0) -> LinkContacts:
    """:class:`LinkContacts`: with ``palm`` (needs the link transforms ``T``) the palm centre's
    (:func:`palm_centre_contact`), then the phalanges ``links (L,)`` at their nearest spheres,
    given every sphere's centre ``(B, S, 3)`` m and radius ``(S,)`` m at the poses of
    ``object_index (B,)``. Distances are the objects' SDF grids' (``GraspTarget.approx_query``,
    ~0.2 mm)."""
    from datagen.synth.energies import _query_targets

    B = centres.shape[0]
    first = palm_centre_contact(hand, targets, object_index, T, margin_m) if palm else None
    if links is None or links.numel() == 0:
        empty = torch.zeros(B, 0, dtype=torch.long, device=centres.device)
        return LinkContacts(*first, empty, palm=True)
    member = hand.sphere_link_index[None, :] == links[:, None]  # (L, S)
    cand = member.any(0).nonzero().squeeze(-1)  # spheres on any of the links
    with torch.no_grad():
        c = centres.detach()[:, cand]
        d = grid_distance(targets, object_index, c)
        if d is None:
            d = _query_targets(targets, object_index, c, exact=False)[0]
        gap = d - radii[cand]  # (B, S')
        big = torch.finfo(gap.dtype).max
        on = member[:, cand]  # (L, S')
        pick = torch.where(on[None], gap[:, None, :], torch.full_like(gap[:, None, :], big)).argmin(-1)  # (B, L)
        sphere = cand[pick]
    rows = torch.arange(B, device=centres.device)[:, None]
    chosen = centres[rows, sphere]  # (B, L, 3), differentiable
    dist, closest, outward = _query_targets(targets, object_index, chosen, exact=False)
    gap, normals = dist - radii[sphere], -outward
    if first is not None:
        gap, closest, normals = (torch.cat([a, b], 1) for a, b in zip(first, (gap, closest, normals)))
    return LinkContacts(gap, closest, normals, sphere, palm=palm)
