"""Values tuned by hand for the built-in hands, derived from a new hand's geometry instead.

``sphere_margin_m`` (how far synthesis lets the collision spheres sink into an object before they
count as penetrating, `HandSpec`): the spheres overshoot the collision geometry by a varying
amount, up to ``sphere_fit.overshoot``, so a sphere sunk by less than the overshoot where it
touches leaves the real link outside. The margin derived here is the 10th percentile of that
overshoot over the fingertip links' collision surfaces, the pads that carry the contacts: sunk
by it, the real pad stays outside the object at 90% of its surface. On the built-in hands it is
0.8-0.9 mm (their hand-tuned margins: Shadow 1.5 mm, Allegro and LEAP 0.5 mm);
``datagen hand calibrate`` then chooses between it and its neighbours by MuJoCo penetration and
success on procedural objects.

The other hand-tuned values are derived elsewhere: joint couplings from tendons, joint equalities
and URDF mimic joints (`mjcf.detect_couplings`); self-collision pairs from sampled configurations
(`make_spec`); the squeeze's joint stiffness from the actuators' transmissions
(`datagen.synth.squeeze.actuator_compliance`); the initial palm distance by the calibration.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .geometry import link_shapes, sample_link_surface
from .mjcf import FlatHand
from .spec import HandSpec

__all__ = ["Derived", "MARGIN_RANGE_M", "derive_settings", "pad_shell_m"]

MARGIN_RANGE_M = (0.0003, 0.0015)  # derived margins are clipped to this (the built-ins' tuned range)
_MARGIN_QUANTILE = 10               # percent of the pads' surface where the spheres overshoot less


@dataclass(frozen=True)
class Derived:
    values: dict = field(default_factory=dict)    # HandSpec field -> value
    reasons: dict = field(default_factory=dict)   # HandSpec field -> one line: how it was derived


def pad_shell_m(spec: HandSpec, flat: FlatHand, samples: int = 3000, seed: int = 0) -> np.ndarray:
    """(N,) how far the collision spheres reach beyond each sampled point of the fingertip links'
    collision surfaces (m; > 0: the point is inside a sphere's shell)."""
    m = flat.model
    rng = np.random.default_rng(seed)
    out = []
    for link in sorted({t.link for t in spec.fingertips.values()}):
        spheres = np.asarray(spec.spheres.get(link, ()), dtype=np.float64).reshape(-1, 4)
        shapes = link_shapes(m, m.body(link).id)
        if not len(spheres) or not shapes:
            continue
        pts, _ = sample_link_surface(shapes, samples, rng)
        dist = np.linalg.norm(pts[:, None, :] - spheres[None, :, :3], axis=-1)
        out.append((spheres[None, :, 3] - dist).max(axis=1))
    return np.concatenate(out) if out else np.zeros(0)


def derive_settings(spec: HandSpec, flat: FlatHand) -> Derived:
    """The derived values for ``spec`` (see the module docstring)."""
    shell = pad_shell_m(spec, flat)
    lo, hi = MARGIN_RANGE_M
    if len(shell):
        q = float(np.percentile(shell, _MARGIN_QUANTILE))
        margin = round(float(np.clip(q, lo, hi)), 4)
        why = (f"the spheres overshoot the fingertip pads by less than {q * 1000:.2f} mm on "
               f"{_MARGIN_QUANTILE}% of their surface (clipped to {lo * 1000:.1f}-{hi * 1000:.1f} mm)")
    else:
        margin, why = lo, "no fingertip link has spheres and collision geometry: the smallest margin"
    return Derived(values={"sphere_margin_m": margin}, reasons={"sphere_margin_m": why})
