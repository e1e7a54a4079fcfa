"""Camera geometry in torch, written for ONNX export and for onnxruntime's CPU kernels.

Conventions (``ghnerf_runtime.contract``): pixel centres at integer coordinates,
all pixels at the model resolution ``H x W``; ``X_cam = R X + t``. Feature maps
at any stride are sampled with ``grid_sample(align_corners=False)`` at the
normalised coordinate ``(2u + 1) / W - 1``, which is resolution independent
under the pixel-centre convention, so one projection serves every stride.

Layout: *planar*. Point sets are ``(3, L)`` (or ``(B, 3, ..., M)``) with the
long axis innermost, never ``(L, 3)``: onnxruntime's broadcasting kernels are
10-15x slower when the innermost axis is 2, 3 or 4 elements long. Camera
products are MatMuls ``(3, 4) @ (4, L)``. No matrix inverse, no boolean indexing.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

#: Grid coordinates are clamped to this magnitude: anything beyond +-1 is already padding.
GRID_CLAMP = 2.0
#: Points with camera depth below this are treated as behind the camera.
MIN_DEPTH = 1e-4


def block_centres(height: int, width: int, stride: int, device=None, dtype=torch.float32) -> Tensor:
    """``(2, h * w)`` model-pixel ``u`` and ``v`` of the centres of ``stride x stride`` blocks, row-major."""
    us = (torch.arange(width // stride, device=device, dtype=dtype) + 0.5) * stride - 0.5
    vs = (torch.arange(height // stride, device=device, dtype=dtype) + 0.5) * stride - 0.5
    v, u = torch.meshgrid(vs, us, indexing="ij")
    return torch.stack([u.reshape(-1), v.reshape(-1)], dim=0)


def ray_directions(K_inv: Tensor, c2w: Tensor, uv: Tensor) -> tuple[Tensor, Tensor]:
    """Rays of target pixels, scaled so that a unit step is a unit of *camera depth*.

    Args:
        K_inv: ``(B, 3, 3)``; c2w: ``(B, 3, 4)`` ``[R^T | centre]``;
        uv: planar pixels ``(B, 2, M)`` or ``(2, M)`` (shared by all targets).

    Returns:
        ``origin`` ``(B, 3, 1)`` and ``direction`` ``(B, 3, M)`` (rig frame); the point at camera depth
        ``z`` is ``origin + z * direction``.
    """
    B = K_inv.shape[0]
    if uv.dim() == 2:
        uv = uv.unsqueeze(0).expand(B, -1, -1)
    uv1 = torch.cat([uv, torch.ones_like(uv[:, :1])], dim=1)  # (B, 3, M)
    rot = torch.matmul(c2w[:, :, :3], K_inv)  # (B, 3, 3) = R^T K^-1
    return c2w[:, :, 3:4], torch.matmul(rot, uv1)


def to_grid(uv: Tensor, height: int, width: int, axis: int) -> Tensor:
    """Model pixels -> ``grid_sample`` coordinates (align_corners=False), clamped to +-GRID_CLAMP.

    ``axis`` is the axis of ``uv`` that holds (u, v) (size 2).
    """
    if height == width:  # one scalar scale: the fast broadcasting path
        s = 2.0 / width
        return (uv * s + (0.5 * s - 1.0)).clamp(-GRID_CLAMP, GRID_CLAMP)
    shape = [1] * uv.dim()
    shape[axis] = 2
    scale = torch.tensor([2.0 / width, 2.0 / height], dtype=uv.dtype, device=uv.device).reshape(shape)
    return (uv * scale + (0.5 * scale - 1.0)).clamp(-GRID_CLAMP, GRID_CLAMP)


def project_planar(P: Tensor, points: Tensor, height: int, width: int) -> tuple[Tensor, Tensor]:
    """Project planar rig points into cameras, as ``grid_sample`` coordinates.

    Args:
        P: ``(S, 3, 4)`` projection matrices (contract resolution); points: ``(3, L)``.

    Returns:
        ``grid`` ``(S, 2, L)`` (planar; points behind a camera get an outside coordinate) and
        ``visible`` ``(S, 1, L)`` (1.0 in front of the camera and inside the image, else 0.0).
    """
    ones = torch.ones_like(points[:1])
    h = torch.matmul(P, torch.cat([points, ones], dim=0))  # (S, 3, L)
    z = h[:, 2:3]
    in_front = (z > MIN_DEPTH).to(points.dtype)
    uv = h[:, :2] / torch.where(z > MIN_DEPTH, z, torch.ones_like(z))
    grid = to_grid(uv, height, width, axis=1)
    grid = grid * in_front + GRID_CLAMP * (1.0 - in_front)
    inside = (grid.abs() <= 1.0).to(points.dtype)
    return grid, inside[:, 0:1] * inside[:, 1:2] * in_front


def planar_to_grid(grid: Tensor, rows: int) -> Tensor:
    """``(S, 2, L)`` planar coordinates -> ``(S, rows, L / rows, 2)`` for ``grid_sample``."""
    S = grid.shape[0]
    return grid.transpose(1, 2).reshape(S, rows, -1, 2)


def grid_sample(maps: Tensor, grid: Tensor, padding: str = "zeros") -> Tensor:
    """Bilinear sample (align_corners=False) of ``maps`` ``(S, C, h, w)`` at ``grid`` ``(S, Ho, Wo, 2)``.

    ``padding="border"`` is computed as zero padding after clamping the grid to the centres of the edge
    pixels, which is the same function but runs ~3x faster in onnxruntime's GridSample.
    Returns channels first, ``(S, C, Ho, Wo)``.
    """
    if padding == "border":
        h, w = maps.shape[-2:]
        if h == w:
            grid = grid.clamp(-1.0 + 1.0 / w, 1.0 - 1.0 / w)
        else:
            lim = torch.tensor([1.0 - 1.0 / w, 1.0 - 1.0 / h], dtype=grid.dtype, device=grid.device)
            grid = torch.minimum(torch.maximum(grid, -lim), lim)
        padding = "zeros"
    return F.grid_sample(maps, grid, mode="bilinear", padding_mode=padding, align_corners=False)


__all__ = ["block_centres", "ray_directions", "to_grid", "project_planar", "planar_to_grid", "grid_sample",
           "GRID_CLAMP", "MIN_DEPTH"]
