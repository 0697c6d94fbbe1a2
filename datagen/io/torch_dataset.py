"""Map-style torch Datasets over a job: its grasps, and (observation, grasp) pairs for learning."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import torch
from torch.utils.data import Dataset

from .dataset import POSE_COLUMNS, joint_names, read_job, read_observations

__all__ = ["GraspDataset", "ObservationGraspDataset", "points_of"]

_GRASP_COLUMNS = [*POSE_COLUMNS, "object_scale_m", "success", "object_id", "object_path", "split", "task"]


def points_of(column: pa.ChunkedArray | pa.Array, width: int = 3) -> list[np.ndarray]:
    """A ``list<float32[width]>`` column as one (n_i, width) float32 array per row."""
    arr = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    offsets = arr.offsets.to_numpy()  # into arr.values, which a slice leaves whole
    flat = np.asarray(arr.values.flatten().to_numpy(zero_copy_only=False), np.float32).reshape(-1, width)
    return [flat[a:b] for a, b in zip(offsets[:-1], offsets[1:])]


class GraspDataset(Dataset):
    """Item ``i``: ``{"pregrasp_qpos", "grasp_qpos", "squeeze_qpos": (nq,) float32 tensors
    ([x y z qw qx qy qz] metres + joints in radians, object frame), "object_scale_m": () float32
    metres, "success": () bool, "object_id": str, "object_path": str (absolute), "split": str,
    "task": str}``. ``only_success`` keeps the grasps that passed the MuJoCo tests, ``split`` the
    grasps of that split's objects (None: all); ``joint_names`` names the joints."""

    def __init__(self, job_dir: str | Path, only_success: bool = True, split: str | None = None):
        self.job_dir = Path(job_dir).resolve()
        table = read_job(self.job_dir, columns=_GRASP_COLUMNS, only_success=only_success)
        if split is not None:
            table = table.filter(pc.equal(table["split"], split))
        self.joint_names = joint_names(self.job_dir)
        nq = 7 + len(self.joint_names)
        self.poses = {c: torch.tensor(np.asarray(table[c].combine_chunks().flatten().to_numpy(zero_copy_only=False),
                                                 dtype=np.float32).reshape(-1, nq)) for c in POSE_COLUMNS}
        self.scale = torch.tensor(table["object_scale_m"].to_numpy().astype(np.float32))
        self.success = torch.tensor(table["success"].to_numpy(zero_copy_only=False).astype(bool))
        self.object_id = table["object_id"].to_pylist()
        self.object_path = [str(self.job_dir / p) for p in table["object_path"].to_pylist()]
        self.split = table["split"].to_pylist()
        self.task = table["task"].to_pylist()

    def __len__(self) -> int:
        return len(self.object_id)

    def __getitem__(self, i: int) -> dict:
        item = {c: self.poses[c][i] for c in POSE_COLUMNS}
        item.update(object_scale_m=self.scale[i], success=self.success[i], object_id=self.object_id[i],
                    object_path=self.object_path[i], split=self.split[i], task=self.task[i])
        return item


class ObservationGraspDataset(Dataset):
    """(observation, grasp) pairs: item ``i`` is the ``i``-th grasp of `GraspDataset` (same
    arguments) with the observation of its object at its scale (``read_observations``, joined on
    ``object_id`` and ``object_scale_m``):

        observation = {"points": (P, 3) float32 metres, object frame, the surface sample's first P
                       (``points``; None: all of them), "normals": (P, 3) outward unit normals,
                       "bbox_m": (2, 3) float32 [min, max] corners, "object_scale_m": () float32,
                       "object_id": str,
                       with views: "view_points": (V, Q, 3) float32 metres, object frame, each view's
                       first Q points (``view_points``; None: the most any view kept, which varies
                       by object, so batches need a fixed Q), repeated cyclically where a view saw
                       fewer (zeros where it saw nothing),
                       "camera_poses": (V, 7) [x y z qw qx qy qz] of each camera (MuJoCo's convention)}

    A grasp whose object has no observation (its observation failed: a failure row of stage
    ``observe``) is left out; ``missing`` counts them. The observations are held once per object
    and scale, shared by their grasps."""

    def __init__(self, job_dir: str | Path, only_success: bool = True, split: str | None = None,
                 points: int | None = 1024, view_points: int | None = 512):
        grasps = GraspDataset(job_dir, only_success=only_success, split=split)
        obs = read_observations(grasps.job_dir, split=split)
        self.joint_names = grasps.joint_names
        keys = list(zip(obs["object_id"].to_pylist(), np.round(obs["object_scale_m"].to_numpy(), 6).tolist()))
        self.observations = [self._observation(obs, r, points, view_points) for r in range(obs.num_rows)]
        index = {k: r for r, k in enumerate(keys)}
        want = zip(grasps.object_id, np.round(grasps.scale.numpy(), 6).tolist())
        pairs = [(i, index.get(k)) for i, k in enumerate(want)]
        self.grasps, self.missing = grasps, sum(r is None for _, r in pairs)
        self.pairs = [(i, r) for i, r in pairs if r is not None]

    @staticmethod
    def _observation(obs: pa.Table, r: int, points: int | None, view_points: int | None) -> dict:
        row = obs.slice(r, 1)
        pts = points_of(row["surface_points_m"])[0][:points]
        out = {"points": torch.from_numpy(pts.copy()),
               "normals": torch.from_numpy(points_of(row["surface_normals"])[0][:points].copy()),
               "bbox_m": torch.tensor(np.stack([row["bbox_min_m"][0].as_py(), row["bbox_max_m"][0].as_py()]),
                                      dtype=torch.float32),
               "object_scale_m": torch.tensor(row["object_scale_m"][0].as_py(), dtype=torch.float32),
               "object_id": row["object_id"][0].as_py()}
        views = row["view_points_m"][0].values  # list<float32[3]> of this row's views
        if len(views):
            clouds = points_of(views)
            q = view_points or max(len(c) for c in clouds)
            out["view_points"] = torch.from_numpy(np.stack([np.resize(c, (q, 3)) if len(c) else np.zeros((q, 3), np.float32)
                                                            for c in clouds]).astype(np.float32))
            out["camera_poses"] = torch.from_numpy(points_of(row["camera_poses"], 7)[0].copy())
        return out

    def __len__(self) -> int:
        return len(self.pairs)

    def __getitem__(self, i: int) -> tuple[dict, dict]:
        g, r = self.pairs[i]
        return self.observations[r], self.grasps[g]
