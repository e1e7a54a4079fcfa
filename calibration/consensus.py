"""Which image pairs agree on the second camera's pose, judged pair by pair before any joint solve.

Each pair alone gives the second camera's pose relative to the first: the board's pose in each camera
(``cv2.solvePnP``, the intrinsics known), composed. Pairs whose two images were taken together agree to
millimetres: on ``tests/calibration/test_pair_and_check.py``'s projected corners (0.2 px noise, boards
1-2.2 m away) a median 7 mm and 0.2 degree off the truth, the worst of 140 86 mm and 2.3 degrees. A pair
whose images are of two instants, or whose board was found wrongly in one, is off by the board's
movement between them: 0.2-2.1 m and 11-100 degrees there. The largest group of pairs that agree with
one pair of them is the consensus. Dropping one pair at a time from a joint fit cannot find two bad
pairs among few (together they drag every pair's error up, and without either one the fit is still
poor); a bad pair cannot drag this, and any number of them is found at once.

The tolerances are tight on purpose: a good pair they leave out (a board far away and square-on,
whose single-camera pose is loose) is tested again against the consensus's joint fit by the caller
(:func:`calibration.solve.calibrate_pair`), which takes it back when it fits.
"""
from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from calibration.board import BoardSpec
from calibration.detect import BoardView, fixes_a_pose

__all__ = ["CONSENSUS_MM", "CONSENSUS_DEG", "pair_relative_pose", "agreeing_pairs"]

#: Two pairs agree when their poses of the second camera are within both (a few times the good pairs' spread).
CONSENSUS_MM = 50.0
CONSENSUS_DEG = 3.0

Pose = tuple[np.ndarray, np.ndarray]  # R (3, 3), t (3,): X_second = R @ X_first + t


def _board_pose(board: BoardSpec, view: BoardView, ids: np.ndarray, K: np.ndarray, dist: np.ndarray) -> Pose | None:
    # a row and one corner off it leaves the pose free (no four corners without three on a line): IPPE still
    # answered, 0.6 m off on exact corners, and under four it raised a cv2.error where None is promised
    if not fixes_a_pose(board, np.asarray(ids)):
        return None
    obj = board.corners_m()[ids].astype(np.float64)
    img = view.corners[np.searchsorted(view.ids, ids)].astype(np.float64)
    # IPPE: made for a planar target, and it picks the better of a flat board's two mirror poses
    try:
        ok, rvec, tvec = cv2.solvePnP(obj, img, K, np.asarray(dist, float), flags=cv2.SOLVEPNP_IPPE)
    except cv2.error:  # corners OpenCV refuses outright (non-finite ones): no pose, as promised
        return None
    if not ok or not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))):
        return None
    return cv2.Rodrigues(rvec)[0], tvec.reshape(3)


def pair_relative_pose(board: BoardSpec, first: BoardView, second: BoardView, ids: np.ndarray,
                       K_first: np.ndarray, dist_first: np.ndarray, K_second: np.ndarray,
                       dist_second: np.ndarray) -> Pose | None:
    """The second camera's pose relative to the first from one image pair, on the corners ``ids`` both found;
    None where either board pose cannot be solved."""
    a = _board_pose(board, first, ids, K_first, dist_first)
    b = _board_pose(board, second, ids, K_second, dist_second)
    if a is None or b is None:
        return None
    R = b[0] @ a[0].T
    return R, b[1] - R @ a[1]


def _disagreement(p: Pose, q: Pose) -> tuple[float, float]:
    """(mm, degrees) between two poses of the second camera."""
    angle = float(np.linalg.norm(cv2.Rodrigues(p[0] @ q[0].T)[0]))
    return 1e3 * float(np.linalg.norm(p[1] - q[1])), float(np.degrees(angle))


def agreeing_pairs(poses: Sequence[Pose | None], *, tol_mm: float = CONSENSUS_MM,
                   tol_deg: float = CONSENSUS_DEG) -> list[int]:
    """Indices of the largest group of ``poses`` that agree with one of them (within ``tol_mm`` and
    ``tol_deg``); of groups as large, the one closest together. A pose of None agrees with none."""
    best: tuple[int, float] | None = None
    group: list[int] = []
    for k, centre in enumerate(poses):
        if centre is None:
            continue
        members, spread = [], 0.0
        for j, pose in enumerate(poses):
            if pose is None:
                continue
            mm, deg = _disagreement(centre, pose)
            if mm <= tol_mm and deg <= tol_deg:
                members.append(j)
                spread += mm / tol_mm + deg / tol_deg
        key = (len(members), -spread)
        if best is None or key > best:
            best, group = key, members
    return group
