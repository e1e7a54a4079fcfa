"""What a renderer that blends the two source images can reach at a target view, given a depth map.

GHNeRF's colour (ENeRF's) is a blend of the source cameras' pixels where each sample projects
(``training.model.heads``): it cannot show a surface neither source camera sees. Fed the dataset's
*true* depth and the sources' true visibility, the blend below is that family's ceiling on a view;
fed a model's rendered depth, it separates the model's geometry from its blending. Pure numpy and
OpenCV on one ``MultiViewDataset`` item (numpy arrays); ``benchmarks/measure_novel_ceiling.py`` runs
it over a split.

Pixels: centres at integers (``ghnerf_runtime.contract.ray_grid``); depth is camera z in metres.
"""
from __future__ import annotations

from collections.abc import Mapping

import cv2
import numpy as np

#: A source sees a point when its own depth map there is within this of the point's depth (metres).
VISIBILITY_TOLERANCE_M = 0.03


def unproject(depth: np.ndarray, K_inv: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """World points ``(H, W, 3)`` of a camera-z ``depth`` map ``(H, W)``; ``c2w`` ``(3, 4)``. A NaN or infinite
    depth has no position: its point is NaN (an infinite one times a zero ray or rotation entry warned and gave
    NaN or inf by chance), as the device's painter places it (``novel_painter.painter_planes``)."""
    depth = np.asarray(depth, np.float64)
    H, W = depth.shape
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    rays = np.stack([u, v, np.ones_like(u)], -1) @ np.asarray(K_inv, np.float64).T  # z = 1
    cam = rays * np.where(np.isfinite(depth), depth, np.nan)[..., None]
    c2w = np.asarray(c2w, np.float64)
    return cam @ c2w[:, :3].T + c2w[:, 3]


def project(points: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel ``u``, ``v`` (float32, for ``cv2.remap``) and camera z of world ``points`` ``(..., 3)``."""
    P = np.asarray(P, np.float64)
    q = points @ P[:, :3].T + P[:, 3]
    z = q[..., 2]
    safe = np.where(np.abs(z) > 1e-9, z, 1e-9)
    return (q[..., 0] / safe).astype(np.float32), (q[..., 1] / safe).astype(np.float32), z


def blend_sources(scene: Mapping[str, np.ndarray], view: int, depth: np.ndarray,
                  tolerance_m: float = VISIBILITY_TOLERANCE_M) -> tuple[np.ndarray, np.ndarray]:
    """The sources' colours at ``depth`` seen from target ``view``, averaged over the sources that see them.

    Args:
        scene: one dataset item as numpy (``images`` ``(S, 3, H, W)``, ``src_P``, ``tgt_K_inv``,
            ``tgt_c2w``, ``tgt_depth`` and ``tgt_has_depth`` with the sources first, as the dataset stores them).
        view: the target view's index.
        depth: ``(H, W)`` camera-z depth of the view (the truth, or a model's).

    Returns:
        ``rgb`` ``(H, W, 3)`` and ``seen`` ``(H, W)`` (some source sees the point). Where no source sees
        it, ``rgb`` is the plain average of the sources: what a blend without visibility would give.
    """
    points = unproject(depth, scene["tgt_K_inv"][view], scene["tgt_c2w"][view])
    S = len(scene["images"])
    colours, sees = [], []
    for s in range(S):
        u, v, z = project(points, scene["src_P"][s])
        # a point without a position (NaN) falls outside every source, as on the device (painter_planes)
        u, v = np.nan_to_num(u, nan=-1.0), np.nan_to_num(v, nan=-1.0)
        img = np.ascontiguousarray(scene["images"][s].transpose(1, 2, 0), np.float32)
        colours.append(cv2.remap(img, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT))
        inside = (u >= 0) & (u <= img.shape[1] - 1) & (v >= 0) & (v <= img.shape[0] - 1) & (z > 0)
        if scene["tgt_has_depth"][s]:  # sources come first among the targets
            own = cv2.remap(np.asarray(scene["tgt_depth"][s], np.float32), u, v, cv2.INTER_NEAREST,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
            inside &= np.abs(own - z) < tolerance_m
        sees.append(inside)
    c, w = np.stack(colours), np.stack(sees).astype(np.float32)[..., None]
    n = w.sum(0)
    rgb = np.where(n > 0, (c * w).sum(0) / np.maximum(n, 1.0), c.mean(0))
    return rgb, n[..., 0] > 0


def affine_fill(rgb: np.ndarray, truth: np.ndarray, region: np.ndarray) -> np.ndarray:
    """``rgb`` ``(H, W, 3)`` with the pixels of ``region`` replaced by their best per-channel affine fit
    (least squares) to ``truth``.

    An oracle, since it reads the truth: on the pixels no source sees it bounds what any global colour
    or shading correction of the borrowed colours can reach (``benchmarks/measure_novel_ceiling.py
    --oracles``)."""
    out = rgb.copy()
    if region.sum() < 2:
        return out
    for c in range(rgb.shape[-1]):
        x, y = rgb[..., c][region].astype(np.float64), truth[..., c][region].astype(np.float64)
        A = np.stack([x, np.ones_like(x)], axis=1)
        (gain, offset), *_ = np.linalg.lstsq(A, y, rcond=None)
        out[..., c][region] = gain * x + offset
    return out


__all__ = ["VISIBILITY_TOLERANCE_M", "unproject", "project", "blend_sources", "affine_fill"]
