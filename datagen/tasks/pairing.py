"""Which objects a task runs on.

A task whose YAML names its object (``eval.object``: the task-benchmark tasks, each with its own
procedural object and virtual joint in `datagen.objects.task_objects`) runs on that object only,
``task-<name>`` of the ``tasks`` object source; every other task (force closure, ...) runs on
every object.
"""

from __future__ import annotations

from typing import Sequence, TypeVar

from .evaluation import task_object
from .spec import TaskSpec

__all__ = ["task_object_id", "task_targets"]

T = TypeVar("T")


def task_object_id(task: TaskSpec) -> str | None:
    """The object id (``task-<name>``) ``task`` is bound to, None if it runs on any object."""
    from datagen.objects.task_objects import object_id

    name = task_object(task)
    return None if name is None else object_id(name)


def task_targets(task: TaskSpec, targets: Sequence[T]) -> list[T]:
    """The items of ``targets`` (anything with an ``object_id``) that ``task`` runs on, in order."""
    oid = task_object_id(task)
    return list(targets) if oid is None else [t for t in targets if t.object_id == oid]
