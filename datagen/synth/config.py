"""Typed configuration of grasp synthesis, loadable from YAML (one ``from_dict`` each)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields

from datagen.config import Config
from datagen.errors import ConfigError
from datagen.tasks import InitConfig, TaskSpec  # noqa: F401  (re-exported: the tasks live in datagen.tasks)

__all__ = ["ConfigError", "EnergyWeights", "SynthConfig"]


@dataclass(frozen=True)
class EnergyWeights(Config):
    """Weights of the energy terms; 0 disables a term. Units make each term ~1 at a typical error."""

    task: float = 1.0  #: mean over K of -cos(s_Wt, s_Wg) (dimensionless, in [-1, 1])
    distance: float = 1e4  #: per m^2 of summed squared fingertip-surface distance (1 cm -> 1)
    penetration: float = 1e5  #: per m^2 of summed squared sphere penetration (1 mm -> 0.1)
    self_penetration: float = 1e5  #: per m^2 of summed squared sphere-pair overlap
    joint_limits: float = 1e2  #: per rad of summed joint-limit violation

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and v >= 0 and math.isfinite(v)):
                raise ConfigError(f"EnergyWeights.{f.name} must be a finite number >= 0, got {v!r}")


#: seeds per grasp of force-closure synthesis by default (``datagen synth`` and the job default):
#: the best of 8 starts (by the whole hand's epsilon) raised six-direction success on the
#: real-object set from 38% to 73% (Shadow, default scales); 16 starts raise Shadow's 0.08 m
#: probe from 68% to 82% (two seeds, 112 grasps each; benchmarks/results/quality.md)
FORCE_CLOSURE_SEEDS = 16


@dataclass(frozen=True)
class SynthConfig(Config):
    """Optimizer and energy settings (defaults follow the paper and ARCHITECTURE.md "Synthesis")."""

    iters: int = 500
    num_directions: int = 100  #: K, wrench directions resampled every iteration
    delta_deg: float = 15.0
    mu: float = 0.5  #: friction coefficient of the GWS model
    normalize: bool = True  #: contact position normalization
    contact_model: str = "pcf"  #: "pcf" point contact with friction, "sfc" soft finger (torsional friction)
    torsional_mu: float = 0.0  #: SFC torsional friction coefficient, m (torque <= torsional_mu * normal force)
    task_energy_kind: str = "cos"  #: "cos" (paper) or "l2" (ablation)
    weights: EnergyWeights = field(default_factory=EnergyWeights)
    step_translation_m: float = 0.002
    step_rotation_rad: float = 0.02
    step_joint_rad: float = 0.03
    step_decay: float = 0.95  #: step multiplier every `decay_every` iterations
    decay_every: int = 50
    momentum: float = 0.9  #: m <- (momentum * m + g) / 2 on per-group normalized gradients
    squeeze_mode: str = "force"  #: pregrasp/squeeze: "force" (balanced grip forces), "normal" or "joint" (see squeeze.py)
    squeeze_force_n: float = 10.0  #: "force": largest fingertip grip force, N (10 N: best of 2/4/10/20 in MuJoCo holds)
    squeeze_kp: float = 5.0  #: "force": position-actuator stiffness the squeeze is computed for, N m/rad (eval protocol)
    squeeze_gap_m: float = 0.002  #: "force": extra fingertip travel along the normal (sphere overshoot), m
    squeeze_mount: bool = True  #: "force"/"hand" on a mounted task object: balance only the force along its joint
    squeeze_m: float = 0.01  #: "normal": fingertips move this far out (pregrasp) / in (squeeze) along the normals
    squeeze_rad: float = 0.1  #: "joint": pregrasp opens each joint by up to this towards the open pose
    contact_threshold_m: float = 0.005  #: fingertips closer than this count as in contact
    sphere_margin_m: float | None = None  #: m collision spheres may sink into the object (None: the hand spec's, see for_hand)
    touch_real_gaps: bool = False  #: after optimizing, move each task fingertip in by its real (not sphere) gap (touch.py)
    exact_contacts: bool = False  #: exact mesh SDF for contacts while optimizing (final contacts always exact)
    seeds_per_grasp: int = 1  #: multi-start: initial poses per output grasp; the best after seed_select_iter goes on
    seed_select_iter: int = 120  #: iterations every seed runs before the best seed of each grasp is kept
    seeds_kept: int = 1  #: seeds of each grasp that go on after seed_select_iter; the best of them at the end
    seed_halving_iter: int = 0  #: 0: off; else at this iteration (< seed_select_iter) each grasp's better half goes on
    seed_contact_gap_m: float = 0.002  #: seed choice: hand links within this of the surface count as contacts, m
    self_pair_skin_m: float = 0.004  #: self-collision pair lists reused while spheres move < half this, m (0: rebuilt every step)
    task_wrench_at_com: bool = False  #: free object, gamma < 180: w_t acts at its centre of mass (as its test applies it), not at the contacts
    task_seed_score: bool = True  #: gamma < 180, task energy on: seed choice by whole-hand task epsilon, else energy
    pinch_antipodal: float = 0.0  #: two task fingers, gamma = 180: weight within E_t of the pinch's antipodal error (wrench/antipodal.py)
    seed: int = 0

    def for_task(self, task) -> "SynthConfig":
        """This config over the task's own ``synth:`` block (`datagen.tasks.TaskSpec.synth_settings`):
        the task's settings replace the defaults, and every field this config sets to a value other
        than SynthConfig's default wins over the task (a job's ``synth:`` mapping, a CLI flag)."""
        if not task.synth:
            return self
        mine, default = self.to_dict(), SynthConfig().to_dict()
        explicit = {k: v for k, v in mine.items() if k != "weights" and v != default[k]}
        weights = {k: v for k, v in mine["weights"].items() if v != default["weights"][k]}
        if weights:
            explicit["weights"] = weights
        return SynthConfig.from_dict(task.synth_settings(explicit), where=f"task {task.name!r} synth")

    def for_hand(self, hand) -> "SynthConfig":
        """This config with the hand's own values where it leaves them open (``sphere_margin_m``:
        how far the hand's collision spheres overshoot its collision geometry, from its spec)."""
        if self.sphere_margin_m is None:
            return dataclasses.replace(self, sphere_margin_m=float(hand.sphere_margin_m))
        return self

    def __post_init__(self):
        if self.sphere_margin_m is not None and not 0 <= self.sphere_margin_m < 0.01:
            raise ConfigError(f"SynthConfig.sphere_margin_m must be in [0, 0.01) m or null, got {self.sphere_margin_m}")
        if not (math.isfinite(self.self_pair_skin_m) and self.self_pair_skin_m >= 0):
            raise ConfigError(f"SynthConfig.self_pair_skin_m must be a finite number >= 0 m, got {self.self_pair_skin_m}")
        if not (math.isfinite(self.pinch_antipodal) and self.pinch_antipodal >= 0):
            raise ConfigError(f"SynthConfig.pinch_antipodal must be a finite number >= 0, got {self.pinch_antipodal}")
        if self.seed_halving_iter < 0:
            raise ConfigError(f"SynthConfig.seed_halving_iter must be >= 0 (0: off), got {self.seed_halving_iter}")
        if self.seeds_per_grasp < 1 or self.seed_select_iter < 1 or self.seeds_kept < 1:
            raise ConfigError(f"SynthConfig: seeds_per_grasp, seed_select_iter and seeds_kept must be >= 1, "
                              f"got {self.seeds_per_grasp}, {self.seed_select_iter}, {self.seeds_kept}")
        if self.iters < 1 or self.num_directions < 1:
            raise ConfigError(f"SynthConfig: iters and num_directions must be >= 1, got {self.iters}, {self.num_directions}")
        if self.task_energy_kind not in ("cos", "l2"):
            raise ConfigError(f"SynthConfig.task_energy_kind must be 'cos' or 'l2', got {self.task_energy_kind!r}")
        if not 0 <= self.delta_deg <= 45:
            raise ConfigError(f"SynthConfig.delta_deg must lie in [0, 45], got {self.delta_deg}")
        if self.contact_model not in ("pcf", "sfc") or self.torsional_mu < 0:
            raise ConfigError(f"SynthConfig.contact_model must be 'pcf' or 'sfc' and torsional_mu >= 0, "
                              f"got {self.contact_model!r}, {self.torsional_mu}")
        if self.squeeze_mode not in ("hand", "force", "normal", "joint"):
            raise ConfigError(f"SynthConfig.squeeze_mode must be 'hand', 'force', 'normal' or 'joint', "
                              f"got {self.squeeze_mode!r}")
        if not self.mu > 0:
            raise ConfigError(f"SynthConfig.mu must be > 0, got {self.mu}")
