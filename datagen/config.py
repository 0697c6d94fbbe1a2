"""The one config helper: typed, frozen dataclasses loaded from mappings and YAML.

Every config class of the library (`SynthConfig`, `EvalConfig`, `TaskSpec`, ...) is a frozen
dataclass deriving from `Config`, which gives it

- ``from_dict(data, where)``: unknown keys refused; every value checked against the field's type
  annotation (``int``, ``float``, ``bool``, ``str``, ``X | None``, ``tuple[X, ...]``, fixed
  ``tuple[X, Y, Z]``, ``Mapping[str, X]``, nested `Config` dataclasses); YAML lists become tuples,
  ints become floats where a float is declared;
- ``from_yaml(path)``, ``to_dict()`` (plain JSON/YAML types: lists, dicts, numbers, strings) and
  ``hash()`` (sha256 of the canonical JSON of ``to_dict()``; stable across runs and machines).

Bounds and cross-field rules stay in each class's ``__post_init__`` (they also guard direct
construction in code). Errors are `ConfigError` (or the class's ``config_error``, e.g.
`EvalError`) naming the field path and the reason.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar, TypeVar, Union

import yaml

from datagen import _bounded
from datagen.errors import ConfigError

__all__ = ["Config", "check_types", "from_mapping", "merge_layers", "read_yaml", "stable_hash", "to_plain"]

C = TypeVar("C", bound="Config")


class Config:
    """Mixin for frozen config dataclasses (see the module docstring)."""

    #: the error class raised for bad input (a `ConfigError` subclass with a ``make`` constructor)
    config_error: ClassVar[type[ConfigError]] = ConfigError

    @classmethod
    def from_dict(cls: type[C], data: Mapping[str, Any] | None = None, where: str | None = None) -> C:
        """Build from a mapping (e.g. parsed YAML); ``where`` prefixes every error (default: class name)."""
        return from_mapping(cls, data, where)

    @classmethod
    def from_yaml(cls: type[C], path: str | Path) -> C:
        """Build from a YAML file holding one mapping of this class's fields (read by `read_yaml`:
        a regular file of at most 1 MiB, plain data, no aliases, no key twice)."""
        try:
            data = read_yaml(path, f"{cls.__name__} file")
        except ValueError as exc:
            raise cls.config_error.make(str(path), str(exc).removeprefix(f"{path}: ")) from None
        return cls.from_dict(data, where=str(path))

    def to_dict(self) -> dict[str, Any]:
        """The fields as plain data (tuples as lists): ``from_dict(to_dict())`` gives an equal config."""
        return to_plain(self)

    def hash(self) -> str:
        """sha256 (hex) of the canonical JSON of `to_dict`: equal configs, equal hashes."""
        return stable_hash(self.to_dict())


class _PlainLoader(yaml.SafeLoader):
    """SafeLoader without aliases (``*ref`` can expand a few hundred bytes into gigabytes) and
    without a key given twice in one mapping (YAML would keep the last one silently)."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            mark = self.peek_event().start_mark
            raise yaml.composer.ComposerError(None, None, "YAML aliases (*name) are not allowed in a config", mark)
        return super().compose_node(parent, index)

    def construct_mapping(self, node, deep=False):
        seen: dict = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                first = seen.get(key)
                seen[key] = key_node.start_mark.line + 1
            except TypeError:  # an unhashable key: the base class names it
                break
            if first is not None:
                raise yaml.constructor.ConstructorError(
                    None, None, f"key {key!r} given twice (lines {first} and {seen[key]}): remove one")
        return super().construct_mapping(node, deep)


def read_yaml(path: str | Path, what: str = "config"):
    """The YAML document at ``path`` as plain data (mappings, lists, scalars). Raises ValueError
    (`datagen._bounded.InputError` for the file itself) naming the file and the reason: a missing
    file, one that is not a regular file (a device, a FIFO: refused before reading), over 1 MiB,
    not UTF-8, invalid YAML, language tags (``!!python/...``), aliases, a key given twice."""
    text = _bounded.read_text(path, _bounded.CONFIG_BYTES, what)
    try:
        return yaml.load(text, Loader=_PlainLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        detail = " ".join(str(exc).split())
        plain = isinstance(exc, (yaml.constructor.ConstructorError, yaml.composer.ComposerError))
        raise ValueError(f"{path}: the {what} is " + ("not plain YAML data" if plain else "not valid YAML")
                         + f": {detail}") from None
    except RecursionError:
        raise ValueError(f"{path}: the {what} is nested too deeply") from None


def to_plain(value: Any) -> Any:
    """Dataclasses, mappings and sequences as dicts and lists (JSON/YAML-safe)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): to_plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_plain(v) for v in value]
    return value


def stable_hash(data: Any) -> str:
    """sha256 (hex) of ``data``'s canonical JSON (sorted keys, no whitespace)."""
    blob = json.dumps(to_plain(data), sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(blob.encode()).hexdigest()


def _error_of(cls: type) -> type[ConfigError]:
    return getattr(cls, "config_error", ConfigError)


def from_mapping(cls: type[C], data: Mapping[str, Any] | None, where: str | None = None) -> C:
    """An instance of dataclass ``cls`` from ``data`` (see the module docstring)."""
    where = where or cls.__name__
    err = _error_of(cls)
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise err.make(where, f"expected a mapping of {cls.__name__} fields, got {type(data).__name__}")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(str(k) for k in set(data) - set(fields))
    if unknown:
        raise err.make(where, f"unknown keys {unknown}", f"known: {sorted(fields)}")
    hints = typing.get_type_hints(cls)
    kwargs = {k: _coerce(hints.get(k, Any), v, f"{where}.{k}", err) for k, v in data.items()}
    missing = sorted(k for k, f in fields.items() if k not in kwargs
                     and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING)
    if missing:
        raise err.make(where, f"missing required field(s) {missing}")
    return cls(**kwargs)


def check_types(obj: Any, where: str | None = None) -> None:
    """Raise the class's config error (see `from_mapping`) for the first field of dataclass ``obj``
    whose value does not fit its annotation, by the rules of ``from_dict``; nothing is converted
    (a list fits a tuple, an int a float). For ``__post_init__``: direct construction in code is
    checked like a mapping."""
    cls = type(obj)
    err, hints = _error_of(cls), typing.get_type_hints(cls)
    for f in dataclasses.fields(obj):
        if f.init:
            _coerce(hints.get(f.name, Any), getattr(obj, f.name), f"{where or cls.__name__}.{f.name}", err)


def _describe(tp: Any) -> str:
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (Union, types.UnionType):
        return " or ".join(_describe(a) for a in args)
    if tp is type(None):
        return "null"
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_describe(args[0])}"
        return f"a list of {len(args)} ({', '.join(_describe(a) for a in args)})"
    if origin in (dict, Mapping, typing.Mapping) or tp in (dict, Mapping):
        return "a mapping"
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return f"a mapping of {tp.__name__} fields"
    return {bool: "true or false", int: "an integer", float: "a number", str: "a string"}.get(tp, str(tp))


def _coerce(tp: Any, v: Any, thing: str, err: type[ConfigError]) -> Any:
    """``v`` checked against annotation ``tp`` (lists -> tuples, ints -> floats)."""
    if tp is Any:
        return v
    origin, args = typing.get_origin(tp), typing.get_args(tp)

    def bad(extra: str = "") -> ConfigError:
        return err.make(thing, f"must be {_describe(tp)}, got {v!r}", extra)

    if origin in (Union, types.UnionType):
        return _coerce_union(args, v, thing, err, bad)
    if tp in _SCALARS:
        return _coerce_scalar(tp, v, bad)
    if origin is tuple:
        if not isinstance(v, (list, tuple)):
            raise bad()
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(args[0], x, f"{thing}[{i}]", err) for i, x in enumerate(v))
        if len(v) != len(args):
            raise bad()
        return tuple(_coerce(a, x, f"{thing}[{i}]", err) for i, (a, x) in enumerate(zip(args, v)))
    if origin in (dict, Mapping) or tp in (dict, Mapping):
        if not isinstance(v, Mapping):
            raise bad()
        vt = args[1] if len(args) == 2 else Any
        return {k: _coerce(vt, x, f"{thing}.{k}", err) for k, x in v.items()}
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if isinstance(v, tp):
            return v
        if not isinstance(v, Mapping):
            raise bad()
        return from_mapping(tp, v, thing)
    if origin is list or tp is list:
        if not isinstance(v, (list, tuple)):
            raise bad()
        return list(v)
    return v


_SCALARS = (type(None), bool, int, float, str)


def _coerce_union(args: tuple, v: Any, thing: str, err: type[ConfigError], bad) -> Any:
    """``v`` as the first alternative of a union that takes it; None for an optional's None."""
    if v is None and type(None) in args:
        return None
    first: ConfigError | None = None
    for a in args:
        if a is type(None):
            continue
        try:
            return _coerce(a, v, thing, err)
        except ConfigError as exc:
            first = first or exc
    # one non-null alternative: its own (more precise) message; several: name them all
    if first is not None and sum(a is not type(None) for a in args) == 1:
        raise first
    raise bad()


def _coerce_scalar(tp: type, v: Any, bad) -> Any:
    """``v`` checked as None, bool, int (not a bool), float (an int becomes a float) or str."""
    if tp is type(None):
        ok = v is None
    elif tp is bool:
        ok = isinstance(v, bool)
    elif tp is int:
        ok = isinstance(v, int) and not isinstance(v, bool)
    elif tp is float:
        ok = isinstance(v, (int, float)) and not isinstance(v, bool)
        if not ok:
            raise bad("YAML reads 1e4 and 1.0e4 as strings: write 1.0e+4 or 10000" if isinstance(v, str) else "")
        return float(v)
    else:
        ok = isinstance(v, str)
    if not ok:
        raise bad()
    return v


def merge_layers(*layers: Mapping[str, Any] | None) -> dict[str, Any]:
    """The layers merged in order, later keys winning; nested mappings merge key by key."""
    out: dict[str, Any] = {}
    for layer in layers:
        for k, v in dict(layer or {}).items():
            if isinstance(v, Mapping) and isinstance(out.get(k), dict):
                out[k] = merge_layers(out[k], v)
            else:
                out[k] = merge_layers(v) if isinstance(v, Mapping) else v
    return out
