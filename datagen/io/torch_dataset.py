"""A map-style torch Dataset over a job's grasps (loaded into memory once)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from .dataset import POSE_COLUMNS, joint_names, read_job

__all__ = ["GraspDataset"]


class GraspDataset(Dataset):
    """Item ``i``: ``{"pregrasp_qpos", "grasp_qpos", "squeeze_qpos": (nq,) float32 tensors
    ([x y z qw qx qy qz] metres + joints in radians, object frame), "object_scale_m": () float32
    metres, "success": () bool, "object_id": str, "object_path": str (absolute)}``.
    ``only_success`` keeps the grasps that passed the MuJoCo tests; ``joint_names`` names the joints.
    """

    def __init__(self, job_dir: str | Path, only_success: bool = True):
        self.job_dir = Path(job_dir).resolve()
        table = read_job(self.job_dir, columns=[*POSE_COLUMNS, "object_scale_m", "success", "object_id", "object_path"],
                         only_success=only_success)
        self.joint_names = joint_names(self.job_dir)
        nq = 7 + len(self.joint_names)
        self.poses = {c: torch.tensor(np.asarray(table[c].combine_chunks().flatten().to_numpy(zero_copy_only=False),
                                                 dtype=np.float32).reshape(-1, nq)) for c in POSE_COLUMNS}
        self.scale = torch.tensor(table["object_scale_m"].to_numpy().astype(np.float32))
        self.success = torch.tensor(table["success"].to_numpy(zero_copy_only=False).astype(bool))
        self.object_id = table["object_id"].to_pylist()
        self.object_path = [str(self.job_dir / p) for p in table["object_path"].to_pylist()]

    def __len__(self) -> int:
        return len(self.object_id)

    def __getitem__(self, i: int) -> dict:
        item = {c: self.poses[c][i] for c in POSE_COLUMNS}
        item.update(object_scale_m=self.scale[i], success=self.success[i], object_id=self.object_id[i],
                    object_path=self.object_path[i])
        return item
