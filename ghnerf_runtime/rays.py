"""Which rays to render: rectangular blocks of the ray grid covering the subject.

The render graphs take any ``ray_uv`` subset (``contract.ray_grid`` gives the full grid of
``stride x stride`` block centres). Rendering only the block that covers the projected
subject box cuts the render cost in proportion to the rays (docs/runtime.md measures it);
rays outside are what the model renders for empty space: heatmap 0, background colour.

A block is ``(row0, col0, rows, cols)`` on a grid of ``grid_h x grid_w`` cells, cell ``(i, j)``
being the ray through model pixel ``((j + 0.5) * stride - 0.5, (i + 0.5) * stride - 0.5)``.
Pure numpy.
"""
from __future__ import annotations

import numpy as np

from ghnerf_runtime.errors import ShapeError
from ghnerf_runtime.geometry.camera import Camera

__all__ = ["Block", "full_block", "box_block", "common_blocks", "block_ray_uv", "scatter_block", "refine_cells",
           "cells_ray_uv", "scatter_cells"]

Block = tuple[int, int, int, int]


def full_block(grid_h: int, grid_w: int) -> Block:
    return (0, 0, int(grid_h), int(grid_w))


def _box_corners(box: np.ndarray) -> np.ndarray:
    lo, hi = np.asarray(box, dtype=np.float64)
    bits = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)])
    return np.where(bits == 1, hi, lo)


def box_block(camera: Camera, box: np.ndarray, stride: int, margin_cells: int = 0) -> Block | None:
    """The grid block covering a rig box in a pinhole ``camera`` whose image is the model input.

    Returns ``None`` when the box is entirely behind the camera or outside its image; the full
    grid when a corner is behind the camera or projects past float64's range (the projection is unbounded).

    Raises:
        ShapeError: ``box`` is not a finite ``(2, 3)`` array.
    """
    box = np.asarray(box, dtype=np.float64)
    if box.shape != (2, 3) or not np.isfinite(box).all():  # NaN reached int(np.floor(nan)): a bare ValueError
        raise ShapeError(f"box must be a finite (2, 3) array (min and max corners), got shape {box.shape}: "
                         f"{box.tolist()}")
    gh, gw = camera.height // stride, camera.width // stride
    corners = _box_corners(box)
    z = camera.to_camera(corners)[:, 2]
    if np.all(z <= 1e-6):
        return None
    if np.any(z <= 1e-6):
        return full_block(gh, gw)
    uv, _ = camera.project(corners, distort=False)
    if not np.isfinite(uv).all():  # in front, but past float64's pixels (1e307 m aside at 1e-5 m): int(nan) raised
        return full_block(gh, gw)
    lo = (uv.min(axis=0) + 0.5) / stride - 0.5  # model pixels -> grid cells (pixel-centre rule)
    hi = (uv.max(axis=0) + 0.5) / stride - 0.5
    c0, r0 = (int(np.floor(v)) - margin_cells for v in lo)
    c1, r1 = (int(np.ceil(v)) + margin_cells for v in hi)
    c0, r0, c1, r1 = max(c0, 0), max(r0, 0), min(c1, gw - 1), min(r1, gh - 1)
    if c1 < c0 or r1 < r0:
        return None
    return (r0, c0, r1 - r0 + 1, c1 - c0 + 1)


def common_blocks(blocks: list[Block | None], grid_h: int, grid_w: int, align: int = 1) -> list[Block]:
    """Blocks of one common size (the graphs take ``(B, R, 2)``: every target the same ``R``).

    The size is the largest of the blocks (a missing block counts as the full grid), rounded up
    to a multiple of ``align`` and clipped to the grid; each block keeps its centre, shifted
    back inside the grid where needed.
    """
    real = [b if b is not None else full_block(grid_h, grid_w) for b in blocks]
    rows = min(-(-max(b[2] for b in real) // align) * align, grid_h)
    cols = min(-(-max(b[3] for b in real) // align) * align, grid_w)
    out = []
    for r0, c0, rh, cw in real:
        nr0 = int(np.clip(r0 + (rh - rows) // 2, 0, grid_h - rows))
        nc0 = int(np.clip(c0 + (cw - cols) // 2, 0, grid_w - cols))
        out.append((nr0, nc0, rows, cols))
    return out


def block_ray_uv(block: Block, stride: int) -> np.ndarray:
    """``(rows * cols, 2)`` float32 model-pixel ray positions of a block, row-major."""
    r0, c0, rows, cols = block
    us = (np.arange(c0, c0 + cols) + 0.5) * stride - 0.5
    vs = (np.arange(r0, r0 + rows) + 0.5) * stride - 0.5
    u, v = np.meshgrid(us, vs)
    return np.stack([u.ravel(), v.ravel()], axis=-1).astype(np.float32)


def scatter_block(values: np.ndarray, block: Block, grid_h: int, grid_w: int, fill: float = 0.0) -> np.ndarray:
    """Rendered ``(R, *C)`` values of a block -> a ``(grid_h, grid_w, *C)`` grid (``fill`` elsewhere)."""
    r0, c0, rows, cols = block
    values = np.asarray(values)
    if values.shape[0] != rows * cols:
        raise ShapeError(f"values have {values.shape[0]} rays, the block {block} has {rows * cols}")
    out = np.full((grid_h, grid_w) + values.shape[1:], fill, dtype=values.dtype)
    out[r0:r0 + rows, c0:c0 + cols] = values.reshape((rows, cols) + values.shape[1:])
    return out


def refine_cells(coarse: np.ndarray, factor: int) -> np.ndarray:
    """A ``(h, w)`` boolean cell mask -> the ``(h * factor, w * factor)`` mask of the cells inside them."""
    m = np.asarray(coarse, dtype=bool)
    return np.repeat(np.repeat(m, factor, axis=0), factor, axis=1)


def cells_ray_uv(mask: np.ndarray, stride: int) -> np.ndarray:
    """``(n, 2)`` float32 model-pixel ray positions of the ``True`` cells of a grid mask, row-major."""
    rows, cols = np.nonzero(np.asarray(mask, dtype=bool))
    return np.stack([(cols + 0.5) * stride - 0.5, (rows + 0.5) * stride - 0.5], axis=-1).astype(np.float32)


def scatter_cells(values: np.ndarray, mask: np.ndarray, fill: float = 0.0) -> np.ndarray:
    """Rendered ``(n, *C)`` values of the ``True`` cells of a ``(gh, gw)`` mask -> a ``(gh, gw, *C)`` grid."""
    mask = np.asarray(mask, dtype=bool)
    values = np.asarray(values)
    if values.shape[0] != int(mask.sum()):
        raise ShapeError(f"values have {values.shape[0]} rays, the mask has {int(mask.sum())} cells")
    out = np.full(mask.shape + values.shape[1:], fill, dtype=values.dtype)
    out[mask] = values
    return out
