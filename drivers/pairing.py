"""Pairing of two cameras' frame streams by capture timestamp.

Pure logic, no threads and no I/O: the base class feeds it frames in arrival
order and asks for pairs. Kept separate so the policy is testable frame by
frame.
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

from drivers.errors import RigConfigError
from drivers.frames import Frame


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


@dataclass(frozen=True)
class PairingConfig:
    """How frames of the two cameras are matched.

    Attributes:
        tolerance_ms: largest capture-time difference for two frames to form a pair.
            Default: a third of a 30 fps frame period.
        policy: see :class:`DropPolicy`.
        max_pending: frames kept per camera while waiting for a partner.
        max_ready: complete pairs queued for the reader (``ALL`` policy).
    """

    tolerance_ms: float = 11.0
    policy: DropPolicy = DropPolicy.LATEST
    max_pending: int = 8
    max_ready: int = 64

    def __post_init__(self) -> None:
        if not 0 < self.tolerance_ms <= MAX_TOLERANCE_MS:  # NaN too; int(ns) of a huge one overflowed
            raise RigConfigError(f"pairing tolerance_ms must be a number in (0, {MAX_TOLERANCE_MS:g}], "
                                 f"got {self.tolerance_ms}")
        try:
            object.__setattr__(self, "policy", DropPolicy(self.policy))
        except ValueError:
            raise RigConfigError(
                f"pairing policy must be one of {[p.value for p in DropPolicy]}, got {self.policy!r}"
            ) from None
        if self.max_pending < 1 or self.max_ready < 1:
            raise RigConfigError(
                f"pairing max_pending and max_ready must be >= 1, got {self.max_pending}, {self.max_ready}"
            )


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

    def snapshot(self) -> "PairingStats":
        return PairingStats(
            dict(self.frames_in), self.pairs_out, dict(self.unpaired), self.pairs_dropped, dict(self.camera_gaps)
        )


class FramePairer:
    """Matches frames from two named cameras into pairs by nearest capture timestamp.

    A frame pairs with the pending frame of the other camera closest in time if
    within tolerance. Pending frames older than the newest frame of the other
    camera minus the tolerance can never pair (cameras deliver in time order)
    and are discarded as unpaired.
    """

    def __init__(self, cameras: tuple[str, str], config: PairingConfig | None = None) -> None:
        self.cameras = cameras
        self.config = config or PairingConfig()
        self._tolerance_ns = int(self.config.tolerance_ms * 1e6)
        self._pending: dict[str, deque[Frame]] = {c: deque() for c in cameras}
        self._last_index: dict[str, int] = {}
        self._ready: deque[tuple[int, Frame, Frame]] = deque()
        self._formed = 0  # pairs formed so far: the sequence number of the next pair
        self.stats = PairingStats(
            frames_in={c: 0 for c in cameras}, unpaired={c: 0 for c in cameras}, camera_gaps={c: 0 for c in cameras}
        )

    def push(self, frame: Frame) -> None:
        """Offer one frame; any pair it completes becomes available from :meth:`pop`."""
        if frame.camera not in self._pending:
            raise RigConfigError(f"frame from unknown camera {frame.camera!r}; pairing {list(self.cameras)}")
        cam = frame.camera
        other = self.cameras[1] if cam == self.cameras[0] else self.cameras[0]
        self.stats.frames_in[cam] += 1
        last = self._last_index.get(cam)
        if last is not None and frame.index > last + 1:
            self.stats.camera_gaps[cam] += frame.index - last - 1
        self._last_index[cam] = frame.index

        candidates = self._pending[other]
        # Partners too old to ever match this or any later frame are lost.
        while candidates and candidates[0].timestamp_ns < frame.timestamp_ns - self._tolerance_ns:
            candidates.popleft()
            self.stats.unpaired[other] += 1
        best = None
        for i, cand in enumerate(candidates):
            dt = abs(cand.timestamp_ns - frame.timestamp_ns)
            if dt <= self._tolerance_ns and (best is None or dt < best[1]):
                best = (i, dt)
        if best is None:
            queue = self._pending[cam]
            queue.append(frame)
            while len(queue) > self.config.max_pending:
                queue.popleft()
                self.stats.unpaired[cam] += 1
            return
        # Frames of the other camera older than the chosen partner can no longer pair.
        for _ in range(best[0]):
            candidates.popleft()
            self.stats.unpaired[other] += 1
        partner = candidates.popleft()
        pair = (frame, partner) if cam == self.cameras[0] else (partner, frame)
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

    def pop(self) -> tuple[int, Frame, Frame] | None:
        """The next complete pair as ``(sequence, frame_a, frame_b)``, or ``None``.

        Sequence numbers count every pair formed, so a reader sees dropped pairs as gaps.
        """
        if not self._ready:
            return None
        self.stats.pairs_out += 1
        return self._ready.popleft()

    def reset(self) -> None:
        """Forget pending frames (after a reconnect the old ones can never pair)."""
        for cam, queue in self._pending.items():
            self.stats.unpaired[cam] += len(queue)
            queue.clear()
        self._last_index.clear()
