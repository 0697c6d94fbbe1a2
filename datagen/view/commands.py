"""``datagen view``: serve the dataset browser, or export static pages of a few grasps."""

from __future__ import annotations

import argparse
import socket
import sys
import time

__all__ = ["register_view"]


def register_view(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("view", help="browse grasps in 3D in a web page (needs the `view` extra: viser)",
                       description="Serve a local web page showing the grasps of a job, a shard or a grasp "
                                   "table (object, hand at pregrasp/grasp/squeeze/simulated, contacts, "
                                   "numbers, filters), or with --export write static HTML pages.")
    p.add_argument("source", help="job directory, shard (JOB/shards/part-*.parquet) or grasp table (.parquet)")
    p.add_argument("--port", type=int, default=8080, help="port (the next free one if taken; default 8080)")
    p.add_argument("--host", default="127.0.0.1",
                   help="interface to listen on (default loopback; reach it remotely with ssh -L)")
    p.add_argument("--row", type=int, default=None, help="row to show first (0-based)")
    p.add_argument("--export", metavar="DIR", default=None,
                   help="write self-contained HTML pages of a few grasps and an index.html to DIR, then exit")
    p.add_argument("--rows", type=int, nargs="+", default=None, help="with --export: these rows (0-based)")
    p.add_argument("--count", type=int, default=4, help="with --export: how many matching rows (default 4)")
    for name in ("verdict", "reason", "task", "hand", "object"):
        p.add_argument(f"--{name}", default=None, help=f"with --export: only rows of this {name}")
    p.set_defaults(func=_view, interrupted="the viewer stopped (with --export: no page is half-written, index.html "
                   "is written last; rerun the same command)")


def _need_viser() -> None:
    try:
        import viser  # noqa: F401
    except ImportError:
        raise ValueError("the viewer needs viser: pip install -e '.[view]' (or `make install`)") from None


def _view(args) -> int:
    from .source import open_source

    _need_viser()
    source = open_source(args.source)
    if args.export is not None:
        from .export import export_html

        if args.rows is not None:
            bad = [r for r in args.rows if not 0 <= r < len(source)]
            if bad:
                raise ValueError(f"rows {bad} are out of range ({args.source} has {len(source)} rows)")
            rows = list(args.rows)
        else:
            rows = [int(i) for i in source.select(verdict=args.verdict, reason=args.reason, task=args.task,
                                                  hand=args.hand, object_id=args.object)[:args.count]]
            if not rows:
                raise ValueError(f"{args.source}: no row matches the filters")
        pages = export_html(source, rows, args.export)
        print(f"wrote {len(pages)} pages and {args.export}/index.html")
        return 0
    from .app import Browser

    browser = Browser(source, host=args.host, port=args.port)
    if args.row is not None:
        if not 0 <= args.row < len(source):
            browser.stop()
            raise ValueError(f"row {args.row} is out of range ({args.source} has {len(source)} rows)")
        browser.select_row(args.row)
    print(f"datagen view: {len(source)} grasps at {browser.url} (Ctrl-C to stop)", flush=True)
    if args.host in ("127.0.0.1", "localhost"):
        port = browser.server.get_port()
        print(f"  from another machine: ssh -L {port}:localhost:{port} USER@{socket.gethostname()}, "
              f"then open http://localhost:{port}/", file=sys.stderr, flush=True)
    try:  # until Ctrl-C: `datagen.cli.main` prints its one line and exits 130
        while True:
            time.sleep(3600)
    finally:
        browser.stop()
