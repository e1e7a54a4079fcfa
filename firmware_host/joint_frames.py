"""Estimator results (and simulator ground truth) as joint-stream frames, for the demo and the daemon.

A frame's ``sequence`` (the wire's seq) is the producer's own frame number, from :class:`FrameNumbers`,
not the driver's ``pair.sequence``: that one restarts at 0 with every (re)opened rig and counts the
pairs skipped or rejected before any frame was made, which a receiver would take for frames lost on
the link (``docs/protocol.md`` section 3).
"""
from __future__ import annotations

import numpy as np

import drivers
from firmware_host.errors import CaptureTimeError
from firmware_host.protocol.constants import U32_MAX, U64_MAX, Flags, hello_scene_flags
from firmware_host.protocol.messages import JointFrame
from ghnerf_runtime.config import EstimatorConfig
from ghnerf_runtime.estimator import PairResult

__all__ = ["FrameNumbers", "announced_scene_flags", "capture_time_us", "estimate_frame", "scene_flags", "truth_frame"]


class FrameNumbers:
    """The seq of each frame a producer sends: 0, 1, 2... without gaps, wrapping at 2**32.

    Take a number only for a frame that is handed to the sinks: a number taken and not sent is a gap.
    """

    def __init__(self) -> None:
        self._next = 0
        self._taken = False

    def take(self) -> int:
        number = self._next
        self._next = (number + 1) & U32_MAX
        self._taken = True
        return number

    @property
    def last(self) -> int | None:
        """The number taken last (None before the first): what a sink opened now announces in its HELLO and
        STATUS (:meth:`ProtocolSink.carry_seq`), so a reopened or added output does not go back to 0."""
        return (self._next - 1) & U32_MAX if self._taken else None


def capture_time_us(pair: drivers.FramePair) -> int:
    """The capture time a frame of ``pair`` carries: its first camera's stamp in whole microseconds.

    Raises:
        CaptureTimeError: a stamp the wire's unsigned 64-bit microseconds cannot hold. A replay with ``keep_time=1``
            delivers the take's recorded stamps, which the recording format allows to be negative: the first such
            pair failed in ``JointFrame`` with a bare ``ValueError``, a traceback from ``ghnerf-demo`` and exit 1 (a
            restart, then the same) from the daemon.
    """
    first = pair.frames[0]
    stamp_us = first.timestamp_ns // 1000
    if not 0 <= stamp_us <= U64_MAX:
        raise CaptureTimeError(
            f"camera {first.camera!r} frame {first.index} was captured at timestamp_ns={first.timestamp_ns}: the joint "
            f"stream carries capture times as microseconds in 0..{U64_MAX} (docs/protocol.md), so this pair cannot "
            "be sent. A replay's keep_time=1 delivers the take's recorded stamps: play it without keep_time=1 (its "
            "frames re-stamped on this host's clock)")
    return stamp_us


def truth_frame(pair: drivers.FramePair, *, sequence: int) -> JointFrame | None:
    """The simulator's ground-truth 3D joints of ``pair`` (confidence 1) as frame ``sequence``, or None when
    it carries none."""
    if pair.joints_3d is None:
        return None
    joints = np.concatenate([pair.joints_3d, np.ones((len(pair.joints_3d), 1))], axis=1)
    return JointFrame(
        sequence=sequence,
        capture_time_us=capture_time_us(pair),
        joint_set=0,
        joints_3d=joints,
    )


def scene_flags(result: PairResult, *, calibration_suspect: bool = False) -> int:
    """The wire flags that say what ``result`` is (docs/protocol.md section 3): what the status file's JSON says
    of a pair, for a receiver that reads only the joint stream (a robot told the joints are one person's, or,
    where the scan for others runs, that someone else was seen: neither is a presence sensor, docs/two-people.md)."""
    flags = Flags.NONE
    if result.several_people:
        flags |= Flags.SEVERAL_PEOPLE
    if result.prior_fallback:
        flags |= Flags.PRIOR_FALLBACK
    if result.single_view is not None:
        flags |= Flags.SINGLE_VIEW
    if calibration_suspect:
        flags |= Flags.CALIBRATION_SUSPECT
    if result.someone_else:  # the latest scan's answer, held until the next (None: no scan this track)
        flags |= Flags.SOMEONE_ELSE
    return int(flags)


def announced_scene_flags(config: EstimatorConfig) -> int:
    """The scene flags a sender whose estimator runs with ``config`` announces in its HELLO: SOMEONE_ELSE only
    where ``presence.scan_every_s`` scans for others (docs/protocol.md, "Scene flags")."""
    return hello_scene_flags(config.presence.scan_every_s > 0)


def estimate_frame(pair: drivers.FramePair, result: PairResult, *, sequence: int,
                   calibration_suspect: bool = False) -> JointFrame:
    """The estimate as sink frame ``sequence``: missing joints are NaN with confidence 0 (missing on the wire).

    The 2D joints are keyed by camera index in ``pair.frames`` order (the rig's pair order), which is
    the order of the names a sink announces in HELLO (``open_sink(url, cameras=...)``). Its ``scene_flags`` are
    :func:`scene_flags`; ``calibration_suspect`` is the daemon's calibration check (``CalibrationWatch.suspect``).
    """
    missing = np.asarray(result.missing, bool)
    xyz = np.where(missing[:, None], np.nan, result.joints_3d)
    conf = np.where(missing, 0.0, result.confidence)
    joints_2d = {}
    for index, frame in enumerate(pair.frames):
        m2 = np.asarray(result.missing_2d[frame.camera], bool)
        uv = np.where(m2[:, None], np.nan, result.joints_2d[frame.camera])
        joints_2d[index] = np.column_stack([uv, np.where(m2, 0.0, result.confidence_2d[frame.camera])])
    return JointFrame(
        sequence=sequence,
        capture_time_us=capture_time_us(pair),
        joint_set=0,
        joints_3d=np.column_stack([xyz, conf]),
        joints_2d=joints_2d,
        scene_flags=scene_flags(result, calibration_suspect=calibration_suspect),
    )
