"""Initial poses and a short synthesis are sane for every built-in hand (palm faces the object,
no hand-object penetration at the start, fingertips reach the surface)."""

import numpy as np
import pytest
import torch
import trimesh

from datagen.hands import load_hand
from datagen.synth import GraspTarget, SynthConfig, TaskSpec, load_task, synthesize
from datagen.synth.init import initial_poses
from tests.hands.conftest import hand_params


@pytest.fixture(scope="module")
def box():
    mesh = trimesh.creation.box(extents=[1.0, 0.7, 1.4])
    mesh.apply_scale(1.0 / np.linalg.norm(0.5 * mesh.extents))
    return GraspTarget.from_mesh(mesh, 0.08, "box")


@pytest.mark.parametrize("name", hand_params())
@pytest.mark.parametrize("init", [
    {"kind": "surround"},
    {"kind": "approach", "approach": [0, 0, -1], "thumb": [1, 0, 0], "roll_deg": 10},
])
def test_initial_poses_face_the_object_without_touching_it(name, init, box):
    hand = load_hand(name)
    spec = TaskSpec.from_dict({"name": "t", "init": init}).init
    B = 32
    root, joints = initial_poses(hand, [box], torch.zeros(B, dtype=torch.long), spec, torch.Generator().manual_seed(0))
    palm = hand.palm_frame(root, joints)
    to_centre = torch.nn.functional.normalize(-palm.origin, dim=-1)
    assert ((palm.approach * to_centre).sum(-1) > 0.5).float().mean() > 0.9
    centres, radii = hand.spheres(root, joints)
    clearance = box.query(centres).distance - radii  # exact mesh distance of every collision sphere
    assert (clearance.amin(-1) > -0.003).float().mean() > 0.9, f"{name}: the open hand starts inside the object"


@pytest.mark.parametrize("name", [p for p in hand_params() if p.values[0] != "shadow"])  # shadow: test_synthesize
def test_short_force_closure_synthesis_reaches_the_surface(name, box):
    hand = load_hand(name)
    cfg = SynthConfig.from_dict({"iters": 300, "seed": 0, "weights": {"self_penetration": 0.0} if name == "leap" else {}})
    res = synthesize(hand, [box], load_task("force_closure"), cfg, 4)
    assert res.usable(0.005).float().mean() >= 0.5, (name, res.tip_distance, res.max_penetration)
    assert torch.isfinite(res.squeeze).all() and torch.isfinite(res.pregrasp).all()
