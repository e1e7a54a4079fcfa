"""Keeping a sink within its link's capacity (pure; driven by capture timestamps)."""
from __future__ import annotations

import math
from typing import Optional

#: Lowest ``max_fps``: a frame an hour, the longest STATUS period. Below a subnormal one the interval
#: overflowed to inf, and inf - inf made every comparison false, so every frame was admitted.
MIN_MAX_FPS = 1 / 3600

# Share of a serial link's raw byte rate given to JOINTS frames; the rest covers
# HELLO/STATUS packets and scheduling jitter so the UART never backs up.
SERIAL_HEADROOM = 0.9
# 8N1: one start bit, eight data bits, one stop bit.
SERIAL_BITS_PER_BYTE = 10


def serial_capacity_fps(baud: int, bytes_per_frame: int, headroom: float = SERIAL_HEADROOM) -> float:
    """Highest JOINTS rate a UART at ``baud`` carries without backing up."""
    return baud / SERIAL_BITS_PER_BYTE / bytes_per_frame * headroom


class RateLimiter:
    """Admits frames at no more than ``max_fps`` on average (GCRA / virtual scheduling).

    A frame is admitted if it is not earlier than its theoretical slot minus a
    tolerance of half an interval, which absorbs capture jitter while keeping the
    long-run rate at or below ``max_fps``. Time is the frames' capture
    timestamps, so decimation is deterministic and testable. ``max_fps=None``
    admits everything.

    A capture clock that steps back by more than a second (a new session) starts
    the schedule again; a smaller step back holds frames (decimated) until the
    clock is past the last admitted frame again, so it never admits a burst.

    :raises ValueError: ``max_fps`` not a finite number >= :data:`MIN_MAX_FPS`.
    """

    def __init__(self, max_fps: Optional[float]) -> None:
        if max_fps is not None and not (math.isfinite(max_fps) and max_fps >= MIN_MAX_FPS):
            # 0 divided by zero; a negative or NaN rate admitted every frame
            raise ValueError(f"max_fps={max_fps!r}: must be a finite number >= {MIN_MAX_FPS:.6g} (a frame an hour)")
        self.max_fps = max_fps
        self._interval_us = None if max_fps is None else 1e6 / max_fps
        # Theoretical arrival time of the next frame, in µs since _origin_us (the stamp that began the schedule): a
        # float of the stamp itself rounds to 2048 µs near the top of the u64 range, and 60 fps capped at 30 sent 30.5.
        self._tat: Optional[float] = None
        self._origin_us = 0
        self._last_us: Optional[int] = None  # capture time of the last frame admitted

    def admit(self, t_us: int) -> bool:
        if self._interval_us is None:
            return True
        # A step back is measured from the last admitted frame, not from the schedule: that runs up to
        # half an interval ahead of it, so with an interval over 2 s every frame after an admitted one
        # looked like a clock a second back, restarted the schedule and went out too (4x the cap at 0.1 fps).
        if self._tat is None or self._last_us is None or t_us < self._last_us - 1_000_000:
            # First frame, or the capture clock jumped back by more than a second (a new session).
            self._origin_us, self._tat = t_us, self._interval_us
            self._last_us = t_us
            return True
        t = t_us - self._origin_us  # exact; as a float exact for 285 years of schedule (2**53 µs)
        if t < self._tat - self._interval_us / 2:
            return False
        self._tat = max(self._tat, float(t)) + self._interval_us
        self._last_us = t_us
        return True
