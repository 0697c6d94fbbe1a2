"""`Evaluator`: one grasp in, one verdict with a reason code and its metrics out.

Order of decisions (the first that applies is the reason):

1. ``invalid_grasp``: a pose is not finite (a wrong row length is an input error and raises);
2. ``penetration``: a hand-object contact at the pregrasp is deeper than
   ``max_pregrasp_penetration_m`` (the public protocol's rejection before simulating);
3. ``no_contact``: fewer than ``min_touching_links`` hand links within ``touch_distance_m`` of
   the object at the grasp pose (so the squeeze alone cannot make a grasp);
4. optional filters at the grasp pose: ``grasp_penetration``, ``self_penetration``, ``low_epsilon``;
5. the simulated test: ``unstable`` (the simulation diverged), ``slipped_<dir>`` (the first
   direction, in ``+x -x +y -y +z -z`` order, failing at the earliest failing check) or
   ``slipped_task`` for a task test; else ``ok``. The object's motion is measured from its
   initial pose (the public protocol), or for a task test with ``measure_from: closed`` from its
   pose once the hand has closed (the paper's task test: hand fixed, object unmoved under -w_t).

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
    GRASP_PENETRATION = "grasp_penetration"
    SELF_PENETRATION = "self_penetration"
    LOW_EPSILON = "low_epsilon"
    UNSTABLE = "unstable"
    SLIPPED_TASK = "slipped_task"

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


@dataclass(frozen=True)
class TaskMargin:
    """The largest multiple of a test's disturbance that a grasp holds (`Evaluator.margin`).

    ``result``: the verdict at the test's own magnitude (identical to `Evaluator.evaluate`).
    ``held_multiple``: the largest multiple of the grid held, found by bisection: above 1 if the
    grasp holds at 1, below it otherwise; 0 when it holds none (or was rejected before
    simulating: penetration, no contact, filters, invalid). Assumes that holding a disturbance
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
    def scene(self, pieces: ObjectPieces, task: TaskTest | None = None) -> tuple[Scene, list[mujoco.MjData]]:
        """The cached scene of ``pieces`` (object joint from ``task``) and its scratch MjData."""
        joint = None if task is None or task.joint == "free" else (task.joint, task.axis, task.anchor, task.limits)
        key = (pieces.paths, pieces.volumes, pieces.scale, joint, () if task is None else task.scenery)
        if key in self._scenes:
            self._scenes.move_to_end(key)
            return self._scenes[key]
        scene = build_scene(self.hand, pieces, self.cfg, task)
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
                 w_t=None) -> GraspResult:
        """Evaluate one grasp.

        Args:
            pieces: the object (normalized pieces and the scale in metres).
            poses: (3, 7 + J) pregrasp, grasp, squeeze rows [x y z qw qx qy qz, joints] in the
                object frame (metres, radians), joints in ``hand.joint_names`` order.
            task: a hold task (six directions) or a task of ``cfg.tasks``.
            w_t: (6,) the row's task wrench; for a task test it replaces the configured ``w_t``
                (the joint, axis and scaling stay the config's). Ignored for hold tasks.
        """
        return self._run(pieces, poses, task, w_t, None).result

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
        cfg = self.cfg
        test = cfg.task_test(task)  # raises EvalError for an unknown task
        if test is not None and w_t is not None:
            test = dataclasses.replace(test, w_t=tuple(float(x) for x in w_t))
        poses = np.asarray(poses, dtype=np.float64)
        width = 7 + self.hand.num_joints
        if poses.shape != (3, width):
            raise EvalError(f"grasp of hand {self.hand.name!r}",
                            f"poses have shape {poses.shape}, expected (3, {width})",
                            "rows are [x y z qw qx qy qz] + joints in the hand MJCF's joint order")
        scene, datas = self.scene(pieces, test)
        n_dir = len(DIRECTIONS) if test is None else 1
        name = "six_direction" if test is None else task
        nan = (math.nan,) * n_dir

        def result(reason: str, success: bool = False, dirs: list[DirectionResult] | None = None,
                   pre: float = math.nan, met: StaticMetrics | None = None, eps: float = math.nan,
                   steps: int = 0) -> GraspResult:
            F = len(self.hand.fingertip_names)
            return GraspResult(
                success=success, reason=reason, test=name,
                direction_success=tuple(d.success for d in dirs) if dirs else (None,) * n_dir,
                direction_translation_m=tuple(d.translation_m for d in dirs) if dirs else nan,
                direction_rotation_deg=tuple(d.rotation_deg for d in dirs) if dirs else nan,
                pregrasp_penetration_m=pre,
                penetration_m=met.penetration if met else math.nan,
                self_penetration_m=met.self_penetration if met else math.nan,
                min_distance_m=met.min_distance if met else math.nan,
                finger_distance_m=tuple(float(x) for x in met.finger_distance) if met else (math.nan,) * F,
                touching_links=met.touching_links if met else 0,
                num_contacts=len(met.contact_points) if met else 0,
                epsilon=eps, sim_steps=steps)

        def done(res: GraspResult, held: float = 0.0, tested: tuple = ()) -> TaskMargin:
            return TaskMargin(res, held, held * magnitude, tested)

        if test is None:
            magnitude = cfg.force_per_kg * scene.object_mass
        else:
            w = test.disturbance(scene.object_mass, pieces.scale, cfg.force_per_kg)
            magnitude = float(np.linalg.norm(w[:3]) if np.any(w[:3]) else np.linalg.norm(w[3:]))

        if not np.all(np.isfinite(poses)) or np.any(np.linalg.norm(poses[:, 3:7], axis=1) < 1e-9):
            return done(result(Reason.INVALID_GRASP.value))
        static = datas[-1]
        pre = static_metrics(scene, static, poses[0], touch_distance=cfg.touch_distance_m,
                             contact_distance=cfg.contact_distance_m, with_self=False).penetration
        met = static_metrics(scene, static, poses[1], touch_distance=cfg.touch_distance_m,
                             contact_distance=cfg.contact_distance_m)
        eps = self.epsilon(met)
        common = dict(pre=pre, met=met, eps=eps)
        if pre > cfg.max_pregrasp_penetration_m:
            return done(result(Reason.PENETRATION.value, **common))
        min_links = cfg.min_touching_links if test is None or test.min_touching_links is None else test.min_touching_links
        if met.touching_links < min_links:
            return done(result(Reason.NO_CONTACT.value, **common))
        if cfg.filter_max_penetration_m is not None and met.penetration > cfg.filter_max_penetration_m:
            return done(result(Reason.GRASP_PENETRATION.value, **common))
        if cfg.filter_max_self_penetration_m is not None and met.self_penetration > cfg.filter_max_self_penetration_m:
            return done(result(Reason.SELF_PENETRATION.value, **common))
        if cfg.filter_min_epsilon is not None and eps < cfg.filter_min_epsilon:
            return done(result(Reason.LOW_EPSILON.value, **common))

        closed = datas[-2]
        initial_state(scene, closed, poses[0])
        pos0 = closed.xpos[scene.object_body].copy()
        quat0 = closed.xquat[scene.object_body].copy()
        close_hand(scene, closed, poses, cfg)
        if test is not None and test.measure_from == "closed":
            # from where the closed hand holds it (the paper's task test: the hand fixed at the
            # grasp, the wrench applied, the object unmoved)
            pos0 = closed.xpos[scene.object_body].copy()
            quat0 = closed.xquat[scene.object_body].copy()
        n0 = int(round(closed.time / cfg.timestep_s))
        if closed.warning[mujoco.mjtWarning.mjWARN_BADQACC].number or not np.all(np.isfinite(closed.qpos)):
            dirs = [DirectionResult(False, math.inf, math.inf, True)] * n_dir
            return done(result(Reason.UNSTABLE.value, False, dirs, steps=n0, **common))
        mass = scene.object_mass
        if test is None:
            f = cfg.force_per_kg * mass
            wrenches = np.array([[*(f * np.asarray(d)), 0.0, 0.0, 0.0] for d in DIRECTIONS])
        else:
            wrenches = test.disturbance(mass, pieces.scale, cfg.force_per_kg)[None]
        pool = self._hold_pool()
        dirs = hold(scene, closed, wrenches, datas[:len(wrenches)], pos0, quat0, self._hold_config(test), pool)
        steps = n0 + sum(int(round(d.time / cfg.timestep_s)) - n0 for d in datas[:len(wrenches)])
        failed = [i for i, d in enumerate(dirs) if d.success is False]
        if not failed:
            res = result(Reason.OK.value, True, dirs, steps=steps, **common)
        else:
            if any(dirs[i].unstable for i in failed):
                reason = Reason.UNSTABLE.value
            elif test is None:
                reason = Reason.slipped(DIRECTION_NAMES[failed[0]])
            else:
                reason = Reason.SLIPPED_TASK.value
            res = result(reason, False, dirs, steps=steps, **common)
        if grid is None:
            return done(res)
        hold_cfg = self._hold_config(test)

        def holds(k: float) -> bool:
            out = hold(scene, closed, k * wrenches, datas[:len(wrenches)], pos0, quat0, hold_cfg, pool)
            return all(d.success for d in out)

        # bisection: grid[lo] held (lo -1: nothing known held), grid[hi] failed (hi len(grid):
        # nothing known to fail), until they are neighbours
        one = grid.index(1.0)
        lo, hi = (one, len(grid)) if res.success else (-1, one)
        tested = [(1.0, res.success)]
        while hi - lo > 1:
            mid = (lo + hi) // 2
            ok = holds(grid[mid])
            tested.append((grid[mid], ok))
            lo, hi = (mid, hi) if ok else (lo, mid)
        return done(res, grid[lo] if lo >= 0 else 0.0, tuple(tested))
