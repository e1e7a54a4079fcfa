"""When the simulated cameras capture: the timing model of ``sim://``, pure and seeded.

Camera ``c`` captures its frame ``k`` at::

    start + k / fps + offset_c + jitter_ck

with ``offset`` = 0 for the first camera and ``offset_ms`` for the second, and
``jitter_ck`` Gaussian (standard deviation ``jitter_ms``) clipped to 45 % of a
frame period so a camera's captures stay in order. Each capture is dropped with
probability ``drop`` (independently per camera and frame). The second camera's frames
reach the host ``latency_ms`` after their capture (a slower transport, such
as a USB hub), the first camera's at it: frames come in order of arrival, stamped with
their capture time. Random draws come from
one generator per camera seeded by ``seed``, so the whole timeline is a function
of the options, never of how fast anybody reads.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivers.errors import RigConfigError


@dataclass(frozen=True)
class TimingModel:
    """Capture timing of the simulated pair (see the module docstring)."""

    fps: float = 30.0
    offset_ms: float = 0.0
    jitter_ms: float = 0.0
    drop: float = 0.0
    seed: int = 0
    latency_ms: float = 0.0

    def __post_init__(self) -> None:
        if not 0 < self.fps <= 1000:
            raise RigConfigError(f"sim timing: fps must be in (0, 1000], got {self.fps}")
        if not 0 <= self.drop <= 1:
            raise RigConfigError(f"sim timing: drop must be a probability in [0, 1], got {self.drop}")
        if self.jitter_ms < 0:
            raise RigConfigError(f"sim timing: jitter_ms must be >= 0, got {self.jitter_ms}")
        if not self.latency_ms >= 0:
            raise RigConfigError(f"sim timing: latency_ms must be >= 0, got {self.latency_ms}")

    @property
    def period_ns(self) -> float:
        return 1e9 / self.fps


@dataclass(frozen=True)
class Capture:
    """One capture instant of one camera (``dropped``: the camera lost it; it is never delivered)."""

    camera: int  # 0 or 1: position in the rig pair
    index: int
    time_ns: int  # absolute, on the source's clock
    nominal_ns: int  # the same without jitter: start + index / fps + offset
    dropped: bool
    arrival_ns: int  # when it reaches the host: time_ns, plus latency_ms for the second camera


class _CameraTimeline:
    def __init__(self, model: TimingModel, camera: int, start_ns: int) -> None:
        self._model = model
        self._camera = camera
        self._start_ns = start_ns + (int(round(model.offset_ms * 1e6)) if camera == 1 else 0)
        self._latency_ns = int(round(model.latency_ms * 1e6)) if camera == 1 else 0
        self._rng = np.random.default_rng([model.seed, camera])
        self._limit_ns = 0.45 * model.period_ns
        self.index = 0
        # A negative offset puts the camera's first captures before the source opened: it starts with the
        # first due after (the others never happened), not with old frames counted as the reader's overruns.
        # Their random draws are still made, so each index keeps its jitter and drop.
        while self._start_ns + int(round(self.index * model.period_ns)) < start_ns:
            self._make(self.index)
            self.index += 1
        self.head = self._make(self.index)

    def _make(self, index: int) -> Capture:
        m = self._model
        nominal = self._start_ns + int(round(index * m.period_ns))
        # Both draws are always made so jitter does not depend on drop (and vice versa).
        jitter = float(np.clip(self._rng.normal(0.0, m.jitter_ms * 1e6), -self._limit_ns, self._limit_ns))
        dropped = bool(self._rng.random() < m.drop)
        time_ns = nominal + int(round(jitter)) if m.jitter_ms else nominal
        return Capture(self._camera, index, time_ns, nominal, dropped, time_ns + self._latency_ns)

    def advance(self) -> Capture:
        current = self.head
        self.index += 1
        self.head = self._make(self.index)
        return current


class CaptureSchedule:
    """Both cameras' captures merged in order of arrival at the host (ties: first camera first).

    Args:
        model: the timing model.
        start_ns: the instant of frame 0 of the first camera.
    """

    def __init__(self, model: TimingModel, start_ns: int) -> None:
        self.model = model
        self.start_ns = start_ns
        self._timelines = (_CameraTimeline(model, 0, start_ns), _CameraTimeline(model, 1, start_ns))

    def peek(self) -> Capture:
        """The next capture (delivered or dropped), without consuming it."""
        a, b = self._timelines[0].head, self._timelines[1].head
        return a if a.arrival_ns <= b.arrival_ns else b

    def pop(self) -> Capture:
        """Consume and return the next capture."""
        nxt = self.peek()
        return self._timelines[nxt.camera].advance()
