"""Host-side camera inputs for the model, shared by tests, calibration data and (later) the dataset.

Wraps the torch-free helpers of ``ghnerf_runtime.contract`` so training and the
runtime compute the camera matrices the same way, plus a small synthetic rig
for tests and calibration when no recorded frames are at hand.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ghnerf_runtime import contract as C
from ghnerf_runtime.geometry import Camera, intrinsics_from_fov, look_at

#: A standing subject's box in the rig frame (metres, y down, z forward).
DEFAULT_BOX = np.array([[-0.5, -1.9, 2.6], [0.5, 0.0, 3.4]])


def box_corners(box: np.ndarray = DEFAULT_BOX) -> np.ndarray:
    lo, hi = np.asarray(box, dtype=np.float64)
    idx = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)])
    return np.where(idx == 1, hi, lo)


def synthetic_rig(height: int, width: int, baseline: float = 0.8, hfov_deg: float = 45.0,
                  target=(0.0, -0.95, 3.0), eye_height: float = -1.2) -> list[Camera]:
    """Two cameras ``baseline`` apart at the rig origin, both looking at ``target``."""
    K = intrinsics_from_fov(width, height, hfov_deg)
    cams = []
    for name, x in (("left", -baseline / 2), ("right", baseline / 2)):
        R, t = look_at((x, eye_height, 0.0), target)
        cams.append(Camera(name, width, height, K, R=R, t=t))
    return cams


def orbit_camera(height: int, width: int, angle_deg: float, radius: float = 3.0, hfov_deg: float = 45.0,
                 target=(0.0, -0.95, 3.0), eye_height: float = -1.2, name: str = "novel") -> Camera:
    """A novel camera on a circle of ``radius`` around ``target`` (0 degrees: at the rig)."""
    a = np.radians(angle_deg)
    eye = (target[0] + radius * np.sin(a), eye_height, target[2] - radius * np.cos(a))
    R, t = look_at(eye, target)
    return Camera(name, width, height, intrinsics_from_fov(width, height, hfov_deg), R=R, t=t)


def scene_inputs(sources: Sequence[Camera], targets: Sequence[Camera], corners: np.ndarray,
                 height: int, width: int, margin: float = 0.1) -> dict[str, np.ndarray]:
    """Every camera input of the graphs (contract names), float32 numpy.

    ``src_P`` ``(S,3,4)``, ``src_centers`` ``(S,3)``, ``tgt_K_inv`` ``(B,3,3)``, ``tgt_c2w`` ``(B,3,4)``,
    ``tgt_P`` ``(B,3,4)``, ``near_far`` ``(B,2)`` (from the box ``corners`` grown by ``margin``).
    """
    out = {"src_P": C.source_projections(sources, height, width), "src_centers": C.source_centers(sources)}
    out.update(C.target_inputs(targets, height, width))
    out["tgt_P"] = C.target_projections(targets, height, width)
    out["near_far"] = np.stack([C.near_far_from_box(c, corners, margin) for c in targets])
    return out


def to_torch(arrays: dict[str, np.ndarray]):
    import torch

    return {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in arrays.items()}


__all__ = ["DEFAULT_BOX", "box_corners", "synthetic_rig", "orbit_camera", "scene_inputs", "to_torch"]
