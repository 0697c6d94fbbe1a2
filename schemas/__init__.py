"""Versioned Arrow schemas for datagen's Parquet files, declared once in JSON.

``grasps.json`` (synthesized rows), ``evaluated.json`` (a dataset shard: grasps + the MuJoCo
evaluation columns, via ``extends``), ``failures.json`` (a job's failed objects) and
``observations.json`` (a job's object observations: point clouds, camera views) declare
every column (type, shape, unit, frame, doc; names end with their unit, `UNIT_SUFFIXES`); :func:`arrow_schema`
builds the ``pyarrow.Schema`` from it (``nq`` = 7 + the hand's joint count), with the schema
name and version in the metadata; :func:`check_version` refuses files of another version.
"""

from __future__ import annotations

import json
import re
from functools import lru_cache
from pathlib import Path

import pyarrow as pa

__all__ = ["UNIT_SUFFIXES", "SchemaError", "arrow_schema", "check_version", "column_table", "columns", "declaration"]

# a column whose values have one unit ends its name with that unit's suffix
UNIT_SUFFIXES = {"m": "_m", "m^2": "_m2", "rad": "_rad", "deg": "_deg", "N": "_n", "N m": "_nm", "s": "_s",
                 "kg": "_kg"}

_DIR = Path(__file__).parent
_SCALARS = {"string": pa.string(), "float32": pa.float32(), "int64": pa.int64(), "int32": pa.int32(), "bool": pa.bool_()}


class SchemaError(ValueError):
    """A file or table that does not match the declared schema (names the file and the mismatch)."""


@lru_cache
def declaration(name: str = "grasps") -> dict:
    path = _DIR / f"{name}.json"
    if not path.is_file():
        raise SchemaError(f"no schema declaration {path}")
    return json.loads(path.read_text())


def columns(name: str = "grasps") -> list[dict]:
    """Columns of ``name``; a declaration with ``extends`` starts with its parent's columns."""
    decl = declaration(name)
    parent = columns(decl["extends"]) if decl.get("extends") else []
    return parent + decl["columns"]


def _parse_type(t: str, dims: dict[str, int]) -> pa.DataType:
    """``string``, ``float32``, ... ; ``float32[N]`` a fixed-size list; ``list<T>`` a list of T."""
    if t.startswith("list<") and t.endswith(">"):
        return pa.list_(_parse_type(t[5:-1], dims))
    m = re.fullmatch(r"(\w+)\[(\w+)\]", t)
    if m:
        return pa.list_(_SCALARS[m[1]], dims[m[2]] if not m[2].isdigit() else int(m[2]))
    return _SCALARS[t]


def _arrow_type(col: dict, dims: dict[str, int]) -> pa.DataType:
    base = _parse_type(col["type"], dims)
    if "shape" in col:
        (n,) = col["shape"]
        return pa.list_(base, dims[n] if isinstance(n, str) else int(n))
    return base


def arrow_schema(name: str = "grasps", **dims: int) -> pa.Schema:
    """Arrow schema of ``name`` with symbolic sizes bound (e.g. ``nq=31``)."""
    decl = declaration(name)
    fields = [pa.field(c["name"], _arrow_type(c, dims), metadata={"doc": c["doc"], "unit": c.get("unit", ""),
                                                                   "frame": c.get("frame", "")})
              for c in columns(name)]
    meta = {"datagen.schema": decl["name"], "datagen.schema_version": str(decl["version"])}
    return pa.schema(fields, metadata=meta)


def check_version(schema: pa.Schema, name: str = "grasps", where: str = "table") -> None:
    """Raise :class:`SchemaError` unless ``schema`` carries this schema's name and version."""
    meta = {k.decode(): v.decode() for k, v in (schema.metadata or {}).items()}
    want = str(declaration(name)["version"])
    if meta.get("datagen.schema") != name or meta.get("datagen.schema_version") != want:
        raise SchemaError(f"{where}: schema {meta.get('datagen.schema')!r} version "
                          f"{meta.get('datagen.schema_version')!r}, expected {name!r} version {want}")


def column_table(name: str = "evaluated") -> list[dict[str, str]]:
    """One dict per column of ``name`` (name, type, unit, frame, meaning) for documentation; a
    fixed-size list shows its size (``float32[nq]``)."""
    out = []
    for c in columns(name):
        t = c["type"] + (f"[{c['shape'][0]}]" if "shape" in c else "")
        out.append({"name": c["name"], "type": t, "unit": c.get("unit", ""), "frame": c.get("frame", ""),
                    "meaning": c["doc"]})
    return out
