"""Geometric augmentation of training crops (``training.augment``): images, joints and heatmaps move together."""
from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from training.augment import AugmentConfig, augment_views, random_similarity, transform_joints, warp_images  # noqa: E402
from training.evaluate import keypoints_from_heatmaps  # noqa: E402
from training.model.config import ConfigError  # noqa: E402


def _matrix(deg: float, scale: float, shift=(0.0, 0.0), size: int = 64) -> torch.Tensor:
    t = math.radians(deg)
    lin = scale * torch.tensor([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]], dtype=torch.float64)
    c = torch.full((2,), (size - 1) / 2, dtype=torch.float64)
    return torch.cat([lin, (c - lin @ c + torch.tensor(shift, dtype=torch.float64))[:, None]], 1)[None]


def test_a_pure_shift_moves_the_image_by_whole_pixels():
    img = torch.rand(1, 3, 32, 32)
    out = warp_images(img, _matrix(0.0, 1.0, (3.0, -2.0), 32))
    assert torch.allclose(out[0, :, 0:30, 3:], img[0, :, 2:32, :29], atol=1e-5)
    assert float(out[0, :, :, :3].abs().max()) == 0.0  # zeros where the source was outside


def test_a_quarter_turn_rotates_the_pixels_about_the_centre():
    img = torch.rand(1, 1, 16, 16)
    out = warp_images(img, _matrix(90.0, 1.0, size=16))
    # p_out = R p_in about the centre: the input's (x, y) lands on (c - (y - c), c + (x - c)), i.e. a rot90
    assert torch.allclose(out[0, 0], torch.rot90(img[0, 0], k=1, dims=(1, 0)), atol=1e-5)


def test_joints_follow_the_transform_and_leave_the_crop_invisible():
    A = _matrix(30.0, 1.2, (4.0, 1.0))
    j = torch.tensor([[[31.5, 31.5], [10.0, 50.0], [63.0, 0.0]]], dtype=torch.float64)
    moved, vis = transform_joints(j, torch.tensor([[True, True, False]]), A, 64)
    assert torch.allclose(moved[0, 0], torch.tensor([35.5, 32.5], dtype=torch.float64))  # the centre only shifts
    p = j[0, 1] - 31.5
    t = math.radians(30.0)
    want = 1.2 * torch.tensor([math.cos(t) * p[0] - math.sin(t) * p[1], math.sin(t) * p[0] + math.cos(t) * p[1]],
                              dtype=torch.float64) + torch.tensor([35.5, 32.5], dtype=torch.float64)
    assert torch.allclose(moved[0, 1], want)
    assert vis.tolist() == [[True, True, False]]  # a hidden joint stays hidden
    far, vis2 = transform_joints(torch.tensor([[[60.0, 60.0]]]), torch.tensor([[True]]), _matrix(0, 1, (10, 0)), 64)
    assert not vis2.any() and float(far[0, 0, 0]) == pytest.approx(70.0)


def test_augmented_heatmaps_peak_at_the_moved_joints_of_the_moved_image():
    g = torch.Generator().manual_seed(3)
    joints = torch.tensor([[[20.0, 40.0], [44.0, 24.0], [31.5, 31.5]]] * 4)
    visible = torch.ones(4, 3, dtype=torch.bool)
    images = torch.zeros(4, 3, 64, 64)
    for k, (x, y) in enumerate(joints[0].tolist()):  # a bright dot at each joint
        images[:, k, int(round(y)), int(round(x))] = 1.0
    cfg = AugmentConfig(rotation_deg=40.0, scale=0.3, shift=0.1)
    out, heat = augment_views(images, joints, visible, cfg, g, heatmap_stride=4, sigma_hm_px=1.5)
    assert out.shape == images.shape and heat.shape == (4, 3, 16, 16)
    uv = keypoints_from_heatmaps(heat.numpy(), 64)  # decoded, back in crop pixels
    for n in range(4):
        for k in range(3):
            if np.isnan(uv[n, k]).any():
                continue  # moved out of the crop: no heatmap
            dot = np.unravel_index(int(out[n, k].argmax()), (64, 64))[::-1]
            assert np.linalg.norm(uv[n, k] - np.array(dot)) < 1.5, (n, k)
    assert not np.isnan(uv[:, 2]).any()  # the centre joint never leaves the crop


def test_the_draws_are_a_function_of_the_generator_and_cover_the_ranges():
    cfg = AugmentConfig(rotation_deg=30.0, scale=0.25, shift=0.1)
    a = random_similarity(2000, 128, cfg, torch.Generator().manual_seed(0))
    b = random_similarity(2000, 128, cfg, torch.Generator().manual_seed(0))
    assert torch.equal(a, b)
    s = torch.sqrt(torch.linalg.det(a[:, :, :2]))
    deg = torch.rad2deg(torch.atan2(a[:, 1, 0], a[:, 0, 0]))
    assert float(s.min()) >= 1 / 1.25 - 1e-9 and float(s.max()) <= 1.25 + 1e-9
    assert float(deg.abs().max()) <= 30.0 + 1e-9 and float(deg.abs().max()) > 25.0
    assert torch.equal(random_similarity(3, 64, AugmentConfig(), torch.Generator())[:, :, :2],
                       torch.eye(2, dtype=torch.float64).expand(3, 2, 2))


@pytest.mark.parametrize("key, value", [("rotation_deg", -1.0), ("scale", 2.0), ("shift", float("nan"))])
def test_bad_ranges_name_the_key(key, value):
    with pytest.raises(ConfigError, match=f"augment.{key}"):
        AugmentConfig(**{key: value}).validate()
