"""Does a rig file still fit the cameras? Board views checked against it, without solving anything.

For each image pair where both cameras found the board, the corners both found are triangulated
with the rig and compared with what the board is known to be: the reprojection error (pixels: a
camera bumped since calibration shows here first), the spacing of neighbouring corners against
``square_m`` (the rig's scale: a baseline read in the wrong unit or a misprinted board), and, for
the floor view (``floor_view``, by default ``floor``), the corners' height above the floor (the
levelling). A corner whose two rays
do not meet in front of both cameras cannot be measured at all: it is counted (``untriangulated``), left
out of the figures, and fails the check, since a rig that fits triangulates every corner both cameras
found. :func:`check_failures` turns the report into the reasons a rig does not fit.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from calibration.board import BoardSpec
from calibration.capture import list_images
from calibration.detect import MIN_CORNERS, BoardView
from ghnerf_runtime.geometry.rig import Rig
from ghnerf_runtime.geometry.triangulation import triangulate_dlt

__all__ = ["check_rig", "check_failures", "floor_unmeasured", "exchanged_fit", "exchanged_report", "sized_as_exchanged",
           "CheckLimits", "FLOOR_VIEW"]

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
              board_thickness_m: float = 0.0, floor_view: str = FLOOR_VIEW) -> dict[str, Any]:
    """The figures above over every pair both of ``rig``'s pair cameras saw (camera -> name -> view);
    the view named ``floor_view`` is the board lying on the floor."""
    a, b = (cam.name for cam in rig.pair)
    per_view: dict[str, dict[str, Any]] = {}
    reproj_all, spacing_all = [], []
    floor = None
    corners_total = untriangulated_total = 0
    for name in sorted(set(views.get(a, {})) & set(views.get(b, {}))):
        va, vb = views[a][name], views[b][name]
        ids = np.intersect1d(va.ids, vb.ids)
        if ids.size < MIN_CORNERS:
            continue
        uv = np.stack([va.corners[np.searchsorted(va.ids, ids)], vb.corners[np.searchsorted(vb.ids, ids)]])
        result = triangulate_dlt(uv, rig.pair)
        # an invalid corner's point is a fill value (the origin), not a measurement: measuring from it
        # gave NaN pixels and a zero scale, which no limit caught
        ok = np.asarray(result.valid, bool)
        points = np.asarray(result.points, float)
        reproj = np.full((2, ids.size), np.nan)
        if ok.any():
            reproj[:, ok] = [np.linalg.norm(cam.project(points[ok])[0] - uv[k][ok], axis=1)
                             for k, cam in enumerate(rig.pair)]
        ok &= np.all(np.isfinite(reproj), axis=0)
        reproj = reproj[:, ok].reshape(-1)
        pairs = _neighbour_pairs(board, ids)
        pairs = pairs[ok[pairs].all(axis=1)] if pairs.size else pairs
        spacing = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1) / board.square_m \
            if pairs.size else np.zeros(0)
        reproj_all.append(reproj)
        spacing_all.append(spacing)
        corners_total += int(ids.size)
        untriangulated_total += int(ids.size - ok.sum())
        entry: dict[str, Any] = {
            "corners": int(ids.size), "untriangulated": int(ids.size - ok.sum()),
            "reprojection_px_rms": round(float(np.sqrt(np.mean(reproj ** 2))), 4) if reproj.size else None,
            "scale": round(float(np.median(spacing)), 5) if spacing.size else None}
        if name == floor_view and ok.any():
            # rig frame: y down, floor at 0; the board's face sits its thickness above the floor
            heights = -(points[ok, 1]) - board_thickness_m
            floor = {"view": name, "height_mm_median": round(1000 * float(np.median(heights)), 2),
                     "height_mm_spread": round(1000 * float(np.ptp(heights)), 2)}
            entry["floor"] = floor
        per_view[name] = entry
    if not per_view:
        return {"pairs": 0, "per_view": {}}
    reproj = np.concatenate(reproj_all)
    spacing = np.concatenate(spacing_all)
    report: dict[str, Any] = {
        "pairs": len(per_view),
        "corners": corners_total,
        "untriangulated": untriangulated_total,
        "reprojection_px_rms": round(float(np.sqrt(np.mean(reproj ** 2))), 4) if reproj.size else None,
        "reprojection_px_p95": round(float(np.percentile(reproj, 95)), 4) if reproj.size else None,
        "scale": round(float(np.median(spacing)), 5) if spacing.size else None,
        "per_view": per_view,
    }
    if floor is not None:
        report["floor"] = floor
    return report


@dataclass(frozen=True)
class CheckLimits:
    """How far a rig may be off and still fit (``ghcal check``'s ``--max-*`` options)."""

    max_px: float = 1.0
    """reprojection error, pixels rms over every corner"""
    max_scale_error: float = 0.01
    """the board's squares measured against ``square_m``: 0.01 is 1 %"""
    max_floor_mm: float = 25.0
    """the floor view's median height off the floor: a rig tilted on its mount keeps its pair's pose,
    so only the floor shows it (1 degree is about 35 mm at 2 m)"""


def check_failures(report: Mapping[str, Any], limits: CheckLimits = CheckLimits()) -> list[str]:
    """Why ``report`` (from :func:`check_rig`, with at least one pair) says the rig does not fit; empty if it fits."""
    reasons = []
    if report.get("untriangulated"):
        views = [n for n, e in report["per_view"].items() if e.get("untriangulated")]
        reasons.append(f"{report['untriangulated']} of {report['corners']} corners do not triangulate in front of "
                       f"both cameras (view(s) {', '.join(views)})")
    rms = report.get("reprojection_px_rms")
    if rms is None or not rms <= limits.max_px:
        reasons.append(f"reprojection {rms} px rms, over {limits.max_px} px" if rms is not None
                       else "no corner could be reprojected")
    scale = report.get("scale")
    if scale is not None and not abs(scale - 1.0) <= limits.max_scale_error:
        reasons.append(f"the board measures {scale:.4f} of its size, off by more than {limits.max_scale_error:.1%}")
    floor = report.get("floor")
    if floor is not None and not abs(floor["height_mm_median"]) <= limits.max_floor_mm:
        reasons.append(f"the floor view lies {floor['height_mm_median']:+.1f} mm off the floor, over "
                       f"{limits.max_floor_mm:g} mm (the rig tilted or moved on its mount)")
    return reasons


def exchanged_fit(rig: Rig, board: BoardSpec, views: Mapping[str, Mapping[str, BoardView]],
                  limits: CheckLimits = CheckLimits(), *, board_thickness_m: float = 0.0,
                  floor_view: str = FLOOR_VIEW) -> dict[str, Any] | None:
    """:func:`check_rig`'s report with the pair's two cameras' views exchanged, where the rig fits them so; None
    where it does not (or the views cannot be exchanged: images of another size than the other camera's).

    Meant for views the rig does not fit as named: each camera's images in the other's folder (another tool's
    capture that named the cameras the other way round, two folders renamed) fail every figure, and the check
    said "a camera moved: calibrate again", from which the solve gave a rig whose cameras are each other's.
    """
    a, b = rig.pair
    if any(v.image_size != b.size for v in views.get(a.name, {}).values()) or \
            any(v.image_size != a.size for v in views.get(b.name, {}).values()):
        return None
    report = exchanged_report(rig, board, views, board_thickness_m=board_thickness_m, floor_view=floor_view)
    return report if report["pairs"] and not check_failures(report, limits) else None


def exchanged_report(rig: Rig, board: BoardSpec, views: Mapping[str, Mapping[str, BoardView]], *,
                     board_thickness_m: float = 0.0, floor_view: str = FLOOR_VIEW) -> dict[str, Any]:
    """:func:`check_rig`'s report with the pair's two cameras' views exchanged, whether the rig fits them or not
    (:func:`exchanged_fit` keeps it only where it does); the views must be each the other camera's size."""
    a, b = rig.pair
    exchanged = {a.name: views.get(b.name, {}), b.name: views.get(a.name, {})}
    return check_rig(rig, board, exchanged, board_thickness_m=board_thickness_m, floor_view=floor_view)


def sized_as_exchanged(rig: Rig, views: Mapping[str, Mapping[str, BoardView]]) -> bool:
    """Whether each of the pair's cameras' images are all the other camera's size, the two sizes differing: the
    folders exchanged, said so from the sizes alone. Every image was "the image is 1280x720, camera 'left' ...
    640x480", and :func:`exchanged_fit` was never reached."""
    a, b = rig.pair
    if a.size == b.size:
        return False
    sizes = {cam.name: {v.image_size for v in views.get(cam.name, {}).values()} for cam in rig.pair}
    return sizes[a.name] == {b.size} and sizes[b.name] == {a.size}


def _expected_image(root: str | os.PathLike | None, camera: str, other: str, name: str) -> str:
    """Where ``camera``'s image ``name`` would be: beside ``other``'s, with the suffix ``other``'s has."""
    folder = None if root is None else Path(root) / other
    # a .jpg capture expects a .jpg
    suffix = list_images(folder).get(name, Path(".png")).suffix if folder is not None and folder.is_dir() else ".png"
    return f"{camera}/{name}{suffix}" if root is None else str(Path(root) / camera / f"{name}{suffix}")


def floor_unmeasured(report: Mapping[str, Any], views: Mapping[str, Mapping[str, BoardView]],
                     floor_view: str = FLOOR_VIEW, *, missed: Mapping[str, Sequence[str]] | None = None,
                     root: str | os.PathLike | None = None,
                     unread: Mapping[str, Mapping[str, str]] | None = None) -> str | None:
    """Why the floor view in ``views`` gave ``report`` (from :func:`check_rig`) no height; None where it gave one
    or where no camera found the board in it (the caller knows whether it was taken at all).

    ``missed`` (camera -> names of images without the board, from
    :func:`~calibration.capture.read_folder`) tells a camera whose floor image is missing from one that did
    not find the board in it; ``root``, the images' folder, names the missing file. ``unread`` (camera -> view
    name -> why its image does not read, :attr:`~calibration.capture.FolderViews.unread`) tells a floor image that
    is there but does not read (before session 75 ``check`` stopped at it, or called it missing).

    ``ghcal check`` said "the board was not found in both cameras' floor view" whatever the reason, also
    where both found it and its corners did not triangulate (a camera turned far: the fix is to calibrate
    again, not to retake the floor view); and "only camera 'left' found the board" where the right camera had
    no floor image at all (copied without it: the fix is the file, not the board's place).
    """
    if "floor" in report:
        return None
    unreadable = [reasons[floor_view] for reasons in (unread or {}).values() if floor_view in reasons]
    if unreadable:
        return (f"the floor view's image does not read ({'; '.join(unreadable)}): take the floor view again "
                "(ghcal capture --floor --force)")
    seen = [camera for camera, named in views.items() if floor_view in named]
    if missed is not None:
        imaged = [c for c in views if floor_view in views[c] or floor_view in missed.get(c, ())]
        absent = [c for c in views if c not in imaged]
        if imaged and absent:
            return (f"camera {absent[0]!r} has no floor image "
                    f"({_expected_image(root, absent[0], imaged[0], floor_view)} is missing; camera {imaged[0]!r} "
                    + ("found the board in its own" if imaged[0] in seen else "has one, without the board found")
                    + "): take the floor view again (ghcal capture --floor --force)")
    if floor_view in report.get("per_view", {}):
        entry = report["per_view"][floor_view]
        return (f"none of the {entry['corners']} corners both cameras found in floor view {floor_view!r} "
                "triangulates in front of both cameras")
    if len(seen) >= 2:
        shared = np.intersect1d(*(views[camera][floor_view].ids for camera in seen[:2])).size
        return (f"the cameras found {shared} of the same corners in floor view {floor_view!r}, fewer than the "
                f"{MIN_CORNERS} a measurement needs")
    if seen:
        return f"only camera {seen[0]!r} found the board in floor view {floor_view!r}"
    return None
