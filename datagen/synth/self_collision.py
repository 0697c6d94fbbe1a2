"""Self-collision energy ``E_self``: summed squared overlap (m^2) of the hand's self-collision
sphere pairs, per pose, with a broad phase that never changes the sum.

A hand spec lists sphere pairs that may not overlap (LEAP: 280k of them for 1312 spheres). Two
exact ways of skipping most of them:

* **Cluster bounds** (:func:`candidate_pairs`): each link's spheres are grouped in clusters of
  about four neighbours; a sphere pair is looked at only where the bounding spheres of its two
  clusters come within the asked margin, and (hands with many sphere pairs per cluster pair:
  LEAP, Allegro) only where each of its spheres comes within the margin of the other's cluster
  bound.
* **Pair lists reused across iterations** (:class:`SelfPairList`, the neighbour lists of
  molecular dynamics): the sphere pairs of a pose within ``skin_m`` of overlapping are kept, and
  reused as long as no sphere of that pose has moved more than ``skin_m / 2`` in the palm's frame
  since: a pair's gap shrinks by at most the sum of its two spheres' displacements, so every pair
  that overlaps is still in the list. A pose whose spheres moved further gets a new list. The
  optimizer moves fingers by up to ~4 mm per iteration at first and by well under 0.5 mm after
  ~50 iterations, so most iterations reuse the list. A pose that moves fast (its list would not
  outlive a few calls) gets a list of only the pairs that overlap now, for this call, at about
  half the cost of one within ``skin_m`` (LEAP: 0.61 against 1.17 s on recorded calls).

Either way the overlapping pairs are summed in the same order, (pose, cluster pair, pair), so the
energy is bit-identical to the all-pairs sum computed in that order.
"""

from __future__ import annotations

import torch

from datagen.scatter import index_add

__all__ = ["SelfPairList", "candidate_pairs", "farthest_point_seeds", "self_overlap_energy"]


def farthest_point_seeds(points: torch.Tensor, k: int) -> list[int]:
    """Indices of ``min(k, N)`` of ``points (N, 3)`` spread by farthest-point sampling from point 0
    (deterministic)."""
    seeds = [0]
    d = (points - points[0]).norm(dim=-1)
    while len(seeds) < min(k, points.shape[0]):
        seeds.append(int(d.argmax()))
        d = torch.minimum(d, (points - points[seeds[-1]]).norm(dim=-1))
    return seeds


def _sphere_clusters(link: torch.Tensor, local: torch.Tensor, size: int) -> torch.Tensor:
    """(S,) cluster id of each sphere: a link's spheres split into ``ceil(n / size)`` clusters
    around farthest-point seeds of their local centres (deterministic); ids are dense, per link."""
    out = torch.empty_like(link)
    nxt = 0
    for li in torch.unique(link).tolist():
        idx = (link == li).nonzero().squeeze(-1)
        c = local[idx]
        k = max(1, -(-idx.numel() // size))
        seeds = farthest_point_seeds(c, k)
        out[idx] = nxt + torch.cdist(c, c[seeds]).argmin(-1)
        nxt += k
    return out


#: the broad phase reads each cluster pair's centres when a hand has at most this many cluster pairs
#: per link pair, else it computes whole link-pair distance matrices (one ``cdist`` per link pair:
#: per-call overhead, but contiguous). One torch thread, 100 / 800 poses: Shadow (199 pairs in 88
#: link pairs) 1.27 -> 0.17 / 4.91 -> 1.32 ms; Allegro (2,863 in 101) 2.4 / 18.4 ms either way;
#: LEAP (20,665 in 96) 10.5 / 142 ms with matrices against 33 / 365 ms reading the pairs.
GATHER_GROUPS_PER_BLOCK = 8


#: the sphere-against-cluster probes (`_probed_pairs`) run where a hand's cluster pairs hold at
#: least this many sphere pairs per probe (a probe: one sphere of a cluster pair against the other
#: cluster), else every pair of a cluster-pair hit goes to the exact test (`_listed_pairs`).
#: Recorded calls of `datagen synth` on the duck, one thread, probes against pairs: LEAP (1.72
#: pairs per probe) 3.70 -> 2.53 s, Allegro (1.38) 1.18 -> 1.03 s; E3M5 (1.10) 0.34 -> 0.40 s,
#: Shadow (0.95) 0.14 -> 0.18 s (benchmarks/results/pipeline.md)
PROBE_MIN_PAIRS_PER_PROBE = 1.25


def _cluster_bounds(hand, cluster_size: int = 4) -> dict:
    """Broad-phase tables of the self-collision pairs, computed once per hand and kept on it.

    Each link's spheres are split into clusters of about ``cluster_size`` neighbouring spheres
    (4: LEAP 19.2 -> 1.9 ms per grasp-iteration, 8: 2.3, 16: 3.3, whole links: 19.2). A
    cluster's bounding sphere is centred at the mean of its sphere centres (a rigid motion of the
    link keeps that point the mean) with the radius enclosing every sphere of the cluster. A
    *group* is a cluster pair that has sphere pairs. Keys: ``cluster (S,)`` each sphere's cluster,
    ``count (C,)``; ``blocks``, the link pairs as cluster ranges ``(a0, a1, b0, b1)`` whose
    distance matrices, flattened one after another, ``perm (G,)`` reorders into the groups;
    ``reach (G,)`` the two bounding radii's sum (m); ``group_a``, ``group_b (G,)`` each group's
    two clusters, read directly where ``gather`` (`GATHER_GROUPS_PER_BLOCK`); ``sizes``,
    ``starts (G,)`` and ``order (P,)`` the sphere pairs of each group (CSR); ``rank (P,)`` each
    pair's position in the (group, pair) order in which overlaps are summed."""
    cached = getattr(hand, "_self_pair_bounds", None)
    if cached is not None and cached["order"].device == hand.self_collision_pairs.device:
        return cached
    dev = hand.self_collision_pairs.device
    local = hand.sphere_centres_local
    link = _sphere_clusters(hand.sphere_link_index.cpu(), local.cpu(), cluster_size).to(local.device)
    L = int(link.max()) + 1 if link.numel() else 1
    count = torch.bincount(link, minlength=L).clamp_min(1)
    mean = index_add(torch.zeros(L, 3, dtype=local.dtype, device=local.device), 0, link, local) / count[:, None]
    reach = (local - mean[link]).norm(dim=-1) + hand.sphere_radii
    radius = torch.zeros(L, dtype=local.dtype, device=local.device).scatter_reduce_(0, link, reach, "amax")
    pairs = hand.self_collision_pairs
    key = link[pairs[:, 0]] * L + link[pairs[:, 1]]
    uniq, group = torch.unique(key, return_inverse=True)
    order = torch.argsort(group, stable=True)
    sizes = torch.bincount(group, minlength=uniq.numel())
    rank = torch.empty_like(order)
    rank[order] = torch.arange(order.numel(), device=dev)
    ga, gb = (uniq // L).cpu(), (uniq % L).cpu()
    owner = torch.zeros(L, dtype=torch.long)  # each cluster's link
    owner[link.cpu()] = hand.sphere_link_index.cpu()
    lo = torch.full((int(owner.max()) + 1,), L, dtype=torch.long).scatter_reduce_(0, owner, torch.arange(L), "amin")
    hi = torch.zeros_like(lo).scatter_reduce_(0, owner, torch.arange(L) + 1, "amax")
    blocks, flat_of, offset = [], {}, 0
    for a, b in torch.unique(torch.stack([owner[ga], owner[gb]], -1), dim=0).tolist():
        blocks.append((int(lo[a]), int(hi[a]), int(lo[b]), int(hi[b])))
        flat_of[(a, b)] = offset
        offset += (hi[a] - lo[a]).item() * (hi[b] - lo[b]).item()
    perm = torch.tensor([flat_of[(int(owner[x]), int(owner[y]))] + (int(x) - int(lo[owner[x]])) * int(hi[owner[y]] - lo[owner[y]])
                         + int(y) - int(lo[owner[y]]) for x, y in zip(ga.tolist(), gb.tolist())], dtype=torch.long)
    out = {"cluster": link, "count": count, "blocks": blocks, "perm": perm.to(dev), "reach": radius[uniq // L] + radius[uniq % L],
           "group_a": (uniq // L).to(dev), "group_b": (uniq % L).to(dev),
           "gather": uniq.numel() <= GATHER_GROUPS_PER_BLOCK * len(blocks),
           "sizes": sizes, "starts": torch.cumsum(sizes, 0) - sizes, "order": order, "rank": rank,
           "end_a": pairs[order, 0], "end_b": pairs[order, 1],  # each pair's spheres, in (group, pair) order
           **{k: v.to(dev) for k, v in _member_tables(link.cpu(), radius.cpu(), pairs.cpu(), uniq.cpu()).items()}}
    out["probe"] = bool(sizes.sum() >= PROBE_MIN_PAIRS_PER_PROBE * out["probe_count"].sum())
    if not out["gather"]:
        out.update(_block_tables(blocks, owner.to(dev), mean, radius, count, perm.to(dev), out["reach"]))
    hand._self_pair_bounds = out
    return out


def _member_tables(cluster: torch.Tensor, radius: torch.Tensor, pairs: torch.Tensor, uniq: torch.Tensor) -> dict:
    """The sphere-against-cluster stage's tables (`_probed_pairs`). Each group (cluster pair
    ``(x, y)``) has *probes*: every sphere of x with y, then every sphere of y with x. Keys:
    ``probe_sphere``, ``probe_far`` (the other cluster), ``probe_second`` (a sphere of y) ``(Q,)``,
    each group's probes ``probe_start``, ``probe_count (G,)``; ``cluster_radius (C,)`` (m); and
    ``pair_key (P,)`` (``i S + j`` of each pair, sorted) with ``pair_of_key (P,)``, its pair."""
    S, L = cluster.numel(), radius.numel()
    members = torch.argsort(cluster, stable=True)  # the spheres by cluster
    count = torch.bincount(cluster, minlength=L)
    start = torch.cumsum(count, 0) - count
    x, y = uniq // L, uniq % L
    sides = []
    for side, (own, far) in enumerate(((x, y), (y, x))):  # each group's own cluster's spheres with the far one
        g, at = _expand(count[own], start[own])
        sides.append((g, members[at], far[g], torch.full_like(g, side, dtype=torch.bool)))
    g, sphere, far, second = (torch.cat(v) for v in zip(*sides))
    order = torch.argsort(g, stable=True)  # grouped, the first cluster's spheres first
    probes = torch.bincount(g, minlength=uniq.numel())
    key, pair_of_key = torch.sort(pairs[:, 0] * S + pairs[:, 1])
    return {"probe_sphere": sphere[order], "probe_far": far[order], "probe_second": second[order],
            "probe_count": probes, "probe_start": torch.cumsum(probes, 0) - probes,
            "cluster_radius": radius, "pair_key": key, "pair_of_key": pair_of_key}


def _block_tables(blocks, owner, mean, radius, count, perm, reach) -> dict:
    """The link-pair blocks' own tables for `_block_groups`: each cluster's link ``cluster_link
    (C,)`` and weight ``cluster_weight (C,)`` (its share of its link's spheres); each link's
    bounding sphere radius ``link_radius (K,)`` about the mean of its spheres (m, enclosing its
    clusters' bounding spheres); each block's two links ``block_a``, ``block_b (N,)``; and per
    block the group of each of its cells ``cell_group`` (list of ``(cells,)``, -1: no group) and
    the cell's bounding radii's sum ``cell_reach`` (-inf where no group: never a candidate)."""
    K = int(owner.max()) + 1
    n_link = torch.zeros(K, dtype=count.dtype, device=count.device).index_add_(0, owner, count)
    weight = (count / n_link[owner]).to(mean.dtype)  # the link mean is the clusters' weighted mean
    link_mean = index_add(torch.zeros(K, 3, dtype=mean.dtype, device=mean.device), 0, owner, mean * weight[:, None])
    link_radius = torch.zeros(K, dtype=mean.dtype, device=mean.device).scatter_reduce_(
        0, owner, (mean - link_mean[owner]).norm(dim=-1) + radius, "amax")
    total = sum((a1 - a0) * (b1 - b0) for a0, a1, b0, b1 in blocks)
    flat_group = torch.full((total,), -1, dtype=torch.long, device=perm.device)
    flat_group[perm] = torch.arange(perm.numel(), device=perm.device)
    flat_reach = torch.full((total,), -torch.inf, dtype=reach.dtype, device=reach.device)
    flat_reach[perm] = reach
    sizes = [(a1 - a0) * (b1 - b0) for a0, a1, b0, b1 in blocks]
    return {"cluster_link": owner, "cluster_weight": weight, "link_radius": link_radius,
            "block_a": torch.tensor([int(owner[a0]) for a0, _, _, _ in blocks], device=owner.device),
            "block_b": torch.tensor([int(owner[b0]) for _, _, b0, _ in blocks], device=owner.device),
            "cell_group": list(flat_group.split(sizes)), "cell_reach": list(flat_reach.split(sizes))}


#: taken off a link pair's bounding-sphere gap (m) before it culls the pair's block: rounding of
#: the link means in float32 is ~1e-8 m
_LINK_TOLERANCE_M = 1e-6


def _block_groups(t, centre: torch.Tensor, margin) -> tuple[torch.Tensor, torch.Tensor]:
    """``(b, g)``: the (pose, group) pairs whose clusters' bounding spheres come within ``margin``
    (m, a number or ``(B, 1)``) for cluster centres ``centre (B, C, 3)``, in (pose, group) order.
    Per link-pair block, only the poses where the two links' bounding spheres come that close
    (about 45% of LEAP's in a synthesis) compute the block's cluster distances; the gaps compared
    are those of the whole-block distance matrices."""
    B = centre.shape[0]
    link = torch.zeros(B, t["link_radius"].shape[0], 3, dtype=centre.dtype, device=centre.device)
    link = index_add(link, 1, t["cluster_link"], centre * t["cluster_weight"][:, None])
    ra, rb = t["link_radius"][t["block_a"]], t["link_radius"][t["block_b"]]
    lgap = (link.index_select(1, t["block_a"]) - link.index_select(1, t["block_b"])).norm(dim=-1) - ra - rb
    block, pose = (lgap - _LINK_TOLERANCE_M < margin).T.nonzero(as_tuple=True)  # by block, then pose
    per_pose = torch.is_tensor(margin) and margin.dim() > 0
    bs, gs = [], []
    counts = torch.bincount(block, minlength=len(t["blocks"])).tolist()
    for k, (poses, (a0, a1, b0, b1)) in enumerate(zip(pose.split(counts), t["blocks"])):
        if poses.numel() == 0:
            continue
        if poses.numel() < B:
            xa, xb = centre[:, a0:a1].index_select(0, poses), centre[:, b0:b1].index_select(0, poses)
        else:
            xa, xb = centre[:, a0:a1], centre[:, b0:b1]
        d = torch.cdist(xa, xb, compute_mode="donot_use_mm_for_euclid_dist").reshape(poses.numel(), -1)
        m = margin.index_select(0, poses) if per_pose else margin
        bb, cell = (d - t["cell_reach"][k] < m).nonzero(as_tuple=True)
        bs.append(poses.index_select(0, bb))
        gs.append(t["cell_group"][k].index_select(0, cell))
    if not bs:
        empty = torch.zeros(0, dtype=torch.long, device=centre.device)
        return empty, empty
    b, g = torch.cat(bs), torch.cat(gs)
    order = torch.argsort(b * t["reach"].shape[0] + g)  # keys are distinct
    return b.index_select(0, order), g.index_select(0, order)


def _dense_groups(t, centre: torch.Tensor, margin) -> tuple[torch.Tensor, torch.Tensor]:
    """`_block_groups`' ``(b, g)`` from every block's whole distance matrix, reordered into groups
    (one ``nonzero`` per call: on a GPU, one wait for the device instead of one per block)."""
    B = centre.shape[0]
    gap = torch.cat([torch.cdist(centre[:, a0:a1], centre[:, b0:b1], compute_mode="donot_use_mm_for_euclid_dist")
                     .reshape(B, -1) for a0, a1, b0, b1 in t["blocks"]], 1).index_select(1, t["perm"]) - t["reach"]
    return (gap < margin).nonzero(as_tuple=True)


def candidate_pairs(hand, centres: torch.Tensor, radii: torch.Tensor, margin_m: float | torch.Tensor = 0.0):
    """``(rows (n,), pair (n,))``: for each pose of ``centres (B, S, 3)`` (m), the self-collision
    sphere pairs (indices into ``hand.self_collision_pairs``) whose gap is below ``margin_m`` (m: a
    number, or one per pose ``(B,)``; 0: the overlapping pairs), ordered by (pose, cluster pair,
    pair). No gradient."""
    t = _cluster_bounds(hand)
    B, S = centres.shape[:2]
    with torch.no_grad():
        centres = centres.detach()
        per_pose = torch.is_tensor(margin_m)
        centre = torch.zeros(B, t["count"].shape[0], 3, dtype=centres.dtype, device=centres.device)
        centre = index_add(centre, 1, t["cluster"], centres) / t["count"][:, None].to(centres.dtype)
        if t["gather"]:  # few groups (Shadow: 199 in 88 link pairs): each group's two centres read directly
            gap = (centre.index_select(1, t["group_a"]) - centre.index_select(1, t["group_b"])).norm(dim=-1) - t["reach"]
            b, g = (gap < (margin_m[:, None] if per_pose else margin_m)).nonzero(as_tuple=True)
        elif centre.device.type == "cpu":  # many (LEAP: 20,665): link-pair blocks of distance matrices, culled
            b, g = _block_groups(t, centre, margin_m[:, None] if per_pose else margin_m)
        else:  # the same blocks whole, without one device sync per block (`_block_groups`' nonzero)
            b, g = _dense_groups(t, centre, margin_m[:, None] if per_pose else margin_m)
        margin = margin_m.index_select(0, b) if per_pose else margin_m
        if t["probe"]:
            return _probed_pairs(t, centres, centre, radii, b, g, margin)
        return _listed_pairs(t, centres, radii, b, g, margin)


def _listed_pairs(t, centres, radii, b, g, margin) -> tuple[torch.Tensor, torch.Tensor]:
    """`candidate_pairs`' ``(rows, pair)`` from its cluster-pair hits ``(b, g) (H,)``: every sphere
    pair of each hit through the exact gap test, in (pose, cluster pair, pair) order. ``centres
    (B, S, 3)`` (m); ``margin``: a number or one per hit (m)."""
    S = centres.shape[1]
    n = t["sizes"][g]
    rows = torch.repeat_interleave(b, n)
    # each candidate's place in the (group, pair) order; its spheres read from there directly
    at = torch.repeat_interleave(t["starts"][g] - (torch.cumsum(n, 0) - n), n) + torch.arange(rows.numel(),
                                                                                                device=rows.device)
    i, j = t["end_a"][at], t["end_b"][at]
    flat, base = centres.reshape(-1, 3), rows * S
    d = (flat.index_select(0, base + i) - flat.index_select(0, base + j)).norm(dim=-1)
    reach = (radii.index_select(0, t["end_a"]) + radii.index_select(0, t["end_b"]))[at]  # radii[i] + radii[j]
    near = d < reach + (torch.repeat_interleave(margin, n) if torch.is_tensor(margin) and margin.dim() > 0 else margin)
    return rows[near], t["order"][at[near]]


#: taken off a sphere's gap to another cluster's bounding sphere (m) before the sphere is dropped:
#: the posed cluster centre is the mean of posed sphere centres, equal to the rigidly moved local
#: mean up to float32 rounding (~1e-8 m at a hand's scale)
_SPHERE_TOLERANCE_M = 1e-6


def _probe_reach(t, radii: torch.Tensor) -> torch.Tensor:
    """(Q,) each probe's sphere radius plus its far cluster's bounding radius (m), kept for the
    ``radii`` tensor it was made from (the hand's own, call after call)."""
    prev = t.get("probe_radii")
    kind = (radii.dtype, radii.device, radii.shape)
    same = prev is radii or (prev is not None and (prev.dtype, prev.device, prev.shape) == kind and torch.equal(prev, radii))
    if not same:
        far = t["cluster_radius"].to(radii).index_select(0, t["probe_far"])
        t["probe_reach"] = radii.index_select(0, t["probe_sphere"]) + far
        t["probe_radii"] = radii
    return t["probe_reach"]


def _probed_pairs(t, centres, centre, radii, b, g, margin) -> tuple[torch.Tensor, torch.Tensor]:
    """``(rows, pair)`` of `candidate_pairs` from its cluster-pair hits ``(b, g) (H,)``. First each
    hit's probes: a sphere of either cluster farther than the margin from the other cluster's
    bounding sphere is within the margin of none of that cluster's spheres (they lie inside it),
    so only the pairs of two surviving spheres are candidates (of LEAP's cluster-pair candidates,
    4-7%); then their exact gap test; sorted into (pose, cluster pair, pair) order.
    ``centres (B, S, 3)``, ``centre (B, C, 3)``: the sphere and cluster centres (m); ``margin``: a
    number or one per hit (m)."""
    S, C, dev = centres.shape[1], centre.shape[1], b.device
    flat, cflat = centres.reshape(-1, 3), centre.reshape(-1, 3)
    per_hit = torch.is_tensor(margin) and margin.dim() > 0
    hit, q = _expand(t["probe_count"].index_select(0, g), t["probe_start"].index_select(0, g))
    sphere, pose = t["probe_sphere"].index_select(0, q), b.index_select(0, hit)
    far = t["probe_far"].index_select(0, q)
    d = (flat.index_select(0, pose * S + sphere) - cflat.index_select(0, pose * C + far)).norm(dim=-1)
    m = margin.index_select(0, hit) if per_hit else margin
    ok = d - _probe_reach(t, radii).index_select(0, q) - _SPHERE_TOLERANCE_M < m
    ok = ok.nonzero().squeeze(-1)
    second = t["probe_second"].index_select(0, q.index_select(0, ok))
    first, second = (~second).nonzero().squeeze(-1), second.nonzero().squeeze(-1)
    ha, sa = hit.index_select(0, ok.index_select(0, first)), sphere.index_select(0, ok.index_select(0, first))
    hb, sb = hit.index_select(0, ok.index_select(0, second)), sphere.index_select(0, ok.index_select(0, second))
    count_b = torch.bincount(hb, minlength=g.numel())
    # each survivor of a hit's first cluster meets the hit's survivors of the second
    e, at = _expand(count_b.index_select(0, ha), (torch.cumsum(count_b, 0) - count_b).index_select(0, ha))
    i, j, hit = sa.index_select(0, e), sb.index_select(0, at), ha.index_select(0, e)
    key = i * S + j
    slot = torch.searchsorted(t["pair_key"], key).clamp_max(t["pair_key"].numel() - 1)
    listed = (t["pair_key"].index_select(0, slot) == key).nonzero().squeeze(-1)  # a self-collision pair
    i, j, hit = i.index_select(0, listed), j.index_select(0, listed), hit.index_select(0, listed)
    pair, rows = t["pair_of_key"].index_select(0, slot.index_select(0, listed)), b.index_select(0, hit)
    d = (flat.index_select(0, rows * S + i) - flat.index_select(0, rows * S + j)).norm(dim=-1)
    m = margin.index_select(0, hit) if per_hit else margin
    near = (d < radii.index_select(0, i) + radii.index_select(0, j) + m).nonzero().squeeze(-1)  # the exact gap test
    rows, pair = rows.index_select(0, near), pair.index_select(0, near)
    order = torch.argsort(rows * t["rank"].numel() + t["rank"].index_select(0, pair))  # keys are distinct
    return rows.index_select(0, order), pair.index_select(0, order)


def _expand(count: torch.Tensor, start: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(owner (N,), at (N,))`` of ranges ``start[k] .. start[k] + count[k] - 1`` laid end to end:
    each element's range ``k`` and value (CSR expansion)."""
    owner = torch.repeat_interleave(torch.arange(count.numel(), device=count.device), count)
    first = (start - torch.cumsum(count, 0) + count).index_select(0, owner)
    return owner, first + torch.arange(owner.numel(), device=count.device)


def self_overlap_energy(hand, centres: torch.Tensor, radii: torch.Tensor,
                        pairs: "SelfPairList | None" = None, frame: torch.Tensor | None = None) -> torch.Tensor:
    """(B,) summed squared overlap (m^2) of the self-collision sphere pairs of posed spheres
    ``centres (B, S, 3)``, radii ``(S,)``. ``pairs`` (with ``frame (B, 4, 4)``, a frame rigidly
    attached to the hand such as the palm's) reuses candidate lists across calls; without it the
    cluster bounds are evaluated afresh. Equal to the all-pairs sum either way."""
    B = centres.shape[0]
    out = centres.new_zeros(B)
    if hand.self_collision_pairs.shape[0] == 0:
        return out
    if pairs is None:
        rows, pair = candidate_pairs(hand, centres, radii)
    else:
        rows, pair = pairs.candidates(centres, radii, frame)
    with torch.no_grad():
        i, j = hand.self_collision_pairs[pair, 0], hand.self_collision_pairs[pair, 1]
        hit = (centres[rows, i] - centres[rows, j]).norm(dim=-1) < radii[i] + radii[j]
        rows, i, j = rows[hit], i[hit], j[hit]  # only overlapping pairs enter the autograd graph
    ov = torch.relu(radii[i] + radii[j] - (centres[rows, i] - centres[rows, j]).norm(dim=-1))
    return index_add(out, 0, rows, ov.square())  # a fixed summation order on CUDA too


def _merge_by_pose(a: tuple[torch.Tensor, torch.Tensor], b: tuple[torch.Tensor, torch.Tensor], B: int):
    """``(rows, pair)`` of two candidate lists merged in (pose, cluster pair, pair) order, each list
    already in that order and every pose's pairs in one list only (a pose's list is kept whole or
    made anew): each entry goes to its pose's block at its place within the pose, no sort."""
    count_a, count_b = torch.bincount(a[0], minlength=B), torch.bincount(b[0], minlength=B)
    count = count_a + count_b
    start = torch.cumsum(count, 0) - count  # (B,) each pose's first slot in the merged list
    rows = torch.empty(a[0].numel() + b[0].numel(), dtype=a[0].dtype, device=a[0].device)
    pair = torch.empty_like(rows)
    for (r, p), c in ((a, count_a), (b, count_b)):
        # place within its pose = place in its list - the pose's first place in that list
        slot = start[r] + torch.arange(r.numel(), device=r.device) - (torch.cumsum(c, 0) - c)[r]
        rows[slot], pair[slot] = r, p
    return rows, pair


#: margin (m) of a list made for one call only: the pairs within it of overlapping (above float
#: rounding, so no overlapping pair is left out); the energy keeps only those that overlap
FRESH_MARGIN_M = 1e-6
#: a pose whose spheres moved more than ``skin_m / SLOW_FRACTION`` per call since its list was made
#: gets a list for one call at `FRESH_MARGIN_M` instead of one within ``skin_m``: a ``skin_m`` list
#: would go stale within ~``SLOW_FRACTION / 2`` calls, and it costs ~2x a fresh one to make (LEAP,
#: recorded calls of 34-512 poses: 1.17 s at 4 mm, 0.61 s at 1 um; benchmarks/results/pipeline.md)
SLOW_FRACTION = 6.0


class SelfPairList:
    """Per-pose lists of the sphere pairs within a margin of overlapping, reused while the pose's
    spheres stay within half that margin of where they were when its list was made (measured in a
    frame attached to the hand, so moving the whole hand costs nothing). The margin is ``skin_m``
    (m) for a pose that moves slowly, and `FRESH_MARGIN_M` (a list for the call it is made in) for
    one whose spheres moved more than ``skin_m / SLOW_FRACTION`` per call since its last list (every
    pose at first: the optimizer's first iterations move fingers by up to ~4 mm). One list serves
    one batch of poses: a batch of another size starts afresh; keep one per optimizer run."""

    def __init__(self, hand, skin_m: float = 0.004):
        if not skin_m > 0:
            raise ValueError(f"SelfPairList: skin_m must be > 0, got {skin_m}")
        self.hand, self.skin_m = hand, skin_m
        self.ref: torch.Tensor | None = None  # (B, S, 3) sphere centres in the hand frame at each list's making
        self.margin: torch.Tensor | None = None  # (B,) m, the margin each pose's list was made with
        self.age: torch.Tensor | None = None  # (B,) calls since each pose's list was made
        self.rows = self.pair = None
        self.rebuilt = 0  # poses whose list was (re)made, over all calls (for benchmarks)

    def candidates(self, centres: torch.Tensor, radii: torch.Tensor, frame: torch.Tensor):
        """``(rows, pair)`` covering every overlapping pair of ``centres (B, S, 3)``, in the order of
        :func:`candidate_pairs`; ``frame (B, 4, 4)`` is the hand frame of each pose."""
        with torch.no_grad():
            c = centres.detach()
            local = (c - frame[:, None, :3, 3]) @ frame[:, :3, :3]  # (B, S, 3) in the hand frame
            B = local.shape[0]
            if self.ref is None or self.ref.shape != local.shape:
                stale = torch.ones(B, dtype=torch.bool, device=local.device)
                moved = torch.full((B,), float("inf"), dtype=local.dtype, device=local.device)
                self.ref = local.clone()
                self.margin = torch.zeros(B, dtype=local.dtype, device=local.device)
                self.age = torch.ones(B, dtype=local.dtype, device=local.device)
                self.rows = torch.zeros(0, dtype=torch.long, device=local.device)
                self.pair = torch.zeros(0, dtype=torch.long, device=local.device)
            else:
                moved = (local - self.ref).norm(dim=-1).amax(-1)  # (B,) farthest sphere's displacement
                stale = 2 * moved >= self.margin
            redo = stale.nonzero().squeeze(-1)
            if redo.numel():
                slow = moved[redo] / self.age[redo] < self.skin_m / SLOW_FRACTION
                margin = torch.where(slow, self.skin_m, FRESH_MARGIN_M).to(local.dtype)
                r_new, p_new = candidate_pairs(self.hand, c[redo], radii, margin)
                kept = ~stale[self.rows]
                self.rows, self.pair = _merge_by_pose((self.rows[kept], self.pair[kept]), (redo[r_new], p_new), B)
                self.ref[redo] = local[redo]
                self.margin[redo] = margin
                self.age[redo] = 0
                self.rebuilt += int(redo.numel())
            self.age += 1
            return self.rows, self.pair
