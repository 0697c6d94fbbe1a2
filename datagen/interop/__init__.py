"""Grasps in and out of peers' formats: DexGraspBench (export and import) and BODex (import).

    datagen export jobs/default --format dexgraspbench --out out/dgb      # one .npy per grasp
    datagen import --format dexgraspbench out/dgb/graspdata --hand shadow_e3m5 --out imported.parquet

Poses convert through the palm's pose (`frames`), objects through their convex pieces
(`objects`); `PEER_HANDS` says how the peer models each shared hand. NOTES.md section 6 describes
the peers' formats.
"""

from .dexgraspbench import PEER_HANDS, export_grasps, read_grasp_files
from .frames import PeerHand, from_peer, matrix_to_pose7, pose7_to_matrix, to_peer
from .objects import export_object, import_object

__all__ = ["PEER_HANDS", "PeerHand", "export_grasps", "export_object", "from_peer", "import_object",
           "matrix_to_pose7", "pose7_to_matrix", "read_grasp_files", "to_peer"]
