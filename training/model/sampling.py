"""Depth hypotheses, depth distributions and depth-guided ray samples (coarse-to-fine).

Level 0 sweeps planes uniform in inverse depth between the subject box's near
and far; every later level sweeps planes uniform in depth inside
``[mean - k std, mean + k std]`` of the previous level (clamped to near/far),
and rays are sampled inside the same interval of the level being rendered.
Volumes are read back along rays with *tent* (linear) weights over the plane
axis: a ray's volume column is fetched once by a 4D ``grid_sample`` and every
sample on the ray interpolates it with a small MatMul, which is exactly
trilinear sampling (align_corners=False) without 5D GridSample.
"""
from __future__ import annotations

import torch
from torch import Tensor

#: Floor of the plane/sample interval (metres), so a confident level never collapses it.
DEFAULT_MIN_RANGE = 0.02
_EPS = 1e-6


def inverse_depth_planes(near_far: Tensor, planes: int, h: int, w: int) -> Tensor:
    """``(B, D, h, w)`` depths uniform in ``1/z`` from near (plane 0) to far (plane D-1)."""
    t = torch.linspace(0.0, 1.0, planes, device=near_far.device, dtype=near_far.dtype)
    inv_near, inv_far = 1.0 / near_far[:, 0:1], 1.0 / near_far[:, 1:2]  # (B, 1)
    inv = inv_near + (inv_far - inv_near) * t  # (B, D)
    return (1.0 / inv)[:, :, None, None].expand(-1, -1, h, w)


def linear_planes(lo: Tensor, hi: Tensor, planes: int) -> Tensor:
    """``(B, D, h, w)`` depths uniform from ``lo`` to ``hi`` (each ``(B, 1, h, w)``)."""
    t = torch.linspace(0.0, 1.0, planes, device=lo.device, dtype=lo.dtype).view(1, planes, 1, 1)
    return lo + (hi - lo) * t


def depth_distribution(logits: Tensor, depths: Tensor) -> tuple[Tensor, Tensor]:
    """Softmax over planes -> per-pixel depth mean and standard deviation, each ``(B, 1, h, w)``."""
    prob = torch.softmax(logits, dim=1)
    mean = (prob * depths).sum(dim=1, keepdim=True)
    var = (prob * (depths - mean) ** 2).sum(dim=1, keepdim=True)
    return mean, torch.sqrt(var + _EPS)


def refine_interval(mean: Tensor, std: Tensor, near: Tensor, far: Tensor, scale: float,
                    min_range: float = DEFAULT_MIN_RANGE) -> tuple[Tensor, Tensor]:
    """``[mean - scale std, mean + scale std]`` widened to ``min_range`` and clamped into ``[near, far]``.

    All tensors broadcast; ``near``/``far`` may be maps or ``(B, 1, 1, 1)``.
    """
    half = torch.clamp(std * scale, min=0.5 * min_range)
    lo = torch.maximum(mean - half, near)
    hi = torch.minimum(mean + half, far)
    # Keep hi - lo >= min_range even when the interval hits near or far.
    hi = torch.maximum(hi, torch.minimum(lo + min_range, far))
    lo = torch.minimum(lo, hi - min_range)
    return lo, hi


def ray_depths(lo: Tensor, hi: Tensor, samples: int, perturb: bool) -> Tensor:
    """``samples`` depths per ray in ``[lo, hi]`` (each ``(B, 1, M)``) -> ``(B, samples, M)``, sorted.

    Bin centres, or one uniform draw per bin when ``perturb`` (training).
    """
    t = ((torch.arange(samples, device=lo.device, dtype=lo.dtype) + 0.5) / samples).reshape(1, samples, 1)
    if perturb:
        B, _, M = lo.shape
        t = t + (torch.rand(B, samples, M, device=lo.device, dtype=lo.dtype) - 0.5) / samples
    return lo + (hi - lo) * t


def plane_index(z: Tensor, lo: Tensor, hi: Tensor, planes: int, spacing: str) -> Tensor:
    """Fractional plane index of depth ``z`` in a volume whose planes span ``[lo, hi]``."""
    if spacing == "inverse":
        inv_lo = 1.0 / lo
        t = (1.0 / torch.clamp(z, min=1e-3) - inv_lo) / (1.0 / hi - inv_lo)
    else:
        t = (z - lo) / (hi - lo)
    return t * (planes - 1)


def tent_weights(index: Tensor, planes: int) -> Tensor:
    """``(B, N, M)`` fractional indices -> ``(B, N, planes, M)`` linear-interpolation weights (zero outside)."""
    d = torch.arange(planes, device=index.device, dtype=index.dtype).reshape(1, 1, planes, 1)
    return torch.relu(1.0 - (index.unsqueeze(2) - d).abs())


def interpolate_planes(column: Tensor, index: Tensor) -> Tensor:
    """Linear interpolation over planes: ``column`` ``(B, C, D, M)``, ``index`` ``(B, N, M)`` -> ``(B, C, N, M)``.

    Linear in the index with zero beyond the end planes, exactly like ``grid_sample`` with zero padding in depth:
    a plane's own value at its index, half of the end plane's at ``-0.5`` and ``D - 0.5``, fading to zero at
    ``-1`` and ``D`` and zero beyond (not zero outside ``[-0.5, D - 0.5]``).
    """
    tent = tent_weights(index, column.shape[2])  # (B, N, D, M)
    return (column.unsqueeze(2) * tent.unsqueeze(1)).sum(dim=3)


__all__ = ["inverse_depth_planes", "linear_planes", "depth_distribution", "refine_interval", "ray_depths",
           "plane_index", "tent_weights", "interpolate_planes", "DEFAULT_MIN_RANGE"]
