"""CLI: ``datagen hand init MJCF_OR_URDF --out myhand.yaml`` and ``datagen hand check myhand.yaml``:
bring your own hand (docs/hands.md). ``datagen hand calibrate`` needs synthesis and the MuJoCo
test, so it lives a layer up (`datagen.pipeline.calibrate`); ``datagen.pipeline.commands``
registers the ``hand`` command with all three actions.

``init`` proposes the spec (`make_spec.propose_spec`: spheres, fingertip pads, palm frame, open
pose, couplings, self-collision pairs), derives the values that were tuned by hand for the
built-in hands (`derive.derive_settings`), writes it, validates it (`validate.validate_hand`) and
renders the review picture. ``check`` validates an edited spec.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

__all__ = ["add_init_and_check"]


def add_init_and_check(actions: argparse._SubParsersAction) -> None:
    """The ``init`` and ``check`` actions of ``datagen hand``."""
    init = actions.add_parser("init", help="propose, validate and picture a hand spec for an MJCF/URDF")
    init.add_argument("source", help="the hand's MJCF or URDF (relative to --package's folder when given)")
    init.add_argument("--package", default="", help="installed Python package holding the asset (referenced, "
                      "never copied)")
    init.add_argument("--out", required=True, help="hand spec YAML to write")
    init.add_argument("--name", default=None, help="hand name, the rows' `hand` (default: the --out file's stem)")
    init.add_argument("--root-body", default=None, help="the hand's top body (default: the top-level body with "
                      "the most joints under it)")
    init.add_argument("--finger", action="append", default=[], metavar="LINK=NAME",
                      help="fingertip link and its finger name, in order (repeat; default: every leaf link "
                      "with collision geometry)")
    init.add_argument("--thumb", default=None, help="finger name of the thumb (default: the finger whose pad "
                      "faces the others')")
    init.add_argument("--render", default=None, help="review picture (default: the --out path with .png)")
    init.add_argument("--no-render", action="store_true", help="write no picture")
    init.add_argument("--seed", type=int, default=0, help="seed of the sphere fit")
    init.set_defaults(func=_init, interrupted="nothing was written to {out}; rerun the same command")

    check = actions.add_parser("check", help="validate a (hand-edited) hand spec against its MJCF/URDF")
    check.add_argument("spec", help="hand spec YAML (or a built-in hand name)")
    check.add_argument("--render", default=None, help="also draw the review picture to this PNG")
    check.set_defaults(func=_check, interrupted="nothing was written")


def _render(spec_path: Path, png: Path) -> str:
    """Draw the review picture of the spec at ``spec_path`` in a child process (mujoco is imported
    here already, with whatever ``MUJOCO_GL`` it found; the child starts with the backend
    `datagen.gl.select_backend` picks). Returns the line to print."""
    import multiprocessing as mp

    from datagen.gl import GLUnavailable, select_backend

    from .render import render_spec_file

    try:
        select_backend()
    except GLUnavailable as exc:
        return f"no review picture: {exc}"
    with mp.get_context("spawn").Pool(1) as pool:
        pool.apply(render_spec_file, (str(spec_path), str(png)))
    return (f"wrote {png} (blue: collision spheres; red: fingertip contact points, orange: their normals; palm "
            "approach blue, thumb axis green)")


def _report(findings) -> int:
    errors = [f for f in findings if f.level == "error"]
    for f in findings:
        print(f.line(), file=sys.stderr if f.level == "error" else sys.stdout)
    return 2 if errors else 0


def _top_body(source: Path) -> str:
    """The top-level body with the most joints under it (the hand, not a table or an object)."""
    from .mjcf import top_level_bodies

    bodies = top_level_bodies(source)
    if not bodies:
        from .spec import HandSpecError

        raise HandSpecError(source, "the model has no bodies", "check the file")
    return max(bodies, key=lambda nj: nj[1])[0]


def _init(args) -> int:
    t0 = time.perf_counter()
    import dataclasses
    import os

    from .derive import derive_settings
    from .load import load_hand
    from .make_spec import propose_spec
    from .mjcf import resolve_asset
    from .spec import AssetRef, HandSpecError, SphereFitConfig, dump_spec
    from .validate import validate_hand

    out = Path(args.out).resolve()
    if args.package:
        asset = AssetRef(path=args.source, package=args.package)
    else:
        asset = AssetRef(path=os.path.relpath(Path(args.source).resolve(), out.parent))
    source = resolve_asset(asset, str(out))
    name = args.name or re.sub(r"[^A-Za-z0-9_-]", "_", out.stem)
    root = args.root_body or _top_body(source)
    fingers = {}
    for item in args.finger:
        link, sep, fname = item.partition("=")
        fingers[link] = fname if sep else link
    spec, flat = propose_spec(source, name=name, root_body=root, asset=asset, fingers=fingers or None,
                              thumb=args.thumb, fit=SphereFitConfig(seed=args.seed))
    derived = derive_settings(spec, flat)
    spec = dataclasses.replace(spec, **derived.values)
    shown = " ".join(a for a in sys.argv[1:]) if sys.argv[1:2] == ["hand"] else f"hand init {args.source}"
    header = (f"Hand spec {name!r}, proposed by `datagen {shown}`.\n"
              "Review it with the picture beside it; `datagen hand check` after an edit, `datagen hand calibrate` "
              "to tune it on procedural objects.\nUnits: metres, radians; points and directions are in their link's "
              "body frame.\n" + "\n".join(f"{k}: {why}" for k, why in derived.reasons.items()))
    out.parent.mkdir(parents=True, exist_ok=True)
    dump_spec(spec, out, header)
    try:
        hand = load_hand(out)
    except HandSpecError as exc:
        print(f"datagen hand init: error: wrote {out}, but it does not load: {exc}", file=sys.stderr)
        return 2
    n = sum(len(v) for v in spec.spheres.values())
    print(f"wrote {out}: hand {name!r} from {source} (root body {root!r}), {hand.num_joints} joints, "
          f"{len(spec.fingertips)} fingers {list(spec.fingertips)}, palm link {spec.palm.link!r}, {n} spheres, "
          f"{len(spec.couplings)} couplings, {len(spec.self_collision_pairs)} self-collision link pairs")
    for k, why in derived.reasons.items():
        print(f"  {k} = {getattr(spec, k)}: {why}")
    code = _report(validate_hand(hand))
    if not args.no_render:
        print(_render(out, Path(args.render) if args.render else out.with_suffix(".png")))
    print(f"{time.perf_counter() - t0:.1f} s. " + ("Fix the errors above and run `datagen hand check "
          f"{args.out}`." if code else f"Next: datagen hand calibrate {args.out}; datagen run --hand {args.out}"))
    return code


def _check(args) -> int:
    from .load import hand_spec_path, load_hand
    from .validate import validate_hand

    hand = load_hand(args.spec)
    findings = validate_hand(hand)
    code = _report(findings)
    if args.render is not None:
        print(_render(hand_spec_path(args.spec), Path(args.render)))
    errors = sum(f.level == "error" for f in findings)
    print(f"{hand.name}: {hand.num_joints} joints, {len(hand.fingertip_names)} fingers, {hand.num_spheres} spheres: "
          + (f"{errors} error(s)" if errors else "ok") + f", {len(findings) - errors} warning(s)")
    return code
