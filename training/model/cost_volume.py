"""Plane-sweep cost volume in the target view's frustum, built from the source views.

For every volume pixel (centre of a ``stride x stride`` block of the target) and
every depth hypothesis, the 3D point ``origin + z * direction`` is projected
into each source, the source features are sampled there, and the cost is the
variance across sources, averaged within ``groups`` channel groups (group-wise
variance keeps the 3D network's input narrow). Depth hypotheses may differ per
pixel (fine levels), so this is a per-pixel warp, not a homography; the camera
matrices come from the host (``ghnerf_runtime.contract``).
"""
from __future__ import annotations

from dataclasses import dataclass

from torch import Tensor

from training.model.config import Config
from training.model.projection import block_centres, grid_sample, planar_to_grid, project_planar, ray_directions


@dataclass
class CostVolumeConfig(Config):
    """Cost volume construction."""

    groups: int = 8
    """Output channels: the per-channel variance is averaged within this many groups."""


def build_cost_volume(
    features: Tensor, src_P: Tensor, K_inv: Tensor, c2w: Tensor, depths: Tensor,
    stride: int, height: int, width: int, groups: int,
) -> Tensor:
    """Group-wise variance cost volume.

    Args:
        features: ``(S, C, Hf, Wf)`` source features (any stride).
        src_P: ``(S, 3, 4)``; K_inv: ``(B, 3, 3)``; c2w: ``(B, 3, 4)`` (target).
        depths: ``(B, D, h, w)`` camera depth of each plane at each volume pixel, ``h = height / stride``.
        groups: ``C`` must be divisible by it.

    Returns:
        ``(B, groups, D, h, w)``.
    """
    S, C = features.shape[:2]
    B, D, h, w = depths.shape
    uv = block_centres(height, width, stride, device=depths.device, dtype=depths.dtype)  # (2, h*w)
    origin, direction = ray_directions(K_inv, c2w, uv)  # (B, 3, 1), (B, 3, hw)
    z = depths.reshape(B, 1, D, h * w)
    points = origin.unsqueeze(3) + z * direction.unsqueeze(2)  # (B, 3, D, hw)
    grid, _ = project_planar(src_P, points.transpose(0, 1).reshape(3, -1), height, width)  # (S, 2, B*D*hw)
    grid = planar_to_grid(grid, B * D * h)  # (S, B*D*h, w, 2)
    if S == 2:  # exact two-view shortcut: onnxruntime reduces slowly over the view axis, and sampling each
        # view on its own avoids splitting the large sampled tensor afterwards
        half = 0.5 * (grid_sample(features[0:1], grid[0:1])[0] - grid_sample(features[1:2], grid[1:2])[0])
        var = half * half  # (C, B*D*h, w)
    else:
        f = grid_sample(features, grid)  # (S, C, B*D*h, w), channels first
        d = f - f.mean(dim=0, keepdim=True)
        var = (d * d).mean(dim=0)
    var = var.reshape(groups, C // groups, B, D, h, w).mean(dim=1)  # (G, B, D, h, w)
    return var.transpose(0, 1)


__all__ = ["CostVolumeConfig", "build_cost_volume"]
