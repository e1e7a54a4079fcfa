"""Render one crop view of the simulated scene, supersampled and box-filtered to the model resolution.

The simulator casts one ray per pixel (no anti-aliasing). The runtime's preprocess
area-averages a large image ROI down to the model input, so edges reach the model
smoothed. To match, a view is rendered **directly at the crop camera** at
``supersample x`` the resolution and reduced with ``cv2.INTER_AREA`` (an exact box
filter for integer factors). Ground truth is reduced consistently:

* ``mask``: coverage of the ``f x f`` block (``f = supersample``) ``>= 0.5``;
* ``depth``: mean depth of the block's foreground subpixels where ``mask``, else 0, so
  ``mask == (depth > 0)`` exactly;
* ``joints_2d``: the rig-frame joints projected by the ``S x S`` crop camera (exact, not
  a rescale of the supersampled truth); ``visible`` is the simulator's visibility at the
  supersampled resolution (inside the crop, in front, not occluded by the body).

Sensor noise is added by the simulator at the supersampled resolution, so the box filter
lowers its standard deviation by ``supersample`` (the runtime's area reduction of a ROI
2-4x larger than the input does likewise).
"""
from __future__ import annotations

import cv2
import numpy as np

from drivers.sim import SimScene
from ghnerf_runtime.geometry import Camera
from ghnerf_runtime.preprocess import Roi, crop_camera
from training.data.sample import ViewData


def block_mean(image: np.ndarray, factor: int) -> np.ndarray:
    """Mean over non-overlapping ``factor x factor`` blocks of an ``(H, W)`` array (float64)."""
    h, w = image.shape[:2]
    return image.reshape(h // factor, factor, w // factor, factor).mean(axis=(1, 3))


def render_view(scene: SimScene, camera: Camera, roi: Roi, t: float, joints_3d: np.ndarray, *, resolution: int,
                supersample: int, roi_from_volume: bool) -> ViewData:
    """Render the crop of ``camera`` given by ``roi`` at scene time ``t`` (see module docstring).

    Args:
        scene: the simulated scene.
        camera: the full camera (its name seeds the sensor noise).
        roi: crop window in the full camera's undistorted pixels.
        joints_3d: ``(25, 3)`` the scene's joints at ``t`` (rig frame).
        resolution: output side ``S``; supersample: render factor ``f``.
        roi_from_volume: recorded in the view (cold-start ROI or not).
    """
    f = int(supersample)
    crop = crop_camera(camera, roi, resolution)
    hi_image, truth = scene.render(crop_camera(camera, roi, resolution * f), t, with_truth=True)
    assert truth is not None
    image = hi_image if f == 1 else cv2.resize(hi_image, (resolution, resolution), interpolation=cv2.INTER_AREA)
    image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)

    fg = truth.mask
    coverage = block_mean(fg.astype(np.float64), f)
    mask = coverage >= 0.5
    depth_sum = block_mean(np.where(fg, truth.depth, 0.0).astype(np.float64), f)
    depth = np.where(mask, depth_sum / np.maximum(coverage, 1e-12), 0.0).astype(np.float16)

    uv, z = crop.project(joints_3d)
    in_front = np.all(np.isfinite(uv), axis=-1) & (z > 0)
    joints_2d = np.where(in_front[:, None], uv, 0.0).astype(np.float32)
    visible = np.asarray(truth.visible, dtype=bool) & in_front
    return ViewData(
        name=camera.name, image=np.ascontiguousarray(image), mask=mask, depth=depth, has_depth=True,
        joints_2d=joints_2d, visible=visible, K=crop.K.copy(), R=crop.R.copy(), t=crop.t.copy(), roi=roi,
        roi_from_volume=bool(roi_from_volume), full_K=camera.K.copy(), full_size=camera.size,
    )


__all__ = ["block_mean", "render_view"]
