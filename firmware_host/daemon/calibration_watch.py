"""Whether the rig's calibration still fits its cameras, from the pairs the daemon estimates.

A camera knocked on its mount after calibration leaves the rig file describing a camera that is no
longer there: the 3D joints go wrong (or every joint fails the reprojection gate and the pairs show
nobody), silently. Two symptoms are watched, each over the last ``window`` pairs that measured it, each with
its own limit and the same hysteresis (suspect above the limit, fits again once back under ``CLEAR_RATIO`` of
it: no flapping near the limit):

* :class:`CalibrationWatch`: how far each pair's two views' confident peaks are from meeting in 3D
  (``PairResult.reprojection_px_median``, measured before the gate). A tilt of either camera raises it for
  every pair at once, while a moving person, a pose or a noisy peak raises it for a few: the median over the
  window, above ``max_px``.
* :class:`FloorWatch`: the height above the floor of each pair's lower triangulated foot (the median of its
  joints, ``PairResult.lowest_foot_m``; the rig frame is levelled, the floor at y = 0). A camera panned (turned about
  its vertical axis) moves the peaks along the epipolar lines of a level rig, where the views still meet and
  only the depth changes: the px check cannot see it, but the person's feet leave the floor (float above it
  or sink below it). The median over the window, further than ``max_floor_m`` from the floor either way.
* :class:`HandednessWatch`: whether the triangulated person is a mirror image (``PairResult.handedness``, +1 a
  person, -1 a mirror image: :mod:`ghnerf_runtime.handedness`). The cameras' inputs exchanged on a symmetric rig
  (the left camera's frames fed as the right's) still meet in 3D and leave the feet near the floor; the skeleton
  comes out mirrored. The median over the window, below ``-max_mirror``.

Pairs without the figure (an empty room, a frame rejected, two people in view not told apart; for the floor,
feet out of view or near a frame's edge) do not count. Two people told apart give the reported subject's own
figures (since session 55: docs/calibration.md). Measured on the
simulated rig with the shipped model: ``benchmarks/measure_calibration_drift.py``, docs/calibration.md "When the
rig no longer fits".
"""
from __future__ import annotations

from collections import deque
from typing import Any, Optional

import numpy as np

__all__ = ["CalibrationWatch", "FloorWatch", "HandednessWatch", "CLEAR_RATIO", "RECALIBRATE", "SWAP_CAMERAS",
           "fixes", "status_words", "symptoms"]

#: A suspect calibration fits again once the median (its distance from the floor) is under this share of
#: the limit.
CLEAR_RATIO = 0.75
#: What to do about a symptom: a camera moved needs a new calibration, the cameras' inputs exchanged only need the plugs
#: or the names in rig.url the right way round (a new calibration would be solved from the exchanged views and fit
#: them). The exchange comes first where both are suspect: it moves the feet off the floor too (8 of the 17 exchanged
#: 30-pair takes flagged the floor check: docs/calibration.md, "Cameras exchanged"), and those clear once it is undone.
RECALIBRATE = "recalibrate (ghcal)"
SWAP_CAMERAS = "swap the cameras' plugs or names in rig.url"
_FIX_ORDER = (SWAP_CAMERAS, RECALIBRATE)


def symptoms(checks) -> str:
    """The suspect checks' symptoms, comma-separated (``1.46 px > 0.8, feet 0.18 m below the floor > 0.1 m``;
    empty when none is), those of the first fix first: the daemon's STATUS= line and ``ghnerf-demo``'s verdict say
    them alike."""
    suspect = [c for c in checks if c.suspect]
    suspect.sort(key=lambda c: _FIX_ORDER.index(c.fix))  # stable: the checks' own order within a fix
    return ", ".join(c.symptom() for c in suspect)


def fixes(checks) -> str:
    """What to do first about the suspect checks (``recalibrate (ghcal)``, or with the cameras exchanged
    ``swap the cameras' plugs or names in rig.url``); empty when none is suspect."""
    wanted = {c.fix for c in checks if c.suspect}
    return next((fix for fix in _FIX_ORDER if fix in wanted), "")


def status_words(checks) -> str:
    """The STATUS= line's words for the checks that are suspect: what to do first, then each symptom
    (``; calibration suspect: recalibrate (ghcal), 1.46 px > 0.8``; empty when none is)."""
    named = symptoms(checks)
    return f"; calibration suspect: {fixes(checks)}, {named}" if named else ""


class _RollingCheck:
    """The median of the last ``window`` figures of one symptom, and whether it is past ``limit`` (``None``: never).

    Subclasses say how far a median is from fitting (:meth:`_distance`) and name things for their reports, and
    ``fix`` what the user should do while it is suspect.
    """

    fix = RECALIBRATE

    def __init__(self, window: int, limit: Optional[float]) -> None:
        self.window = int(window)
        self.limit = limit
        self.values: deque[float] = deque(maxlen=self.window)
        self.suspect = False

    def configure(self, window: int, limit: Optional[float]) -> Optional[bool]:
        """New settings (a reload), keeping the newest values that fit; returns :meth:`add`'s answer for them."""
        self.window, self.limit = int(window), limit
        self.values = deque(self.values, maxlen=self.window)
        return self._judge()

    def reset(self) -> None:
        """Forget every value (another calibration or model: the old pairs say nothing of it)."""
        self.values.clear()
        self.suspect = False

    @property
    def median(self) -> Optional[float]:
        return float(np.median(self.values)) if self.values else None

    def add(self, value: Optional[float]) -> Optional[bool]:
        """One pair's figure (``None``: not measured, not counted). Returns the new state when it changes (True: now
        suspect, False: fits again), else ``None``: the caller logs transitions."""
        if value is None or not np.isfinite(value):
            return None
        self.values.append(float(value))
        return self._judge()

    def _distance(self, median: float) -> float:
        return median

    def symptom(self) -> str:
        raise NotImplementedError

    def status(self) -> str:
        """The STATUS= line's words while suspect (empty otherwise)."""
        return status_words([self]) if self.suspect else ""

    def _judge(self) -> Optional[bool]:
        median = self.median
        if self.limit is None or median is None:
            now = False
        elif len(self.values) < self.window:
            now = self.suspect  # too few pairs to change the verdict
        else:
            far = self._distance(median)
            now = far > self.limit if not self.suspect else far >= CLEAR_RATIO * self.limit
        if now == self.suspect:
            return None
        self.suspect = now
        return now


class CalibrationWatch(_RollingCheck):
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
        super().__init__(window, max_px)

    def configure(self, window: int, max_px: Optional[float]) -> Optional[bool]:
        return super().configure(window, max_px)

    @property
    def max_px(self) -> Optional[float]:
        return self.limit

    @property
    def median_px(self) -> Optional[float]:
        return self.median

    def report(self) -> dict[str, Any]:
        """The status file's ``calibration`` object (its view agreement's keys)."""
        median = self.median_px
        return {"reprojection_px_median": None if median is None else round(median, 3), "pairs": len(self.values),
                "window": self.window, "max_px": self.max_px, "suspect": self.suspect}

    def symptom(self) -> str:
        """What is wrong while suspect, for the STATUS= line: ``1.46 px > 0.8`` (empty otherwise)."""
        return f"{self.median_px:.2f} px > {self.max_px:g}" if self.suspect else ""


class FloorWatch(_RollingCheck):
    """The rolling median of the pairs' lower triangulated foot's height, and whether the feet have left
    the floor (a camera turned since calibration, a pan above all).

    Args:
        window: pairs with a triangulated foot joint the median is taken over; none is judged before it is full.
        max_floor_m: how far from the floor (metres, above or below) the median may be before the calibration is
            suspect; ``None``: never (people standing on a stage or lying on a bed are not on the rig's floor).

    Example:
        >>> watch = FloorWatch(window=3, max_floor_m=0.1)
        >>> [watch.add(h) for h in (0.02, -0.2, None, -0.19, -0.22, 0.01, 0.03, 0.0)]
        [None, None, None, True, None, None, False, None]
        >>> watch.report()
        {'lowest_foot_m_median': 0.01, 'floor_pairs': 3, 'max_floor_m': 0.1, 'floor_suspect': False}
    """

    def __init__(self, window: int, max_floor_m: Optional[float]) -> None:
        super().__init__(window, max_floor_m)

    def configure(self, window: int, max_floor_m: Optional[float]) -> Optional[bool]:
        return super().configure(window, max_floor_m)

    @property
    def max_floor_m(self) -> Optional[float]:
        return self.limit

    def _distance(self, median: float) -> float:
        return abs(median)  # floating above the floor or sunk below it: the depth is wrong either way

    def words(self) -> str:
        """Where the feet are, for the log and the STATUS line: ``feet 0.18 m below the floor``."""
        median = self.median
        if median is None:
            return "no feet seen"
        return f"feet {abs(median):.2f} m {'above' if median >= 0 else 'below'} the floor"

    def report(self) -> dict[str, Any]:
        """The status file's ``calibration`` object's floor keys."""
        median = self.median
        return {"lowest_foot_m_median": None if median is None else round(median, 3), "floor_pairs": len(self.values),
                "max_floor_m": self.max_floor_m, "floor_suspect": self.suspect}

    def symptom(self) -> str:
        """What is wrong while suspect, for the STATUS= line: ``feet 0.18 m below the floor > 0.1 m`` (empty
        otherwise)."""
        return f"{self.words()} > {self.max_floor_m:g} m" if self.suspect else ""


class HandednessWatch(_RollingCheck):
    """The rolling median of the pairs' handedness, and whether the rig triangulates a mirror image of the person: the
    two cameras' inputs exchanged (a symmetric rig's left camera fed as its right).

    Args:
        window: pairs with a handedness figure the median is taken over; none is judged before it is full.
        max_mirror: how far below 0 the median may go before the cameras look exchanged (``None``: never); the
            true rig's windows stay near +0.8, an exchanged rig's near -0.7 (docs/calibration.md, "Cameras
            exchanged").

    Example:
        >>> watch = HandednessWatch(window=3, max_mirror=0.2)
        >>> [watch.add(h) for h in (0.8, -0.7, None, -0.6, -0.8, 0.9, 0.7, 0.8)]
        [None, None, None, True, None, None, False, None]
        >>> watch.report()
        {'handedness_median': 0.8, 'handedness_pairs': 3, 'max_mirror': 0.2, 'exchanged_suspect': False}
    """

    fix = SWAP_CAMERAS  # the rig file is right; the frames come in under each other's names

    def __init__(self, window: int, max_mirror: Optional[float]) -> None:
        super().__init__(window, max_mirror)

    @property
    def max_mirror(self) -> Optional[float]:
        return self.limit

    def _distance(self, median: float) -> float:
        return -median  # a person reads +1, a mirror image -1

    def report(self) -> dict[str, Any]:
        """The status file's ``calibration`` object's handedness keys."""
        median = self.median
        return {"handedness_median": None if median is None else round(median, 3),
                "handedness_pairs": len(self.values), "max_mirror": self.max_mirror, "exchanged_suspect": self.suspect}

    def symptom(self) -> str:
        """What is wrong while suspect, for the STATUS= line (empty otherwise)."""
        return (f"cameras look exchanged (mirror image: handedness {self.median:.2f} < -{self.max_mirror:g})"
                if self.suspect else "")
