"""On-disk layout of one processed object (a cache entry), as named constants.

    <entry>/
      meta.json                      status, reason, id, hashes, normalization, pieces, timings
      normalized.obj                 the repaired input mesh, normalized units
      surface.obj                    simplified watertight surface, normalized units
      coacd/coacd_convex_piece_<i>.obj   convex pieces, normalized units (DexGraspNet's names)
      coacd/decomposed.obj           all pieces in one file (DexGraspNet's name)
      object.xml                     MJCF of the pieces at scale 1 (meshdir="coacd")

Normalized units: centred at the bounding-box centre, bounding-box half-diagonal 1. A failed
object's entry holds only meta.json.
"""

META = "meta.json"
NORMALIZED = "normalized.obj"
SURFACE = "surface.obj"
PIECES_DIR = "coacd"
PIECE = "coacd_convex_piece_{i}.obj"
DECOMPOSED = "decomposed.obj"
MJCF = "object.xml"
META_VERSION = 1
