"""Hand kinematics benchmark: FK + collision spheres, forward and forward+backward, per hand.

For each available built-in hand and batch size B in (100, 1000), float32 on the CPU (or the GPU
when there is one): median wall time over several runs of
* fk: ``link_transforms`` (all links, root pose applied), no grad;
* fk+spheres: ``spheres`` (world centres of every collision sphere) plus fingertip points, no grad;
* fk+spheres fwd+bwd: the same with root pose and joints requiring grad, a scalar loss, backward;
* self-pen fwd+bwd (B=100 only): ``self_penetration`` over all self-collision sphere pairs.

Run with ``make bench-hands``; writes ``benchmarks/results/hands.md``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import torch

from benchmarks.common import machine_description, replace_section
from datagen.hands import available_hands, load_hand

RESULTS = Path(__file__).parent / "results" / "hands.md"
HEADING = "## Hand kinematics benchmark (`make bench-hands`)"


def timings(fn, repeats: int) -> tuple[float, float]:
    """(median, min) wall time of ``fn()`` in ms over ``repeats`` runs after one warm-up run. The
    minimum is reported too: on a shared machine it is the steadier estimate of the cost."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times), min(times)
BATCHES = (100, 1000)


def _inputs(hand, B: int, gen: torch.Generator, grad: bool):
    root = torch.cat([0.1 * torch.randn(B, 3, generator=gen), torch.randn(B, 4, generator=gen)], dim=-1)
    q = hand.random_joints((B,), gen).cpu()
    root, q = root.to(hand.device, hand.dtype), q.to(hand.device, hand.dtype)
    return root.requires_grad_(grad), q.requires_grad_(grad)


def _fmt(t) -> str:
    return "" if t is None else f"{t[0]:.1f} ({t[1]:.1f})"


def bench_hand(name: str, repeats: int, device: str) -> list[tuple]:
    hand = load_hand(name, device=device, dtype=torch.float32)
    gen = torch.Generator().manual_seed(0)
    sync = torch.cuda.synchronize if device.startswith("cuda") else (lambda: None)
    rows = []
    for B in BATCHES:
        root, q = _inputs(hand, B, gen, grad=False)

        def fk():
            hand.link_transforms(root, q)
            sync()

        def fk_spheres():
            T = hand.link_transforms(root, q)
            hand.spheres(root, q, T)
            hand.fingertip_points(root, q, T)
            sync()

        rg, qg = _inputs(hand, B, gen, grad=True)

        def fk_spheres_bwd():
            T = hand.link_transforms(rg, qg)
            c, r = hand.spheres(rg, qg, T)
            loss = (c.square().sum(-1) - r.square()).sum() + hand.fingertip_points(rg, qg, T).square().sum()
            loss.backward()
            sync()

        times = [timings(f, repeats) for f in (fk, fk_spheres, fk_spheres_bwd)]
        if B == 100:
            def self_pen():
                hand.self_penetration(rg, qg).sum().backward()
                sync()
            times.append(timings(self_pen, max(3, repeats // 2)))
        else:
            times.append(None)
        rows.append((name, hand.num_joints, hand.num_spheres, len(hand.self_collision_pairs), B, *times))
        print(f"{name:12s} B={B:5d} " + " ".join(_fmt(t) for t in times) + " ms", flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=11)
    parser.add_argument("--hands", nargs="*", default=None)
    parser.add_argument("--out", type=Path, default=RESULTS)
    # One thread by default: on the shared 2-core machine, two intra-op threads stall whenever one is
    # descheduled (medians with 2 threads swung 10-100x run to run); 0 keeps torch's default.
    parser.add_argument("--threads", type=int, default=1, help="torch intra-op threads (0: torch's default)")
    args = parser.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    device = "cuda" if torch.cuda.is_available() else "cpu"
    machine = machine_description()
    hands = args.hands or available_hands()
    rows = [r for name in hands for r in bench_hand(name, args.repeats, device)]
    lines = [
        HEADING,
        "",
        f"Machine: {machine}. Device: {device}, float32. Each cell: median (minimum) in ms of "
        f"{args.repeats} runs after a warm-up. Load average at the end: {os.getloadavg()[0]:.2f} "
        "(the machine is shared; medians include other users' load).",
        "",
        "fk = `link_transforms`; fk+spheres = FK + world sphere centres + fingertip points; fwd+bwd adds a "
        "scalar loss over them and `backward()` (root pose and joints require grad; pytorch-kinematics' "
        "analytical FK backward); self-pen = `self_penetration` over every self-collision sphere pair, "
        "forward + backward, B=100 only. One torch thread unless `--threads` says otherwise: with two "
        "threads on this shared 2-core machine the medians swung 10-100x between runs.",
        "",
        "| hand | joints | spheres | self-coll. sphere pairs | B | fk | fk+spheres | fk+spheres fwd+bwd | self-pen fwd+bwd |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, J, S, P, B, t_fk, t_sp, t_bwd, t_self in rows:
        lines.append(f"| {name} | {J} | {S} | {P} | {B} | {_fmt(t_fk)} | {_fmt(t_sp)} | {_fmt(t_bwd)} | {_fmt(t_self)} |")
    missing = [n for n in ("shadow", "leap", "allegro", "shadow_e3m5") if n not in hands]
    if missing:
        lines += ["", f"Not measured (asset package not installed; `make hands`): {', '.join(missing)}."]
    replace_section(args.out, HEADING, lines)  # the page's other sections (bench_any_hand) are kept
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
