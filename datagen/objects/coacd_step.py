"""Convex decomposition with CoACD under a fixed seed (normalized object units).

CoACD's reference tools seed it from the clock; here the seed comes from the config, so the
same mesh and config give the same pieces byte for byte (checked in the tests).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from .config import ProcessConfig
from .errors import MeshProcessingError, Reason

__all__ = ["ConvexPiece", "decompose", "pieces_from_meshes"]


@dataclass(frozen=True)
class ConvexPiece:
    """A convex part: vertices (n, 3) float64 and faces (f, 3) int64, normalized units."""

    vertices: np.ndarray
    faces: np.ndarray
    volume: float


def _hull_volume(v: np.ndarray) -> float:
    try:
        return float(ConvexHull(v).volume)
    except (QhullError, ValueError):
        return 0.0


def pieces_from_meshes(parts, cfg: ProcessConfig, thing: str) -> list[ConvexPiece]:
    """Wrap (vertices, faces) pairs as pieces, dropping those with volume <= min_part_volume."""
    pieces = []
    for v, f in parts:
        v, f = np.asarray(v, np.float64), np.asarray(f, np.int64)
        if len(v) < 4 or len(f) < 4 or not np.isfinite(v).all():
            continue
        vol = _hull_volume(v)
        if vol > cfg.min_part_volume:
            pieces.append(ConvexPiece(v, f, vol))
    if not pieces:
        raise MeshProcessingError(Reason.COACD_NO_PARTS, thing,
                                  f"no convex part has volume > {cfg.min_part_volume:g}")
    return pieces


def decompose(vertices: np.ndarray, faces: np.ndarray, cfg: ProcessConfig,
              thing: str) -> list[ConvexPiece]:
    """Run CoACD on a normalized mesh; pieces are decimated to cfg.coacd_max_ch_vertex vertices."""
    import coacd  # heavy native module: import on use

    coacd.set_log_level("error")
    try:
        parts = coacd.run_coacd(
            coacd.Mesh(np.asarray(vertices, np.float64), np.asarray(faces, np.int32)),
            threshold=cfg.coacd_threshold,
            max_convex_hull=cfg.coacd_max_convex_hull,
            preprocess_mode="auto",
            preprocess_resolution=cfg.coacd_preprocess_resolution,
            resolution=cfg.coacd_resolution,
            mcts_nodes=cfg.coacd_mcts_nodes,
            mcts_iterations=cfg.coacd_mcts_iterations,
            mcts_max_depth=cfg.coacd_mcts_max_depth,
            decimate=True,
            max_ch_vertex=cfg.coacd_max_ch_vertex,
            seed=cfg.coacd_seed,
        )
    except Exception as exc:
        raise MeshProcessingError(Reason.COACD_FAILED, thing,
                                  f"CoACD raised {type(exc).__name__}: {exc}") from exc
    return pieces_from_meshes(parts, cfg, thing)
