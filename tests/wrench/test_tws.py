"""TWS support mapping and the task energy."""

import numpy as np
import pytest
import torch

from datagen.wrench import grasp_wrench_boundary, sample_directions, task_energy, task_wrench_support
from tests.wrench import oracles


def _angle(a, b):
    a = a / a.norm(dim=-1, keepdim=True)
    b = b / b.norm(dim=-1, keepdim=True)
    return torch.arccos((a * b).sum(-1).clamp(-1, 1))


@pytest.mark.parametrize("gamma", [15.0, 60.0, 120.0])
def test_sector_mapping_inside_and_outside(gamma):
    w = torch.tensor([0.0, 0, 0, 0, 0, 1], dtype=torch.float64)
    u = sample_directions(4000, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    s = task_wrench_support(u, w, gamma)
    inside = _angle(u, w) <= np.radians(gamma)
    assert inside.any() and (~inside).any() or gamma == 15.0
    assert torch.allclose(s[inside], u[inside])
    out = ~inside
    assert torch.allclose(_angle(s[out], w), torch.full((int(out.sum()),), np.radians(gamma), dtype=torch.float64), atol=1e-9)
    # on the rim, in the plane of u and w_t: s = a u + b w
    basis = torch.stack([u[out], w.expand_as(u[out])], -1)
    coef = torch.linalg.lstsq(basis, s[out][..., None]).solution
    assert torch.allclose((basis @ coef).squeeze(-1), s[out], atol=1e-9)
    assert torch.allclose(s.norm(dim=-1), torch.ones(len(s), dtype=torch.float64))


def test_sector_mapping_maximizes_over_sampled_sector():
    """s_Wt(u) is the arg max of u.t over the sector: no sampled sector point does better."""
    rng = np.random.default_rng(0)
    w = np.array([1.0, 0, 1, 0, 0, 0]) / np.sqrt(2)
    cap = torch.tensor(oracles.sample_cap(rng, w, np.radians(40), 20000))
    u = sample_directions(200, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    s = task_wrench_support(u, torch.tensor(w), 40.0)
    best_sampled = (u @ cap.T).amax(-1)
    assert ((u * s).sum(-1) >= best_sampled - 1e-12).all()
    assert ((u * s).sum(-1) - best_sampled).max() < 0.05  # 20k samples of a 5-D cap are sparse


def test_full_sphere_is_identity_and_antipode_is_finite():
    u = sample_directions(100, dtype=torch.float64)
    w = torch.tensor([0.0, 1, 0, 0, 0, 0], dtype=torch.float64)
    assert torch.allclose(task_wrench_support(u, w, 180.0), u)
    s = task_wrench_support(-w[None], w, 30.0)
    assert torch.isfinite(s).all() and _angle(s, w).item() == pytest.approx(np.radians(30))


def test_batched_tasks():
    u = sample_directions(50, dtype=torch.float64)
    W = torch.eye(6, dtype=torch.float64)[:3]
    gam = torch.tensor([10.0, 90.0, 180.0], dtype=torch.float64)
    S = task_wrench_support(u, W, gam)
    assert S.shape == (3, 50, 6)
    for i in range(3):
        assert torch.allclose(S[i], task_wrench_support(u, W[i], float(gam[i])))


def _knob_contacts(twist: float):
    """Two fingertips pinching a 2 cm knob from +-x; 'twist' tilts the normals tangentially."""
    p = torch.tensor([[0.02, 0.0, 0.0], [-0.02, 0.0, 0.0]], dtype=torch.float64)
    c, s = np.cos(twist), np.sin(twist)
    n = torch.tensor([[-c, s, 0.0], [c, -s, 0.0]], dtype=torch.float64)
    return p, n


def test_task_energy_prefers_a_pose_that_can_apply_the_task_wrench():
    u = sample_directions(2000, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    w_t, gamma = [0, 0, 0, 0, 0, 1], 15.0  # turn a knob: torque about z
    # pushing on the top face cannot produce z torque; a pinch on the sides can (friction)
    top = (torch.tensor([[0.01, 0, 0.02], [-0.01, 0, 0.02]], dtype=torch.float64),
           torch.tensor([[0, 0, -1.0], [0, 0, -1.0]], dtype=torch.float64))
    side = _knob_contacts(0.0)
    e_top = task_energy(*top, 0.5, w_t, gamma, u)
    e_side = task_energy(*side, 0.5, w_t, gamma, u)
    assert e_side < e_top - 0.05 * len(u)
    # the energy's minimum is -K, reached only if every boundary point lies in the sector
    assert (e_side >= -len(u) - 1e-9) and (e_top >= -len(u) - 1e-9)


def test_task_energy_gradient_descent_lowers_energy():
    """Following -grad E_t w.r.t. the normals of a pinch rotates them to produce z torque."""
    u = sample_directions(256, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    p, n = _knob_contacts(0.0)
    n = (n + 0.3 * torch.tensor([[0, 0, 1.0], [0, 0, 1.0]], dtype=torch.float64)).requires_grad_(True)
    energies = []
    for _ in range(30):
        e = task_energy(p, n, 0.3, [0, 0, 0, 0, 0, 1], 15.0, u)
        (g,) = torch.autograd.grad(e, n)
        energies.append(e.item())
        with torch.no_grad():
            n -= 0.002 * g
    assert energies[-1] < energies[0] - 1.0


@pytest.mark.parametrize("kind", ["cos", "l2"])
def test_task_energy_gradcheck_and_l2_magnitude(kind):
    rng = np.random.default_rng(0)
    p, n = oracles.sample_surface_contacts(rng, 4, "box")
    P = torch.tensor(p, requires_grad=True)
    N = torch.tensor(n, requires_grad=True)
    u = sample_directions(64, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    assert torch.autograd.gradcheck(lambda a, b: task_energy(a, b, 0.5, [0, 0, 1, 0, 0, 0], 30.0, u, kind=kind),
                                    (P, N), eps=1e-7, atol=1e-5)
    if kind == "l2":  # the L2 ablation depends on the GWS magnitude, the cosine energy does not
        sg = grasp_wrench_boundary(P, N, u, 0.5)
        st = task_wrench_support(u, [0, 0, 1, 0, 0, 0], 30.0)
        e = task_energy(P, N, 0.5, [0, 0, 1, 0, 0, 0], 30.0, u, kind="l2")
        assert e.item() == pytest.approx(((sg - st) ** 2).sum().item())
        e_cos = task_energy(P, N, 0.5, [0, 0, 1, 0, 0, 0], 30.0, u)
        e_cos_2mu = task_energy(P, N, 0.5, [0, 0, 1, 0, 0, 0], 30.0, u, normalize=False)
        assert torch.isfinite(e_cos) and torch.isfinite(e_cos_2mu)


def test_task_energy_is_finite_when_gws_point_is_origin():
    p = torch.zeros(2, 3, dtype=torch.float64, requires_grad=True)
    n = torch.tensor([[0, 0, 1.0], [0, 0, 1.0]], dtype=torch.float64, requires_grad=True)
    u = torch.tensor([[0, 0, -1.0, 0, 0, 0]], dtype=torch.float64)  # theta = pi: s_Wg = 0
    e = task_energy(p, n, 0.5, [0, 0, -1, 0, 0, 0], 10.0, u)
    assert e.item() == 0.0
    gp, gn = torch.autograd.grad(e, (p, n))
    assert torch.isfinite(gp).all() and torch.isfinite(gn).all()


def test_bad_task_arguments():
    u = sample_directions(4, dtype=torch.float64)
    with pytest.raises(ValueError, match="gamma_deg"):
        task_wrench_support(u, [1, 0, 0, 0, 0, 0], 200.0)
    with pytest.raises(ValueError, match="w_t"):
        task_wrench_support(u, [1, 0, 0], 30.0)
    with pytest.raises(ValueError, match="kind"):
        task_energy(torch.zeros(2, 3), torch.ones(2, 3), 0.5, [1, 0, 0, 0, 0, 0], 30.0, u.float(), kind="l1")


@pytest.mark.parametrize("normalize", [True, False])
def test_task_wrench_at_contacts_is_the_wrench_the_contact_forces_make(normalize):
    """Contact forces whose resultant about ``origin`` is the task wrench: mapped through the
    grasp matrix (the GWS's own coordinates), they give the direction `task_wrench_at_contacts`
    returns. The resultant is plain statics (numpy sums of forces and moments)."""
    from datagen.wrench.gws import grasp_matrix
    from datagen.wrench.tws import task_wrench_at_contacts

    rng = np.random.default_rng(2)
    for _ in range(5):
        p = rng.normal(size=(4, 3)) * 0.03 + rng.normal(size=3) * 0.05
        n = rng.normal(size=(4, 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        f = rng.normal(size=(4, 3))
        origin = rng.normal(size=3) * 0.05
        w = np.concatenate([f.sum(0), np.cross(p - origin, f).sum(0)])  # the forces' wrench about origin
        G, _ = grasp_matrix(torch.tensor(p), torch.tensor(n), normalize=normalize)
        from datagen.wrench._geometry import tangent_basis

        d, e = (x.numpy() for x in tangent_basis(torch.tensor(n)))
        local = np.stack([(f * n).sum(1), (f * d).sum(1), (f * e).sum(1)], 1).reshape(-1)  # (n, d, e) per contact
        in_gws = G.numpy() @ local
        got = task_wrench_at_contacts(w.tolist(), torch.tensor(p), torch.tensor(origin), normalize=normalize).numpy()
        np.testing.assert_allclose(got, in_gws / np.linalg.norm(in_gws), atol=1e-9)


def test_task_wrench_at_contacts_keeps_a_pure_torque_and_batches():
    from datagen.wrench.tws import task_wrench_at_contacts

    p = torch.randn(3, 4, 3, dtype=torch.float64) * 0.02
    origin = torch.randn(3, 3, dtype=torch.float64) * 0.1
    w = task_wrench_at_contacts([0, 0, 0, 0, 0, 2.0], p, origin)
    torch.testing.assert_close(w, torch.tensor([[0, 0, 0, 0, 0, 1.0]] * 3, dtype=torch.float64))
    # a force acting at the contacts' centroid is unchanged
    w = task_wrench_at_contacts([0, 0, 1.0, 0, 0, 0], p, p.mean(1))
    torch.testing.assert_close(w, torch.tensor([[0, 0, 1.0, 0, 0, 0]] * 3, dtype=torch.float64))
