"""The source-blend ceiling (``training.blend_ceiling``) on a generated scene: geometry and visibility."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

from ghnerf_runtime.metrics import masked_psnr  # noqa: E402
from training.blend_ceiling import blend_sources, project, unproject  # noqa: E402


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
