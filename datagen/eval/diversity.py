"""Diversity of a set of grasps of one hand, as the peer benchmarks measure it (pure NumPy).

Two measures, each defined the way the public code of its benchmark computes it:

* **PCA explained variance** (DexGraspBench ``src/task/statistic.py`` and Dexonomy
  ``dexonomy/op/compute_stats.py``, ``get_diversity``): each grasp is the vector
  ``x = [t (3), r (3), q (J)]`` with ``t`` the hand root's translation in the object frame
  (``R_obj^T (p_hand - p_obj)``, metres), ``r`` the axis-angle of ``R_obj^T R_hand`` (radians,
  angle in [0, pi]) and ``q`` the joints (radians); a PCA of the centred, unscaled vectors
  (scikit-learn's ``PCA()``); reported: the cumulative explained-variance ratio of the top 1..5
  components. Lower means more diverse (the variance is spread over more directions). Dexonomy
  applies it to the successful grasps (DexGraspBench's ``task_stat`` to every evaluated one).
* **Mean joint entropy** (GraspQP ``HandModel.joint_entropy`` and its evaluation's
  ``calc_entropy_for_grasps``): per joint, a histogram of 32 equal bins over the joint's
  [lower, upper] limits (``torch.histc``: values outside the range are not counted, a value at
  the upper limit is in the last bin), ``p`` the counts over their sum, ``H = -sum p ln p``
  (nats; a joint with no value in range counts 0), then the mean over the joints. The maximum is
  ``ln 32 = 3.47`` (uniform over the bins); 0 means every grasp has the same joint value.

Rows are this project's grasp rows ``[x y z qw qx qy qz, joints]`` (the ``grasp_qpos`` column),
which are already in the object frame; an object pose can be given for rows that are not.
Shapes: N grasps, J joints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["GraspDiversity", "grasp_diversity", "grouped_diversity", "pose_features", "pca_explained_variance",
           "joint_entropy", "ENTROPY_BINS", "PCA_COMPONENTS"]

ENTROPY_BINS = 32   #: GraspQP's bins per joint
PCA_COMPONENTS = 5  #: DexGraspBench's reported components


def _unit(q: np.ndarray) -> np.ndarray:
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, 4) Hamilton products a b of [w x y z] quaternions (the rotation R_a R_b)."""
    aw, av, bw, bv = a[:, :1], a[:, 1:], b[:, :1], b[:, 1:]
    return np.concatenate([aw * bw - (av * bv).sum(-1, keepdims=True), aw * bv + bw * av + np.cross(av, bv)], -1)


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(N, 3) vectors v rotated by the unit quaternions q (N, 4)."""
    qv = np.concatenate([np.zeros((len(v), 1)), v], -1)
    conj = q * np.array([1.0, -1.0, -1.0, -1.0])
    return _quat_mul(_quat_mul(q, qv), conj)[:, 1:]


def _rotvec(q: np.ndarray) -> np.ndarray:
    """(N, 3) axis * angle of unit quaternions (N, 4), angle in [0, pi] (the sign with w >= 0)."""
    q = np.where(q[:, :1] < 0, -q, q)
    v = np.linalg.norm(q[:, 1:], axis=-1)
    angle = 2 * np.arctan2(v, q[:, 0])
    scale = np.where(v > 1e-12, angle / np.maximum(v, 1e-300), 2.0)  # angle / sin(angle / 2) -> 2
    return q[:, 1:] * scale[:, None]


def pose_features(qpos: np.ndarray, obj_pose: np.ndarray | None = None) -> np.ndarray:
    """(N, 6 + J) PCA vectors ``[t, r, q]`` (module docstring) of grasp rows ``qpos`` (N, 7 + J).

    ``obj_pose``: (N, 7) or (7,) the object's pose [x y z qw qx qy qz] in the rows' frame
    (default: the identity: rows in the object frame, as this project's are)."""
    qpos = np.atleast_2d(np.asarray(qpos, dtype=np.float64))
    n = len(qpos)
    obj = np.broadcast_to(np.asarray([0, 0, 0, 1, 0, 0, 0] if obj_pose is None else obj_pose, np.float64), (n, 7))
    inv = _unit(obj[:, 3:]) * np.array([1.0, -1.0, -1.0, -1.0])  # R_obj^T
    t = _rotate(inv, qpos[:, :3] - obj[:, :3])
    r = _rotvec(_quat_mul(inv, _unit(qpos[:, 3:7])))
    return np.concatenate([t, r, qpos[:, 7:]], axis=1)


def pca_explained_variance(features: np.ndarray, components: int = PCA_COMPONENTS) -> np.ndarray:
    """(components,) cumulative explained-variance ratio of the top 1..components principal
    components of ``features`` (N, D), centred and unscaled. NaN where undefined: fewer than 2
    grasps, or no variance at all. With fewer than ``components`` non-zero components the
    later entries are 1."""
    x = np.asarray(features, dtype=np.float64)
    if x.ndim != 2 or len(x) < 2:
        return np.full(components, math.nan)
    s = np.linalg.svd(x - x.mean(axis=0), compute_uv=False)
    var = s ** 2
    if var.sum() <= 0:
        return np.full(components, math.nan)
    ratio = np.zeros(max(components, len(var)))
    ratio[:len(var)] = var / var.sum()
    return np.cumsum(ratio)[:components]


def joint_entropy(joints: np.ndarray, lower: np.ndarray, upper: np.ndarray, bins: int = ENTROPY_BINS,
                  per_joint: bool = False):
    """Mean over joints of each joint's histogram entropy (nats; module docstring).

    joints (N, J) radians, lower / upper (J,) the hand's joint limits. ``per_joint``: return the
    (J,) entropies instead of their mean. NaN for no grasps."""
    q = np.atleast_2d(np.asarray(joints, dtype=np.float64))
    lo, hi = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
    if q.shape[1] != len(lo) or len(lo) != len(hi) or np.any(hi <= lo):
        raise ValueError(f"joint_entropy: {q.shape[1]} joints against {len(lo)} lower / {len(hi)} upper limits "
                         "(each upper must exceed its lower)")
    if len(q) == 0:
        return np.full(len(lo), math.nan) if per_joint else math.nan
    out = np.zeros(len(lo))
    for j in range(len(lo)):
        v = q[:, j]
        v = v[(v >= lo[j]) & (v <= hi[j])]
        if not len(v):
            continue  # the peer's NaN entropy, set to 0
        k = np.minimum(((v - lo[j]) / (hi[j] - lo[j]) * bins).astype(np.int64), bins - 1)
        p = np.bincount(k, minlength=bins) / len(v)
        p = p[p > 0]
        out[j] = float(-(p * np.log(p)).sum())
    return out if per_joint else float(out.mean())


@dataclass(frozen=True)
class GraspDiversity:
    """Both measures of one set of grasps: ``n`` grasps, ``pca`` (5,) cumulative explained-variance
    ratios of the top 1..5 components (NaN: undefined), ``joint_entropy`` mean nats (max ln 32)."""

    n: int
    pca: tuple
    joint_entropy: float


def grasp_diversity(qpos: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                    obj_pose: np.ndarray | None = None) -> GraspDiversity:
    """`GraspDiversity` of grasp rows ``qpos`` (N, 7 + J), joint limits (J,) each."""
    qpos = np.atleast_2d(np.asarray(qpos, dtype=np.float64))
    if len(qpos) == 0:
        return GraspDiversity(0, (math.nan,) * PCA_COMPONENTS, math.nan)
    pca = pca_explained_variance(pose_features(qpos, obj_pose))
    return GraspDiversity(len(qpos), tuple(float(x) for x in pca), joint_entropy(qpos[:, 7:], lower, upper))


def grouped_diversity(qpos: np.ndarray, keys: list, lower: np.ndarray, upper: np.ndarray) -> list[tuple]:
    """``[(key, GraspDiversity), ...]`` of the rows ``qpos`` (N, 7 + J) sharing each distinct
    ``keys[i]`` (N hashable, sortable keys, e.g. (task, scale)), in sorted key order."""
    qpos = np.atleast_2d(np.asarray(qpos, dtype=np.float64))
    if len(keys) != len(qpos):
        raise ValueError(f"grouped_diversity: {len(keys)} keys for {len(qpos)} rows")
    index: dict = {}
    for i, k in enumerate(keys):
        index.setdefault(k, []).append(i)
    return [(k, grasp_diversity(qpos[index[k]], lower, upper)) for k in sorted(index)]
