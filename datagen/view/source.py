"""The rows a viewer shows: a job directory, one of its shards, or a grasp table file.

``open_source`` finds the rows with `datagen.io` (a job: finished shards only, schema version
checked) or takes one Parquet file, and remembers where ``object_path`` is relative to (the job
directory for a job or a job's shard, the file's directory otherwise, as ``datagen eval``
does) and the evaluation config the rows were simulated with (the file metadata's
``datagen.eval_config``).

Column names are looked up, not assumed: `find_column` accepts the declared name with or
without a unit suffix (``penetration`` / ``penetration_m``), so files written before or after
a rename both open.
"""

from __future__ import annotations

import json
from collections import OrderedDict
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from datagen.io import POSE_COLUMNS, layout, open_dataset, shard_paths
from datagen.io.integrity import read_parquet
from schemas import SchemaError, check_version

__all__ = ["GraspSource", "INDEX_COLUMNS", "ViewError", "find_column", "open_source", "VERDICTS"]

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


# columns read for every row up front (filters, picker, paths); the rest is read per shown row
INDEX_COLUMNS = ("grasp_id", "object_id", "object_scale", "object_path", "hand", "task", "success", "reason")


class GraspSource:
    """Rows to view, from Parquet ``files`` (a job's finished shards, or one file).

    Only the `INDEX_COLUMNS` of every row are held in memory, as category codes (a dataset of a
    million rows costs tens of MB); a row's other columns are read from its file when it is
    shown (the last files read are cached). ``base`` is the directory ``object_path`` is
    relative to; ``eval_config`` the `EvalConfig` fields the rows were simulated with ({}:
    unknown, the defaults are used); ``where`` names the source in messages.
    """

    def __init__(self, files: list[Path], base: Path, where: str, eval_config: dict | None = None,
                 metadata: dict | None = None, cached_files: int = 2) -> None:
        self.files = [Path(f) for f in files]
        self.base, self.where = Path(base), where
        self.eval_config, self.metadata = dict(eval_config or {}), dict(metadata or {})
        self.schema = pq.read_schema(self.files[0])
        names = self.schema.names
        need = [*POSE_COLUMNS, "object_id", "object_path", "hand"]
        missing = [c for c in need if c not in names]
        if find_column(names, "object_scale") is None:
            missing.append("object_scale")
        if missing:
            raise ViewError(self.where, f"missing columns {missing}",
                            "view a datagen job, a shard or a `datagen synth` / `datagen eval` table")
        index = [c for c in (find_column(names, stem) for stem in INDEX_COLUMNS) if c is not None]
        parts = [read_parquet(f, index) for f in self.files]  # page checksums verified: a damaged file is named
        self._starts = np.cumsum([0] + [p.num_rows for p in parts])
        self._index = pa.concat_tables(parts) if len(parts) > 1 else parts[0]
        if self._index.num_rows == 0:
            raise ViewError(self.where, "has no rows")
        self._categories: dict[str, tuple[np.ndarray, list]] = {}
        self._tables: OrderedDict[int, pa.Table] = OrderedDict()
        self._cached_files = cached_files

    def __len__(self) -> int:
        return self._index.num_rows

    # ------------------------------------------------------------------ columns
    def column(self, stem: str) -> str | None:
        """The actual name of the column ``stem`` (see `find_column`), or None."""
        return find_column(self.schema.names, stem)

    def categories(self, stem: str) -> tuple[np.ndarray, list]:
        """Codes (N,) int32 and their labels of an index column, or of ``verdict`` (`VERDICTS`)
        or ``scale`` (``0.060 m``: equal float32 scales share a label). Code -1: no value."""
        if stem not in self._categories:
            self._categories[stem] = self._encode(stem)
        return self._categories[stem]

    def _encode(self, stem: str) -> tuple[np.ndarray, list]:
        n = len(self)
        if stem == "verdict":
            name = self.column("success")
            if name is None:
                return np.full(n, 2, dtype=np.int32), list(VERDICTS)
            ok = self._index.column(name)
            codes = np.where(pc.is_null(ok).to_numpy(zero_copy_only=False), 2,
                             np.where(pc.fill_null(ok, False).to_numpy(zero_copy_only=False), 0, 1))
            return codes.astype(np.int32), list(VERDICTS)
        if stem == "scale":
            values = self._index.column(self.column("object_scale")).to_numpy().astype(np.float64)
            labels, codes = np.unique(np.round(values, 6), return_inverse=True)
            return codes.astype(np.int32), [f"{v:.3f} m" for v in labels]
        name = self.column(stem)
        if name is None or name not in self._index.column_names:
            return np.full(n, -1, dtype=np.int32), []
        enc = self._index.column(name).cast(pa.string()).dictionary_encode().combine_chunks()
        codes = pc.fill_null(enc.indices, -1).to_numpy(zero_copy_only=False).astype(np.int32)
        return codes, [str(v) for v in enc.dictionary.to_pylist()]

    def value(self, stem: str, i: int):
        """Row ``i``'s value of ``stem``: a label of `categories` (None: no value), else the
        column's value read from the row."""
        if stem in ("verdict", "scale") or find_column(INDEX_COLUMNS, stem) is not None:
            codes, labels = self.categories(stem)
            return None if codes[i] < 0 else labels[codes[i]]
        name = self.column(stem)
        return None if name is None else self.row(i)[name]

    def values(self, stem: str) -> list:
        """Every row's `value` of an index column (a list: for tests and small sources)."""
        codes, labels = self.categories(stem)
        return [None if c < 0 else labels[c] for c in codes]

    def options(self, stem: str, rows: np.ndarray | None = None) -> list[str]:
        """The labels of ``stem`` present among ``rows`` (default all), in order of first row."""
        codes, labels = self.categories(stem)
        sel = codes if rows is None else codes[rows]
        _, first = np.unique(sel, return_index=True)
        return [labels[c] for c in sel[np.sort(first)] if c >= 0 and labels[c] != ""]

    def scale(self, i: int) -> float:
        """Row ``i``'s object scale in metres."""
        return float(self._index.column(self.column("object_scale"))[i].as_py())

    # ------------------------------------------------------------------ rows
    def _locate(self, i: int) -> tuple[int, int]:
        if not 0 <= i < len(self):
            raise IndexError(f"row {i} out of range ({len(self)} rows)")
        f = int(np.searchsorted(self._starts, i, side="right")) - 1
        return f, i - int(self._starts[f])

    def row(self, i: int) -> dict:
        """Row ``i`` as a dict of Python values (every column)."""
        f, j = self._locate(i)
        if f not in self._tables:
            self._tables[f] = read_parquet(self.files[f])
            while len(self._tables) > self._cached_files:
                self._tables.popitem(last=False)
        self._tables.move_to_end(f)
        return self._tables[f].slice(j, 1).to_pylist()[0]

    def poses(self, i: int) -> np.ndarray:
        """(3, 7 + J) float64 pregrasp, grasp, squeeze of row ``i`` (object frame, m / rad)."""
        row = self.row(i)
        return np.stack([np.asarray(row[c], dtype=np.float64) for c in POSE_COLUMNS])

    def table(self, i: int) -> tuple | None:
        """The support plane ``[n, d]`` (object frame) of a tabletop row ``i``; None: floating."""
        row = self.row(i)
        return tuple(float(x) for x in row["support_plane"]) if row.get("scene") == "tabletop" else None

    def object_dir(self, i: int) -> Path:
        """The processed-object directory of row ``i``."""
        p = Path(self.value("object_path", i))
        return p if p.is_absolute() else self.base / p

    # ------------------------------------------------------------------ verdicts and filters
    def verdicts(self) -> list[str]:
        """Per row: ``success``, ``failure`` or ``not evaluated`` (a table without eval columns)."""
        return self.values("verdict")

    def reasons(self) -> list[str]:
        """Per row the failure reason code (``ok`` for a success, empty where not evaluated)."""
        return ["" if r is None else r for r in self.values("reason")]

    def scales(self) -> list[str]:
        """Per row the object scale as a label (``0.060 m``)."""
        return self.values("scale")

    def select(self, verdict: str | None = None, reason: str | None = None, task: str | None = None,
               hand: str | None = None, scale: str | None = None, object_id: str | None = None) -> np.ndarray:
        """Indices (ascending) of the rows matching every given filter (None = any)."""
        keep = np.ones(len(self), dtype=bool)
        for stem, wanted in (("verdict", verdict), ("reason", reason), ("task", task), ("hand", hand),
                             ("scale", scale), ("object_id", object_id)):
            if wanted is not None:
                codes, labels = self.categories(stem)
                keep &= codes == (labels.index(wanted) if wanted in labels else -2)
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
            open_dataset(p)  # checks the schema version
        except SchemaError as exc:
            raise ViewError(str(p), str(exc), "read it with the datagen version that wrote it") from None
        meta = _metadata(pq.read_schema(shards[0]))
        return GraspSource(shards, p.resolve(), str(p), _eval_config(meta), meta)
    if not p.is_file():
        raise ViewError(str(p), "not found", "pass a job directory, a shard or a grasp table (.parquet)")
    try:
        schema = pq.read_schema(p)
    except (pa.ArrowInvalid, OSError) as exc:
        raise ViewError(str(p), f"cannot be read as Parquet: {exc}") from None
    meta = _metadata(schema)
    job = p.resolve().parent.parent
    in_job = p.resolve().parent.name == layout.SHARDS_DIR and (job / layout.JOB_JSON).is_file()
    if in_job or meta.get("datagen.schema") == "evaluated":
        try:
            check_version(schema, "evaluated", where=str(p))
        except SchemaError as exc:
            raise ViewError(str(p), str(exc), "read it with the datagen version that wrote it") from None
    return GraspSource([p], job if in_job else p.resolve().parent, str(p), _eval_config(meta), meta)
