"""Keeping a sink within its link's capacity (pure; driven by capture timestamps)."""
from __future__ import annotations

from typing import Optional

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
    """

    def __init__(self, max_fps: Optional[float]) -> None:
        self.max_fps = max_fps
        self._interval_us = None if max_fps is None else 1e6 / max_fps
        self._tat: Optional[float] = None  # theoretical arrival time of the next frame

    def admit(self, t_us: int) -> bool:
        if self._interval_us is None:
            return True
        if self._tat is None or t_us < self._tat - self._interval_us - 1e6:
            # First frame, or the capture clock jumped back by more than a second (a new session).
            self._tat = float(t_us) + self._interval_us
            return True
        if t_us < self._tat - self._interval_us / 2:
            return False
        self._tat = max(self._tat, float(t_us)) + self._interval_us
        return True
