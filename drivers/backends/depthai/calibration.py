"""A depthai ``CalibrationHandler`` (the device EEPROM) turned into our :class:`Rig`.

Rig frame (the project convention, docs/rig-file.md): metres, x right, y down,
z forward, origin on the floor below the midpoint of the two camera centres.
The EEPROM knows the cameras relative to each other but not where the floor is,
so we assume the device is mounted without pitch (the left camera's optical axis
is horizontal), rolled ``mount_roll_deg`` about it (0: level, 180: upside down),
at ``mount_height_m`` above the floor. A tilted mount needs a calibrated rig file
(``rig=``).

Intrinsics are converted to the output size the way the Camera node produces it
(``ImgResizeMode.CROP``: centre crop to the output aspect ratio, then scale),
with depthai's own scaling convention (``cx' = cx * s``), which makes them equal
to ``getCameraIntrinsics(socket, w, h)`` whenever the aspect ratio is kept.

Extrinsics: ``getCameraExtrinsics(src, dst)`` maps points from ``src``'s frame to
``dst``'s (``X_dst = R X_src + t``); its translation is in centimetres unless
``unit=`` asks otherwise, so we ask for ``LengthUnit.METER``.
"""
from __future__ import annotations

import numpy as np
import depthai as dai

from drivers.errors import RigInitializationError
from ghnerf_runtime.errors import GeometryError
from ghnerf_runtime.geometry import Camera, Rig, WorkingVolume, nearest_rotation
from ghnerf_runtime.rig_file import principal_point_problem

#: Where a person can stand in front of a level-mounted OAK (rig frame, metres): used
#: when the calibration comes from the device; a rig file carries its own.
DEFAULT_VOLUME = WorkingVolume(np.array([-1.5, -2.3, 0.5]), np.array([1.5, 0.1, 5.0]))


def crop_resize_intrinsics(K: np.ndarray, source_size: tuple[int, int], size: tuple[int, int]) -> np.ndarray:
    """Intrinsics after a centre crop to ``size``'s aspect ratio and a scale to ``size``.

    Args:
        K: ``(3, 3)`` intrinsics at ``source_size`` (width, height).
        size: output (width, height).
    """
    (w0, h0), (w, h) = source_size, size
    scale = max(w / w0, h / h0)  # scale so the output is covered, the excess is cropped
    x0 = (w0 * scale - w) / 2
    y0 = (h0 * scale - h) / 2
    out = np.asarray(K, dtype=np.float64).copy()
    out[:2, :] *= scale
    out[0, 2] -= x0
    out[1, 2] -= y0
    out[2] = (0.0, 0.0, 1.0)
    return out


def _camera(
    calib: dai.CalibrationHandler, socket: dai.CameraBoardSocket, name: str, size: tuple[int, int], device: str
) -> Camera:
    where = f"device calibration of {device} {socket.name} ({name})"
    if not calib.hasCameraCalibration(socket):
        raise RigInitializationError(f"{where}: the EEPROM has no calibration for this socket")
    model = calib.getDistortionModel(socket)
    if model != dai.CameraModel.Perspective:
        raise RigInitializationError(
            f"{where}: distortion model {model.name} is not supported (only Perspective); supply rig=FILE"
        )
    K0, w0, h0 = calib.getDefaultIntrinsics(socket)
    dist = np.asarray(calib.getDistortionCoefficients(socket), dtype=np.float64)
    if dist.size == 14 and np.any(dist[12:] != 0):
        raise RigInitializationError(f"{where}: tilted-sensor terms tx, ty = {dist[12:].tolist()} are not supported")
    K = crop_resize_intrinsics(np.asarray(K0), (w0, h0), size)
    # The rule a rig file enforces (a take recorded from this rig must replay): checked where the rig is made.
    problem = principal_point_problem(K, size[0], size[1], advice=(
        f"the EEPROM's intrinsics (calibrated at {w0}x{h0}) do not fit this socket at {size[0]}x{size[1]}; "
        "recalibrate the device or supply rig=FILE"))
    if problem is not None:
        raise RigInitializationError(f"{where}: {problem}")
    try:
        return Camera(name, size[0], size[1], K, dist=dist)
    except GeometryError as e:
        raise RigInitializationError(f"{where}: {e}") from e


def rig_from_calibration(
    calib: dai.CalibrationHandler,
    left: dai.CameraBoardSocket,
    right: dai.CameraBoardSocket,
    size: tuple[int, int],
    mount_height_m: float,
    *,
    mount_roll_deg: float = 0.0,
    names: tuple[str, str] = ("left", "right"),
    rig_id: str = "oak",
    volume: WorkingVolume = DEFAULT_VOLUME,
) -> Rig:
    """The stereo pair ``left``/``right`` of ``calib`` as a two-camera rig at output ``size``.

    ``mount_roll_deg``: the device turned about its viewing direction, counterclockwise as seen
    from behind it; the rig frame stays level (y down), so the cameras carry the roll.

    Raises:
        RigInitializationError: a socket is not calibrated, uses an unsupported lens
            model or a principal point far from its image's centre
            (:func:`ghnerf_runtime.rig_file.principal_point_problem`), or the extrinsics
            are not a rigid transform.
    """
    cam_l = _camera(calib, left, names[0], size, rig_id)
    cam_r = _camera(calib, right, names[1], size, rig_id)
    try:
        T = np.asarray(calib.getCameraExtrinsics(left, right, unit=dai.LengthUnit.METER), dtype=np.float64)
    except RuntimeError as e:
        raise RigInitializationError(f"device calibration has no extrinsics {left.name} -> {right.name}: {e}") from e
    R_lr, t_lr = T[:3, :3], T[:3, 3]
    R_lr = nearest_rotation(R_lr)  # the EEPROM stores float32: snap back onto a rotation
    centre_r = -R_lr.T @ t_lr  # right camera centre in the left camera's frame
    # The left camera's frame is the level rig frame rolled: X_cam = roll @ X_rig + origin. Turned
    # counterclockwise (seen from behind), the camera's x axis turns from the rig's right towards up.
    a = np.radians(mount_roll_deg)
    roll = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    # Rig origin in left-camera coordinates: below the midpoint of the centres, on the floor (the rig's down).
    origin = 0.5 * centre_r + mount_height_m * roll[:, 1]
    try:
        cam_l = cam_l.with_pose(roll, origin)
        cam_r = cam_r.with_pose(R_lr @ roll, R_lr @ origin + t_lr)
        return Rig(
            (cam_l, cam_r),
            volume,
            rig_id=rig_id,
            metadata={
                "source": "depthai-eeprom",
                "sockets": [left.name, right.name],
                "mount_height_m": mount_height_m,
                "mount_roll_deg": mount_roll_deg,
                "assumes": "no pitch; the roll is mount_roll_deg",
            },
        )
    except GeometryError as e:
        raise RigInitializationError(f"device calibration {left.name} -> {right.name} is not a rigid transform: {e}") from e
