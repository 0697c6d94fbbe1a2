"""``datagen report JOB_DIR``: a dataset card (JOB_DIR/README.md) with tables and rendered grasps.

Rendering uses MuJoCo's offscreen GL, chosen by `datagen.gl.select_backend` (``MUJOCO_GL`` if set,
else egl, then osmesa); when no backend works the card says so instead of showing pictures.
"""

from __future__ import annotations

import json
import os
from collections import Counter
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from .job import JobDir
from .status import job_status

__all__ = ["write_report"]


def _table(header: list[str], rows: list[list]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return out + [""]


def _read_rows(job: JobDir) -> pa.Table | None:
    paths = [job.shard_path(i) for i in sorted(job.finished()) if job.shard_path(i).is_file()]
    tables = [pq.read_table(p) for p in paths]
    tables = [t for t in tables if t.num_rows]
    return pa.concat_tables(tables) if tables else None


def _render(job: JobDir, rows: pa.Table, n: int) -> tuple[list[str], str]:
    """(relative PNG paths, note). Renders the first ``n`` successful grasps (else any) in a fresh
    process: MuJoCo reads MUJOCO_GL when first imported, and this one may have imported it."""
    if n <= 0 or rows is None:
        return [], "Rendering was skipped (--renders 0)."
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    from datagen.gl import GLUnavailable, select_backend

    try:
        select_backend()  # sets MUJOCO_GL, inherited by the rendering process
    except GLUnavailable as exc:
        return [], f"No grasp pictures: {exc}. Rerun `datagen report` once a backend works."
    ok = [i for i, s in enumerate(rows["success"].to_pylist()) if s] or list(range(rows.num_rows))
    picked = rows.take(ok[:n]).to_pylist()
    with ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as pool:
        return pool.submit(_render_rows, str(job.path), picked).result()


def _render_rows(path: str, picked: list[dict]) -> tuple[list[str], str]:
    job = JobDir(path)
    try:
        from datagen.eval import EvalConfig, build_scene
        from datagen.eval.render import render_grasp
        from datagen.eval.table import row_pieces, row_poses
        from datagen.hands import load_hand

        cfg = EvalConfig.from_dict(job.config().eval)
        paths, hands = [], {}
        for row in picked:
            hand = hands.setdefault(row["hand"], load_hand(row["hand"]))
            scene = build_scene(hand, row_pieces(row, job.path), cfg, cfg.task_test(row["task"]))
            rel = f"renders/{row['grasp_id']}.png"
            render_grasp(scene, row_poses(row), cfg, job.path / rel)
            paths.append(rel)
        return paths, ""
    except Exception as exc:  # noqa: BLE001 - no GL is a note in the card, not an error
        return [], (f"No grasp pictures: no offscreen GL context could be opened "
                    f"(MUJOCO_GL={os.environ.get('MUJOCO_GL')}): {type(exc).__name__}: {exc}. "
                    "`python -m datagen.gl` names a backend that works; rerun `datagen report`.")


def write_report(path: str | Path, renders: int = 3) -> Path:
    job = JobDir(path)
    doc = job.read_job()
    s = job_status(job.path)
    rows = _read_rows(job)
    fails = pq.read_table(job.failures_path) if job.failures_path.is_file() else None
    cfg = doc["config"]
    md = [f"# Dataset card: {job.path.name}", "",
          f"Dexterous grasps of the **{cfg['hand']}** hand on {s['objects']} objects from `{cfg['source']}`, "
          f"tasks {', '.join(cfg['tasks'])}, synthesized by `datagen` and verified in MuJoCo.", "",
          f"- config hash `{doc['config_hash']}`, code `{doc['code_version']}`, created {doc['created_at']} "
          f"on `{doc['host']}`",
          f"- shards {s['shards_done']}/{s['shards_total']}{'' if s['complete'] else ' (incomplete)'}; "
          f"files `shards/part-NNNNN.parquet` (schema `evaluated`, see `schemas/`), `failures.parquet`",
          f"- packages: " + ", ".join(f"{k} {v}" for k, v in doc["packages"].items()), "",
          "## Outcome", ""]
    md += _table(["grasps", "successful", "success rate", "objects failed"],
                 [[s["grasps"], s["success"], f"{s['success_rate']:.1%}", fails.num_rows if fails is not None else 0]])
    if rows is not None:
        md += ["### By task and scale", ""]
        groups: dict = {}
        for t, sc, ok in zip(rows["task"].to_pylist(), rows["object_scale"].to_pylist(), rows["success"].to_pylist()):
            g = groups.setdefault((t, round(sc, 4)), [0, 0])
            g[0] += 1
            g[1] += bool(ok)
        md += _table(["task", "scale (m)", "grasps", "success rate"],
                     [[t, sc, n, f"{k / n:.1%}"] for (t, sc), (n, k) in sorted(groups.items())])
        md += ["### Grasp outcomes (reason codes)", ""]
        md += _table(["reason", "grasps"], [[k, v] for k, v in s["eval_reasons"].items()])
        md += ["### Metrics (successful grasps)", ""]
        okr = rows.filter(pc.equal(rows["success"], True))
        mrows = []
        for col, unit, mult in (("penetration_m", "mm", 1000), ("max_penetration", "mm", 1000), ("epsilon", "", 1),
                                ("synth_epsilon", "", 1), ("touching_links", "", 1)):
            if okr.num_rows:
                v = okr[col].cast(pa.float64())
                mrows.append([col, unit, f"{pc.mean(v).as_py() * mult:.3g}", f"{pc.max(v).as_py() * mult:.3g}"])
        md += _table(["column", "unit", "mean", "max"], mrows) if mrows else ["no successful grasps", ""]
    md += ["## Failures (objects without rows)", ""]
    if fails is not None and fails.num_rows:
        md += _table(["stage", "reason", "objects"],
                     [[k.split(':')[0], k.split(':', 1)[1], v] for k, v in Counter(
                         f"{a}:{b}" for a, b in zip(fails["stage"].to_pylist(), fails["reason"].to_pylist())).items()])
    else:
        md += ["none", ""]
    md += ["## Where the time went (worker seconds)", ""]
    md += _table(["stage", "seconds"], [[k[:-2], f"{v:.1f}"] for k, v in s["stage_seconds"].items()])
    md += ["shard_wall / shard_cpu: wall and CPU seconds of the shard tasks (CPU excludes isolated CoACD "
           "processes).", ""]
    pics, note = _render(job, rows, renders)
    md += ["## Grasps", ""]
    if pics:
        md += ["Columns: hand at the pregrasp, the grasp, after pregrasp -> grasp -> squeeze in MuJoCo; "
               "rows: two views.", ""] + [f"![{p}]({p})" for p in pics] + [""]
    else:
        md += [note, ""]
    md += ["## Config", "", "```json", json.dumps(cfg, indent=1, sort_keys=True), "```", ""]
    out = job.path / "README.md"
    out.write_text("\n".join(md))
    return out
