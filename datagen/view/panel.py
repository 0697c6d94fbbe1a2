"""A row's numbers as Markdown: verdict and failure reason, metrics, per-direction displacement.

Units come from the column's Arrow field metadata (``unit``, written from schemas/*.json) or
its name's suffix; lengths are shown in millimetres.
"""

from __future__ import annotations

import math

import pyarrow as pa

from datagen.eval.config import DIRECTION_NAMES

from .source import GraspSource, find_column

__all__ = ["METRICS", "format_value", "verdict_line", "row_markdown", "unit_of"]

# (column stem, label) of the metric table, in order; absent columns are skipped
METRICS = (
    ("epsilon", "epsilon (MuJoCo contacts)"),
    ("synth_epsilon", "epsilon (synthesis)"),
    ("penetration_m", "penetration at the grasp"),
    ("pregrasp_penetration_m", "penetration at the pregrasp"),
    ("self_penetration_m", "self penetration"),
    ("min_distance_m", "min hand-object distance"),
    ("sphere_penetration_m", "deepest sphere penetration (synthesis)"),
    ("num_contacts", "contacts"),
    ("touching_links", "touching links"),
    ("energy_total", "energy"),
)
_SHOWN = {"success", "reason", "eval_test", "dir_success", "dir_translation_m", "dir_rotation_deg"}


def unit_of(field: pa.Field) -> str:
    """The unit of a column: its metadata's ``unit``, else its name's suffix (``_m``, ``_deg``)."""
    meta = {k.decode(): v.decode() for k, v in (field.metadata or {}).items()}
    if meta.get("unit"):
        return meta["unit"]
    for suf, unit in (("_m", "m"), ("_deg", "deg"), ("_rad", "rad")):
        if field.name.endswith(suf):
            return unit
    return ""


def format_value(value, unit: str) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        if math.isnan(value):
            return "-"
        if unit == "m":
            return f"{1000 * value:.2f} mm"
        if unit == "deg":
            return f"{value:.1f} deg"
        return f"{value:.4g}" + (f" {unit}" if unit else "")
    if isinstance(value, str) and len(value) > 20:
        return value[:16] + "..."  # hashes: the start identifies them
    return f"{value}" + (f" {unit}" if unit and isinstance(value, int) else "")


def verdict_line(source: GraspSource, i: int) -> str:
    """``Verdict: success``, ``Verdict: failure (slipped_+x)`` or ``Verdict: not evaluated``."""
    verdict = source.value("verdict", i)
    reason = source.value("reason", i) or ""
    return f"Verdict: {verdict}" + (f" ({reason})" if verdict == "failure" and reason else "")


def row_markdown(source: GraspSource, i: int) -> str:
    """Markdown of row ``i``: verdict, identity, metrics, per-direction results, other scalars."""
    schema = source.schema
    row = source.row(i)
    names = schema.names
    scale_col = source.column("object_scale")
    out = [f"**{verdict_line(source, i)}**", "",
           f"object `{row['object_id']}` at {float(row[scale_col]):.3f} m, hand `{row['hand']}`, "
           f"task `{row.get('task', '-')}`" + (f", grasp `{row['grasp_id']}`" if "grasp_id" in row else ""),
           "", "| metric | value |", "|---|---|"]
    used = set(_SHOWN) | {scale_col}
    for stem, label in METRICS:
        name = find_column(names, stem)
        if name is not None:
            out.append(f"| {label} | {format_value(row[name], unit_of(schema.field(name)))} |")
            used.add(name)
    moved, turned = source.column("dir_translation_m"), source.column("dir_rotation_deg")
    if moved is not None and row.get(moved) is not None:
        ok = row.get(source.column("dir_success") or "", None) or [None] * len(row[moved])
        test = str(row.get("eval_test") or "")
        dirs = DIRECTION_NAMES if len(row[moved]) == len(DIRECTION_NAMES) else [test or "task"] * len(row[moved])
        rot = row.get(turned) if turned else None
        out += ["", f"test `{test or '-'}`", "", "| direction | held | displacement | rotation |", "|---|---|---|---|"]
        for k, d in enumerate(dirs):
            held = {True: "yes", False: "no", None: "not run"}[ok[k] if k < len(ok) else None]
            out.append(f"| {d} | {held} | {format_value(row[moved][k], 'm')} | {format_value(rot[k] if rot else None, 'deg')} |")
        used.update({moved, turned})
    rest = [n for n in names if n not in used and not pa.types.is_nested(schema.field(n).type)
            and n not in ("object_id", "hand", "task", "grasp_id", "object_path")]
    if rest:
        out += ["", "| column | value |", "|---|---|"]
        out += [f"| {n} | {format_value(row[n], unit_of(schema.field(n)))} |" for n in rest]
    return "\n".join(out)
