import io

import numpy as np
import pytest
import torch
import trimesh

from datagen.objects import procedural
from datagen.objects.sdf import MeshSDF, closest_on_triangles

HALF = np.array([0.5, 0.3, 0.2])  # box half extents, mesh units


def box_sdf(p):
    """Analytic signed distance to the box |x| <= HALF (independent reference)."""
    q = np.abs(p) - HALF
    return np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(-1), 0)


@pytest.fixture(scope="module")
def box():
    m = trimesh.creation.box(extents=2 * HALF)
    return MeshSDF(m.vertices, m.faces, dtype=torch.float64, grid_resolution=8)


@pytest.fixture(scope="module")
def mug():
    i = next(i for i in range(100) if procedural.family_of(0, i) == "mug")
    m = trimesh.load(io.BytesIO(procedural.generate(0, i).obj_bytes), file_type="obj", process=False)
    v = (m.vertices - m.bounds.mean(0)) / (np.linalg.norm(m.extents) / 2)  # normalized units
    return trimesh.Trimesh(v, m.faces, process=False)


def test_box_matches_analytic_sdf_at_any_scale(box):
    rng = np.random.default_rng(0)
    p = rng.uniform(-1.5, 1.5, size=(3000, 3))
    for scale in (0.06, 0.12):
        r = box.query(torch.tensor(p * scale), scale)
        assert np.allclose(r.distance.numpy(), scale * box_sdf(p), atol=1e-12)
        # the closest point is on the surface and at |distance| from the query
        assert np.allclose(box_sdf(r.closest.numpy() / scale), 0, atol=1e-12)
        assert np.allclose(np.linalg.norm(r.closest.numpy() - p * scale, axis=-1),
                           np.abs(r.distance.numpy()), atol=1e-12)
        # outside, the normal is the analytic gradient (q+ / |q+|)
        q = np.maximum(np.abs(p) - HALF, 0) * np.sign(p)
        out = box_sdf(p) > 1e-6
        expected = q[out] / np.linalg.norm(q[out], axis=-1, keepdims=True)
        assert np.allclose(r.normal.numpy()[out], expected, atol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("scale", [0.06, 0.12])
def test_within_1cm_error_below_half_mm_against_trimesh(mug, scale):
    sdf = MeshSDF(mug.vertices, mug.faces)  # default float32, default grid
    ms = trimesh.Trimesh(mug.vertices * scale, mug.faces, process=False)
    pts, fi = trimesh.sample.sample_surface(ms, 1500, seed=1)
    pts = pts + ms.face_normals[fi] * np.random.default_rng(1).uniform(-0.01, 0.01, (len(pts), 1))
    r = sdf.query(torch.tensor(pts, dtype=torch.float32), scale)
    reference = -trimesh.proximity.signed_distance(ms, pts)  # trimesh: positive inside
    err = np.abs(r.distance.numpy() - reference)
    assert err.max() <= 5e-4
    assert np.median(err) <= 1e-5  # it is exact up to float32 rounding
    closest_ref, dist_ref, _ = trimesh.proximity.closest_point(ms, pts)
    assert np.abs(np.linalg.norm(r.closest.numpy() - pts, axis=-1) - dist_ref).max() <= 5e-4


def test_grid_culling_equals_brute_force(mug):
    rng = np.random.default_rng(2)
    p = torch.tensor(rng.uniform(-1.4, 1.4, size=(800, 3)))
    grid = MeshSDF(mug.vertices, mug.faces, dtype=torch.float64, grid_resolution=16,
                   max_candidates=48)
    brute = MeshSDF(mug.vertices, mug.faces, dtype=torch.float64, grid_resolution=0)
    a, b = grid.query(p), brute.query(p)
    assert torch.allclose(a.distance, b.distance, atol=1e-12)
    assert bool(grid.overflow.any()) and not bool(grid.overflow.all())  # both paths exercised


def test_gradient_is_the_normal_and_passes_gradcheck(mug):
    sdf = MeshSDF(mug.vertices, mug.faces, dtype=torch.float64, grid_resolution=8)
    rng = np.random.default_rng(3)
    p = torch.tensor(rng.uniform(-1.2, 1.2, size=(500, 3)) * 0.1, requires_grad=True)
    r = sdf.query(p, 0.1)
    (g,) = torch.autograd.grad(r.distance.sum(), p)
    assert torch.allclose(g, r.normal, atol=1e-8)
    assert torch.allclose(r.normal.norm(dim=-1), torch.ones(500, dtype=torch.float64))
    few = p[:8].detach().clone().requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: sdf.query(x, 0.1).distance, (few,), eps=1e-7)


def test_batch_shapes_and_per_point_loop(box):
    p = torch.tensor(np.random.default_rng(4).uniform(-0.1, 0.1, size=(2, 5, 3)))
    r = box.query(p, 0.1)
    assert r.distance.shape == (2, 5) and r.closest.shape == (2, 5, 3) and r.normal.shape == (2, 5, 3)
    loop = torch.stack([box.query(x[None], 0.1).distance[0] for x in p.reshape(-1, 3)])
    assert torch.allclose(r.distance.reshape(-1), loop, atol=1e-14)


def test_closest_on_triangles_features():
    a, b, c = (torch.tensor(x, dtype=torch.float64) for x in ([0, 0, 0], [1, 0, 0], [0, 1, 0]))
    pts = torch.tensor([[0.2, 0.2, 1.0], [0.5, -1.0, 0.0], [-1.0, -1.0, 0.5], [2.0, 2.0, 0.0]],
                       dtype=torch.float64)
    q, f = closest_on_triangles(pts, a, b, c)
    assert torch.allclose(q, torch.tensor([[0.2, 0.2, 0], [0.5, 0, 0], [0, 0, 0], [0.5, 0.5, 0]],
                                          dtype=torch.float64))
    assert f.tolist() == [0, 1, 4, 2]  # face, edge ab, vertex a, edge bc


def test_bad_arguments_are_named(box):
    with pytest.raises(ValueError, match="scale must be > 0"):
        box.query(torch.zeros(1, 3, dtype=torch.float64), 0.0)
    with pytest.raises(ValueError, match="no faces"):
        MeshSDF(np.zeros((3, 3)), np.zeros((0, 3), int))


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_matches_cpu(box):
    p = torch.tensor(np.random.default_rng(5).uniform(-0.1, 0.1, size=(1000, 3)))
    cpu = box.query(p, 0.1).distance
    m = trimesh.creation.box(extents=2 * HALF)
    gpu = MeshSDF(m.vertices, m.faces, dtype=torch.float64, grid_resolution=8, device="cuda")
    assert torch.allclose(gpu.query(p.cuda(), 0.1).distance.cpu(), cpu, atol=1e-12)


@pytest.mark.parametrize("mesh", [trimesh.creation.torus(0.5, 0.15), trimesh.creation.icosphere(subdivisions=2)],
                         ids=["torus", "icosphere"])
def test_culling_grid_cells_hold_exactly_the_triangles_near_their_centre(mesh):
    """Each cell of the culling grid lists every triangle within (its centre's distance to the
    mesh + one cell diagonal) of its centre, and only those: checked by brute force over all
    triangles, so the per-block bound the builder prunes with never drops a needed triangle."""
    res, k = 16, 128
    sdf = MeshSDF(mesh.vertices, mesh.faces, grid_resolution=res, max_candidates=k)
    idx = np.stack(np.meshgrid(*[np.arange(res)] * 3, indexing="ij"), -1).reshape(-1, 3)
    centres = sdf.lo + (torch.as_tensor(idx, dtype=sdf.lo.dtype) + 0.5) * sdf.cell_size
    t = sdf.tris
    q, _ = closest_on_triangles(centres[:, None], t[:, 0], t[:, 1], t[:, 2])
    d = (centres[:, None] - q).norm(dim=-1)  # (cells, F) every pair
    reach = float(sdf.cell_size.norm()) * (1 + 1e-4) + 1e-9
    near = d <= d.amin(-1, keepdim=True) + reach
    assert torch.equal(sdf.counts, near.sum(-1))
    complete = (sdf.counts <= k).nonzero().squeeze(-1)  # cells whose whole list fits in the K slots
    assert len(complete) >= 200
    for c in complete[::5].tolist():
        n = int(sdf.counts[c])
        assert set(sdf.cells[c, :n].tolist()) == set(near[c].nonzero().squeeze(-1).tolist())
