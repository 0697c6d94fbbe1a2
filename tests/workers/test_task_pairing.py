"""A benchmark task runs only on its own object; other tasks on every object of the shard."""

from types import SimpleNamespace

from datagen.tasks import load_task
from workers.shard import task_targets


def test_tasks_pair_with_their_objects():
    targets = [SimpleNamespace(object_id=i) for i in ("task-knob2", "task-drawer", "proc-s0-000001")]
    assert [t.object_id for t in task_targets(load_task("turn_knob2"), targets)] == ["task-knob2"]
    assert [t.object_id for t in task_targets(load_task("pull_drawer"), targets)] == ["task-drawer"]
    assert task_targets(load_task("force_closure"), targets) == targets
    assert task_targets(load_task("precision_key"), targets) == []  # its object is not in this shard
