"""Flip test: 2D joint heatmaps averaged over an image and its mirror image.

The human encoder was trained on mirrored images too (``encoder_flip`` / pretraining ``flip``), so
its heatmaps of a mirrored crop are a second, partly independent estimate: mirrored back (width
reversed, left and right joints swapped) and averaged with the first, they cancel part of each
other's error, for a second run of the human encoder (the held-out gain, measured per model, is in
docs/runtime.md, "Flip test", and its settings table). Pure numpy.
"""
from __future__ import annotations

import numpy as np

from ghnerf_runtime.body25 import FLIP_INDEX
from ghnerf_runtime.errors import ShapeError


def mirror_images(images: np.ndarray) -> np.ndarray:
    """``(..., H, W)`` images (channels first) mirrored left to right, contiguous."""
    return np.ascontiguousarray(images[..., ::-1])


def mirror_projections(src_P: np.ndarray, width: int) -> np.ndarray:
    """``(S, 3, 4)`` projection matrices of the mirrored images: pixel column ``u`` -> ``width - 1 - u``.

    The cameras that would have taken the mirrored crops (a left-handed frame: ``det`` of the 3x3 part
    changes sign). The human encoder reads images only; the estimator passes these with the mirrored
    images so that a graph which does read the cameras sees a consistent input.
    """
    m = np.array([[-1.0, 0.0, width - 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    return (m @ np.asarray(src_P, np.float64)).astype(np.asarray(src_P).dtype)


def unmirror_heatmaps(heatmaps: np.ndarray) -> np.ndarray:
    """``(S, J, h, w)`` heatmaps of mirrored images, back in the original images' frame.

    Exact when the heatmap stride divides the image width: cell ``x`` of a mirrored image covers the
    pixels of cell ``w - 1 - x`` of the original. A left joint of the mirror image is the right joint.
    """
    heatmaps = np.asarray(heatmaps)
    if heatmaps.ndim != 4 or heatmaps.shape[1] != len(FLIP_INDEX):
        raise ShapeError(f"heatmaps: expected (S, {len(FLIP_INDEX)}, h, w), got {heatmaps.shape}")
    return np.ascontiguousarray(heatmaps[:, list(FLIP_INDEX), :, ::-1])


def flip_averaged(heatmaps: np.ndarray, mirrored: np.ndarray) -> np.ndarray:
    """The mean of ``heatmaps`` and ``mirrored`` (the heatmaps of the mirrored images), in float32."""
    heatmaps, mirrored = np.asarray(heatmaps, np.float32), np.asarray(mirrored, np.float32)
    if heatmaps.shape != mirrored.shape:
        raise ShapeError(f"heatmaps {heatmaps.shape} and mirrored {mirrored.shape} differ in shape")
    # Halved before the sum: two out-of-contract values past half float32's range (1.7e38) summed to inf, and
    # the decoder drops a joint with an inf where it scales any other map past 1 back to its peak.
    return 0.5 * heatmaps + 0.5 * unmirror_heatmaps(mirrored)


def presence_peak(heatmaps: np.ndarray, views, rank: int) -> float:
    """The ``rank``-th strongest joint's peak value in ``views`` of ``(S, J, h, w)`` heatmaps: per joint the
    geometric mean over those views of its heatmap maxima (clipped to [0, 1]); a map holding any non-finite value
    has no peak (a maximum of 0), as :func:`~ghnerf_runtime.keypoints.decode_keypoints` drops that joint; 0 with
    fewer joints.

    What the estimator compares with ``heatmaps.flip_test_skip_below`` before the flip test's second run: a
    pair where fewer than ``presence.min_joints`` joints reach it shows nobody.

    Example:
        >>> h = np.zeros((2, 3, 4, 4), np.float32)
        >>> h[0, :, 1, 1], h[1, :, 2, 2] = [0.9, 0.4, 0.1], [0.4, 0.9, 0.0]
        >>> round(presence_peak(h, (0, 1), 2), 3), round(presence_peak(h, (0,), 2), 3)
        (0.6, 0.4)
    """
    heat = np.asarray(heatmaps)
    if heat.ndim != 4 or min(heat.shape[2:]) < 1 or rank < 1 or len(views) < 1:  # else numpy's bare errors
        raise ShapeError(f"heatmaps: expected (S, J, h, w) with h, w >= 1, rank >= 1 and at least one view, got "
                         f"{heat.shape}, rank {rank} and views {tuple(views)}")
    return ranked_peak(joint_peaks(heat[list(views)]), range(len(views)), rank)


def joint_peaks(heatmaps: np.ndarray) -> np.ndarray:
    """``(S, J)`` float64: each view's maximum of each joint's map in ``(S, J, h, w)`` heatmaps, 0 for a map holding
    any non-finite value (:func:`presence_peak`'s peaks, before the views are combined). Taken once, they answer
    :func:`ranked_peak` for any of the views, which :func:`presence_peak` took the maxima again for each time."""
    heat = np.asarray(heatmaps)
    maps = heat.reshape(heat.shape[0], heat.shape[1], -1)
    # nan_to_num made an inf map a full-strength peak, a joint the decoder reports missing
    return np.where(np.isfinite(maps).all(-1), maps.max(-1), 0.0).astype(np.float64)


def ranked_peak(peaks: np.ndarray, views, rank: int) -> float:
    """:func:`presence_peak` from the views' :func:`joint_peaks` ``peaks`` ``(S, J)``: the ``rank``-th strongest of
    the per-joint geometric means over ``views`` of their peaks (clipped to [0, 1]); 0 with fewer joints.

    Example:
        >>> peaks = np.array([[0.9, 0.4, 0.1], [0.4, 0.9, 0.0]])
        >>> round(ranked_peak(peaks, (0, 1), 2), 3), round(ranked_peak(peaks, (0,), 2), 3)
        (0.6, 0.4)
    """
    if rank < 1 or len(views) < 1:
        raise ShapeError(f"ranked_peak needs rank >= 1 and at least one view, got rank {rank} and views {tuple(views)}")
    joint = np.exp(np.log(np.clip(np.asarray(peaks)[list(views)], 1e-30, 1.0)).mean(0))
    return float(np.sort(joint)[::-1][rank - 1]) if len(joint) >= rank else 0.0
