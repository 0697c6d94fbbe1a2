"""Synthesis results as Arrow rows of the ``grasps`` schema (``schemas/grasps.json``)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Mapping

import numpy as np
import pyarrow as pa

import datagen
from schemas import arrow_schema

__all__ = ["grasp_id", "hand_asset_sha256", "result_table"]


def grasp_id(object_id: str, scale: float, hand: str, task: str, seed: int, index: int,
             grasp_type: str = "precision", stable_pose: int = -1) -> str:
    key = f"{object_id}|{scale:.6f}|{hand}|{task}|{seed}|{index}"
    if grasp_type not in ("precision", "task"):  # the fingertip grasps keep the ids they had
        key += f"|{grasp_type}"
    if stable_pose >= 0:  # on a table: one id space per stable pose (floating grasps keep theirs)
        key += f"|table{stable_pose}"
    return hashlib.sha256(key.encode()).hexdigest()[:24]


def hand_asset_sha256(hand) -> str:
    return hashlib.sha256(Path(hand.mjcf_path).read_bytes()).hexdigest()


def result_table(result, targets, hand, task, cfg, *, contact_threshold_m: float | None = None,
                 splits: Mapping[str, str] | None = None) -> pa.Table:
    """One row per grasp of a :class:`~datagen.synth.SynthesisResult` (float32 poses). ``splits``
    maps object ids to their manifest split (the ``split`` column; empty for objects it lacks)."""
    nq = 7 + hand.num_joints
    B = int(result.object_index.shape[0])
    oi = result.object_index.cpu().numpy()
    counters: dict[int, int] = {}
    index = np.empty(B, dtype=np.int32)
    for b, k in enumerate(oi):
        index[b] = counters.get(int(k), 0)
        counters[int(k)] = index[b] + 1
    thr = cfg.contact_threshold_m if contact_threshold_m is None else contact_threshold_m

    def f32(x):
        return np.asarray(x.detach().cpu().numpy() if hasattr(x, "detach") else x, dtype=np.float32)

    def fixed(x, n):
        return pa.FixedSizeListArray.from_arrays(pa.array(f32(x).reshape(-1)), n)

    pts, nrm = f32(result.contact_points), f32(result.contact_normals)
    F = pts.shape[1]
    point_lists = pa.ListArray.from_arrays(np.arange(0, (B + 1) * F, F, dtype=np.int32),
                                           fixed(pts.reshape(-1, 3), 3))
    normal_lists = pa.ListArray.from_arrays(np.arange(0, (B + 1) * F, F, dtype=np.int32),
                                            fixed(nrm.reshape(-1, 3), 3))
    asset = hand_asset_sha256(hand)
    e = {k: f32(v) for k, v in result.energies.items()}
    columns = {
        "grasp_id": [grasp_id(targets[k].object_id, targets[k].scale, hand.name, task.name, result.seed, int(i),
                              result.grasp_type, targets[k].stable_pose) for k, i in zip(oi, index)],
        "object_id": [targets[k].object_id for k in oi],
        "split": [(splits or {}).get(targets[k].object_id, "") for k in oi],
        "object_scale_m": np.array([targets[k].scale for k in oi], dtype=np.float32),
        "object_path": [targets[k].object_path for k in oi],
        "mesh_sha256": [targets[k].mesh_sha256 for k in oi],
        "hand": [hand.name] * B,
        "hand_asset_sha256": [asset] * B,
        "joint_names": [list(hand.joint_names)] * B,
        "task": [task.name] * B,
        "grasp_type": [result.grasp_type] * B,
        "w_t": fixed(np.tile(np.asarray(task.w_t, dtype=np.float32) / np.linalg.norm(task.w_t), (B, 1)), 6),
        "gamma_deg": np.full(B, task.gamma_deg, dtype=np.float32),
        "pregrasp_qpos": fixed(result.pregrasp, nq),
        "grasp_qpos": fixed(result.grasp, nq),
        "squeeze_qpos": fixed(result.squeeze, nq),
        "init_qpos": fixed(result.initial, nq),
        "contact_fingers": [list(result.fingers)] * B,
        "contact_points_m": point_lists,
        "contact_normals": normal_lists,
        "tip_distance_m": [list(r) for r in f32(result.tip_distance)],
        "energy_total": e["total"], "energy_task": e["task"], "energy_distance_m2": e["distance"],
        "energy_penetration_m2": e["penetration"], "energy_self_penetration_m2": e["self_penetration"],
        "energy_joint_limits_rad": e["joint_limits"],
        "synth_epsilon": f32(result.epsilon),
        "sphere_penetration_m": f32(result.max_penetration),
        "synth_usable": result.usable(thr).cpu().numpy(),
        "seed": np.full(B, result.seed, dtype=np.int64),
        "grasp_index": index,
        **_scene_columns([targets[k] for k in oi], fixed),
    }
    schema = arrow_schema("grasps", nq=nq)
    meta = dict(schema.metadata)
    meta.update({
        b"datagen.joint_names": json.dumps(hand.joint_names).encode(),
        b"datagen.code_version": datagen.__version__.encode(),
        b"datagen.synth_config": json.dumps(cfg.to_dict(), default=list).encode(),
    })
    return pa.Table.from_pydict(columns, schema=schema.with_metadata(meta))


_IDENTITY_POSE = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)


def _scene_columns(targets, fixed) -> dict:
    """The scene columns of rows on ``targets`` (one per row): ``scene``, ``stable_pose``, the
    object's pose in the table frame and the support plane in the object frame (floating: -1,
    the identity and a zero plane)."""
    return {
        "scene": [t.scene for t in targets],
        "stable_pose": np.array([t.stable_pose for t in targets], dtype=np.int32),
        "object_pose_table": fixed(np.array([t.table_pose or _IDENTITY_POSE for t in targets]).reshape(-1, 7), 7),
        "support_plane": fixed(np.array([t.support_plane or (0.0,) * 4 for t in targets]).reshape(-1, 4), 4),
    }
