"""Batched synthesis of hand poses for many objects at once (paper Sec. IV-C).

``synthesize(hand, targets, task, cfg, num_per_object)`` optimizes ``len(targets) *
num_per_object`` poses in one tensor program: forward kinematics, energies and the optimizer are
batched over all of them; only the distance queries loop over the distinct objects. With
``cfg.seeds_per_grasp`` > 1 each pose is the best of that many starts, chosen after
``cfg.seed_select_iter`` iterations (:mod:`datagen.synth.select`).

Outputs per grasp (:class:`SynthesisResult`, all in each object's frame, metres/radians):
``grasp`` = ``[x y z qw qx qy qz, joints...]`` (the hand MJCF's joint order); ``squeeze`` the
same root with finger joints set so that position actuators press the task fingertips onto the
object with balanced grip forces, and ``pregrasp`` = ``2 grasp - squeeze`` (:mod:`datagen.synth.squeeze`), pulled back towards the grasp where it
would sink the hand deeper into the object than the grasp does;
the task fingertips' contact points and inward normals; final energy terms; epsilon of those
contacts; the initial pose (for rendering). A mounted task object's scenery (door, panel, housing,
cabinet: `datagen.synth.scenery`) is part of every penetration term and of the initial poses.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import torch

from datagen.synth.config import SynthConfig, TaskSpec
from datagen.tasks.grasp_type import TASK_GRASP_TYPE, load_grasp_type
from datagen.synth.energies import contact_sphere_index, evaluate_state, hand_object_state, task_origins
from datagen.synth.init import initial_poses
from datagen.synth.optimizer import GroupedDescent, PoseVariables
from datagen.synth.scenery import Scenery
from datagen.synth.select import seed_scores, top_seeds
from datagen.synth.self_collision import SelfPairList
from datagen.synth.squeeze import backtrack_pregrasp, force_squeeze
from datagen.wrench import sample_directions

__all__ = ["SynthesisResult", "finger_joint_groups", "finger_joint_mask", "synthesize"]


@dataclass
class SynthesisResult:
    object_index: torch.Tensor  # (B,) index into the targets
    grasp: torch.Tensor  # (B, 7 + J)
    pregrasp: torch.Tensor  # (B, 7 + J)
    squeeze: torch.Tensor  # (B, 7 + J)
    initial: torch.Tensor  # (B, 7 + J)
    contact_points: torch.Tensor  # (B, F, 3) m
    contact_normals: torch.Tensor  # (B, F, 3) inward
    tip_distance: torch.Tensor  # (B, F) m, signed gap of each task fingertip's contact sphere
    energies: dict[str, torch.Tensor] = field(default_factory=dict)  # name -> (B,)
    max_penetration: torch.Tensor | None = None  # (B,) m, deepest sphere penetration
    epsilon: torch.Tensor | None = None  # (B,)
    fingers: list[str] = field(default_factory=list)
    grasp_type: str = "precision"  # the grasp type whose contact set the poses were synthesized with
    seed: int = 0
    timings: dict[str, float] = field(default_factory=dict)

    def usable(self, contact_threshold_m: float, max_penetration_m: float = 0.005) -> torch.Tensor:
        """(B,) bool: every task fingertip within the threshold and penetration below the limit."""
        return (self.tip_distance.abs().amax(-1) <= contact_threshold_m) & (self.max_penetration <= max_penetration_m)


def _joint_groups(hand) -> dict[str, list[int]]:
    """Joint indices per fingertip chain (``finger<k>``) and ``shared`` (on several chains: wrist)."""
    m = hand.mj_model
    link_body = {name: i + 1 for i, name in enumerate(hand.link_names)}
    chains = []
    for tip in hand.fingertip_link_index.tolist():
        body, ancestors = link_body[hand.link_names[tip]], set()
        while body > 0:
            ancestors.add(body)
            body = int(m.body_parentid[body])
        chains.append(ancestors)
    groups: dict[str, list[int]] = {}
    for j in range(hand.num_joints):
        b = int(m.jnt_bodyid[j])
        owners = [k for k, anc in enumerate(chains) if b in anc]
        key = f"finger{owners[0]}" if len(owners) == 1 else "shared"
        groups.setdefault(key, []).append(j)
    return groups


def finger_joint_groups(hand) -> list[torch.Tensor]:
    """Joint index groups: one per fingertip chain, plus one for joints shared by all (wrist)."""
    return [torch.tensor(v, device=hand.device) for v in _joint_groups(hand).values()]


def finger_joint_mask(hand) -> torch.Tensor:
    """(J,) bool: joints that belong to exactly one fingertip chain (not the wrist)."""
    mask = torch.zeros(hand.num_joints, dtype=torch.bool, device=hand.device)
    for key, idx in _joint_groups(hand).items():
        mask[idx] = key != "shared"
    return mask


def _resolve_fingers(hand, task: TaskSpec) -> list[int]:
    """Indices of the task's contact fingertips. Names the hand lacks (``lf`` on four-finger
    hands) are dropped; a task left with none of its fingertips is an error."""
    if task.fingers == "all":
        return list(range(len(hand.fingertip_names)))
    present = [f for f in task.fingers if f in hand.fingertip_names]
    if not present:
        raise ValueError(f"task {task.name!r} names fingertips {list(task.fingers)}, none of which hand "
                         f"{hand.name!r} has; it has {hand.fingertip_names}")
    return [hand.fingertip_names.index(f) for f in present]


def _mount(task: TaskSpec, targets, object_index: torch.Tensor):
    """``(kind, axis, anchor_m, mounted (B,) bool)``: the hinge or slide a mounted task object moves
    on (its test's virtual joint, object frame) and the samples on that object; None when the task
    has no such object among ``targets`` (force closure, a free object)."""
    from datagen.tasks import task_object, task_object_id, task_test_from_spec

    if task_object(task) is None:
        return None
    test = task_test_from_spec(task)
    if test is None or test.joint == "free":
        return None
    oid = task_object_id(task)
    on = torch.tensor([t.object_id == oid for t in targets], dtype=torch.bool, device=object_index.device)
    mounted = on[object_index]
    return (test.joint, test.axis, test.anchor, mounted) if bool(mounted.any()) else None


#: rows per Python thread below which a split batch runs slower than one intra-op-threaded batch (its
#: parts' per-op Python work contends for the GIL): Shadow, 2 cores, 1600 seeds 12.8 -> 10.6 s, 100
#: poses 3.8 -> 5.5 s (benchmarks/results/synth_cli.md)
MIN_ROWS_PER_THREAD = 400


def _row_parts(index: torch.Tensor, targets, threads: int) -> list[torch.Tensor]:
    """Rows of a batch (each row's target in ``index (B,)``) in up to ``threads`` parts of at least
    ``MIN_ROWS_PER_THREAD`` rows. A batch laid out as ``arange(T).repeat_interleave(R)`` is cut
    within every target (each part: the same share of every target's rows, so it keeps the layout
    and the stacked grid queries of `datagen.synth.stacked`); a single target's batch is cut into
    contiguous ranges; any other layout stays whole. The poses then equal the whole batch's bit for
    bit (tests/synth/test_multistart.py; parts of one row per target: gradients differed by 3e-8)."""
    from datagen.synth.stacked import per_target_rows

    B = index.shape[0]
    parts = max(1, min(threads, B // MIN_ROWS_PER_THREAD))
    R = per_target_rows(targets, index) if len(targets) > 1 else B
    if R == 0:
        return [torch.arange(B, device=index.device)]
    while R % parts:
        parts -= 1
    rows = torch.arange(B, device=index.device).reshape(-1, R)  # (T, R)
    return [rows[:, R * k // parts:R * (k + 1) // parts].reshape(-1) for k in range(parts)]


def _in_threads(fn, parts: list[torch.Tensor]) -> list:
    """``[fn(rows) for rows in parts]``, the parts at once in Python threads with one intra-op
    thread each (torch ops release the GIL); a single part runs as is. For per-pose computations."""
    if len(parts) == 1:
        return [fn(parts[0])]
    from concurrent.futures import ThreadPoolExecutor

    before = torch.get_num_threads()

    def one(rows):
        torch.set_num_threads(1)  # this thread's own ops run on one intra-op thread too
        return fn(rows)

    torch.set_num_threads(1)
    try:
        with ThreadPoolExecutor(len(parts)) as pool:
            return list(pool.map(one, parts))
    finally:
        torch.set_num_threads(before)


def _run_split(opt: GroupedDescent, energy_on, x: PoseVariables, index: torch.Tensor, targets,
               iters: int, callback, first: int, threads: int):
    """``opt.run`` over the rows of ``x``, on the CPU in parts at once (`_row_parts`, `_in_threads`):
    every pose's arithmetic is that of the whole batch's run, so the poses do not depend on
    ``threads``. ``callback`` sees the first part only."""
    parts = _row_parts(index, targets, threads) if x.translation.device.type == "cpu" else []
    if len(parts) <= 1:
        return opt.run(energy_on(index), x, iters, callback=callback, first_iter=first)

    def part(rows):
        xs = PoseVariables(x.translation[rows], x.quaternion[rows], x.joints[rows])
        return opt.run(energy_on(index[rows]), xs, iters, callback=callback if rows is parts[0] else None, first_iter=first)

    out = _in_threads(part, parts)
    back = torch.argsort(torch.cat(parts))  # concatenated part order -> row order
    xs = PoseVariables(*(torch.cat([getattr(o[0], f) for o in out])[back] for f in ("translation", "quaternion", "joints")))
    return xs, torch.cat([o[1] for o in out])[back], {k: torch.cat([o[2][k] for o in out])[back] for k in out[0][2]}


@dataclass
class _Batch:
    """What one synthesis batch is made of (set up once by `_setup`)."""

    object_index: torch.Tensor  # (B,) target of each output grasp
    seed_index: torch.Tensor  # (B S,) target of each start
    finger_index: list  # the task fingertips (indices into hand.fingertip_names)
    tip_spheres: torch.Tensor  # (F,) their contact spheres
    scenery: object  # a mounted task object's fixed parts, or None
    root: torch.Tensor  # (B S, 7) initial root poses
    joints: torch.Tensor  # (B S, J) initial joints, coupled
    directions: torch.Tensor  # (K, 6) wrench directions
    links: torch.Tensor | None = None  # (L,) the grasp type's extra contact links (palm, phalanges); None: fingertips only
    link_pull: torch.Tensor | None = None  # (L,) bool: those the distance term pulls onto the surface
    pieces: list | None = None  # the targets' convex pieces for the penetration terms (cfg.penetration_pieces); None: the surface only


def _grasp_links(hand, grasp_type, finger_index) -> tuple[torch.Tensor | None, torch.Tensor | None]:
    """``(links (L,), pull (L,) bool)`` of a grasp type's extra contact roles: the palm link and
    the phalanges (each taking part at its nearest collision sphere), and which of them the
    distance term pulls (None, None: the fingertips only)."""
    from datagen.synth.links import contact_links

    palm, phal = grasp_type.role("palm"), grasp_type.role("phalanges")
    phalanges = contact_links(hand, finger_index) if phal is not None else []
    links = ([hand.palm_link] if palm is not None else []) + phalanges
    pull = ([palm == "pull"] if palm is not None else []) + [phal == "pull"] * len(phalanges)
    if not links:
        return None, None
    return (torch.tensor(links, dtype=torch.long, device=hand.device),
            torch.tensor(pull, dtype=torch.bool, device=hand.device))


def _setup(hand, targets, task, cfg, num_per_object: int, gen: torch.Generator, grasp_type=None) -> _Batch:
    """The batch's indices, the task fingertips, the initial poses and the wrench directions
    (drawn from ``gen`` in that order); ``grasp_type`` (`datagen.tasks.GraspType`): its extra
    contact links and its initial-pose fields over the task's (None: the fingertips only)."""
    dev, dt = hand.device, hand.dtype
    object_index = torch.arange(len(targets), device=dev).repeat_interleave(num_per_object)
    finger_index = _resolve_fingers(hand, task)
    links, pull = _grasp_links(hand, grasp_type, finger_index) if grasp_type is not None else (None, None)
    if grasp_type is not None:
        task = dataclasses.replace(task, init=grasp_type.apply_init(task.init))
    seed_index = object_index.repeat_interleave(cfg.seeds_per_grasp)  # seeds of grasp b: rows b S .. b S + S - 1
    # a mounted object's door, housing or cabinet; the table under a tabletop target
    scenery = Scenery.for_task(task, targets, dev, dt, cfg.sphere_margin_m)
    root, joints = initial_poses(hand, targets, seed_index, task.init, gen, tip_index=finger_index, scenery=scenery)
    directions = sample_directions(cfg.num_directions, generator=gen, device=dev, dtype=dt)
    pieces = [t.pieces() for t in targets] if cfg.penetration_pieces else None
    return _Batch(object_index, seed_index, finger_index, contact_sphere_index(hand)[finger_index], scenery,
                  root, hand.apply_couplings(joints), directions, links, pull, pieces)


def _energy_on(hand, targets, task, cfg, b: _Batch):
    """``energy_on(index)``: the energy function of one optimizer run over the rows whose targets
    are ``index (N,)`` (its own self-collision pair lists), returning ``(total (N,), extras)``."""

    def energy_on(index):
        self_pairs = SelfPairList(hand, cfg.self_pair_skin_m) if cfg.self_pair_skin_m > 0 else None
        origin = task_origins(task, targets, index, cfg)

        def energy_fn(t, q, j):
            jj = hand.apply_couplings(j)
            state = hand_object_state(hand, targets, index, torch.cat([t, q], -1), jj, b.tip_spheres,
                                      exact_contacts=cfg.exact_contacts, sphere_margin=cfg.sphere_margin_m,
                                      self_collision=cfg.weights.self_penetration > 0, self_pairs=self_pairs,
                                      scenery=b.scenery, links=b.links, link_pull=b.link_pull, pieces=b.pieces)
            terms = evaluate_state(state, cfg, task, b.directions, task_origin=origin)
            extras = {k: v.detach() for k, v in terms.as_dict().items()}
            extras.update(tip_distance=state.tip_distance.detach(), max_penetration=state.max_penetration.detach())
            return terms.total, extras
        return energy_fn
    return energy_on


def _optimize(hand, targets, task, cfg, b: _Batch, callback, threads: int):
    """``(x, extras, initial)``: the optimized poses of the output grasps, their last energy terms
    and the initial pose ``(B, 7 + J)`` each came from. With ``cfg.seeds_per_grasp`` S > 1 every
    start runs ``seed_select_iter`` iterations, then the best of each grasp's S goes on
    (`datagen.synth.select`)."""
    energy_on = _energy_on(hand, targets, task, cfg, b)
    opt = GroupedDescent(finger_joint_groups(hand), (cfg.step_translation_m, cfg.step_rotation_rad, cfg.step_joint_rad),
                         momentum=cfg.momentum, step_decay=cfg.step_decay, decay_every=cfg.decay_every,
                         project=hand.apply_couplings)
    x = PoseVariables(b.root[:, :3].clone(), b.root[:, 3:].clone(), b.joints.clone())
    root, joints, first = b.root, b.joints, 0
    S = cfg.seeds_per_grasp
    if S > 1:  # multi-start: every seed runs the first iterations, the best of each grasp goes on
        first = min(cfg.seed_select_iter, cfg.iters)
        x, e, extras = _run_split(opt, energy_on, x, b.seed_index, targets, first, callback, 0, threads)
        scores = seed_scores(hand, targets, b.seed_index, x.root_pose(), hand.apply_couplings(x.joints), e,
                             b.tip_spheres, task, cfg, task_origins(task, targets, b.seed_index, cfg))
        keep = top_seeds(scores, S)
        x = PoseVariables(x.translation[keep], x.quaternion[keep], x.joints[keep])
        root, joints = root[keep], joints[keep]
        extras = {k: v[keep] for k, v in extras.items()}
    if cfg.iters > first:
        x, _, extras = _run_split(opt, energy_on, x, b.object_index, targets, cfg.iters - first, callback, first,
                                  threads)
    return x, extras, torch.cat([root, joints], -1)


def _squeeze_extra(hand, state, cfg):
    """A grasp type's extra contacts for the squeeze (`force_squeeze`'s ``extra``): the palm and
    the phalanges, touching within ``cfg.seed_contact_gap_m`` of the surface (the sphere margin
    added back); None for the fingertips alone."""
    lc = state.links
    if lc is None:
        return None
    links = hand.sphere_link_index[lc.sphere]  # (B, L)
    touching = lc.gap + cfg.sphere_margin_m <= cfg.seed_contact_gap_m
    return lc.points, lc.normals, links, touching


def _finish(hand, targets, task, cfg, b: _Batch, x: PoseVariables):
    """``(grasp, pregrasp, squeeze, state)`` at the optimized poses: the squeeze presses the task
    fingertips with balanced grip forces (`datagen.synth.squeeze.force_squeeze`), the pregrasp is
    its mirror image pulled back where it would sink the hand deeper than the grasp."""
    idx = b.object_index
    with torch.no_grad():
        grasp_j, root_f = hand.apply_couplings(x.joints), x.root_pose()
        state = hand_object_state(hand, targets, idx, root_f, grasp_j, b.tip_spheres,
                                  sphere_margin=cfg.sphere_margin_m, scenery=b.scenery, links=b.links,
                                  link_pull=b.link_pull, pieces=b.pieces)
        pre_j, sq_j = force_squeeze(hand, root_f, grasp_j, b.tip_spheres, state.contact_points, state.contact_normals,
                                    cfg.contact.mu, cfg.squeeze_kp, cfg.squeeze_force_n, cfg.squeeze_gap_m,
                                    finger_joint_mask(hand), mount=_mount(task, targets, idx),
                                    extra=_squeeze_extra(hand, state, cfg))

        def depth(j):  # deepest collision-sphere penetration (m) at joints j, this root
            return hand_object_state(hand, targets, idx, root_f, j, b.tip_spheres, self_collision=False,
                                     scenery=b.scenery, pieces=b.pieces).max_penetration

        pre_j = backtrack_pregrasp(hand, grasp_j, pre_j, depth)
    cat = lambda j: torch.cat([root_f, j], -1)  # noqa: E731
    return cat(grasp_j), cat(pre_j), cat(sq_j), state


def _row_grasp_type(task: TaskSpec, grasp_type) -> str:
    """What a row records: the grasp type, or ``task`` for a task naming its own fingertips
    synthesized with the fingertip-only (precision) contact set."""
    own = task.fingers != "all" and not grasp_type.extra_contacts
    return TASK_GRASP_TYPE if own else grasp_type.name


def synthesize(hand, targets, task: TaskSpec, cfg: SynthConfig, num_per_object: int, *,
               generator: torch.Generator | None = None, callback=None, threads: int | None = None) -> SynthesisResult:
    """Optimize ``num_per_object`` poses on each target; see the module docstring. ``cfg`` is the
    resolved config of ``task`` and its grasp type (`datagen.pipeline.resolve(...).synth_for(type)`;
    one lacking the task's ``synth:`` block is refused; the type's ``synth:`` block is a layer of
    that resolution, not applied here). ``threads`` (default: torch's intra-op thread count): on the
    CPU, a large batch (the seeds' first iterations) runs in up to that many parts at once
    (`_run_split`; the poses do not depend on it)."""
    import time

    t0 = time.perf_counter()
    cfg.check_task(task)
    gt = load_grasp_type(cfg.grasp_type).for_hand(hand.name)  # the type's `hands:` entry (init) for this hand
    cfg = cfg.for_hand(hand)  # the hand's sphere margin
    threads = torch.get_num_threads() if threads is None else int(threads)
    task = task.for_hand(hand.name)  # the task's `hands:` entry for this hand (init, fingers), if any
    b = _setup(hand, targets, task, cfg, num_per_object, generator or torch.Generator().manual_seed(cfg.seed), gt)
    x, extras, initial = _optimize(hand, targets, task, cfg, b, callback, threads)
    t_opt = time.perf_counter() - t0
    grasp, pregrasp, squeeze, state = _finish(hand, targets, task, cfg, b, x)
    dt = hand.dtype
    eps = (cfg.contact.epsilon(state.contact_points.double(), state.contact_normals.double()).to(dt)
           if len(b.finger_index) > 1 else torch.zeros(len(b.object_index), dtype=dt, device=hand.device))
    return SynthesisResult(
        object_index=b.object_index, grasp=grasp, pregrasp=pregrasp, squeeze=squeeze, initial=initial,
        contact_points=state.contact_points, contact_normals=state.contact_normals,
        tip_distance=state.tip_distance, max_penetration=state.max_penetration, epsilon=eps.detach(),
        energies={k: v for k, v in extras.items() if k not in ("tip_distance", "max_penetration")},
        fingers=[hand.fingertip_names[i] for i in b.finger_index], grasp_type=_row_grasp_type(task, gt), seed=cfg.seed,
        timings={"optimize_s": t_opt, "total_s": time.perf_counter() - t0},
    )
