"""The ten task objects of the task-oriented benchmark (paper §V-B), built procedurally.

Each object is a union of convex parts (manifold3d), in metres, at a realistic size, and comes
with its virtual joint: the degree of freedom the task test lets it move on (a revolute joint
for turning, a prismatic one for pushing/pulling, free for lifting and precision grasps).

Frame: the object frame the synthesis and the evaluation use. Processing
(`datagen.objects.process`) re-centres a mesh at its bounding-box centre and scales it to
half-diagonal 1, so every builder returns its mesh already centred at its bounding-box centre
(the builder's own frame is shifted, and the joint anchor with it) and ``scale_m`` = the
half-diagonal: then a normalized point ``x`` lies at ``scale_m * x`` metres = the builder's
point minus the centre, and the anchor (metres) lands where it should. The convex parts are
the object's exact convex decomposition (no CoACD needed), in the same frame.

Orientation: gravity is off in the evaluation, so every object is posed for a hand that comes
from above (+z, palm down): turning axes, pushing and pulling directions are the z axis; lifting
is +z.

Scenery: the static surroundings a mounted part comes with, as axis-aligned boxes in the same
frame (``TaskObject.scenery_m``): the closed door (leaf and frame) behind the lever handle, the
panel behind each knob, the button's housing (a bezel round the cap, 5 mm of it showing), the
cabinet round the drawer front (carcass behind it, neighbouring fronts and stiles 3 mm away). A
hand must not pass through them (synthesis penetration, evaluation contacts); the moving part
does not collide with them (it slides or turns inside them). The free objects (handbag, plate,
lid, key, plug) have none.

Determinism: no randomness; OBJ text with fixed formatting (same bytes on every run).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import manifold3d as mf
import numpy as np
import trimesh

__all__ = ["TASK_OBJECTS", "TaskObject", "VirtualJoint", "build", "names", "obj_bytes", "object_id"]

_SEG = 40  # circular segments


@dataclass(frozen=True)
class VirtualJoint:
    """The DoF of a task object in its (bbox-centred) frame.

    ``kind``: ``free`` (6 DoF), ``hinge`` (revolute about ``axis`` through ``anchor_m``) or
    ``slide`` (prismatic along ``axis``); ``axis`` unit (3,), ``anchor_m`` (3,) metres.
    ``limits``: the joint's travel from the initial pose, ``(lower, upper)`` in metres (slide) or
    radians (hinge), None on a side without an end stop (e.g. a push button's cap bottoms out
    in its housing but nothing holds it down); None: no end stops."""

    kind: str
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    anchor_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    limits: tuple[float | None, float | None] | None = None


@dataclass(frozen=True)
class TaskObject:
    """One task object: ``mesh`` (metres, bbox-centred, watertight), ``parts`` its convex parts
    as ``(vertices (n, 3) m, faces (f, 3))`` in the same frame, its joint, ``scale_m`` (metres
    per normalized unit = bbox half-diagonal) and ``points_m``: named reference points (metres,
    same frame) that task specs aim at and tests check (e.g. the lever's pivot)."""

    name: str
    mesh: trimesh.Trimesh
    parts: tuple
    joint: VirtualJoint
    scale_m: float
    points_m: dict
    description: str
    scenery_m: tuple = ()  #: static boxes ``((lo (3,), hi (3,)), ...)`` metres, same frame (module docstring)


# ----------------------------------------------------------------------------- primitives
def _cyl(r: float, z0: float, z1: float, x: float = 0.0, y: float = 0.0, seg: int = _SEG) -> mf.Manifold:
    """Cylinder of radius r along z from z0 to z1, axis through (x, y)."""
    return mf.Manifold.cylinder(z1 - z0, r, r, seg).translate((x, y, z0))


def _box(lo, hi) -> mf.Manifold:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return mf.Manifold.cube(tuple(hi - lo), False).translate(tuple(lo))


def _hull(*solids: mf.Manifold) -> mf.Manifold:
    return mf.Manifold.batch_hull(list(solids))


def _sphere(r: float, c, seg: int = 24) -> mf.Manifold:
    return mf.Manifold.sphere(r, seg).translate(tuple(float(x) for x in c))


def _rod(p0, p1, r: float) -> mf.Manifold:
    """Capsule-like convex rod of radius r between two points (hull of two spheres)."""
    return _hull(_sphere(r, p0, 16), _sphere(r, p1, 16))


# ----------------------------------------------------------------------------- objects
# Each builder returns (convex parts, joint in the builder frame, reference points, description).
def _lever_handle():
    """Door lever: rose (r 27 mm) + neck (r 9 mm) on the pivot axis z, lever 12 cm along +x."""
    parts = [_cyl(0.027, 0.0, 0.010), _cyl(0.009, 0.009, 0.058),
             _hull(_cyl(0.011, 0.045, 0.063), _cyl(0.009, 0.046, 0.062, x=0.115))]
    return parts, VirtualJoint("hinge", (0, 0, 1), (0, 0, 0)), \
        {"pivot": (0, 0, 0), "grip": (0.075, 0, 0.054)}, "door lever handle on its pivot, on a closed door"


def _knob2():
    """Round knob (stove knob): flange r 24 mm, body r 20 mm, 30 mm tall, turning about z."""
    parts = [_cyl(0.024, 0.0, 0.005), _cyl(0.020, 0.004, 0.028), _cyl(0.017, 0.027, 0.030)]
    return parts, VirtualJoint("hinge", (0, 0, 1), (0, 0, 0)), {"axis": (0, 0, 0), "top": (0, 0, 0.030)}, \
        "round knob, 48 mm flange, 30 mm tall"


def _knob3():
    """Three-lobed clamping knob, 62 mm across the lobes, 25 mm tall, turning about z."""
    parts = [_cyl(0.016, 0.0, 0.007)]
    for k in range(3):
        a = 2 * math.pi * k / 3
        parts.append(_hull(_cyl(0.011, 0.005, 0.025), _cyl(0.009, 0.005, 0.025, 0.022 * math.cos(a), 0.022 * math.sin(a))))
    return parts, VirtualJoint("hinge", (0, 0, 1), (0, 0, 0)), {"axis": (0, 0, 0), "top": (0, 0, 0.025)}, \
        "three-lobed knob (lobe tips at 31 mm), its axis off the bounding-box centre"


def _handbag():
    """Handbag: rounded body 26 x 10 x 18 cm, a semicircular padded handle (tube r 1 cm, arch r 7 cm)."""
    hx, hy, hz, r = 0.13, 0.05, 0.09, 0.02
    body = _hull(*[_sphere(r, (sx * (hx - r), sy * (hy - r), hz + sz * (hz - r)))
                   for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    arch, top, n = 0.07, 2 * hz - 0.01, 12
    pts = [(arch * math.cos(math.pi * k / n), 0.0, top + arch * math.sin(math.pi * k / n)) for k in range(n + 1)]
    parts = [body] + [_rod(pts[k], pts[k + 1], 0.010) for k in range(n)]
    return parts, VirtualJoint("free"), {"strap_top": (0, 0, top + arch)}, "handbag with a carrying strap"


def _plate():
    """Dinner plate, r 11 cm: flat well (r 7.5 cm, 4 mm) and a sloped rim 19 mm high, 5 mm thick."""
    parts = [_cyl(0.075, 0.0, 0.004, seg=48)]
    prof = [(0.070, 0.000), (0.112, 0.014), (0.112, 0.019), (0.068, 0.005)]  # (r, z), convex
    n = 32
    for k in range(n):
        a0, a1 = 2 * math.pi * (k - 0.02) / n, 2 * math.pi * (k + 1.02) / n  # slight overlap
        pts = np.array([(r * math.cos(a), r * math.sin(a), z) for a in (a0, a1) for r, z in prof])
        parts.append(mf.Manifold.hull_points(pts))
    return parts, VirtualJoint("free"), {"rim": (0.108, 0, 0.016)}, "dinner plate with a sloped rim"


def _button():
    """Push button cap: r 11 mm, 12 mm tall, on a 14 mm collar; pressed along -z, 4 mm of travel
    to its end stop (the housing's floor; the housing is scenery)."""
    parts = [_cyl(0.014, 0.0, 0.003), _cyl(0.011, 0.002, 0.011), _cyl(0.009, 0.010, 0.012)]
    return parts, VirtualJoint("slide", (0, 0, 1), (0, 0, 0), limits=(-0.004, None)), {"top": (0, 0, 0.012)}, \
        "push button cap in its housing, 4 mm travel"


def _drawer():
    """Drawer front 36 x 14 x 2 cm (face +z) with a flat bar pull: 13 cm long, 12 x 27 mm section,
    4 cm clear of the front (room for four fingertips behind it)."""
    parts = [_box((-0.18, -0.07, 0.0), (0.18, 0.07, 0.02)),
             _cyl(0.006, 0.019, 0.075, x=-0.055), _cyl(0.006, 0.019, 0.075, x=0.055),
             _hull(_rod((-0.065, 0, 0.066), (0.065, 0, 0.066), 0.006), _rod((-0.065, 0, 0.081), (0.065, 0, 0.081), 0.006))]
    return parts, VirtualJoint("slide", (0, 0, 1), (0, 0, 0)), {"bar": (0, 0, 0.0735)}, \
        "drawer front with a bar pull, in its cabinet"


def _jar_lid():
    """Jar lid r 35 mm, 16 mm tall, 24 grip ridges around its skirt."""
    parts = [_cyl(0.034, 0.0, 0.016, seg=48)]
    for k in range(24):
        a = 2 * math.pi * k / 24
        c, s = math.cos(a), math.sin(a)
        parts.append(_rod((0.034 * c, 0.034 * s, 0.002), (0.034 * c, 0.034 * s, 0.013), 0.0012))
    return parts, VirtualJoint("free"), {"top": (0, 0, 0.016)}, "ridged jar lid"


def _key():
    """House key standing blade down: bow disc r 13 mm (2.4 mm thick, in the xz plane), 30 mm blade."""
    bow = mf.Manifold.cylinder(0.0024, 0.013, 0.013, _SEG).rotate((90.0, 0.0, 0.0)).translate((0, 0.0012, 0.045))
    parts = [bow, _box((-0.006, -0.001, 0.029), (0.006, 0.001, 0.034)),   # shoulder
             _hull(_box((-0.0035, -0.001, 0.003), (0.002, 0.001, 0.030)), _box((-0.0035, -0.001, 0.0), (-0.001, 0.001, 0.001)))]
    for z in (0.008, 0.015, 0.022):  # teeth
        parts.append(_box((0.0015, -0.001, z), (0.0035, 0.001, z + 0.004)))
    return parts, VirtualJoint("free"), {"bow": (0, 0, 0.045)}, "house key, bow up"


def _usb_a():
    """USB-A plug standing connector down: shell 12 x 4.5 x 12 mm, body 16 x 8 x 30 mm, cable stub."""
    parts = [_box((-0.006, -0.00225, 0.0), (0.006, 0.00225, 0.0125)),
             _hull(_box((-0.0075, -0.004, 0.012), (0.0075, 0.004, 0.014)), _box((-0.006, -0.0035, 0.040), (0.006, 0.0035, 0.042))),
             _cyl(0.0025, 0.041, 0.052)]
    return parts, VirtualJoint("free"), {"body": (0, 0, 0.027)}, "USB-A plug, connector down"


def _slab(half_xy: float, z0: float, z1: float):
    return (-half_xy, -half_xy, z0), (half_xy, half_xy, z1)


def _frame(hole_x: float, hole_y: float, outer: float, z0: float, z1: float):
    """Four boxes round a rectangular hole |x| < hole_x, |y| < hole_y, out to |x|, |y| < outer."""
    return [((hole_x, -outer, z0), (outer, outer, z1)), ((-outer, -outer, z0), (-hole_x, outer, z1)),
            ((-hole_x, hole_y, z0), (hole_x, outer, z1)), ((-hole_x, -outer, z0), (hole_x, -hole_y, z1))]


# Static surroundings per object, boxes (lo, hi) in the builder's frame (metres).
_SCENERY = {
    # the closed door, 40 mm thick, in its wall, the rose mounted on its face (z = 0); 1.2 m square,
    # so that a forearm (35 cm behind the Shadow palm) cannot reach round it
    "lever_handle": [_slab(0.60, -0.040, 0.0)],
    # the panel (stove front, cabinet door) the knob's flange sits on
    "knob2": [_slab(0.40, -0.030, 0.0)],
    "knob3": [_slab(0.40, -0.030, 0.0)],
    # housing in a control panel: a bezel at z = 7 mm with a 25 mm square opening round the 22 mm
    # cap (its top at 12 mm: 5 mm show), over the collar, and the floor under the cap's 4 mm of travel
    "button": [_slab(0.40, -0.040, -0.005)] + _frame(0.0125, 0.0125, 0.40, -0.005, 0.007),
    # overlay drawer: carcass behind the front (z < 0), the fronts above and below and the side
    # stiles flush with it, 3 mm gaps; a 1.2 m wide cabinet face
    "drawer": [_slab(0.60, -0.40, 0.0)] + _frame(0.183, 0.073, 0.60, 0.0, 0.02),
}


_BUILDERS = {
    "lever_handle": _lever_handle, "knob2": _knob2, "knob3": _knob3, "handbag": _handbag, "plate": _plate,
    "button": _button, "drawer": _drawer, "jar_lid": _jar_lid, "key": _key, "usb_a": _usb_a,
}
TASK_OBJECTS: tuple[str, ...] = tuple(_BUILDERS)


def names() -> tuple[str, ...]:
    return TASK_OBJECTS


def object_id(name: str) -> str:
    """Stable object id of a task object (``task-<name>``)."""
    return f"task-{name}"


def _mesh_arrays(m: mf.Manifold) -> tuple[np.ndarray, np.ndarray]:
    mesh = m.to_mesh()
    return np.asarray(mesh.vert_properties, np.float64)[:, :3], np.asarray(mesh.tri_verts, np.int64)


@functools.lru_cache(maxsize=None)
def build(name: str) -> TaskObject:
    """The task object ``name`` (one of `TASK_OBJECTS`), bbox-centred; see the module docstring."""
    if name not in _BUILDERS:
        raise KeyError(f"unknown task object {name!r}; known: {list(TASK_OBJECTS)}")
    parts, joint, points, desc = _BUILDERS[name]()
    v, f = _mesh_arrays(mf.Manifold.batch_boolean(parts, mf.OpType.Add))
    v = np.round(v, 6)  # the OBJ text's precision, so the centre below is the processed one
    lo, hi = v.min(0), v.max(0)
    centre = (lo + hi) / 2
    shift = lambda p: tuple(float(x) for x in np.round(np.asarray(p, float) - centre, 6))  # noqa: E731
    mesh = trimesh.Trimesh(v - centre, f, process=False)
    cparts = tuple((pv - centre, pf) for pv, pf in (_mesh_arrays(p) for p in parts))
    scale = float(np.linalg.norm(hi - lo) / 2)
    jnt = VirtualJoint(joint.kind, tuple(float(x) for x in joint.axis), shift(joint.anchor_m), joint.limits)
    scenery = tuple((shift(lo), shift(hi)) for lo, hi in _SCENERY.get(name, ()))
    return TaskObject(name, mesh, cparts, jnt, scale, {k: shift(p) for k, p in points.items()}, desc, scenery)


def obj_bytes(name: str) -> bytes:
    """Deterministic OBJ text (metres, bbox-centred) of task object ``name``."""
    obj = build(name)
    lines = [f"# datagen task object {name}: {obj.description}"]
    lines += ["v %.6f %.6f %.6f" % tuple(p) for p in np.asarray(obj.mesh.vertices).tolist()]
    lines += ["f %d %d %d" % tuple(t) for t in (np.asarray(obj.mesh.faces) + 1).tolist()]
    return ("\n".join(lines) + "\n").encode("ascii")
