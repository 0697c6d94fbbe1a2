"""The ten task objects: deterministic, watertight, realistic sizes, joints where they belong.

The joint anchors are checked against the geometry itself (cross-sections of the hinge boss /
knob lobes, whose centroid lies on the turning axis by symmetry), before and after processing,
and against MuJoCo's own compiled joint.
"""

import json

import numpy as np
import pytest
import trimesh

from datagen.objects import task_objects as T
from datagen.objects.manifest import build_manifest, load_manifest, write_manifest
from datagen.objects.process import process_object
from datagen.objects.sources import iter_source, resolve
from datagen.objects.errors import ManifestError

# Expected extents (m), written from the designs (the builders' docstrings), +-1 mm.
EXTENTS = {"lever_handle": (0.151, 0.054, 0.063), "knob2": (0.048, 0.048, 0.030), "button": (0.028, 0.028, 0.012),
           "drawer": (0.36, 0.14, 0.087), "jar_lid": (0.0704, 0.0704, 0.016), "handbag": (0.26, 0.10, 0.25),
           "plate": (0.224, 0.224, 0.019)}


@pytest.mark.parametrize("name", T.TASK_OBJECTS)
def test_builds_deterministic_watertight_centred(name):
    a = T.obj_bytes(name)
    T.build.cache_clear()
    assert T.obj_bytes(name) == a  # same bytes when rebuilt
    obj = T.build(name)
    m = obj.mesh
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    lo, hi = m.bounds
    assert np.allclose((lo + hi) / 2, 0, atol=1e-6)  # bbox-centred: processing's centre is 0
    assert obj.scale_m == pytest.approx(np.linalg.norm(hi - lo) / 2, rel=1e-6)
    assert 0.01 < m.extents.max() < 0.4  # hand-sized household objects
    assert len(obj.parts) >= 1 and all(trimesh.Trimesh(v, f).is_convex for v, f in obj.parts)
    if name in EXTENTS:
        assert np.allclose(m.extents, EXTENTS[name], atol=1e-3)


def _section_centroid(mesh, z):
    """Centroid (x, y) of the mesh's cross-section at height z (area-weighted)."""
    sec = mesh.section(plane_origin=[0, 0, z], plane_normal=[0, 0, 1])
    A, C = 0.0, np.zeros(2)
    for loop in sec.discrete:  # closed polylines; shoelace area and centroid, outer loops only here
        x, y = loop[:, 0], loop[:, 1]
        cross = x[:-1] * y[1:] - x[1:] * y[:-1]
        a = cross.sum() / 2
        A += abs(a)
        C += np.sign(a) * np.array([((x[:-1] + x[1:]) * cross).sum(), ((y[:-1] + y[1:]) * cross).sum()]) / 6
    return C / A, A


def test_lever_pivot_is_on_the_neck_axis():
    obj = T.build("lever_handle")
    a = np.array(obj.joint.anchor_m)
    assert obj.joint.kind == "hinge" and obj.joint.axis == (0.0, 0.0, 1.0)
    # the neck (a 9 mm round shaft) between the rose and the lever: its section is a disc about the pivot
    z = a[2] + 0.03  # 3 cm above the rose's bottom face (rose 0-10 mm, lever from 45 mm)
    c, area = _section_centroid(obj.mesh, z)
    assert np.allclose(c, a[:2], atol=1e-4)
    assert area == pytest.approx(np.pi * 0.009**2, rel=0.02)
    assert a[0] < -0.04  # the pivot is far off the bbox centre (the lever extends along +x)


def test_knob3_axis_is_the_lobes_symmetry_axis_not_the_bbox_centre():
    obj = T.build("knob3")
    a = np.array(obj.joint.anchor_m)
    c, _ = _section_centroid(obj.mesh, a[2] + 0.015)  # through the three lobes
    assert np.allclose(c, a[:2], atol=2e-4)
    assert abs(a[0]) > 0.003  # and that axis is not the bbox centre


def test_sources_manifest_and_processing_keep_the_anchor(tmp_path):
    refs = list(iter_source("tasks"))
    assert [r.path for r in refs] == list(T.TASK_OBJECTS) and refs[0].object_id == "task-lever_handle"
    entries = build_manifest("tasks", None)
    assert all(e.scales == (T.build(e.path).scale_m,) for e in entries)  # each at its own scale
    path = write_manifest(entries, tmp_path / "m.jsonl")
    assert load_manifest(path) == entries
    with pytest.raises(ManifestError, match="unknown task object"):
        resolve("tasks", "teapot", "task-teapot")
    e = entries[0]
    p = process_object(e.ref(), root=tmp_path / "cache")
    assert p.ok and json.loads((p.entry / "meta.json").read_text())["pieces_origin"] == "builder"
    surface = trimesh.load(p.surface_path, force="mesh")
    surface.apply_scale(e.scales[0])  # normalized units -> metres of the object frame
    anchor = np.array(T.build("lever_handle").joint.anchor_m)
    c, _ = _section_centroid(surface, anchor[2] + 0.03)
    assert np.allclose(c, anchor[:2], atol=2e-4)
    assert len(p.piece_volumes) == len(T.build("lever_handle").parts)
