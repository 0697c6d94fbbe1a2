"""The one base of datagen's exceptions: every error names the thing, the reason and a remedy.

A failed grasp or object is a *status* with a reason code (rows and failure records), not an
exception; these are for bad input and unusable configuration. Each domain keeps its own
subclass where it is raised (`datagen.objects.ObjectError`, `datagen.hands.HandSpecError`, ...);
the two that several layers share live here:

- `ConfigError`: a malformed config or task spec (unknown key, wrong type, out of bounds).
- `EvalError`: a configuration or input problem of the MuJoCo evaluation (a `ConfigError`).

A command-line front end catches `DatagenError` and prints ``str(exc)``; ``exc.remedy`` holds the
fix alone (may be empty).
"""

from __future__ import annotations

__all__ = ["ConfigError", "DatagenError", "EvalError"]


class DatagenError(Exception):
    """Base of datagen's errors. ``remedy``: what the user can do about it ("" if nothing known)."""

    remedy: str = ""

    def __init__(self, message: str, remedy: str = "") -> None:
        self.remedy = remedy
        super().__init__(message + (f" ({remedy})" if remedy else ""))

    def __reduce__(self):
        # rebuilt from its message and attributes, not by calling __init__ again (whose signature
        # differs per subclass): it crosses process boundaries intact (Ray tasks, process pools)
        return _rebuild, (type(self), self.args, dict(self.__dict__))


def _rebuild(cls: type, args: tuple, state: dict) -> "DatagenError":
    exc = cls.__new__(cls, *args)
    exc.args = args
    exc.__dict__.update(state)
    return exc


class ConfigError(DatagenError, ValueError):
    """A malformed config or task spec; the message names the file/field and the fix."""

    def __init__(self, message: str, remedy: str = "", *, thing: str = "", reason: str = "") -> None:
        self.thing, self.reason = thing, reason or message
        super().__init__(message, remedy)

    @classmethod
    def make(cls, thing: str, reason: str, remedy: str = "") -> "ConfigError":
        """The error for ``thing`` (a field, a file) with ``reason`` (the config helper's constructor)."""
        return cls(f"{thing}: {reason}", remedy, thing=thing, reason=reason)


class EvalError(ConfigError):
    """A configuration or input problem of the evaluation (not a failed grasp, which is a status).

    The message names the thing, the reason and, where possible, the remedy."""

    def __init__(self, thing: str, reason: str, remedy: str = "") -> None:
        super().__init__(f"{thing}: {reason}", remedy, thing=thing, reason=reason)

    @classmethod
    def make(cls, thing: str, reason: str, remedy: str = "") -> "EvalError":
        return cls(thing, reason, remedy)
