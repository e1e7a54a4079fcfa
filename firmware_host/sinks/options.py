"""Options every sink understands, from the URL query or keyword arguments."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Optional, Sequence

from firmware_host.errors import SinkConfigError
from firmware_host.protocol.constants import ALL_SCENE_FLAGS, SCENE_FLAGS
from firmware_host.sinks.backoff import BackoffPolicy
from firmware_host.sinks.rate import MIN_MAX_FPS
from firmware_host.sinks.url import SinkUrl, boolean, positive_float, positive_int
from ghnerf_runtime.plain_values import whole_number_or_none


def monotonic_us() -> int:
    return time.monotonic_ns() // 1000


#: Longest STATUS (and HELLO) period: an hour.
MAX_STATUS_S = 3600.0
#: Shortest STATUS (and HELLO) period: at most 100 of each a second on an idle link, a frame rate's worth (1e-300
#: was accepted: ~1000 a second, the worker doing nothing else). The tests' fast STATUS uses this floor.
MIN_STATUS_S = 0.01
#: Most frames a sink holds: over 2 minutes of outage at 30 fps (over one at 60 fps), ~11 MiB of BODY_25 frames with
#: both cameras' 2D joints (~23 MiB at 64 joints); 10**23 was accepted and grew without bound during an outage.
MAX_QUEUE = 4096
#: Shortest and longest ``stall_s``: below a few frames' time at 30 fps one late write would read as a stall; an
#: hour is as long as a STATUS period may be.
MIN_STALL_S, MAX_STALL_S = 0.1, 3600.0


def rig_id_text(raw: str) -> str:
    """The ``rig_id`` option: given empty (``rig_id=``) it is refused rather than read as the default (none
    announced), which hid a config whose value was left out."""
    if raw == "":
        raise ValueError("empty: give the id HELLO announces, or leave rig_id out")
    return raw


def camera_names_problem(names: Sequence[object]) -> str:
    """Why ``names`` cannot be the cameras HELLO announces, ``""`` when they can: JOINTS_2D numbers a camera by
    its place in the list, so an empty name (``a,,b``) or a name given twice (the second camera sent as the
    first) is refused."""
    seen: set[str] = set()
    for k, name in enumerate(names):
        if not isinstance(name, str):
            continue  # left to HELLO's encoder, which refuses a name that is not text
        if name == "":
            return f"camera {k} has an empty name (each comma separates two names)"
        if name in seen:
            return f"camera name {name!r} is given twice (JOINTS_2D numbers a camera by its place in the list)"
        seen.add(name)
    return ""


def scene_flags_mask(url: str, value: object) -> int:
    """The scene flags a HELLO announces (the ``scene_flags`` keyword), as a Python int: a whole number (NumPy's
    too) of scene-flag bits only, since a link bit or a reserved one announced would tell receivers something untrue.

    :raises SinkConfigError: keyed ``scene_flags``."""
    flags = whole_number_or_none(value)
    scene = f"the scene flags 0x{ALL_SCENE_FLAGS:02x}"
    if flags is None:
        raise SinkConfigError(url, "scene_flags", value, f"must be a whole number of {scene}, not "
                                                         f"{type(value).__name__}")
    if flags < 0 or flags & ~ALL_SCENE_FLAGS:
        raise SinkConfigError(url, "scene_flags", value, f"sets bits other than {scene}")
    return flags


def camera_names(raw: str) -> list[str]:
    """The ``cameras`` option as text: comma-separated names, in index order (:func:`camera_names_problem`).
    A name written with spaces around it (``left, right``) is refused too: ' right' is no camera's name, and its
    2D joints would never be sent. (A keyword's tuple, a rig's own names, is taken as named.)"""
    if raw == "":
        raise ValueError("empty: give the camera names in index order (e.g. cameras=left,right), or leave "
                         "cameras out")
    names = raw.split(",")
    problem = camera_names_problem(names) or next(
        (f"camera {k}'s name {name!r} has spaces around it (write the names without them)"
         for k, name in enumerate(names) if name != name.strip()), "")
    if problem:
        raise ValueError(problem)
    return names


def backoff_policy(url: str, value: object) -> BackoffPolicy:
    """The ``backoff`` keyword: a :class:`BackoffPolicy`, None for the default. Anything else reached the worker,
    whose first line died on it (a sink ``connecting`` for ever, its frames queued and never sent).

    :raises SinkConfigError: keyed ``backoff``."""
    if value is None:
        return BackoffPolicy()
    if not isinstance(value, BackoffPolicy):
        raise SinkConfigError(url, "backoff", value, f"must be a BackoffPolicy, not {type(value).__name__}")
    return value


def clock_function(url: str, value: object) -> Callable[[], int]:
    """The ``clock_us`` keyword: a callable returning microseconds, None for :func:`monotonic_us`. Anything else
    failed every connect as a backend bug, retried for ever.

    :raises SinkConfigError: keyed ``clock_us``."""
    if value is None:
        return monotonic_us
    if not callable(value):
        raise SinkConfigError(url, "clock_us", value, f"must be a function returning microseconds, not "
                                                      f"{type(value).__name__}")
    return value  # type: ignore[return-value]


@dataclass(frozen=True)
class SinkOptions:
    queue: int = 4
    """Frames held while the link is busy or away; when full the oldest is dropped and counted."""
    fps: Optional[float] = None
    """The producer's nominal rate, used to warn up front when the link cannot carry it."""
    max_fps: Optional[float] = None
    """Cap on the rate sent, on top of the link's own capacity."""
    status_s: float = 1.0
    """Period of STATUS (and repeated HELLO) packets on protocol sinks."""
    stall_s: float = 2.0
    """An open link that got no frame through for this long since a write failed, or whose write has been in
    progress this long, reads ``stalled`` (its receiver stopped reading) instead of ``up``."""
    send_2d: bool = False
    """Also send JOINTS_2D for each camera in ``JointFrame.joints_2d``."""
    rig_id: str = ""
    """Announced in HELLO (printable ASCII, at most 32 characters)."""
    cameras: tuple[str, ...] = ()
    """Camera names in index order, announced in HELLO; names in joints_2d map to these indices."""
    joint_count: int = 25
    """Joints per frame, used to size the link budget before the first frame."""
    backoff: BackoffPolicy = field(default_factory=BackoffPolicy)
    """Reconnect schedule after a failed connect or an unplug."""
    clock_us: Callable[[], int] = monotonic_us
    """Clock for send timestamps; must be the clock of ``JointFrame.capture_time_us``."""
    scene_flags: int = SCENE_FLAGS
    """The scene flags the producer sets on its frames, announced in HELLO's header flags (a keyword only: the
    producer's to say, not the link's): ``hello_scene_flags(True)`` where its estimator scans for others."""

    @classmethod
    def take(cls, u: SinkUrl, kw: dict) -> "SinkOptions":
        """Pop the common options from the URL query and ``kw`` (kw wins)."""
        opts = cls(
            queue=u.take("queue", positive_int, cls.queue, kw),
            fps=u.take("fps", positive_float, None, kw),
            max_fps=u.take("max_fps", positive_float, None, kw),
            status_s=u.take("status_s", positive_float, cls.status_s, kw),
            stall_s=u.take("stall_s", positive_float, cls.stall_s, kw),
            send_2d=u.take("send_2d", boolean, cls.send_2d, kw),
            rig_id=u.take("rig_id", rig_id_text, cls.rig_id, kw),
            cameras=tuple(u.take("cameras", camera_names, (), kw)),
            joint_count=u.take("joint_count", positive_int, cls.joint_count, kw),
            backoff=backoff_policy(u.url, kw.pop("backoff", None)),
            clock_us=clock_function(u.url, kw.pop("clock_us", None)),
            scene_flags=scene_flags_mask(u.url, kw.pop("scene_flags", SCENE_FLAGS)),
        )
        problem = camera_names_problem(opts.cameras)  # a keyword's tuple of names: the query's are checked above
        if problem:
            raise SinkConfigError(u.url, "cameras", opts.cameras, problem)
        if opts.max_fps is not None and opts.max_fps < MIN_MAX_FPS:
            # RateLimiter refuses it at start(); refused here it is named with its URL, at open_sink()
            raise SinkConfigError(u.url, "max_fps", opts.max_fps, f"must be at least {MIN_MAX_FPS:.6g} "
                                                                  "(a frame an hour)")
        if not 1 <= opts.queue <= MAX_QUEUE:
            # held in memory: a long outage keeps the newest MAX_QUEUE frames, the older ones dropped and counted
            raise SinkConfigError(u.url, "queue", opts.queue, f"must be in [1, {MAX_QUEUE}] frames")
        if not MIN_STATUS_S <= opts.status_s <= MAX_STATUS_S:
            # a receiver that joins late waits this long for HELLO; far larger also overflows the waits, and far
            # smaller floods an idle link with HELLO + STATUS
            raise SinkConfigError(u.url, "status_s", opts.status_s,
                                  f"must be in [{MIN_STATUS_S:g}, {MAX_STATUS_S:g}] seconds")
        if not MIN_STALL_S <= opts.stall_s <= MAX_STALL_S:
            # shorter reads one late write as a stalled receiver; longer hides one from the status file for hours
            raise SinkConfigError(u.url, "stall_s", opts.stall_s,
                                  f"must be in [{MIN_STALL_S:g}, {MAX_STALL_S:g}] seconds")
        return opts


def reject_unknown_kw(url: str, kw: dict) -> None:
    if kw:
        key = sorted(kw)[0]
        raise SinkConfigError(url, key, kw[key], "unknown keyword argument")
