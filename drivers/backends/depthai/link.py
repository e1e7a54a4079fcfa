"""Everything that needs an attached device, behind one small interface.

:class:`DeviceLink` is what :class:`~drivers.backends.depthai.source.DepthaiRigSource`
needs from a device: start the stereo pipeline, read the calibration, hand over
the next Sync group, stop. :class:`DaiDeviceLink` implements it with depthai.
Tests implement it with a host-only depthai pipeline (tests/drivers), which
exercises the same Sync stage and message types without hardware.

Links raise depthai's own exceptions, which the source converts at its boundary; only what
:func:`open_device` finds wrong before it connects (a device in use, ambiguous or absent), and a start
cut short by :meth:`DeviceLink.cancel`, are raised as our :class:`~drivers.errors.RigInitializationError`
already.
"""
from __future__ import annotations

import datetime
import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import depthai as dai

from drivers.backends.depthai.options import board_socket
from drivers.backends.depthai.pipeline import build_sync_stage
from drivers.errors import RigInitializationError, RigOperationError
from ghnerf_runtime.path_check import shown

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class StereoRequest:
    """What to stream: which device and sockets, at what rate and size, synced how tightly."""

    device_id: str | None
    left: str
    right: str
    fps: float
    width: int
    height: int
    tolerance_ms: float
    queue_size: int


class DeviceLink(Protocol):
    """A started stereo stream on one device."""

    def start(self, request: StereoRequest) -> None:
        """Connect, build the pipeline (two cameras -> Sync -> host queue) and start it."""

    def device_id(self) -> str:
        """The connected device's id (for the rig id and logs)."""

    def device_name(self) -> str:
        """The connected device's XLink name (USB port path such as ``1.3``, or IP address), for messages:
        with two identical OAKs it says which socket or cable to look at. Empty when unknown."""

    def calibration(self) -> dai.CalibrationHandler:
        """The device's calibration (EEPROM)."""

    def next_group(self, timeout_s: float) -> dai.MessageGroup | None:
        """The next synced group with ``left`` and ``right`` ImgFrames, or ``None`` after ``timeout_s``."""

    def is_running(self) -> bool:
        """Whether the device is still connected and its pipeline running (asked after a timeout: a device
        lost without closing the queue would otherwise read as a silent camera)."""

    def cancel(self) -> None:
        """From another thread while :meth:`start` runs (a close landing during the source's open): ``start`` goes
        no further than the step it is in, raising. Must not wait for ``start``; harmless once it returned. What
        ``start`` made is released by :meth:`close`, as after any failed start."""

    def close(self) -> None:
        """Stop the pipeline and release the device. Safe to call more than once."""


#: Links slower than USB3 (``getUsbSpeed()``; ``UNKNOWN`` is a PoE device, not slow).
_SLOW_USB = ("LOW", "FULL", "HIGH")
#: XLink states of a device another process holds: USB OAKs show ``UNBOOTED`` (or ``BOOTLOADER``) when
#: free and ``BOOTED`` while a host runs a pipeline on them; a crashed host's device stays ``BOOTED``
#: until its watchdog resets it (seconds). Other states (the RVC4 gate's) are left to depthai to judge.
_IN_USE_STATES = ("X_LINK_BOOTED",)


def _state(info: dai.DeviceInfo) -> str:
    return getattr(info.state, "name", str(info.state))


def describe_devices(devices: list[dai.DeviceInfo]) -> str:
    """``id (name, STATE)`` for each device, for messages that must say what is connected."""
    if not devices:
        return "none"
    # the id and name as the device and XLink report them: escaped where one holds a control character
    return ", ".join(f"{shown(d.getDeviceId())} ({shown(d.name)}, {_state(d).removeprefix('X_LINK_')})"
                     for d in devices)


def _in_use_error(info: dai.DeviceInfo) -> RigInitializationError:
    return RigInitializationError(
        f"depthai device {shown(info.getDeviceId())} ({shown(info.name)}) is in use by another process (XLink state "
        f"{_state(info).removeprefix('X_LINK_')}): stop that process, or wait a few seconds if it crashed "
        "(the device resets itself)"
    )


def choose_device(target: str | None, connected: list[dai.DeviceInfo]) -> dai.DeviceInfo | None:
    """The connected device the URL's target (device id or XLink name; ``None``: any) means.

    Returns ``None`` when nothing connected matches (yet): depthai then searches for it for its
    default search time, as it does for a device still rebooting; if that fails too, the caller names
    the connected devices (:func:`open_device`).

    Raises:
        RigInitializationError: the device is in use by another process; the name matches several
            devices; or, without a target, every connected device is in use.
    """
    if target:
        matches = [d for d in connected if target in (d.getDeviceId(), d.name)]
        if len(matches) > 1:
            raise RigInitializationError(
                f"depthai device {target!r} is ambiguous: it names {len(matches)} connected devices "
                f"({describe_devices(matches)}); give the device id"
            )
        if matches and _state(matches[0]) in _IN_USE_STATES:
            raise _in_use_error(matches[0])
        return matches[0] if matches else None
    free = [d for d in connected if _state(d) not in _IN_USE_STATES]
    if connected and not free:
        if len(connected) == 1:
            raise _in_use_error(connected[0])
        raise RigInitializationError(
            f"every connected depthai device is in use by another process: {describe_devices(connected)}"
        )
    if len(free) > 1:
        # "The first found" depends on USB enumeration order: which OAK a restart opens could change.
        log.warning(
            "depthai: %d devices are free (%s) and the URL names none: opening %s; give its id in the URL "
            "(depthai://ID) to keep the choice", len(free), describe_devices(free), shown(free[0].getDeviceId()),
        )
    return free[0] if free else None


def open_device(
    request: StereoRequest,
    device_class: Callable[..., dai.Device] = dai.Device,
    list_devices: Callable[[], list[dai.DeviceInfo]] = dai.Device.getAllConnectedDevices,
) -> dai.Device:
    """Connect to the requested device (or the first free one) and prepare it for a stream we own.

    * the device is looked up first among all connected ones (``getAllConnectedDevices()``, which also
      lists those in use): one in use by another process, a name that matches several devices, and a
      device that cannot be found are errors that say so and list what is connected
      (:func:`choose_device`).
    * depthai's own reconnection is switched off (``setMaxReconnectionAttempts(0)``: "0 to disable
      reconnection"). While it retries, depthai 3.12's host bridges wait for the device ("Waiting
      for reconnect") and the output queue stays open and silent, so an unplug would read as
      timeouts; a device back from a reconnect is rebooted with its pipeline restarted behind the
      pairer's back. Switched off, a lost device ends the pipeline, its queue closes and the
      source raises :class:`~drivers.errors.RigDisconnectedError`; whoever owns the source
      reopens it (the daemon does, re-reading the EEPROM).
    * a link below USB3 is logged as a warning with the stream's bandwidth: two NV12 streams at
      640x400 and 30 fps are about 23 MB/s, 1280x800 four times that, more than USB2's 480 Mbit/s.

    Raises:
        RigInitializationError: the device is in use, ambiguous or not connected.
        RuntimeError, ValueError: depthai's own, from a device that fails while it is prepared.
    """
    target = request.device_id
    info = choose_device(target, list_devices())
    try:
        if info is not None:
            device = device_class(info)  # exactly the device looked up, not the first that answers to its name
        else:
            device = device_class(target) if target else device_class()
    except RuntimeError as e:
        wanted = f"depthai device {target!r}" if target else "a depthai device"
        try:  # asked again: the device may have gone, or come, during depthai's search
            connected = describe_devices(list_devices())
        except RuntimeError as listing:
            connected = f"unknown (listing them failed: {listing})"
        raise RigInitializationError(f"cannot connect to {wanted}: {e}; connected devices: {connected}") from e
    try:  # the caller only learns of the device once this returns: close it on any failure here
        device.setMaxReconnectionAttempts(0)
        speed = device.getUsbSpeed()
        name = getattr(speed, "name", str(speed))
        if name in _SLOW_USB:
            mb_s = 2 * request.width * request.height * 1.5 * request.fps / 1e6
            log.warning(
                "depthai device %s is on a USB link of speed %s (USB2 or slower): two %dx%d streams at %.0f fps "
                "need about %.0f MB/s as NV12; frames will drop if the link cannot carry them. Use a USB3 port "
                "and cable, or lower width/height/fps", shown(device.getDeviceId()), name, request.width,
                request.height, request.fps, mb_s,
            )
        else:
            log.info("depthai device %s on USB speed %s", shown(device.getDeviceId()), name)
    except BaseException:
        device.close()
        raise
    return device


def check_cameras(request: StereoRequest, device_id: str, features: list[dai.CameraFeatures]) -> None:
    """Refuse, naming the option, a stream the device's sensors cannot give (``getConnectedCameraFeatures()``):
    a socket without a camera, a size larger than the sensor (it would be upscaled, or the image would not
    have the rig's size) or an fps above every sensor mode's ``maxFps``.

    Raises:
        RigInitializationError: naming the option, its value and what the device has.
    """
    by_socket = {f.socket.name: f for f in features}
    device = shown(device_id)  # as describe_devices shows it
    # a sensor's name is the device's text (its EEPROM): escaped where it holds a control character
    have = ", ".join(f"{f.socket.name} ({shown(f.sensorName)}, {f.width}x{f.height})" for f in features) or "none"
    for option, socket in (("left", request.left), ("right", request.right)):
        feature = by_socket.get(socket)
        if feature is None:
            raise RigInitializationError(
                f"depthai device {device} has no camera on socket {socket} (option {option}={socket}); "
                f"its cameras: {have}"
            )
        sensor = f"the {socket} sensor's ({shown(feature.sensorName)})"
        known = feature.width > 0 and feature.height > 0  # CameraFeatures' default is -1: not reported
        if known and (request.width > feature.width or request.height > feature.height):
            raise RigInitializationError(
                f"depthai device {device}: options width={request.width} height={request.height} exceed "
                f"{sensor} {feature.width}x{feature.height}; ask for at most that"
            )
        fastest = max((config.maxFps for config in feature.configs), default=None)
        if fastest is not None and request.fps > fastest:
            raise RigInitializationError(
                f"depthai device {device}: option fps={request.fps:g} exceeds {sensor} fastest mode, {fastest:g} fps"
            )


class DaiDeviceLink:
    """:class:`DeviceLink` on a real OAK device through depthai 3.x.

    Args:
        connect: opens the device for a request (default :func:`open_device`).
        pipeline_for: makes the pipeline that runs on a device (default ``dai.Pipeline``). Both are
            parameters so that tests run this class on stand-ins checked against depthai's stubs.
    """

    def __init__(
        self,
        connect: Callable[[StereoRequest], dai.Device] | None = None,
        pipeline_for: Callable[[dai.Device], dai.Pipeline] = dai.Pipeline,
    ) -> None:
        self._connect = connect or open_device
        self._pipeline_for = pipeline_for
        self._device: dai.Device | None = None
        self._pipeline: dai.Pipeline | None = None
        self._queue: dai.MessageQueue | None = None
        self._cancelled = threading.Event()

    def start(self, request: StereoRequest) -> None:
        self._device = self._connect(request)
        # Connecting (depthai boots the device) is the long step and cannot be interrupted: a cancel during it
        # stops here, before any camera streams.
        if self._cancelled.is_set():
            raise RigInitializationError(f"depthai device {shown(self.device_id())}: start cancelled (a cancel() "
                                         "from another thread) once connected, before its pipeline was built")
        check_cameras(request, self._device.getDeviceId(), self._device.getConnectedCameraFeatures())
        pipeline = self._pipeline_for(self._device)
        self._pipeline = pipeline
        # depthai 3.12 keeps a pipeline running when one of its devices is lost ("permissive mode") unless
        # it was the last one; strict mode says what we mean: a lost device ends this stream.
        pipeline.setStopOnDeviceLoss(True)
        outputs = []
        for socket in (request.left, request.right):
            cam = pipeline.create(dai.node.Camera).build(board_socket(socket), sensorFps=request.fps)
            outputs.append(cam.requestOutput(
                (request.width, request.height), resizeMode=dai.ImgResizeMode.CROP, fps=request.fps,
                # The rig carries the EEPROM's distortion and undistorts itself: the frames must be the
                # lens's own. Left unset (None), the device decides, and an OAK's wide lens may be undistorted.
                enableUndistortion=False,
            ))
        self._queue = build_sync_stage(
            pipeline, outputs[0], outputs[1], tolerance_ms=request.tolerance_ms, queue_size=request.queue_size
        )
        pipeline.start()
        log.info("depthai device %s streaming %s+%s at %.0f fps", shown(self.device_id()), request.left, request.right,
                 request.fps)

    def device_id(self) -> str:
        return self._device.getDeviceId() if self._device is not None else ""

    def device_name(self) -> str:
        return self._device.getDeviceInfo().name if self._device is not None else ""

    def calibration(self) -> dai.CalibrationHandler:
        assert self._device is not None, "start() first"
        return self._device.readCalibration()

    def next_group(self, timeout_s: float) -> dai.MessageGroup | None:
        queue = self._queue  # once: close() from another thread sets it to None
        if queue is None:  # closed, or never started: an AssertionError reached a reader racing a close
            raise RigOperationError("depthai link is not started, or was closed")
        return queue.get(datetime.timedelta(seconds=max(timeout_s, 0.0)))

    def is_running(self) -> bool:
        """The pipeline runs and its device is connected. ``getDeviceState()`` (thread-safe) also sees a device
        that dropped off while the pipeline still runs, which ``isClosed()`` (thread-unsafe, "may return outdated
        values") need not."""
        pipeline, device = self._pipeline, self._device
        if pipeline is None or device is None or not pipeline.isRunning() or device.isClosed():
            return False
        return device.getDeviceState() == dai.DeviceState.RUNNING

    def cancel(self) -> None:
        self._cancelled.set()

    def close(self) -> None:
        pipeline, device = self._pipeline, self._device
        self._pipeline = self._device = self._queue = None
        try:
            if pipeline is not None:
                pipeline.stop()
        finally:
            if device is not None:
                device.close()
