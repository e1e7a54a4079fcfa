"""Volume compositing: agreement with the textbook product, and stability at extreme densities."""
from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from training.model.rendering import compositing_weights, render_rays  # noqa: E402


def reference_weights(sigma):
    alpha = 1.0 - torch.exp(-sigma)
    trans = torch.cumprod(torch.cat([torch.ones_like(alpha[..., :1]), 1.0 - alpha + 1e-10], -1), -1)[..., :-1]
    return alpha * trans


def test_matches_cumprod_for_moderate_densities():
    sigma = torch.rand(5, 7, 8, dtype=torch.float64) * 3.0
    torch.testing.assert_close(compositing_weights(sigma), reference_weights(sigma), rtol=1e-6, atol=1e-9)


def test_sample_axis_argument():
    sigma = torch.rand(2, 6, 9) * 2
    w_last = compositing_weights(sigma.transpose(1, 2), dim=-1)
    w_mid = compositing_weights(sigma, dim=-2)
    torch.testing.assert_close(w_mid, w_last.transpose(1, 2))


def test_empty_rays_show_background():
    sigma = torch.zeros(3, 4, 10)  # (B, N, M), samples on dim -2
    z = torch.linspace(2.0, 3.0, 4).view(1, 4, 1).expand(3, 4, 10)
    rgb = torch.rand(3, 3, 4, 10)
    heat = torch.rand(25, 3, 4, 10)
    out = render_rays(sigma, z, rgb, heat, background=0.25, dim=-2)
    assert torch.all(out["weights"] == 0) and torch.all(out["acc"] == 0)
    torch.testing.assert_close(out["rgb"], torch.full((3, 3, 10), 0.25))
    assert torch.all(out["heatmaps"] == 0)
    assert torch.all(torch.isfinite(out["depth"]))


@pytest.mark.parametrize("big", [1e30, float("inf"), 1e4])
def test_huge_density_is_opaque_and_finite_with_finite_gradients(big):
    sigma = torch.tensor([[0.0, big, 0.5, big], [big, big, big, big], [0.0, 0.0, 0.0, 0.0]], requires_grad=True)
    values = torch.rand(4, 3, 4, requires_grad=True)  # (C, rays, N)
    z = torch.linspace(2.0, 3.0, 4).expand(3, 4)
    out = render_rays(sigma, z, values[:3], values, dim=-1)
    w = out["weights"]
    assert torch.all(torch.isfinite(w))
    torch.testing.assert_close(w[0], torch.tensor([0.0, 1.0, 0.0, 0.0]), atol=1e-6, rtol=0)
    torch.testing.assert_close(w[1], torch.tensor([1.0, 0.0, 0.0, 0.0]), atol=1e-6, rtol=0)
    torch.testing.assert_close(out["acc"], torch.tensor([1.0, 1.0, 0.0]), atol=1e-6, rtol=0)
    loss = out["rgb"].sum() + out["heatmaps"].sum() + out["depth"].sum() + out["acc"].sum()
    loss.backward()
    assert torch.all(torch.isfinite(sigma.grad)) and torch.all(torch.isfinite(values.grad))


def test_gradients_finite_over_a_wide_range():
    sigma = torch.logspace(-8, 30, 64).reshape(8, 8).requires_grad_(True)
    w = compositing_weights(sigma)
    assert torch.all(w >= 0) and torch.all(w.sum(-1) <= 1 + 1e-6)
    (w * torch.arange(8.0)).sum().backward()
    assert torch.all(torch.isfinite(sigma.grad))


def test_single_sample():
    sigma = torch.tensor([[0.0], [1.0]])
    torch.testing.assert_close(compositing_weights(sigma), 1.0 - torch.exp(-sigma))


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
def test_half_precision_densities_composite_without_nan_gradients(dtype):
    # float16: exp(-20) and the 1e-10 both round to 0, so log(0) = -inf and its gradient was NaN
    sigma32 = torch.tensor([[20.0, 1.0, 1.0], [0.5, 80.0, 2.0], [0.0, 0.0, 0.0], [1e4, 3.0, 0.1]])
    sigma = sigma32.to(dtype).requires_grad_(True)
    w = compositing_weights(sigma)
    assert w.dtype == dtype and torch.all(torch.isfinite(w))
    torch.testing.assert_close(w.float(), compositing_weights(sigma.detach().float()).to(dtype).float())
    (w.float() * torch.arange(3.0)).sum().backward()
    assert torch.all(torch.isfinite(sigma.grad))
