"""Static, self-contained HTML pages of a few grasps (for a paper, a dataset card, a bug report).

Each page is viser's client with the scene embedded (``StateSerializer.as_html``: no server,
no network; open the file in a browser). The scene plays the row's poses in order, one per
``seconds_per_pose`` (pregrasp, grasp, squeeze, simulated), with viser's playback controls; a
label names the pose and the verdict. ``index.html`` lists the pages with each row's numbers.
Exporting starts a viser server on a free loopback port for the time it takes (viser records
scenes from a server) and stops it.
"""

from __future__ import annotations

import html
from pathlib import Path

from datagen._atomic import atomic_write_text

from .draw import GraspDrawing, camera_for
from .panel import METRICS, format_value, unit_of, verdict_line
from .posing import STATES, SceneCache
from .source import GraspSource, find_column

__all__ = ["export_html"]


def _page_name(source: GraspSource, i: int) -> str:
    gid = source.value("grasp_id", i)
    return f"grasp-{i:05d}" + (f"-{str(gid)[:12]}" if gid else "") + ".html"


def export_html(source: GraspSource, rows: list[int], out_dir: str | Path, *,
                seconds_per_pose: float = 1.5) -> list[Path]:
    """Write one page per row of ``rows`` and ``index.html`` into ``out_dir``; returns the pages."""
    import viser

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cache = SceneCache(source.eval_config, base=source.base)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    pages = []
    try:
        for i in rows:
            server.scene.set_up_direction("+z")
            drawing = GraspDrawing(server.scene)
            hand, task, scale = source.value("hand", i), source.value("task", i) or "", source.scale(i)
            posed = cache.posed(hand, source.object_dir(i), scale, task, source.poses(i), source.table(i))
            key = (hand, str(source.object_dir(i)), scale, task, source.table(i))
            server.scene.set_up_direction(tuple(key[4][:3]) if key[4] else "+z")  # the table's up
            points, normals = source.value("contact_points", i), source.value("contact_normals", i)
            head = f"{source.value('object_id', i)} at {scale:.3f} m, {hand}, {task}: {verdict_line(source, i)}"

            def draw(state: str) -> None:
                drawing.show(posed, points, normals, state, key)
                server.scene.add_label("/label", f"{head}; pose: {state}", position=(0.0, 0.0, 2.5 * scale))

            draw(STATES[0])
            pos, look = camera_for(posed)
            server.initial_camera.position = tuple(pos)
            server.initial_camera.look_at = tuple(look)
            recording = server.get_scene_serializer()
            for state in STATES[1:]:
                recording.insert_sleep(seconds_per_pose)
                draw(state)
            recording.insert_sleep(seconds_per_pose)
            page = out / _page_name(source, i)
            atomic_write_text(page, recording.as_html())
            pages.append(page)
            server.scene.reset()
    finally:
        server.stop()
    _write_index(source, rows, pages, out / "index.html")
    return pages


def _write_index(source: GraspSource, rows: list[int], pages: list[Path], path: Path) -> None:
    schema = source.schema
    metric_cols = [(find_column(schema.names, stem), label) for stem, label in METRICS]
    metric_cols = [(c, label) for c, label in metric_cols if c is not None]
    head = ["page", "object", "scale", "hand", "task", "verdict"] + [label for _, label in metric_cols]
    lines = ["<!doctype html>", "<meta charset='utf-8'>", f"<title>datagen grasps: {html.escape(source.where)}</title>",
             "<style>body{font-family:sans-serif} td,th{padding:2px 8px;border-bottom:1px solid #ddd}</style>",
             f"<h1>Grasps of {html.escape(source.where)}</h1>",
             "<p>Each page plays pregrasp, grasp, squeeze (actuator target) and the simulated closing; "
             "drag to orbit, scroll to zoom. Pages are self-contained: no server or network needed.</p>",
             "<table>", "<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr>"]
    for i, page in zip(rows, pages):
        row = source.row(i)
        cells = [f"<a href='{html.escape(page.name)}'>{html.escape(page.stem)}</a>", html.escape(str(row["object_id"])),
                 source.value("scale", i), html.escape(str(row["hand"])),
                 html.escape(str(row.get("task", ""))), html.escape(verdict_line(source, i)[len("Verdict: "):])]
        cells += [html.escape(format_value(row[c], unit_of(schema.field(c)))) for c, _ in metric_cols]
        lines.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    lines.append("</table>")
    atomic_write_text(path, "\n".join(lines) + "\n")
