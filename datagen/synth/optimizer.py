"""Batched gradient descent with per-group normalized steps, momentum and a greedy line search.

Variables of a hand pose: root translation (m), root rotation (a rotation vector applied on the
left of the current quaternion, rad) and joints (rad), the joints split into groups (wrist, each
finger). Each group's gradient is normalized per sample, filtered by the momentum
``m <- (beta m + g) / 2`` and scaled by the group's step, which decays by ``step_decay`` every
``decay_every`` iterations. The candidate is kept only where it lowers that sample's energy
(greedy single-candidate line search); a rejected sample halves its own step scale and an
accepted one grows it back (x1.25, at most 1); a rejected sample also restarts its momentum. One forward and one backward pass per iteration:
the candidate is evaluated with its gradient, which is reused when it is accepted.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from datagen.synth.rotation import axis_angle_to_quat, quat_multiply

__all__ = ["PoseVariables", "GroupedDescent"]


@dataclass
class PoseVariables:
    """A batch of hand poses: translation (B, 3) m, unit quaternion (B, 4), joints (B, J) rad."""

    translation: torch.Tensor
    quaternion: torch.Tensor
    joints: torch.Tensor

    def root_pose(self) -> torch.Tensor:
        return torch.cat([self.translation, self.quaternion], dim=-1)

    def where(self, mask: torch.Tensor, other: "PoseVariables") -> "PoseVariables":
        m = mask[:, None]
        return PoseVariables(torch.where(m, self.translation, other.translation),
                             torch.where(m, self.quaternion, other.quaternion),
                             torch.where(m, self.joints, other.joints))


def _normalize_groups(g: torch.Tensor, groups: list[torch.Tensor]) -> torch.Tensor:
    out = torch.zeros_like(g)
    for idx in groups:
        gg = g[:, idx]
        out[:, idx] = gg / gg.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    return out


class GroupedDescent:
    """The optimizer; ``energy_fn(translation, rot_vec, joints) -> (B,)`` energy, differentiable.

    ``project(joints)`` maps joints back onto limits/couplings after each step.
    """

    def __init__(self, joint_groups: list[torch.Tensor], steps: tuple[float, float, float], *,
                 momentum: float = 0.9, step_decay: float = 0.95, decay_every: int = 50, project=None):
        self.joint_groups = joint_groups
        self.step_t, self.step_r, self.step_j = steps
        self.beta, self.decay, self.decay_every = momentum, step_decay, decay_every
        self.project = project or (lambda j: j)

    def _evaluate(self, energy_fn, x: PoseVariables):
        t = x.translation.detach().requires_grad_(True)
        w = torch.zeros_like(t).requires_grad_(True)
        j = x.joints.detach().requires_grad_(True)
        q = quat_multiply(axis_angle_to_quat(w), x.quaternion.detach())
        e, extras = energy_fn(t, q, j)
        gt, gw, gj = torch.autograd.grad(e.sum(), (t, w, j))
        return e.detach(), (gt, gw, gj), extras

    def run(self, energy_fn, x: PoseVariables, iters: int, callback=None, first_iter: int = 0):
        """Optimize ``x`` for ``iters`` iterations; returns the final variables, energy and extras.

        ``first_iter`` continues an earlier run's schedule: the step starts decayed as at that
        iteration (momentum and per-sample step scales start afresh)."""
        e, g, extras = self._evaluate(energy_fn, x)
        m = [torch.zeros_like(gi) for gi in g]
        B = x.translation.shape[0]
        scale = torch.ones(B, 1, dtype=x.translation.dtype, device=x.translation.device)
        step = self.decay ** (first_iter // self.decay_every)
        for it in range(first_iter, first_iter + iters):
            if it > first_iter and it % self.decay_every == 0:
                step *= self.decay
            gn = (g[0] / g[0].norm(dim=-1, keepdim=True).clamp_min(1e-12),
                  g[1] / g[1].norm(dim=-1, keepdim=True).clamp_min(1e-12),
                  _normalize_groups(g[2], self.joint_groups))
            m = [(self.beta * mi + gi) / 2 for mi, gi in zip(m, gn)]
            s = step * scale
            cand = PoseVariables(
                x.translation - self.step_t * s * m[0],
                quat_multiply(axis_angle_to_quat(-self.step_r * s * m[1]), x.quaternion),
                self.project(x.joints - self.step_j * s * m[2]),
            )
            cand.quaternion = cand.quaternion / cand.quaternion.norm(dim=-1, keepdim=True)
            e_c, g_c, extras_c = self._evaluate(energy_fn, cand)
            ok = e_c < e
            x = cand.where(ok, x)
            e = torch.where(ok, e_c, e)
            g = tuple(torch.where(ok[:, None], a, b) for a, b in zip(g_c, g))
            extras = {k: torch.where(ok.reshape((-1,) + (1,) * (v.dim() - 1)), v, extras[k]) for k, v in extras_c.items()}
            scale = torch.where(ok[:, None], (scale * 1.25).clamp_max(1.0), scale * 0.5).clamp_min(1e-4)
            m = [torch.where(ok[:, None], mi, torch.zeros_like(mi)) for mi in m]  # rejected: restart momentum
            if callback is not None:
                callback(it, x, e, ok)
        return x, e, extras
