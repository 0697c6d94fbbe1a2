"""Grasps in and out of peers' formats: DexGraspBench (export and import) and BODex (import).

    datagen export jobs/default --format dexgraspbench --out out/dgb      # one .npy per grasp
    datagen import --format dexgraspbench out/dgb/graspdata --hand shadow_e3m5 --out imported.parquet
    datagen import --format bodex BODEX_OUTPUT/graspdata --hand allegro --root BODEX/src/curobo/content --out b.parquet

Poses convert through the palm's pose (`frames`), objects through their convex pieces
(`objects`); `PEER_HANDS` and `BODEX_HANDS` say how each peer models each shared hand. NOTES.md section 6 describes
the peers' formats.
"""

from .bodex import BODEX_HANDS, read_bodex_files
from .dexgraspbench import PEER_HANDS, export_grasps, read_grasp_files
from .frames import PeerHand, from_peer, matrix_to_pose7, pose7_to_matrix, to_peer
from .objects import export_object, import_object

__all__ = ["BODEX_HANDS", "PEER_HANDS", "PeerHand", "export_grasps", "export_object", "from_peer", "import_object",
           "matrix_to_pose7", "pose7_to_matrix", "read_bodex_files", "read_grasp_files", "to_peer"]
