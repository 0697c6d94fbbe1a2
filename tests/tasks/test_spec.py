"""Tasks as data: built-in YAMLs load, a YAML task round-trips, tasks pair with their objects."""

from types import SimpleNamespace

import pytest
import yaml

from datagen.errors import ConfigError
from datagen.tasks import (SPEC_DIR, InitConfig, TaskSpec, builtin_tasks, load_task, task_object_id,
                           task_targets, task_test_from_spec)


def test_builtin_specs_are_package_files_and_all_load():
    names = builtin_tasks()
    assert "force_closure" in names and len(names) == len(list(SPEC_DIR.glob("*.yaml")))
    for n in names:
        spec = load_task(n)
        assert spec.name == n and len(spec.w_t) == 6 and isinstance(spec.init, InitConfig)


def test_a_yaml_task_round_trips(tmp_path):
    spec = TaskSpec(name="t", w_t=(0, 0, 1, 0, 0, 0), gamma_deg=30.0, fingers=("th", "ff"),
                    init=InitConfig(kind="approach", thumb=(1.0, 0.0, 0.0)),
                    eval={"test": "task", "object": "knob2"})
    p = tmp_path / "t.yaml"
    p.write_text(yaml.safe_dump(spec.to_dict()))
    again = load_task(p)
    assert again == spec and again.hash() == spec.hash()
    assert task_test_from_spec(again).joint == "hinge"  # knob2's own joint


def test_unknown_task_and_missing_file_are_config_errors(tmp_path):
    with pytest.raises(ConfigError, match="unknown task 'juggle'") as err:
        load_task("juggle")
    assert "force_closure" in err.value.remedy
    with pytest.raises(ConfigError, match="does not exist"):
        load_task(tmp_path / "none.yaml")


def test_tasks_pair_with_their_objects():
    targets = [SimpleNamespace(object_id=i) for i in ("task-knob2", "task-drawer", "proc-s0-000001")]
    assert task_object_id(load_task("turn_knob2")) == "task-knob2"
    assert [t.object_id for t in task_targets(load_task("pull_drawer"), targets)] == ["task-drawer"]
    assert task_targets(load_task("force_closure"), targets) == targets
    assert task_targets(load_task("precision_key"), targets) == []  # its object is not among them


def test_hands_block_overrides_init_and_fingers_for_that_hand_only(tmp_path):
    p = tmp_path / "h.yaml"
    p.write_text("name: h\nfingers: [th, ff, mf]\ninit: {kind: approach, curl: 0.3, target_m: [0, 0, 0.01]}\n"
                 "hands:\n  allegro: {init: {curl: 0.5, target_m: [0.0, 0.02, 0.0]}, fingers: [th, ff]}\n"
                 "  leap: {init: {aim: fingertips}}\n")
    spec = load_task(p)
    a = spec.for_hand("allegro")
    assert (a.init.curl, a.init.target_m, a.fingers) == (0.5, (0.0, 0.02, 0.0), ("th", "ff"))
    assert a.init.kind == "approach" and a.hands == {}  # the rest is the task's
    leap = spec.for_hand("leap")
    assert (leap.init.aim, leap.init.curl, leap.fingers) == ("fingertips", 0.3, ("th", "ff", "mf"))
    shadow = spec.for_hand("shadow")
    assert (shadow.init, shadow.fingers) == (spec.init, spec.fingers)
    p.write_text(yaml.safe_dump(spec.to_dict()))
    assert load_task(p) == spec  # round-trips with its hands block


@pytest.mark.parametrize("block, field", [("allegro: {init: {curll: 0.5}}", "curll"),
                                          ("allegro: {init: {curl: 2.0}}", "curl"),
                                          ("allegro: {finger: [th]}", "finger")])
def test_bad_hands_block_names_the_field(tmp_path, block, field):
    p = tmp_path / "h.yaml"
    p.write_text(f"name: h\nhands:\n  {block}\n")
    with pytest.raises(ConfigError, match=field):
        load_task(p)


def test_synth_block_is_the_start_and_callers_settings_go_on_top(tmp_path):
    from datagen.pipeline import resolve

    p = tmp_path / "s.yaml"
    p.write_text("name: s\nsynth: {exact_contacts: true, seeds_per_grasp: 8, weights: {task: 3.0}}\n")
    spec = load_task(p)
    cfg = resolve("shadow", p, flags={"synth": {"weights": {"distance": 2.0e4}, "iters": 7}}).synth
    assert (cfg.exact_contacts, cfg.seeds_per_grasp, cfg.iters, cfg.task) == (True, 8, 7, "s")
    assert (cfg.weights.task, cfg.weights.distance) == (3.0, 2.0e4)  # weights merged key by key
    assert resolve("shadow", p, config={"synth": {"weights": {"task": 0.0}}}).synth.weights.task == 0.0
    assert spec.for_hand("allegro").synth == spec.synth
    p.write_text("name: s\nsynth: {seeds: 8}\n")
    with pytest.raises(ConfigError, match=r"task 's'.*seeds"):
        resolve("shadow", p)
