"""Typed configuration of grasp synthesis, loadable from YAML (one ``from_dict`` each)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields

from datagen.config import Config
from datagen.errors import ConfigError
from datagen.tasks import InitConfig, TaskSpec  # noqa: F401  (re-exported: the tasks live in datagen.tasks)
from datagen.wrench.contact import ContactModel

__all__ = ["ConfigError", "ContactModel", "EnergyWeights", "SynthConfig"]


@dataclass(frozen=True)
class EnergyWeights(Config):
    """Weights of the energy terms; 0 disables a term. Units make each term ~1 at a typical error."""

    task: float = 1.0  #: mean over K of -cos(s_Wt, s_Wg) (dimensionless, in [-1, 1])
    distance: float = 1e4  #: per m^2 of summed squared fingertip-surface distance (1 cm -> 1)
    penetration: float = 1e5  #: per m^2 of summed squared sphere penetration (1 mm -> 0.1)
    self_penetration: float = 1e5  #: per m^2 of summed squared sphere-pair overlap
    joint_limits: float = 1e2  #: per rad of summed joint-limit violation
    link_distance: float = 1e4  #: per m^2 of summed squared gap of a grasp type's pulled links (the palm of a power grasp)

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and v >= 0 and math.isfinite(v)):
                raise ConfigError(f"EnergyWeights.{f.name} must be a finite number >= 0, got {v!r}")


@dataclass(frozen=True)
class SynthConfig(Config):
    """Optimizer and energy settings. The defaults are the library's (the paper's single start,
    ARCHITECTURE.md "Synthesis"); what a job or ``datagen synth`` runs is the resolved recipe
    (`datagen.pipeline.resolve`: a preset, the task's ``synth:`` block and the user's settings
    on top), and ``task`` names the task whose block it holds."""

    iters: int = 500  #: optimizer iterations per pose (the seeds' first seed_select_iter included)
    num_directions: int = 100  #: K, wrench directions resampled every iteration
    contact: ContactModel = field(default_factory=ContactModel)  #: friction, CPN, cone approximation
    task_energy_kind: str = "cos"  #: "cos" (paper) or "l2" (the paper's ablation, bench-tasks)
    weights: EnergyWeights = field(default_factory=EnergyWeights)  #: weights of the energy terms (0 disables one)
    step_translation_m: float = 0.002  #: root translation step of the per-group normalized descent, m
    step_rotation_rad: float = 0.02  #: root rotation step, rad
    step_joint_rad: float = 0.03  #: joint step of each finger group, rad
    step_decay: float = 0.95  #: step multiplier every `decay_every` iterations
    decay_every: int = 50  #: iterations per step decay
    momentum: float = 0.9  #: m <- (momentum * m + g) / 2 on per-group normalized gradients
    squeeze_force_n: float = 10.0  #: largest fingertip grip force of the squeeze, N (best of 2/4/10/20 in MuJoCo holds)
    squeeze_gap_m: float = 0.002  #: extra fingertip travel along the normal at the squeeze (sphere overshoot), m
    squeeze_kp: float = 5.0  #: position-actuator stiffness the squeeze is computed for, N m/rad: the evaluation's
                             #: for this hand (its protocol's gains), set by the resolver (not a setting of its own)
    contact_threshold_m: float = 0.005  #: fingertips closer than this count as in contact
    sphere_margin_m: float | None = None  #: m collision spheres may sink into the object (None: the hand spec's times sphere_margin_scale)
    sphere_margin_scale: float = 1.0  #: the hand spec's sphere margin is multiplied by this where sphere_margin_m is null (a grasp type's setting)
    exact_contacts: bool = False  #: exact mesh SDF for contacts while optimizing (final contacts always exact)
    seeds_per_grasp: int = 1  #: multi-start: initial poses per output grasp; the best after seed_select_iter goes on
    seed_select_iter: int = 120  #: iterations every seed runs before the best seed of each grasp is kept
    seed_contact_gap_m: float = 0.002  #: seed choice: hand links within this of the surface count as contacts, m
    #: seed choice: a seed with a collision sphere deeper than this in the object surface (beyond
    #: the sphere margin) ranks below every seed without one, m (None: depth is not looked at; a
    #: grasp type's setting)
    seed_max_depth_m: float | None = None
    self_pair_skin_m: float = 0.004  #: self-collision pair lists reused while spheres move < half this, m (0: rebuilt every step)
    task_wrench_at_com: bool = False  #: free object, gamma < 180: w_t acts at its centre of mass (as its test applies it), not at the contacts
    pinch_antipodal: float = 0.0  #: two task fingers, gamma = 180: weight within E_t of the pinch's antipodal error (wrench/antipodal.py)
    link_activation_m: float = 0.01  #: a grasp type's extra contact counts in the GWS with bound 1 - gap / this (0 beyond), m
    penetration_pieces: bool = False  #: penetration terms also against the object's convex pieces (what MuJoCo collides: synth/pieces.py)
    seed: int = 0  #: seed of the initial poses and wrench directions (a job: its seed + the shard index)
    task: str = ""  #: the task whose ``synth:`` block this config holds (set by the resolver; "" none)
    grasp_type: str = "precision"  #: the grasp type (name or YAML, datagen/tasks/grasp_types) of the batch's contact set (set per batch from the recipe's grasp_types)

    def for_hand(self, hand) -> "SynthConfig":
        """This config with the hand's own values where it leaves them open (``sphere_margin_m``:
        how far the hand's collision spheres overshoot its collision geometry, from its spec)."""
        if self.sphere_margin_m is None:
            return dataclasses.replace(self, sphere_margin_m=float(hand.sphere_margin_m) * self.sphere_margin_scale)
        return self

    def check_task(self, task) -> None:
        """Refuse (`ConfigError`) a config that does not hold ``task``'s own ``synth:`` block:
        synthesizing with it would silently drop the task's settings (exact contacts, seeds, ...)."""
        if task.synth and self.task != task.name:
            raise ConfigError(f"SynthConfig was resolved for task {self.task!r}, not {task.name!r}: it lacks the "
                              f"task's synth block ({', '.join(sorted(task.synth))})",
                              f"build it with datagen.pipeline.resolve(hand, {task.name!r}).synth")

    def __post_init__(self):
        if self.sphere_margin_m is not None and not 0 <= self.sphere_margin_m < 0.01:
            raise ConfigError(f"SynthConfig.sphere_margin_m must be in [0, 0.01) m or null, got {self.sphere_margin_m}")
        if not (math.isfinite(self.sphere_margin_scale) and 0 <= self.sphere_margin_scale <= 1):
            raise ConfigError(f"SynthConfig.sphere_margin_scale must be in [0, 1], got {self.sphere_margin_scale}")
        if not (math.isfinite(self.self_pair_skin_m) and self.self_pair_skin_m >= 0):
            raise ConfigError(f"SynthConfig.self_pair_skin_m must be a finite number >= 0 m, got {self.self_pair_skin_m}")
        if not (math.isfinite(self.pinch_antipodal) and self.pinch_antipodal >= 0):
            raise ConfigError(f"SynthConfig.pinch_antipodal must be a finite number >= 0, got {self.pinch_antipodal}")
        if self.seed_max_depth_m is not None and not (math.isfinite(self.seed_max_depth_m) and self.seed_max_depth_m > 0):
            raise ConfigError(f"SynthConfig.seed_max_depth_m must be null or a finite number > 0 m, got {self.seed_max_depth_m}")
        if self.seeds_per_grasp < 1 or self.seed_select_iter < 1:
            raise ConfigError(f"SynthConfig: seeds_per_grasp and seed_select_iter must be >= 1, "
                              f"got {self.seeds_per_grasp}, {self.seed_select_iter}")
        if not (math.isfinite(self.link_activation_m) and self.link_activation_m > 0):
            raise ConfigError(f"SynthConfig.link_activation_m must be a finite number > 0 m, got {self.link_activation_m}")
        if self.iters < 1 or self.num_directions < 1:
            raise ConfigError(f"SynthConfig: iters and num_directions must be >= 1, got {self.iters}, {self.num_directions}")
        if self.task_energy_kind not in ("cos", "l2"):
            raise ConfigError(f"SynthConfig.task_energy_kind must be 'cos' or 'l2', got {self.task_energy_kind!r}")
        if not (math.isfinite(self.squeeze_force_n) and self.squeeze_force_n >= 0 and self.squeeze_gap_m >= 0):
            raise ConfigError(f"SynthConfig: squeeze_force_n and squeeze_gap_m must be >= 0, "
                              f"got {self.squeeze_force_n}, {self.squeeze_gap_m}")
