"""Injectable clocks, so the simulated rig's timing is testable without sleeping."""
from __future__ import annotations

import threading
import time
from typing import Protocol


class Clock(Protocol):
    """Monotonic time source in nanoseconds."""

    def now_ns(self) -> int: ...

    def sleep_until(self, deadline_ns: int) -> None: ...


class MonotonicClock:
    """The real clock: ``time.monotonic_ns`` and real sleeping."""

    def now_ns(self) -> int:
        return time.monotonic_ns()

    def sleep_until(self, deadline_ns: int) -> None:
        delay = (deadline_ns - time.monotonic_ns()) / 1e9
        if delay > 0:
            time.sleep(delay)


class ManualClock:
    """A clock that only moves when told to; ``sleep_until`` jumps straight to the deadline.

    Lets tests run a 30 fps timing model at full CPU speed with exact timestamps.
    """

    def __init__(self, start_ns: int = 0) -> None:
        self._now = int(start_ns)
        self._lock = threading.Lock()

    def now_ns(self) -> int:
        with self._lock:
            return self._now

    def advance(self, delta_ns: int) -> None:
        with self._lock:
            self._now += int(delta_ns)

    def sleep_until(self, deadline_ns: int) -> None:
        with self._lock:
            self._now = max(self._now, int(deadline_ns))
