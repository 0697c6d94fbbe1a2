"""``datagen report JOB_DIR``: a dataset card (JOB_DIR/README.md) with tables and rendered grasps.

The card opens with Hugging Face front matter (``configs: data_files`` naming the shards, and
the object observations as a second config), then outcomes, the successes' diversity, the
observations, a column table generated from ``schemas/evaluated.json`` (name, unit, frame, meaning),
reader snippets, and captioned pictures of successes and failures across several objects.
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

from datagen._atomic import atomic_write_text
from datagen.io import integrity
from schemas import column_table

from .job import JobDir, JobError, JobIOError, writing
from .status import job_status

__all__ = ["pick_renders", "write_report"]

_FRONT_MATTER = """---
pretty_name: {name}
task_categories:
- robotics
tags:
- dexterous-grasping
- robotics
- mujoco
configs:
- config_name: default
  data_files:
  - split: train
    path: shards/part-*.parquet
{observations}---
"""
_OBS_CONFIG = """- config_name: observations
  data_files:
  - split: train
    path: observations/part-*.parquet
"""
_OBS_READERS = """```python
import pandas as pd                                   # one row per object and scale, no project code needed
obs = pd.read_parquet("observations")
grasps = pd.read_parquet("shards")
pairs = grasps.merge(obs, on=["object_id", "object_scale_m"])   # each grasp with its object's clouds

from datagen.io import ObservationGraspDataset        # with the project: (observation, grasp) torch pairs
ds = ObservationGraspDataset(".", split="train", points=1024)
```
"""
_READERS = """```python
import pandas as pd                                   # any Parquet reader works, no project code needed
df = pd.read_parquet("shards")                        # one row per grasp; df[df.success] for verified ones
joints = df.joint_names[0]                            # names of grasp_qpos[7:]

import duckdb                                         # per-object success rates in SQL
duckdb.sql("select object_id, avg(success::int) from 'shards/*.parquet' group by 1").show()

from datasets import load_dataset                     # Hugging Face (the front matter names the files)
ds = load_dataset("parquet", data_files="shards/part-*.parquet", split="train")

from datagen.io import GraspDataset, read_job         # with the project: schema check, torch Dataset
table = read_job(".", only_success=True)
```
"""


def _table(header: list[str], rows: list[list]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c).replace("|", "\\|") for c in r) + " |" for r in rows]
    return out + [""]


def _read_rows(job: JobDir) -> pa.Table | None:
    """Every row of the finished shards (`datagen.io.read_job`: each checked against the ledger,
    page checksums verified), None before the first row."""
    from datagen.io import read_job

    try:
        return read_job(job.path)
    except FileNotFoundError:  # no finished shard with rows yet
        return None


def pick_renders(success: list[bool], objects: list[str], n: int) -> list[int]:
    """Up to ``n`` row indices to draw: successes and failures alternately (starting with a
    success), each from an object not drawn yet while one is left; deterministic."""
    pools = {True: [i for i, s in enumerate(success) if s], False: [i for i, s in enumerate(success) if not s]}
    picked: list[int] = []
    seen: set[str] = set()
    want = True
    while len(picked) < n and (pools[True] or pools[False]):
        pool = pools[want] or pools[not want]
        j = next((k for k, i in enumerate(pool) if objects[i] not in seen), 0)
        i = pool.pop(j)
        picked.append(i)
        seen.add(objects[i])
        want = not want
    return picked


def _caption(row: dict) -> str:
    verdict = "success" if row["success"] else f"failure ({row['reason']})"
    pen = row.get("penetration_m")
    pen = "" if pen is None or pen != pen else f", penetration {pen * 1000:.1f} mm"
    return (f"**{verdict}**: object `{row['object_id']}` ({row.get('split') or 'no split'}) at scale "
            f"{row['object_scale_m']:.3f} m, task `{row['task']}`, hand `{row['hand']}`{pen}, "
            f"epsilon {row['epsilon']:.3f}; grasp `{row['grasp_id']}`")


def _render(job: JobDir, rows: pa.Table | None, n: int) -> tuple[list[tuple[str, str]], str]:
    """([(relative PNG path, caption)], note). Renders `pick_renders` rows in a fresh process:
    MuJoCo reads MUJOCO_GL when first imported, and this one may have imported it."""
    if n <= 0 or rows is None:
        return [], "Rendering was skipped (--renders 0)."
    import multiprocessing as mp

    from datagen._interrupt import on_sigint, sigint_blocked
    from datagen.gl import GLUnavailable, select_backend

    try:
        select_backend()  # sets MUJOCO_GL, inherited by the rendering process
    except GLUnavailable as exc:
        return [], f"No grasp pictures: {exc}. Rerun `datagen report` once a backend works."
    picked = rows.take(pick_renders(rows["success"].to_pylist(), rows["object_id"].to_pylist(), n)).to_pylist()
    with sigint_blocked():  # Ctrl-C: the renderer ignores it, and the pool's exit here ends it
        pool = mp.get_context("spawn").Pool(1, initializer=on_sigint, initargs=("ignore",))
    with pool:
        paths, note = pool.apply(_render_rows, (str(job.path), picked))
    return [(p, _caption(r)) for p, r in zip(paths, picked)], note


def _render_rows(path: str, picked: list[dict]) -> tuple[list[str], str]:
    job = JobDir(path)
    try:
        from datagen.eval import build_scene
        from datagen.eval.render import render_grasp
        from datagen.eval.table import row_pieces, row_poses
        from datagen.hands import load_hand

        cfg = job.config().recipes()[0].eval
        paths, hands = [], {}
        for row in picked:
            hand = hands.setdefault(row["hand"], load_hand(row["hand"], base=job.path))
            scene = build_scene(hand, row_pieces(row, job.path), cfg, cfg.task_test(row["task"]))
            rel = f"renders/{row['grasp_id']}.png"
            render_grasp(scene, row_poses(row), cfg, job.path / rel)
            paths.append(rel)
        return paths, ""
    except Exception as exc:  # noqa: BLE001 - no GL is a note in the card, not an error
        return [], (f"No grasp pictures: no offscreen GL context could be opened "
                    f"(MUJOCO_GL={os.environ.get('MUJOCO_GL')}): {type(exc).__name__}: {exc}. "
                    "`python -m datagen.gl` names a backend that works; rerun `datagen report`.")


def _columns_section(rows: pa.Table | None) -> list[str]:
    md = ["## Columns", "",
          "One row per grasp. Poses are in the object's frame (origin at the centre of its bounding box) at "
          "the row's `object_scale_m`. A `*_qpos` column holds [x, y, z (m), qw, qx, qy, qz (root "
          "quaternion), then one value per joint named in `joint_names` (rad)]. Names end with their unit "
          "(`_m`, `_m2`, `_rad`, `_deg`); `success` is the MuJoCo verdict, `synth_usable` only the synthesis-side "
          "pre-check. Declared in `schemas/evaluated.json`.", ""]
    md += _table(["column", "type", "unit", "frame", "meaning"],
                 [[f"`{c['name']}`", f"`{c['type']}`", c["unit"], c["frame"], c["meaning"]]
                  for c in column_table("evaluated")])
    if rows is not None and "joint_names" in rows.column_names and rows.num_rows:
        names = rows["joint_names"][0].as_py()
        md += [f"Joints of `{rows['hand'][0].as_py()}` (qpos[7:] in this order): "
               + ", ".join(f"`{n}`" for n in names), ""]
    return md


def _diversity_section(job_dir: Path, rows: pa.Table | None) -> list[str]:
    """The successes' diversity per task and scale (`job_diversity`), or why it is not shown."""
    from .status import DIVERSITY_LEGEND, job_diversity

    md = ["### Diversity (successful grasps)", ""]
    if rows is None:
        return md + ["no grasps", ""]
    try:
        div = job_diversity(job_dir)
    except JobError as exc:
        return md + [f"Not computed: {exc}", ""]
    if not div:
        return md + ["no successful grasps", ""]
    md += _table(["hand", "task", "object_scale_m", "grasps", "PCA explained variance, top 1 / 2 / 3 / 4 / 5",
                  "mean joint entropy (nats)"],
                 [[r["hand"], r["task"], "all" if r["object_scale_m"] is None else r["object_scale_m"], r["n"],
                   " / ".join("-" if x is None else f"{x:.2f}" for x in r["pca"]),
                   "-" if r["joint_entropy"] is None else f"{r['joint_entropy']:.2f}"] for r in div])
    return md + [DIVERSITY_LEGEND + ". `datagen status --diversity` prints the same table.", ""]


def _observations(job: JobDir) -> pa.Table | None:
    """The job's observation rows without their point columns, or None when it has none."""
    from datagen.io import observation_paths

    if not observation_paths(job.path):
        return None
    from datagen.io import read_observations

    return read_observations(job.path, columns=["object_id", "object_scale_m", "split", "view_pixels",
                                                "depth_renderer"])


def _observations_section(obs: pa.Table | None, cfg: dict) -> list[str]:
    md = ["## Object observations", ""]
    if obs is None:
        return md + ["None in this job (`observations: {points: 0, views: 0}`, or a job made before they existed).", ""]
    o = cfg.get("observations") or {}
    views = o.get("views", 0)
    renderers = sorted({r for r in obs["depth_renderer"].to_pylist() if r})
    pixels = [n for v in obs["view_pixels"].to_pylist() for n in v]
    md += [f"`observations/part-NNNNN.parquet` beside each shard: {obs.num_rows} rows, one per object and scale "
           f"({len(set(obs['object_id'].to_pylist()))} objects), joinable to the grasps on `object_id` and "
           f"`object_scale_m` (schema `observations`, `schemas/observations.json`; in the ledger, checked by "
           "`datagen verify`). Each row: "
           f"{o.get('points', 2048)} surface points with outward normals and the bounding box, in the grasps' "
           "object frame and metres"
           + (f"; {views} single-view partial clouds (depth images of {o.get('image_width', 160)} x "
              f"{o.get('image_height', 120)} px back-projected, at most {o.get('view_points', 1024)} points each; "
              f"the camera poses and intrinsics recorded; rendered by {', '.join(renderers) or '-'}; "
              f"{min(pixels) if pixels else 0} to {max(pixels) if pixels else 0} object pixels per view)"
              if views else "; no camera views (`observations.views: 0`)") + ".", "", _OBS_READERS,
           "A reference learner trained on these pairs: `python examples/learn_grasps.py <this directory>` "
           "(datagen repository; docs/learning.md says what it shows and what it does not). It is an example "
           "and a measurement of what a small model gets out of such a job, against an object-blind baseline "
           "on the same test objects, not a research claim.", ""]
    return md


def _evaluation_line(overrides: dict, job_code: str) -> str:
    """The MuJoCo test the rows' ``success`` comes from: `EvalConfig` with the job's ``eval``
    overrides, as this code resolves them (named when it is not the job's own code version)."""
    from datagen.eval import EvalConfig

    from .job import code_version

    try:
        e = EvalConfig.from_dict(overrides, where="job.json config.eval")
    except Exception as exc:  # noqa: BLE001 - a job of other code: its eval block is in the config below
        return f"- MuJoCo test: as the job's `eval` block below sets it (this code cannot read it: {exc})"
    hold = (f"a direction passes once its creep has settled (early pass: `settle_checks` {e.settle_checks}, "
            f"`settle_safety` {e.settle_safety:g}; the full hold's verdict on every row measured both ways, "
            "benchmarks/results/eval.md)" if e.settle_checks else "every passing direction held for the whole time")
    code = code_version()
    return (f"- MuJoCo test: six directions ({e.force_per_kg:g} N per kg of object, {e.object_mass_kg:g} kg) or the "
            f"task's disturbance, for {e.hold_steps * e.timestep_s:g} s; a grasp passes while the object moves less "
            f"than {e.max_translation_m * 100:g} cm and {e.max_rotation_deg:g} deg; {hold}"
            + ("" if code == job_code else f" (settings as code `{code}` resolves the job's `eval` overrides)"))


def _protocol_line(doc: dict, hand: str) -> str:
    """Whose hand gains the verdicts follow: job.json's ``eval_protocol`` (jobs before it: the
    gains every hand had then, kp 5 and +-3)."""
    from datagen.eval.protocol import PEER_GAINS

    p = doc.get("eval_protocol")
    if p is None:
        return ("- hand gains: every hand at kp 5, force +-3 (a job made before `eval_protocol` was recorded; "
                "`protocol: uniform` now)")
    if p == "dexgraspbench" and hand in PEER_GAINS:
        g = PEER_GAINS[hand]
        limit = "no force limit" if g.force_limit is None else f"force +-{g.force_limit:g}"
        return (f"- hand gains: protocol `dexgraspbench`, DexGraspBench's {hand} file (kp {g.kp:g}, kv {g.kv:g}, "
                f"{limit}; {g.source}); verdicts against its evaluator: benchmarks/results/interop.md")
    return f"- hand gains: protocol `{p}` (datagen/eval/protocol.py)"


def write_report(path: str | Path, renders: int = 6) -> Path:
    """Write JOB/README.md; ``renders`` grasps are drawn (half successes, half failures)."""
    job = JobDir(path)
    doc = job.read_job()
    out = job.path / "README.md"
    if not os.access(job.path, os.W_OK | os.X_OK) or (out.exists() and not os.access(out, os.W_OK)):
        raise JobIOError(f"cannot write the dataset card {out}: the job directory is not writable",
                         "run `datagen report` on a writable copy of the job (cp -r), or as its owner")
    s = job_status(job.path)
    if s["damaged"]:
        i, why = next(iter(s["damaged"].items()))
        raise JobError(f"job {job.path}: shard {i} does not match its ledger entry ({why}); the card would "
                       "miss its rows", integrity.redo_remedy(job.path))
    rows = _read_rows(job)
    fails = (integrity.read_parquet(job.failures_path, remedy=integrity.redo_remedy(job.path))
             if job.failures_path.is_file() else None)
    cfg = doc["config"]
    obs = _observations(job)
    md = _header_section(job, doc, s, obs)
    md += _outcome_section(rows, s, fails)
    md += _diversity_section(job.path, rows)
    md += _observations_section(obs, cfg)
    md += _failures_section(fails)
    md += ["## Where the time went (worker seconds)", ""]
    md += _table(["stage", "seconds"], [[k[:-2], f"{v:.1f}"] for k, v in s["stage_seconds"].items()])
    md += ["shard_wall / shard_cpu: wall and CPU seconds of the shard tasks (CPU excludes isolated CoACD "
           "processes).", ""]
    md += _columns_section(rows)
    md += ["## Reading", "", _READERS]
    md += _grasps_section(job, rows, renders)
    md += ["## Config", "", "```json", json.dumps(cfg, indent=1, sort_keys=True), "```", ""]
    with writing(out, "the dataset card"):
        atomic_write_text(out, "\n".join(md))
    return out


def _header_section(job: JobDir, doc: dict, s: dict, obs) -> list[str]:
    """The card's front matter, title, provenance lines and the ``## Outcome`` heading."""
    cfg = doc["config"]
    return [_FRONT_MATTER.format(name=json.dumps(f"datagen {job.path.name}"), observations=_OBS_CONFIG if obs else ""),
            f"# Dataset card: {job.path.name}", "",
            f"Dexterous grasps of the **{cfg['hand']}** hand on {s['objects']} objects from `{cfg['source']}`, "
            f"tasks {', '.join(cfg['tasks'])}, synthesized by `datagen` and verified in MuJoCo.", "",
            f"- config hash `{doc['config_hash']}`, code `{doc['code_version']}`, created {doc['created_at']} "
            f"on `{doc['host']}`",
            f"- shards {s['shards_done']}/{s['shards_total']}{'' if s['complete'] else ' (incomplete)'}; "
            f"files `shards/part-NNNNN.parquet` (schema `evaluated`, see `schemas/`), `failures.parquet`; "
            f"`object_path` points into `objects/` (relative to this directory)",
            "- packages: " + ", ".join(f"{k} {v}" for k, v in doc["packages"].items()),
            _evaluation_line(cfg.get("eval") or {}, doc["code_version"]), _protocol_line(doc, cfg["hand"]), "",
            "## Outcome", ""]


def _outcome_section(rows, s: dict, fails) -> list[str]:
    """The outcome table, and with rows: success by task and scale, by split, the reason codes and
    the successes' metrics."""
    md = _table(["grasps", "successful", "success rate", "objects failed"],
                [[s["grasps"], s["success"], f"{s['success_rate']:.1%}", fails.num_rows if fails is not None else 0]])
    if rows is None:
        return md
    md += ["### By task and scale", ""]
    groups: dict = {}
    for t, sc, ok in zip(rows["task"].to_pylist(), rows["object_scale_m"].to_pylist(), rows["success"].to_pylist()):
        g = groups.setdefault((t, round(sc, 4)), [0, 0])
        g[0] += 1
        g[1] += bool(ok)
    md += _table(["task", "object_scale_m", "grasps", "success rate"],
                 [[t, sc, n, f"{k / n:.1%}"] for (t, sc), (n, k) in sorted(groups.items())])
    if "split" in rows.column_names:
        splits, objs = rows["split"].to_pylist(), rows["object_id"].to_pylist()
        md += ["### By split", ""]
        md += _table(["split", "grasps", "objects"],
                     [[sp, n, len({o for o, x in zip(objs, splits) if x == sp})]
                      for sp, n in sorted(Counter(splits).items())])
    md += ["### Grasp outcomes (reason codes)", ""]
    md += _table(["reason", "grasps"], [[k, v] for k, v in s["eval_reasons"].items()])
    md += ["### Metrics (successful grasps)", ""]
    okr = rows.filter(pc.equal(rows["success"], True))
    mrows = []
    for col, unit, mult in (("penetration_m", "mm", 1000), ("sphere_penetration_m", "mm", 1000),
                            ("epsilon", "", 1), ("synth_epsilon", "", 1), ("touching_links", "", 1)):
        if okr.num_rows and col in okr.column_names:
            v = okr[col].cast(pa.float64())
            mrows.append([f"`{col}`", unit or "as stored", f"{pc.mean(v).as_py() * mult:.3g}",
                          f"{pc.max(v).as_py() * mult:.3g}"])
    return md + (_table(["column", "shown in", "mean", "max"], mrows) if mrows else ["no successful grasps", ""])


def _failures_section(fails) -> list[str]:
    """Objects without rows, by stage and reason."""
    md = ["## Failures (objects without rows)", ""]
    if fails is None or not fails.num_rows:
        return md + ["none", ""]
    md += _table(["stage", "reason", "objects"],
                 [[k.split(':')[0], k.split(':', 1)[1], v] for k, v in Counter(
                     f"{a}:{b}" for a, b in zip(fails["stage"].to_pylist(), fails["reason"].to_pylist())).items()])
    return md + ["Stages: `process` (object processing: mesh checks, CoACD), `target` (the synthesis target: surface "
                 "samples and SDF grid), `synth` (optimization), `eval` (MuJoCo).", ""]


def _grasps_section(job: JobDir, rows, renders: int) -> list[str]:
    """How to browse the grasps, and ``renders`` static pictures (or why there are none)."""
    pics, note = _render(job, rows, renders)
    md = ["## Grasps", "",
          "Browse these grasps in 3D: run `datagen view <this job directory>` and open the printed URL "
          "(on a remote machine, first `ssh -L 8080:localhost:8080 <user>@<host>`, then open "
          "http://localhost:8080/); `datagen view <job> --export DIR` writes self-contained HTML pages of a "
          "few grasps. The pictures below are static renders.", ""]
    if not pics:
        return md + [note, ""]
    md += ["Each picture: columns = hand at the pregrasp, the grasp, after pregrasp -> grasp -> squeeze in "
           "MuJoCo; rows = two views (from beyond the object towards the palm, and 90 degrees around).", ""]
    for i, (p, caption) in enumerate(pics, 1):
        md += [f"![{p}]({p})", "", f"{i}. {caption}", ""]
    return md
