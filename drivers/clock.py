"""Injectable clocks, so the simulated rig's timing is testable without sleeping."""
from __future__ import annotations

import threading
import time
from typing import Protocol


class Clock(Protocol):
    """Monotonic time source in nanoseconds."""

    def now_ns(self) -> int: ...

    def sleep_until(self, deadline_ns: int) -> None: ...

    def wait_until(self, deadline_ns: int, wake: threading.Event) -> bool:
        """As :meth:`sleep_until`, but returns early once ``wake`` is set (a close from another thread); True:
        woken."""
        ...


class MonotonicClock:
    """The real clock: ``time.monotonic_ns`` and real sleeping."""

    def now_ns(self) -> int:
        return time.monotonic_ns()

    def sleep_until(self, deadline_ns: int) -> None:
        delay = (deadline_ns - time.monotonic_ns()) / 1e9
        if delay > 0:
            time.sleep(delay)

    def wait_until(self, deadline_ns: int, wake: threading.Event) -> bool:
        # Looped on the clock, so that it never returns before the deadline (as time.sleep does not) and a wait
        # longer than Event.wait takes (threading.TIMEOUT_MAX) is waited in parts.
        while not wake.is_set():
            delay = (deadline_ns - time.monotonic_ns()) / 1e9
            if delay <= 0:
                return False
            wake.wait(min(delay, threading.TIMEOUT_MAX))
        return True


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

    def wait_until(self, deadline_ns: int, wake: threading.Event) -> bool:
        if wake.is_set():
            return True  # woken before it slept: no time passes
        self.sleep_until(deadline_ns)
        return False
