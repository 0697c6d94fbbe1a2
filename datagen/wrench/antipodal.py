"""The antipodal error of a two-contact pinch: how far its contact normals turn from its axis.

Two point contacts with friction hold a free object in force closure only if the line through
them lies inside both friction cones (the antipodal condition). Their grasp wrench space has no
interior (no torque about that line), so at gamma = 180 deg the epsilon metric is 0 for every
pinch and the cosine task energy (eq. 8) scores a pinch centred on two faces (-0.79) about as a
near-miss whose fingertips sit on the faces' edges; in MuJoCo the edge pinches twist the object
out as the hand closes (`benchmarks/results/tasks.md`, sessions 19 and 22). This error measures
the pinch's margin directly. It is not in the paper: an addition for two-finger precision tasks
(`SynthConfig.pinch_antipodal`).
"""

from __future__ import annotations

import torch

from datagen.wrench._geometry import safe_normalize


def pinch_antipodal_error(points: torch.Tensor, normals: torch.Tensor) -> torch.Tensor:
    """``(...)``: ``(1 - n0 . u) + (1 + n1 . u)`` of two contacts ``points (..., 2, 3)`` m with unit
    normals ``normals (..., 2, 3)`` pointing into the object, ``u`` the unit axis from contact 0 to
    contact 1. 0 when both normals lie on the axis facing each other; ``1 - cos(a)`` for a normal
    turned by ``a`` from it; symmetric in the two contacts."""
    u = safe_normalize(points[..., 1, :] - points[..., 0, :])
    return (1 - (normals[..., 0, :] * u).sum(-1)) + (1 + (normals[..., 1, :] * u).sum(-1))
