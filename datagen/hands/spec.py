"""Hand specs: the small typed description of a hand that sits beside its MJCF/URDF.

A spec names the kinematic source (an MJCF or URDF inside an installed registry package, or a
user's file), the root body, and everything grasp synthesis needs that the source does not say:
collision spheres per link, fingertip contact points, the palm frame, the default open pose,
joint couplings and the self-collision link pairs. Specs are written by
``python -m datagen.hands.make_spec`` and reviewed by a person; the built-in ones live in
``datagen/hands/specs/*.yaml``.

Units: metres and radians throughout; every point and direction is in its link's body frame
(the MuJoCo body frame of that link).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Mapping

import yaml

from datagen._atomic import atomic_write_text
from datagen._bounded import HAND_SPEC_BYTES, read_text
from datagen.config import Config
from datagen.errors import DatagenError

__all__ = [
    "HandSpecError",
    "AssetRef",
    "Fingertip",
    "PalmFrame",
    "Coupling",
    "SelfCollisionPair",
    "SphereFitConfig",
    "HandSpec",
    "load_spec",
    "dump_spec",
]

SPEC_VERSION = 1


class HandSpecError(DatagenError, ValueError):
    """A hand spec or hand asset is unusable; the message names the file, the reason and the fix."""

    def __init__(self, path: str | Path | None, reason: str, remedy: str = "") -> None:
        self.path = None if path is None else str(path)
        self.reason = reason
        where = f"{self.path}: " if self.path else ""
        super().__init__(f"{where}{reason}", remedy)

    @classmethod
    def make(cls, thing: str, reason: str, remedy: str = "") -> "HandSpecError":
        """The error `datagen.config` raises for a bad field ``thing`` (the file is added by the caller)."""
        return cls(None, f"{thing}: {reason}", remedy)


def _vec(value: Any, n: int, what: str, path: str | None) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise HandSpecError(path, f"{what} must be a list of {n} numbers, got {value!r}") from None
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise HandSpecError(path, f"{what} must be {n} finite numbers, got {value!r}")
    return out


def _unit(value: Any, what: str, path: str | None) -> tuple[float, float, float]:
    v = _vec(value, 3, what, path)
    norm = math.sqrt(sum(x * x for x in v))
    if norm < 1e-9:
        raise HandSpecError(path, f"{what} must be a non-zero direction, got {value!r}")
    return tuple(x / norm for x in v)  # type: ignore[return-value]


@dataclass(frozen=True)
class AssetRef:
    """Where the hand's MJCF/URDF lives.

    ``package`` set: ``path`` is relative to that installed Python package's directory (registry
    assets are referenced, never copied). ``package`` empty: ``path`` is absolute or relative to
    the spec file's directory. ``sha256``: set in a pinned copy (a job's ``hands/NAME.yaml``):
    `datagen.hands.asset.asset_sha256` of the files the spec was used with; loading refuses other
    bytes.
    """

    path: str
    package: str = ""
    sha256: str = ""

    def __post_init__(self) -> None:
        if not self.path:
            raise HandSpecError(None, "mjcf.path is empty")
        if self.sha256 and (len(self.sha256) != 64 or any(c not in "0123456789abcdef" for c in self.sha256)):
            raise HandSpecError(None, f"mjcf.sha256 must be 64 lowercase hex digits, got {self.sha256!r}")


@dataclass(frozen=True)
class Fingertip:
    """One named contact point on a finger pad (link frame, metres) and the pad's outward normal."""

    link: str
    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    # the link's collision sphere that carries the contact (an index into `HandSpec.spheres[link]`);
    # None: the sphere whose surface is nearest ``point`` (`datagen.synth.energies.contact_sphere_index`)
    sphere: int | None = None


@dataclass(frozen=True)
class PalmFrame:
    """Palm frame in ``link``'s frame: origin on the palm surface, approach = palm normal pointing
    out of the palm (the direction the hand moves to grasp), thumb = unit axis towards the thumb,
    orthogonal to approach."""

    link: str
    origin: tuple[float, float, float]
    approach: tuple[float, float, float]
    thumb: tuple[float, float, float]

    def __post_init__(self) -> None:
        dot = sum(a * b for a, b in zip(self.approach, self.thumb))
        if abs(dot) > 1e-3:
            raise HandSpecError(None, f"palm.approach and palm.thumb must be orthogonal (dot {dot:.3g})")


@dataclass(frozen=True)
class Coupling:
    """A passive joint coupling: ``q[joint] = ratio * q[leader] + offset`` (radians).

    Shadow's tendon-coupled fingertip joints: the distal joint follows the middle joint.
    """

    joint: str
    leader: str
    ratio: float
    offset: float = 0.0


@dataclass(frozen=True)
class SelfCollisionPair:
    """Two links checked against each other for self-collision, and which of their spheres take
    part (indices into each link's sphere list; empty = all of them)."""

    link_a: str
    link_b: str
    spheres_a: tuple[int, ...] = ()
    spheres_b: tuple[int, ...] = ()


@dataclass(frozen=True)
class SphereFitConfig(Config):
    """Parameters of the sphere fit (kept in the spec so the fit is reproducible)."""

    config_error: ClassVar[type[HandSpecError]] = HandSpecError

    overshoot: float = 0.0028  # m, how far a sphere may reach beyond the collision geometry
    coverage: float = 0.985 # target fraction of surface samples covered, per link
    max_spheres_per_link: int = 256
    samples_per_link: int = 3000  # surface samples per link for the greedy cover
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0.0 < self.overshoot <= 0.01:
            raise HandSpecError(None, f"sphere_fit.overshoot must be in (0, 0.01] m, got {self.overshoot}")
        if not 0.5 <= self.coverage <= 1.0:
            raise HandSpecError(None, f"sphere_fit.coverage must be in [0.5, 1], got {self.coverage}")
        if self.max_spheres_per_link < 1 or self.samples_per_link < 100:
            raise HandSpecError(None, "sphere_fit.max_spheres_per_link >= 1 and samples_per_link >= 100")


@dataclass(frozen=True)
class HandSpec:
    """Everything datagen knows about one hand, beyond its MJCF/URDF (see module docstring)."""

    name: str
    mjcf: AssetRef
    root_body: str
    spheres: Mapping[str, tuple[tuple[float, float, float, float], ...]]  # link -> (x, y, z, r)
    fingertips: Mapping[str, Fingertip]
    palm: PalmFrame
    open_pose: Mapping[str, float] = field(default_factory=dict)  # joint -> rad; missing joints: 0 clipped
    couplings: tuple[Coupling, ...] = ()
    self_collision_pairs: tuple[SelfCollisionPair, ...] = ()
    sphere_fit: SphereFitConfig = field(default_factory=SphereFitConfig)
    position_actuator_kp: float = 5.0  # gain of the position actuators added when the source has none
    # How far (m) synthesis lets this hand's collision spheres sink into the object before they
    # count as penetrating: where the spheres overshoot the hand's collision geometry, a sunk sphere
    # is a real link just touching. Shadow's coarse fit (429 spheres) needs 1.5 mm; Allegro's fine
    # one (792) penetrates 1.2 mm at p90 in MuJoCo with that, 0.03 mm with 0.5 mm, at the same
    # success (benchmarks/results/quality.md). SynthConfig.sphere_margin_m overrides it.
    sphere_margin_m: float = 0.0015
    # The finger that opposes the others (one of `fingertips`; None: the hand has none): a wrap or
    # rim start turns the thumb-to-fingers axis across the object (`datagen.synth.init`). A spec
    # without the key: "th" when it names a finger so, else None.
    thumb_finger: str | None = None
    source_file: str | None = None  # the YAML this spec was read from, for error messages

    def __post_init__(self) -> None:
        p = self.source_file
        if not self.name or not self.name.replace("_", "").replace("-", "").isalnum():
            raise HandSpecError(p, f"name must be a simple identifier, got {self.name!r}")
        if not self.root_body:
            raise HandSpecError(p, "root_body is empty", "name the MJCF body that is the hand's root")
        if not self.spheres or not any(self.spheres.values()):
            raise HandSpecError(p, "no collision spheres", "regenerate the spec with make_spec")
        for link, spheres in self.spheres.items():
            for s in spheres:
                if not s[3] > 0:
                    raise HandSpecError(p, f"sphere radius must be > 0 on link {link!r}, got {s[3]}")
        if not self.fingertips:
            raise HandSpecError(p, "no fingertips", "list at least one fingertip contact point")
        for fname, tip in self.fingertips.items():
            n = len(self.spheres.get(tip.link, ()))
            if tip.sphere is not None and not 0 <= tip.sphere < n:
                raise HandSpecError(p, f"fingertips.{fname}.sphere {tip.sphere} is out of range: link {tip.link!r} "
                                    f"has {n} spheres", "give an index below that, or remove the key")
        for pr in self.self_collision_pairs:
            for link, idx in ((pr.link_a, pr.spheres_a), (pr.link_b, pr.spheres_b)):
                n = len(self.spheres.get(link, ()))
                if n == 0 or any(not 0 <= i < n for i in idx):
                    raise HandSpecError(p, f"self_collision_pairs: link {link!r} has {n} spheres, "
                                        f"sphere indices {list(idx)[:5]}... are out of range")
        if self.thumb_finger is not None and self.thumb_finger not in self.fingertips:
            raise HandSpecError(p, f"thumb_finger {self.thumb_finger!r} is not one of the fingertips "
                                f"{list(self.fingertips)}", "name one of them, or remove the key for a hand without a thumb")
        if self.position_actuator_kp <= 0:
            raise HandSpecError(p, "position_actuator_kp must be > 0")
        if not 0 <= self.sphere_margin_m < 0.01:
            raise HandSpecError(p, f"sphere_margin_m must be in [0, 0.01) m, got {self.sphere_margin_m}")

    # ------------------------------------------------------------------ YAML round trip
    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source_file: str | Path | None = None) -> "HandSpec":
        """Build and validate a spec from its YAML mapping; errors name ``source_file``."""
        p = None if source_file is None else str(source_file)
        _check_keys(data, p)
        try:
            mjcf, spheres = _asset_ref(data["mjcf"], p), _spheres(data["spheres"], p)
            tips = _fingertips(data["fingertips"], p)
            palm, couplings = _palm(data["palm"], p), _couplings(data.get("couplings"))
            pairs = _pairs(data.get("self_collision_pairs"), p)
            return cls(
                name=str(data["name"]), mjcf=mjcf, root_body=str(data["root_body"]), spheres=spheres,
                fingertips=tips, palm=palm, couplings=couplings, self_collision_pairs=pairs,
                sphere_fit=SphereFitConfig.from_dict(data.get("sphere_fit"), "sphere_fit"),
                open_pose={str(k): float(v) for k, v in (data.get("open_pose") or {}).items()},
                position_actuator_kp=float(data.get("position_actuator_kp", 5.0)),
                sphere_margin_m=float(data.get("sphere_margin_m", 0.0015)),
                thumb_finger=_thumb_finger(data, tips), source_file=p,
            )
        except HandSpecError as exc:
            if exc.path is None and p is not None:
                raise HandSpecError(p, exc.reason, exc.remedy) from None
            raise
        except (KeyError, TypeError, ValueError) as exc:
            raise HandSpecError(p, f"malformed spec: {type(exc).__name__}: {exc}") from None

    def to_dict(self) -> dict[str, Any]:
        """The YAML mapping of this spec (numbers rounded to 0.1 micrometre / 1e-6)."""

        def r(xs, nd=7):
            return [round(float(x), nd) for x in xs]

        mjcf: dict[str, Any] = {"path": self.mjcf.path}
        if self.mjcf.package:
            mjcf = {"package": self.mjcf.package, "path": self.mjcf.path}
        if self.mjcf.sha256:
            mjcf["sha256"] = self.mjcf.sha256
        return {
            "version": SPEC_VERSION,
            "name": self.name,
            "mjcf": mjcf,
            "root_body": self.root_body,
            "palm": {"link": self.palm.link, "origin": r(self.palm.origin), "approach": r(self.palm.approach, 6),
                     "thumb": r(self.palm.thumb, 6)},
            "fingertips": {k: {"link": t.link, "point": r(t.point), "normal": r(t.normal, 6),
                               **({} if t.sphere is None else {"sphere": t.sphere})}
                           for k, t in self.fingertips.items()},
            "open_pose": {k: round(float(v), 6) for k, v in self.open_pose.items()},
            "couplings": [{"joint": c.joint, "leader": c.leader, "ratio": round(c.ratio, 6),
                           "offset": round(c.offset, 6)} for c in self.couplings],
            **({"thumb_finger": self.thumb_finger} if self.thumb_finger != default_thumb(self.fingertips) else {}),
            "position_actuator_kp": self.position_actuator_kp,
            "sphere_margin_m": self.sphere_margin_m,
            "sphere_fit": {"overshoot": self.sphere_fit.overshoot, "coverage": self.sphere_fit.coverage,
                           "max_spheres_per_link": self.sphere_fit.max_spheres_per_link,
                           "samples_per_link": self.sphere_fit.samples_per_link, "seed": self.sphere_fit.seed},
            "self_collision_pairs": [
                {"links": [pr.link_a, pr.link_b], "spheres_a": list(pr.spheres_a), "spheres_b": list(pr.spheres_b)}
                for pr in self.self_collision_pairs],
            "spheres": {k: [r(s) for s in v] for k, v in self.spheres.items()},
        }


def default_thumb(fingertips: Mapping[str, Any]) -> str | None:
    """The thumb of a spec that does not name one: the finger called "th", if any."""
    return "th" if "th" in fingertips else None


def _thumb_finger(data: Mapping[str, Any], tips: Mapping[str, Any]) -> str | None:
    if "thumb_finger" not in data:
        return default_thumb(tips)
    value = data["thumb_finger"]
    return None if value is None else str(value)


class _FlowListDumper(yaml.SafeDumper):
    """Writes short numeric lists inline ([x, y, z, r]) so specs stay readable and small."""


def _repr_list(dumper: yaml.SafeDumper, data: list) -> yaml.Node:
    flow = all(isinstance(x, (int, float)) for x in data) or (
        len(data) <= 4 and all(isinstance(x, (int, float, str)) for x in data))
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_FlowListDumper.add_representer(list, _repr_list)


# libyaml's safe loader where PyYAML was built with it: the same documents as yaml.safe_load (the
# built-in specs are checked in tests/hands/test_spec.py), 6x faster on a spec's sphere lists
# (LEAP's 94 kB: 0.20 -> 0.03 s, paid by every process that loads a hand).
_SPEC_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def load_spec(path: str | Path) -> HandSpec:
    """Read and validate a YAML hand spec; any problem raises `HandSpecError` naming ``path``."""
    path = Path(path)
    if not path.is_file():
        raise HandSpecError(path, "hand spec file not found", "pass a built-in hand name or an existing YAML path")
    try:
        data = yaml.load(read_text(path, HAND_SPEC_BYTES, "hand spec"), Loader=_SPEC_LOADER)  # noqa: S506 - safe
    except yaml.YAMLError as exc:
        raise HandSpecError(path, f"not valid YAML: {exc}") from None
    return HandSpec.from_dict(data, source_file=path)


def dump_spec(spec: HandSpec, path: str | Path, header: str = "") -> None:
    """Write ``spec`` as YAML to ``path``; ``header`` lines become leading comments."""
    text = yaml.dump(spec.to_dict(), Dumper=_FlowListDumper, sort_keys=False, width=120)
    comments = "".join(f"# {line}\n" if line else "#\n" for line in header.splitlines())
    atomic_write_text(path, comments + text)


_SPEC_KEYS = {"version", "name", "mjcf", "root_body", "spheres", "fingertips", "palm", "open_pose",
              "couplings", "self_collision_pairs", "sphere_fit", "position_actuator_kp", "sphere_margin_m",
              "thumb_finger"}


def _check_keys(data: Any, p: str | None) -> None:
    """A spec is a mapping of this version with the required keys and no unknown one."""
    if not isinstance(data, Mapping):
        raise HandSpecError(p, "a hand spec must be a YAML mapping")
    version = data.get("version", SPEC_VERSION)
    if version != SPEC_VERSION:
        raise HandSpecError(p, f"spec version {version!r} is not supported (expected {SPEC_VERSION})")
    unknown = sorted(set(data) - _SPEC_KEYS)
    if unknown:
        raise HandSpecError(p, f"unknown keys {unknown}", f"allowed keys: {sorted(_SPEC_KEYS)}")
    for key in ("name", "mjcf", "root_body", "spheres", "fingertips", "palm"):
        if key not in data:
            raise HandSpecError(p, f"missing required key {key!r}")


def _asset_ref(mj: Any, p: str | None) -> AssetRef:
    """``mjcf:`` as a path or a mapping {path, package, sha256}."""
    if isinstance(mj, str):
        return AssetRef(path=mj)
    if not isinstance(mj, Mapping):
        raise HandSpecError(p, "mjcf must be a path or a mapping {package, path}")
    extra = sorted(set(mj) - {"path", "package", "sha256"})
    if extra:
        raise HandSpecError(p, f"mjcf: unknown keys {extra}", "allowed: path, package, sha256")
    return AssetRef(path=str(mj.get("path", "")), package=str(mj.get("package", "") or ""),
                    sha256=str(mj.get("sha256", "") or ""))


def _spheres(data: Any, p: str | None) -> dict[str, tuple]:
    """``spheres:``: link name -> tuple of [x, y, z, r] (link frame, metres)."""
    if not isinstance(data, Mapping):
        raise HandSpecError(p, "spheres must map link names to lists of [x, y, z, r]")
    return {str(link): tuple(_vec(s, 4, f"sphere on link {link!r}", p) for s in (items or ()))
            for link, items in data.items()}


def _fingertips(data: Any, p: str | None) -> dict[str, "Fingertip"]:
    """``fingertips:``: finger name -> {link, point, normal, sphere}."""
    if not isinstance(data, Mapping):
        raise HandSpecError(p, "fingertips must map finger names to {link, point, normal}")
    tips = {}
    for fname, tip in data.items():
        if not isinstance(tip, Mapping) or "link" not in tip or "point" not in tip:
            raise HandSpecError(p, f"fingertip {fname!r} needs link, point and normal")
        tips[str(fname)] = Fingertip(
            link=str(tip["link"]),
            point=_vec(tip["point"], 3, f"fingertips.{fname}.point", p),
            normal=_unit(tip.get("normal"), f"fingertips.{fname}.normal", p),
            sphere=None if tip.get("sphere") is None else int(tip["sphere"]),
        )
    return tips


def _palm(data: Any, p: str | None) -> "PalmFrame":
    """``palm:`` {link, origin, approach, thumb}; the two directions normalised."""
    if not isinstance(data, Mapping):
        raise HandSpecError(p, "palm must be a mapping {link, origin, approach, thumb}")
    return PalmFrame(link=str(data.get("link", "")), origin=_vec(data.get("origin"), 3, "palm.origin", p),
                     approach=_unit(data.get("approach"), "palm.approach", p),
                     thumb=_unit(data.get("thumb"), "palm.thumb", p))


def _couplings(data: Any) -> tuple["Coupling", ...]:
    """``couplings:`` [{joint, leader, ratio, offset}]."""
    return tuple(Coupling(joint=str(c["joint"]), leader=str(c["leader"]), ratio=float(c["ratio"]),
                          offset=float(c.get("offset", 0.0))) for c in (data or ()))


def _pairs(data: Any, p: str | None) -> tuple["SelfCollisionPair", ...]:
    """``self_collision_pairs:`` entries [link, link] or {links, spheres_a, spheres_b}."""
    pairs = []
    for pair in data or ():
        if isinstance(pair, Mapping) and len(pair.get("links", ())) == 2:
            pairs.append(SelfCollisionPair(
                str(pair["links"][0]), str(pair["links"][1]),
                tuple(int(i) for i in pair.get("spheres_a") or ()),
                tuple(int(i) for i in pair.get("spheres_b") or ())))
        elif isinstance(pair, (list, tuple)) and len(pair) == 2:
            pairs.append(SelfCollisionPair(str(pair[0]), str(pair[1])))
        else:
            raise HandSpecError(p, "self_collision_pairs entries are [link, link] or "
                                f"{{links: [a, b], spheres_a: [...], spheres_b: [...]}}, got {pair!r}")
    return tuple(pairs)
