"""What synthesis needs of an object: distance queries, its scale and hull for initialization."""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
import trimesh

from datagen.objects import grid_cache
from datagen.objects.cache import cache_root
from datagen.objects.grid_sdf import GridSDF
from datagen.objects.sdf import MeshSDF, SDFResult

__all__ = ["GraspTarget"]


@dataclass
class GraspTarget:
    """One object at one scale, in its own frame (origin at its bounding-box centre), floating or
    resting on a table in one stable pose (`on_table`; the table is ``support_plane`` there).

    ``sdf`` holds the surface in normalized units; ``scale`` is metres per unit. ``hull_points``
    ``(H, 3)`` metres and ``hull_normals`` ``(H, 3)`` outward unit sample the convex hull for
    initial palm placements.
    """

    object_id: str
    scale: float
    sdf: MeshSDF
    hull_points: torch.Tensor
    hull_normals: torch.Tensor
    object_path: str = ""  #: processed-object directory (for evaluation and provenance)
    mesh_sha256: str = ""
    grid: GridSDF | None = None  #: fast approximate distances for the collision spheres
    scene: str = "floating"  #: "floating", or "tabletop": resting on a table (`datagen.objects.tabletop`)
    stable_pose: int = -1  #: tabletop: the rank of its stable pose (0 the most probable); -1 floating
    support_plane: tuple | None = None  #: tabletop: (4,) ``[n, d]``, height above the table ``n . x + d`` (m, object frame)
    table_pose: tuple | None = None  #: tabletop: (7,) the object's pose in the table frame ``[x y z qw qx qy qz]`` (m)
    piece_paths: tuple = ()  #: the convex pieces MuJoCo collides (OBJ, normalized units); () unknown
    grid_root: str | None = None  #: the objects cache root its grids came from (the pieces' grid is kept there too); None: not cached

    @classmethod
    def from_mesh(cls, mesh: trimesh.Trimesh, scale: float, object_id: str, *, object_path: str = "",
                  mesh_sha256: str = "", hull_samples: int = 2048, seed: int = 0,
                  grid_resolution: int = 64, cache_grid: bool = False,
                  cache: str | Path | None = None) -> "GraspTarget":
        """From a mesh in normalized units (``scale`` metres per unit).

        ``cache_grid``: take the SDF grid and the exact SDF's culling grid from (or store them in)
        the grid cache under the objects cache root ``cache`` (None: ``$DATAGEN_CACHE``), see
        :mod:`datagen.objects.grid_cache`; both are in normalized units, so one serves every scale.
        """
        if not scale > 0:
            raise ValueError(f"{object_id}: scale must be > 0 metres, got {scale}")
        if cache_grid:
            sdf, _ = grid_cache.load_or_build_mesh_sdf(np.asarray(mesh.vertices), np.asarray(mesh.faces), root=cache)
            grid, _ = grid_cache.load_or_build(mesh.vertices, mesh.faces, resolution=grid_resolution, seed=seed,
                                               root=cache, exact=sdf)
        else:
            sdf = MeshSDF(np.asarray(mesh.vertices), np.asarray(mesh.faces))
            grid = GridSDF.from_mesh(mesh.vertices, mesh.faces, resolution=grid_resolution, seed=seed, exact=sdf)
        hull = mesh.convex_hull
        pts, faces = trimesh.sample.sample_surface_even(hull, hull_samples, seed=seed)
        if len(pts) < 16:  # sample_surface_even can return few points on tiny hulls
            pts, faces = trimesh.sample.sample_surface(hull, hull_samples, seed=seed)
        return cls(object_id, float(scale), sdf,
                   torch.as_tensor(np.asarray(pts) * scale, dtype=torch.float32),
                   torch.as_tensor(hull.face_normals[faces], dtype=torch.float32),
                   object_path=object_path, mesh_sha256=mesh_sha256, grid=grid,
                   grid_root=str(cache_root(cache)) if cache_grid else None)

    @classmethod
    def from_processed(cls, processed, scale: float, *, cache_grid: bool = True, **kw) -> "GraspTarget":
        """From a :class:`datagen.objects.process.ProcessedObject` (its watertight surface).

        The SDF grid comes from the grid cache (built and stored on a miss) unless
        ``cache_grid=False``; ``cache=`` names the objects cache root (default ``$DATAGEN_CACHE``).
        """
        if not processed.ok:
            raise ValueError(f"{processed.object_id}: object failed processing ({processed.reason}): {processed.message}")
        mesh = trimesh.load(Path(processed.surface_path), force="mesh", process=False)
        target = cls.from_mesh(mesh, scale, processed.object_id, object_path=str(processed.entry),
                               mesh_sha256=processed.mesh_sha256, cache_grid=cache_grid, **kw)
        return replace(target, piece_paths=tuple(str(p) for p in processed.piece_paths))

    def pieces(self) -> "GraspTarget":
        """This target with its convex pieces' distance grid as ``grid`` (`datagen.synth.pieces`:
        what the penetration terms see with ``SynthConfig.penetration_pieces``); itself when its
        pieces are unknown or it has no grid."""
        if not self.piece_paths or self.grid is None:
            return self
        from datagen.synth.pieces import pieces_grid

        return replace(self, grid=pieces_grid(self.piece_paths, self.grid, root=self.grid_root))

    @functools.cached_property
    def centre_of_mass(self) -> np.ndarray:
        """``(3,)`` m, object frame: the centroid of the solid the surface encloses (uniform
        density; MuJoCo's centre of mass of the convex pieces, whose mass is split by volume, lies
        within a few millimetres of it)."""
        mesh = trimesh.Trimesh(self.sdf.vertices.detach().cpu().double().numpy(), self.sdf.faces.cpu().numpy(),
                               process=False)
        return np.asarray(mesh.center_mass, dtype=np.float64) * self.scale

    @functools.cached_property
    def footprint(self):
        """Its `datagen.objects.tabletop.Footprint` on its table (m); a floating target's on a
        plane under its lowest point along the object frame's z."""
        from datagen.objects.tabletop import footprint

        verts = self.sdf.vertices.detach().cpu().double().numpy() * self.scale
        plane = self.support_plane if self.support_plane is not None else (0.0, 0.0, 1.0, -float(verts[:, 2].min()))
        return footprint(verts, plane)

    def on_table(self, pose) -> "GraspTarget":
        """This target resting on a table in ``pose`` (a `datagen.objects.tabletop.StablePose`)."""
        return replace(self, scene="tabletop", stable_pose=int(pose.index),
                       support_plane=tuple(float(x) for x in pose.plane(self.scale)),
                       table_pose=tuple(float(x) for x in pose.pose7(self.scale)))

    def query(self, points: torch.Tensor) -> SDFResult:
        """Signed distance (m, < 0 inside), closest point (m), outward normal for ``(..., 3)`` m."""
        return self.sdf.query(points, self.scale)

    def distance(self, points: torch.Tensor) -> torch.Tensor:
        """Approximate signed distance (m) from the grid, ``(...)`` for ``(..., 3)`` m."""
        return self.grid.distance(points, self.scale) if self.grid is not None else self.query(points).distance

    def approx_query(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Grid-based ``(distance, closest, outward normal)`` for ``(..., 3)`` m.

        The normal is the (detached) central difference of the grid distance over one cell: a
        continuous field, unlike the trilinear gradient, which jumps at every cell face and so
        makes the contact normals (and the task energy) jump under a line search. ``closest =
        p - d n``, so its gradient is the tangent projection ``I - n n^T``. Accurate to the
        grid (~0.2 mm).
        """
        if self.grid is None:
            res = self.query(points)
            return res.distance, res.closest, res.normal
        with torch.no_grad():
            g = self.grid
            h = float(((g.hi - g.lo) / (g.values.shape[0] - 1)).max()) * self.scale
            p = points.detach()
            offs = (torch.eye(3, dtype=p.dtype, device=p.device) * h).view((3,) + (1,) * (p.dim() - 1) + (3,))
            shifted = torch.cat([p[None] + offs, p[None] - offs])  # (6, ..., 3): one cell along +-x, y, z
            d6 = self.distance(shifted)  # one grid query for the six (the same value per point)
            grad = torch.stack([d6[k] - d6[k + 3] for k in range(3)], dim=-1)  # contiguous, as the norm below needs
            n = grad / grad.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        d = self.distance(points)
        return d, points - d[..., None] * n, n

    def to(self, device) -> "GraspTarget":
        """A copy on ``device`` (this one is unchanged, like ``torch.Tensor.to``)."""
        return replace(self, sdf=self.sdf.to(device), grid=None if self.grid is None else self.grid.to(device),
                       hull_points=self.hull_points.to(device), hull_normals=self.hull_normals.to(device))
