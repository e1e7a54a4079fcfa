"""Is anyone besides the tracked subject in the working volume? (``presence.scan_every_s``, session 64)

A tracked pair's crop is the subject's square: a second person beside them is mostly outside it, and the
``several_people`` flag (docs/two-people.md) says only that the reported joints' maps showed two people. Every
``scan_every_s`` seconds while tracking, the estimator runs the cold pass's keypoint graph once on the whole
working volume's crops and asks the presence rule (``presence.min_joints`` joints at the encoder threshold) of each
view's heatmaps with the tracked subject's projected box blanked out: someone else is there when both views
answer yes. A person hidden behind the subject in a view, or standing inside the subject's box, is not seen
(docs/two-people.md, "Anyone else near?").
"""
from __future__ import annotations

import numpy as np

from .tracking import box_corners

#: The subject's box is their reported joints grown by this much every way (m) before it is blanked out: a limb
#: swinging past the joints of the pair, and the heatmaps' spread around a peak, stay inside it. 0.2 since session 64's
#: review U (0.3 before): at 0.3 the box projected into view 0 covered a person a metre beside on 18 of 80 joining
#: pairs, at 0.2 on 1; 0.1 told a lone person once in 300 pairs, 0.15 and 0.2 never (docs/two-people.md).
SUBJECT_MARGIN_M = 0.2


def subject_box(points: np.ndarray, valid: np.ndarray, margin_m: float = SUBJECT_MARGIN_M) -> np.ndarray | None:
    """``(2, 3)`` the box of the ``valid`` joints of ``points`` ``(J, 3)`` grown by ``margin_m``; None without any."""
    found = np.asarray(points, np.float64)[np.asarray(valid, bool)]
    if len(found) == 0:
        return None
    return np.stack([found.min(axis=0) - margin_m, found.max(axis=0) + margin_m])


def box_cells(P: np.ndarray, box: np.ndarray, stride: int) -> tuple[int, int, int, int]:
    """``(u0, v0, u1, v1)``: the heatmap cells (of ``stride`` pixels) that the projection of ``box`` through the
    crop camera ``P`` ``(3, 4)`` covers, both ends included (unclipped: may lie past the map)."""
    corners = np.concatenate([box_corners(box), np.ones((8, 1))], axis=1) @ np.asarray(P, np.float64).T
    uv = corners[:, :2] / corners[:, 2:] / stride
    (u0, v0), (u1, v1) = np.floor(uv.min(axis=0)), np.ceil(uv.max(axis=0))
    return int(u0), int(v0), int(u1), int(v1)


def strong_joints_outside(heat: np.ndarray, cells: tuple[int, int, int, int], threshold: float) -> int:
    """The joints of one view's heatmaps ``(J, H, W)`` whose peak outside ``cells`` (:func:`box_cells`) is at
    least ``threshold``."""
    u0, v0, u1, v1 = cells
    _, H, W = heat.shape
    outside = np.array(heat, np.float32)
    outside[:, max(v0, 0):min(max(v1 + 1, 0), H), max(u0, 0):min(max(u1 + 1, 0), W)] = 0.0
    return int(np.count_nonzero(outside.reshape(len(outside), -1).max(axis=1) >= threshold))


def someone_else(heat: np.ndarray, cells: list[tuple[int, int, int, int]], threshold: float, min_joints: int) -> bool:
    """Whether both views' heatmaps ``(2, J, H, W)`` show at least ``min_joints`` strong joints outside the subject's
    cells (one per view): one view alone may see a person the other's frame leaves out, or a phantom."""
    return all(strong_joints_outside(h, c, threshold) >= min_joints for h, c in zip(heat, cells))


class ScanClock:
    """When the next scan is due: every ``every_s`` seconds of capture time while tracking (0: never), counted from
    the track's cold start."""

    def __init__(self, every_s: float) -> None:
        self.every_s = float(every_s)
        self._last: float | None = None

    def due(self, now_s: float) -> bool:
        """Whether a scan is due at ``now_s``; a clock that went back (a replay restarted) counts as due."""
        if self.every_s <= 0:
            return False
        return self._last is None or not (self._last <= now_s < self._last + self.every_s)

    def ran(self, now_s: float) -> None:
        self._last = float(now_s)

    def reset(self) -> None:
        """The track was lost, the time unknown: the next tracked pair scans at once."""
        self._last = None

    def cold_start(self, now_s: float) -> None:
        """A cold pass read the whole working volume at ``now_s``: the first scan of the track it starts is due
        ``every_s`` later, not on its first pair, which already ran the cold pass and its refined one (p99)."""
        self._last = float(now_s)
