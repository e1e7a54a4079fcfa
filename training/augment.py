"""Random similarity transforms (rotation, scale, shift) of training crops, their 2D joints and heatmaps.

The human encoder's pretraining sees each stored crop as the dataset framed it. Rotating, scaling and
shifting the crop shows it poses and framings the dataset does not hold (a raised arm at another angle,
a subject nearer the crop's edge), the standard remedy when a 2D pose model fits its training poses
better than unseen ones. The image is resampled (bilinear, zeros outside); the joints are moved by the
same transform and the heatmaps are drawn again from them (so they stay Gaussians of the documented
sigma, which warping the stored heatmaps would not give under scaling). A joint moved out of the crop
becomes invisible, as the dataset marks one that is outside.

Pixel convention: crop pixels with centres at integers (``ghnerf_runtime.contract.ray_grid``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor

from training.model.config import Config, ConfigError


@dataclass
class AugmentConfig(Config):
    """Ranges of the random transform, drawn per image (all 0: no augmentation)."""

    rotation_deg: float = 0.0
    """Rotation about the crop centre, uniform in ``[-rotation_deg, rotation_deg]``."""
    scale: float = 0.0
    """Zoom factor, log-uniform in ``[1 / (1 + scale), 1 + scale]``."""
    shift: float = 0.0
    """Translation per axis, uniform in ``[-shift, shift]`` times the crop side."""

    def validate(self, path: str = "augment") -> None:
        for key, hi in (("rotation_deg", 180.0), ("scale", 1.0), ("shift", 0.5)):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0.0 <= v <= hi):
                raise ConfigError(f"{path}.{key}: must be a number in [0, {hi:g}], got {v!r}")

    @property
    def enabled(self) -> bool:
        return bool(self.rotation_deg or self.scale or self.shift)


def random_similarity(n: int, size: int, config: AugmentConfig, generator: torch.Generator) -> Tensor:
    """``(n, 2, 3)`` forward transforms in crop pixels: ``p_out = A[:, :2] @ p_in + A[:, 2]``."""
    u = torch.rand(n, 4, generator=generator, dtype=torch.float64) * 2 - 1  # uniform in [-1, 1]
    theta = torch.deg2rad(u[:, 0] * config.rotation_deg)
    s = torch.exp(u[:, 1] * math.log1p(config.scale))
    shift = u[:, 2:] * config.shift * size
    c, si = torch.cos(theta) * s, torch.sin(theta) * s
    lin = torch.stack([torch.stack([c, -si], -1), torch.stack([si, c], -1)], -2)  # (n, 2, 2)
    centre = torch.full((n, 2), (size - 1) / 2.0, dtype=torch.float64)
    offset = centre - (lin @ centre[..., None])[..., 0] + shift
    return torch.cat([lin, offset[..., None]], -1)


def warp_images(images: Tensor, transforms: Tensor) -> Tensor:
    """``images`` ``(N, C, H, W)`` resampled so that input pixel ``p`` lands on ``A p`` (bilinear, zeros outside)."""
    N, _, H, W = images.shape
    A = transforms.to(torch.float64)
    inv_lin = torch.linalg.inv(A[:, :, :2])
    inv_off = -(inv_lin @ A[:, :, 2:])[..., 0]
    ys, xs = torch.meshgrid(torch.arange(H, dtype=torch.float64), torch.arange(W, dtype=torch.float64), indexing="ij")
    out_px = torch.stack([xs, ys], -1).reshape(1, -1, 2)  # (1, HW, 2) output pixel centres
    src = out_px @ inv_lin.transpose(1, 2) + inv_off[:, None, :]  # (N, HW, 2) where each output pixel reads
    norm = torch.stack([(src[..., 0] + 0.5) / W * 2 - 1, (src[..., 1] + 0.5) / H * 2 - 1], -1)
    grid = norm.reshape(N, H, W, 2).to(images.dtype)
    return F.grid_sample(images, grid, mode="bilinear", padding_mode="zeros", align_corners=False)


def transform_joints(joints_2d: Tensor, visible: Tensor, transforms: Tensor, size: int) -> tuple[Tensor, Tensor]:
    """Joints ``(N, J, 2)`` moved by ``transforms``; visible only while inside the ``size`` crop."""
    A = transforms.to(torch.float64)
    moved = joints_2d.to(torch.float64) @ A[:, :, :2].transpose(1, 2) + A[:, None, :, 2]
    inside = ((moved >= -0.5) & (moved <= size - 0.5)).all(-1)
    return moved.to(joints_2d.dtype), visible & inside & torch.isfinite(moved).all(-1)


def augment_views(images: Tensor, joints_2d: Tensor, visible: Tensor, config: AugmentConfig,
                  generator: torch.Generator, heatmap_stride: int, sigma_hm_px: float) -> tuple[Tensor, Tensor]:
    """Randomly transformed ``images`` ``(N, 3, S, S)`` and heatmap grids ``(N, J, S / stride, S / stride)``
    drawn from the transformed joints (Gaussian, ``sigma_hm_px`` heatmap pixels, zero when not visible)."""
    from ghnerf_runtime.contract import ray_grid
    from training.train import heatmaps_at

    N, _, S, _ = images.shape
    A = random_similarity(N, S, config, generator)
    joints, vis = transform_joints(joints_2d, visible, A, S)
    uv = torch.from_numpy(ray_grid(S, S, heatmap_stride)).to(images.dtype)
    h = S // heatmap_stride
    heat = heatmaps_at(joints.to(images.dtype), vis, uv[None].expand(N, -1, -1), sigma_hm_px * heatmap_stride)
    return warp_images(images, A), heat.transpose(1, 2).reshape(N, -1, h, h)


__all__ = ["AugmentConfig", "random_similarity", "warp_images", "transform_joints", "augment_views"]
