"""GWS boundary estimator against independent references (SOCP, NumPy)."""

import numpy as np
import pytest
import torch

from datagen.wrench import grasp_wrench_boundary, sample_directions, support_value
from tests.conftest import DEVICES
from tests.wrench import oracles


def _contacts(seed: int, m: int, kind: str = "sphere"):
    rng = np.random.default_rng(seed)
    p, n = oracles.sample_surface_contacts(rng, m, kind)
    return torch.tensor(p), torch.tensor(n)


@pytest.mark.parametrize("mu", [0.2, 0.5, 1.0])
@pytest.mark.parametrize("normalize", [True, False])
def test_exact_support_identity(mu, normalize):
    """u.s(u) = sum_i max(0, a_i + mu |t_i|), with a_i, t_i taken in world coordinates."""
    p, n = _contacts(1, 5, "box")
    u = sample_directions(500, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    w = grasp_wrench_boundary(p, n, u, mu, delta_deg=0.0, normalize=normalize)
    pn = oracles.cpn(p.numpy()) if normalize else p.numpy()
    un = u.numpy()
    g = un[:, None, :3] + np.cross(un[:, None, 3:], pn[None])  # u_f + u_tau x p
    a = (g * n.numpy()[None]).sum(-1)
    t = g - a[..., None] * n.numpy()[None]
    expected = np.maximum(0.0, a + mu * np.linalg.norm(t, axis=-1)).sum(-1)
    assert np.allclose((un * w.numpy()).sum(-1), expected, atol=1e-12)
    assert np.allclose(support_value(p, n, u, mu, normalize=normalize).numpy(), expected, atol=1e-12)


@pytest.mark.parametrize("mu", [0.3, 1.0])
def test_support_value_matches_socp(mu):
    p, n = _contacts(2, 4, "sphere")
    maps = oracles.grasp_maps(oracles.cpn(p.numpy()), n.numpy())
    u = sample_directions(20, generator=torch.Generator().manual_seed(4), dtype=torch.float64)
    h = support_value(p, n, u, mu)
    for k in range(len(u)):
        assert h[k].item() == pytest.approx(oracles.support_socp(maps, mu, u[k].numpy()), rel=1e-6, abs=1e-7)


@pytest.mark.parametrize("delta_deg", [0.0, 15.0, 30.0])
@pytest.mark.parametrize("mu", [0.2, 0.5, 1.0])
def test_membership_socp(delta_deg, mu):
    """Largest q with q*w in the GWS: exactly 1 for the exact mapping, >= 1 for delta > 0."""
    p, n = _contacts(5, 5, "box")
    maps = oracles.grasp_maps(oracles.cpn(p.numpy()), n.numpy())
    u = sample_directions(24, generator=torch.Generator().manual_seed(6), dtype=torch.float64)
    w = grasp_wrench_boundary(p, n, u, mu, delta_deg=delta_deg).numpy()
    q = np.array([oracles.radial_scale(maps, mu, wk) for wk in w])
    if delta_deg == 0.0:
        assert np.allclose(q, 1.0, atol=1e-5)
    else:
        assert (q >= 1.0 - 1e-6).all()
        assert (q > 1.0 + 1e-4).any()  # the approximation really moves points inward


def test_soft_finger_membership_and_pcf_limit():
    p, n = _contacts(7, 3, "sphere")
    u = sample_directions(16, generator=torch.Generator().manual_seed(8), dtype=torch.float64)
    mu, mu_t = 0.5, 0.02
    w = grasp_wrench_boundary(p, n, u, mu, delta_deg=0.0, contact_model="sfc", torsional_mu=mu_t)
    d = torch.linalg.norm(p - p.mean(0), dim=-1).mean().item()
    maps = oracles.grasp_maps(oracles.cpn(p.numpy()), n.numpy(), soft=True)
    q = np.array([oracles.radial_scale(maps, mu, wk, mu_t=mu_t / d) for wk in w.numpy()])
    assert np.allclose(q, 1.0, atol=1e-5)
    h_sfc = support_value(p, n, u, mu, contact_model="sfc", torsional_mu=mu_t)
    h_pcf = support_value(p, n, u, mu)
    assert (h_sfc >= h_pcf - 1e-12).all() and (h_sfc > h_pcf + 1e-6).any()
    w0 = grasp_wrench_boundary(p, n, u, mu, delta_deg=15.0, contact_model="sfc", torsional_mu=0.0)
    assert torch.allclose(w0, grasp_wrench_boundary(p, n, u, mu, delta_deg=15.0), atol=1e-12)


def test_cpn_invariance_and_rotation_equivariance():
    p, n = _contacts(9, 5, "box")
    u = sample_directions(64, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    w = grasp_wrench_boundary(p, n, u, 0.4)
    shifted = grasp_wrench_boundary(3.7 * p + torch.tensor([0.3, -1.0, 2.0], dtype=p.dtype), n, u, 0.4)
    assert torch.allclose(w, shifted, atol=1e-10)
    q, _ = torch.linalg.qr(torch.randn(3, 3, dtype=torch.float64))
    R = q * torch.sign(torch.det(q))
    big = torch.block_diag(R, R)
    rotated = grasp_wrench_boundary(p @ R.T, n @ R.T, u @ big.T, 0.4)
    assert torch.allclose(rotated, w @ big.T, atol=1e-10)


def test_batch_matches_loop_and_float32():
    ps, ns = zip(*[_contacts(s, 5, "box") for s in range(6)])
    P, N = torch.stack(ps).reshape(2, 3, 5, 3), torch.stack(ns).reshape(2, 3, 5, 3)
    mu = torch.tensor([[0.2, 0.5, 1.0], [0.3, 0.3, 0.6]], dtype=torch.float64)
    u = sample_directions(128, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    W = grasp_wrench_boundary(P, N, u, mu)
    for i in range(2):
        for j in range(3):
            single = grasp_wrench_boundary(P[i, j], N[i, j], u, float(mu[i, j]))
            assert torch.allclose(W[i, j], single, atol=1e-12)
    w32 = grasp_wrench_boundary(P.float(), N.float(), u.float(), mu.float())
    assert w32.dtype == torch.float32
    assert torch.allclose(w32.double(), W, atol=2e-5)
    per_batch_u = u.expand(2, 3, -1, -1)
    assert torch.allclose(grasp_wrench_boundary(P, N, per_batch_u, mu), W, atol=1e-12)


@pytest.mark.parametrize("delta_deg", [0.0, 15.0])
@pytest.mark.parametrize("contact_model", ["pcf", "sfc"])
def test_gradcheck(delta_deg, contact_model):
    p, n = _contacts(11, 4, "sphere")
    p.requires_grad_(True)
    n.requires_grad_(True)
    u = sample_directions(32, generator=torch.Generator().manual_seed(5), dtype=torch.float64)

    def fn(pp, nn):
        return grasp_wrench_boundary(pp, nn, u, 0.5, delta_deg=delta_deg, contact_model=contact_model, torsional_mu=0.01)

    assert torch.autograd.gradcheck(fn, (p, n), eps=1e-7, atol=1e-5)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_degenerate_inputs_have_finite_gradients(dtype):
    """Zero tangent (theta exactly 0), coincident contacts, theta = pi, zero direction component."""
    n = torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]], dtype=dtype, requires_grad=True)
    p = torch.zeros(2, 3, dtype=dtype, requires_grad=True)  # coincident contacts at the origin
    u = torch.tensor(
        [[0, 0, 1, 0, 0, 0], [0, 0, -1, 0, 0, 0], [0, 0, 0, 0, 0, 1], [1, 0, 0, 0, 0, 0]], dtype=dtype
    )
    for normalize in (True, False):
        for model in ("pcf", "sfc"):
            for delta in (0.0, 15.0):
                w = grasp_wrench_boundary(p, n, u, 0.5, delta_deg=delta, normalize=normalize, contact_model=model,
                                          torsional_mu=0.01)
                assert torch.isfinite(w).all()
                assert torch.allclose(w[0, :3], torch.tensor([0, 0, 2.0], dtype=dtype))  # theta = 0 -> c
                assert torch.allclose(w[1], torch.zeros(6, dtype=dtype))  # theta = pi -> apex
                gp, gn = torch.autograd.grad(w.sum() + support_value(p, n, u, 0.5).sum(), (p, n))
                assert torch.isfinite(gp).all() and torch.isfinite(gn).all()


@pytest.mark.parametrize("device", DEVICES)
def test_device_and_dtype_follow_inputs(device):
    p, n = _contacts(3, 5, "box")
    p, n = p.to(device, torch.float32), n.to(device, torch.float32)
    u = sample_directions(10, generator=torch.Generator().manual_seed(0), device=device)
    w = grasp_wrench_boundary(p, n, u, 0.5)
    assert w.device.type == device and w.dtype == torch.float32 and w.shape == (10, 6)


def test_sample_directions_uniform_and_seeded():
    g = torch.Generator().manual_seed(123)
    u = sample_directions(20000, generator=g, dtype=torch.float64)
    assert torch.allclose(u.norm(dim=-1), torch.ones(20000, dtype=torch.float64))
    assert u.mean(0).abs().max() < 0.02  # centred
    assert torch.allclose(u.T @ u / 20000, torch.eye(6, dtype=torch.float64) / 6, atol=0.01)  # isotropic
    assert torch.equal(u, sample_directions(20000, generator=torch.Generator().manual_seed(123), dtype=torch.float64))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(delta_deg=60.0), "delta_deg"),
        (dict(contact_model="soft"), "contact_model"),
        (dict(torsional_mu=-1.0), "torsional_mu"),
    ],
)
def test_bad_arguments_are_named(kwargs, match):
    p, n = _contacts(0, 3)
    u = sample_directions(4, dtype=torch.float64)
    with pytest.raises(ValueError, match=match):
        grasp_wrench_boundary(p, n, u, 0.5, **kwargs)
    with pytest.raises(ValueError, match="normals"):
        grasp_wrench_boundary(p, n[:2], u, 0.5)
    with pytest.raises(ValueError, match="mu"):
        grasp_wrench_boundary(p, n, u, -0.1)


@pytest.mark.parametrize("mu", [0.3, 1.0])
def test_weighted_support_matches_socp_with_force_bounds(mu):
    """A grasp type's extra contacts enter the GWS with a normal-force bound each (grasp_matrix
    ``weights``): the support equals the SOCP whose contact i has 0 <= f_n <= bound_i."""
    p, n = _contacts(7, 5, "box")
    bounds = torch.tensor([1.0, 1.0, 0.25, 0.0, 0.6], dtype=torch.float64)
    maps = oracles.grasp_maps(p.numpy(), n.numpy())
    u = sample_directions(16, generator=torch.Generator().manual_seed(8), dtype=torch.float64)
    w = grasp_wrench_boundary(p, n, u, mu, delta_deg=0.0, normalize=False, weights=bounds)
    for k in range(len(u)):
        ref = oracles.support_socp(maps, mu, u[k].numpy(), bounds=bounds.numpy())
        assert float(u[k] @ w[k]) == pytest.approx(ref, rel=1e-6, abs=1e-7)


def test_palm_contact_adds_its_bound_to_the_lift_support():
    """Hand-computed: two fingertips pinch a ball of radius r along x; the force support along
    +z (lifting) is friction only, 2 mu. A palm contact under the ball pushing +z with bound b
    adds b; with bound 0 (out of reach) the GWS is the pinch's, also under CPN."""
    mu, r = 0.5, 0.04
    tips = torch.tensor([[r, 0, 0], [-r, 0, 0]], dtype=torch.float64)
    tip_n = torch.tensor([[-1.0, 0, 0], [1.0, 0, 0]], dtype=torch.float64)
    p = torch.cat([tips, torch.tensor([[0, 0, -r]], dtype=torch.float64)])
    n = torch.cat([tip_n, torch.tensor([[0, 0, 1.0]], dtype=torch.float64)])
    up = torch.tensor([[0, 0, 1.0, 0, 0, 0]], dtype=torch.float64)
    for b in (1.0, 0.5):
        w = grasp_wrench_boundary(p, n, up, mu, delta_deg=0.0, normalize=False,
                                  weights=torch.tensor([1.0, 1.0, b], dtype=torch.float64))
        assert float(w[0, 2]) == pytest.approx(2 * mu + b, abs=1e-12)
    u = sample_directions(64, generator=torch.Generator().manual_seed(9), dtype=torch.float64)
    off = grasp_wrench_boundary(p, n, u, mu, delta_deg=0.0, weights=torch.tensor([1.0, 1.0, 0.0], dtype=torch.float64))
    assert torch.allclose(off, grasp_wrench_boundary(tips, tip_n, u, mu, delta_deg=0.0), atol=1e-12)
    ones = grasp_wrench_boundary(p, n, u, mu, delta_deg=15.0, weights=torch.ones(3, dtype=torch.float64))
    assert torch.allclose(ones, grasp_wrench_boundary(p, n, u, mu, delta_deg=15.0), atol=1e-12)
