"""Whether the rig's calibration still fits its cameras, from the pairs the daemon estimates.

A camera knocked on its mount after calibration leaves the rig file describing a camera that is no
longer there: the 3D joints go wrong (or every joint fails the reprojection gate and the pairs show
nobody), silently. Each pair says how far its two views' confident peaks are from meeting in 3D
(``PairResult.reprojection_px_median``, measured before the gate); a tilt of either camera raises it for
every pair at once, while a moving person, a pose or a noisy peak raises it for a few. So the watch
takes the median over the last ``window`` measured pairs (pairs without one, an empty room, do not
count) and calls the calibration suspect above ``max_px``, and fits again once that median is back
under ``CLEAR_RATIO`` of it (no flapping near the limit). Measured on the simulated rig with the shipped
model: ``benchmarks/measure_calibration_drift.py``, docs/calibration.md "When the rig no longer fits".
"""
from __future__ import annotations

from collections import deque
from typing import Any, Optional

import numpy as np

__all__ = ["CalibrationWatch", "CLEAR_RATIO"]

#: A suspect calibration fits again once the median is under this share of ``max_px``.
CLEAR_RATIO = 0.75


class CalibrationWatch:
    """The rolling median of the pairs' view agreement, and whether it says the rig has moved.

    Args:
        window: measured pairs the median is taken over; none is judged before it is full.
        max_px: the median (model-input pixels) above which the calibration is suspect; ``None``: never.

    Example:
        >>> watch = CalibrationWatch(window=3, max_px=1.0)
        >>> [watch.add(px) for px in (0.3, 2.0, None, 2.5, 2.2, 0.2, 0.1, 0.3)]
        [None, None, None, True, None, None, False, None]
        >>> watch.report()
        {'reprojection_px_median': 0.2, 'pairs': 3, 'window': 3, 'max_px': 1.0, 'suspect': False}
    """

    def __init__(self, window: int, max_px: Optional[float]) -> None:
        self.window = int(window)
        self.max_px = max_px
        self.values: deque[float] = deque(maxlen=self.window)
        self.suspect = False

    def configure(self, window: int, max_px: Optional[float]) -> Optional[bool]:
        """New settings (a reload), keeping the newest values that fit; returns :meth:`add`'s answer for them."""
        self.window, self.max_px = int(window), max_px
        self.values = deque(self.values, maxlen=self.window)
        return self._judge()

    def reset(self) -> None:
        """Forget every value (another calibration or model: the old pairs say nothing of it)."""
        self.values.clear()
        self.suspect = False

    @property
    def median_px(self) -> Optional[float]:
        return float(np.median(self.values)) if self.values else None

    def add(self, px: Optional[float]) -> Optional[bool]:
        """One estimated pair's ``reprojection_px_median`` (``None``: not measured, not counted). Returns the new
        state when it changes (True: now suspect, False: fits again), else ``None``: the caller logs transitions."""
        if px is None or not np.isfinite(px):
            return None
        self.values.append(float(px))
        return self._judge()

    def _judge(self) -> Optional[bool]:
        median = self.median_px
        if self.max_px is None or median is None:
            now = False
        elif len(self.values) < self.window:
            now = self.suspect  # too few pairs to change the verdict
        else:
            now = median > self.max_px if not self.suspect else median >= CLEAR_RATIO * self.max_px
        if now == self.suspect:
            return None
        self.suspect = now
        return now

    def report(self) -> dict[str, Any]:
        """The status file's ``calibration`` object."""
        median = self.median_px
        return {"reprojection_px_median": None if median is None else round(median, 3), "pairs": len(self.values),
                "window": self.window, "max_px": self.max_px, "suspect": self.suspect}

    def status(self) -> str:
        """The STATUS= line's words while suspect (empty otherwise)."""
        if not self.suspect:
            return ""
        return f"; calibration suspect: recalibrate (ghcal), {self.median_px:.2f} px > {self.max_px:g}"
