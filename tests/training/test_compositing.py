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


@pytest.mark.parametrize("negative", [-1.0, -1e30, float("-inf")])
def test_negative_densities_are_empty_space_with_finite_gradients(negative):
    """A negative density (a head without its softplus, a corrupt checkpoint) is no matter: clamped to 0, it
    stops nothing, and backward through the clamp stays finite."""
    sigma = torch.tensor([[negative, 2.0, negative, 1.0], [negative] * 4], requires_grad=True)
    z = torch.linspace(2.0, 3.0, 4).expand(2, 4)
    rgb = torch.rand(3, 2, 4, requires_grad=True)
    out = render_rays(sigma, z, rgb, None, background=0.25, dim=-1)
    want = compositing_weights(torch.tensor([[0.0, 2.0, 0.0, 1.0], [0.0] * 4]))
    torch.testing.assert_close(out["weights"], want)
    torch.testing.assert_close(out["rgb"][:, 1], torch.full((3,), 0.25))  # all-empty ray: the background
    (out["rgb"].sum() + out["depth"].sum() + out["acc"].sum()).backward()
    assert torch.all(torch.isfinite(sigma.grad)) and torch.all(torch.isfinite(rgb.grad))
    assert torch.all(sigma.grad[sigma.detach() < 0] == 0)  # below the clamp: no pull either way


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64, torch.float16])
def test_any_mix_of_extreme_densities_gives_weights_in_range_and_finite_gradients(dtype):
    """Property sweep: rays mixing 0, negative, -inf, denormal, moderate, 1e30 and inf densities (some rays all
    empty, some all opaque) composite to weights in [0, 1] summing to at most 1, a depth within the samples'
    range, colour within the colours' and the background's, and finite gradients for every input."""
    rng = torch.Generator().manual_seed(62)
    specials = torch.tensor([0.0, -1.0, float("-inf"), 1e-40, 0.3, 5.0, 1e30, float("inf")], dtype=torch.float64)
    for _ in range(20):
        sigma64 = specials[torch.randint(len(specials), (16, 12), generator=rng)]
        sigma64[0] = 0.0  # an all-empty ray
        sigma64[1] = float("inf")  # an all-opaque one
        sigma = sigma64.to(dtype).requires_grad_(True)
        z = (2.0 + torch.rand(16, 12, generator=rng, dtype=torch.float64).cumsum(-1)).requires_grad_(True)
        rgb = torch.rand(3, 16, 12, generator=rng, dtype=torch.float64).requires_grad_(True)
        heat = torch.rand(2, 16, 12, generator=rng, dtype=torch.float64).requires_grad_(True)
        out = render_rays(sigma, z, rgb, heat, background=0.5, dim=-1)
        w = out["weights"].double()
        # (<= 1 to the convention's 1e-10 per sample: ENeRF's T multiplies 1 - alpha + 1e-10, above 1 in float64)
        assert torch.all((w >= 0) & (w <= 1 + 1e-8)) and torch.all(w.sum(-1) <= 1 + 1e-3)
        depth = out["depth"]
        assert torch.all((depth >= 0) & (depth <= z.max(-1).values + 1e-9))
        assert torch.all((out["rgb"] >= -1e-6) & (out["rgb"] <= 1 + 1e-6))
        loss = sum(v.double().sum() for v in out.values())
        loss.backward()
        for leaf in (sigma, z, rgb, heat):
            assert torch.all(torch.isfinite(leaf.grad)), leaf.grad
