"""Does a rig file still fit the cameras? Board views checked against it, without solving anything.

For each image pair where both cameras found the board, the corners both found are triangulated
with the rig and compared with what the board is known to be: the reprojection error (pixels: a
camera bumped since calibration shows here first), the spacing of neighbouring corners against
``square_m`` (the rig's scale: a baseline read in the wrong unit or a misprinted board), and, for
a view named ``floor``, the corners' height above the floor (the levelling).
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from calibration.board import BoardSpec
from calibration.detect import MIN_CORNERS, BoardView
from ghnerf_runtime.geometry.rig import Rig
from ghnerf_runtime.geometry.triangulation import triangulate_dlt

__all__ = ["check_rig", "FLOOR_VIEW"]

FLOOR_VIEW = "floor"


def _neighbour_pairs(board: BoardSpec, ids: np.ndarray) -> np.ndarray:
    """Index pairs (into ``ids``) of corners one square apart along a row or a column."""
    per_row = board.squares_x - 1
    where = {int(i): k for k, i in enumerate(ids)}
    pairs = []
    for k, i in enumerate(ids):
        i = int(i)
        if i % per_row != per_row - 1 and i + 1 in where:
            pairs.append((k, where[i + 1]))
        if i + per_row in where:
            pairs.append((k, where[i + per_row]))
    return np.asarray(pairs, int).reshape(-1, 2)


def check_rig(rig: Rig, board: BoardSpec, views: Mapping[str, Mapping[str, BoardView]], *,
              board_thickness_m: float = 0.0) -> dict[str, Any]:
    """The figures above over every pair both of ``rig``'s pair cameras saw (camera -> name -> view)."""
    a, b = (cam.name for cam in rig.pair)
    per_view: dict[str, dict[str, float]] = {}
    reproj_all, spacing_all = [], []
    floor = None
    for name in sorted(set(views.get(a, {})) & set(views.get(b, {}))):
        va, vb = views[a][name], views[b][name]
        ids = np.intersect1d(va.ids, vb.ids)
        if ids.size < MIN_CORNERS:
            continue
        uv = np.stack([va.corners[np.searchsorted(va.ids, ids)], vb.corners[np.searchsorted(vb.ids, ids)]])
        result = triangulate_dlt(uv, rig.pair)
        points = np.asarray(result.points, float)
        reproj = np.concatenate([np.linalg.norm(cam.project(points)[0] - uv[k], axis=1)
                                 for k, cam in enumerate(rig.pair)])
        pairs = _neighbour_pairs(board, ids)
        spacing = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1) / board.square_m \
            if pairs.size else np.zeros(0)
        reproj_all.append(reproj)
        spacing_all.append(spacing)
        entry = {"corners": int(ids.size), "reprojection_px_rms": round(float(np.sqrt(np.mean(reproj ** 2))), 4),
                 "scale": round(float(np.median(spacing)), 5) if spacing.size else None}
        if name == FLOOR_VIEW:
            # rig frame: y down, floor at 0; the board's face sits its thickness above the floor
            heights = -(points[:, 1]) - board_thickness_m
            floor = {"height_mm_median": round(1000 * float(np.median(heights)), 2),
                     "height_mm_spread": round(1000 * float(np.ptp(heights)), 2)}
            entry["floor"] = floor
        per_view[name] = entry
    if not per_view:
        return {"pairs": 0, "per_view": {}}
    reproj = np.concatenate(reproj_all)
    spacing = np.concatenate(spacing_all)
    report: dict[str, Any] = {
        "pairs": len(per_view),
        "reprojection_px_rms": round(float(np.sqrt(np.mean(reproj ** 2))), 4),
        "reprojection_px_p95": round(float(np.percentile(reproj, 95)), 4),
        "scale": round(float(np.median(spacing)), 5) if spacing.size else None,
        "per_view": per_view,
    }
    if floor is not None:
        report["floor"] = floor
    return report
