"""`ContactModel`: how synthesis models each contact's wrenches (paper Sec. IV-A).

Point contacts with friction (PCF) under the L-infinity bound (each normal force <= 1): the
friction coefficient of the cones, the finite cone's approximation (eq. 6, ``delta_deg``; 0 is
the exact eq. 5) and contact position normalization (CPN). The functions of this package take
these as arguments; the model carries them as one value from a config to every caller (the
energies, the seed choice, the squeeze's grip forces and the final epsilon).
Shapes as in the package: points ``(..., m, 3)`` metres, normals ``(..., m, 3)`` unit, inward.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from datagen.config import Config
from datagen.errors import ConfigError

__all__ = ["ContactModel"]


@dataclass(frozen=True)
class ContactModel(Config):
    """Friction and GWS-estimator settings of a contact set (defaults: the paper's)."""

    mu: float = 0.5  #: friction coefficient of the contact cones
    normalize: bool = True  #: contact position normalization (CPN) before building the grasp matrices
    delta_deg: float = 15.0  #: eq. 6's cone approximation, degrees in [0, 45] (0: the exact eq. 5)

    def __post_init__(self):
        if not (math.isfinite(self.mu) and self.mu > 0):
            raise ConfigError(f"ContactModel.mu must be a finite number > 0, got {self.mu}")
        if not 0 <= self.delta_deg <= 45:
            raise ConfigError(f"ContactModel.delta_deg must lie in [0, 45], got {self.delta_deg}")

    def epsilon(self, points: torch.Tensor, normals: torch.Tensor, **kw) -> torch.Tensor:
        """``(...)`` the epsilon metric (`datagen.wrench.epsilon_metric`) of these contacts."""
        from datagen.wrench.epsilon import epsilon_metric

        return epsilon_metric(points, normals, self.mu, normalize=self.normalize, **kw)

    def task_epsilon(self, points: torch.Tensor, normals: torch.Tensor, w_t, gamma_deg, **kw) -> torch.Tensor:
        """``(...)`` the task epsilon (`datagen.wrench.task_epsilon`) over the TWS sector."""
        from datagen.wrench.epsilon import task_epsilon

        return task_epsilon(points, normals, self.mu, w_t, gamma_deg, normalize=self.normalize, **kw)

    def task_energy(self, points: torch.Tensor, normals: torch.Tensor, w_t, gamma_deg, directions: torch.Tensor,
                    kind: str = "cos", weights: torch.Tensor | None = None) -> torch.Tensor:
        """``(...)`` E_t (eq. 8, `datagen.wrench.task_energy`) over ``directions (K, 6)``;
        ``weights (..., m)``: each contact's normal-force bound (None: 1 each, the paper's)."""
        from datagen.wrench.tws import task_energy

        return task_energy(points, normals, self.mu, w_t, gamma_deg, directions, kind=kind,
                           delta_deg=self.delta_deg, normalize=self.normalize, weights=weights)
