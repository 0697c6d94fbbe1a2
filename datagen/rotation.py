"""Rotations, in one place: quaternions ``[qw, qx, qy, qz]`` (Hamilton convention, MuJoCo's
order), rotation vectors (radians) and 3x3 matrices acting on column vectors.

Torch functions are batched over leading dimensions and differentiable (synthesis, hand
kinematics); the ``*_np`` functions are their NumPy counterparts for the simulator side.
"""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["axis_angle_to_quat", "matrix_to_quat", "quat_angle_np", "quat_multiply", "quat_to_matrix",
           "quat_to_matrix_np", "rotate_about"]


def quat_to_matrix(quat: torch.Tensor) -> torch.Tensor:
    """``(..., 4)`` quaternions [w x y z] (normalized first) -> ``(..., 3, 3)`` rotation matrices."""
    q = quat / quat.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1).reshape(q.shape[:-1] + (3, 3))


def axis_angle_to_quat(omega: torch.Tensor) -> torch.Tensor:
    """``(..., 3)`` rotation vectors (radians) -> ``(..., 4)`` unit quaternions; smooth at 0."""
    theta_sq = (omega * omega).sum(-1, keepdim=True)
    theta = theta_sq.clamp_min(1e-24).sqrt()
    small = theta_sq < 1e-8
    half_sinc = torch.where(small, 0.5 - theta_sq / 48.0, torch.sin(0.5 * theta) / theta)
    w = torch.where(small, 1.0 - theta_sq / 8.0, torch.cos(0.5 * theta))
    return torch.cat([w, half_sinc * omega], dim=-1)


def quat_multiply(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product ``a * b`` of ``(..., 4)`` quaternions (apply ``b`` first, then ``a``)."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], dim=-1)


def matrix_to_quat(R: torch.Tensor) -> torch.Tensor:
    """``(..., 3, 3)`` rotation matrices -> ``(..., 4)`` unit quaternions with ``qw >= 0``."""
    m = R
    trace = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    cands = torch.stack([
        torch.stack([1 + trace, m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], -1),
        torch.stack([m[..., 2, 1] - m[..., 1, 2], 1 + m[..., 0, 0] - m[..., 1, 1] - m[..., 2, 2], m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0]], -1),
        torch.stack([m[..., 0, 2] - m[..., 2, 0], m[..., 0, 1] + m[..., 1, 0], 1 - m[..., 0, 0] + m[..., 1, 1] - m[..., 2, 2], m[..., 1, 2] + m[..., 2, 1]], -1),
        torch.stack([m[..., 1, 0] - m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1], 1 - m[..., 0, 0] - m[..., 1, 1] + m[..., 2, 2]], -1),
    ], dim=-2)  # (..., 4, 4): row k is 4 |q_k| q for the k-th largest-component formula
    diag = torch.stack([1 + trace, 1 + m[..., 0, 0] - m[..., 1, 1] - m[..., 2, 2],
                        1 - m[..., 0, 0] + m[..., 1, 1] - m[..., 2, 2], 1 - m[..., 0, 0] - m[..., 1, 1] + m[..., 2, 2]], -1)
    best = diag.argmax(-1)
    q = torch.gather(cands, -2, best[..., None, None].expand(*best.shape, 1, 4)).squeeze(-2)
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    return torch.where(q[..., :1] < 0, -q, q)


def rotate_about(v: torch.Tensor, axis: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """Rodrigues rotation of ``v (..., 3)`` about unit ``axis (..., 3)`` by ``angle (...)`` radians."""
    c, s = torch.cos(angle)[..., None], torch.sin(angle)[..., None]
    return v * c + torch.linalg.cross(axis, v) * s + axis * (axis * v).sum(-1, keepdim=True) * (1 - c)


def quat_to_matrix_np(quat: np.ndarray) -> np.ndarray:
    """NumPy `quat_to_matrix`: ``(..., 4)`` [w x y z] (normalized first) -> ``(..., 3, 3)`` float64."""
    return quat_to_matrix(torch.as_tensor(np.asarray(quat, dtype=np.float64))).numpy()


def quat_angle_np(q0: np.ndarray, q1: np.ndarray) -> float:
    """Angle (radians, in [0, pi]) of the rotation between unit quaternions ``q0`` and ``q1`` (4,)."""
    c = min(1.0, abs(float(np.dot(q0, q1))))
    return float(2.0 * np.arccos(c))
