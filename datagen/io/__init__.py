"""Reading datagen jobs: shards and object observations as Arrow/pandas-ready tables, torch Datasets.

    from datagen.io import GraspDataset, ObservationGraspDataset, read_job, read_observations
    table = read_job("jobs/default", only_success=True)
    loader = torch.utils.data.DataLoader(GraspDataset("jobs/default"), batch_size=256)
    clouds = read_observations("jobs/default")            # one row per object and scale
    pairs = ObservationGraspDataset("jobs/default", split="train")   # (observation, grasp) items
"""

from . import integrity, layout
from .dataset import (POSE_COLUMNS, joint_names, observation_paths, open_dataset, read_job, read_observations,
                      shard_paths)
from .integrity import ShardError
from .torch_dataset import GraspDataset, ObservationGraspDataset, points_of

__all__ = ["GraspDataset", "ObservationGraspDataset", "POSE_COLUMNS", "ShardError", "integrity", "joint_names",
           "layout", "observation_paths", "open_dataset", "points_of", "read_job", "read_observations", "shard_paths"]
