"""Why big objects fail: the mechanism behind every row of the default force-closure job (issue 41).

``measure`` replays each row of the jobs that ``bench_quality --scales ...`` made (one job per
hand) in MuJoCo with the evaluation's own scene and closing (`datagen.eval`: `build_scene`,
`initial_state`, `close_hand`, the default `EvalConfig`, nothing changed) and records per row:

* geometry at the grasp pose: the palm's distance to the object, the hand links within 5 mm
  (fingertips, other phalanges, palm), the synthesized fingertip contacts' spread (largest pairwise
  distance over the object's bounding-box diagonal) and opposition (``-min n_i . n_j`` over the
  contact normals: 1 = an antipodal pair, <= 0 = every normal in one half-space), finger joints
  within 1% of their range from a limit, actuators whose squeeze target the control range clips;
* the closing: the object's displacement at the end of pregrasp -> grasp and of grasp -> squeeze
  (from its initial pose, as the test measures), and its direction in the palm frame;
* the squeeze's forces (MuJoCo contact forces at the end of the closing): the hand-object normal
  force in all and per link kind, the links in contact, the net force the hand puts on the object,
  finger actuators at their force limit;
* each direction's hold simulated in full and independently (no early pass, no stop at the first
  failing direction; the verdict stays the job's): which directions fail, when, and whether by
  rotation (15 deg) or translation (5 cm) first; each direction in the palm frame (approach axis
  ``a`` out of the palm, thumb axis ``t``, finger axis ``f = a x t``).

``report`` classifies every failure into one exclusive mechanism and ranks the attributes that
explain failures (attributable failures: ``n_H (fail rate with H - fail rate without H)``); it
prints markdown. ``render`` draws examples of each class (`datagen.eval.render`).
Usage: ``python -m benchmarks.diagnose_sizes measure --work DIR``, then ``report``, ``render``.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from datagen.io import read_job
from datagen.objects.manifest import load_manifest

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "manifests" / "real_dev.jsonl"
COLUMNS = ["object_id", "object_scale_m", "hand", "task", "pregrasp_qpos", "grasp_qpos", "squeeze_qpos",
           "object_path", "success", "reason", "synth_epsilon", "epsilon", "contact_points_m", "contact_normals",
           "dir_success", "touching_links", "grasp_id"]
HAND_TAGS = {"shadow": "shadow", "shadow_e3m5": "e3m5", "allegro": "allegro", "leap": "leap"}
TOUCH_M = 0.005


def palm_frame(scene, data) -> np.ndarray:
    """(3, 3) rows: approach, thumb and finger axes of the palm in the object frame."""
    hand = scene.hand
    b = scene.model.body("hand/" + hand.spec.palm.link).id
    R = data.xmat[b].reshape(3, 3)
    a, t = R @ np.asarray(hand.spec.palm.approach), R @ np.asarray(hand.spec.palm.thumb)
    return np.stack([a, t, np.cross(a, t)])


def link_kinds(scene) -> np.ndarray:
    """(L,) 'tip', 'palm' or 'phalanx' per hand link (hand.link_names order)."""
    hand = scene.hand
    tips = {t.link for t in hand.spec.fingertips.values()}
    return np.array(["tip" if n in tips else "palm" if n == hand.spec.palm.link else "phalanx"
                     for n in hand.link_names])


def wrap_measures(frame: np.ndarray, pts: np.ndarray, nrm: np.ndarray, verts: np.ndarray) -> dict:
    """How the fingertip contacts sit round the object along the palm's approach axis ``a``:
    ``reach_past`` the largest contact height past the object's centre, ``(p - c) . a`` over the
    object's half extent along ``a`` (< 0: no fingertip reaches past the middle of the object);
    ``push_out`` the mean of the inward contact normals along ``a`` (> 0: pressing the tips in
    pushes the object away from the palm). ``verts`` (V, 3) the object's vertices, metres."""
    a = frame[0]
    h = verts @ a
    c, half = 0.5 * (h.max() + h.min()), 0.5 * (h.max() - h.min())
    return {"reach_past": float(((pts @ a) - c).max() / half) if len(pts) else math.nan,
            "push_out": float((nrm @ a).mean()) if len(nrm) else math.nan}


def static_geometry(scene, data, row: dict, poses: np.ndarray, verts: np.ndarray) -> dict:
    """Geometry of the grasp pose (see the module docstring)."""
    from datagen.eval.metrics import hand_object_distances, set_static_pose

    set_static_pose(scene, data, poses[1])
    dist, _, _ = hand_object_distances(scene, data, 0.05)
    kinds = link_kinds(scene)
    per_link = np.full(len(kinds), 0.05)
    np.minimum.at(per_link, scene.hand_geom_link, dist)
    touch = per_link <= TOUCH_M
    pts = np.asarray(row["contact_points_m"], dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(row["contact_normals"], dtype=np.float64).reshape(-1, 3)
    diag = 2.0 * float(row["object_scale_m"])
    spread = max((np.linalg.norm(p - q) for p in pts for q in pts), default=0.0) / diag
    opposition = -float(np.min(nrm @ nrm.T)) if len(nrm) > 1 else -1.0
    hand = scene.hand
    lo, hi = hand.joint_lower.cpu().numpy(), hand.joint_upper.cpu().numpy()
    q = poses[1, 7:]
    at_limit = (np.minimum(q - lo, hi - q) <= 0.01 * (hi - lo))
    want = scene.ctrl_matrix @ poses[2, 7:]
    clipped = (want < scene.ctrl_range[:, 0] - 0.01) | (want > scene.ctrl_range[:, 1] + 0.01)
    return {**wrap_measures(palm_frame(scene, data), pts, nrm, verts),
            "palm_mm": 1000 * float(per_link[hand.palm_link]), "touch_tip": int(touch[kinds == "tip"].sum()),
            "touch_phalanx": int(touch[kinds == "phalanx"].sum()), "touch_palm": bool(touch[kinds == "palm"].any()),
            "spread": spread, "opposition": opposition, "joints_at_limit": int(at_limit.sum()),
            "squeeze_clipped": int(clipped.sum()),
            "centroid_off": float(np.linalg.norm(pts.mean(axis=0))) / float(row["object_scale_m"]) if len(pts) else math.nan}


def contact_forces(scene, data) -> dict:
    """Hand-object contact forces in ``data`` (N): normal force in all and per link kind, the
    links in contact, the net force on the object, finger actuators at their force limit."""
    import mujoco

    m = scene.model
    kinds = link_kinds(scene)
    link_of = dict(zip(scene.hand_geoms.tolist(), scene.hand_geom_link.tolist()))
    obj = set(scene.object_geoms.tolist())
    f6 = np.zeros(6)
    normal = {"tip": 0.0, "phalanx": 0.0, "palm": 0.0}
    links, net = set(), np.zeros(3)
    for i in range(data.ncon):
        c = data.contact[i]
        g1, g2 = int(c.geom1), int(c.geom2)
        if not ((g1 in obj and g2 in link_of) or (g2 in obj and g1 in link_of)):
            continue
        mujoco.mj_contactForce(m, data, i, f6)
        li = link_of[g1 if g2 in obj else g2]
        normal[kinds[li]] += float(f6[0])
        links.add(li)
        world = c.frame.reshape(3, 3).T @ f6[:3]  # the force of geom1 on geom2
        net += world if g2 in obj else -world
    force = data.actuator_force[scene.actuators]
    return {"grip_n": sum(normal.values()), **{f"grip_{k}_n": v for k, v in normal.items()},
            "links_in_contact": len(links), "net_force_n": float(np.linalg.norm(net)),
            "act_saturated": float(np.mean(np.abs(force) >= 0.98 * 3.0))}


def _displacement(scene, data, pos0, quat0) -> tuple[float, float, np.ndarray]:
    from datagen.rotation import quat_angle_np

    b = scene.object_body
    d = data.xpos[b] - pos0
    return float(np.linalg.norm(d)), float(np.degrees(quat_angle_np(data.xquat[b], quat0))), d


def full_holds(scene, closed, cfg, pos0, quat0) -> list[dict]:
    """Each direction held for the whole 2 s on its own: fails (bool), when (s), by what."""
    import mujoco

    from datagen.eval.config import DIRECTIONS

    out = []
    f = cfg.force_per_kg * scene.object_mass
    d = mujoco.MjData(scene.model)
    for u in DIRECTIONS:
        mujoco.mj_copyData(d, scene.model, closed)
        d.xfrc_applied[:] = 0
        d.xfrc_applied[scene.object_body, :3] = f * np.asarray(u)
        rec = {"fail": False, "t_s": math.nan, "by": "", "max_t": 0.0, "max_r": 0.0}
        for k in range(cfg.hold_steps // cfg.check_every):
            mujoco.mj_step(scene.model, d, nstep=cfg.check_every)
            t, r, _ = _displacement(scene, d, pos0, quat0)
            rec["max_t"], rec["max_r"] = max(rec["max_t"], t), max(rec["max_r"], r)
            if not np.all(np.isfinite(d.qpos)) or t >= cfg.max_translation_m or r >= cfg.max_rotation_deg:
                rec.update(fail=True, t_s=(k + 1) * cfg.check_every * cfg.timestep_s,
                           by="rotation" if r >= cfg.max_rotation_deg and t < cfg.max_translation_m else "translation")
                break
        out.append(rec)
    return out


def replay(scene, row: dict, poses: np.ndarray, cfg, holds: bool) -> dict:
    """The closing (and the full holds when ``holds``) of one row, measured."""
    import mujoco

    from datagen.eval.hold import _set_targets, initial_state, slerp  # close_hand's steps, measured between phases

    m = scene.model
    data = mujoco.MjData(m)
    initial_state(scene, data, poses[0])
    pos0, quat0 = data.xpos[scene.object_body].copy(), data.xquat[scene.object_body].copy()
    rec = {}
    for name, (a, b) in (("grasp", (poses[0], poses[1])), ("squeeze", (poses[1], poses[2]))):
        for k in range(1, cfg.waypoints + 1):
            t = k / cfg.waypoints
            _set_targets(scene, data, a[:3] + t * (b[:3] - a[:3]), slerp(a[3:7], b[3:7], t), a[7:] + t * (b[7:] - a[7:]))
            mujoco.mj_step(m, data, nstep=cfg.steps_per_waypoint)
        tr, rot, d = _displacement(scene, data, pos0, quat0)
        rec[f"{name}_t_mm"], rec[f"{name}_r_deg"] = 1000 * tr, rot
    frame = palm_frame(scene, data)
    rec["shift_palm"] = (frame @ d).tolist()  # the closing's displacement on the palm axes (a, t, f), m
    rec.update(contact_forces(scene, data))
    rec["dirs_palm"] = [(frame @ np.asarray(u)).tolist() for u in _directions()]
    if holds:
        rec["holds"] = full_holds(scene, data, cfg, pos0, quat0)
    return rec


def hand_aperture(hand) -> float:
    """The hand's largest thumb-to-fingertip distance (m): its open pose and 4000 uniform joint samples."""
    import torch

    g = torch.Generator().manual_seed(0)
    lo, hi = hand.joint_lower, hand.joint_upper
    q = hand.apply_couplings(lo + torch.rand(4000, hand.num_joints, generator=g, dtype=lo.dtype) * (hi - lo))
    q = torch.cat([hand.open_pose[None], q])
    root = torch.tensor([0, 0, 0, 1, 0, 0, 0], dtype=lo.dtype).expand(len(q), 7)
    with torch.no_grad():
        p = hand.fingertip_points(root, q)
    th = p[:, hand.fingertip_names.index("th")][:, None]
    return float((p - th).norm(dim=-1).max())


def object_vertices(pieces) -> np.ndarray:
    """(V, 3) the vertices of the object's convex pieces at its scale (m)."""
    import trimesh

    return pieces.scale * np.concatenate([trimesh.load(p, force="mesh").vertices for p in pieces.paths])


def _directions():
    from datagen.eval.config import DIRECTIONS

    return DIRECTIONS


def measure(args) -> None:
    from datagen.eval import EvalConfig, build_scene
    from datagen.eval.table import row_pieces, row_poses
    from datagen.hands import load_hand

    import mujoco

    cfg = EvalConfig()
    families = {e.id: e.family for e in load_manifest(MANIFEST)}
    out = args.out.open("a")
    done = set()
    if args.out.stat().st_size:
        done = {json.loads(x)["grasp_id"] for x in args.out.read_text().splitlines() if x.strip()}
    for job in sorted(args.work.glob(f"*-g*-o*{args.tag}")):
        hand_name = job.name.split("-0.")[0]
        try:
            rows = read_job(job, columns=COLUMNS).to_pylist()
        except FileNotFoundError:  # no finished shard yet
            continue
        hand = load_hand(hand_name)
        aperture = hand_aperture(hand)
        scenes, t0 = {}, time.perf_counter()
        for i, row in enumerate(rows):
            if row["grasp_id"] in done:
                continue
            key = (row["object_id"], row["object_scale_m"])
            if key not in scenes:
                scenes.clear()
                pieces = row_pieces(row, job)
                scenes[key] = build_scene(hand, pieces, cfg), object_vertices(pieces)
            (scene, verts), poses = scenes[key], row_poses(row)
            rec = {"grasp_id": row["grasp_id"], "hand": hand_name, "object_id": row["object_id"],
                   "family": families.get(row["object_id"], "?"), "scale": round(float(row["object_scale_m"]), 4),
                   "success": bool(row["success"]), "reason": row["reason"], "synth_epsilon": row["synth_epsilon"],
                   "epsilon": row["epsilon"], "touching_links": row["touching_links"],
                   "widths_m": sorted((verts.max(axis=0) - verts.min(axis=0)).tolist()), "aperture_m": aperture}
            rec.update(static_geometry(scene, mujoco.MjData(scene.model), row, poses, verts))
            if row["reason"] not in ("penetration", "no_contact", "invalid_grasp"):
                rec.update(replay(scene, row, poses, cfg, holds=not row["success"]))
            out.write(json.dumps(rec) + "\n")
            out.flush()
        print(f"{hand_name}: {len(rows)} rows in {time.perf_counter() - t0:.0f} s", flush=True)


# ---------------------------------------------------------------------------------------- report
AXES = ("a", "t", "f")
AXIS_NAMES = {"+a": "out of the palm (away from it)", "-a": "into the palm", "+t": "towards the thumb",
              "-t": "away from the thumb", "+f": "towards the fingertips", "-f": "towards the wrist"}
LOST_T_MM, LOST_R_DEG = 50.0, 15.0  # the test's own thresholds, reached before any load


def palm_axis(v) -> str:
    """The palm axis ('+a', '-t', ...) a vector (on the palm axes a, t, f) mostly points along."""
    v = np.asarray(v, dtype=float)
    i = int(np.argmax(np.abs(v)))
    return ("+" if v[i] >= 0 else "-") + AXES[i]


def mechanism(r: dict) -> tuple[str, str]:
    """(class, detail) of a failed row: the first mechanism that applies."""
    if r["reason"] in ("penetration", "no_contact", "invalid_grasp"):
        return "rejected before simulating (" + r["reason"] + ")", ""
    if r["squeeze_t_mm"] >= LOST_T_MM or r["squeeze_r_deg"] >= LOST_R_DEG or r["links_in_contact"] == 0:
        phase = "grasp" if r["grasp_t_mm"] >= LOST_T_MM or r["grasp_r_deg"] >= LOST_R_DEG else "squeeze"
        return "lost while closing", f"{phase}, shift {palm_axis(r['shift_palm'])}"
    fails = [(h, i) for i, h in enumerate(r["holds"]) if h["fail"]]
    if not fails:
        return "holds in the full replay", ""
    h, i = min(fails, key=lambda x: (x[0]["t_s"], -x[0]["max_t"]))
    kind = "rotates under the load" if h["by"] == "rotation" else "slides under the load"
    return kind, f"{palm_axis(r['dirs_palm'][i])}, {len(fails)} of 6 directions"


#: attributes of the grasp pose (decided before any simulation): candidate causes
CAUSES = {
    "too_wide": ("object's middle extent > half the hand's aperture",
                 lambda r: r["widths_m"][1] > 0.5 * r["aperture_m"]),
    "no_fc": ("not in force closure at synthesis (fingertip epsilon 0)", lambda r: r["synth_epsilon"] <= 0),
    "one_sided": ("fingertip normals not opposing (no pair within 60 deg of antipodal)",
                  lambda r: r["opposition"] < 0.5),
    "small_spread": ("fingertip contacts span < 40% of the object's diagonal", lambda r: r["spread"] < 0.4),
    "palm_far": ("palm > 10 mm from the object", lambda r: r["palm_mm"] > 10),
    "no_reach": ("no fingertip reaches past the object's middle along the approach axis",
                 lambda r: r["reach_past"] < 0),
    "push_out": ("the tips' inward normals push the object away from the palm (mean along a > 0.2)",
                 lambda r: r["push_out"] > 0.2),
    "few_touch": ("< 3 links within 5 mm of the object", lambda r: r["touch_tip"] + r["touch_phalanx"]
                  + r["touch_palm"] < 3),
    "at_limit": ("a finger joint within 1% of its range from a limit", lambda r: r["joints_at_limit"] > 0),
    "clipped": ("squeeze target clipped by an actuator's control range", lambda r: r["squeeze_clipped"] > 0),
}
#: the squeeze's outcome, for the rows that keep the object through the closing
SQUEEZE = {
    "weak_grip": ("normal force < 1.67 N (1 N / friction 0.6)", lambda r: r["grip_n"] < 1 / 0.6),
    "few_links": ("< 3 links in contact", lambda r: r["links_in_contact"] < 3),
    "no_palm": ("palm not in contact", lambda r: r["grip_palm_n"] <= 0),
    "shifted": ("object moved >= 10 mm or 5 deg while closing", lambda r: r["squeeze_t_mm"] >= 10
                or r["squeeze_r_deg"] >= 5),
    "saturated": ("a finger actuator at its force limit", lambda r: r["act_saturated"] > 0),
}


def load(path: Path) -> list[dict]:
    return [json.loads(x) for x in path.read_text().splitlines() if x.strip()]


def pct(a, b) -> str:
    return f"{100 * a / b:.0f}" if b else "-"


def class_table(rows: list[dict]) -> list[str]:
    """Per hand x scale: success and the share of rows per failure class."""
    classes = ["lost while closing", "slides under the load", "rotates under the load", "rejected before simulating"]
    out = ["| hand | scale m | n | success % | " + " | ".join(c + " %" for c in classes) + " |",
           "|---|---|---|---|" + "---|" * len(classes)]
    for hand in HAND_TAGS:
        for s in sorted({r["scale"] for r in rows if r["hand"] == hand}):
            sel = [r for r in rows if r["hand"] == hand and r["scale"] == s]
            fails = [mechanism(r)[0] for r in sel if not r["success"]]
            cells = [pct(sum(f.startswith(c) for f in fails), len(sel)) for c in classes]
            out.append(f"| {hand} | {s:g} | {len(sel)} | {pct(sum(r['success'] for r in sel), len(sel))} | "
                       + " | ".join(cells) + " |")
    return out


def detail_key(r: dict) -> tuple[str, str]:
    """(class, detail) with the detail cut to what the tables group by."""
    k, d = mechanism(r)
    return k, d if k == "lost while closing" else d.split(",")[0]


def detail_table(rows: list[dict], scales) -> list[str]:
    """Failures' details (direction in the palm frame, phase) at the given scales, all hands."""
    from collections import Counter

    c = Counter()
    n = 0
    for r in rows:
        if r["scale"] in scales and not r["success"]:
            n += 1
            c[detail_key(r)] += 1
    out = ["| class | detail | failures | % of failures |", "|---|---|---|---|"]
    for (k, d), v in c.most_common(8):
        out.append(f"| {k} | {d} | {v} | {pct(v, n)} |")
    return out


def attributable(rows: list[dict], pred) -> float | None:
    """Failures attributable to ``pred``, stratified by hand and scale: the sum over strata of
    ``n_H (fail rate with H - fail rate without H)``, over the strata with >= 2 rows on each side
    (None: no such stratum)."""
    total, used = 0.0, False
    for key in {(r["hand"], r["scale"]) for r in rows}:
        st = [r for r in rows if (r["hand"], r["scale"]) == key]
        has = [not r["success"] for r in st if pred(r)]
        hasnt = [not r["success"] for r in st if not pred(r)]
        if len(has) >= 2 and len(hasnt) >= 2:
            total += len(has) * (np.mean(has) - np.mean(hasnt))
            used = True
    return total if used else None


def attribute_table(rows: list[dict], hands, scales, attributes: dict, held: bool = False) -> list[str]:
    """Per attribute: prevalence in failures and successes, and the failures attributable to it
    (`attributable`, as a share of the failures considered). ``held``: only the rows that keep
    the object through the closing."""
    sim = [r for r in rows if r["hand"] in hands and r["scale"] in scales and "grip_n" in r
           and (not held or r["success"] or mechanism(r)[0] != "lost while closing")]
    fails = [r for r in sim if not r["success"]]
    oks = [r for r in sim if r["success"]]
    out = ["| attribute | in failures % | in successes % | attributable failures % |", "|---|---|---|---|"]
    ranked, none = [], []
    for desc, pred in attributes.values():
        af = attributable(sim, pred)
        if af is None:  # no size where both sides have 2 rows: nothing to compare
            none.append(f"{desc} ({pct(sum(pred(r) for r in fails), len(fails))}% of failures)")
            continue
        share = af / max(len(fails), 1)
        ranked.append((share, f"| {desc} | {pct(sum(pred(r) for r in fails), len(fails))} | "
                       f"{pct(sum(pred(r) for r in oks), len(oks))} | {100 * share:.0f} |"))
    return ([f"{len(sim)} rows, {len(fails)} failures."
             + (" No contrast within a size: " + "; ".join(none) + "." if none else ""), ""] + out
            + [x for _, x in sorted(ranked, key=lambda x: -x[0])])


def quantity_table(rows: list[dict], hand: str) -> list[str]:
    """Medians per scale, successes / failures, of the measured quantities."""
    keys = [("reach_past", "reach past middle"), ("push_out", "push out"), ("palm_mm", "palm gap mm"), ("links_in_contact", "links in contact"), ("grip_n", "grip N"),
            ("grip_palm_n", "palm N"), ("spread", "tip spread / diagonal"), ("opposition", "opposition"),
            ("squeeze_t_mm", "closing shift mm")]
    out = ["| scale m | " + " | ".join(k[1] + " (ok / fail)" for k in keys) + " |", "|---|" + "---|" * len(keys)]
    for s in sorted({r["scale"] for r in rows if r["hand"] == hand}):
        sel = [r for r in rows if r["hand"] == hand and r["scale"] == s and "grip_n" in r]
        cells = []
        for k, _ in keys:
            ok = [r[k] for r in sel if r["success"]]
            bad = [r[k] for r in sel if not r["success"]]
            med = lambda v: f"{np.median(v):.2g}" if v else "-"  # noqa: E731
            cells.append(f"{med(ok)} / {med(bad)}")
        out.append(f"| {s:g} | " + " | ".join(cells) + " |")
    return out


def family_table(rows: list[dict]) -> list[str]:
    fams = sorted({r["family"] for r in rows})
    scales = sorted({r["scale"] for r in rows})
    out = ["| family | " + " | ".join(f"{s:g} m" for s in scales) + " |", "|---|" + "---|" * len(scales)]
    for f in fams:
        cells = []
        for s in scales:
            sel = [r for r in rows if r["family"] == f and r["scale"] == s]
            cells.append(pct(sum(r["success"] for r in sel), len(sel)) + f" ({len(sel)})")
        out.append(f"| {f} | " + " | ".join(cells) + " |")
    return out


def reach_table(rows: list[dict]) -> list[str]:
    """Success against the object's middle bounding-box extent over the hand's aperture, per hand."""
    edges = [0.0, 0.35, 0.5, 0.65, 0.8, 1.0, 10.0]
    names = [f"{a:g}-{b:g}" if b < 10 else f"> {a:g}" for a, b in zip(edges, edges[1:])]
    out = ["| hand | aperture mm | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for hand in HAND_TAGS:
        sel = [r for r in rows if r["hand"] == hand]
        if not sel:
            continue
        ratio = np.array([r["widths_m"][1] / r["aperture_m"] for r in sel])
        ok = np.array([r["success"] for r in sel])
        cells = []
        for a, b in zip(edges, edges[1:]):
            m = (ratio >= a) & (ratio < b)
            cells.append(f"{pct(ok[m].sum(), m.sum())} ({m.sum()})")
        out.append(f"| {hand} | {1000 * sel[0]['aperture_m']:.0f} | " + " | ".join(cells) + " |")
    return out


def report(args) -> None:
    rows = load(args.out)
    big = {0.1, 0.12, 0.15}
    lines = ["### Success and failure classes (% of rows)", ""] + class_table(rows)
    lines += ["", "### Success % (rows) by the object's middle extent over the hand's aperture", ""]
    lines += reach_table(rows)
    lines += ["", "### Failure details at 0.10-0.15 m (all hands)", ""] + detail_table(rows, big)
    lines += ["", "### Failure details at 0.06-0.08 m (all hands)", ""] + detail_table(rows, {0.06, 0.08})
    small = {0.06, 0.08}
    for hands, name in ((("shadow", "shadow_e3m5"), "Shadow and E3M5"), (("allegro", "leap"), "Allegro and LEAP")):
        for sc, sname in ((big, "0.10-0.15"), (small, "0.06-0.08")):
            lines += ["", f"### Grasp-pose causes at {sname} m: {name}", ""]
            lines += attribute_table(rows, hands, sc, CAUSES)
            lines += ["", f"### The squeeze, rows that keep the object through the closing, {sname} m: {name}", ""]
            lines += attribute_table(rows, hands, sc, SQUEEZE, held=True)
    for hand in HAND_TAGS:
        lines += ["", f"### Medians, {hand}", ""] + quantity_table(rows, hand)
    lines += ["", "### Success % by family (rows), Shadow", ""] + family_table([r for r in rows if r["hand"] == "shadow"])
    lines += ["", "### Success % by family (rows), all hands", ""] + family_table(rows)
    print("\n".join(lines))


def pick_examples(rows: list[dict], hand: str, scales, obj: str = "") -> list[tuple[str, dict]]:
    """(name, row) per failure class of ``hand`` at ``scales`` (the most frequent detail, the
    median object shift among those rows), and one success, for the pictures; ``obj``: only
    that object's rows."""
    from collections import Counter

    sel = [r for r in rows if r["hand"] == hand and r["scale"] in scales and (not obj or r["object_id"] == obj)]
    out = []
    for (k, d), _ in Counter(detail_key(r) for r in sel if not r["success"]).most_common(3):
        cands = sorted((r for r in sel if not r["success"] and detail_key(r) == (k, d)),
                       key=lambda r: (r.get("squeeze_t_mm", 0), r["grasp_id"]))
        out.append((f"{k.split(' ')[0]}_{d.replace(' ', '').replace(',', '_').replace('+', 'p').replace('-', 'm')}",
                    cands[len(cands) // 2]))
    ok = sorted((r for r in sel if r["success"]), key=lambda r: r["grasp_id"])
    if ok:
        out.append(("success", ok[len(ok) // 2]))
    return out


def render(args) -> None:
    from datagen.gl import select_backend

    select_backend()
    from datagen.eval import EvalConfig, build_scene
    from datagen.eval.render import grasp_frames
    from datagen.eval.table import row_pieces, row_poses
    from datagen.hands import load_hand
    from datagen.hands.render import write_png

    rows = load(args.out)
    cfg = EvalConfig()
    for example in args.examples.split(","):
        hand, scale, *obj = example.split("@")
        scale = float(scale)
        job = next(args.work.glob(f"{hand}-0.*{args.tag}"))
        table = {r["grasp_id"]: r for r in read_job(job, columns=COLUMNS).to_pylist()}
        for name, r in pick_examples(rows, hand, {scale}, obj[0] if obj else ""):
            row = table[r["grasp_id"]]
            scene = build_scene(load_hand(hand), row_pieces(row, job), cfg)
            path = args.render_dir / f"{HAND_TAGS[hand]}_{scale:g}_{name}_{row['object_id'].split('__')[-1]}.png"
            img = grasp_frames(scene, row_poses(row), cfg, width=2 * args.width, height=2 * args.height)
            # each view's middle half (the camera stands 5 object scales away): 2x the object
            tiles = [[img[i * 2 * args.height:(i + 1) * 2 * args.height, j * 2 * args.width:(j + 1) * 2 * args.width]
                      [args.height // 2:-args.height // 2, args.width // 2:-args.width // 2] for j in range(3)]
                     for i in range(2)]
            path.parent.mkdir(parents=True, exist_ok=True)
            write_png(path, np.concatenate([np.concatenate(t, axis=1) for t in tiles], axis=0))
            print(path, mechanism(r) if not r["success"] else "success", r["object_id"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("command", choices=["measure", "report", "render"])
    ap.add_argument("--work", type=Path, default=ROOT / ".cache" / "bench_quality", help="bench_quality's job folder")
    ap.add_argument("--tag", default="-s0.06_0.08_0.1_0.12_0.15", help="job name suffix (the scales)")
    ap.add_argument("--out", type=Path, default=None, help="per-row measurements (JSON lines; default WORK/diagnosis.jsonl)")
    ap.add_argument("--examples", default="shadow@0.12,shadow@0.15", help="render: HAND@SCALE[@OBJECT_ID],...")
    ap.add_argument("--render-dir", type=Path, default=Path("out/diagnosis"), help="render: PNG folder")
    ap.add_argument("--width", type=int, default=240, help="render: pixels per view (each cropped to half)")
    ap.add_argument("--height", type=int, default=180)
    args = ap.parse_args()
    args.out = args.out or args.work / "diagnosis.jsonl"
    args.out.touch()
    {"measure": measure, "report": report, "render": render}[args.command](args)


if __name__ == "__main__":
    main()
