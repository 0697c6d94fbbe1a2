"""`pinch_antipodal_error` on hand-computed pinches, and where synthesis adds it to E_t."""

import math

import torch

from datagen.wrench import pinch_antipodal_error


def _pinch(tilt0: float, tilt1: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Contacts 0.05 m apart on the z axis; inward normals turned by tilt0 / tilt1 (rad) about x."""
    p = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 0.05]], dtype=torch.float64)
    n0 = torch.tensor([0.0, -math.sin(tilt0), math.cos(tilt0)], dtype=torch.float64)  # into the object: +z
    n1 = torch.tensor([0.0, math.sin(tilt1), -math.cos(tilt1)], dtype=torch.float64)  # into the object: -z
    return p, torch.stack([n0, n1])


def test_hand_computed_pinches():
    p, n = _pinch(0.0, 0.0)
    assert pinch_antipodal_error(p, n).item() == 0.0  # normals on the axis, facing each other
    a, b = 0.2, 0.35
    p, n = _pinch(a, b)
    assert math.isclose(pinch_antipodal_error(p, n).item(), (1 - math.cos(a)) + (1 - math.cos(b)), rel_tol=1e-12)
    # the contacts listed the other way round: the same error
    assert math.isclose(pinch_antipodal_error(p.flip(0), n.flip(0)).item(), pinch_antipodal_error(p, n).item(),
                        rel_tol=1e-12)
    # both normals turned outwards (pointing away from each other): the largest error, 4
    p, n = _pinch(0.0, 0.0)
    assert math.isclose(pinch_antipodal_error(p, -n).item(), 4.0, rel_tol=1e-12)


def test_batched_and_differentiable_towards_the_axis():
    p, n = _pinch(0.3, 0.0)
    P = p.expand(5, 2, 3).clone().requires_grad_(True)
    err = pinch_antipodal_error(P, n.expand(5, 2, 3))
    assert err.shape == (5,)
    err.sum().backward()
    # contact 0's normal leans to -y: moving contact 1 towards -y aligns the axis with it
    assert (P.grad[:, 1, 1] > 0).all() and (P.grad[:, 0, 1] < 0).all()
