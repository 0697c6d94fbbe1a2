"""Processing configuration: one validated dataclass, loaded from YAML, hashed for the cache.

Units: every length here is in *normalized object units* unless the field name says ``raw``
(units of the input file) or ``kg``. The normalized object is centred at its bounding-box
centre and scaled so the bounding-box half-diagonal is 1 (it fits in the unit ball); a
manifest scale ``s`` (metres) multiplies it, so at scale ``s`` the object fits in a ball of
radius ``s`` metres.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from datagen.config import Config, check_types, read_yaml
from datagen.errors import ConfigError

__all__ = ["MAX_MESH_BYTES", "ProcessConfig", "PROCESS_VERSION", "read_yaml"]

# The default cap on a mesh file's size: the largest mesh `max_faces` lets through in the most
# verbose format (ASCII STL, ~250 bytes per face: 125 MB), with room to spare. Above it the file
# is refused unread (reason file_too_large), before any parser holds it in memory.
MAX_MESH_BYTES = 256 << 20
# fields that gate which files are read but never change what a processed object holds: outside
# the cache key (`ProcessConfig.hash`), so raising a cap reuses every cached object
_UNHASHED = ("max_mesh_bytes",)

# Bump when the pipeline's output changes for the same config: it invalidates cache entries.
PROCESS_VERSION = 1


@dataclass(frozen=True)
class ProcessConfig(Config):
    """Settings of the per-object pipeline (see module docstring for units). From a mapping or
    YAML through the config helper (`datagen.config`: unknown keys refused, types checked)."""

    # --- validation (raw units of the input file) ---
    max_mesh_bytes: int = MAX_MESH_BYTES  # larger mesh files are refused unread (file_too_large); not hashed
    max_faces: int = 500_000             # larger meshes are rejected (too_many_faces)
    max_abs_coordinate_raw: float = 1e4  # |coordinate| above this is rejected (huge_coordinates)
    min_volume_fraction: float = 1e-6    # hull volume / bbox-diagonal^3 below this: degenerate
    # --- CoACD (normalized units); the seed is fixed so pieces are reproducible ---
    coacd_threshold: float = 0.05        # concavity threshold
    coacd_seed: int = 0                              # CoACD's random seed (fixed: reproducible pieces)
    coacd_preprocess_resolution: int = 50            # CoACD manifold preprocessing voxel resolution
    coacd_resolution: int = 2000                     # CoACD's sampling resolution of the Hausdorff distance
    coacd_mcts_nodes: int = 20                       # CoACD's Monte Carlo tree search: nodes
    coacd_mcts_iterations: int = 150                 # CoACD's Monte Carlo tree search: iterations
    coacd_mcts_max_depth: int = 3                    # CoACD's Monte Carlo tree search: depth
    coacd_max_convex_hull: int = -1      # -1: no limit
    coacd_max_ch_vertex: int = 64        # pieces are decimated to at most this many vertices
    min_part_volume: float = 1e-10       # parts at or below this volume are dropped
    # --- simplified watertight surface (normalized units) ---
    surface_tolerance: float = 0.002     # max surface deviation allowed by simplification
    surface_max_faces: int = 6000        # tolerance is doubled until the surface fits
    # --- MuJoCo model ---
    total_mass_kg: float = 0.1           # split over pieces in proportion to their volume
    geom_condim: int = 4                             # contact dimensionality of the object's geoms
    geom_friction: tuple[float, float, float] = (0.6, 0.02, 0.0001)  # sliding, torsional, rolling
    mjcf_check_scale: float = 0.06       # the model is compiled by MuJoCo at this scale (m)

    def __post_init__(self):
        def need(ok: bool, what: str):
            if not ok:
                raise ConfigError(f"ProcessConfig.{what}")

        check_types(self)
        need(self.max_mesh_bytes > 0, f"max_mesh_bytes must be > 0, got {self.max_mesh_bytes}")
        need(self.max_faces > 0, f"max_faces must be > 0, got {self.max_faces}")
        need(self.max_abs_coordinate_raw > 0, "max_abs_coordinate_raw must be > 0")
        need(0 <= self.min_volume_fraction < 1, "min_volume_fraction must be in [0, 1)")
        need(0 < self.coacd_threshold <= 1, f"coacd_threshold must be in (0, 1], got {self.coacd_threshold}")
        need(isinstance(self.coacd_seed, int) and self.coacd_seed >= 0, "coacd_seed must be an int >= 0")
        need(self.coacd_preprocess_resolution >= 10, "coacd_preprocess_resolution must be >= 10")
        need(self.coacd_resolution >= 100, "coacd_resolution must be >= 100")
        need(self.coacd_max_ch_vertex >= 8, "coacd_max_ch_vertex must be >= 8")
        need(self.min_part_volume >= 0, "min_part_volume must be >= 0")
        need(0 < self.surface_tolerance < 0.1, "surface_tolerance must be in (0, 0.1)")
        need(self.surface_max_faces >= 100, "surface_max_faces must be >= 100")
        need(self.total_mass_kg > 0, "total_mass_kg must be > 0")
        need(self.geom_condim in (1, 3, 4, 6), "geom_condim must be 1, 3, 4 or 6")
        need(len(self.geom_friction) == 3 and min(self.geom_friction) >= 0,
             "geom_friction must be 3 non-negative numbers (slide, torsion, roll)")
        need(self.mjcf_check_scale > 0, "mjcf_check_scale must be > 0 (metres)")
        object.__setattr__(self, "geom_friction", tuple(float(x) for x in self.geom_friction))

    @classmethod
    def from_yaml(cls, path: str | Path) -> "ProcessConfig":
        """Load from a YAML mapping (an empty file gives the defaults); tags, aliases and files
        over 1 MiB are refused (`read_yaml`)."""
        return cls.from_dict(read_yaml(path, "processing config") or {}, where=str(path))

    def hash(self) -> str:
        """sha256 of the canonical JSON of the config and PROCESS_VERSION (the cache key part),
        without the file-size cap (`_UNHASHED`)."""
        fields = {k: v for k, v in self.to_dict().items() if k not in _UNHASHED}
        blob = json.dumps({"v": PROCESS_VERSION, **fields}, sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()
