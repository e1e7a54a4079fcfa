"""``opencv://``: two cameras that OpenCV opens: USB (UVC) webcams, video files, network streams.

For a rig without an OAK: two webcams calibrated with ``ghcal``, or two videos of one take played
as if live. Examples::

    opencv://?first=/dev/v4l/by-id/usb-A-video-index0&second=/dev/v4l/by-id/usb-B-video-index0
    opencv://?first=/dev/video0&second=/dev/video2&rig=/etc/ghnerf/rig.json&fourcc=MJPG&fps=30
    opencv://?first=take/left.mp4&second=take/right.mp4&rig=rig.json   # two videos of one take

Options:

* ``first``, ``second`` (required): what ``cv2.VideoCapture`` opens for the rig's first and second
  camera: a device path, a device index (``0``), a video file, or a stream URL (percent-encoded
  inside the query: ``rtsp%3A%2F%2Fcam1%2Fstream``; its password, ``user:pass@`` or ``token=``, is shown as
  ``***`` in messages, logs and a recording's manifest). Prefer the stable paths under
  ``/dev/v4l/by-id/`` (or ``by-path/``, for two webcams of one model): indices can swap between
  boots, which would swap left and right under a rig file of the same size, and on Linux each
  webcam usually takes two nodes (``/dev/video0`` and its metadata node ``/dev/video1``), so the
  second webcam is ``/dev/video2``, not ``1``. A still image (a PNG or JPEG, told by its content whatever its
  name) is no video: refused at :meth:`open` with :class:`~drivers.errors.RigConfigError` naming the option, since
  session 64 (FFmpeg opens it as a one-frame video: the stream delivered one pair, then ended, "video ... ended after
  1 frames"); play still images as a ``replay://`` take (docs/recording-format.md). An animated PNG or GIF plays as
  a video.
* ``rig``: the rig file (``ghcal solve``); its first two cameras are ``first`` and ``second``, in
  that order, and their image sizes are asked of the cameras and checked on every frame. Without
  it the source has a nominal, uncalibrated rig (``hfov``, ``names``, the size the cameras deliver):
  enough for ``ghcal capture``, not for 3D joints (the daemon refuses it).
* ``width``, ``height`` (without ``rig``): the size asked of live cameras and required of every
  frame, videos' too; ``fps``, ``fourcc``: the rate and format asked of live cameras (two webcams on
  one USB bus usually need ``fourcc=MJPG``). A size a camera does not deliver (``width``/``height``
  or the rig file's) is an error at :meth:`open` (:class:`~drivers.errors.FrameSizeError`; against a
  rig file it says whether the file looks calibrated at another resolution: :func:`rig_size_message`);
  a rate or format it does not take is a warning. ``fps`` is also the pace of a video whose file does
  not state its rate.
* ``api``: OpenCV's capture backend: ``any`` (default), ``v4l2``, ``ffmpeg``, ``gstreamer``,
  ``dshow``, ``msmf``, ``avfoundation``. One this OpenCV lacks (a build without GStreamer) fails the open saying
  so, naming those it has (since session 73; it was said to be an unplugged camera or a file it cannot decode).
* ``names``, ``hfov`` (without ``rig``): the nominal rig's camera names (default ``left,right``) and
  horizontal field of view in degrees (20 to 150, default 70).
* ``loop`` (two videos of the same length in time: 40 frames at 30 fps and 20 at 15 fps are): start
  over at the end instead of ending the stream; refused for two live cameras (since session 73: it did nothing).
* ``tolerance_ms``: pairing tolerance (default: half a frame period at the slowest of the rates
  the cameras report and ``fps``, else 30 fps; at most 10 s); ``policy``: ``latest`` (default) or ``all``;
  ``max_pending`` (8, at most 256): frames held per camera while waiting for the other's: a camera
  whose frames reach the host that many frames after the other's (a slower USB path or
  hub) never pairs unless it is raised (:mod:`drivers.pairing_options`);
  ``queue``: frames held per camera for the reader (default 4, at most 256; under ``latest`` each read
  takes in all of them and returns the newest pair; a camera whose queue is full loses its oldest
  frame, counted in ``stats.overruns`` (and, between frames the pairer saw, in ``stats.camera_gaps``);
  two videos are read in step, neither past the other's next frame (in time: they may differ in
  rate), so one that decodes slower than its rate holds the other back and their frames still pair;
  under ``all`` they also wait for room instead of dropping: every pair of the take is delivered,
  however slowly one decodes);
  ``open_timeout_s``: how long :meth:`open` waits for each camera's first frame (default 10), and how
  long a live camera may then go without delivering one before it counts as disconnected. A
  failed :meth:`open` is final: open a new source.

Timing. Each camera's capture is opened by :meth:`open`, then owned by that camera's thread, which
grabs, decodes and queues its frames and releases the capture when it stops (never while it is
being read). A live camera's frame is stamped with the host's monotonic clock when its grab
returns, except where both cameras are V4L2 devices (Linux webcams): there each frame carries the
kernel's own stamp of its capture (``CAP_PROP_POS_MSEC``, on the same monotonic clock), which a busy
host's late wake-ups do not delay. A driver stamp that is not on that clock (in the future, more than
``DRIVER_STAMP_MAX_AGE_S`` before the grab, or not after the camera's previous one) turns driver stamps off
for both cameras, with a warning, so the two are never stamped differently for long. Webcams are not synchronised in hardware, so a pair
is two frames within ``tolerance_ms``:
the default pairs each frame with the other camera's nearest, so a fast movement is seen up to
half a frame apart by the two cameras (an OAK's shared trigger avoids that). That default leaves
no margin for a camera slower than it reports (auto-exposure in dim light can halve a webcam's
rate): give ``fps=`` the rate it really keeps, or a ``tolerance_ms``. A network stream's
frames are stamped on arrival, after its own buffering, which may differ between the two streams.
A video is a file (a path that is not a device index, not under ``/dev/``, not a URL and not a
GStreamer pipeline, which has ``!`` between its elements and is live; an OpenCV
image sequence such as ``seq/%04d.png`` counts): it is paced at its rate from a start
shared by both files and stamped by its frame number, so two constant-rate videos that start at
the same instant pair frame by frame (a phone's variable-rate video drifts). Its frames are read as stored: a
rotation in its container (a phone's, held upright) is ignored, as an image's EXIF orientation is
(:func:`ghnerf_runtime.video_files.read_as_stored`). Not modelled:
exposure, white balance or rolling-shutter differences between the two cameras.

Ends. A live camera that stops delivering (unplugged: ``MAX_UNDECODABLE`` failed grabs in a row, a frame period
apart; fewer are tried again, since session 73) raises :class:`RigDisconnectedError` from the
next read, after the frames it delivered before; so does one whose grab hangs (a stalled stream or
pipeline) for ``open_timeout_s``, naming it, and one whose grabbed frames do not decode ``MAX_UNDECODABLE``
times in a row (fewer are skipped). Each frame lost to a failed grab tried again or to a frame skipped is a gap in
the camera's frame index (``stats.camera_gaps``), and a run of them is one warning, naming the frames
and why (since session 74: a failed grab tried again was neither logged nor counted, and each skipped frame was a
warning of its own, a flood at 30 fps). The warning comes as the reader takes the frame after the run, when the
gap is counted (:mod:`drivers.backends.opencv_lost`), and says whether it is: not where that frame is the camera's
first the reader took, nor (said at the close) where the close came before the reader took it; a run still going
when the source is closed is said as the camera's thread ends, "still going at close" (since session 75), not
counted: no frame follows it. The runs whose frame after them the full queue dropped unread (a reader that does not
read while the camera loses frame after frame) are held as one, "frames A to B in N runs (...)", one warning: they
were held one each, without bound, and said one warning each. When a video ends, the stream ends
(:class:`EndOfStream`) once the other camera has delivered past the ended one's last frame: no pair
can follow, so a longer video is not played out to its end.

Closing from another thread. A :meth:`close` that lands while :meth:`open` runs ends the open's wait for the cameras'
first frames at once (it waited out ``open_timeout_s``) and no further camera is opened; the open releases, on its own
thread, what it opened and raises :class:`~drivers.errors.RigInitializationError` ("closed while open() started its
cameras"). The close does not wait for that: a capture OpenCV is still opening cannot be interrupted (a stream's
open can take its own timeout), so :meth:`lingering` names each camera the open still holds (opened, being opened,
its thread in a grab) until it is released; it said nothing. A read the close lands in hands out no frame, not even
one queued before the close: :class:`RigOperationError` ("closed while a read waited for its frame", as ``sim://``
and ``replay://`` say).
"""
from __future__ import annotations

import logging
import math
import os
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from drivers.backends.opencv_lost import RUN_CLOSED, RUN_ENDED, LostRun, UnreadRuns
from drivers.base import RigSource, load_rig_option
from drivers.clock import Clock, MonotonicClock
from drivers.errors import (
    EndOfStream,
    FrameSizeError,
    RigConfigError,
    RigDisconnectedError,
    RigInitializationError,
    RigOperationError,
)
from drivers.frames import Frame
from drivers.pairing import MAX_TOLERANCE_MS, DropPolicy, PairingConfig, PairingStats
from drivers.pairing_options import PairingOptions, take_pairing_options
from drivers.url import RigUrl, redact_url
from ghnerf_runtime.geometry import Rig
from ghnerf_runtime.video_files import is_still_image, read_as_stored

log = logging.getLogger(__name__)
#: The rig id of the nominal rig an ``opencv://`` source without ``rig=`` makes (for ``ghcal capture`` only).
NOMINAL_RIG_ID = "opencv-uncalibrated"


def is_nominal_rig(rig: Rig) -> bool:
    """Whether ``rig`` is that nominal, uncalibrated rig (also as a recording of it replays it)."""
    return bool(rig.metadata.get("uncalibrated")) or rig.rig_id == NOMINAL_RIG_ID

#: ``api=`` -> OpenCV's capture backend constant.
APIS = {"any": cv2.CAP_ANY, "v4l2": cv2.CAP_V4L2, "ffmpeg": cv2.CAP_FFMPEG, "gstreamer": cv2.CAP_GSTREAMER,
        "dshow": cv2.CAP_DSHOW, "msmf": cv2.CAP_MSMF, "avfoundation": cv2.CAP_AVFOUNDATION}
#: Frame rate assumed where neither the camera nor ``fps=`` says.
FALLBACK_FPS = 30.0
#: The nominal rig's field of view bounds (those of :class:`drivers.sim.placement.RigPlacement`).
HFOV_RANGE = (20.0, 150.0)
#: The nominal rig's image size bounds, each way (those of :class:`drivers.sim.placement.RigPlacement`).
NOMINAL_SIZE_RANGE = (16, 8192)
#: A V4L2 driver's frame stamp older than this at the grab is not on the host's monotonic clock.
DRIVER_STAMP_MAX_AGE_S = 2.0
#: Grabbed frames in a row that cannot be decoded, or a live camera's grabs in a row that fail, before it counts as
#: lost (fewer are skipped, or tried again).
MAX_UNDECODABLE = 10
#: The largest device index ``cv2.VideoCapture`` takes (a C int).
MAX_DEVICE_INDEX = 2**31 - 1


@dataclass
class OpenCVRigStats(PairingStats):
    """Pairing counters plus the frames each camera lost from its full queue before pairing (a slow reader)."""

    overruns: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class OpenCVOptions:
    """The URL's options, validated (see the module docstring). ``pairing.tolerance_ms`` None: from the cameras'
    rate."""

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
    open_timeout_s: float = 10.0
    pairing: PairingOptions = PairingOptions()

    @classmethod
    def from_url(cls, url: RigUrl) -> "OpenCVOptions":
        def fail(message: str) -> RigConfigError:
            return RigConfigError(f"rig URL {url.url!r}: {message}")

        if url.target:
            raise fail("name the cameras with first= and second=, e.g. opencv://?first=/dev/video0&second=/dev/video2")
        first, second = url.take_str("first"), url.take_str("second")
        for name, value in (("first", first), ("second", second)):
            if not value:
                raise fail(f"option {name}= (a device path or index, a video file or a stream URL) is required")
        for name, value in (("first", first), ("second", second)):
            if is_device_index(value) and _index_too_large(value):  # type: ignore[arg-type]
                # cv2.VideoCapture takes a C int: a larger index was a bare cv2.error naming no option
                raise fail(f"option {name}={value!r}: a device index is at most {MAX_DEVICE_INDEX}")
        if _same_camera(first, second):  # type: ignore[arg-type]
            raise fail(f"first= and second= are the same camera ({redact_url(first)!r}, {redact_url(second)!r})")
        rig_path = url.take_str("rig")
        given = set(url.options)
        fourcc = url.take_str("fourcc")
        if fourcc is not None and (len(fourcc) != 4 or not fourcc.isascii() or not fourcc.isprintable()):
            raise fail(f"option fourcc={fourcc!r} must be four characters, e.g. MJPG")
        names = tuple(n.strip() for n in (url.take_str("names", "left,right") or "").split(","))
        if len(names) != 2 or not all(names) or names[0] == names[1]:
            raise fail("option names= must be two different names, e.g. left,right")
        options = cls(
            first=first, second=second,  # type: ignore[arg-type]
            rig_path=rig_path,
            # the nominal rig's bounds: width= and height= are given without rig=, for it
            width=url.take_int("width", 0, lo=NOMINAL_SIZE_RANGE[0], hi=NOMINAL_SIZE_RANGE[1]) or None,
            height=url.take_int("height", 0, lo=NOMINAL_SIZE_RANGE[0], hi=NOMINAL_SIZE_RANGE[1]) or None,
            fps=url.take_float("fps", 0.0, lo=0.1, hi=1000.0) or None,
            fourcc=fourcc,
            api=url.take_str("api", "any", choices=tuple(APIS)) or "any",
            names=(names[0], names[1]),
            hfov_deg=url.take_float("hfov", 70.0, lo=HFOV_RANGE[0], hi=HFOV_RANGE[1]),
            loop=url.take_bool("loop", False),
            queue=url.take_int("queue", 4, lo=1, hi=256),
            open_timeout_s=url.take_float("open_timeout_s", 10.0, lo=0.1, hi=600.0),
            pairing=take_pairing_options(url),
        )
        url.finish()
        if options.loop and not (is_video_file(options.first) or is_video_file(options.second)):
            raise fail("option loop=1 starts videos over; first= and second= are live cameras (loop= did nothing)")
        if (options.width is None) != (options.height is None):
            raise fail("give width= and height= together")
        if rig_path is not None:
            pointless = sorted(given & {"width", "height", "names", "hfov"})
            if pointless:
                raise fail(f"option(s) {pointless} do not apply with rig= (the rig file sets the cameras' names "
                           f"and sizes)")
        return options


def _closed_while_reading() -> RigOperationError:
    """What a read raises when another thread closes the source under it (sim:// and replay:// say the same)."""
    return RigOperationError("opencv:// source closed while a read waited for its frame")


def _closed_during_open() -> RigInitializationError:
    """What an open() raises when another thread closes the source while it opens the cameras or waits for their
    first frames (worded as sim://, replay:// and depthai:// word theirs)."""
    return RigInitializationError("opencv:// source closed while open() started its cameras: the open was cancelled")


def _same_camera(first: str, second: str) -> bool:
    """Two specs naming one device (an index and its /dev/videoN, a by-id link and its target) or one file."""
    def resolved(spec: str) -> str:
        if "://" in spec:
            return spec
        return os.path.realpath(f"/dev/video{device_index(spec)}" if is_device_index(spec) else spec)  # 00 is 0
    return resolved(first) == resolved(second)


def is_device_index(spec: str) -> bool:
    """``0``, ``2``: ASCII digits only (``str.isdigit`` is true of ``²``, which ``int`` refuses: a bare
    ValueError from the URL, naming no option)."""
    return spec.isascii() and spec.isdigit()


def capture_target(spec: str) -> int | str:
    """What ``cv2.VideoCapture`` is given for ``first=`` / ``second=``: a device index as an int."""
    return device_index(spec) if is_device_index(spec) else spec


def device_index(spec: str) -> int:
    """A device index (:func:`is_device_index`) as an int, its leading zeros dropped first: ``int()`` refuses text
    of over 4300 digits (a bare ValueError naming no option), ``00...01`` included."""
    return int(spec.lstrip("0") or "0")


def _index_too_large(spec: str) -> bool:
    """A device index over :data:`MAX_DEVICE_INDEX`, told by its digits before any ``int()`` (:func:`device_index`)."""
    digits = spec.lstrip("0")
    return len(digits) > len(str(MAX_DEVICE_INDEX)) or device_index(spec) > MAX_DEVICE_INDEX


def is_video_file(spec: str) -> bool:
    """A video file or image sequence, played at its own pace; a device, a stream or a GStreamer
    pipeline (its elements linked by ``!``, e.g. a Jetson's CSI camera: ``nvarguscamerasrc ! ... !
    appsink``) is live."""
    return not is_device_index(spec) and "://" not in spec and not spec.startswith("/dev/") and "!" not in spec


class _Camera:
    """One ``cv2.VideoCapture`` and the thread that owns it: grabs, decodes, checks and queues its frames."""

    def __init__(self, name: str, option: str, spec: str, size: tuple[int, int] | None,
                 source: "OpenCVRigSource") -> None:
        self.name, self.option, self.spec, self.source = name, option, spec, source  # option: "first" or "second"
        self.shown = redact_url(spec)  # in messages and logs: a stream URL's password never
        self.size = size  # (width, height) every frame must have; None: the first frame's (a nominal rig)
        self.size_from = "rig" if source._fixed_rig is not None else ("asked" if size is not None else "first")
        self.video = is_video_file(spec)
        self.capture: Any = None
        self.fps = 0.0  # as the camera or file reports it (0: unknown)
        self.frame_count = 0  # a video's, as its container says (0: unknown)
        self.index = 0
        self.index_queued = -1  # the last queued frame's index (written under the source's lock)
        self.at_pass_end = False  # loop: waiting for the other video to end its pass (under the lock)
        self.last_stamp_ns = -1  # the last queued frame's (written under the source's lock)
        self.last_frame_s = 0.0  # time.monotonic() of its last queued frame, or of its start (under the lock)
        self.v4l2 = False  # a live V4L2 device: its driver stamps frames on the host's monotonic clock
        self.lost = LostRun()  # the frames lost since its last queued frame (its own thread's)
        self.opening = False  # open() is opening its capture (set under the source's lock: see _open_camera)
        self.thread = threading.Thread(target=self._run, name=f"opencv {name}", daemon=True)

    @property
    def holds_device(self) -> bool:
        """Whether the camera still holds its device: being opened, its capture not yet released (by its thread as
        it ends, or by the close where no thread started), or its thread still running."""
        return self.opening or self.capture is not None or self.thread.is_alive()

    # The capture is opened on the caller's thread (errors are raised from open()), then only the
    # camera's own thread touches it, and releases it when it stops.
    def open(self) -> None:
        o = self.source.options
        if self.video and "%" not in self.spec and not os.path.exists(self.spec):
            raise RigInitializationError(f"camera {self.name!r}: no such video file {self.shown!r}")
        if self.video and is_still_image(self.spec):
            raise RigConfigError(still_image_message(self.option, self.shown, self.name))
        capture = self.source._capture_factory(capture_target(self.spec), APIS[o.api])
        if not capture.isOpened():
            capture.release()
            why = missing_api(o.api)
            if why is not None:
                raise RigInitializationError(f"camera {self.name!r}: OpenCV cannot open {self.shown!r}: {why}")
            raise RigInitializationError(
                f"camera {self.name!r}: OpenCV cannot open {self.shown!r} (api={o.api}): "
                + ("not a video OpenCV decodes" if self.video else
                   "not plugged in, busy in another program, no permission (the video group), or not this index "
                   "(a webcam's second node is its metadata: use /dev/v4l/by-id/ paths)"))
        self.capture = capture
        if self.video:  # as stored, a phone's rotation ignored (a device's or a stream's frames: nothing to turn)
            read_as_stored(capture, self.shown)
        else:
            self.v4l2 = _backend_name(capture) == "V4L2"
            # FOURCC first: a webcam offers its larger sizes only compressed.
            if o.fourcc:
                capture.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter_fourcc(*o.fourcc))
            if self.size is not None:
                capture.set(cv2.CAP_PROP_FRAME_WIDTH, self.size[0])
                capture.set(cv2.CAP_PROP_FRAME_HEIGHT, self.size[1])
            if o.fps:
                capture.set(cv2.CAP_PROP_FPS, o.fps)
            got_fourcc = int(capture.get(cv2.CAP_PROP_FOURCC))
            if o.fourcc and got_fourcc and got_fourcc != cv2.VideoWriter_fourcc(*o.fourcc):
                log.warning("camera %r (%s) did not take fourcc=%s", self.name, self.shown, o.fourcc)
        fps = float(capture.get(cv2.CAP_PROP_FPS) or 0.0)
        self.fps = fps if 0.0 < fps < 1000.0 else 0.0
        if not self.video and o.fps and self.fps and abs(self.fps - o.fps) > 0.5:
            log.warning("camera %r (%s) runs at %.1f fps, not the fps=%g asked", self.name, self.shown, self.fps, o.fps)
        self.frame_count = max(int(capture.get(cv2.CAP_PROP_FRAME_COUNT) or 0), 0) if self.video else 0

    def release(self) -> None:
        if self.capture is not None:
            try:
                self.capture.release()
            except Exception as e:  # noqa: BLE001 - releasing a vanished device: it is gone either way
                log.debug("opencv: releasing %s: %s", self.shown, e)
            self.capture = None

    @property
    def pace_fps(self) -> float:
        return self.fps or self.source.options.fps or FALLBACK_FPS

    def due_ns(self, index: int) -> int:
        """A video's frame ``index``: its stamp, and when it is due, from the start both videos share."""
        return self.source._anchor_ns + round(index * 1e9 / self.pace_fps)

    def _run(self) -> None:
        src = self.source
        try:
            self._grab_loop()
        except Exception as e:  # noqa: BLE001 - a capture backend failing: the reader gets it, typed
            src._fail(RigOperationError(f"camera {self.name!r} ({self.shown}): {type(e).__name__}: {e}"))
        finally:
            self.release()
            # a run still open as the thread ends (the source closed, or the stream failed) is said too, once
            self._end_lost_run(end=RUN_CLOSED if src._stop.is_set() else RUN_ENDED)

    def _grab_loop(self) -> None:
        src = self.source
        since_rewind = 0
        undecodable = 0  # grabbed frames in a row that did not decode
        failed_grabs = 0  # a live camera's grabs in a row that failed
        while not src._stop.is_set():
            if not self.capture.grab():
                failed_grabs += 1
                if not self.video and failed_grabs < MAX_UNDECODABLE:
                    # A stream's hiccup or a USB frame error fails one grab: tried again a frame later (no busy
                    # loop), where one such grab took the whole rig down; a run of them is a lost camera.
                    self.lost.failed_grabs += 1
                    self.index += 1  # the frame it lost: the camera's index gap, as an undecodable frame's
                    if src._stop.wait(1.0 / self.pace_fps):
                        return
                    continue
                if self.video and src.options.loop and since_rewind > 0:
                    # Each video starts over at its own end: two of one length stay paired frame by frame, as
                    # indices and stamps run on across passes; two of different lengths would not.
                    if not src._passed(self, since_rewind):
                        return
                    self.capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
                    since_rewind = 0
                    continue
                self._end_lost_run(end=RUN_ENDED)  # a run that ends the camera or video is said too
                if self.video:
                    src._end(self, EndOfStream(f"video {self.shown} (camera {self.name!r}) ended after {self.index} "
                                               f"frames"))
                elif self.index_queued < 0:  # not its index: the frames it lost moved that on
                    src._fail(RigInitializationError(
                        f"camera {self.name!r} ({self.shown}) opened but delivered no frame (two webcams on one USB "
                        f"bus: try fourcc=MJPG, a smaller size or a lower fps)"))
                else:
                    src._fail(RigDisconnectedError(f"camera {self.name!r} ({self.shown}) stopped delivering frames "
                                                   f"(unplugged?): {failed_grabs} grabs in a row failed"))
                return
            failed_grabs = 0
            grabbed_ns = src.clock.now_ns()
            since_rewind += 1
            ok, image = self.capture.retrieve()
            if not ok or image is None:
                # A webcam sharing a USB bus sends the odd truncated MJPG frame: skipped (a camera gap, as the
                # index moves on), where one such frame took the whole rig down; a run of them is a lost camera.
                undecodable += 1
                if undecodable < MAX_UNDECODABLE:
                    self.lost.undecodable += 1
                    self.index += 1
                    continue
                self._end_lost_run(end=RUN_ENDED)
                src._fail(RigDisconnectedError(f"camera {self.name!r} ({self.shown}): {undecodable} grabbed frames "
                                               f"in a row could not be decoded"))
                return
            undecodable = 0
            raw, image = image, _bgr(image)
            if image is None:
                src._fail(RigOperationError(f"camera {self.name!r} ({self.shown}) delivered an image that is not "
                                            f"8-bit colour or grey (shape {raw.shape}, {raw.dtype})"))
                return
            if self.size is not None and (image.shape[1], image.shape[0]) != self.size:
                src._fail(self._size_error((image.shape[1], image.shape[0])))
                return
            if self.size is None:
                self.size = (image.shape[1], image.shape[0])
            if self.video:  # paced: due at its frame number's time from the shared start
                stamp = self.due_ns(self.index)
                if src._stop.wait(max(0.0, (stamp - src.clock.now_ns()) / 1e9)):
                    return
            else:
                stamp = max(self._live_stamp(grabbed_ns), self.last_stamp_ns + 1)
            if not src._put(Frame(camera=self.name, image=image, timestamp_ns=stamp, index=self.index),
                            wait_room=self.video and src.pairing.policy is DropPolicy.ALL, lost=self.lost):
                return  # a frame refused (closed, failed): the thread's end says the run, as it ends
            if self.lost.frames:  # the source holds the run now: said as the reader takes this frame
                self.lost = LostRun()
            self.index += 1

    def _end_lost_run(self, *, end: str) -> None:
        """No frame will follow the run of frames lost (if any), ``end`` says why (``RUN_ENDED``, ``RUN_CLOSED``):
        it is logged, once."""
        words = self.lost.words(self.index, end)
        if words is not None:  # (none lost, the usual end: nothing to reset)
            log.warning("camera %r (%s) lost %s", self.name, self.shown, words)
            self.lost = LostRun()

    def _size_error(self, delivered: tuple[int, int]) -> FrameSizeError:
        """A frame of ``delivered`` (width, height), not this camera's size; worded by where that size came from."""
        got, (w, h) = f"{delivered[0]}x{delivered[1]}", self.size  # type: ignore[misc]
        if self.size_from == "rig":
            message = rig_size_message(self.name, self.shown, delivered, (w, h),
                                       rig_file=self.source.options.rig_path, live=not self.video)
        elif self.size_from == "asked":
            message = f"camera {self.name!r} ({self.shown}) delivered {got}, not the width={w}&height={h} asked"
        else:
            message = f"camera {self.name!r} ({self.shown}) delivered {got}, not the {w}x{h} of its first frame"
        return FrameSizeError(message, self.name, (w, h), delivered)

    def _live_stamp(self, grabbed_ns: int) -> int:
        """The frame's driver stamp where the source uses them (module docstring, Timing), else the grab's."""
        src = self.source
        if not src.driver_stamps:
            return grabbed_ns
        ms = float(self.capture.get(cv2.CAP_PROP_POS_MSEC))
        driver_ns = round(ms * 1e6) if math.isfinite(ms) else -1
        # A stamp at or before the previous frame's (a driver whose clock jumped back, or repeats a stamp) is
        # off the clock too: clamped after the previous one, the camera's frames would stay behind the other's
        # by the jump and never pair again.
        if grabbed_ns - DRIVER_STAMP_MAX_AGE_S * 1e9 <= driver_ns <= grabbed_ns and driver_ns > self.last_stamp_ns:
            return driver_ns
        src.driver_stamps = False
        log.warning("camera %r (%s): its driver's frame stamp (%.3f ms) is not on the host's monotonic clock (%.3f "
                    "ms at the grab, %.3f ms at its previous frame): both cameras' frames are stamped at their grab "
                    "from now on", self.name, self.shown, ms, grabbed_ns / 1e6, self.last_stamp_ns / 1e6)
        return grabbed_ns


def rig_size_message(camera: str, shown: str, delivered: tuple[int, int], expected: tuple[int, int], *,
                     rig_file: str | None, live: bool) -> str:
    """Why camera ``camera`` (``shown``: its device or file) delivering ``delivered`` (width, height) does not fit its
    rig camera of ``expected``, and what to do: the same shape at another scale is most likely a rig file calibrated
    at another resolution of this camera; another shape, another sensor mode or camera. No rig file is rescaled
    here: a mode of another resolution may also crop the sensor differently, and ghcal has no command for it."""
    (dw, dh), (rw, rh) = delivered, expected
    where = f"its rig camera in {rig_file}" if rig_file else "its rig camera"
    message = f"camera {camera!r} ({shown}) delivered {dw}x{dh}, but {where} is {rw}x{rh}"
    # the same aspect ratio, to 1 % of the rig's (854x480 against 1280x720): |dw/dh - rw/rh| <= 0.01 rw/rh, times
    # dh*rh. Measured against rw*rh the tolerance grew with the scale down (4 % at a quarter of the size)
    if abs(dw * rh - dh * rw) <= 0.01 * dh * rw:
        message += (f": the same shape at {dw / rw:.3g} times the size, so the rig file was most likely calibrated "
                    f"at another resolution of this camera")
    else:
        message += (f": another shape ({dw / dh:.3g}:1 against {rw / rh:.3g}:1), so another mode of the sensor "
                    f"(cropped) or another camera than the one calibrated")
    again = f"calibrate again at {dw}x{dh} (ghcal, docs/calibration.md)"
    if live:  # it was asked for the rig's size and did not take it
        mjpg = " (a webcam offers its larger sizes only compressed: add fourcc=MJPG to the URL)" if rw * rh > dw * dh \
            else ""
        return message + f"; have the camera deliver {rw}x{rh}{mjpg} or {again}"
    return message + f"; {again}, or use videos recorded at {rw}x{rh}"


def still_image_message(option: str, shown: str, camera: str) -> str:
    """Why a still image named by ``first=`` or ``second=`` is refused: OpenCV's FFmpeg backend opens a PNG or JPEG
    as a one-frame video, and the stream ended after its first pair ("video ... ended after 1 frames")."""
    return (f"opencv:// option {option}={shown} (camera {camera!r}): a still image, not a video (opencv:// would play "
            f"it as one frame and end); play still images as a replay:// take, a folder whose manifest.json and "
            f"frames.jsonl name them (docs/recording-format.md)")


def video_size(spec: str) -> tuple[int, int] | None:
    """The frame size a video file's container states (nothing decoded), None where OpenCV cannot say: the size as
    stored, as its frames are read (:func:`read_as_stored`), not turned by a rotation in its container."""
    capture = cv2.VideoCapture(spec)
    try:
        if not capture.isOpened():
            return None
        read_as_stored(capture, redact_url(spec))
        size = int(capture.get(cv2.CAP_PROP_FRAME_WIDTH) or 0), int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT) or 0)
    finally:
        capture.release()
    return size if size[0] > 0 and size[1] > 0 else None


def _pass_mismatch(videos: list[tuple[_Camera, int]]) -> str | None:
    """loop=1: None where passes of these many frames of the videos last as long (to a microsecond, so their
    stamps stay in step pass after pass: 40 frames at 30 fps and 20 at 15 fps do), else their lengths, for the
    error. Frame counts alone refused two videos of one take at two rates."""
    spans = [round(frames * 1e9 / cam.pace_fps) for cam, frames in videos]
    if max(spans) - min(spans) <= 1_000:
        return None
    if len({cam.pace_fps for cam, _ in videos}) == 1:
        return " and ".join(str(frames) for _, frames in videos) + " frames"
    return " and ".join(f"{frames} frames at {cam.pace_fps:g} fps" for cam, frames in videos)


def missing_api(api: str) -> str | None:
    """Why ``api=`` cannot open anything where this OpenCV lacks that capture backend (a build without GStreamer,
    DirectShow off Windows), naming the ones it has; None where it has it (or ``any``). Without it a camera that did
    not open was said to be unplugged, busy or without permission, or a video file not one OpenCV decodes."""
    registry = cv2.videoio_registry
    if api == "any" or registry.hasBackend(APIS[api]):
        return None
    present = sorted({registry.getBackendName(b) for b in registry.getBackends() if registry.hasBackend(b)})
    return (f"option api={api}: this OpenCV has no {api} capture backend (it has {', '.join(present) or 'none'}; "
            f"api=any picks one)")


def _backend_name(capture: Any) -> str:
    """The capture's OpenCV backend (``"V4L2"``, ``"FFMPEG"``, ...); ``""`` where it does not say."""
    try:
        return str(capture.getBackendName())
    except Exception:  # noqa: BLE001 - a backend without a name, or a stand-in: no driver stamps
        return ""


def _bgr(image: np.ndarray) -> np.ndarray | None:
    """``(H, W, 3)`` uint8 BGR, as every frame is (grey and BGRA converted); None for anything else, an empty image
    too (cvtColor's assertion on it was the error)."""
    if image.dtype != np.uint8 or image.size == 0:
        return None
    if image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 1):
        return cv2.cvtColor(image.reshape(image.shape[:2]), cv2.COLOR_GRAY2BGR)
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    return image if image.ndim == 3 and image.shape[2] == 3 else None


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
        if clock is not None and not isinstance(clock, MonotonicClock):
            raise RigConfigError("opencv:// runs on the real clock (its cameras do)")
        self._pairing_given = pairing is not None or options.pairing.tolerance_ms is not None
        super().__init__(None, pairing=pairing or options.pairing.config(500.0 / (options.fps or FALLBACK_FPS)),
                         clock=clock)
        self.options = options
        self._fixed_rig = rig
        self._capture_factory = capture_factory
        self._cameras: list[_Camera] = []
        self._queue: deque[Frame | Exception] = deque()
        self._per_camera: dict[str, int] = {}
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._anchor_ns = 0
        self._ending: tuple[int, EndOfStream] | None = None  # a video ended: (its last stamp, the end to raise)
        self._failed = False  # an end or a failure is queued: later frames are not
        self._delivered: set[str] = set()  # cameras that queued a frame (open() waits for both)
        self._ended: set[str] = set()  # videos that ended
        self._pass_frames: dict[str, list[int]] = {}  # loop: frames in each pass, per video
        self._open_cancelled = False  # a close() landed before or while open() ran (under the lock)
        self._overruns: dict[str, int] = {}  # per camera: frames dropped from a full queue before the reader took them
        self._unread_runs = UnreadRuns()  # runs of lost frames whose frame after them is queued, not yet read
        self.drain_limit = 2 * options.queue  # what the queues hold: under latest a read takes all of it
        self.driver_stamps = False  # both cameras are V4L2 devices whose driver stamps are used (Timing)

    @classmethod
    def from_url(cls, url: RigUrl, *, rig: Rig | None = None,
                 capture_factory: Callable[[int | str, int], Any] = cv2.VideoCapture,
                 pairing: PairingConfig | None = None, clock: Clock | None = None) -> "OpenCVRigSource":
        options = OpenCVOptions.from_url(url)
        from_file = rig is None and options.rig_path is not None
        if from_file:
            rig = load_rig_option(url, options.rig_path)
        source = cls(options, rig=rig, capture_factory=capture_factory, pairing=pairing, clock=clock)
        if from_file:
            source._rig_read_from(options.rig_path)
        return source

    @property
    def stats(self) -> OpenCVRigStats:
        with self._cond:
            overruns = dict(self._overruns)
        return OpenCVRigStats(**vars(super().stats), overruns=overruns)

    # ------------------------------------------------------------------ hooks
    def _open(self) -> None:
        o = self.options
        with self._cond:
            if self._open_cancelled:  # closed after open() checked, before this began
                raise _closed_during_open()
            if self._stop.is_set():
                # A thread of the failed attempt may still be in a grab; it must not feed a new one.
                raise RigOperationError("opencv://: an open() that failed is final: make a new source "
                                        "(drivers.open_rig)")
        if self._fixed_rig is not None:
            sizes = [(c.width, c.height) for c in self._fixed_rig.pair]
            names = [c.name for c in self._fixed_rig.pair]
        else:
            sizes = [(o.width, o.height) if o.width else None] * 2
            names = list(o.names)
        self._cameras = [_Camera(name, option, spec, size, self) for name, option, spec, size
                         in zip(names, ("first", "second"), (o.first, o.second), sizes)]
        self._per_camera = {cam.name: 0 for cam in self._cameras}
        self._overruns = {cam.name: 0 for cam in self._cameras}
        try:
            for cam in self._cameras:
                self._open_camera(cam)
            videos = [cam for cam in self._cameras if cam.video]
            mismatch = _pass_mismatch([(cam, cam.frame_count) for cam in videos]) \
                if o.loop and len(videos) == 2 and all(cam.frame_count for cam in videos) else None
            if mismatch:
                raise RigInitializationError(
                    f"loop=1: the videos have {mismatch}; looping them would pair different instants from the "
                    f"second pass on (trim them to one length)")
            if not self._pairing_given:
                # half a frame period at the slowest rate known: a camera's report, or fps= where that
                # is lower (a webcam may report 30 fps and keep 15 in dim light: fps= says so)
                rate = min(min((r for r in (cam.fps, o.fps) if r), default=FALLBACK_FPS) for cam in self._cameras)
                # at most the pairer's bound: a rate reported under 0.05 fps (a time-lapse file) failed the open
                # on a tolerance_ms the URL never gave
                self.pairing = o.pairing.config(min(500.0 / rate, MAX_TOLERANCE_MS))
            self._anchor_ns = self.clock.now_ns()
            self.driver_stamps = all(cam.v4l2 for cam in self._cameras)
            for cam in self._cameras:
                cam.last_frame_s = time.monotonic()
                cam.thread.start()
            sizes = self._first_frames()
            rig = self._fixed_rig or self._nominal_rig(sizes)
        except BaseException:
            self._close()
            raise
        if self._fixed_rig is None:
            self._log_about_rig_once(log, logging.WARNING, "opencv://: no rig= given: a nominal, uncalibrated rig "
                                     "(%g deg field of view) names the cameras; calibrate with ghcal before trusting "
                                     "3D joints", o.hfov_deg)
        self._set_rig(rig, built=self._fixed_rig is None)

    def _open_camera(self, cam: _Camera) -> None:
        """``cam.open()``, unless a close from another thread cancelled the open. Checked, and the camera marked as
        opening, under the lock :meth:`_cancel_open` sets the stop under: either the close comes first and nothing
        more is opened, or :meth:`lingering` asked after the close names the camera until it is released."""
        with self._cond:
            if self._stop.is_set():
                raise _closed_during_open()
            cam.opening = True
        try:
            cam.open()
        finally:
            cam.opening = False  # opened (its capture held from here) or failed (released)
        if self._stop.is_set():  # closed while OpenCV opened it: no thread is started (_open's _close releases it)
            raise _closed_during_open()

    def _first_frames(self) -> list[tuple[int, int]]:
        """Wait for each camera's first frame (kept for the reader); their sizes. A camera that fails or
        delivers nothing within ``open_timeout_s`` fails the open, naming it; a close from another thread ends the
        wait at once (:meth:`_cancel_open`), where it waited out ``open_timeout_s`` before."""
        deadline = time.monotonic() + self.options.open_timeout_s
        with self._cond:
            while True:
                if self._stop.is_set():
                    raise _closed_during_open()
                for item in self._queue:
                    if isinstance(item, FrameSizeError):  # typed: the daemon tells a wrong rig file by it
                        raise type(item)(*item.args) from None
                    if isinstance(item, Exception):
                        raise RigInitializationError(str(item)) from None
                if self._delivered >= set(self._per_camera):
                    break
                left = deadline - time.monotonic()
                if left <= 0:
                    silent = [f"{cam.name!r} ({cam.shown})" for cam in self._cameras if cam.name not in self._delivered]
                    raise RigInitializationError(
                        f"camera(s) {', '.join(silent)} delivered no frame within {self.options.open_timeout_s:g} s "
                        f"(open_timeout_s)")
                self._cond.wait(left)
        return [cam.size for cam in self._cameras]  # type: ignore[misc]

    def _nominal_rig(self, sizes: list[tuple[int, int]]) -> Rig:
        from drivers.sim.placement import RigPlacement  # a plausible two-camera placement, metres

        o = self.options
        if o.width is None and sizes[0] != sizes[1]:
            raise RigInitializationError(f"the cameras deliver {sizes[0][0]}x{sizes[0][1]} and "
                                         f"{sizes[1][0]}x{sizes[1][1]}; give width= and height= so both match")
        width, height = sizes[0]
        lo, hi = NOMINAL_SIZE_RANGE
        if not (lo <= width <= hi and lo <= height <= hi):
            # RigPlacement refused it naming only its own field: "RigPlacement.width: must be an int in [16, 8192]"
            raise RigInitializationError(f"the cameras deliver {width}x{height}: the nominal rig (no rig=) takes {lo} "
                                         f"to {hi} pixels each way; give width= and height= or a rig file (rig=)")
        rig = RigPlacement(width=width, height=height, hfov_deg=o.hfov_deg, names=o.names).build(rig_id=NOMINAL_RIG_ID)
        # marked, so that a recording of it, replayed, is still known for what it is (the daemon refuses it)
        return Rig(rig.cameras, rig.volume, rig.rig_id, metadata={**rig.metadata, "uncalibrated": True})

    # ------------------------------------------------------ from the camera threads
    def _put(self, frame: Frame, *, wait_room: bool, lost: LostRun | None = None) -> bool:
        """Queue a frame, the first after the camera's run of frames ``lost`` where that has any (said as the reader
        takes the frame); False: stop grabbing (closed, or the stream has ended or failed).

        A full queue (``queue`` frames of this camera) waits for room when ``wait_room`` (a video under
        ``policy=all``: every pair counts); otherwise its oldest frame goes (a live camera runs on).
        A video first waits for the other video to catch up (:meth:`_must_wait`), under either policy.
        """
        with self._cond:
            while self._must_wait(frame, wait_room) and not self._stop.is_set() and not self._failed:
                self._cond.wait(0.1)
            if self._stop.is_set() or self._failed:
                return False
            if self._ending is not None and frame.timestamp_ns > self._ending[0] + self.pairing.tolerance_ms * 1e6:
                self._queue.append(self._ending[1])  # past the ended video's last frame: no pair can follow
                self._failed = True
                self._cond.notify_all()
                return False
            if self._per_camera[frame.camera] >= self.options.queue:
                for k, queued in enumerate(self._queue):
                    if isinstance(queued, Frame) and queued.camera == frame.camera:
                        del self._queue[k]
                        self._unread_runs.dropped(queued.camera, queued.index)  # its runs held as one: bounded
                        break
                self._overruns[frame.camera] += 1
            else:
                self._per_camera[frame.camera] += 1
            self._queue.append(frame)
            if lost is not None and lost.frames:
                self._unread_runs.queued(frame.camera, frame.index, lost)
            self._camera(frame.camera).index_queued = frame.index
            self._delivered.add(frame.camera)
            self._camera(frame.camera).last_stamp_ns = frame.timestamp_ns
            self._camera(frame.camera).last_frame_s = time.monotonic()
            self._cond.notify_all()
            return True

    def _camera(self, name: str) -> _Camera:
        return next(cam for cam in self._cameras if cam.name == name)

    def _must_wait(self, frame: Frame, wait_room: bool) -> bool:
        """(Under the lock.) With ``wait_room``, a full queue waits for the reader. A video also waits while
        its frame is later than the other video's next, under either policy: paced alone, a video that
        decodes slower than its rate fell ever further behind the other, whose frames it could then never
        pair with (under ``latest`` no pair at all formed after the first few). Compared by time, not frame
        number: a 30 fps video held to a 15 fps one's frame number played at half its rate, its frames
        ever further behind the other's."""
        if wait_room and self._per_camera[frame.camera] >= self.options.queue:
            return True
        if not self._camera(frame.camera).video:
            return False  # a live camera runs at its own rate; it cannot be held back
        return any(other.video and other.name not in self._ended and not other.at_pass_end
                   and other.name != frame.camera and frame.timestamp_ns > other.due_ns(other.index_queued + 1)
                   for other in self._cameras)

    def _end(self, camera: _Camera, end: EndOfStream) -> None:
        """A video ended: the stream ends once every camera has, or another has delivered past its last
        frame (then checked again by :meth:`_put` as the other camera's frames come)."""
        with self._cond:
            if self._failed:
                return
            self._ended.add(camera.name)
            if self._ending is None or camera.last_stamp_ns < self._ending[0]:
                self._ending = (camera.last_stamp_ns, end)
            past_ns = self._ending[0] + self.pairing.tolerance_ms * 1e6
            if all(c.name in self._ended or c.last_stamp_ns > past_ns for c in self._cameras):
                self._queue.append(self._ending[1])
                self._failed = True
            self._cond.notify_all()

    def _passed(self, camera: _Camera, frames: int) -> bool:
        """loop=1: a video finished a pass of ``frames``. It waits for the other video to finish the same
        pass (so none starts over early), then both compare: False (and the stream fails) on a different
        length, which would pair different instants from then on."""
        with self._cond:
            passes = self._pass_frames.setdefault(camera.name, [])
            passes.append(frames)
            others = [c for c in self._cameras if c is not camera and c.video]
            camera.at_pass_end = True  # the other, longer or behind, reads on to its own end meanwhile
            self._cond.notify_all()
            while not self._stop.is_set() and not self._failed and \
                    any(len(self._pass_frames.get(o.name, [])) < len(passes) for o in others):
                self._cond.wait(0.1)
            camera.at_pass_end = False
            if self._stop.is_set() or self._failed:
                return False
            lengths = {camera.name: frames, **{o.name: self._pass_frames[o.name][len(passes) - 1] for o in others}}
            mismatch = _pass_mismatch([(c, lengths[c.name]) for c in self._cameras if c.name in lengths])
        if mismatch:
            self._fail(RigOperationError(f"loop=1: the videos have {mismatch}; looping them would pair different "
                                         f"instants (trim them to one length)"))
            return False
        return True

    def _fail(self, error: Exception) -> None:
        with self._cond:
            if not self._failed:
                self._queue.append(error)
                self._failed = True
            self._cond.notify_all()

    def _stalled_in(self) -> float:
        """(Under the lock.) Seconds until a live camera has gone ``open_timeout_s`` without a frame; at 0 the
        stream fails with :class:`RigDisconnectedError` naming it. A grab that hangs (a stalled USB stream, a
        GStreamer pipeline that stopped) never returns to say so, and the reads only timed out, naming no camera."""
        if self._failed:
            return math.inf
        now, limit = time.monotonic(), self.options.open_timeout_s
        live = [cam for cam in self._cameras if not cam.video]
        silent = [cam for cam in live if now - cam.last_frame_s >= limit]
        if silent:
            self._fail(RigDisconnectedError(
                ", ".join(f"camera {cam.name!r} ({cam.shown})" for cam in silent)
                + f" delivered no frame for {limit:g} s (open_timeout_s): stalled or unplugged"))
            return math.inf
        return min((cam.last_frame_s + limit - now for cam in live), default=math.inf)

    # ------------------------------------------------------------ reader side
    def _read_frame(self, timeout_s: float) -> Frame | None:
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while True:
                if self._stop.is_set():  # set under this lock: a frame queued before the close is not handed out
                    raise _closed_while_reading()
                if self._queue:
                    break
                stall_s = self._stalled_in()
                if self._queue:
                    break  # the stall, failed just now
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(min(left, stall_s))
            item = self._queue[0]
            if isinstance(item, Exception):
                raise type(item)(*item.args)  # a fresh one each read: it stays queued until close
            self._queue.popleft()
            self._per_camera[item.camera] -= 1
            self._cond.notify_all()  # a video waiting for room
            # the pairer gets it (read() pushes every frame read): now the gap of a run before it counts, or not
            runs = self._unread_runs.read(item.camera, item.index)
        for words in runs:
            self._log_lost(item.camera, words)
        return item

    def _log_lost(self, camera: str, words: str) -> None:
        log.warning("camera %r (%s) lost %s", camera, self._camera(camera).shown, words)

    def _frame_available(self) -> bool:
        with self._cond:
            return bool(self._queue) and isinstance(self._queue[0], Frame)

    def lingering(self) -> tuple[str, ...]:
        """The cameras still held after the close: a thread in a grab that hangs, and, after a close that cancelled
        an open, those the opening thread has opened (or is opening) and not yet released."""
        with self._cond:
            if not self._stop.is_set():  # open (or never opened): nothing was left behind yet
                return ()
            cameras = list(self._cameras)
        return tuple(f"camera {cam.name!r} ({cam.shown})" for cam in cameras if cam.holds_device)

    def _cancel_open(self) -> None:
        # Stops what the open waits for, not the open itself: a capture being opened cannot be interrupted, and the
        # opening thread releases what it opened (_open's _close). lingering() names those cameras meanwhile.
        with self._cond:
            self._open_cancelled = True
            self._stop.set()  # the first-frame wait ends, camera threads stop at their next frame, no camera opens
            self._cond.notify_all()

    def _close(self) -> None:
        with self._cond:  # under the lock: a read takes no frame once the close has begun (_read_frame)
            self._stop.set()
            self._cond.notify_all()
        deadline = time.monotonic() + 2.0
        for cam in self._cameras:
            if cam.thread.is_alive():
                cam.thread.join(timeout=max(0.0, deadline - time.monotonic()))
            elif cam.thread.ident is None:
                cam.release()  # never started (a failed open): released here
            # A thread still in a grab on a dead camera releases its capture when that grab returns;
            # releasing it from here, under the grab, is what OpenCV's captures do not survive.
            if cam.thread.is_alive():
                log.warning("opencv: camera %r (%s) is still in a read; it is released when that returns",
                            cam.name, cam.shown)
        with self._cond:  # _put queues nothing once _stop is set
            unread = self._unread_runs.closed()
        for camera, words in unread:
            self._log_lost(camera, words)
