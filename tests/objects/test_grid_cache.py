"""The SDF grid cache: a cached grid equals a freshly built one, is reused without a rebuild,
is keyed by resolution (and the mesh), and a damaged file is detected and rebuilt."""

import numpy as np
import pytest
import torch
import trimesh

from datagen.objects import grid_cache
from datagen.objects.grid_sdf import GridSDF


@pytest.fixture
def builds(monkeypatch):
    """Count calls of GridSDF.from_mesh (the build the cache saves)."""
    calls = []
    real = GridSDF.from_mesh.__func__

    def counting(cls, *a, **kw):
        calls.append(kw.get("resolution"))
        return real(cls, *a, **kw)

    monkeypatch.setattr(GridSDF, "from_mesh", classmethod(counting))
    return calls


def _mesh():
    m = trimesh.creation.capsule(height=1.0, radius=0.4, count=[12, 12])
    m.apply_translation(-m.bounds.mean(0))
    return m.apply_scale(1 / np.linalg.norm(0.5 * m.extents))


KW = dict(samples=20_000)


def test_cached_grid_equals_a_fresh_build_and_is_not_rebuilt(tmp_path, builds):
    m = _mesh()
    fresh = GridSDF.from_mesh(m.vertices, m.faces, resolution=16, **KW)
    first, built1 = grid_cache.load_or_build(m.vertices, m.faces, resolution=16, root=tmp_path, **KW)
    second, built2 = grid_cache.load_or_build(m.vertices, m.faces, resolution=16, root=tmp_path, **KW)
    assert (built1, built2) == (True, False)
    assert builds == [16, 16]  # the fresh one and the first cache miss; the hit built nothing
    for g in (first, second):
        assert torch.equal(g.values, fresh.values) and torch.equal(g.lo, fresh.lo) and torch.equal(g.hi, fresh.hi)
    p = torch.tensor([[0.0, 0.0, 0.0], [0.3, 0.2, 0.9], [2.0, 0.0, 0.0]])
    assert torch.equal(second.distance(p, 0.08), fresh.distance(p, 0.08))


def test_resolutions_and_meshes_do_not_collide(tmp_path, builds):
    m = _mesh()
    g16, _ = grid_cache.load_or_build(m.vertices, m.faces, resolution=16, root=tmp_path, **KW)
    g12, built = grid_cache.load_or_build(m.vertices, m.faces, resolution=12, root=tmp_path, **KW)
    assert built and g16.values.shape == (16,) * 3 and g12.values.shape == (12,) * 3
    other = trimesh.creation.box((1.2, 0.5, 0.8))
    gb, built = grid_cache.load_or_build(other.vertices, other.faces, resolution=16, root=tmp_path, **KW)
    assert built and not torch.equal(gb.values, g16.values)
    assert len(list((tmp_path / "grids").rglob("*.npz"))) == 3
    _, built = grid_cache.load_or_build(m.vertices, m.faces, resolution=16, root=tmp_path, **KW)
    assert not built


@pytest.mark.parametrize("damage", ["garbage", "wrong_values"])
def test_a_damaged_file_is_rebuilt(tmp_path, builds, damage):
    m = _mesh()
    good, _ = grid_cache.load_or_build(m.vertices, m.faces, resolution=12, root=tmp_path, **KW)
    (path,) = (tmp_path / "grids").rglob("*.npz")
    if damage == "garbage":
        path.write_bytes(b"not a grid")
    else:  # same check record, other values: the digest must catch it
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
        arrays["values"] = arrays["values"] + 1
        with open(path, "wb") as fh:
            np.savez(fh, **arrays)
    again, built = grid_cache.load_or_build(m.vertices, m.faces, resolution=12, root=tmp_path, **KW)
    assert built and torch.equal(again.values, good.values)
    _, built = grid_cache.load_or_build(m.vertices, m.faces, resolution=12, root=tmp_path, **KW)
    assert not built  # the rebuilt file replaced the damaged one


def test_grasp_target_reuses_the_grid_across_scales(tmp_path, builds):
    from datagen.synth import GraspTarget

    m = _mesh()
    a = GraspTarget.from_mesh(m, 0.06, "capsule", hull_samples=64, grid_resolution=16, cache_grid=True, cache=tmp_path)
    b = GraspTarget.from_mesh(m, 0.10, "capsule", hull_samples=64, grid_resolution=16, cache_grid=True, cache=tmp_path)
    assert builds == [16]
    assert torch.equal(a.grid.values, b.grid.values)
    # sdf_s(x) = s * sdf_1(x / s): the same grid answers at both scales
    p = torch.tensor([[0.0, 0.0, 0.05], [0.02, 0.01, 0.0]])
    assert torch.allclose(b.distance(p), 0.10 * a.grid.distance(p / 0.10, 1.0), atol=1e-7)


def test_cached_exact_sdf_answers_exactly_like_a_fresh_one(tmp_path, monkeypatch):
    from datagen.objects.sdf import MeshSDF

    m = trimesh.creation.torus(0.7, 0.25)
    fresh = MeshSDF(m.vertices, m.faces, grid_resolution=12)
    a, built_a = grid_cache.load_or_build_mesh_sdf(m.vertices, m.faces, grid_resolution=12, root=tmp_path)
    calls = []
    real = MeshSDF._build_grid
    monkeypatch.setattr(MeshSDF, "_build_grid", lambda self, *x: (calls.append(1), real(self, *x))[1])
    b, built_b = grid_cache.load_or_build_mesh_sdf(m.vertices, m.faces, grid_resolution=12, root=tmp_path)
    assert (built_a, built_b) == (True, False) and calls == []  # the second one built no culling grid
    assert torch.equal(b.cells, fresh.cells) and torch.equal(b.counts, fresh.counts)
    assert torch.equal(b.lo, fresh.lo) and torch.equal(b.cell_size, fresh.cell_size)
    p = torch.tensor(np.random.default_rng(0).normal(size=(500, 3)) * 0.8, dtype=torch.float32)
    r0, r1 = fresh.query(p, 0.1), b.query(p, 0.1)
    assert torch.equal(r0.distance, r1.distance) and torch.equal(r0.face, r1.face)
    _, built = grid_cache.load_or_build_mesh_sdf(m.vertices, m.faces, grid_resolution=10, root=tmp_path)
    assert built  # another resolution is another entry
