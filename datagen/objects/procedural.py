"""Deterministic generator of household-like objects (the built-in default source).

Each object is a closed, manifold triangle mesh built with manifold3d from a family and a few
random shape parameters. Sizes are in metres and in DexGraspNet's range (largest extent about
6-30 cm); processing re-normalizes anyway, so what matters is shape and proportion.

Determinism: ``generate(seed, index)`` draws every parameter from
``numpy.random.default_rng([seed, index])`` and writes the OBJ text with fixed formatting, so
the same ``(seed, index)`` gives the same bytes on every run and machine of the same
manifold3d build.
"""

from __future__ import annotations

from dataclasses import dataclass

import manifold3d as mf
import numpy as np

__all__ = ["FAMILIES", "ProceduralObject", "generate", "object_id", "family_of"]

_SEG = 40  # circular segments for revolved shapes (a few thousand triangles at most)


def _revolve(profile: list[tuple[float, float]], seg: int = _SEG) -> mf.Manifold:
    """Revolve a closed (r, z) polygon (r >= 0, counter-clockwise) about the z axis."""
    return mf.Manifold.revolve(mf.CrossSection([np.asarray(profile, dtype=np.float64)]), seg)


def _hollow(outer: np.ndarray, z: np.ndarray, wall: float, floor: float) -> list:
    """(r, z) polygon of a thin-walled open-top vessel with outer radius ``outer(z)``."""
    pts = [(0.0, z[0])] + [(float(r), float(h)) for r, h in zip(outer, z)]
    inner = [(max(float(r) - wall, 1e-3), float(h)) for r, h in zip(outer, z) if h >= z[0] + floor]
    return pts + inner[::-1] + [(0.0, inner[0][1])]


def _rounded_box(rng):
    half = rng.uniform([0.02, 0.015, 0.01], [0.12, 0.07, 0.06])
    r = rng.uniform(0.1, 0.45) * half.min()
    c = half - r
    spheres = [mf.Manifold.sphere(r, 16).translate((sx * c[0], sy * c[1], sz * c[2]))
               for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    return mf.Manifold.batch_hull(spheres)


def _can(rng):
    r, h = rng.uniform(0.025, 0.06), rng.uniform(0.06, 0.2)
    c = rng.uniform(0.05, 0.2) * r
    return _revolve([(0, 0), (r - c, 0), (r, c), (r, h - c), (r - c, h), (0, h)])


def _cylinder(rng):
    r, h = rng.uniform(0.01, 0.06), rng.uniform(0.05, 0.28)
    return mf.Manifold.cylinder(h, r, -1.0, _SEG)


def _bottle(rng):
    rb, hb = rng.uniform(0.025, 0.05), rng.uniform(0.08, 0.2)
    rn, hs, hn = rng.uniform(0.25, 0.5) * rb, rng.uniform(0.02, 0.06), rng.uniform(0.02, 0.06)
    t = np.linspace(0, np.pi, 8)
    shoulder = [(rn + (rb - rn) * (1 + np.cos(a)) / 2, hb + hs * a / np.pi) for a in t]
    top = hb + hs + hn
    return _revolve([(0, 0), (rb, 0)] + shoulder + [(rn, top), (0, top)])


def _vase(rng):
    h, r0 = rng.uniform(0.1, 0.3), rng.uniform(0.03, 0.07)
    amp, freq, ph = rng.uniform(0.1, 0.4), rng.uniform(0.5, 1.5), rng.uniform(0, 2 * np.pi)
    z = np.linspace(0, h, 16)
    outer = r0 * (1 + amp * np.sin(2 * np.pi * freq * z / h + ph))
    return _revolve(_hollow(outer, z, wall=0.2 * outer.min(), floor=0.1 * h))


def _bowl(rng):
    r, h = rng.uniform(0.05, 0.12), rng.uniform(0.03, 0.08)
    z = np.linspace(0, h, 12)
    outer = 0.45 * r + 0.55 * r * np.sin(0.5 * np.pi * z / h) ** 0.7
    return _revolve(_hollow(outer, z, wall=rng.uniform(0.06, 0.12) * r, floor=0.12 * h))


def _mug(rng):
    r, h = rng.uniform(0.03, 0.05), rng.uniform(0.07, 0.12)
    wall = rng.uniform(0.08, 0.15) * r
    body = _revolve(_hollow(np.full(2, r), np.array([0.0, h]), wall=wall, floor=0.1 * h))
    hr, ht = rng.uniform(0.25, 0.4) * h, rng.uniform(0.08, 0.14) * h
    ring = mf.Manifold.revolve(mf.CrossSection.circle(ht, 16).translate((hr, 0.0)), 24, 180.0)
    handle = ring.rotate((90.0, 90.0, 0.0)).translate((r - 0.3 * ht, 0.0, h / 2))
    return body + handle


def _torus(rng):
    rr, rt = rng.uniform(0.03, 0.08), rng.uniform(0.008, 0.025)
    sec = mf.CrossSection.circle(rt, 20).scale((1.0, rng.uniform(0.7, 1.6))).translate((rr, 0.0))
    return mf.Manifold.revolve(sec, _SEG)


def _cone(rng):
    r, h = rng.uniform(0.03, 0.08), rng.uniform(0.06, 0.2)
    return mf.Manifold.cylinder(h, r, rng.uniform(0.0, 0.4) * r, _SEG)


def _superellipsoid(rng):
    a = rng.uniform([0.03, 0.03, 0.03], [0.1, 0.08, 0.08])
    e1, e2 = rng.uniform(0.2, 1.6, size=2)

    def warp(p):
        d = p / np.linalg.norm(p, axis=1, keepdims=True)
        q = np.abs(d / a) + 1e-12
        f = (q[:, 0] ** (2 / e2) + q[:, 1] ** (2 / e2)) ** (e2 / e1) + q[:, 2] ** (2 / e1)
        return d * f[:, None] ** (-e1 / 2)

    return mf.Manifold.sphere(1.0, 32).warp_batch(warp)


def _capsule(rng):
    r, l = rng.uniform(0.015, 0.05), rng.uniform(0.02, 0.2)
    return mf.Manifold.batch_hull([mf.Manifold.sphere(r, 24).translate((0, 0, z)) for z in (0, l)])


def _box(size, centre):
    return mf.Manifold.cube(tuple(size), True).translate(tuple(centre))


def _compound(rng, kind: str):
    w, t, d = rng.uniform(0.06, 0.18), rng.uniform(0.012, 0.035), rng.uniform(0.015, 0.05)
    arm = rng.uniform(0.4, 1.0) * w
    base = _box((w, d, t), (0, 0, 0))
    if kind == "L":
        return base + _box((t, d, arm), (w / 2 - t / 2, 0, arm / 2))
    if kind == "T":
        return base + _box((t, d, arm), (0, 0, -arm / 2))
    return (base + _box((t, d, arm), (w / 2 - t / 2, 0, arm / 2))
            + _box((t, d, arm), (-w / 2 + t / 2, 0, arm / 2)))


def _blobby(rng):
    parts, centres = [], [np.zeros(3)]
    for k in range(int(rng.integers(3, 7))):
        radii = rng.uniform(0.015, 0.045, size=3)
        if k:
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction)
            centres.append(centres[int(rng.integers(len(centres)))] + 0.6 * radii.min() * direction)
        ell = mf.Manifold.sphere(1.0, 20).scale(tuple(radii))
        parts.append(ell.rotate(tuple(rng.uniform(0, 360, size=3))).translate(tuple(centres[-1])))
    return mf.Manifold.batch_boolean(parts, mf.OpType.Add)


FAMILIES: dict = {
    "rounded_box": _rounded_box, "can": _can, "cylinder": _cylinder, "bottle": _bottle,
    "vase": _vase, "bowl": _bowl, "mug": _mug, "torus": _torus, "cone": _cone,
    "superellipsoid": _superellipsoid, "capsule": _capsule,
    "compound_L": lambda rng: _compound(rng, "L"), "compound_T": lambda rng: _compound(rng, "T"),
    "compound_U": lambda rng: _compound(rng, "U"), "blobby": _blobby,
}


@dataclass(frozen=True)
class ProceduralObject:
    """One generated object: ``obj_bytes`` is the OBJ text (metres) of a closed manifold mesh."""

    object_id: str
    family: str
    seed: int
    index: int
    obj_bytes: bytes


def object_id(seed: int, index: int) -> str:
    """Stable object id of procedural object ``index`` of generator ``seed``."""
    return f"proc-s{seed}-{index:06d}"


def family_of(seed: int, index: int) -> str:
    """The family drawn for ``(seed, index)`` (the first draw of its generator)."""
    return _family(np.random.default_rng([seed, index]))


def _family(rng) -> str:
    names = list(FAMILIES)
    return names[int(rng.integers(len(names)))]


def _to_obj(vertices: np.ndarray, faces: np.ndarray, header: str) -> bytes:
    lines = [f"# {header}"]
    lines += ["v %.6f %.6f %.6f" % tuple(v) for v in vertices.tolist()]
    lines += ["f %d %d %d" % tuple(f) for f in (faces + 1).tolist()]
    return ("\n".join(lines) + "\n").encode("ascii")


def generate(seed: int, index: int) -> ProceduralObject:
    """Generate procedural object ``index`` of generator ``seed`` (both non-negative ints)."""
    if seed < 0 or index < 0:
        raise ValueError(f"procedural object (seed={seed}, index={index}): both must be >= 0")
    rng = np.random.default_rng([seed, index])
    family = _family(rng)
    solid = FAMILIES[family](rng)
    mesh = solid.to_mesh()
    vertices = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    faces = np.asarray(mesh.tri_verts, dtype=np.int64)
    header = f"datagen procedural family={family} seed={seed} index={index}"
    return ProceduralObject(object_id(seed, index), family, seed, index,
                            _to_obj(vertices, faces, header))
