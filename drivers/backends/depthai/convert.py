"""depthai messages to our frames, and depthai exceptions to our typed errors.

Timestamps: ``ImgFrame.getTimestamp()`` is the capture time translated by depthai's
time sync into the host's ``dai::Clock`` (``std::chrono::steady_clock``, which on
Linux is ``CLOCK_MONOTONIC``: the same clock as ``time.monotonic_ns()``), so it is
directly our host-monotonic ``timestamp_ns``. ``getTimestampDevice()`` is the
device's own clock and is not used. Python's ``timedelta`` carries microseconds,
so timestamps have microsecond resolution.
"""
from __future__ import annotations

import contextlib
import datetime
from collections.abc import Iterator

import cv2
import depthai as dai

from drivers.errors import DriverError, FrameSizeError, RigDisconnectedError, RigOperationError
from drivers.frames import Frame
from ghnerf_runtime.geometry import Rig

#: Names of the Sync node inputs (and so of the messages in each group).
LEFT, RIGHT = "left", "right"


def timedelta_to_ns(delta: datetime.timedelta) -> int:
    """Exact integer nanoseconds of a ``timedelta`` (no float rounding)."""
    return (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1_000


def frame_from_img(message: dai.ImgFrame, camera: str, rig: Rig) -> Frame:
    """One ``dai.ImgFrame`` as a :class:`Frame` of ``camera``: BGR image, host-monotonic timestamp.

    Raises:
        FrameSizeError: the image does not have the rig camera's size (the rig would be wrong); typed, so that
            the daemon tells cameras that never deliver the rig's size (a rig that does not fit) from a bad frame.
    """
    image = message.getCvFrame()  # BGR for colour types, 2-D for GRAY8/RAW8 (mono sensors)
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    cam = rig.camera(camera)
    if image.shape[:2] != (cam.height, cam.width):
        raise FrameSizeError(
            f"depthai delivered a {image.shape[1]}x{image.shape[0]} image for camera {camera!r}, "
            f"the rig says {cam.width}x{cam.height}",
            camera, (cam.width, cam.height), (image.shape[1], image.shape[0]),
        )
    return Frame(
        camera=camera,
        image=image,
        timestamp_ns=timedelta_to_ns(message.getTimestamp()),
        index=int(message.getSequenceNum()),
    )


def frames_from_group(group: dai.MessageGroup, rig: Rig) -> tuple[Frame, Frame]:
    """The two frames of a Sync group, as the rig's first and second camera.

    Raises:
        RigOperationError: the group lacks one of the Sync inputs or holds something else than images.
        FrameSizeError: an image does not have its rig camera's size (:func:`frame_from_img`).
    """
    names = set(group.getMessageNames())
    frames = []
    for key, camera in ((LEFT, rig.pair[0].name), (RIGHT, rig.pair[1].name)):
        if key not in names:
            raise RigOperationError(f"depthai Sync group has no {key!r} message (has {sorted(names)})")
        message = group[key]
        if not isinstance(message, dai.ImgFrame):
            raise RigOperationError(f"depthai Sync group message {key!r} is a {type(message).__name__}, not an ImgFrame")
        frames.append(frame_from_img(message, camera, rig))
    return frames[0], frames[1]


@contextlib.contextmanager
def depthai_errors(action: str, error: type[DriverError]) -> Iterator[None]:
    """Re-raise depthai's exceptions as ours, keeping the cause.

    A closed queue means the pipeline stopped under us (device lost): always
    :class:`RigDisconnectedError`. Other depthai errors (``RuntimeError`` and its
    ``XLinkError``/``EepromError`` subclasses) become ``error``, and so does ``ValueError``:
    depthai-core's ``DeviceBase::checkClosed()`` throws ``std::invalid_argument`` ("Device already
    closed or disconnected"), which pybind11 raises as ``ValueError``, from any device call made
    after the device dropped off the bus (``readCalibration()`` right after a flaky USB boot).
    """
    try:
        yield
    except DriverError:
        raise
    except dai.MessageQueue.QueueException as e:
        raise RigDisconnectedError(f"{action}: depthai queue closed (device lost or pipeline stopped): {e}") from e
    except (RuntimeError, ValueError) as e:
        raise error(f"{action}: {e}") from e
