"""A DeviceLink with no device: a host-only depthai pipeline (``dai.Pipeline(False)``).

Two ThreadedHostNodes play the cameras: they send real ``dai.ImgFrame``s (GRAY8,
like OAK mono sensors) stamped on depthai's host clock, through the production
Sync stage (:func:`drivers.backends.depthai.pipeline.build_sync_stage`), into a
real ``dai.MessageQueue``. The calibration is a real ``dai.CalibrationHandler``
loaded from a JSON EEPROM dump. What cannot run without hardware: a ``dai.Device``, the
``Camera`` nodes (depthai 3.12 refuses to create a device node in a pipeline without a device:
"Pipeline is host only, cannot create device node") and reading an EEPROM. For those,
:class:`StandInDevice` and :class:`HostBackedPipeline` run the production
:class:`~drivers.backends.depthai.link.DaiDeviceLink` with every call on them checked against
depthai's stubs (tests/drivers/depthai_stubs.py).
Test-only: lives in tests/, never in production code.
"""
from __future__ import annotations

import datetime
import threading
import time
from pathlib import Path

import depthai as dai
import numpy as np

from drivers.backends.depthai.link import StereoRequest
from drivers.backends.depthai.pipeline import build_sync_stage
from tests.drivers.depthai_stubs import StandIn, check_call

CALIBRATION = Path(__file__).parent / "fixtures" / "oak_d_calibration.json"


def stamp(image_frame: dai.ImgFrame, t_ns: int) -> None:
    delta = datetime.timedelta(microseconds=t_ns // 1000)
    image_frame.setTimestamp(delta)
    image_frame.setTimestampDevice(delta)


class CameraNode(dai.node.ThreadedHostNode):
    """Sends GRAY8 frames at ``fps``; frame k is due at ``start_ns + k/fps + offset``, pixel value k % 256."""

    def __init__(self, fps: float, size: tuple[int, int], start_ns: int, offset_ms: float = 0.0,
                 drop: float = 0.0, seed: int = 0) -> None:
        super().__init__()
        self.out = self.createOutput()
        self.fps, self.size, self.start_ns = fps, size, start_ns
        self.offset_ns = int(offset_ms * 1e6)
        self.drop = drop
        self.rng = np.random.default_rng(seed)
        self.sent: list[tuple[int, int]] = []  # (index, timestamp_ns) actually sent
        self.finished = threading.Event()
        self.silent = threading.Event()  # set: sends nothing more, as a camera on a lost device

    def run(self) -> None:
        try:
            self._run()
        finally:
            self.finished.set()

    def _run(self) -> None:
        k = 0
        while self.isRunning():
            due = self.start_ns + int(k * 1e9 / self.fps) + self.offset_ns
            while self.isRunning() and time.monotonic_ns() < due:
                time.sleep(min(0.005, max(due - time.monotonic_ns(), 0) / 1e9))
            if not self.isRunning():
                return
            if self.rng.random() >= self.drop and not self.silent.is_set():
                frame = dai.ImgFrame()
                frame.setCvFrame(np.full((self.size[1], self.size[0]), k % 256, np.uint8), dai.ImgFrame.Type.GRAY8)
                stamp(frame, due)
                frame.setSequenceNum(k)
                self.out.send(frame)
                self.sent.append((k, due))
            k += 1


def join_stopped(pipeline: dai.Pipeline, cameras: list[CameraNode]) -> None:
    """Wait, after ``pipeline.stop()``, for every node's thread to end, the GIL released.

    stop() only signals. The pipeline's destructor joins the node threads while holding the GIL, and a node that
    needs the GIL to finish deadlocked it: these Python cameras, and the Sync node letting go of frames they made
    (its thread waits for the GIL in depthai's bindings; seen at load ~10, the run hung in a fixture's teardown).
    The cameras are waited for first, generously: on a starved machine (a niced CI beside a training run) one took
    over 2 s to notice the stop. ``pipeline.wait()`` then joins them all, the Sync node's thread too.
    """
    for camera in cameras:
        if not camera.finished.wait(60.0):
            raise RuntimeError("a host camera node did not stop within 60 s of pipeline.stop()")
    pipeline.wait()


class HostPipelineLink:
    """:class:`~drivers.backends.depthai.link.DeviceLink` on a host-only pipeline (see module docstring)."""

    def __init__(self, *, offset_ms: float = 0.0, drop: float = 0.0, calibration: Path = CALIBRATION,
                 fps: float | None = None) -> None:
        self.offset_ms, self.drop, self.calibration_path, self.fps = offset_ms, drop, calibration, fps
        self.pipeline: dai.Pipeline | None = None
        self.queue: dai.MessageQueue | None = None
        self.cameras: list[CameraNode] = []
        self.closed = 0

    def start(self, request: StereoRequest) -> None:
        self.request = request
        pipeline = dai.Pipeline(False)
        fps = self.fps or request.fps
        start = time.monotonic_ns() + 20_000_000
        size = (request.width, request.height)
        self.cameras = [
            pipeline.create(CameraNode, fps, size, start, 0.0, self.drop, 1),
            pipeline.create(CameraNode, fps, size, start, self.offset_ms, self.drop, 2),
        ]
        self.queue = build_sync_stage(
            pipeline, self.cameras[0].out, self.cameras[1].out,
            tolerance_ms=request.tolerance_ms, queue_size=request.queue_size,
        )
        pipeline.start()
        self.pipeline = pipeline

    def device_id(self) -> str:
        return "host-pipeline"

    def device_name(self) -> str:
        return "host"

    def calibration(self) -> dai.CalibrationHandler:
        return dai.CalibrationHandler(self.calibration_path)

    def next_group(self, timeout_s: float) -> dai.MessageGroup | None:
        assert self.queue is not None
        return self.queue.get(datetime.timedelta(seconds=max(timeout_s, 0.0)))

    def is_running(self) -> bool:
        return self.pipeline is not None and self.pipeline.isRunning()

    def cancel(self) -> None:
        """Nothing to cut short: start() here is quick, and the source checks for a close once it returns."""

    def unplug(self) -> None:
        """Stop the pipeline under the reader, as a lost device does: its queue closes."""
        if self.pipeline is not None:
            self.pipeline.stop()

    def close(self) -> None:
        self.closed += 1
        if self.pipeline is None:
            return
        if self.pipeline.isRunning():
            self.pipeline.stop()
        join_stopped(self.pipeline, self.cameras)


def image_group(indices: tuple[int, int], size: tuple[int, int], fps: float = 30.0) -> dai.MessageGroup:
    """A Sync group as the host queue hands it out: ``left``/``right`` GRAY8 frames with these sequence
    numbers, both stamped at the first one's frame time."""
    group = dai.MessageGroup()
    for name, index in zip(("left", "right"), indices):
        frame = dai.ImgFrame()
        frame.setCvFrame(np.full((size[1], size[0]), indices[0] % 256, np.uint8), dai.ImgFrame.Type.GRAY8)
        stamp(frame, 1_000_000_000 + int(indices[0] * 1e9 / fps))
        frame.setSequenceNum(index)
        group[name] = frame
    return group


class ScriptedLink:
    """A :class:`~drivers.backends.depthai.link.DeviceLink` whose host queue holds the groups a test chose
    (their frame indices), all at once; then nothing, with the pipeline running or (``stops``) not."""

    def __init__(self, groups: list[tuple[int, int]], *, stops: bool = False, device: str = "14442C10D1") -> None:
        self.indices, self.stops, self.device = list(groups), stops, device
        self.groups: list[dai.MessageGroup] = []
        self.closed = 0

    def start(self, request: StereoRequest) -> None:
        self.groups = [image_group(ix, (request.width, request.height)) for ix in self.indices]

    def device_id(self) -> str:
        return "" if self.closed else self.device  # as DaiDeviceLink: no device once closed

    def device_name(self) -> str:
        return "" if self.closed else "1.3"  # a USB port path, as depthai names a USB device

    def calibration(self) -> dai.CalibrationHandler:
        return dai.CalibrationHandler(CALIBRATION)

    def next_group(self, timeout_s: float) -> dai.MessageGroup | None:
        return self.groups.pop(0) if self.groups else None

    def is_running(self) -> bool:
        return bool(self.groups) or not self.stops

    def cancel(self) -> None:
        """Nothing to cut short: start() here is quick, and the source checks for a close once it returns."""

    def close(self) -> None:
        self.closed += 1


# ----------------------------------------------------------------- stand-ins for what needs a device
DEVICE_ID = "14442C10D13EABCE00"


def camera_features(socket: str, sensor: str, size: tuple[int, int], max_fps: float) -> dai.CameraFeatures:
    """A camera as ``getConnectedCameraFeatures()`` describes it (depthai's own types)."""
    features = dai.CameraFeatures()
    features.socket, features.sensorName = dai.CameraBoardSocket.__members__[socket], sensor
    features.width, features.height = size
    config = dai.CameraSensorConfig()
    config.width, config.height, config.minFps, config.maxFps = size[0], size[1], 1.0, max_fps
    features.configs = [config]
    return features


OAK_D = [camera_features("CAM_A", "IMX378", (4056, 3040), 60.0),
         camera_features("CAM_B", "OV9282", (1280, 800), 120.0),
         camera_features("CAM_C", "OV9282", (1280, 800), 120.0)]


class StandInDevice(StandIn):
    """A connected OAK-D as ``dai.Device`` answers, calls checked against the stubs. ``state`` is what
    ``getDeviceState()`` says (a test sets ``DISCONNECTED`` to drop it off the bus)."""

    stands_for = dai.Device

    def __init__(self, device_id: str = DEVICE_ID, speed: dai.UsbSpeed = dai.UsbSpeed.SUPER) -> None:
        self.state = dai.DeviceState.RUNNING
        self.closed = False
        info = dai.DeviceInfo("1.3", device_id, dai.XLinkDeviceState.X_LINK_BOOTED, dai.XLinkProtocol.X_LINK_USB_VSC,
                              dai.XLinkPlatform.X_LINK_MYRIAD_X, dai.XLinkError_t.X_LINK_SUCCESS)
        super().__init__({
            "getDeviceId": device_id,
            "getDeviceInfo": info,
            "getConnectedCameraFeatures": OAK_D,
            "readCalibration": lambda: dai.CalibrationHandler(CALIBRATION),
            "getDeviceState": lambda: self.state,
            "isClosed": lambda: self.closed,
            "close": self._close,
            "setMaxReconnectionAttempts": lambda *args, **kwargs: None,
            "getUsbSpeed": speed,
        })

    def _close(self) -> None:
        self.closed = True


class StandInCamera(StandIn):
    """``dai.node.Camera`` on a host pipeline: ``build`` is checked and recorded, each ``requestOutput`` is
    checked and answered with the output of a host node sending GRAY8 frames of the size and fps asked."""

    stands_for = dai.node.Camera

    def __init__(self, pipeline: "HostBackedPipeline") -> None:
        self._pipeline = pipeline
        super().__init__({"build": lambda *args, **kwargs: self, "requestOutput": self._output})

    def _output(self, size: tuple[int, int], type=None, resizeMode=None, fps=None, enableUndistortion=None,
                alphaScaling=None) -> dai.Node.Output:
        node = self._pipeline.real.create(CameraNode, fps or 30.0, tuple(size), self._pipeline.start_ns, 0.0, 0.0,
                                          len(self._pipeline.sources))
        self._pipeline.sources.append(node)
        return node.out


class HostBackedPipeline(StandIn):
    """``dai.Pipeline(device)`` with a real host-only pipeline beneath: the Sync stage, its queue, start, stop and
    isRunning are depthai's own; only ``create(dai.node.Camera)`` gives a :class:`StandInCamera`. Every call is
    checked against the stubs, the constructor's too."""

    stands_for = dai.Pipeline

    def __init__(self, device: StandInDevice) -> None:
        check_call(dai.Pipeline, "__init__", (device,))
        self.device = device
        self.real = dai.Pipeline(False)
        self.start_ns = time.monotonic_ns() + 50_000_000
        self.sources: list[CameraNode] = []
        self.cameras: list[StandInCamera] = []
        self.started = False
        super().__init__({
            "create": self._create,
            "setStopOnDeviceLoss": self.real.setStopOnDeviceLoss,
            "start": self._start,
            "isRunning": self.real.isRunning,
            "stop": self._stop,
        })

    def _create(self, node_class: type, *args, **kwargs):
        if node_class is dai.node.Camera:
            self.cameras.append(StandInCamera(self))
            return self.cameras[-1]
        return self.real.create(node_class, *args, **kwargs)

    def _start(self) -> None:
        self.real.start()
        self.started = True

    def silence(self) -> None:
        """The cameras send nothing more, the pipeline still running: a lost device's streams go idle."""
        for node in self.sources:
            node.silent.set()

    def _stop(self) -> None:
        self.real.stop()
        if not self.started:
            return
        join_stopped(self.real, self.sources)  # as HostPipelineLink.close: the destructor must find no thread to join
