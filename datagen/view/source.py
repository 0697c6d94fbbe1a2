"""The rows a viewer shows: a job directory, one of its shards, or a grasp table file.

``open_source`` reads the rows with `datagen.io` (a job: finished shards only, schema version
checked) or pyarrow (a file), and remembers where ``object_path`` is relative to (the job
directory for a job or a job's shard, the file's directory otherwise, as ``datagen eval``
does) and the evaluation config the rows were simulated with (the file metadata's
``datagen.eval_config``).

Column names are looked up, not assumed: `find_column` accepts the declared name with or
without a unit suffix (``penetration`` / ``penetration_m``), so files written before or after
a rename both open.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from datagen.io import POSE_COLUMNS, layout, read_job, shard_paths
from schemas import SchemaError, check_version

__all__ = ["GraspSource", "ViewError", "find_column", "open_source", "VERDICTS"]

# unit suffixes a column name may carry (schemas/*.json name units this way)
UNIT_SUFFIXES = ("_m", "_deg", "_rad", "_n", "_kg", "_s", "_mm")
VERDICTS = ("success", "failure", "not evaluated")


class ViewError(ValueError):
    """A source the viewer cannot show; the message names it, the reason and the remedy."""

    def __init__(self, thing: str, reason: str, remedy: str = "") -> None:
        super().__init__(f"{thing}: {reason}" + (f" ({remedy})" if remedy else ""))


def find_column(names: list[str] | tuple[str, ...], stem: str) -> str | None:
    """The column called ``stem``, or ``stem`` plus a unit suffix (``_m``, ``_deg``, ...), or
    ``stem`` minus one; None if there is none."""
    if stem in names:
        return stem
    for suf in UNIT_SUFFIXES:
        if stem + suf in names:
            return stem + suf
        if stem.endswith(suf) and stem[: -len(suf)] in names:
            return stem[: -len(suf)]
    return None


@dataclass
class GraspSource:
    """Rows to view. ``table`` one row per grasp; ``base`` the directory ``object_path`` is
    relative to; ``eval_config`` the `EvalConfig` fields the rows were simulated with ({}:
    unknown, the defaults are used); ``where`` names the source in messages."""

    table: pa.Table
    base: Path
    where: str
    eval_config: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        names = self.table.column_names
        need = [*POSE_COLUMNS, "object_id", "object_path", "hand"]
        missing = [c for c in need if c not in names]
        if find_column(names, "object_scale") is None:
            missing.append("object_scale")
        if missing:
            raise ViewError(self.where, f"missing columns {missing}",
                            "view a datagen job, a shard or a `datagen synth` / `datagen eval` table")
        if self.table.num_rows == 0:
            raise ViewError(self.where, "has no rows")
        self._cache: dict[str, list] = {}

    # ------------------------------------------------------------------ columns
    def column(self, stem: str) -> str | None:
        """The actual name of the column ``stem`` (see `find_column`), or None."""
        return find_column(self.table.column_names, stem)

    def values(self, stem: str) -> list:
        """All values of column ``stem`` as a Python list (None per row where it is absent)."""
        if stem not in self._cache:
            name = self.column(stem)
            self._cache[stem] = ([None] * len(self) if name is None
                                 else self.table.column(name).to_pylist())
        return self._cache[stem]

    def __len__(self) -> int:
        return self.table.num_rows

    def row(self, i: int) -> dict:
        """Row ``i`` as a dict of Python values (every column)."""
        if not 0 <= i < len(self):
            raise IndexError(f"row {i} out of range ({len(self)} rows)")
        return self.table.slice(i, 1).to_pylist()[0]

    def poses(self, i: int) -> np.ndarray:
        """(3, 7 + J) float64 pregrasp, grasp, squeeze of row ``i`` (object frame, m / rad)."""
        return np.stack([np.asarray(self.table.column(c)[i].as_py(), dtype=np.float64) for c in POSE_COLUMNS])

    def object_dir(self, i: int) -> Path:
        """The processed-object directory of row ``i``."""
        p = Path(self.values("object_path")[i])
        return p if p.is_absolute() else self.base / p

    # ------------------------------------------------------------------ verdicts and filters
    def _derived(self, key: str, make) -> list[str]:
        if key not in self._cache:
            self._cache[key] = make()
        return self._cache[key]

    def verdicts(self) -> list[str]:
        """Per row: ``success``, ``failure`` or ``not evaluated`` (a table without eval columns)."""
        return self._derived(" verdicts", lambda: ["not evaluated" if v is None else ("success" if v else "failure")
                                                   for v in self.values("success")])

    def reasons(self) -> list[str]:
        """Per row the failure reason code (``ok`` for a success, empty where not evaluated)."""
        return self._derived(" reasons", lambda: ["" if r is None else str(r) for r in self.values("reason")])

    def scales(self) -> list[str]:
        """Per row the object scale as a label (``0.060 m``), so equal float32 scales compare equal."""
        return self._derived(" scales", lambda: [f"{float(s):.3f} m" for s in self.values("object_scale")])

    def select(self, verdict: str | None = None, reason: str | None = None, task: str | None = None,
               hand: str | None = None, scale: str | None = None, object_id: str | None = None) -> np.ndarray:
        """Indices (ascending) of the rows matching every given filter (None = any)."""
        keep = np.ones(len(self), dtype=bool)
        for wanted, have in ((verdict, self.verdicts), (reason, self.reasons), (scale, self.scales),
                             (task, lambda: self.values("task")), (hand, lambda: self.values("hand")),
                             (object_id, lambda: self.values("object_id"))):
            if wanted is not None:
                keep &= np.array([str(v) == wanted for v in have()], dtype=bool)
        return np.flatnonzero(keep)


def _metadata(schema: pa.Schema) -> dict:
    return {k.decode(): v.decode() for k, v in (schema.metadata or {}).items()}


def _eval_config(meta: dict) -> dict:
    raw = meta.get("datagen.eval_config")
    if not raw:
        return {}
    try:
        return json.loads(raw)
    except json.JSONDecodeError:
        return {}


def open_source(path: str | Path) -> GraspSource:
    """A job directory, a shard of one (``JOB/shards/part-*.parquet``) or a grasp table file."""
    p = Path(path)
    if p.is_dir():
        if not (p / layout.JOB_JSON).is_file():
            raise ViewError(str(p), f"is a directory but not a datagen job (no {layout.JOB_JSON})",
                            "pass a job directory, a shard or a grasp table (.parquet)")
        shards = shard_paths(p)
        if not shards:
            raise ViewError(str(p), "no finished shard with rows yet", "wait for `datagen run` or check `datagen status`")
        try:
            table = read_job(p)
        except SchemaError as exc:
            raise ViewError(str(p), str(exc), "read it with the datagen version that wrote it") from None
        meta = _metadata(pq.read_schema(shards[0]))
        return GraspSource(table, p.resolve(), str(p), _eval_config(meta), meta)
    if not p.is_file():
        raise ViewError(str(p), "not found", "pass a job directory, a shard or a grasp table (.parquet)")
    try:
        table = pq.read_table(p)
    except (pa.ArrowInvalid, OSError) as exc:
        raise ViewError(str(p), f"cannot be read as Parquet: {exc}") from None
    meta = _metadata(table.schema)
    job = p.resolve().parent.parent
    in_job = p.resolve().parent.name == layout.SHARDS_DIR and (job / layout.JOB_JSON).is_file()
    if in_job or meta.get("datagen.schema") == "evaluated":
        try:
            check_version(table.schema, "evaluated", where=str(p))
        except SchemaError as exc:
            raise ViewError(str(p), str(exc), "read it with the datagen version that wrote it") from None
    return GraspSource(table, job if in_job else p.resolve().parent, str(p), _eval_config(meta), meta)
