"""Reading datagen jobs: shards as Arrow/pandas-ready tables and a torch Dataset.

    from datagen.io import GraspDataset, read_job
    table = read_job("jobs/default", only_success=True)
    loader = torch.utils.data.DataLoader(GraspDataset("jobs/default"), batch_size=256)
"""

from . import integrity, layout
from .dataset import POSE_COLUMNS, joint_names, open_dataset, read_job, shard_paths
from .integrity import ShardError
from .torch_dataset import GraspDataset

__all__ = ["GraspDataset", "POSE_COLUMNS", "ShardError", "integrity", "joint_names", "layout", "open_dataset",
           "read_job", "shard_paths"]
