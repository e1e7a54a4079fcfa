"""``opencv://``: two cameras that OpenCV opens: USB (UVC) webcams, video files, network streams.

For a rig without an OAK: two webcams calibrated with ``ghcal``, or two videos of one take played
as if live. Examples::

    opencv://?first=0&second=1                                   # two webcams, a nominal rig: for ghcal capture
    opencv://?first=0&second=1&rig=/etc/ghnerf/rig.json          # the same, calibrated (ghcal solve)
    opencv://?first=/dev/video2&second=/dev/video4&rig=rig.json&fourcc=MJPG&fps=30
    opencv://?first=take/left.mp4&second=take/right.mp4&rig=rig.json   # two synchronised videos

Options:

* ``first``, ``second`` (required): what ``cv2.VideoCapture`` opens for the rig's first and second
  camera: a device index (``0``), a device path (``/dev/video2``), a video file, or a stream URL
  (percent-encoded inside the query: ``rtsp%3A%2F%2Fcam1%2Fstream``).
* ``rig``: the rig file (``ghcal solve``); its first two cameras are ``first`` and ``second``, in
  that order, and their image size is what the cameras must deliver. Without it the source has a
  nominal, uncalibrated rig (``hfov``, ``names``): enough for ``ghcal capture``, not for 3D joints.
* ``width``, ``height``, ``fps``, ``fourcc``: asked of live cameras (default: the rig's size, the
  camera's own rate and format); what a camera really delivers is checked against the rig at
  :meth:`open`. Two webcams on one USB bus usually need ``fourcc=MJPG``.
* ``api``: OpenCV's capture backend: ``any`` (default), ``v4l2``, ``ffmpeg``, ``gstreamer``,
  ``dshow``, ``msmf``, ``avfoundation``.
* ``names``: the two camera names of the nominal rig (default ``left,right``); ``hfov``: its
  horizontal field of view in degrees (default 70).
* ``loop`` (videos): start over at the end instead of ending the stream.
* ``tolerance_ms``: pairing tolerance (default: half a frame period at ``fps``, or at 30 fps);
  ``policy``: ``latest`` (default) or ``all``; ``queue``: frames held per camera (default 4).

Timing. Each camera has its own grabbing thread. A live camera's frame is stamped with the host's
monotonic clock as it is grabbed: webcams are not synchronised in hardware, so a pair is two
frames within ``tolerance_ms`` (the default pairs each frame with the other camera's nearest one;
a person moving fast is seen up to half a frame apart by the two cameras, which an OAK's shared
trigger avoids). A video file is paced at its own frame rate from a start shared by both files and
stamped by its frame number, so two videos of one take pair exactly as recorded. Not modelled:
exposure, white balance or rolling-shutter differences between the two cameras.

A live camera that stops delivering (unplugged) raises :class:`RigDisconnectedError` from the next
read, after the frames it delivered before; a video's end raises :class:`EndOfStream` the same way.
"""
from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from drivers.base import RigSource
from drivers.clock import Clock, MonotonicClock
from drivers.errors import (
    EndOfStream,
    RigConfigError,
    RigDisconnectedError,
    RigInitializationError,
    RigOperationError,
)
from drivers.frames import Frame
from drivers.pairing import DropPolicy, PairingConfig
from drivers.url import RigUrl
from ghnerf_runtime.errors import RigFileError
from ghnerf_runtime.geometry import Rig
from ghnerf_runtime.rig_file import load_rig

log = logging.getLogger(__name__)

#: ``api=`` -> OpenCV's capture backend constant.
APIS = {"any": cv2.CAP_ANY, "v4l2": cv2.CAP_V4L2, "ffmpeg": cv2.CAP_FFMPEG, "gstreamer": cv2.CAP_GSTREAMER,
        "dshow": cv2.CAP_DSHOW, "msmf": cv2.CAP_MSMF, "avfoundation": cv2.CAP_AVFOUNDATION}
VIDEO_SUFFIXES = (".mp4", ".avi", ".mkv", ".mov", ".webm", ".m4v", ".mpg", ".mpeg")
#: Frame rate assumed for pacing a video whose container does not say.
FALLBACK_FPS = 30.0


@dataclass(frozen=True)
class OpenCVOptions:
    """The URL's options, validated (see the module docstring)."""

    first: str
    second: str
    rig_path: str | None = None
    width: int | None = None
    height: int | None = None
    fps: float | None = None
    fourcc: str | None = None
    api: str = "any"
    names: tuple[str, str] = ("left", "right")
    hfov_deg: float = 70.0
    loop: bool = False
    queue: int = 4
    pairing: PairingConfig = field(default_factory=PairingConfig)

    @classmethod
    def from_url(cls, url: RigUrl) -> "OpenCVOptions":
        if url.target:
            raise RigConfigError(f"rig URL {url.url!r}: name the cameras with first= and second=, "
                                 f"e.g. opencv://?first=0&second=1")
        first, second = url.take_str("first"), url.take_str("second")
        for name, value in (("first", first), ("second", second)):
            if not value:
                raise RigConfigError(f"rig URL {url.url!r}: option {name}= (a device index, a device path, a video "
                                     f"file or a stream URL) is required")
        fourcc = url.take_str("fourcc")
        if fourcc is not None and (len(fourcc) != 4 or not fourcc.isascii() or not fourcc.isprintable()):
            raise RigConfigError(f"rig URL {url.url!r}: option fourcc={fourcc!r} must be four characters, e.g. MJPG")
        names = tuple(n.strip() for n in (url.take_str("names", "left,right") or "").split(","))
        if len(names) != 2 or not all(names) or names[0] == names[1]:
            raise RigConfigError(f"rig URL {url.url!r}: option names= must be two different names, e.g. left,right")
        fps = url.take_float("fps", 0.0, lo=0.0, hi=1000.0) or None
        tolerance_default = 500.0 / (fps or FALLBACK_FPS)  # half a frame period: every frame finds its nearest
        options = cls(
            first=first, second=second,  # type: ignore[arg-type]
            rig_path=url.take_str("rig"),
            width=url.take_int("width", 0, lo=0, hi=16384) or None,
            height=url.take_int("height", 0, lo=0, hi=16384) or None,
            fps=fps,
            fourcc=fourcc,
            api=url.take_str("api", "any", choices=tuple(APIS)) or "any",
            names=(names[0], names[1]),
            hfov_deg=url.take_float("hfov", 70.0, lo=10.0, hi=170.0),
            loop=url.take_bool("loop", False),
            queue=url.take_int("queue", 4, lo=1, hi=256),
            pairing=PairingConfig(
                tolerance_ms=url.take_float("tolerance_ms", tolerance_default, lo=0.001, hi=10_000.0),
                policy=DropPolicy(url.take_str("policy", DropPolicy.LATEST.value,
                                               choices=tuple(p.value for p in DropPolicy))),
            ),
        )
        url.finish()
        if (options.width is None) != (options.height is None):
            raise RigConfigError(f"rig URL {url.url!r}: give width= and height= together")
        return options


def capture_target(spec: str) -> int | str:
    """What ``cv2.VideoCapture`` is given for ``first=`` / ``second=``: a device index as an int."""
    return int(spec) if spec.isdigit() else spec


def is_video_file(spec: str) -> bool:
    """A file played at its own pace (not a live camera or stream)."""
    return not spec.isdigit() and "://" not in spec and spec.lower().endswith(VIDEO_SUFFIXES)


class _Camera:
    """One ``cv2.VideoCapture`` and the thread that grabs from it into the shared queue."""

    def __init__(self, name: str, spec: str, capture: Any, source: "OpenCVRigSource") -> None:
        self.name, self.spec, self.capture, self.source = name, spec, capture, source
        self.video = is_video_file(spec)
        fps = float(capture.get(cv2.CAP_PROP_FPS) or 0.0)
        self.fps = fps if 0.0 < fps < 1000.0 else (source.options.fps or FALLBACK_FPS)
        self.index = 0
        self.thread = threading.Thread(target=self._run, name=f"opencv {name}", daemon=True)

    def size(self) -> tuple[int, int]:
        return int(self.capture.get(cv2.CAP_PROP_FRAME_WIDTH)), int(self.capture.get(cv2.CAP_PROP_FRAME_HEIGHT))

    def _run(self) -> None:
        src = self.source
        since_rewind = 0  # frames since the start (or the last rewind): a video that yields none never loops
        try:
            while not src._stop.is_set():
                if not self.capture.grab():
                    if self.video and src.options.loop and since_rewind > 0:
                        self.capture.set(cv2.CAP_PROP_POS_FRAMES, 0)  # indices and stamps run on across passes
                        since_rewind = 0
                        continue
                    if self.video:
                        src._end(self.name, EndOfStream(f"video {self.spec} (camera {self.name!r}) ended after "
                                                        f"{self.index} frames"))
                    else:
                        src._put(RigDisconnectedError(f"camera {self.name!r} ({self.spec}) stopped delivering frames "
                                                      f"(unplugged?)"))
                    return
                grabbed_ns = src.clock.now_ns()
                since_rewind += 1
                ok, image = self.capture.retrieve()
                if not ok or image is None:
                    src._put(RigDisconnectedError(f"camera {self.name!r} ({self.spec}): a grabbed frame could not be "
                                                  f"decoded"))
                    return
                if self.video:  # paced: due at its frame number's time from the shared start
                    stamp = src._anchor_ns + round(self.index * 1e9 / self.fps)
                    src.clock.sleep_until(stamp)
                else:
                    stamp = grabbed_ns
                src._put(Frame(camera=self.name, image=_bgr(image), timestamp_ns=stamp, index=self.index))
                self.index += 1
        except Exception as e:  # noqa: BLE001 - a capture backend failing: the reader gets it, typed
            src._put(RigOperationError(f"camera {self.name!r} ({self.spec}): {type(e).__name__}: {e}"))


def _bgr(image: np.ndarray) -> np.ndarray:
    """``(H, W, 3)`` uint8 BGR, as every frame is (a grey camera's frames are expanded)."""
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    return image


class OpenCVRigSource(RigSource):
    """Two ``cv2.VideoCapture`` cameras as a rig (see the module docstring).

    Args:
        options: validated URL options.
        rig: the calibration (its first two cameras are ``first`` and ``second``); ``None``: a nominal one.
        capture_factory: builds a capture from ``(target, api)`` (default ``cv2.VideoCapture``).
    """

    scheme = "opencv"

    def __init__(self, options: OpenCVOptions, *, rig: Rig | None = None,
                 capture_factory: Callable[[int | str, int], Any] = cv2.VideoCapture,
                 pairing: PairingConfig | None = None, clock: Clock | None = None) -> None:
        super().__init__(None, pairing=pairing or options.pairing, clock=clock)
        if clock is not None and not isinstance(clock, MonotonicClock):
            raise RigConfigError("opencv:// runs on the real clock (its cameras do)")
        self.options = options
        self._fixed_rig = rig
        self._capture_factory = capture_factory
        self._cameras: list[_Camera] = []
        self._queue: deque[Frame | Exception] = deque()
        self._per_camera: dict[str, int] = {}
        self._ended: set[str] = set()  # cameras whose video has ended
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._anchor_ns = 0
        self.frames_overflowed = 0  # taken from a full per-camera queue before the reader got to them

    @classmethod
    def from_url(cls, url: RigUrl, *, rig: Rig | None = None,
                 capture_factory: Callable[[int | str, int], Any] = cv2.VideoCapture,
                 pairing: PairingConfig | None = None, clock: Clock | None = None) -> "OpenCVRigSource":
        options = OpenCVOptions.from_url(url)
        if rig is None and options.rig_path is not None:
            try:
                rig = load_rig(options.rig_path)
            except RigFileError as e:
                raise RigConfigError(f"rig URL {url.url!r}: option rig={options.rig_path}: {e}") from e
        if rig is not None and options.width is not None and (options.width, options.height) != \
                (rig.pair[0].width, rig.pair[0].height):
            raise RigConfigError(f"rig URL {url.url!r}: width={options.width}&height={options.height} but the rig "
                                 f"file's cameras are {rig.pair[0].width}x{rig.pair[0].height}")
        return cls(options, rig=rig, capture_factory=capture_factory, pairing=pairing, clock=clock)

    # ------------------------------------------------------------------ hooks
    def _open(self) -> None:
        o = self.options
        names = (self._fixed_rig.pair[0].name, self._fixed_rig.pair[1].name) if self._fixed_rig else o.names
        try:
            for name, spec in zip(names, (o.first, o.second)):
                self._cameras.append(_Camera(name, spec, self._start_capture(name, spec), self))
            sizes = [cam.size() for cam in self._cameras]
            rig = self._fixed_rig or self._nominal_rig(sizes)
            for cam, size, rig_cam in zip(self._cameras, sizes, rig.pair):
                if size != (rig_cam.width, rig_cam.height):
                    raise RigInitializationError(
                        f"camera {cam.name!r} ({cam.spec}) delivers {size[0]}x{size[1]} but the rig's camera is "
                        f"{rig_cam.width}x{rig_cam.height}" + ("" if cam.video else "; it may not offer that size "
                                                               "(v4l2-ctl --list-formats-ext lists what it does)"))
        except BaseException:
            self._release()
            raise
        if self._fixed_rig is None:
            log.warning("opencv://: no rig= given: a nominal, uncalibrated rig (%g deg field of view) names the "
                        "cameras; calibrate with ghcal before trusting 3D joints", o.hfov_deg)
        self._set_rig(rig)
        self._per_camera = {cam.name: 0 for cam in self._cameras}
        self._anchor_ns = self.clock.now_ns()
        for cam in self._cameras:
            cam.thread.start()

    def _start_capture(self, name: str, spec: str) -> Any:
        o = self.options
        capture = self._capture_factory(capture_target(spec), APIS[o.api])
        if not capture.isOpened():
            capture.release()
            raise RigInitializationError(f"camera {name!r}: OpenCV cannot open {spec!r} (api={o.api}): "
                                         + ("no such file or not a video OpenCV decodes" if is_video_file(spec) else
                                            "not plugged in, busy in another program, or no permission "
                                            "(the video group)"))
        if not is_video_file(spec):
            # FOURCC first: a webcam offers its larger sizes only compressed.
            if o.fourcc:
                capture.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter_fourcc(*o.fourcc))
            width, height = (o.width, o.height) if o.width else \
                ((self._fixed_rig.pair[0].width, self._fixed_rig.pair[0].height) if self._fixed_rig else (None, None))
            if width:
                capture.set(cv2.CAP_PROP_FRAME_WIDTH, width)
                capture.set(cv2.CAP_PROP_FRAME_HEIGHT, height)
            if o.fps:
                capture.set(cv2.CAP_PROP_FPS, o.fps)
            capture.set(cv2.CAP_PROP_BUFFERSIZE, 1)  # the newest frame, not one queued in the driver
        return capture

    def _nominal_rig(self, sizes: list[tuple[int, int]]) -> Rig:
        from drivers.sim.placement import RigPlacement  # a plausible two-camera placement, metres

        if sizes[0] != sizes[1]:
            raise RigInitializationError(f"the cameras deliver {sizes[0][0]}x{sizes[0][1]} and "
                                         f"{sizes[1][0]}x{sizes[1][1]}; give width= and height= so both match")
        width, height = sizes[0]
        return RigPlacement(width=width, height=height, hfov_deg=self.options.hfov_deg,
                            names=self.options.names).build(rig_id="opencv-uncalibrated")

    def _put(self, item: Frame | Exception) -> None:
        """From a grabbing thread: queue a frame (the oldest of its camera goes when it holds ``queue``)."""
        with self._cond:
            if isinstance(item, Frame):
                if self._per_camera[item.camera] >= self.options.queue:
                    for k, queued in enumerate(self._queue):
                        if isinstance(queued, Frame) and queued.camera == item.camera:
                            del self._queue[k]
                            break
                    self.frames_overflowed += 1
                else:
                    self._per_camera[item.camera] += 1
            self._queue.append(item)
            self._cond.notify_all()

    def _end(self, camera: str, end: EndOfStream) -> None:
        """From a video's thread at its end: the stream ends once every camera has (the other's last
        frames, decoded a little later, still make their pairs)."""
        with self._cond:
            self._ended.add(camera)
            if self._ended >= set(self._per_camera):
                self._queue.append(end)
                self._cond.notify_all()

    def _read_frame(self, timeout_s: float) -> Frame | None:
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while not self._queue:
                left = deadline - time.monotonic()
                if left <= 0 or self._stop.is_set():
                    return None
                self._cond.wait(left)
            item = self._queue.popleft()
            if isinstance(item, Exception):
                self._queue.appendleft(item)  # stays: every later read raises it too, until close
                raise item
            self._per_camera[item.camera] -= 1
            return item

    def _frame_available(self) -> bool:
        with self._cond:
            return bool(self._queue) and isinstance(self._queue[0], Frame)

    def _close(self) -> None:
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        for cam in self._cameras:
            if cam.thread.is_alive():
                cam.thread.join(timeout=2.0)  # a grab blocked on a dead camera returns with its timeout
        self._release()

    def _release(self) -> None:
        for cam in self._cameras:
            try:
                cam.capture.release()
            except Exception as e:  # noqa: BLE001 - releasing a vanished device: it is gone either way
                log.debug("opencv: releasing %s: %s", cam.spec, e)
        self._cameras = []
