"""EvalConfig / TaskTest validation and YAML loading."""

import math

import numpy as np
import pytest

from datagen.eval import DEFAULT_TASKS, EvalConfig, EvalError, TaskTest


def test_defaults_are_the_public_protocol():
    c = EvalConfig()
    assert (c.timestep_s, c.integrator, c.cone, c.impratio, c.noslip_iterations) == (0.004, "implicitfast",
                                                                                    "elliptic", 10.0, 2)
    assert c.gravity == (0.0, 0.0, 0.0) and c.condim == 4 and c.friction == (0.6, 0.02)
    assert c.hand_solimp == (0.5, 0.99, 1e-4) and c.hand_solref == (0.005, 1.0)
    assert (c.actuator_kp, c.actuator_force_limit, c.object_mass_kg) == (5.0, 3.0, 0.1)
    assert c.waypoints * c.steps_per_waypoint * c.timestep_s == pytest.approx(0.4)
    assert c.hold_seconds == pytest.approx(2.0) and c.check_every == 50
    assert c.force_per_kg * c.object_mass_kg == pytest.approx(1.0)
    assert (c.max_translation_m, c.max_rotation_deg, c.max_pregrasp_penetration_m) == (0.05, 15.0, 0.01)


def test_yaml_round_trip_and_task_override(tmp_path):
    path = tmp_path / "eval.yaml"
    path.write_text("threads: 3\nmax_rotation_deg: 10\ntasks:\n  open_lid: {w_t: [0, 0, 0, 0, 0, -2], "
                    "joint: hinge, axis: [0, 0, 2], anchor: [0, 0.01, 0]}\n")
    c = EvalConfig.from_yaml(path)
    assert c.threads == 3 and c.max_rotation_deg == 10
    t = c.task_test("open_lid")
    assert t.joint == "hinge" and t.axis == (0.0, 0.0, 1.0) and t.anchor == (0.0, 0.01, 0.0)
    assert set(DEFAULT_TASKS) < set(c.tasks)  # built-ins kept
    assert c.task_test("force_closure") is None
    assert EvalConfig.from_dict(c.to_dict()) == c


def test_disturbance_is_minus_w_t_scaled():
    t = TaskTest(w_t=(0, 0, 3, 0, 0, 4), torque_arm=2.0)
    w = t.disturbance(0.1, 0.05, 10.0)
    # unit w_t = (0, 0, .6, 0, 0, .8); force 1 N; torque arm 2 scales = 0.1 m
    assert np.allclose(w, [0, 0, -0.6, 0, 0, -0.8 * 1.0 * 0.1])


@pytest.mark.parametrize("bad, word", [
    ({"timestep_s": 0}, "timestep_s"), ({"hold_steps": 510}, "check_every"), ({"settle_checks": -1}, "settle_checks"), ({"settle_safety": 0.5}, "settle_safety"), ({"bogus": 1}, "unknown keys"),
    ({"cone": "round"}, "cone"), ({"contact_distance_m": 0.001}, "touch_distance_m"),
    ({"tasks": {"x": {"w_t": [0, 0, 0, 0, 0, 0]}}}, "non-zero"),
    ({"tasks": {"x": {"w_t": [1, 0, 0, 0, 0, 0], "joint": "ball"}}}, "joint"),
    ({"tasks": {"force_closure": {"w_t": [1, 0, 0, 0, 0, 0]}}}, "hold_tasks"),
])
def test_bad_configs_name_the_field(bad, word):
    with pytest.raises(EvalError, match=word):
        EvalConfig.from_dict(bad)


def test_unknown_task_is_an_error_naming_it():
    with pytest.raises(EvalError, match="open_sesame"):
        EvalConfig().task_test("open_sesame")
    assert math.isclose(EvalConfig().max_rotation_deg, 15.0)
