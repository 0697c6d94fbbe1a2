"""Object observations (datagen/objects/observations.py) of a processed procedural mug, checked
against its own surface mesh with trimesh's independent queries: points on the surface, normals
pointing out, view points seen from their camera, the bounding box, the scale."""

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import trimesh

from datagen.objects import procedural
from datagen.objects.observations import (ObservationConfig, observation_table, observe_isolated, observe_object,
                                          resolve_renderer)
from datagen.objects.process import process_object
from datagen.objects.sources import iter_source
from schemas import arrow_schema
from tests.objects.test_views import needs_gl

MUG = next(i for i in range(100) if procedural.family_of(0, i) == "mug")
SCALES = (0.06, 0.1)
CFG = ObservationConfig(points=512, views=3, view_points=200, image_width=64, image_height=48, renderer="raycast")


@pytest.fixture(scope="module")
def mug(tmp_path_factory, fast_cfg):
    ref = next(r for r in iter_source("procedural:0", MUG + 1) if r.path == str(MUG))
    out = process_object(ref, fast_cfg, tmp_path_factory.mktemp("cache"))
    assert out.ok, out.message
    return out


@pytest.fixture(scope="module")
def rows(mug):
    return observe_object(mug, SCALES, CFG, seed=3, renderer="raycast")


def _surface(mug, scale):
    m = trimesh.load(mug.surface_path, process=False, force="mesh")
    m.apply_scale(scale)
    return m


def test_one_row_per_scale_in_metres(mug, rows):
    assert [r["object_scale_m"] for r in rows] == list(SCALES)
    for r in rows:
        m = _surface(mug, r["object_scale_m"])
        np.testing.assert_allclose(r["bbox_min_m"], m.bounds[0], atol=1e-7)
        np.testing.assert_allclose(r["bbox_max_m"], m.bounds[1], atol=1e-7)
        assert r["surface_points_m"].shape == (512, 3) and r["surface_normals"].shape == (512, 3)
    # the same object sample at every scale
    np.testing.assert_allclose(rows[1]["surface_points_m"], rows[0]["surface_points_m"] * (0.1 / 0.06), rtol=1e-5)


def test_surface_points_lie_on_the_surface_with_outward_normals(mug, rows):
    for r in rows:
        m = _surface(mug, r["object_scale_m"])
        p, n = r["surface_points_m"].astype(float), r["surface_normals"].astype(float)
        _, dist, _ = trimesh.proximity.closest_point(m, p)
        assert dist.max() < 1e-6
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)
        eps = 1e-3 * r["object_scale_m"]
        inside_out, inside_in = m.contains(p + eps * n), m.contains(p - eps * n)
        assert inside_out.mean() < 0.05 and inside_in.mean() > 0.95  # thin walls and edges aside


def test_view_points_are_surface_points_their_camera_sees(mug, rows):
    for r in rows:
        m = _surface(mug, r["object_scale_m"])
        assert r["camera_poses"].shape == (3, 7)
        np.testing.assert_allclose(np.linalg.norm(r["camera_poses"][:, :3], axis=1), CFG.camera_distance_m, rtol=1e-6)
        assert len(r["view_points_m"]) == 3
        for cam, pts, n_px in zip(r["camera_poses"], r["view_points_m"], r["view_pixels"]):
            assert 0 < len(pts) == min(n_px, CFG.view_points)
            _, dist, tri = trimesh.proximity.closest_point(m, pts.astype(float))
            assert dist.max() < 1e-5 * r["object_scale_m"] / 0.06
            facing = np.einsum("ij,ij->i", m.face_normals[tri], cam[:3] - pts)
            assert (facing > 0).mean() > 0.97  # front faces (a grazing edge pixel aside)
            # nothing lies between the camera and a seen point (ray cast back, independently)
            d = pts - cam[:3]
            first = trimesh.ray.ray_triangle.RayMeshIntersector(m).intersects_location(
                np.broadcast_to(cam[:3], d.shape), d / np.linalg.norm(d, axis=1, keepdims=True), multiple_hits=False)
            hit = np.full(len(pts), np.inf)
            hit[first[1]] = np.linalg.norm(first[0] - cam[:3], axis=1)
            assert np.mean(hit >= np.linalg.norm(d, axis=1) - 1e-6) > 0.97


def test_rows_are_deterministic_and_seeded(mug, rows):
    again = observe_object(mug, SCALES, CFG, seed=3, renderer="raycast")
    other = observe_object(mug, SCALES, CFG, seed=4, renderer="raycast")
    for a, b, c in zip(rows, again, other):
        for k in ("surface_points_m", "camera_poses"):
            np.testing.assert_array_equal(a[k], b[k])
            assert not np.array_equal(a[k], c[k])


def test_the_table_has_the_declared_schema_and_reads_back_with_plain_pyarrow(rows, tmp_path):
    table = observation_table(rows)
    assert table.schema.equals(arrow_schema("observations"), check_metadata=False)
    pq.write_table(table, tmp_path / "o.parquet")
    back = pq.read_table(tmp_path / "o.parquet").to_pylist()
    assert back[1]["object_scale_m"] == pytest.approx(0.1)
    np.testing.assert_allclose(back[1]["surface_points_m"], rows[1]["surface_points_m"])
    np.testing.assert_allclose(back[0]["view_points_m"][2], rows[0]["view_points_m"][2])
    assert back[0]["depth_renderer"] == "raycast"
    assert observation_table([]).num_rows == 0


def test_points_only_needs_no_renderer(mug):
    (r,) = observe_object(mug, (0.08,), ObservationConfig(points=64, views=0), seed=0, renderer="none-needed")
    assert r["view_points_m"] == [] and r["camera_poses"].shape == (0, 7) and r["depth_renderer"] == ""


def test_bad_settings_are_one_line():
    from datagen.errors import ConfigError

    with pytest.raises(ConfigError, match="renderer must be one of auto, mujoco, raycast"):
        ObservationConfig(renderer="opengl")
    with pytest.raises(ConfigError, match="views must be in 0..64"):
        ObservationConfig(views=-1)


@needs_gl
def test_mujoco_rows_agree_with_ray_cast_rows_in_a_worker(mug, rows):
    assert resolve_renderer("auto") == "mujoco"
    gl = observe_isolated(mug, SCALES, ObservationConfig(**{**CFG.to_dict(), "renderer": "auto"}), 3, 120.0)
    for a, b in zip(gl, rows):
        assert a["depth_renderer"] == "mujoco"
        np.testing.assert_array_equal(a["surface_points_m"], b["surface_points_m"])
        for va, vb, na, nb in zip(a["view_points_m"], b["view_points_m"], a["view_pixels"], b["view_pixels"]):
            assert abs(na - nb) <= 0.02 * nb  # silhouette pixels may fall either side
            if na == nb:  # the same pixels, so the same random subset of them: the same points
                np.testing.assert_allclose(va, vb, atol=1e-4)
            else:  # the same visible surface: each MuJoCo point within a pixel's footprint of the ray cast's
                d = np.linalg.norm(va[:, None, :] - vb[None, :, :], axis=2).min(axis=1)
                assert np.median(d) < 2 * CFG.camera_distance_m / 48


def test_without_gl_auto_casts_rays_and_mujoco_is_refused_in_one_line(monkeypatch):
    import datagen.gl
    from datagen.gl import GLUnavailable
    from datagen.objects import observations
    from workers.job import JobConfig, JobError

    def no_gl():
        raise GLUnavailable("no offscreen OpenGL backend works here: egl: libEGL not found")

    monkeypatch.setattr(datagen.gl, "select_backend", no_gl)
    monkeypatch.setattr(observations, "_resolved", {})
    assert resolve_renderer("auto") == "raycast" and resolve_renderer("raycast") == "raycast"
    with pytest.raises(GLUnavailable):
        resolve_renderer("mujoco")
    JobConfig(observations={"views": 2}).check_observations()  # auto: fine
    with pytest.raises(JobError) as info:
        JobConfig(observations={"views": 2, "renderer": "mujoco"}).check_observations()
    msg = str(info.value)
    assert "\n" not in msg and "observations.renderer is mujoco" in msg and "libEGL not found" in msg
