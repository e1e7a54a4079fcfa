"""Surface normals of a depth map's points, for renderers and their learnt parts (kornia-style: pure
geometry, no state).

numpy only.
"""
from __future__ import annotations

import numpy as np

__all__ = ["masked_difference", "surface_normals"]


def masked_difference(points: np.ndarray, mask: np.ndarray, axis: int) -> np.ndarray:
    """Central difference of ``points`` ``(H, W, C)`` along image ``axis`` (0: rows, 1: columns),
    one-sided where a neighbour is outside ``mask`` (zero where both are)."""
    fwd = np.zeros_like(points)
    ok = np.zeros(mask.shape, bool)
    lo, hi = [slice(None)] * 2, [slice(None)] * 2
    lo[axis], hi[axis] = slice(None, -1), slice(1, None)
    lo, hi = tuple(lo), tuple(hi)
    fwd[lo] = points[hi] - points[lo]
    ok[lo] = mask[hi] & mask[lo]
    bwd, ok_b = np.zeros_like(points), np.zeros(mask.shape, bool)
    bwd[hi], ok_b[hi] = fwd[lo], ok[lo]
    n = ok.astype(np.float64) + ok_b
    return (fwd * ok[..., None] + bwd * ok_b[..., None]) / np.maximum(n, 1.0)[..., None]


def surface_normals(points: np.ndarray, mask: np.ndarray, center: np.ndarray) -> np.ndarray:
    """Unit normals ``(H, W, 3)`` of the surface through ``points`` ``(H, W, 3)`` (a depth map's pixels
    unprojected) inside ``mask``, facing the camera at ``center`` (same frame as ``points``).

    From the points' image-space differences, one-sided at the silhouette so that an edge pixel's
    normal comes from its own side rather than from the background; a pixel with no neighbour in the
    mask along an axis (a one-pixel sliver) faces the camera. A point without a finite position (a NaN
    or infinite depth) has no surface: its neighbours difference across it as across the silhouette,
    and its own normal is the zero vector, the "no normal" value callers give pixels off the subject
    (NaN arithmetic made it NaN, cast to int8 as garbage, and turned its neighbours to face the camera).
    Outside ``mask`` the values are meaningless (callers zero them)."""
    points = np.asarray(points, np.float64)
    finite = np.isfinite(points).all(axis=-1)
    mask = np.asarray(mask, bool) & finite
    points = np.where(finite[..., None], points, 0.0)  # NaN * 0 is NaN: keep it out of the differences
    n = np.cross(masked_difference(points, mask, 1), masked_difference(points, mask, 0))
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    towards_camera = np.asarray(center, np.float64) - points
    view = towards_camera / np.maximum(np.linalg.norm(towards_camera, axis=-1, keepdims=True), 1e-12)
    n = np.where(length > 1e-12, n / np.maximum(length, 1e-12), view)
    n = np.where(((n * towards_camera).sum(-1) < 0)[..., None], -n, n)
    return np.where(finite[..., None], n, 0.0)
