"""The SDF grid (penetration queries) against the exact mesh SDF."""

import numpy as np
import pytest
import torch
import trimesh

from datagen.objects.grid_sdf import GridSDF
from datagen.objects.sdf import MeshSDF


def _unit(mesh):
    mesh.apply_translation(-mesh.bounds.mean(0))
    return mesh.apply_scale(1 / np.linalg.norm(0.5 * mesh.extents))


@pytest.mark.slow
@pytest.mark.parametrize("make", [lambda: trimesh.creation.box(extents=[1.0, 0.7, 1.4]),
                                  lambda: trimesh.creation.icosphere(3),
                                  lambda: trimesh.creation.torus(0.7, 0.25)], ids=["box", "sphere", "torus"])
def test_grid_matches_exact_distance_near_the_surface(make):
    mesh = _unit(make())
    exact = MeshSDF(mesh.vertices, mesh.faces)
    grid = GridSDF.from_mesh(mesh.vertices, mesh.faces, exact=exact)
    rng = np.random.default_rng(0)
    p = torch.tensor(mesh.sample(3000, seed=1) + rng.normal(size=(3000, 3)) * 0.05, dtype=torch.float32)
    scale = 0.08
    d_exact = exact.query(p * scale, scale).distance.float()
    d_grid = grid.distance(p * scale, scale)
    near = d_exact.abs() < 0.01
    err = (d_grid - d_exact)[near].abs()
    assert err.max() < 0.001  # < 1 mm within 1 cm of the surface at 8 cm scale
    assert err.quantile(0.95) < 0.0003
    assert (torch.sign(d_grid[d_exact.abs() > 0.002]) == torch.sign(d_exact[d_exact.abs() > 0.002])).all()


def test_outside_the_grid_is_a_positive_upper_bound_and_gradients_are_finite():
    mesh = _unit(trimesh.creation.box(extents=[1.0, 1.0, 1.0]))
    grid = GridSDF.from_mesh(mesh.vertices, mesh.faces, resolution=24)
    far = torch.tensor([[3.0, 0.0, 0.0], [0.0, -5.0, 2.0]], requires_grad=True)
    d = grid.distance(far)
    exact = MeshSDF(mesh.vertices, mesh.faces).query(far.detach()).distance.float()
    assert (d >= exact - 1e-4).all() and (d > 0).all()
    assert torch.allclose(d, exact, rtol=0.05)
    (g,) = torch.autograd.grad(d.sum(), far)
    assert torch.isfinite(g).all()
    with pytest.raises(ValueError, match="resolution"):
        GridSDF.from_mesh(mesh.vertices, mesh.faces, resolution=2)
