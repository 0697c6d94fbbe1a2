"""Whose hand gains the hold test uses: ``EvalConfig.protocol``.

Everything else in the six-direction test is one protocol (`EvalConfig`: physics, contacts,
object, forces, thresholds, hold); the hand's position actuators are where published evaluations
differ. Two choices:

* ``"dexgraspbench"`` (default): DexGraspBench's own hand files (JYChen18/DexGraspBench 1e7a5a6,
  ``assets/hand/<hand>/right_hand.xml``) for the hands it shares with this project, `PEER_GAINS`
  below; any other hand (the gymnasium-robotics Shadow, a user's hand) gets ``actuator_kp`` and
  +-``actuator_force_limit`` as under ``"uniform"``, i.e. the gains of DexGraspBench's Shadow. The
  hands' joint damping and friction are their assets' (the built-in LEAP and Allegro are
  Menagerie's, `datagen.hands.menagerie`, whose damping the peer's files keep).
* ``"uniform"``: every hand at ``actuator_kp``, force +-``actuator_force_limit`` and actuator
  damping kv at most ``actuator_kp * actuator_time_constant_s`` (the project's evaluation up to
  this choice; the same gains for every hand).

The two differ only for LEAP and Allegro. Agreement of each with DexGraspBench's own evaluator:
benchmarks/results/interop.md.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["HandGains", "PEER_GAINS", "PROTOCOLS", "hand_gains"]

PROTOCOLS = ("dexgraspbench", "uniform")


@dataclass(frozen=True)
class HandGains:
    """Position-actuator settings of one hand in the evaluation scene."""

    kp: float                    #: stiffness, N m / rad (N / m for slides)
    kv: float                    #: velocity damping (bias -kv qdot)
    force_limit: float | None    #: symmetric force range; None: unlimited
    source: str = ""             #: where the values come from


# DexGraspBench's hand files (their position actuators and, for LEAP, the Menagerie file it includes)
PEER_GAINS: dict[str, HandGains] = {
    "shadow_e3m5": HandGains(5.0, 0.0, 3.0, "assets/hand/shadow/right_hand.xml: <position forcerange=\"-3 3\" kp=\"5\"/>"),
    "allegro": HandGains(5.0, 0.0, None, "assets/hand/allegro/right_hand.xml: <position kp=\"5\"/> (no kv, no forcerange)"),
    "leap": HandGains(3.0, 0.01, None, "MuJoCo Menagerie leap_hand/right_hand.xml, included unchanged: "
                                       "<position kp=\"3.0\" kv=\"0.01\"/> (no forcerange)"),
}


def hand_gains(cfg, hand_name: str, asset_kv: float) -> HandGains:
    """The gains of hand ``hand_name`` under ``cfg`` (an `EvalConfig`); ``asset_kv`` is the
    actuator's own damping in the hand asset (kept under "uniform" up to the time-constant cap)."""
    if cfg.protocol == "dexgraspbench" and hand_name in PEER_GAINS:
        return PEER_GAINS[hand_name]
    kv = min(max(float(asset_kv), 0.0), cfg.actuator_kp * cfg.actuator_time_constant_s)
    return HandGains(cfg.actuator_kp, kv, cfg.actuator_force_limit, "EvalConfig actuator_kp / actuator_force_limit")
