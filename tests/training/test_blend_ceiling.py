"""The source-blend ceiling (``training.blend_ceiling``) on a generated scene: geometry and visibility."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

from ghnerf_runtime.metrics import masked_psnr  # noqa: E402
from training.blend_ceiling import affine_fill, blend_sources, project, unproject  # noqa: E402


@pytest.fixture(scope="module")
def scene(data64):
    from training.data.torch_dataset import MultiViewDataset

    return {k: v.numpy() for k, v in MultiViewDataset(data64, "val")[0].items()}


def psnr(pred, truth, mask):
    return float(np.ravel(masked_psnr(np.clip(pred, 0, 1)[None], truth[None], mask[None]).per_image)[0])


def test_unproject_then_project_is_the_pixel_grid(scene):
    t = 2
    depth = np.where(scene["tgt_depth"][t] > 0, scene["tgt_depth"][t], 3.0)
    u, v, z = project(unproject(depth, scene["tgt_K_inv"][t], scene["tgt_c2w"][t]), scene["tgt_P"][t])
    H, W = depth.shape
    vv, uu = np.mgrid[0:H, 0:W]
    assert np.allclose(u, uu, atol=1e-3) and np.allclose(v, vv, atol=1e-3)
    assert np.allclose(z, depth, atol=1e-4)


@pytest.mark.parametrize("view", [0, 1])
def test_a_source_blended_at_its_true_depth_gives_back_its_own_image(scene, view):
    mask = np.asarray(scene["tgt_masks"][view], bool)
    assert mask.sum() > 50
    truth = scene["tgt_images"][view].transpose(1, 2, 0) * mask[..., None]
    rgb, seen = blend_sources(scene, view, scene["tgt_depth"][view])
    assert seen[mask].mean() > 0.97  # a camera sees its own visible surface
    at_truth = psnr(rgb, truth, mask)
    assert at_truth > 30.0
    # the depth 25 cm off: the source's own pixels no longer pass the visibility check, the other's are wrong
    off, seen_off = blend_sources(scene, view, scene["tgt_depth"][view] + 0.25)
    assert seen_off[mask].mean() < 0.5
    assert psnr(off, truth, mask) < at_truth - 5.0


def test_affine_fill_recovers_a_per_channel_gain_and_offset_inside_the_region_only():
    rng = np.random.default_rng(0)
    rgb = rng.uniform(0, 1, (8, 9, 3))
    gain, offset = np.array([0.5, 1.3, 0.8]), np.array([0.1, -0.2, 0.05])
    truth = rgb * gain + offset
    region = np.zeros((8, 9), bool)
    region[2:6, 1:7] = True
    before = rgb.copy()
    out = affine_fill(rgb, truth, region)
    assert np.allclose(out[region], truth[region], atol=1e-9)
    assert np.array_equal(out[~region], rgb[~region])  # outside the region: untouched
    assert np.array_equal(rgb, before)  # the input is not modified


def test_affine_fill_never_does_worse_than_the_colours_it_corrects():
    rng = np.random.default_rng(1)
    truth = rng.uniform(0, 1, (16, 16, 3))
    rgb = np.clip(truth + rng.normal(0, 0.2, truth.shape), 0, 1)  # no affine relation, just noise
    region = rng.uniform(size=(16, 16)) < 0.5
    err = lambda x: float(((x - truth)[region] ** 2).sum())  # noqa: E731
    assert err(affine_fill(rgb, truth, region)) <= err(rgb) + 1e-12  # identity is among the fits
    one = np.zeros((16, 16), bool)
    one[3, 4] = True
    assert np.array_equal(affine_fill(rgb, truth, one), rgb)  # a single pixel fixes no line: left alone
