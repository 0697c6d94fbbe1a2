"""A precomputed signed-distance grid with trilinear interpolation (fast, approximate).

Built once per object on a regular grid over the mesh's bounding box plus a margin (normalized
units): the distance of each grid node to a dense sample of the surface (a KD-tree query), signed by
the outward normals of its 8 nearest samples, and by the exact mesh SDF where they disagree
(near edges). The sample spacing bounds the error (about 1% of
the object's half-diagonal at the defaults; measured in tests/objects/test_grid_sdf.py). ``query`` interpolates with
``torch.nn.functional.grid_sample`` (differentiable w.r.t. the points, any device). Outside the
grid the distance is the grid value at the nearest boundary point plus the distance to the
grid box: an upper bound of the true distance (triangle inequality), positive since the grid
box has a margin around the mesh, which is all penetration terms need (far points never
penetrate). Use the exact MeshSDF where closest points and normals must be exact
(fingertip contacts), and this grid for the hundreds of collision spheres per hand.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
import trimesh
from scipy.spatial import cKDTree

from datagen._interrupt import sigint_deferred

__all__ = ["GridSDF"]


class GridSDF:
    """Signed distance grid ``(R, R, R)`` in normalized units over ``[lo, hi]``."""

    def __init__(self, values: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor):
        self.values = values  # (R, R, R), indexed [x, y, z]
        self.lo, self.hi = lo, hi
        self._floor: float | None = None  # boundary_floor(), computed on first use

    @classmethod
    def from_mesh(cls, vertices, faces, *, resolution: int = 64, margin: float = 0.25,
                  samples: int = 200_000, seed: int = 0, dtype=torch.float32, exact=None) -> "GridSDF":
        """Grid of a closed mesh ``(V, 3)``/``(T, 3)`` in normalized units (``resolution^3`` nodes).

        ``exact``: an existing :class:`~datagen.objects.sdf.MeshSDF` of the same mesh to reuse.
        """
        if resolution < 4:
            raise ValueError(f"GridSDF resolution must be >= 4, got {resolution}")
        mesh = trimesh.Trimesh(np.asarray(vertices, dtype=np.float64), np.asarray(faces), process=False)
        pts, face = trimesh.sample.sample_surface(mesh, samples, seed=seed)
        pts = np.vstack([pts, mesh.vertices])  # vertices too: exact at corners
        normals = np.vstack([mesh.face_normals[face], mesh.vertex_normals])
        lo = mesh.vertices.min(0) - margin
        hi = mesh.vertices.max(0) + margin
        axes = [np.linspace(lo[i], hi[i], resolution) for i in range(3)]
        nodes = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        # Ctrl-C waits for the query's end: an interrupted query leaves SciPy's worker threads
        # running on freed arrays, and the interpreter crashes (SIGSEGV) when it exits
        with sigint_deferred():
            dist, idx = cKDTree(pts).query(nodes, k=8, workers=-1)
        votes = ((nodes[:, None] - pts[idx]) * normals[idx]).sum(-1) >= 0  # (N, 8) outside?
        sign = np.where(votes[:, 0], 1.0, -1.0)
        dist = dist[:, 0]
        ambiguous = np.flatnonzero(votes.any(1) & ~votes.all(1))  # near edges: ask the exact SDF
        if ambiguous.size:
            if exact is None:
                from datagen.objects.sdf import MeshSDF

                exact = MeshSDF(mesh.vertices, mesh.faces)
            with torch.no_grad():
                d = exact.query(torch.as_tensor(nodes[ambiguous])).distance.cpu().numpy()
            sign[ambiguous] = np.where(d < 0, -1.0, 1.0)
        values = torch.as_tensor((sign * dist).reshape((resolution,) * 3), dtype=dtype)
        return cls(values, torch.as_tensor(lo, dtype=dtype), torch.as_tensor(hi, dtype=dtype))

    def boundary_floor(self) -> float:
        """The least value on the grid's six faces (normalized units): every distance this grid
        gives outside its box is at least this plus the distance to the box (see `distance`)."""
        if self._floor is None:
            v = self.values
            self._floor = float(torch.stack([v[0].min(), v[-1].min(), v[:, 0].min(), v[:, -1].min(),
                                             v[:, :, 0].min(), v[:, :, -1].min()]).min())
        return self._floor

    def to(self, device) -> "GridSDF":
        """A copy on ``device`` (this one is unchanged, like ``torch.Tensor.to``)."""
        return GridSDF(self.values.to(device), self.lo.to(device), self.hi.to(device))

    def distance(self, points: torch.Tensor, scale: float = 1.0) -> torch.Tensor:
        """Signed distance (m, < 0 inside) of points ``(..., 3)`` m at ``scale`` m per unit, ``(...)``."""
        shape = points.shape[:-1]
        p = points.reshape(-1, 3) / scale
        lo, hi = self.lo.to(p.dtype), self.hi.to(p.dtype)
        inside = torch.maximum(torch.minimum(p, hi), lo)
        outside = (p - inside).norm(dim=-1)
        u = 2 * (inside - lo) / (hi - lo) - 1  # [-1, 1], x y z
        grid = self.values.to(p.dtype).permute(2, 1, 0)[None, None]  # (1, 1, D=z, H=y, W=x)
        d = F.grid_sample(grid, u[None, :, None, None, :], mode="bilinear", align_corners=True)
        d = d.reshape(-1) + outside
        return (scale * d).reshape(shape)
