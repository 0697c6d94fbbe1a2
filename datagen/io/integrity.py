"""A job that vouches for its files: the ledger records each shard file's size, rows and sha256.

A finished shard's ledger entry (``ledger/part-NNNNN.json``, written last) lists the files it
wrote, by path relative to the job directory::

    "files": {"shards/part-00003.parquet":   {"bytes": 48213, "rows": 96, "sha256": "9f1c..."},
              "observations/part-00003.parquet": {"bytes": 157322, "rows": 4, "sha256": "5d2e..."},
              "failures/part-00003.parquet": {"bytes": 2210, "rows": 1, "sha256": "04ab..."}}

(a shard without rows lists no shard file; a job without observations, or a shard whose objects
all failed, no observations file). Readers trust only what the ledger lists, as it
lists it: `audit` checks every entry, cheaply (each file's size and its Parquet footer's row
count) or deeply (also its sha256, and that the processed objects its rows name are in the
job). Every Parquet file is written with page checksums (CRC32 per page, `WRITE_OPTIONS`) and
read with their verification on (`read_parquet`), so a flipped bit in a page is an error naming
the file, never a wrong value. Entries written before the ledger
held ``files`` are accepted as they are (`Audit.unrecorded`): nothing to check them against.

    a = audit(job_dir, deep=True)
    a.finished      # {shard index: ledger entry} whose files match
    a.problems      # {shard index: "shards/part-00003.parquet: truncated: ..."} (to redo)
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from datagen import _bounded
from datagen.errors import DatagenError

from . import layout

__all__ = ["Audit", "ShardError", "WRITE_OPTIONS", "audit", "check_file", "check_text", "file_record",
           "observations_file", "read_ledger", "read_parquet", "sha256_of", "text_record"]

#: keyword arguments of every ``pq.write_table`` of a job's files: CRC32 page checksums
WRITE_OPTIONS = {"write_page_checksum": True}
_LEDGER_NAME = re.compile(r"^part-(\d{5,})\.json$")


class ShardError(DatagenError, ValueError):
    """A job file that does not match its ledger entry or cannot be read: names the file, the
    reason and the remedy (rerun the job, which redoes that shard)."""

    def __init__(self, path: str | Path, reason: str, remedy: str = "") -> None:
        self.path, self.reason = str(path), reason
        super().__init__(f"{path}: {reason}", remedy)


def redo_remedy(job_dir: str | Path) -> str:
    """The remedy of a damaged shard: rerunning the job redoes it (same seed, same rows)."""
    return (f"rerun the job (`datagen run --resume --out {job_dir}`): it redoes that shard with the same seed, "
            "so the same rows")


def sha256_of(path: str | Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def file_record(path: str | Path) -> dict:
    """``{"bytes", "rows", "sha256"}`` of a Parquet file just written (rows from its footer)."""
    return {"bytes": os.path.getsize(path), "rows": pq.read_metadata(path).num_rows, "sha256": sha256_of(path)}


def check_file(path: Path, record: dict, deep: bool) -> str | None:
    """Why ``path`` does not match its ledger ``record``, or None: missing, another size
    (truncated or grown), an unreadable footer, another row count; ``deep``: another sha256."""
    why = _size_problem(path, record, f"the ledger lists {record.get('rows', '?')} rows")
    if why:
        return why
    try:
        rows = pq.read_metadata(path).num_rows
    except (OSError, pa.ArrowException) as exc:
        return f"its Parquet footer cannot be read ({_one_line(exc)})"
    if rows != record.get("rows"):
        return f"{rows} rows in its footer, the ledger recorded {record.get('rows')}"
    if deep:
        try:
            sha = sha256_of(path)
        except OSError as exc:
            return f"cannot be read ({exc.strerror})"
        if sha != record.get("sha256"):
            return f"sha256 {sha[:12]}... != the ledger's {str(record.get('sha256'))[:12]}...: its bytes changed"
    return None


def _size_problem(path: Path, record: dict, listed: str) -> str | None:
    """Why ``path`` is not ``record["bytes"]`` long (missing, unreadable, truncated, grown), or None;
    ``listed``: what the record says it holds, for a missing file's message."""
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        return f"missing ({listed}, {record.get('bytes', '?')} bytes)"
    except OSError as exc:
        return f"cannot be read ({exc.strerror})"
    want = record.get("bytes")
    if size != want:
        kind = "truncated" if isinstance(want, int) and size < want else "changed size"
        return f"{kind}: {size} bytes, the ledger recorded {want}"
    return None


def text_record(text: str) -> dict:
    """``{"bytes", "lines", "sha256"}`` of a text file's content (UTF-8), as `check_text` checks it."""
    data = text.encode()
    return {"bytes": len(data), "lines": data.count(b"\n"), "sha256": hashlib.sha256(data).hexdigest()}


def check_text(path: Path, record: dict) -> str | None:
    """Why the text file ``path`` does not match ``record`` (`text_record`), or None: missing,
    another size, another line count, another sha256. Bounded: a file larger than the record
    says is not read."""
    why = _size_problem(path, record, f"the ledger recorded {record.get('lines', '?')} lines")
    if why:
        return why
    try:
        data = path.read_bytes()
    except OSError as exc:
        return f"cannot be read ({exc.strerror})"
    lines = data.count(b"\n")
    if lines != record.get("lines"):
        return f"{lines} lines, the ledger recorded {record.get('lines')}"
    sha = hashlib.sha256(data).hexdigest()
    if sha != record.get("sha256"):
        return f"sha256 {sha[:12]}... != the ledger's {str(record.get('sha256'))[:12]}...: its bytes changed"
    return None


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def read_ledger(path: Path) -> dict:
    """One ledger entry; `ShardError` naming it when it is empty, truncated or not an object."""
    try:
        entry = _bounded.read_json(path, "ledger entry")
    except _bounded.InputError as exc:
        raise ShardError(path, exc.detail) from None
    if not isinstance(entry, dict):
        raise ShardError(path, "the ledger entry is not a JSON object")
    return entry


def read_parquet(path: str | Path, columns: list[str] | None = None, filter=None, remedy: str = "") -> pa.Table:
    """A Parquet file with its page checksums verified; `ShardError` naming the file for a
    damaged page, page header or footer."""
    try:
        return pq.read_table(path, columns=columns, filters=filter, page_checksum_verification=True)
    except FileNotFoundError:
        raise ShardError(path, "missing", remedy) from None
    except (OSError, pa.ArrowException) as exc:
        raise ShardError(path, f"damaged: {_one_line(exc)}", remedy) from None


@dataclass
class Audit:
    """What `audit` found. ``finished``: index -> entry of the shards whose files match;
    ``problems``: index -> one line (the file and what is wrong); ``unrecorded``: finished shards
    whose entry lists no files (written by code before the ledger recorded them)."""

    finished: dict[int, dict] = field(default_factory=dict)
    problems: dict[int, str] = field(default_factory=dict)
    unrecorded: list[int] = field(default_factory=list)
    checked_files: int = 0

    def shard_files(self, job_dir: str | Path) -> dict[int, Path]:
        """Shard files (with rows) of the finished shards, by index."""
        job_dir = Path(job_dir)
        out = {}
        for i, entry in sorted(self.finished.items()):
            p = job_dir / shard_file(i)
            if "files" in entry:
                if shard_file(i) in entry["files"]:
                    out[i] = p
            elif p.is_file():
                out[i] = p
        return out

    def observation_files(self, job_dir: str | Path) -> dict[int, Path]:
        """Observation files of the finished shards that recorded one, by index."""
        return {i: Path(job_dir) / observations_file(i) for i, entry in sorted(self.finished.items())
                if observations_file(i) in entry.get("files", {})}


def shard_file(index: int) -> str:
    return f"{layout.SHARDS_DIR}/{layout.SHARD_NAME.format(index=index)}.parquet"


def observations_file(index: int) -> str:
    return f"{layout.OBSERVATIONS_DIR}/{layout.SHARD_NAME.format(index=index)}.parquet"


def failures_file(index: int) -> str:
    return f"{layout.FAILURES_DIR}/{layout.SHARD_NAME.format(index=index)}.parquet"


def audit(job_dir: str | Path, deep: bool = False) -> Audit:
    """Check every ledger entry of the job at ``job_dir`` against the files it lists (see the
    module docstring); a ledger entry that cannot be read is a problem of its shard."""
    job_dir = Path(job_dir)
    out = Audit()
    for p in sorted((job_dir / layout.LEDGER_DIR).glob("part-*.json")):
        m = _LEDGER_NAME.match(p.name)
        if not m:
            continue
        i = int(m.group(1))
        try:
            entry = read_ledger(p)
        except ShardError as exc:
            out.problems[i] = f"{layout.LEDGER_DIR}/{p.name}: {exc.reason}"
            continue
        files = entry.get("files")
        if files is None:
            out.unrecorded.append(i)
            out.finished[i] = entry
            continue
        bad = None
        for rel, record in sorted(files.items()):
            out.checked_files += 1
            why = check_file(job_dir / rel, record if isinstance(record, dict) else {}, deep)
            if why:
                bad = f"{rel}: {why}"
                break
        if bad is None and deep and shard_file(i) in files:
            bad = _missing_object(job_dir, job_dir / shard_file(i))
        if bad:
            out.problems[i] = bad
        else:
            out.finished[i] = entry
    return out


def _missing_object(job_dir: Path, shard: Path) -> str | None:
    """A processed object the shard's rows name (``object_path``) that the job lacks, or None."""
    try:
        rels = read_parquet(shard, ["object_path"])["object_path"].unique().to_pylist()
    except ShardError as exc:
        return f"{shard.relative_to(job_dir)}: {exc.reason}"
    for rel in rels:
        if not (job_dir / rel / "meta.json").is_file():
            return f"{rel}: a processed object its rows name is missing from the job"
    return None
