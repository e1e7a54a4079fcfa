"""The whole-volume recheck of a crop on the rays, cached (session 71).

A person seen by one camera only: the other camera's crop is on the rays of the seen joints
(``SubjectTracker.rays_camera``). Where the frame check rejects that crop (a plain wall, a panel hiding the person),
the estimator asks the same camera's whole-volume crop of the frame: passing, the camera works and the rays crop is
kept (session 70). That costs one more preprocess a pair for as long as it lasts (2.0-2.4 ms at 1280 x 800,
``benchmarks/time_rays_recheck.py``), so a verdict that passed is reused for the following pairs while the rays crop
keeps being rejected for the same reason, at much the same brightness (``frame_check.volume_recheck_levels``), through
the same camera state and tracker, at most ``frame_check.volume_recheck_every - 1`` times in a row: a covered lens is
reported within ``volume_recheck_every`` pairs (the last of them checks the camera again), at once where covering it
darkened the crop. A pair's own passes off the rays (a turn search's) leave the verdict; a pair with none on them voids
it (session 72).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

def mean_level(plane: np.ndarray, inside: np.ndarray | None, levels_per_unit: float) -> float:
    """The mean of a model-input plane in 8-bit levels (up to the normalisation's offset, the same for every crop of
    an estimator) over the pixels that show the frame; NaN where none does (no verdict holds then)."""
    values = plane if inside is None else plane[inside]
    return float(values.mean()) * levels_per_unit if values.size else float("nan")


@dataclass(frozen=True)
class VolumeVerdict:
    """A camera's whole-volume crop passed the frame check while its crop on the rays was rejected.

    ``camera_state`` and ``tracker`` are the estimator's objects the verdict was taken through (a crop turn, a
    kept turn's tracker: others void it), ``resets`` the tracker's ``SubjectTracker.resets`` then (any reset voids
    it), ``reason`` and ``level`` the rays crop's rejection and :func:`mean_level` then, ``reuses_left`` the pairs it
    may still answer before the camera is checked again, ``recheck_levels`` how far the level may move meanwhile
    (``frame_check.volume_recheck_levels``)."""

    camera_state: object
    tracker: object
    resets: int
    reason: str
    level: float
    reuses_left: int
    recheck_levels: float

    def holds(self, camera_state: object, tracker: object, reason: str, level: float) -> bool:
        """Whether this verdict answers for a rays crop rejected for ``reason`` at ``level`` through ``camera_state``
        and ``tracker`` now, without a recheck."""
        return (self.reuses_left > 0 and camera_state is self.camera_state and tracker is self.tracker
                and getattr(tracker, "resets", None) == self.resets and reason == self.reason
                and abs(level - self.level) <= self.recheck_levels)

    def reused(self) -> "VolumeVerdict":
        """The verdict after answering one more pair."""
        return replace(self, reuses_left=self.reuses_left - 1)
