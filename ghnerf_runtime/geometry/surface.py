"""Surface normals of a depth map's points, for renderers and their learnt parts (kornia-style: pure
geometry, no state).

numpy only.
"""
from __future__ import annotations

import numpy as np

from ghnerf_runtime.errors import ShapeError

__all__ = ["masked_difference", "surface_mask", "surface_normals"]


def surface_mask(depth: np.ndarray, subject: np.ndarray | None = None) -> np.ndarray:
    """``(H, W)`` bool: where a depth map shows a surface, the learnt painter's subject mask: inside
    ``subject`` (the geometry's silhouette; default every pixel) with a positive depth.

    A NaN depth (nothing known there) is no surface, so off the mask; +inf is on (a wild surface far
    off: the painter's depth plane holds it at float16's largest, :func:`surface_normals` gives it no
    normal). The one rule the device's painter (``novel_painter.painter_planes``) and the training
    caches (``training.fill_features``) both call: the device's ``depth > 0`` left a NaN pixel off,
    while the caches took the geometry's mask as it was and kept it on, so the network trained on a
    mask plane the device never builds there.

    Raises:
        ShapeError: ``subject`` is not ``depth``'s shape.
    """
    depth = np.asarray(depth, np.float64)
    on = depth > 0  # NaN compares false: off
    if subject is None:
        return on
    subject = np.asarray(subject, bool)
    if subject.shape != depth.shape:
        raise ShapeError(f"subject mask {subject.shape} must be the depth map's shape {depth.shape}")
    return subject & on


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
