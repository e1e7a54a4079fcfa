"""Pairing of two cameras' frame streams by capture timestamp.

Pure logic, no threads and no I/O: the base class feeds it frames in arrival
order and asks for pairs. Kept separate so the policy is testable frame by
frame.
"""
from __future__ import annotations

import numbers
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

from drivers.errors import RigConfigError, RigOperationError
from drivers.frames import Frame
from ghnerf_runtime.path_check import shown
from ghnerf_runtime.plain_values import is_finite_number, is_real_number, is_true_false


class DropPolicy(str, Enum):
    """What to do with frames that can no longer be paired.

    ``LATEST``: a live device wants the newest pair; older complete pairs
    waiting in the queue are dropped (and counted) so latency never grows.
    ``ALL``: deliver every pair in order (recording, offline processing).
    """

    LATEST = "latest"
    ALL = "all"


#: Frames more than this apart (10 s) are never one moment, whatever the source.
MAX_TOLERANCE_MS = 10_000.0

#: Largest ``max_pending`` and ``max_ready``. The pairer holds up to ``2 * (max_pending + max_ready)`` frames, 1024
#: at this bound: 0.9 GiB of 640x480 BGR frames, 5.9 GiB of 1920x1080, 192 GiB of the largest frame a backend
#: makes (8192x8192, 192 MiB each), where the defaults' 144 frames are already 27 GiB. So the bound only stops a
#: count no memory holds at any size (10**400 was taken); 256 pairs are 8.5 s of a stalled 30 fps reader.
MAX_HELD = 256


@dataclass(frozen=True)
class PairingConfig:
    """How frames of the two cameras are matched.

    Attributes:
        tolerance_ms: largest capture-time difference for two frames to form a pair.
            Default: a third of a 30 fps frame period.
        policy: see :class:`DropPolicy`.
        max_pending: frames kept per camera while waiting for a partner (1 to :data:`MAX_HELD`).
        max_ready: complete pairs queued for the reader (``ALL`` policy; 1 to :data:`MAX_HELD`).
    """

    tolerance_ms: float = 11.0
    policy: DropPolicy = DropPolicy.LATEST
    max_pending: int = 8
    max_ready: int = 64

    def __post_init__(self) -> None:
        # a Python or numpy number, stored as Python's (True was 1 ms, "5" a bare TypeError); NaN is refused too,
        # and a huge one, whose int(ns) overflowed
        if not (is_real_number(self.tolerance_ms) and 0 < self.tolerance_ms <= MAX_TOLERANCE_MS):
            raise RigConfigError(f"pairing tolerance_ms must be a number in (0, {MAX_TOLERANCE_MS:g}], "
                                 f"got {self.tolerance_ms!r}")
        object.__setattr__(self, "tolerance_ms", float(self.tolerance_ms))
        try:
            object.__setattr__(self, "policy", DropPolicy(self.policy))
        except ValueError:
            raise RigConfigError(
                f"pairing policy must be one of {[p.value for p in DropPolicy]}, got {self.policy!r}"
            ) from None
        for name in ("max_pending", "max_ready"):
            value = getattr(self, name)
            if not (isinstance(value, numbers.Integral) and not is_true_false(value)
                    and 1 <= value <= MAX_HELD):
                # 2.5 held 3 frames, True 1; 10**400 was taken, a queue no memory holds
                raise RigConfigError(f"pairing {name} must be a whole number in [1, {MAX_HELD}] "
                                     f"(frames held in memory), got {value!r}")
            object.__setattr__(self, name, int(value))


@dataclass
class PairingStats:
    """Counters a user (and the daemon's health report) reads to see what was lost and why."""

    frames_in: dict[str, int] = field(default_factory=dict)
    pairs_out: int = 0
    unpaired: dict[str, int] = field(default_factory=dict)  # frames that never found a partner
    # complete pairs discarded by the LATEST policy or a full queue, or lost whole before pairing
    # (both cameras' frames at once: depthai's host queue); sequence gaps count them all
    pairs_dropped: int = 0
    # index gaps: frames the camera skipped, or the backend lost one camera at a time before pairing
    # (a backend counter says so: sim's and opencv's ``overruns``)
    camera_gaps: dict[str, int] = field(default_factory=dict)
    # of ``unpaired``: frames dropped because their camera already held ``max_pending`` waiting for the other's (the
    # other silent, or its frames arriving that many frames behind): says when ``max_pending`` is what stops pairs
    overflowed: dict[str, int] = field(default_factory=dict)

    def snapshot(self) -> "PairingStats":
        return PairingStats(
            dict(self.frames_in), self.pairs_out, dict(self.unpaired), self.pairs_dropped, dict(self.camera_gaps),
            dict(self.overflowed),
        )


#: Frame intervals remembered per camera: 3/4 of the shortest of them bounds how soon its next frame comes.
RECENT_INTERVALS = 8
#: Links of a run of ever closer frames the pairer looks along before deciding (see FramePairer._decide).
LOOKAHEAD = 2


class FramePairer:
    """Matches frames from two named cameras into pairs by nearest capture timestamp.

    The closest two frames (within tolerance) pair first, then the closest of the rest, and so on,
    as if every frame were known in advance: each frame gets its nearest partner unless that one is
    nearer still to another frame. Pairing a frame with the first partner in tolerance instead took
    a worse partner whenever the cameras ran at different rates or jittered, and then left the
    better frame unpaired (30 against 25 fps: pairs up to 20 ms apart where 13.3 ms was possible;
    ``benchmarks/measure_pairing.py``).

    Frames of each camera come in capture order, and the two cameras' frames nearly so. The oldest
    frame held is decided (paired with the other camera's next frame, or unpaired) once it is known
    whether a later frame is closer to that partner (:meth:`_decide`): once each camera has
    delivered a frame after the pair, or sooner where none can be closer (a camera's next frame
    comes at least 3/4 of its shortest recent interval after its last). A pair is so held back by
    at most one frame; simultaneous captures (a shared trigger, an OAK) pair at once. When the
    stream ends, :meth:`flush` decides what is still held.
    """

    def __init__(self, cameras: tuple[str, str], config: PairingConfig | None = None) -> None:
        self.cameras = cameras
        self.config = config or PairingConfig()
        self._tolerance_ns = int(self.config.tolerance_ms * 1e6)
        self._pending: dict[str, deque[Frame]] = {c: deque() for c in cameras}
        self._last_index: dict[str, int] = {}
        self._newest_ns: dict[str, int] = {}  # each camera's latest capture time pushed
        self._intervals: dict[str, deque[int]] = {c: deque(maxlen=RECENT_INTERVALS) for c in cameras}
        self._ready: deque[tuple[int, Frame, Frame]] = deque()
        self._formed = 0  # pairs formed so far: the sequence number of the next pair
        self.stats = PairingStats(
            frames_in={c: 0 for c in cameras}, unpaired={c: 0 for c in cameras}, camera_gaps={c: 0 for c in cameras},
            overflowed={c: 0 for c in cameras},
        )

    def push(self, frame: Frame) -> None:
        """Offer one frame; any pair it lets the pairer decide becomes available from :meth:`pop`."""
        if frame.camera not in self._pending:
            raise RigConfigError(f"frame from unknown camera {frame.camera!r}; pairing {list(self.cameras)}")
        cam = frame.camera
        _check_stamp(frame)
        self.stats.frames_in[cam] += 1
        last = self._last_index.get(cam)
        if last is not None and frame.index > last + 1:
            self.stats.camera_gaps[cam] += frame.index - last - 1
        self._last_index[cam] = frame.index

        newest = self._newest_ns.get(cam)
        if newest is not None and frame.timestamp_ns < newest:
            # Time went back (a clock reset, a bad stamp): this camera's held frames are of a timeline that
            # has ended. They are decided now, on what is known, so its queue stays in capture order.
            self._settle(final=True, until_gone=cam)
            self._intervals[cam].clear()
            self._drop_stale(self._other(cam), frame.timestamp_ns)
        elif newest is not None:
            self._intervals[cam].append(frame.timestamp_ns - newest)
        self._newest_ns[cam] = frame.timestamp_ns
        queue = self._pending[cam]
        queue.append(frame)
        self._settle()
        while len(queue) > self.config.max_pending:  # the other camera is silent or lags: bounded memory
            queue.popleft()
            self.stats.unpaired[cam] += 1
            self.stats.overflowed[cam] += 1
            self._settle()

    def flush(self) -> None:
        """No frame will follow (the stream ended): decide every held frame on what is known."""
        self._settle(final=True)

    def _other(self, cam: str) -> str:
        return self.cameras[1] if cam == self.cameras[0] else self.cameras[0]

    def _drop_stale(self, cam: str, reset_ns: int) -> None:
        """The other camera's clock went back to ``reset_ns``: drop (as unpaired) ``cam``'s held frames
        beyond its tolerance. They were captured before that reset (on a live rig both clocks usually
        reset together); kept, they are older than the other camera's first frames after it by more than
        the tolerance, which then went unpaired: a pair lost per reset. A frame within tolerance may still
        pair (a stamp stepped back a little) and is kept. The cost: where only one stamp was bad and the
        clock comes back, a frame ``cam`` held beyond it is lost, which its partner's next frame could
        have paired with (the frame the bad stamp belonged to is lost either way)."""
        held = self._pending[cam]
        dropped = 0
        while held and held[-1].timestamp_ns > reset_ns + self._tolerance_ns:
            held.pop()
            dropped += 1
        self.stats.unpaired[cam] += dropped
        if not held:
            self._newest_ns.pop(cam, None)  # on the old timeline: says nothing of the new one
        elif dropped:
            self._newest_ns[cam] = held[-1].timestamp_ns  # the dropped stamps are of the old timeline

    def _earliest_next_ns(self, cam: str) -> int | None:
        """The earliest capture time ``cam``'s next frame can have: three quarters of its shortest recent
        interval on (``None``: nothing known). Jitter a tenth of the period leaves the bound ~3 standard
        deviations of an interval in hand; a camera that speeds up past it costs one nearest pair, no more."""
        newest = self._newest_ns.get(cam)
        if newest is None or not self._intervals[cam]:
            return newest
        return newest + min(self._intervals[cam]) * 3 // 4

    def _settle(self, final: bool = False, until_gone: str | None = None) -> None:
        """Decide the oldest held frames while their fate is known (see the class docstring).

        ``final``: no frame will follow, so decide them all; with ``until_gone``, only until that
        camera holds none (the other camera's later frames may pair with what comes next)."""
        first, second = (self._pending[c] for c in self.cameras)
        while True:
            if until_gone is not None and not self._pending[until_gone]:
                return
            if not first or not second:
                waiting = first or second
                cam = self.cameras[0] if first else self.cameras[1]
                other_newest = self._newest_ns.get(self._other(cam))
                # final: no partner will come; else frames the other camera is already past can never pair
                while waiting and (final or (other_newest is not None
                                             and waiting[0].timestamp_ns < other_newest - self._tolerance_ns)):
                    waiting.popleft()
                    self.stats.unpaired[cam] += 1
                return
            chain = self._chain(LOOKAHEAD + 2)
            decision = self._decide(chain, final)
            if decision is None:
                return  # a frame still to come decides it
            (x, x_cam), (y, y_cam) = chain[0], chain[1]
            self._pending[x_cam].popleft()
            if not decision:
                self.stats.unpaired[x_cam] += 1
                continue
            self._pending[y_cam].popleft()
            self._form((x, y) if x_cam == self.cameras[0] else (y, x))

    def _chain(self, n: int) -> list[tuple[Frame, str]]:
        """The first ``n`` held frames of both cameras in capture order (ties: the first camera first)."""
        queues = [self._pending[c] for c in self.cameras]
        at = [0, 0]
        out: list[tuple[Frame, str]] = []
        while len(out) < n:
            a, b = (q[k] if k < len(q) else None for q, k in zip(queues, at))
            if a is None and b is None:
                break
            i = 0 if b is None or (a is not None and a.timestamp_ns <= b.timestamp_ns) else 1
            out.append((queues[i][at[i]], self.cameras[i]))
            at[i] += 1
        return out

    def _decide(self, chain: list[tuple[Frame, str]], final: bool) -> bool | None:
        """Whether the oldest frame pairs with the next one (True), is unpaired (False), or must wait (None).

        ``chain`` holds frames in capture order, c0 c1 c2 ... Two frames can only pair if they are
        neighbours in it and of different cameras (a frame between them is closer to one of them).
        The closest such neighbours pair first: c0-c1 does unless c1-c2 is closer and takes c1. But
        c1-c2 is lost in turn if c2-c3 is closer still, and so on: along a run of ever closer
        neighbours every second link pairs. Runs longer than :data:`LOOKAHEAD` links are cut there
        (assumed to end), so a pair waits for at most that many more frames.
        """
        (x, x_cam), (y, y_cam) = chain[0], chain[1]
        gap = y.timestamp_ns - x.timestamp_ns
        if y_cam == x_cam or gap > self._tolerance_ns:
            return False
        links = 0  # links of the run of ever closer neighbours after c0-c1
        while links < LOOKAHEAD:
            end, end_cam = chain[links + 1]
            if links + 2 < len(chain):
                nxt, nxt_cam = chain[links + 2]
                next_gap = nxt.timestamp_ns - end.timestamp_ns
                if nxt_cam == end_cam or next_gap >= gap:  # ties: the earlier pair
                    break
            elif final or (earliest := self._earliest_next_ns(self._other(end_cam))) is not None \
                    and earliest >= end.timestamp_ns + gap:
                break  # nothing closer can come: the other camera's next frame is too late
            else:
                return None
            links, gap = links + 1, next_gap
        return links % 2 == 0

    def _form(self, pair: tuple[Frame, Frame]) -> None:
        self._ready.append((self._formed, *pair))
        self._formed += 1
        limit = 1 if self.config.policy is DropPolicy.LATEST else self.config.max_ready
        while len(self._ready) > limit:
            self._ready.popleft()
            self.stats.pairs_dropped += 1

    def skip_pairs(self, n: int) -> None:
        """``n`` pairs lost whole before the next frames (both cameras skipped together): dropped,
        with their sequence numbers, and not counted again as the cameras' index gaps."""
        self._formed += n
        self.stats.pairs_dropped += n
        for cam in self._last_index:
            self._last_index[cam] += n

    def replace_held(self, replace: Callable[[Frame], Frame]) -> None:
        """Put ``replace(frame)`` in place of every frame still held (waiting for a partner, or in a
        pair not yet read): a backend loads here the images of frames it pushed without them."""
        for queue in self._pending.values():
            for i, frame in enumerate(queue):
                queue[i] = replace(frame)
        for i, (sequence, first, second) in enumerate(self._ready):
            self._ready[i] = (sequence, replace(first), replace(second))

    def discard_held(self, drop: Callable[[Frame], bool]) -> None:
        """Forget every held frame for which ``drop(frame)`` is true (one whose image could not be loaded):
        a waiting one counts as unpaired, a pair not yet read that holds one as dropped (a sequence gap)."""
        for cam, queue in self._pending.items():
            kept = [frame for frame in queue if not drop(frame)]
            self.stats.unpaired[cam] += len(queue) - len(kept)
            queue.clear()
            queue.extend(kept)
        ready = [item for item in self._ready if not (drop(item[1]) or drop(item[2]))]
        self.stats.pairs_dropped += len(self._ready) - len(ready)
        self._ready.clear()
        self._ready.extend(ready)
        self._settle()  # a frame that waited on a discarded one may be decided now

    def pop(self) -> tuple[int, Frame, Frame] | None:
        """The next complete pair as ``(sequence, frame_a, frame_b)``, or ``None``.

        Sequence numbers count every pair formed, so a reader sees dropped pairs as gaps.
        """
        if not self._ready:
            return None
        self.stats.pairs_out += 1
        return self._ready.popleft()

    def reset(self) -> None:
        """Decide the held frames on what is known, then forget the cameras' history (after a
        reconnect the old frames can never pair, and indices and capture times restart)."""
        self._settle(final=True)
        self._last_index.clear()
        self._newest_ns.clear()
        for intervals in self._intervals.values():
            intervals.clear()


def _check_stamp(frame: Frame) -> None:
    """Refuse a capture time that is no finite number. NaN compares false with every stamp, so a NaN frame paired
    with whatever came next (a pair with no capture time went out as valid); None raised a bare TypeError from a
    comparison deep in the pairer; inf never paired and no counter said why."""
    if type(frame.timestamp_ns) is int:  # every backend's stamp: skip the ABC checks, a fifth of push's time
        return
    if not is_finite_number(frame.timestamp_ns):
        raise RigOperationError(f"frame {frame.index} of camera {frame.camera!r} has capture time timestamp_ns="
                                f"{frame.timestamp_ns!r}: a finite number of nanoseconds expected")


def frames_since(before: PairingStats, after: PairingStats) -> dict[str, int]:
    """Frames each camera delivered between two snapshots of the counters."""
    return {cam: after.frames_in.get(cam, 0) - before.frames_in.get(cam, 0) for cam in after.frames_in}


def silent_cameras(before: PairingStats, after: PairingStats) -> list[str]:
    """The cameras that delivered no frame between two snapshots of the counters."""
    return [cam for cam, n in frames_since(before, after).items() if n == 0]


def why_no_pair(before: PairingStats, after: PairingStats, config: PairingConfig) -> str:
    """What the counters say of a stretch with no pair (``before``: at the last pair or the open): a camera that
    delivered nothing, or frames of both cameras that never paired: within the tolerance, or while the pairer held
    ``max_pending`` frames of one camera for the other's (a lagging transport). Each needs its own remedy (a cable,
    the cameras' sync, ``max_pending``), and "no pair" alone sent the operator to the cable."""
    came = frames_since(before, after)
    silent = silent_cameras(before, after)
    if len(silent) == len(came):
        return "neither camera delivered a frame"
    if silent:
        # a rig file's names, which may hold any text: escaped where a log or status line would act on it (an ESC)
        others = ", ".join(f"{shown(cam)}: {n}" for cam, n in came.items() if n)
        return f"camera {silent[0]!r} delivered no frame ({others})"
    counts = ", ".join(f"{shown(cam)} {n}" for cam, n in came.items())
    waited_out = _overflowed_since(before, after)
    if any(waited_out.values()):
        # the pairer's wait ran out (max_pending): the other camera's frames were still to come when these went
        ahead = max(waited_out, key=waited_out.__getitem__)
        behind = next(cam for cam in came if cam != ahead)
        return (f"frames came from both cameras ({counts}) but none paired: camera {ahead!r} held max_pending="
                f"{config.max_pending} frames waiting for {behind!r}'s and dropped {waited_out[ahead]} more, so "
                f"{behind!r}'s frames arrive {config.max_pending} or more frames behind (a slower transport: raise "
                f"the rig URL's max_pending, at most {MAX_HELD}), or its clock is behind")
    return (f"frames came from both cameras ({counts}) but none paired within the pairing tolerance of "
            f"{config.tolerance_ms:g} ms: the cameras do not capture together")


def _overflowed_since(before: PairingStats, after: PairingStats) -> dict[str, int]:
    """Frames each camera dropped for ``max_pending`` between two snapshots of the counters."""
    return {cam: after.overflowed.get(cam, 0) - before.overflowed.get(cam, 0) for cam in after.frames_in}
