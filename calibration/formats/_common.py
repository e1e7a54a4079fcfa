"""Validation shared by the foreign-format readers, and the default working volume."""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from ghnerf_runtime.errors import GeometryError, RigFileError
from ghnerf_runtime.geometry.camera import Camera, nearest_rotation
from ghnerf_runtime.geometry.rig import Rig, WorkingVolume
from ghnerf_runtime.rig_file import (
    MAX_IMAGE_SIDE,
    ROTATION_TOLERANCE,
    distortion_problem,
    focal_length_problem,
    principal_point_problem,
)

DISTORTION_LENGTHS = (0, 4, 5, 8, 12, 14)
#: Foreign files often print rotations with few digits: rotations whose ``|R R^T - I|``
#: is within this are accepted and snapped to the nearest rotation, as in our own rig file.
FOREIGN_ROTATION_TOLERANCE = ROTATION_TOLERANCE

#: Default working volume: distance in front of the cameras and cube side, metres.
DEFAULT_VOLUME_DISTANCE_M = 2.5
DEFAULT_VOLUME_SIDE_M = 2.5


def show(value: Any, limit: int = 120) -> str:
    text = np.array2string(value, precision=6, separator=", ") if isinstance(value, np.ndarray) else repr(value)
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def not_text_problem(head: bytes, what: str) -> str | None:
    """Why a file starting with ``head`` is not the UTF-8 text of ``what`` (None: it may be). The parsers said
    "(-215:Assertion failed) buf" (OpenCV, a file of NULs), "Invalid or unsupported syntax" at line 1 (OpenCV,
    UTF-16 text: a Windows editor's "Unicode") or "not UTF-8 (byte 0)", none naming what the file was."""
    if head[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return "UTF-16 text (its byte-order mark says so): save it as UTF-8"
    if b"\x00" in head:
        return f"a binary file (a NUL byte at {head.index(bytes(1))}), not {what} text"
    return None


def fail(path, field: str | None, message: str) -> RigFileError:
    return RigFileError(message, path=None if path is None else str(path), field=field)


def join(field: str, key: str) -> str:
    """``cameras[0]`` + ``K`` -> ``cameras[0].K``; an empty parent gives just the key."""
    return f"{field}.{key}" if field else key


def check_units(units_to_metres: float) -> float:
    # float() took "0.001" and True (1 m per unit) and raised a bare ValueError for "mm"
    if isinstance(units_to_metres, bool) or not isinstance(units_to_metres, (int, float, np.integer, np.floating)):
        raise GeometryError(f"units_to_metres must be a positive finite number, got {units_to_metres!r}")
    value = float(units_to_metres)
    if not (math.isfinite(value) and value > 0):
        raise GeometryError(f"units_to_metres must be a positive finite number, got {units_to_metres!r}")
    return value


def as_array(path, field: str, value: Any, shapes: Sequence[tuple[int, ...]], what: str) -> np.ndarray:
    """``value`` as a finite float array reshaped to the first of ``shapes`` it fits (by size)."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise fail(path, field, f"must be {what}, got {show(value)}") from None
    for shape in shapes:
        if arr.size == int(np.prod(shape)) and (arr.ndim <= 1 or arr.shape == shape or 1 in arr.shape):
            arr = arr.reshape(shape)
            break
    else:
        raise fail(path, field, f"must be {what}, got shape {arr.shape}: {show(arr)}")
    if not np.all(np.isfinite(arr)):
        raise fail(path, field, f"must contain only finite numbers, got {show(arr)}")
    return arr


def rotation(path, field: str, value: Any) -> np.ndarray:
    """A 3x3 rotation matrix, or a Rodrigues 3-vector (converted with ``cv2.Rodrigues``)."""
    import cv2

    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise fail(path, field, f"must be a 3x3 rotation matrix or a Rodrigues 3-vector, got {show(value)}") from None
    if arr.size == 3:
        arr = as_array(path, field, arr, [(3,)], "a 3x3 rotation matrix or a Rodrigues 3-vector")
        R, _ = cv2.Rodrigues(arr.reshape(3, 1))
        if not np.all(np.isfinite(R)):  # |r| past 1e154 overflows: its NaN matrix was refused later, naming the
            # camera's own file (not stereo_calib's extrinsics file it came from) and not the value
            raise fail(path, field, "a Rodrigues vector this long gives no rotation (OpenCV's is NaN), "
                                    f"got {show(arr)}")
        return R
    R = as_array(path, field, arr, [(3, 3)], "a 3x3 rotation matrix or a Rodrigues 3-vector")
    dev = float(np.abs(R @ R.T - np.eye(3)).max())
    det = float(np.linalg.det(R))
    if dev > FOREIGN_ROTATION_TOLERANCE or abs(det - 1.0) > FOREIGN_ROTATION_TOLERANCE:
        raise fail(path, field, f"must be a rotation (orthonormal, det +1): max |R R^T - I| = {dev:.3g}, "
                                f"det = {det:.6g}, got {show(R)}")
    if dev > 1e-12:
        R = nearest_rotation(R)
    return R


def make_camera(path, field: str, *, name: str, width: Any, height: Any, K: Any, dist: Any, R: Any, t: Any,
                K_key: str = "K", dist_key: str = "distortion", R_key: str = "R", t_key: str = "T",
                size_keys: tuple[str, str] = ("width", "height")) -> Camera:
    """Validate each parameter (errors name ``field.<key>``) and build the camera."""
    for what, key, v in (("width", size_keys[0], width), ("height", size_keys[1], height)):
        if (isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v)
                or v <= 0 or v != int(v)):
            raise fail(path, join(field, key), f"image {what} must be a positive integer, got {show(v)}")
        if v > MAX_IMAGE_SIDE:  # the rig file's limit: imported, it was saved to a rig file load_rig refused
            raise fail(path, join(field, key), f"image {what} must be at most {MAX_IMAGE_SIDE}, got {show(v)}")
    K = as_array(path, join(field, K_key), K, [(3, 3)], "a 3x3 camera matrix")
    if not (K[0, 0] > 0 and K[1, 1] > 0) or K[2, 2] != 1.0 or np.any(K[2, :2] != 0) or K[1, 0] != 0:
        raise fail(path, join(field, K_key),
                   f"must be a pinhole matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got {show(K)}")
    # a calibration of another image size (often not in the file: the caller's image_size) would make
    # the rig wrong silently; "inside the image" let through 1280x720 read as 1920x1080
    problem = principal_point_problem(K, int(width), int(height)) or focal_length_problem(K, int(width), int(height))
    if problem:
        sizes = " x ".join(dict.fromkeys(size_keys))
        raise fail(path, join(field, K_key), f"camera {str(name)!r}, image size from {sizes}: {problem}")
    if K[0, 1] != 0:  # the tools that write these files project without it: ours would disagree with theirs
        raise fail(path, join(field, K_key), f"has a skew K[0][1] = {float(K[0, 1])!r}, which OpenCV's camera "
                                             "model (and so this file's writer) ignores; set it to 0")
    try:
        d = np.asarray(dist if dist is not None else [], dtype=np.float64).reshape(-1)
    except (TypeError, ValueError, OverflowError):
        raise fail(path, join(field, dist_key), f"must be a list of numbers, got {show(dist)}") from None
    if d.size not in DISTORTION_LENGTHS or not np.all(np.isfinite(d)):
        raise fail(path, join(field, dist_key),
                   f"must be 0, 4, 5, 8, 12 or 14 finite OpenCV coefficients, got {d.size}: {show(d)}")
    if problem := distortion_problem(d):  # the rig file's bound: imported, it was saved to a file load_rig refused
        raise fail(path, join(field, dist_key), f"camera {str(name)!r}: {problem}")
    if d.size == 14 and np.any(d[12:] != 0):
        raise fail(path, join(field, dist_key), f"tilt terms tx, ty must be 0, got {show(d[12:])}")
    R = rotation(path, join(field, R_key), R)
    t = as_array(path, join(field, t_key), t, [(3,)], "a 3-vector")
    try:
        return Camera(str(name), int(width), int(height), K, dist=d, R=R, t=t)
    except GeometryError as e:  # pragma: no cover - checked above
        raise fail(path, field, str(e)) from e


def make_rig(path, cameras: Sequence[Camera], fields: Sequence[str], *, volume: WorkingVolume | None,
             rig_id: str, metadata: dict, list_field: str, pair_t: tuple[Any, str]) -> Rig:
    """``pair_t``: the file and field the second camera's translation came from (for the baseline's error)."""
    if len(cameras) < 2:
        raise fail(path, list_field, f"a rig needs at least two cameras, got {len(cameras)}")
    seen: dict[str, str] = {}
    for cam, field in zip(cameras, fields):
        if cam.name in seen:
            raise fail(path, join(field, "name"), f"duplicate camera name {cam.name!r} (also {seen[cam.name]})")
        seen[cam.name] = field
    if volume is not None and not isinstance(volume, WorkingVolume):
        raise GeometryError(f"volume must be a WorkingVolume or None, got {type(volume).__name__}")
    try:
        rig = Rig(tuple(cameras), volume if volume is not None else default_working_volume(cameras),
                  rig_id=rig_id, metadata=metadata)
    except GeometryError as e:  # translations so large (1e20 file units) that no volume fits in front of them
        raise fail(path, list_field, str(e)) from e
    # the rig file's reader refuses a pair this close (intrinsics-only calibrations leave both poses at zero):
    # accepted here, it failed later, naming the file it was saved to
    problem = rig.baseline_problem()
    if problem:
        raise fail(pair_t[0], pair_t[1], problem)
    if far := rig.far_camera_problem():  # a third camera under the pair's bound, as the rig file's reader has it
        raise fail(path, join(fields[far[0]], pair_t[1].rpartition(".")[2]), far[1])
    return rig


def default_working_volume(
    cameras: Sequence[Camera],
    *,
    distance_m: float = DEFAULT_VOLUME_DISTANCE_M,
    side_m: float = DEFAULT_VOLUME_SIDE_M,
) -> WorkingVolume:
    """A working volume for calibrations that carry none: a cube in front of the cameras.

    The cube is axis-aligned in the rig frame, ``side_m`` on a side, centred on:

    1. the point closest (least squares) to the cameras' optical axes, when the axes
       converge, i.e. the smallest eigenvalue of ``sum_i (I - a_i a_i^T)`` exceeds
       ``sin^2(2 deg)`` per camera, and that point lies between 0.3 m and 20 m in front of
       every camera; otherwise
    2. the mean camera centre plus ``distance_m`` along the mean optical axis (a parallel
       stereo pair), or the mean camera centre itself when the axes cancel out (cameras
       facing each other).

    It is a starting point; the calibration tool should let the user edit it.

    Args:
        cameras: the rig's cameras (at least one), rig frame in metres.
        distance_m: distance in front of the cameras for the parallel case.
        side_m: side of the cube.

    Returns:
        The :class:`WorkingVolume`.
    """
    if not cameras:
        raise GeometryError("default_working_volume needs at least one camera")
    if not (distance_m > 0 and side_m > 0):
        raise GeometryError(f"distance_m and side_m must be positive, got {distance_m}, {side_m}")
    centres = np.stack([c.center for c in cameras])
    axes = np.stack([c.R[2] for c in cameras])  # optical axes in the rig frame
    proj = np.eye(3)[None] - axes[:, :, None] * axes[:, None, :]
    A = proj.sum(axis=0)
    centre = None
    if np.linalg.eigvalsh(A)[0] > len(cameras) * np.sin(np.radians(2.0)) ** 2:
        p = np.linalg.solve(A, np.einsum("cij,cj->i", proj, centres))
        depth = np.einsum("ci,ci->c", p - centres, axes)
        if np.all((depth > 0.3) & (depth < 20.0)):
            centre = p
    if centre is None:
        mean_axis = axes.mean(axis=0)
        norm = np.linalg.norm(mean_axis)
        centre = centres.mean(axis=0) + (distance_m * mean_axis / norm if norm > 0.5 else 0.0)
    half = 0.5 * side_m
    return WorkingVolume(centre - half, centre + half)


def refuse_skew(cameras: Sequence[Camera], what: str) -> None:
    """Foreign formats follow OpenCV's camera model, which has no skew: writing one would lose it silently."""
    for cam in cameras:
        if cam.K[0, 1] != 0.0:
            raise GeometryError(f"camera {cam.name!r} has a skew K[0][1] = {float(cam.K[0, 1])!r}; {what} cannot "
                                "hold it (OpenCV's camera model has none): keep this rig in our rig file")
