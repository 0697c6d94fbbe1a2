"""``.to(device)`` returns a copy on the device and leaves the original where it was
(GraspTarget, MeshSDF and GridSDF alike, like ``torch.Tensor.to``)."""

import torch
import trimesh

from datagen.synth import GraspTarget


def test_to_returns_a_copy_and_keeps_the_original():
    t = GraspTarget.from_mesh(trimesh.creation.box((1, 1, 1)), 0.05, "box", hull_samples=64, grid_resolution=8)
    assert t.grid is not None
    moved = t.to("meta")  # a device every machine has: tensors without storage
    assert moved is not t and moved.sdf is not t.sdf and moved.grid is not t.grid
    for a, b in ((t.hull_points, moved.hull_points), (t.sdf.vertices, moved.sdf.vertices),
                 (t.grid.values, moved.grid.values)):
        assert a.device == torch.device("cpu") and b.device == torch.device("meta")
    d = t.distance(torch.tensor([[0.0, 0.0, 0.05]]))  # the original still answers on the CPU
    assert torch.allclose(d, torch.tensor([0.025]), atol=1e-6)
