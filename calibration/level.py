"""Put an imported rig in the project's rig frame: gravity down, the floor at y = 0.

Calibration tools (OpenCV's stereo_calib, anipose) express their cameras in a frame of their own,
usually the first camera's or the board's. The runtime reads the rig frame as x right, y down
(gravity), z forward, origin on the floor below the midpoint of the stereo pair (docs/rig-file.md):
the skeleton prior, the upright crops and the working volume all rely on it. What a calibration
cannot know, the user says: how high the reference camera hangs above the floor and how it is
tilted (pitch from an inclinometer or a phone's level app, roll as ``depthai://``'s ``mount_roll``).
"""
from __future__ import annotations

import math

import numpy as np

from ghnerf_runtime.errors import GeometryError
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.rig import Rig, WorkingVolume

__all__ = ["LEVEL_VOLUME", "down_in_camera", "level_rig"]

#: Where a person can stand in front of a levelled rig (rig frame, metres), as for a level OAK.
LEVEL_VOLUME = WorkingVolume(np.array([-1.5, -2.3, 0.5]), np.array([1.5, 0.1, 5.0]))


def down_in_camera(pitch_deg: float = 0.0, roll_deg: float = 0.0) -> np.ndarray:
    """Gravity's direction in a camera's frame (x right, y down, z along the optical axis).

    ``pitch_deg``: the optical axis below the horizon (positive looks down). ``roll_deg``: the camera
    turned about its optical axis, counterclockwise as seen from behind it (180: upside down).

    Raises:
        GeometryError: an angle that is not a finite number (a NaN gave a NaN direction, silently).
    """
    for what, value in (("pitch_deg", pitch_deg), ("roll_deg", roll_deg)):
        if not _is_number(value):
            raise GeometryError(f"{what} must be a finite number of degrees, got {value!r}")
    p, r = math.radians(pitch_deg), math.radians(roll_deg)
    level = np.array([0.0, math.cos(p), math.sin(p)])  # a camera looking down sees gravity partly ahead
    roll = np.array([[math.cos(r), -math.sin(r), 0.0], [math.sin(r), math.cos(r), 0.0], [0.0, 0.0, 1.0]])
    return roll @ level


def _is_number(value) -> bool:
    return (not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
            and math.isfinite(value))


def level_rig(rig: Rig, *, camera_height_m: float, pitch_deg: float = 0.0, roll_deg: float = 0.0,
              reference: int = 0, volume: WorkingVolume | None = None) -> Rig:
    """``rig`` re-expressed in a level rig frame.

    The frame: y along gravity (given for the ``reference`` camera by ``pitch_deg`` and ``roll_deg``),
    z the horizontal bisector of the stereo pair's optical axes, x = y cross z (right), origin on the
    floor, ``camera_height_m`` below the reference camera, under the midpoint of the pair's centres.
    The cameras' relative poses and intrinsics are kept exactly.

    Args:
        volume: the working volume in the new frame; default :data:`LEVEL_VOLUME`.

    Raises:
        GeometryError: a height that is not positive and finite, an angle that is not finite, a
            ``reference`` that is not a camera's index, or a pair looking straight along gravity.
    """
    if not (_is_number(camera_height_m) and camera_height_m > 0):
        raise GeometryError(f"camera_height_m must be a positive number of metres, got {camera_height_m!r}")
    # an infinite angle raised a bare ValueError from math.cos, a NaN one a GeometryError about R
    for what, value in (("pitch_deg", pitch_deg), ("roll_deg", roll_deg)):
        if not _is_number(value):
            raise GeometryError(f"{what} must be a finite number of degrees, got {value!r}")
    if isinstance(reference, bool) or not isinstance(reference, (int, np.integer)) \
            or not 0 <= reference < len(rig.cameras):
        raise GeometryError(f"reference must be the index of one of the rig's {len(rig.cameras)} cameras, "
                            f"got {reference!r}")
    ref = rig.cameras[reference]
    down = down_in_camera(pitch_deg, roll_deg)
    # everything below in the reference camera's frame
    to_ref = [ref.R @ cam.R.T for cam in rig.pair]  # camera i's axes -> the reference's
    axes = [m[:, 2] for m in to_ref]
    forward = axes[0] + axes[1]
    forward = forward - (forward @ down) * down
    if np.linalg.norm(forward) < 1e-6:
        raise GeometryError("the stereo pair looks straight along gravity: no horizontal forward direction")
    z = forward / np.linalg.norm(forward)
    x = np.cross(down, z)
    M = np.stack([x, down, z], axis=1)  # the new frame's axes in the reference camera's frame
    centres = [ref.R @ cam.center + ref.t for cam in rig.pair]
    mid = 0.5 * (centres[0] + centres[1])
    origin = mid + (camera_height_m - mid @ down) * down  # on the floor below the pair's midpoint
    cams = []
    for cam in rig.cameras:
        rel = cam.R @ ref.R.T  # the reference camera's frame -> this camera's
        R = rel @ M
        t = rel @ (origin - ref.t) + cam.t
        cams.append(Camera(cam.name, cam.width, cam.height, cam.K, cam.dist, R, t))
    metadata = dict(rig.metadata)
    metadata["levelled"] = {"reference": ref.name, "camera_height_m": float(camera_height_m),
                            "pitch_deg": float(pitch_deg), "roll_deg": float(roll_deg)}
    return Rig(tuple(cams), volume if volume is not None else LEVEL_VOLUME, rig_id=rig.rig_id, metadata=metadata)
