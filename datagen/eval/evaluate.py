"""`Evaluator`: one grasp in, one verdict with a reason code and its metrics out.

Order of decisions (the first that applies is the reason):

1. ``invalid_grasp``: a pose is not finite (a wrong row length is an input error and raises);
2. ``penetration``: a hand-object contact at the pregrasp is deeper than
   ``max_pregrasp_penetration_m`` (the public protocol's rejection before simulating);
3. ``no_contact``: fewer than ``min_touching_links`` hand links within ``touch_distance_m`` of
   the object at the grasp pose (so the squeeze alone cannot make a grasp);
4. the simulated test: ``unstable`` (the simulation diverged), ``slipped_<dir>`` (the first
   direction, in ``+x -x +y -y +z -z`` order, failing at the earliest failing check) or
   ``slipped_task`` for a task test; else ``ok``. The object's motion is measured from its
   initial pose (the public protocol), or for a task test with ``measure_from: closed`` from its
   pose once the hand has closed (the paper's task test: hand fixed, object unmoved under -w_t).

A tabletop row (its support plane passed as ``table``) takes the lift test of `datagen.eval.lift`
instead of the six directions (test ``tabletop_lift``): after ``penetration``, ``hand_in_table``
(a hand geom deeper than ``max_table_penetration_m`` in the table at the pregrasp or the grasp),
then ``no_contact``, then the lift's own codes (``object_left_on_table``, ``object_dropped``,
``object_slipped``, ``unstable``).

Metrics are computed for every grasp (also rejected ones) at the grasp pose: penetration,
self penetration, per-finger contact distance, and the epsilon metric
(`datagen.wrench.epsilon_metric`, contacts within ``contact_distance_m``, mu = friction).

`Evaluator.margin` also measures how large a disturbance the grasp holds: the same test (same
thresholds, same closed hand) repeated at multiples of its disturbance, bisecting a fixed grid
(`MULTIPLES`, quarter octaves), see `TaskMargin`.
"""

from __future__ import annotations

import dataclasses
import enum
import logging
import math
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import mujoco
import numpy as np
import torch

from datagen.wrench import EpsilonSearch, epsilon_metric

from .config import DIRECTION_NAMES, DIRECTIONS, EvalConfig, EvalError, TaskTest
from .hold import DirectionResult, close_hand, hold, initial_state
from .lift import LIFT_TEST, lift, lift_reason, table_depth
from .metrics import StaticMetrics, static_metrics
from .scene import ObjectPieces, Scene, build_scene

log = logging.getLogger(__name__)

__all__ = ["MULTIPLES", "OCTAVE_MULTIPLES", "Reason", "GraspResult", "Evaluator", "TaskMargin"]

#: the fixed grid of disturbance multiples `Evaluator.margin` bisects (1: the test's own
#: magnitude): quarter octaves 2^(k/4) from 0.25 to 32, each 19% above the one before. Octaves
#: (`OCTAVE_MULTIPLES`, the grid until 2026-11-27) tied most poses of a task at one value
#: (benchmarks/results/tasks.md, Notes, session 23).
MULTIPLES = tuple(2.0 ** (k / 4) for k in range(-8, 21))
OCTAVE_MULTIPLES = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0)


class Reason(str, enum.Enum):
    """Stable reason codes of a verdict (``slipped_<dir>`` is built from `DIRECTION_NAMES`)."""

    OK = "ok"
    INVALID_GRASP = "invalid_grasp"
    PENETRATION = "penetration"
    NO_CONTACT = "no_contact"
    UNSTABLE = "unstable"
    SLIPPED_TASK = "slipped_task"
    HAND_IN_TABLE = "hand_in_table"
    OBJECT_LEFT_ON_TABLE = "object_left_on_table"
    OBJECT_DROPPED = "object_dropped"
    OBJECT_SLIPPED = "object_slipped"

    @staticmethod
    def slipped(direction: str) -> str:
        return f"slipped_{direction}"


@dataclass(frozen=True)
class GraspResult:
    """The verdict and metrics of one grasp (metres, degrees).

    ``test``: ``six_direction`` or the task name. ``direction_*``: one entry per direction
    (six, in `DIRECTION_NAMES` order) or one for a task test; success None and NaN metrics
    where the direction was not simulated (rejected before, or stopped at another's failure).
    ``finger_distance_m``: (F,) signed, fingertip links in ``hand.fingertip_names`` order.
    """

    success: bool
    reason: str
    test: str
    direction_success: tuple
    direction_translation_m: tuple
    direction_rotation_deg: tuple
    pregrasp_penetration_m: float
    penetration_m: float
    self_penetration_m: float
    min_distance_m: float
    finger_distance_m: tuple
    touching_links: int
    num_contacts: int
    epsilon: float
    sim_steps: int
    table_penetration_m: float = math.nan  # tabletop: the hand's depth in the table (pregrasp and grasp); NaN: no table


@dataclass(frozen=True)
class TaskMargin:
    """The largest multiple of a test's disturbance that a grasp holds (`Evaluator.margin`).

    ``result``: the verdict at the test's own magnitude (identical to `Evaluator.evaluate`).
    ``held_multiple``: the largest multiple of the grid held, found by bisection: above 1 if the
    grasp holds at 1, below it otherwise; 0 when it holds none (or was rejected before
    simulating: penetration, no contact, invalid). Assumes that holding a disturbance
    implies holding a smaller one of the same direction (only the bisection's own tests check
    it), so the grid's neighbour above ``held_multiple`` was tested and failed unless
    ``held_multiple`` ends the grid. ``held_wrench``: ``held_multiple`` times the test's
    disturbance magnitude (N for a force, N m for a pure torque; the six-direction test's force,
    N). ``tested``: ``(multiple, held)`` pairs in the order simulated (1 first)."""

    result: GraspResult
    held_multiple: float
    held_wrench: float
    tested: tuple


class Evaluator:
    """Evaluates grasps of one hand under one `EvalConfig`. Scenes (one per object, scale and
    object joint) are cached, ``cache_size`` at most. Not thread-safe: use one per worker.
    Call `close` (or use it as a context manager) to stop its thread pool.

    ``spare_cores``: optional, how many CPU cores sit idle right now (a job's shard asks its Ray
    cluster). With ``cfg.threads`` 1, a grasp that starts while one is idle steps its directions
    on 2 threads: the verdicts are the same for any number of threads (`hold`), so this only
    fills a core that would wait, such as the one a job's first finished shard leaves behind."""

    def __init__(self, hand, cfg: EvalConfig | None = None, *, cache_size: int = 8,
                 spare_cores: Callable[[], int] | None = None) -> None:
        self.hand = hand
        self.cfg = cfg or EvalConfig()
        self._scenes: OrderedDict = OrderedDict()
        self._hold_cfgs: dict = {}
        self._cache_size = cache_size
        self._pool = ThreadPoolExecutor(self.cfg.threads) if self.cfg.threads > 1 else None
        self._spare_cores, self._spare_pool = spare_cores, None
        self._search = EpsilonSearch(num_samples=self.cfg.epsilon_samples,
                                     num_starts=min(8, self.cfg.epsilon_samples), iters=self.cfg.epsilon_iters)

    def close(self) -> None:
        for pool in (self._pool, self._spare_pool):
            if pool is not None:
                pool.shutdown()
        self._pool = self._spare_pool = None

    def _hold_pool(self) -> ThreadPoolExecutor | None:
        """The pool that steps the next grasp's directions: the config's (``threads`` > 1), else,
        while ``spare_cores()`` reports an idle core, one of 2 threads; None: this thread."""
        if self._pool is not None or self._spare_cores is None or self._spare_cores() < 1:
            return self._pool
        if self._spare_pool is None:
            self._spare_pool = ThreadPoolExecutor(2)
        return self._spare_pool

    def __enter__(self) -> "Evaluator":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ scenes
    def scene(self, pieces: ObjectPieces, task: TaskTest | None = None,
              table: tuple | None = None) -> tuple[Scene, list[mujoco.MjData]]:
        """The cached scene of ``pieces`` (object joint from ``task``; ``table``: a support plane
        ``[n, d]``, None: none) and its scratch MjData."""
        joint = None if task is None or task.joint == "free" else (task.joint, task.axis, task.anchor, task.limits)
        key = (pieces.paths, pieces.volumes, pieces.scale, joint, () if task is None else task.scenery)
        if table is not None:
            key += (table,)
        if key in self._scenes:
            self._scenes.move_to_end(key)
            return self._scenes[key]
        scene = build_scene(self.hand, pieces, self.cfg, task, table=table, visual=False)
        log.debug("scene of %s: %d pieces at scale %.3f m, joint %s (%d scenes cached)",
                  pieces.object_id, len(pieces.paths), pieces.scale, joint[0] if joint else "free", len(self._scenes) + 1)
        datas = [mujoco.MjData(scene.model) for _ in range(len(DIRECTIONS) + 2)]
        self._scenes[key] = (scene, datas)
        while len(self._scenes) > self._cache_size:
            self._scenes.popitem(last=False)
        return scene, datas

    def _hold_config(self, test: TaskTest | None) -> EvalConfig:
        """The config with a task test's own pass thresholds (cached per test)."""
        if test is None or (test.max_translation_m is None and test.max_rotation_deg is None):
            return self.cfg
        key = (test.max_translation_m, test.max_rotation_deg)
        if key not in self._hold_cfgs:
            self._hold_cfgs[key] = dataclasses.replace(
                self.cfg, max_translation_m=test.max_translation_m or self.cfg.max_translation_m,
                max_rotation_deg=test.max_rotation_deg or self.cfg.max_rotation_deg)
        return self._hold_cfgs[key]

    # ------------------------------------------------------------------ one grasp
    def epsilon(self, metrics: StaticMetrics) -> float:
        """Epsilon of the grasp's contacts (0 with fewer than 2 contacts)."""
        if len(metrics.contact_points) < 2:
            return 0.0
        mu = self.cfg.epsilon_mu if self.cfg.epsilon_mu is not None else self.cfg.friction[0]
        p = torch.as_tensor(metrics.contact_points, dtype=torch.float64)
        n = torch.as_tensor(metrics.contact_normals, dtype=torch.float64)
        with torch.no_grad():
            return float(epsilon_metric(p, n, mu, search=self._search))

    def evaluate(self, pieces: ObjectPieces, poses: np.ndarray, task: str = "force_closure",
                 w_t=None, table=None) -> GraspResult:
        """Evaluate one grasp.

        Args:
            pieces: the object (normalized pieces and the scale in metres).
            poses: (3, 7 + J) pregrasp, grasp, squeeze rows [x y z qw qx qy qz, joints] in the
                object frame (metres, radians), joints in ``hand.joint_names`` order.
            task: a hold task (six directions) or a task of ``cfg.tasks``.
            w_t: (6,) the row's task wrench; for a task test it replaces the configured ``w_t``
                (the joint, axis and scaling stay the config's). Ignored for hold tasks.
            table: (4,) the row's support plane ``[n, d]`` (object frame, m) of a tabletop row:
                the lift test instead of the six directions (a hold task only). None: floating.
        """
        if table is not None:
            return self._tabletop(pieces, poses, task, tuple(float(x) for x in table))
        return self._run(pieces, poses, task, w_t, None).result

    def _tabletop(self, pieces: ObjectPieces, poses: np.ndarray, task: str, plane: tuple) -> GraspResult:
        """The verdict of a tabletop row: the static checks, the hand's depth in the table, the
        lift (`datagen.eval.lift`)."""
        cfg = self.cfg
        test, poses = self._grasp_input(poses, task, None)
        if test is not None:
            raise EvalError(f"tabletop grasp of task {task!r}", "its task test has no table",
                            "tabletop rows are force-closure grasps (the lift test)")
        scene, datas = self.scene(pieces, None, plane)
        verdict = _Verdict(self.hand, LIFT_TEST, 1)
        if not np.all(np.isfinite(poses)) or np.any(np.linalg.norm(poses[:, 3:7], axis=1) < 1e-9):
            return verdict(Reason.INVALID_GRASP.value)
        common, rejected = self._static_checks(scene, datas[-1], poses, None)
        common["table"] = max(table_depth(scene, datas[-1], poses[0]), table_depth(scene, datas[-1], poses[1]))
        if rejected != Reason.PENETRATION.value and common["table"] > cfg.max_table_penetration_m:
            rejected = Reason.HAND_IN_TABLE.value
        if rejected:
            return verdict(rejected, **common)
        res = lift(scene, datas[-2], poses, np.asarray(plane[:3]), cfg)
        reason = lift_reason(res, cfg)
        return verdict(reason or Reason.OK.value, reason is None, [res.direction], steps=res.steps, **common)

    def margin(self, pieces: ObjectPieces, poses: np.ndarray, task: str = "force_closure", w_t=None,
               multiples=MULTIPLES) -> TaskMargin:
        """`evaluate` plus the largest multiple of the test's disturbance held (see `TaskMargin`).

        ``multiples``: increasing grid of positive multiples containing 1. Each multiple is the
        same hold test (thresholds, directions) from the same closed hand, with the disturbance
        (the task's wrench, or the six-direction force) scaled by it."""
        grid = tuple(float(m) for m in multiples)
        if 1.0 not in grid or any(m <= 0 for m in grid) or list(grid) != sorted(set(grid)):
            raise EvalError("Evaluator.margin multiples", f"must be increasing, > 0 and contain 1, got {multiples!r}")
        return self._run(pieces, poses, task, w_t, grid)

    def _run(self, pieces: ObjectPieces, poses: np.ndarray, task: str, w_t, grid) -> TaskMargin:
        """The verdict (and with ``grid`` the held multiple) of one grasp: the shared steps
        (checks at the static poses, closing the hand, the hold, the reason) around the test's
        disturbances, six directions (`six_direction_wrenches`) or the task's (`task_wrenches`)."""
        cfg = self.cfg
        test, poses = self._grasp_input(poses, task, w_t)
        scene, datas = self.scene(pieces, test)
        verdict = _Verdict(self.hand, "six_direction" if test is None else task, len(DIRECTIONS) if test is None else 1)
        wrenches = (six_direction_wrenches(cfg, scene.object_mass) if test is None
                    else task_wrenches(test, cfg, scene.object_mass, pieces.scale))
        magnitude = float(np.linalg.norm(wrenches[0, :3]) if np.any(wrenches[0, :3]) else np.linalg.norm(wrenches[0, 3:]))

        def done(res: GraspResult, held: float = 0.0, tested: tuple = ()) -> TaskMargin:
            return TaskMargin(res, held, held * magnitude, tested)

        if not np.all(np.isfinite(poses)) or np.any(np.linalg.norm(poses[:, 3:7], axis=1) < 1e-9):
            return done(verdict(Reason.INVALID_GRASP.value))
        common, rejected = self._static_checks(scene, datas[-1], poses, test)
        if rejected:
            return done(verdict(rejected, **common))
        closed, pos0, quat0, n0 = self._close(scene, datas[-2], poses, test)
        if closed is None:
            dirs = [DirectionResult(False, math.inf, math.inf, True)] * verdict.n_dir
            return done(verdict(Reason.UNSTABLE.value, False, dirs, steps=n0, **common))
        pool, hold_cfg = self._hold_pool(), self._hold_config(test)
        dirs = hold(scene, closed, wrenches, datas[:len(wrenches)], pos0, quat0, hold_cfg, pool)
        steps = n0 + sum(int(round(d.time / cfg.timestep_s)) - n0 for d in datas[:len(wrenches)])
        reason = _failure_reason(dirs, test)
        res = verdict(reason or Reason.OK.value, reason is None, dirs, steps=steps, **common)
        if grid is None:
            return done(res)

        def holds(k: float) -> bool:
            return all(d.success for d in hold(scene, closed, k * wrenches, datas[:len(wrenches)], pos0, quat0,
                                               hold_cfg, pool))

        held, tested = _bisect(grid, res.success, holds)
        return done(res, held, tested)

    def _grasp_input(self, poses: np.ndarray, task: str, w_t) -> tuple[TaskTest | None, np.ndarray]:
        """``(test, poses)``: the task's test (None: six directions; the row's ``w_t`` replacing
        its own) and the poses as a (3, 7 + J) float array (`EvalError` for another shape)."""
        test = self.cfg.task_test(task)  # raises EvalError for an unknown task
        if test is not None and w_t is not None:
            test = dataclasses.replace(test, w_t=tuple(float(x) for x in w_t))
        poses = np.asarray(poses, dtype=np.float64)
        width = 7 + self.hand.num_joints
        if poses.shape != (3, width):
            raise EvalError(f"grasp of hand {self.hand.name!r}",
                            f"poses have shape {poses.shape}, expected (3, {width})",
                            "rows are [x y z qw qx qy qz] + joints in the hand MJCF's joint order")
        return test, poses

    def _static_checks(self, scene: Scene, data: mujoco.MjData, poses: np.ndarray,
                       test: TaskTest | None) -> tuple[dict, str | None]:
        """``(metrics, reason)``: the static metrics at the pregrasp and the grasp, and the reason
        the grasp is rejected before simulating (None: it is simulated)."""
        cfg = self.cfg
        pre = static_metrics(scene, data, poses[0], touch_distance=cfg.touch_distance_m,
                             contact_distance=cfg.contact_distance_m, with_self=False).penetration
        met = static_metrics(scene, data, poses[1], touch_distance=cfg.touch_distance_m,
                             contact_distance=cfg.contact_distance_m)
        common = dict(pre=pre, met=met, eps=self.epsilon(met))
        if pre > cfg.max_pregrasp_penetration_m:
            return common, Reason.PENETRATION.value
        min_links = cfg.min_touching_links if test is None or test.min_touching_links is None else test.min_touching_links
        return common, Reason.NO_CONTACT.value if met.touching_links < min_links else None

    def _close(self, scene: Scene, closed: mujoco.MjData, poses: np.ndarray, test: TaskTest | None):
        """``(closed, pos0, quat0, steps)``: the hand driven pregrasp -> grasp -> squeeze in
        ``closed``, the object pose the test measures from (its start, or the closed hand's for
        a task measured from there) and the steps taken; ``closed`` None when the closing blew up."""
        initial_state(scene, closed, poses[0])
        pos0, quat0 = closed.xpos[scene.object_body].copy(), closed.xquat[scene.object_body].copy()
        close_hand(scene, closed, poses, self.cfg)
        if test is not None and test.measure_from == "closed":
            # from where the closed hand holds it (the paper's task test: the hand fixed at the
            # grasp, the wrench applied, the object unmoved)
            pos0, quat0 = closed.xpos[scene.object_body].copy(), closed.xquat[scene.object_body].copy()
        n0 = int(round(closed.time / self.cfg.timestep_s))
        if closed.warning[mujoco.mjtWarning.mjWARN_BADQACC].number or not np.all(np.isfinite(closed.qpos)):
            return None, pos0, quat0, n0
        return closed, pos0, quat0, n0


def six_direction_wrenches(cfg: EvalConfig, mass: float) -> np.ndarray:
    """``(6, 6)`` the six-direction protocol's disturbances: a force of ``force_per_kg`` x mass
    (N) along +-x, +-y, +-z (`DIRECTIONS` order), no torque."""
    f = cfg.force_per_kg * mass
    return np.array([[*(f * np.asarray(d)), 0.0, 0.0, 0.0] for d in DIRECTIONS])


def task_wrenches(test: TaskTest, cfg: EvalConfig, mass: float, scale: float) -> np.ndarray:
    """``(1, 6)`` a task test's disturbance -w_t on the object's joint, scaled as its YAML says."""
    return test.disturbance(mass, scale, cfg.force_per_kg)[None]


def _failure_reason(dirs: list[DirectionResult], test: TaskTest | None) -> str | None:
    """The reason code of held directions (None: all passed): unstable, the first direction
    that slipped (six directions) or ``slipped_task``."""
    failed = [i for i, d in enumerate(dirs) if d.success is False]
    if not failed:
        return None
    if any(dirs[i].unstable for i in failed):
        return Reason.UNSTABLE.value
    return Reason.slipped(DIRECTION_NAMES[failed[0]]) if test is None else Reason.SLIPPED_TASK.value


def _bisect(grid: tuple, held_at_one: bool, holds) -> tuple[float, tuple]:
    """``(held multiple, tested)``: bisection on ``grid`` for the largest multiple ``holds(k)``
    holds, from the verdict at 1 (grid[lo] held, lo -1: nothing known held; grid[hi] failed, hi
    len(grid): nothing known to fail; until they are neighbours)."""
    one = grid.index(1.0)
    lo, hi = (one, len(grid)) if held_at_one else (-1, one)
    tested = [(1.0, held_at_one)]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        ok = holds(grid[mid])
        tested.append((grid[mid], ok))
        lo, hi = (mid, hi) if ok else (lo, mid)
    return (grid[lo] if lo >= 0 else 0.0), tuple(tested)


@dataclass(frozen=True)
class _Verdict:
    """Builds a `GraspResult` of one test for a hand (``n_dir`` directions)."""

    hand: object
    name: str
    n_dir: int

    def __call__(self, reason: str, success: bool = False, dirs: list[DirectionResult] | None = None,
                 pre: float = math.nan, met: StaticMetrics | None = None, eps: float = math.nan,
                 steps: int = 0, table: float = math.nan) -> GraspResult:
        nan, F = (math.nan,) * self.n_dir, len(self.hand.fingertip_names)
        return GraspResult(
            success=success, reason=reason, test=self.name,
            direction_success=tuple(d.success for d in dirs) if dirs else (None,) * self.n_dir,
            direction_translation_m=tuple(d.translation_m for d in dirs) if dirs else nan,
            direction_rotation_deg=tuple(d.rotation_deg for d in dirs) if dirs else nan,
            pregrasp_penetration_m=pre,
            penetration_m=met.penetration if met else math.nan,
            self_penetration_m=met.self_penetration if met else math.nan,
            min_distance_m=met.min_distance if met else math.nan,
            finger_distance_m=tuple(float(x) for x in met.finger_distance) if met else (math.nan,) * F,
            touching_links=met.touching_links if met else 0,
            num_contacts=len(met.contact_points) if met else 0,
            epsilon=eps, sim_steps=steps, table_penetration_m=table)
