"""``sim://``: a simulated two-camera rig filming a synthetic person (or two: ``second=``), as a first-class backend.

In the spirit of python-can's virtual bus: a real backend, not a test mock. It
models what breaks a stereo pipeline: capture timing from an injectable clock,
Gaussian timestamp jitter, an inter-camera capture offset, independent frame
drops per camera, and a camera vanishing (unplug). Frames carry ground truth (the subject's).

URL options (every one validated; unknown ones are rejected by name)::

    sim://?fps=30&seed=0&motion=wave&width=640&height=480&jitter_ms=0.5&offset_ms=2&drop=0.01

* ``fps`` (30): capture rate of each camera.
* ``seed`` (0): the person, clothes and room, and the timing noise (jitter, drops).
* ``motion`` (``wave``): a procedural motion (``drivers.sim.MOTION_NAMES``; ``freestyle``
  moves every joint along random curves drawn from ``seed``); or
  ``bvh=PATH``: a BVH clip (the two are exclusive).
* ``width``, ``height`` (640x480): image size of both cameras.
* ``baseline`` (1.2 m), ``convergence`` (degrees; default: both aimed at the
  subject), ``distance`` (3.0 m, 1 to 8: the subject stands this far ahead,
  where the working volume is centred; 2 m deep, shallower under 1.5 m so it
  starts 0.5 m from the rig), ``mount_height`` (1.3 m: the cameras above the
  floor; ``height`` is the image height): rig placement
  (:class:`drivers.sim.RigPlacement`). A placement whose cameras do not both
  see the subject's hips (``convergence=120``) is a ``RigConfigError``.
* ``jitter_ms`` (0): standard deviation of each capture instant.
* ``offset_ms`` (0): capture offset of the second camera after the first.
* ``latency_ms`` (0, at most 10000): the second camera's frames reach the host this long after
  their capture, stamped with their capture time (a slower transport, such as a
  USB hub). A latency of ``max_pending`` frames or more never pairs unless ``max_pending``
  is raised (below); one past the most it takes (256 frames: ``latency_ms=10000`` at 30 fps)
  is a ``RigConfigError`` naming the largest latency that pairs.
* ``drop`` (0): probability that a camera loses a frame (per camera, per frame).
* ``unplug_after_s``: the second camera vanishes this long after open:
  ``read()`` then raises :class:`RigDisconnectedError`, now and on every later call.
* ``noise`` (1.5): sensor read noise, standard deviation in 8-bit levels.
* ``tolerance_ms`` (11, at most 1000), ``policy`` (``latest``), ``max_pending`` (8, at most 256:
  frames held per camera while waiting for the other's): pairing
  (:func:`drivers.pairing_options.take_pairing_options`).
* ``cache`` (default ``$XDG_CACHE_HOME/ghnerf-sim`` or ``~/.cache/ghnerf-sim``):
  directory of the pre-rendered loop cache, or ``off``. A file there (or above it) is refused
  (``RigConfigError`` naming the option), as a ``bvh=`` that is no file is.
* ``workers`` (CPU count): render threads.
* ``max_loop_mb`` (2048): refuse (``RigConfigError``) a loop needing more memory
  than this, rather than exhausting the machine.
* ``second`` (none; ``X,Z``): a second person standing at rig-frame ``(x, z)`` metres (x to the right, z
  ahead; the subject stands at ``(0, distance)``), as ``benchmarks/measure_two_people.py --places`` places
  people: ``second=1.0,3.4`` is its default places' offset, a metre beside the subject and 0.4 m behind
  (docs/two-people.md, "Rehearse it on the simulated rig"). Their body, clothes and motion come from
  ``seed`` + 1000 (the benchmark's second person), rendered into the subject's room with
  :func:`drivers.sim.render_people_and_truth` (the nearer person's pixel in front). Refused
  (``RigConfigError``): a place either camera does not see (the hips outside its image: the runtime would
  never see them), and hips within 0.4 m of the subject's at any instant of the loop (the bodies would pass
  through each other, one picture of two people's parts): :mod:`drivers.backends.sim_second`.
* ``second_motion`` (the subject's motion; ``wave`` with ``bvh=``): the second person's procedural motion. It
  plays the subject's loop instants, so one of another period restarts with the subject's loop.
* ``second_after_s`` (none: from the first frame): the second person walks in this long after open, as
  ``unplug_after_s`` counts; frames captured before show the subject alone (the one-person URL's loop and
  cache entry; ``open()`` fills both loops, twice the memory).

Real time: rendering a 640x480 pair can take longer than a 30 fps period on a
2-core machine (``benchmarks/bench_sim_render.py`` prints the figure). The motion loops (``period_s`` of the scene), so frames are a
function of (camera, frame index modulo the loop length): ``open()`` renders the
whole loop (both cameras) with a thread pool, or loads it from the disk cache,
logging progress, and returns only when every frame is in memory (a ``close()`` from another thread meanwhile
stops the rendering at its next frame, the cache's load or write at its next chunk, a half-written entry removed,
never named: ``open()`` raises :class:`RigInitializationError` and keeps no loop).
After open a frame costs a memory copy, so pairs are delivered at the nominal rate however
slow the renderer. The price is open time (first run only, with the disk cache)
and memory: about 2.8 MB per camera frame at 640x480 (image plus truth maps),
~200 MB for the 1.2 s default ``wave`` loop.

Timing model (:mod:`drivers.backends.sim_timing`): each camera captures frame
``k`` at ``open + k/fps + offset + jitter``, and it reaches the host then (the
second camera's ``latency_ms`` later); ``read`` sleeps on the clock until the
next frame arrives (a ``close()`` from another thread wakes it at once, raising
:class:`RigOperationError`) and returns frames in order of arrival, so with a
:class:`~drivers.clock.ManualClock` tests run at full speed with exact
timestamps. With ``policy=latest`` each ``read`` first takes in every capture
already due, so a slow reader gets the newest pair and the older ones count in
``stats.pairs_dropped`` (sequence gaps). Frames that arrived longer ago than a backlog
of 8 frames per camera (as a driver queue would hold) are lost before pairing: a
``policy=all`` reader that falls behind, or any reader stalled that long,
loses them, counted as ``stats.overruns``; ``stats.simulated_drops`` counts the
``drop`` losses (both also show as index gaps in ``stats.camera_gaps``).

Each frame says which scene instant it shows (``scene_time_s``, within the loop)
and carries the ground truth of that instant (``truth``, ``joints_3d``): always the subject's, with a second
person too (their mask, depth and part labels are the subject's whole silhouette, also where the second person
stands in front, and ``visible`` asks only the subject's own body; the second person's joints are not carried).

What it does NOT model: the image does not move with the jitter (it shows the
nominal capture instant; ``scene_time_s`` says which); noise, like the image,
repeats every loop pass; the loop is stretched to a whole number of frames
(``round(period_s * fps)``), so motion speed is off by at most half a frame per
loop (at a low rate, where a period has few frames, the loop spans several
periods instead, each frame at most 1 % of a period off the instant a real
camera would show: ``_loop_length``); no exposure time, motion blur or rolling shutter; no clock drift between
the cameras; no USB bandwidth limits or reconnection after an unplug; nothing
of the scene model's own omissions (see :mod:`drivers.sim`).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import os
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.backends.sim_loop import FillCancelled, FrameLoop, LoopFrame, default_cache_root
from drivers.backends.sim_second import SecondPerson, check_second_person, take_second_person
from drivers.backends.sim_timing import Capture, CaptureSchedule, TimingModel
from drivers.base import RigSource
from drivers.clock import Clock
from drivers.errors import RigConfigError, RigDisconnectedError, RigInitializationError, RigOperationError
from drivers.frames import Frame
from drivers.pairing import MAX_HELD, PairingConfig, PairingStats
from drivers.pairing_options import take_pairing_options
from drivers.sim import (MOTION_NAMES, MotionParams, RigPlacement, SceneConfig, SensorModel, SimScene,
                         render_people_and_truth)
from drivers.url import RigUrl
from ghnerf_runtime.body25 import JOINT_INDEX
from ghnerf_runtime.geometry import Rig
from ghnerf_runtime.rig_file import rig_to_dict

log = logging.getLogger(__name__)

#: Captures a camera holds for a slow reader before it loses the oldest (a driver queue).
BACKLOG_FRAMES = 8
#: Bytes per pixel of a pre-rendered frame: BGR image 3, mask 1, depth 4, part labels 1.
LOOP_BYTES_PER_PIXEL = 9
#: How far (in motion periods) a loop frame's instant may drift per frame before the loop spans several
#: periods, and the most it spans (see _loop_length).
MAX_LOOP_PHASE_ERROR = 0.01
MAX_LOOP_PERIODS = 64


def _check_subject_in_view(scene: SimScene, rig: Rig, placement: RigPlacement) -> None:
    """Refuse a placement whose cameras do not see the subject: its hips (at scene time 0) must be in
    front of both cameras and inside both images (``convergence=120`` turned each camera 60 degrees
    away from a subject 3 m ahead, and the rig filmed an empty room without a word)."""
    hips = scene.joints_3d(0.0)[JOINT_INDEX["MidHip"]]
    for cam in rig.pair:
        uv, depth = cam.project(hips)
        if np.all(np.isfinite(uv)) and 0 <= uv[0] < cam.width and 0 <= uv[1] < cam.height:
            continue
        where = (f"behind the camera (depth {float(depth):.2f} m)" if not depth > 0 else
                 f"outside the {cam.width}x{cam.height} image" if not np.all(np.isfinite(uv)) else
                 f"at pixel ({uv[0]:.0f}, {uv[1]:.0f}), outside the {cam.width}x{cam.height} image")
        convergence = "aimed at the subject" if placement.convergence_deg is None else f"{placement.convergence_deg:g}"
        raise RigConfigError(
            f"sim: camera {cam.name!r} does not see the subject standing {placement.distance_m:g} m ahead: its hips "
            f"are {where}, with baseline={placement.baseline_m:g}, convergence={convergence}, "
            f"distance={placement.distance_m:g}, mount_height={placement.camera_height_m:g} (lower convergence, "
            "or leave it out to aim both cameras at the subject)"
        )


@dataclass
class SimRigStats(PairingStats):
    """Pairing counters plus what the simulator did on purpose (or to a slow reader)."""

    simulated_drops: dict[str, int] = dataclasses.field(default_factory=dict)
    overruns: dict[str, int] = dataclasses.field(default_factory=dict)


@dataclass(frozen=True)
class SimOptions:
    """Validated ``sim://`` options (see the module docstring)."""

    timing: TimingModel
    scene: SceneConfig
    placement: RigPlacement
    unplug_after_s: float | None
    pairing: PairingConfig
    cache_root: Path | None
    workers: int
    max_loop_mb: float = 2048.0
    second: SecondPerson | None = None

    @classmethod
    def from_url(cls, url: RigUrl) -> "SimOptions":
        if url.target:  # "sim://fps=60" would otherwise run at the defaults without a word
            raise RigConfigError(f"rig URL {url.url!r}: sim:// takes no target ({url.target!r}); "
                                 "options go after '?', as in sim://?fps=60")
        fps = url.take_float("fps", 30.0, lo=0.1, hi=1000.0)
        seed = url.take_int("seed", 0, lo=0, hi=2**32 - 1)
        motion = url.take_str("motion", None, choices=MOTION_NAMES)
        bvh = url.take_str("bvh")
        if motion is not None and bvh is not None:
            raise RigConfigError(f"rig URL {url.url!r}: give motion= or bvh=, not both")
        if bvh is not None and not Path(bvh).is_file():
            raise RigConfigError(f"rig URL {url.url!r}: option bvh={bvh!r}: no such file")
        width = url.take_int("width", 640, lo=16, hi=8192)
        height = url.take_int("height", 480, lo=16, hi=8192)
        baseline = url.take_float("baseline", 1.2, lo=0.05, hi=4.0)
        convergence = url.take_float("convergence", float("nan"), lo=-10.0, hi=120.0) if "convergence" in url.options else None
        distance = url.take_float("distance", 3.0, lo=1.0, hi=8.0)
        mount_height = url.take_float("mount_height", 1.3, lo=0.3, hi=3.0)
        noise = url.take_float("noise", 1.5, lo=0.0, hi=50.0)
        timing = TimingModel(
            fps=fps,
            offset_ms=url.take_float("offset_ms", 0.0, lo=-1000.0, hi=1000.0),
            jitter_ms=url.take_float("jitter_ms", 0.0, lo=0.0, hi=1000.0),
            latency_ms=url.take_float("latency_ms", 0.0, lo=0.0, hi=10_000.0),
            drop=url.take_float("drop", 0.0, lo=0.0, hi=1.0),
            seed=seed,
        )
        unplug = url.take_float("unplug_after_s", -1.0, lo=0.0, hi=1e6) if "unplug_after_s" in url.options else None
        pairing = take_pairing_options(url, max_tolerance_ms=1000.0)
        _check_latency_can_pair(url, timing, pairing.config())
        cache = url.take_str("cache")
        if cache not in (None, "off"):
            _check_cache_folder(url, Path(cache))
        workers = url.take_int("workers", os.cpu_count() or 2, lo=1, hi=64)
        max_loop_mb = url.take_float("max_loop_mb", 2048.0, lo=1.0)
        second = take_second_person(url, seed, motion)
        url.finish()
        kwargs = {"motion": bvh} if bvh is not None else ({"motion": motion} if motion else {})
        if motion == "freestyle":  # its random trajectories follow the URL's seed too
            kwargs["motion_params"] = MotionParams(seed=seed)
        return cls(
            timing=timing,
            # The subject stands `distance` ahead, where the cameras aim and the working volume is centred
            # (it stayed at 3 m whatever distance said: out of the rig's volume at distance=1.5 or 8).
            scene=SceneConfig(seed=seed, sensor=SensorModel(read_noise=noise), position_xz=(0.0, distance), **kwargs),
            placement=RigPlacement(
                baseline_m=baseline, convergence_deg=convergence, camera_height_m=mount_height,
                distance_m=distance, width=width, height=height, volume_depth_m=_volume_depth(distance),
            ),
            unplug_after_s=unplug,
            pairing=pairing.config(),
            cache_root=None if cache == "off" else (Path(cache) if cache else default_cache_root()),
            workers=workers,
            max_loop_mb=max_loop_mb,
            second=second,
        )


def _check_latency_can_pair(url: RigUrl, timing: TimingModel, pairing: PairingConfig) -> None:
    """Refuses a ``latency_ms`` that no ``max_pending`` pairs: the first camera holds every frame it captures while
    the second's frame of the same instant is on its way (about ``latency_ms * fps`` of them), and the pairer holds
    at most :data:`~drivers.pairing.MAX_HELD`. Such a URL opened (after rendering its loop) and timed out on every
    read. Only a lag past what the pair's tolerance and a frame of jitter could bridge is refused."""
    period_ms = 1000.0 / timing.fps
    lag_frames = (timing.latency_ms - pairing.tolerance_ms - period_ms) / period_ms
    if lag_frames < MAX_HELD:
        return
    largest_ms = MAX_HELD * period_ms
    raise RigConfigError(
        f"rig URL {url.url!r}: latency_ms={timing.latency_ms:g} at fps={timing.fps:g} puts the second camera "
        f"{timing.latency_ms / period_ms:.0f} frames behind the first: it never pairs, max_pending holding at most "
        f"{MAX_HELD} frames per camera; the largest latency that pairs is under {largest_ms:.0f} ms at this fps "
        f"(with max_pending={MAX_HELD})")


def _check_cache_folder(url: RigUrl, folder: Path) -> None:
    """Refuses a ``cache=`` that names a file, or a folder under one: the user named a place for the cache and a
    file there is a mistake (it was only a warning when the loop could not be stored, every open rendering again),
    as ``bvh=`` naming no file is. A folder not yet made is fine: the loop's first store makes it."""
    place = folder
    while not place.exists() and place != place.parent:  # the nearest part of the path that is there
        place = place.parent
    if place.exists() and not place.is_dir():
        where = "is a file" if place == folder else f"is under {str(place)!r}, a file"
        raise RigConfigError(f"rig URL {url.url!r}: option cache={str(folder)!r} {where}: give a folder for the "
                             "loop cache, or cache=off")


def _volume_depth(distance_m: float) -> float:
    """The working volume's depth: 2 m, shallower for a subject closer than 1.5 m, so that the volume still
    starts 0.5 m from the rig (:class:`RigPlacement`'s limit), instead of refusing distance=1..1.5 with an
    error about a field the URL does not have."""
    return min(RigPlacement.volume_depth_m, 2.0 * (distance_m - 0.5))


def _loop_length(period_s: float, fps: float) -> tuple[int, int]:
    """The pre-rendered loop: how many motion periods ``n`` it spans and its frames ``L`` per camera.

    Frame ``j`` shows the instant ``j * n * period_s / L`` (modulo the period), where a camera at ``fps``
    would see ``j / fps``: the loop is right when each frame moves the motion on by what one frame period
    does. One period of ``round(period_s * fps)`` frames is, at the usual rates; at a low rate it was not
    (``fps=1`` and the 1.2 s ``wave``: one frame, the same instant in every frame, a person frozen). So
    ``n`` is the fewest periods whose ``L = round(n * period_s * fps)`` frames step through the motion
    at most :data:`MAX_LOOP_PHASE_ERROR` of a period per frame off a real camera's step (the phases a
    slow camera strobes through; one exactly in step with the motion sees one pose, and so does the
    loop). From 10 frames a period on, ``n = 1`` always qualifies: loops at the usual rates are unchanged.
    """
    per_period = period_s * fps
    if not per_period > 0 or not math.isfinite(per_period):
        raise RigConfigError(f"sim: a motion period of {period_s:g} s at {fps:g} fps cannot be simulated")
    best: tuple[float, int, int] | None = None
    for n in range(1, MAX_LOOP_PERIODS + 1):
        frames = round(n * per_period)
        if frames < 1:
            continue
        error = abs(n * per_period - frames) / (frames * per_period)  # periods per frame
        if error <= MAX_LOOP_PHASE_ERROR:
            return n, frames
        if best is None or error < best[0]:
            best = (error, n, frames)
    return (best[1], best[2]) if best is not None else (1, max(1, round(per_period)))


def _closed_while_reading() -> RigOperationError:
    """What a read raises when another thread closes the source under it."""
    return RigOperationError("sim source closed while a read waited for its frame")


def _closed_during_open() -> RigInitializationError:
    """What an open() raises when another thread closes the source while it pre-renders (or loads) its loop."""
    return RigInitializationError("sim source closed while open() pre-rendered its loop: the open was cancelled")


class SimRigSource(RigSource):
    """The simulated rig (see the module docstring for options and what it does not model).

    Args:
        options: validated options.
        clock: drives capture timing and timeouts (a ``ManualClock`` makes it instant and exact).
    """

    scheme = "sim"

    def __init__(self, options: SimOptions, *, pairing: PairingConfig | None = None, clock: Clock | None = None) -> None:
        self.options = options
        self._scene = SimScene(options.scene)  # validates the motion (BVH) now, not at open
        rig: Rig = options.placement.build(rig_id="sim")
        super().__init__(rig, pairing=pairing or options.pairing, clock=clock, rig_built=True)
        self.period_s = self._scene.period_s
        self.loop_periods, self.loop_frames = _loop_length(self.period_s, options.timing.fps)
        _check_subject_in_view(self._scene, rig, options.placement)
        if options.second is not None:
            check_second_person(self._scene, SimScene(options.second.scene), rig)
        w, h = rig.pair[0].size
        loop_mb = 2 * self.loop_frames * w * h * LOOP_BYTES_PER_PIXEL / 1e6 * len(self._loop_people())
        if loop_mb > options.max_loop_mb:
            raise RigConfigError(
                f"sim: the motion loops every {self.period_s:.1f} s: {self.loop_frames} frames per camera at "
                f"{options.timing.fps:g} fps and {w}x{h} need {loop_mb:.0f} MB pre-rendered, over max_loop_mb="
                f"{options.max_loop_mb:g} (lower fps or size, use a shorter clip, or raise max_loop_mb)"
            )
        self._local = threading.local()  # SimScene is not thread-safe: one per render thread
        self._loop: FrameLoop | None = None  # what the URL films (two people with second=)
        self._loop_alone: FrameLoop | None = None  # the subject alone, before second_after_s
        self._schedule: CaptureSchedule | None = None
        self._unplug_ns: int | None = None
        self._second_joins_ns: int | None = None
        self._unplugged = False
        self._closing = threading.Event()  # set by close: wakes a read waiting in another thread, stops an open
        names = rig.names[:2]
        self._drops = {n: 0 for n in names}
        self._overruns = {n: 0 for n in names}
        self.fill_report = None

    @classmethod
    def from_url(cls, url: RigUrl, *, clock: Clock | None = None, pairing: PairingConfig | None = None) -> "SimRigSource":
        return cls(SimOptions.from_url(url), pairing=pairing, clock=clock)

    @property
    def stats(self) -> SimRigStats:
        return SimRigStats(**vars(super().stats), simulated_drops=dict(self._drops), overruns=dict(self._overruns))

    # ----------------------------------------------------------- rendering
    def scene_time(self, camera: int, j: int) -> float:
        """The scene instant shown by loop frame ``j`` of camera ``camera`` (0 or 1)."""
        offset_s = self.options.timing.offset_ms / 1000.0 if camera == 1 else 0.0
        return (j * self.loop_periods * self.period_s / self.loop_frames + offset_s) % self.period_s

    def _loop_people(self) -> list[bool]:
        """The loops ``open()`` fills, each by whether the second person is in it: the subject alone before a
        ``second_after_s``, then (or from the start) the URL's scene."""
        second = self.options.second
        if second is None:
            return [False]
        return [False, True] if second.after_s is not None else [True]

    def _thread_scenes(self) -> tuple[SimScene, SimScene | None]:
        """This render thread's subject and second person (``None`` without ``second=``)."""
        scenes = getattr(self._local, "scenes", None)
        if scenes is None:
            second = self.options.second
            scenes = self._local.scenes = (SimScene(self.options.scene),
                                           None if second is None else SimScene(second.scene))
        return scenes

    def _render(self, camera: int, j: int, *, together: bool = False) -> LoopFrame:
        """Loop frame ``j`` of ``camera``: the subject, and the second person too where ``together``. The truth
        (``truth``, ``joints_3d``) is always the subject's (:func:`drivers.sim.render_people_and_truth`)."""
        scene, second = self._thread_scenes()
        t = self.scene_time(camera, j)
        cam = self.rig.cameras[camera]
        if together and second is not None:  # the second person plays the subject's loop instants too
            image, truth = render_people_and_truth((scene, second), cam, t)
        else:
            image, truth = scene.render(cam, t)
        return LoopFrame(image=image, truth=truth, scene_time_s=t, joints_3d=scene.joints_3d(t))

    def cache_key(self, together: bool | None = None) -> str:
        """Hash of everything that changes the pre-rendered pixels (options, rig, simulator code) of the loop
        the URL films (``together``: ``None``), or of the subject alone (``False``) or with the second person
        (``True``). A one-person loop's key names no second person, so ``second_after_s``'s first loop is the
        one-person URL's entry."""
        import drivers.sim  # the package, to hash its sources
        import ghnerf_runtime.body25
        import ghnerf_runtime.geometry

        scene = self.options.scene
        bvh = Path(str(scene.motion))
        together = self.options.second is not None if together is None else together
        described = {
            "scene": repr(scene),
            "rig": rig_to_dict(self.rig),
            "loop": [self.loop_frames, self.period_s, self.options.timing.offset_ms, self.loop_periods],
        }
        if together and self.options.second is not None:  # only then: one person's keys stay what they were
            described["second"] = repr(self.options.second.scene)
        h = hashlib.sha256()
        h.update(json.dumps(described, sort_keys=True, default=repr).encode())
        if bvh.suffix.lower() == ".bvh":
            h.update(bvh.read_bytes())
        # The ray casting and lens model the renderer uses live in ghnerf_runtime.geometry, the joint
        # order in body25, and which instant a loop frame shows here: all of them make the pixels.
        sources = sorted(Path(drivers.sim.__file__).parent.rglob("*.py"))
        sources += sorted(Path(ghnerf_runtime.geometry.__file__).parent.rglob("*.py"))
        sources += [Path(ghnerf_runtime.body25.__file__), Path(__file__)]
        for source in sources:
            h.update(source.read_bytes())  # a renderer change invalidates old entries
        return h.hexdigest()[:32]

    # ----------------------------------------------------------- hooks
    def _open(self) -> None:
        try:
            for together in self._loop_people():
                self._fill_loop(together)
            if self._closing.is_set():  # closed after the last frame rendered (or as the cache loaded)
                raise _closed_during_open()
        except FillCancelled as e:  # a close stopped the render, the cache load or the cache write at its next step
            self._drop_loops()
            raise _closed_during_open() from e
        except BaseException:
            self._drop_loops()  # a failed open keeps no loop: hundreds of MB
            raise
        start = self.clock.now_ns()
        self._schedule = CaptureSchedule(self.options.timing, start)
        if self.options.unplug_after_s is not None:
            self._unplug_ns = start + int(round(self.options.unplug_after_s * 1e9))
        second = self.options.second
        self._second_joins_ns = None if second is None or second.after_s is None else (
            start + int(round(second.after_s * 1e9)))

    def _fill_loop(self, together: bool) -> None:
        """Renders (or loads from the disk cache) the loop with the second person or without, held (before it
        fills, so that a close meanwhile cancels it) as ``_loop``, or ``_loop_alone`` where the second person joins
        later; ``fill_report`` says how the last one became ready."""
        cache_dir = None
        if self.options.cache_root is not None:
            cache_dir = self.options.cache_root / self.cache_key(together)

        def render(camera: int, j: int) -> LoopFrame:
            return self._render(camera, j, together=together)

        # stop: a close() from another thread stops the fill at its next frame, checksum chunk or written chunk
        loop = FrameLoop(render, self.loop_frames, workers=self.options.workers, cache_dir=cache_dir,
                         stop=self._closing)
        if together or self.options.second is None:
            self._loop = loop
        else:
            self._loop_alone = loop
        w, h = self.rig.pair[0].size
        who = "two people" if together else "the subject"

        def progress(done: int, total: int, elapsed: float) -> None:
            left = elapsed * (total - done) / max(done, 1)
            log.info("sim: pre-rendering the %.2f s loop of %s at %dx%d: %d/%d frames, ~%.0f s left",
                     self.period_s, who, w, h, done, total, left)

        self.fill_report = loop.fill(progress)
        log.info("sim: loop of %d frames per camera ready (%s in %.1f s, %.0f MB)",
                 self.loop_frames, self.fill_report.source, self.fill_report.wall_s, loop.nbytes() / 1e6)

    def _read_frame(self, timeout_s: float) -> Frame | None:
        schedule = self._schedule
        if schedule is None:  # read() refuses a source not open: closed by another thread since the read began
            raise _closed_while_reading()
        second = self.rig.pair[1].name
        if self._unplugged:
            raise RigDisconnectedError(f"sim camera {second!r} was unplugged (unplug_after_s)")
        deadline = self.clock.now_ns() + int(timeout_s * 1e9)
        backlog_ns = BACKLOG_FRAMES * schedule.model.period_ns
        while True:
            capture = schedule.peek()
            due = capture.arrival_ns
            if self._unplug_ns is not None and due >= self._unplug_ns:
                due = self._unplug_ns  # nothing more arrives: the next event is the unplug
            if due > deadline:
                self._wait_until(deadline, schedule)
                return None
            self._wait_until(due, schedule)
            if due == self._unplug_ns:
                self._unplugged = True
                raise RigDisconnectedError(
                    f"sim camera {second!r} unplugged {self.options.unplug_after_s:g} s after open (unplug_after_s)"
                )
            schedule.pop()
            name = self.rig.pair[capture.camera].name
            if capture.dropped:
                self._drops[name] += 1
            elif self.clock.now_ns() - capture.arrival_ns > backlog_ns:  # the backlog is of frames arrived
                self._overruns[name] += 1
            else:
                frame = self._frame(capture)
                if self._closing.is_set():  # closed while the frame was made: a closed source hands out none
                    raise _closed_while_reading()
                return frame

    def _wait_until(self, when_ns: int, schedule: CaptureSchedule) -> None:
        """Sleeps on the clock until ``when_ns``; a close from another thread meanwhile ends the wait at once."""
        self.clock.wait_until(when_ns, self._closing)
        if self._closing.is_set() or self._schedule is not schedule or self._loop is None:
            raise _closed_while_reading()

    def _frame_available(self) -> bool:
        schedule = self._schedule
        if schedule is None or self._unplugged:
            return False
        due = schedule.peek().arrival_ns
        if self._unplug_ns is not None and due >= self._unplug_ns:
            return False  # the next event is the unplug: the next read raises it, after the pairs captured before
        return due <= self.clock.now_ns()

    def _frame(self, capture: Capture) -> Frame:
        # Read once each: a close from another thread since the read's wait ended drops them (it asserted)
        loop, alone = self._loop, self._loop_alone
        if loop is None:
            raise _closed_while_reading()
        joins_ns = self._second_joins_ns
        if alone is not None and joins_ns is not None and capture.time_ns < joins_ns:
            loop = alone  # captured before the second person joins (second_after_s)
        shown = loop.frame(capture.camera, capture.index % self.loop_frames)
        return Frame(
            camera=self.rig.pair[capture.camera].name,
            image=shown.image,
            timestamp_ns=capture.time_ns,
            index=capture.index,
            truth=shown.truth,
            scene_time_s=shown.scene_time_s,
            joints_3d=shown.joints_3d,
        )

    def _cancel_open(self) -> None:
        self._closing.set()  # a pre-render stops at its next frame; the open drops its loops and raises

    def _close(self) -> None:
        self._closing.set()
        self._drop_loops()

    def _drop_loops(self) -> None:
        for loop in (self._loop, self._loop_alone):
            if loop is not None:
                loop.close()
        self._loop = None
        self._loop_alone = None
        self._schedule = None
