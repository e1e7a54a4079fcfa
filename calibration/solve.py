"""From board views to a rig: each camera's intrinsics, the pair's relative pose, the floor.

Pure computation on detected views (:class:`~calibration.detect.BoardView`); no file or camera I/O.

1. **Intrinsics** per camera (``cv2.calibrateCameraExtended``) from every view where that camera
   saw the board; a view whose reprojection error is far above the others' (a blurred or moving
   frame) is dropped once and the solve repeated.
2. **Relative pose** of the second camera (``cv2.stereoCalibrateExtended`` with the intrinsics
   fixed) from the views both cameras saw at the same instant, on the corners both found.
3. **Levelling** into the rig frame (docs/rig-file.md: y down along gravity, floor at y = 0):
   either from one view of the board lying flat on the floor (its plane is the floor, its normal
   gravity; the most accurate, and nothing to measure), or from the reference camera's height and
   tilt measured by hand (:func:`calibration.level.level_rig`).

The report (:attr:`RigSolution.report`) carries every figure a user needs to judge the result and
``warnings`` in words where one is out of the usual range.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import cv2
import numpy as np

from calibration.board import BoardSpec
from calibration.consensus import agreeing_pairs, pair_relative_pose
from calibration.detect import MIN_CORNERS, BoardView, fixes_a_pose
from calibration.errors import SolveError
from calibration.image_sizes import mixed_views_problem
from calibration.level import LEVEL_VOLUME, level_rig
from ghnerf_runtime.geometry.camera import Camera, fold_terms_text, folded_by_tangential
from ghnerf_runtime.geometry.rig import MAX_BASELINE_M, MIN_BASELINE_M, Rig, WorkingVolume
from ghnerf_runtime.rig_file import (CAMERA_HEIGHT_RANGE_M, distortion_problem, focal_length_problem,
                                     principal_point_problem)

__all__ = ["LENS_MODELS", "Intrinsics", "PairPose", "Floor", "RigSolution", "calibrate_intrinsics",
           "calibrate_pair", "floor_from_view", "floor_from_pair", "solve_rig", "fold_warning", "MIN_VIEWS", "MAX_PAIR_PX",
           "USUAL_PITCH_DEG", "typed_pitch_warning", "BOARD_DISTANCE_SLACK", "median_board_distance_m",
           "board_distance_warning", "SIDE_NAMES", "expected_sides", "sides_warning", "REPEAT_PX", "corner_gaps",
           "same_pose", "repeated_views", "MIN_ORIENTATION_SPREAD_DEG", "orientation_spread_deg"]

#: Lens models: OpenCV flags and what they suit.
LENS_MODELS = {
    "standard": 0,  # k1, k2, p1, p2, k3: most lenses up to ~100 degrees
    "narrow": cv2.CALIB_FIX_K3,  # k1, k2, p1, p2: long lenses, where k3 only fits noise
    "rational": cv2.CALIB_RATIONAL_MODEL,  # 8 terms: wide lenses; needs views reaching the image corners
}
#: Fewest views a camera's intrinsics are solved from (OpenCV needs 3; fewer than ~10 is weak).
MIN_VIEWS = 4
#: A view whose error exceeds this multiple of the median (and 1 px) is dropped once as an outlier.
OUTLIER_FACTOR = 3.0
#: No image pair kept for the pair's pose may fit worse than this (px, the mean of its two images' rms error). A
#: still board seen by both cameras at the same instant fits at 0.3 px with 0.2 px noise
#: (benchmarks/measure_pair_outliers.py), 0.08-0.12 px rendered (benchmarks/measure_calibration.py), real
#: captures usually under 1 px; two unsynchronised pairs of five left in the fit put it at 17-42 px (the first).
MAX_PAIR_PX = 3.0
#: The image is divided into this grid to measure how much of it the board's corners covered.
COVERAGE_GRID = (8, 6)
#: OpenCV's standard deviation of the focal length, as a share of it: above the first a camera is refused (views
#: that all show the board at one angle fit any focal length: 175 % for eight fronto-parallel views, where twelve
#: tilted ones give 0.7 %); above the second the report warns.
MAX_FOCAL_STD_SHARE = 0.10
WARN_FOCAL_STD_SHARE = 0.02
#: Fewest degrees between the board's orientations in two of a camera's views (the largest angle between two views'
#: board normals, as the solve poses them): below it the camera is refused, whatever OpenCV's standard deviation says.
#: Ten views held square-on, within 3 degrees, of a 500 px lens (tests/calibration/test_degenerate_solves.py) solved
#: to f 44 px "give or take 0.03 px": the branch where a short focal length and a board held close fit as well as the
#: truth, where OpenCV's figure says nothing. Such solves spread the orientations over less than this (from 0.8
#: degrees: the short focal length flattens them); every solve within 10 % of the truth, of views tilted up to 3-30
#: degrees, over 10.5 or more (benchmarks/measure_orientation_spread.py, 40 seeds of 8 and 15 views per tilt bound;
#: tilted about one axis only, --one-axis, over 15.2). The other wrong branch, a focal length 2.5-45 times too long,
#: spreads them widely; its distortion terms (4.9e3 and more) are refused instead, at the rig file's bound
#: (:func:`_lens_problem`).
MIN_ORIENTATION_SPREAD_DEG = 5.0
#: The first camera's pitch (degrees below the horizon) usual for a rig filming people; outside it the report
#: warns (a floor view of a board not lying flat, or a --pitch read from the vertical).
USUAL_PITCH_DEG = (-15.0, 60.0)
#: The board's median distance from the first camera over the pair's views is expected within the working
#: volume's depth range widened by this factor either way (default volume 0.5-5 m: 0.25-10 m). Every length the
#: solve gives scales with the board's square_m, and a square_m off by 10x (8 mm typed for 80, 0.8 m for 0.08)
#: gives a rig as consistent as the true one: the distance the board was held at is the figure that shows it (a
#: body-capture rig is calibrated with the board where people will stand, not 10 cm or 20 m away).
BOARD_DISTANCE_SLACK = 2.0
#: Camera names that say a side (``depthai://``'s sensors, docs/calibration.md): a pair so named is expected with its
#: "left" camera on the left, whatever the rig's order. A pair named otherwise (``cam_a``/``cam_b``, ``0``/``1``) is
#: expected with its first camera on the left, where every rig source puts it (``opencv://``'s nominal rig names
#: its ``first=`` camera ``left``, ``drivers.sim.placement.RigPlacement`` its ``names[0]``). A pair solved the other
#: way round, by more than this share of the baseline along the first camera's x (its image's rightward axis), is
#: warned about (each folder holding the other camera's images); a pair stacked one above the other has no side.
SIDE_NAMES = ("left", "right")
SIDES_SHARE = 0.5
#: Two images of one camera show the same board pose (counted once) where every corner both found lies within this many
#: pixels of the other's, and they share at least half of each one's corners. On ghcal synth's rendered views (its rig
#: until session 68, calibration.render.example_rig; benchmarks/measure_repeated_views.py, 3 seeds) one pose's two
#: images lay at most 1.84 px apart (re-saved as JPEG of quality 75; 1.11 px at quality 95, 0.75 px rendered twice with
#: other sensor noise: a still board exposed twice), a board moved 5 mm at most 2.99 px (median 2.3), and each view at
#: least 33 px from the capture's nearest other view (median 91 px): a re-saved image and a frame grabbed twice are
#: caught, and so is a board nudged by a few millimetres (no pose the fit lacks: a 1 mm nudge is within a re-saved
#: copy's spread, so no threshold could tell them apart); the poses a capture's views take are not.
#: 0.5 px would have missed over a tenth of the still board's second exposures (90th percentile 0.53 px) and of the
#: quality-85 copies (0.61 px).
REPEAT_PX = 3.0


@dataclass(frozen=True)
class Intrinsics:
    K: np.ndarray
    dist: np.ndarray
    rms_px: float
    per_view_px: dict[str, float]
    dropped: tuple[str, ...]
    coverage: float
    image_size: tuple[int, int]
    focal_std_px: float = 0.0  # OpenCV's standard deviation of fx and fy, the larger


@dataclass(frozen=True)
class PairPose:
    """``X_second = R @ X_first + T`` (metres), from the views both cameras saw."""

    R: np.ndarray
    T: np.ndarray
    rms_px: float
    per_view_px: dict[str, float]
    dropped: tuple[str, ...] = ()


@dataclass(frozen=True)
class Floor:
    """Gravity and the floor in one camera's frame, from a board lying on the floor."""

    down: np.ndarray  # unit vector along gravity, camera frame
    height_m: float  # the camera centre above the floor
    pitch_deg: float  # the optical axis below the horizon
    roll_deg: float  # turned about the optical axis (counterclockwise from behind; 180: upside down)
    rms_px: float  # of the board pose fit


@dataclass
class RigSolution:
    rig: Rig
    report: dict[str, Any] = field(default_factory=dict)


def corner_gaps(view: BoardView, other: BoardView) -> np.ndarray:
    """The pixel distance between each corner both images found (by id) and its place in the other image."""
    _, mine, theirs = np.intersect1d(view.ids, other.ids, return_indices=True)
    return np.linalg.norm(view.corners[mine] - other.corners[theirs], axis=1)


def same_pose(view: BoardView, other: BoardView, *, within_px: float = REPEAT_PX) -> bool:
    """Whether two images of one camera show the board at the same pose (:data:`REPEAT_PX`): a copy, a re-saved
    JPEG, a burst's frame grabbed twice, a still board exposed twice. Their corner ids may differ a little (a
    re-saved image loses a corner or two): at least half of each one's are shared, and :data:`MIN_CORNERS`."""
    gaps = corner_gaps(view, other)
    if gaps.size < max(MIN_CORNERS, len(view) / 2, len(other) / 2):
        return False
    return bool(np.all(gaps <= within_px))


def repeated_views(views: Mapping[str, BoardView], *, skip: str | None = None) -> dict[str, str]:
    """View name -> the earlier view (by name) it shows the same pose as (:func:`same_pose`), for the views to count
    once: each copy weighed its pose once more in the lens's fit. ``skip`` (the floor view) is neither."""
    kept: list[str] = []
    repeats: dict[str, str] = {}
    for name in sorted(n for n in views if n != skip):
        same = next((earlier for earlier in kept if same_pose(views[name], views[earlier])), None)
        if same is None:
            kept.append(name)
        else:
            repeats[name] = same
    return repeats


def _object_points(board: BoardSpec, view: BoardView) -> np.ndarray:
    return board.corners_m()[view.ids].astype(np.float32).reshape(-1, 1, 3)


def _image_points(view: BoardView, ids: np.ndarray | None = None) -> np.ndarray:
    corners = view.corners if ids is None else view.corners[np.searchsorted(view.ids, ids)]
    return corners.astype(np.float32).reshape(-1, 1, 2)


def _coverage(views: Mapping[str, BoardView], image_size: tuple[int, int]) -> float:
    gx, gy = COVERAGE_GRID
    hit = np.zeros((gy, gx), bool)
    w, h = image_size
    for view in views.values():
        cx = np.clip((view.corners[:, 0] / w * gx).astype(int), 0, gx - 1)
        cy = np.clip((view.corners[:, 1] / h * gy).astype(int), 0, gy - 1)
        hit[cy, cx] = True
    return float(hit.mean())


def calibrate_intrinsics(board: BoardSpec, views: Mapping[str, BoardView], *, lens: str = "standard",
                         camera: str = "camera", tangential: bool = True) -> Intrinsics:
    """One camera's K and distortion from its views (name -> view). ``tangential=False`` holds p1 and p2 at
    exactly 0 (OpenCV's ``CALIB_ZERO_TANGENT_DIST``), for views whose fitted p1/p2 fold the lens model inside
    the image (:func:`fold_warning`).

    :raises SolveError: fewer than :data:`MIN_VIEWS` views, mixed image sizes, an unknown lens model, views OpenCV
        cannot solve (too few corners in all, a view of under 4), views that do not determine the focal length.
    """
    if lens not in LENS_MODELS:
        raise SolveError(f"lens model {lens!r} is not one of {sorted(LENS_MODELS)}")
    views = dict(views)
    mixed = mixed_views_problem(camera, views)  # ghcal said so of the files first: a library caller's guard
    if mixed is not None:
        raise SolveError(f"{mixed}. Solved as they are, a camera's views at two sizes cannot share one lens")
    if len(views) < MIN_VIEWS:
        raise SolveError(f"camera {camera!r}: the board was found in {len(views)} image(s); at least {MIN_VIEWS} "
                         "are needed (15-30 is usual: near and far, tilted, reaching the image corners)")
    size = next(iter(views.values())).image_size  # all one size (above)
    dropped: list[str] = []
    for attempt in range(2):
        names = sorted(views)
        try:
            rms, K, dist, rvecs, _, std_intrinsics, _, per_view = cv2.calibrateCameraExtended(
                [_object_points(board, views[n]) for n in names], [_image_points(views[n]) for n in names],
                size, None, None, flags=_intrinsics_flags(lens, tangential))
        except cv2.error as e:  # too few corners in all, a view of under 4 or of one row: a library caller's views
            raise SolveError(f"camera {camera!r}: OpenCV cannot solve the lens from {len(names)} views of "
                             f"{sum(len(views[n]) for n in names)} corners in all ({_opencv_words(e)}): each view "
                             f"needs {MIN_CORNERS} corners at least, not all in one row") from e
        errors = dict(zip(names, np.asarray(per_view, float).reshape(-1)))
        median = float(np.median(list(errors.values())))
        outliers = [n for n, e in errors.items() if e > max(OUTLIER_FACTOR * median, 1.0)]
        if attempt or not outliers or len(views) - len(outliers) < MIN_VIEWS:
            break
        dropped = outliers
        views = {n: v for n, v in views.items() if n not in outliers}
    if not np.all(np.isfinite(K)) or not np.all(np.isfinite(dist)):
        raise SolveError(f"camera {camera!r}: the solve diverged (the views may all show the board at one angle)")
    focal = float(min(K[0, 0], K[1, 1]))
    focal_std = float(np.max(np.asarray(std_intrinsics, float).reshape(-1)[:2]))
    if not focal > 0 or not focal_std <= MAX_FOCAL_STD_SHARE * focal:  # NaN refused too
        raise SolveError(f"camera {camera!r}: the views do not determine the focal length (f {focal:.1f} px, give "
                         f"or take {focal_std:.1f} px; at most {MAX_FOCAL_STD_SHARE:.0%} is accepted): the board was "
                         "seen at too few angles. Tilt it 20-45 degrees towards and away from the camera, both ways, "
                         "near and far, and capture again")
    spread = orientation_spread_deg(rvecs)
    if not spread >= MIN_ORIENTATION_SPREAD_DEG:
        raise SolveError(f"camera {camera!r}: the board faced the camera the same way in every view (its "
                         f"orientations span {spread:.1f} degrees; at least {MIN_ORIENTATION_SPREAD_DEG:g} are "
                         f"needed), so the views do not determine the focal length (solved to {focal:.1f} px, a figure "
                         "any other would fit as well). Tilt it 20-45 degrees towards and away from the camera, both "
                         "ways, near and far, and capture again")
    # OpenCV hands the rational model back as 14 terms, the thin-prism and tilt ones held at 0: the rig
    # file and the report get the 8 it fits (docs/calibration.md), as the other models get their 5
    dist = np.asarray(dist, float).reshape(-1)[:8 if lens == "rational" else 5]
    return Intrinsics(K=np.asarray(K, float), dist=dist, rms_px=float(rms),
                      per_view_px={n: round(float(e), 4) for n, e in errors.items()}, dropped=tuple(dropped),
                      coverage=_coverage(views, size), image_size=size, focal_std_px=focal_std)


def _opencv_words(error: cv2.error) -> str:
    """OpenCV's own reason in ``error``, without its version, source line, error code and function."""
    words = str(error).split("error: ", 1)[-1].strip()
    return re.sub(r"^\(-?\d+:[^)]*\)\s*|\s*in function '[^']*'$", "", words)


def orientation_spread_deg(rvecs) -> float:
    """The largest angle (degrees) between the board's normals in two views, from their board -> camera rotation
    vectors: how far apart the orientations a camera saw the board in lie (:data:`MIN_ORIENTATION_SPREAD_DEG`)."""
    normals = np.array([cv2.Rodrigues(np.asarray(r, float).reshape(3))[0][:, 2] for r in rvecs]).reshape(-1, 3)
    if len(normals) < 2:
        return 0.0
    cosines = np.clip(normals @ normals.T, -1.0, 1.0)
    return float(np.degrees(np.arccos(cosines.min())))


def _intrinsics_flags(lens: str, tangential: bool) -> int:
    """``cv2.calibrateCamera``'s flags for ``lens`` (:data:`LENS_MODELS`), p1 and p2 held at 0 without
    ``tangential``."""
    return LENS_MODELS[lens] | (0 if tangential else cv2.CALIB_ZERO_TANGENT_DIST)


def _lens_terms_flags(*dists: np.ndarray) -> int:
    """The flags that make OpenCV use every distortion term given. With the intrinsics fixed it still
    projects through only the first five unless told otherwise, so a rational lens's k4-k6 were ignored
    and the pair's pose came out wrong by tens of pixels."""
    n = max(int(np.asarray(d).size) for d in dists)
    flags = 0
    if n > 5:
        flags |= cv2.CALIB_RATIONAL_MODEL
    if n > 8:
        flags |= cv2.CALIB_THIN_PRISM_MODEL
    if n > 12:
        flags |= cv2.CALIB_TILTED_MODEL
    return flags


def calibrate_pair(board: BoardSpec, first: Mapping[str, BoardView], second: Mapping[str, BoardView],
                   intr_first: Intrinsics, intr_second: Intrinsics, *, names: tuple[str, str] = ("first", "second"),
                   min_common: int = MIN_CORNERS, max_pair_px: float = MAX_PAIR_PX) -> PairPose:
    """The second camera's pose relative to the first, from views both saw (same view name).

    Pairs that do not fit (two instants, a board found wrongly) are dropped, and named in ``dropped``:
    first those that disagree with the consensus of the pairs' single-pair poses, then the worst one at
    a time; no pair kept may fit worse than ``max_pair_px`` (docs/calibration.md).

    :raises SolveError: fewer than :data:`MIN_VIEWS` shared views with ``min_common`` shared corners that
        fix a pose (:func:`~calibration.detect.fixes_a_pose`); bad pairs that would leave fewer than :data:`MIN_VIEWS` or are more than a quarter;
        a pair kept over ``max_pair_px``.
    """
    shared = []
    for name in sorted(set(first) & set(second)):
        ids = np.intersect1d(first[name].ids, second[name].ids)
        # Each camera's corners fix a pose (the detector sees to that), but the corners both found can
        # still be one row, or one row and a corner: no pose from those, and OpenCV's fit of it went to
        # 1e106 px, or it was dropped as a pair "not taken at the same instant" in place of one that was.
        if ids.size >= min_common and fixes_a_pose(board, ids):
            shared.append((name, ids))
    if len(shared) < MIN_VIEWS:
        raise SolveError(f"cameras {names[0]!r} and {names[1]!r} both saw the board in {len(shared)} image pair(s); "
                         f"at least {MIN_VIEWS} are needed: hold it where both cameras see it")
    def solve(pairs: list) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        obj = [board.corners_m()[ids].astype(np.float32).reshape(-1, 1, 3) for _, ids in pairs]
        img_a = [_image_points(first[n], ids) for n, ids in pairs]
        img_b = [_image_points(second[n], ids) for n, ids in pairs]
        R0, T0 = np.eye(3), np.zeros((3, 1))
        # -> rms, K1, D1, K2, D2, R, T, E, F, rvecs, tvecs, per-view errors
        result = cv2.stereoCalibrateExtended(
            # copies: OpenCV writes into these (unchanged with the intrinsics fixed) and refuses read-only arrays
            obj, img_a, img_b, intr_first.K.copy(), intr_first.dist.copy(), intr_second.K.copy(),
            intr_second.dist.copy(), intr_first.image_size, R0, T0,
            flags=cv2.CALIB_FIX_INTRINSIC | _lens_terms_flags(intr_first.dist, intr_second.dist))
        per = np.asarray(result[-1], float).reshape(len(pairs), 2).mean(axis=1)
        return float(result[0]), result[5], result[6], per

    def bad_pair(rms: float, per: np.ndarray) -> tuple[int, tuple] | None:
        """A pair that does not fit with the others (its two images not taken at the same instant, or one
        blurred or mis-detected) and the fit without it; None when every pair fits."""
        worst = int(np.argmax(per))
        if per[worst] > max(OUTLIER_FACTOR * float(np.median(np.delete(per, worst))), 1.0):
            return worst, solve(shared[:worst] + shared[worst + 1:])
        # With few pairs the bad one's error need not stand out at all (five pairs at 10-31 px, the
        # unsynchronised one not the worst; the pose 1.3 m off): where the fit is poor, the pair
        # without which the others fit far better is the bad one.
        if not rms > 1.0:
            return None
        trials = [solve(shared[:k] + shared[k + 1:]) for k in range(len(shared))]
        best = int(np.argmin([t[0] if np.isfinite(t[0]) else np.inf for t in trials]))
        return (best, trials[best]) if OUTLIER_FACTOR * trials[best][0] < rms else None

    dropped: list[str] = []
    total, max_dropped = len(shared), max(1, len(shared) // 4)
    rms, R, T, per = solve(shared)
    # First the pairs that disagree with the others one by one (calibration/consensus.py): two or more
    # bad pairs among few drag every pair's error up together, and dropping one at a time found neither
    # (two of five put the second camera 0.5-1.5 m off, with only a warning).
    bad = _disagreeing_pairs(board, first, second, intr_first, intr_second, shared, solve)
    if bad:
        good = [p for k, p in enumerate(shared) if k not in bad]
        without = solve(good)
        if len(good) < MIN_VIEWS or len(bad) > max_dropped:
            raise SolveError(_bad_pairs_message(names, [shared[k][0] for k in bad], [], rms, without[0], len(good),
                                                total))
        dropped = [shared[k][0] for k in bad]
        shared = good
        rms, R, T, per = without
    # Then one bad pair drags the fit and raises the good ones' errors too, so drop only the worst, solve
    # again, and repeat while one is still bad. A bad pair is never kept: where dropping it would leave
    # fewer than MIN_VIEWS pairs, or drop more than a quarter of them, the solve stops (with exactly
    # MIN_VIEWS pairs one unsynchronised pair put the second camera 0.4-1.7 m off, and only warned).
    while (found := bad_pair(rms, per)) is not None:
        k, without = found
        if len(shared) - 1 < MIN_VIEWS or len(dropped) >= max_dropped:
            raise SolveError(_bad_pairs_message(names, [shared[k][0]], dropped, rms, without[0], len(shared) - 1,
                                                total))
        dropped.append(shared[k][0])
        shared = shared[:k] + shared[k + 1:]
        rms, R, T, per = without
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(T)) and np.isfinite(rms)):
        raise SolveError(f"cameras {names[0]!r} and {names[1]!r}: the pair's pose diverged (the shared views may all "
                         "show the board at one angle, or the two images of a pair were not taken together)")
    # Last, a hard limit: whatever the rules above let through, no pair kept fits this badly
    over = sorted(((float(e), n) for (n, _), e in zip(shared, per) if not e <= max_pair_px), reverse=True)
    if over:
        raise SolveError(
            f"cameras {names[0]!r} and {names[1]!r}: {len(over)} of the {len(shared)} image pairs kept fit at more "
            f"than {max_pair_px:g} px (" + ", ".join(f"{n!r} {e:.2f} px" for e, n in over[:5])
            + (", ..." if len(over) > 5 else "") + f"; pair error {rms:.2f} px): a still board seen by both cameras "
            "at the same instant fits well under 1 px. Were the two cameras' images taken together (the board held "
            "still), and did each camera's own fit go well (its reprojection error)? Remove or retake "
            + ", ".join(repr(n) for _, n in over[:5]))
    return PairPose(R=np.asarray(R, float), T=np.asarray(T, float).reshape(3), rms_px=float(rms),
                    per_view_px={n: round(float(e), 4) for (n, _), e in zip(shared, per)}, dropped=tuple(dropped))


def _disagreeing_pairs(board: BoardSpec, first: Mapping[str, BoardView], second: Mapping[str, BoardView],
                       intr_first: Intrinsics, intr_second: Intrinsics, shared: list,
                       solve: Callable[[list], tuple[float, np.ndarray, np.ndarray, np.ndarray]]) -> list[int]:
    """Indices into ``shared`` of the pairs that do not fit with the consensus of the others.

    The consensus is the largest group whose single-pair poses agree (:func:`calibration.consensus.
    agreeing_pairs`); it is trusted only as a majority (else nothing is decided here). Each pair outside
    it is solved with the group and kept when its own error in that fit is within the outlier bound
    (:data:`OUTLIER_FACTOR` times the group's median error, at least 1 px): a good pair whose single-
    camera pose was loose comes back, a pair of two instants does not.
    """
    poses = [pair_relative_pose(board, first[n], second[n], ids, intr_first.K, intr_first.dist, intr_second.K,
                                intr_second.dist) for n, ids in shared]
    group = agreeing_pairs(poses)
    if len(group) == len(shared) or 2 * len(group) <= len(shared):
        return []
    base = [shared[k] for k in group]
    _, _, _, per = solve(base)
    bound = max(OUTLIER_FACTOR * float(np.median(per)), 1.0)
    bad = []
    for k in range(len(shared)):
        if k in group:
            continue
        # its own error only: a bad pair the group let in (a board moved a few cm) must not make a good one bad
        if not solve(base + [shared[k]])[3][-1] <= bound:
            bad.append(k)
    return bad


def _bad_pairs_message(names: tuple[str, str], bad: list[str], dropped: list[str], rms: float, rms_without: float,
                       left: int, total: int) -> str:
    """Why the pair's pose is not solved: the pairs ``bad`` do not fit, and they cannot be dropped."""
    listed = ", ".join(repr(n) for n in bad)
    head = (f"cameras {names[0]!r} and {names[1]!r}: "
            + (f"the image pair {listed} does not fit" if len(bad) == 1 else f"the image pairs {listed} do not fit")
            + f" the others (pair error {rms:.2f} px with {'it' if len(bad) == 1 else 'them'}, {rms_without:.2f} px "
            "without): " + ("its two images were" if len(bad) == 1 else "the two images of each were")
            + " not taken at the same instant, or the board was found wrongly in one")
    if dropped:
        head += f"; pair(s) {', '.join(repr(n) for n in dropped)} were dropped already for the same reason"
    retake = ", ".join(repr(n) for n in [*dropped, *bad])
    if left < MIN_VIEWS:
        return (f"{head}. That leaves {left} good pair(s) of {total}, and at least {MIN_VIEWS} are needed: capture "
                f"{MIN_VIEWS - left} more view(s) where both cameras see the board (8 or more is usual), or retake "
                f"{retake}")
    return (f"{head}. More than a quarter of the {total} pairs do not fit: are both cameras' images taken at the "
            f"same instant (hold the board still for each view)? Remove or retake {retake}")


def floor_from_view(board: BoardSpec, view: BoardView, intr: Intrinsics, *, board_thickness_m: float = 0.0) \
        -> Floor:
    """Gravity and the camera's height from a view of the board lying flat on the floor, printed face up."""
    ok, rvec, tvec = cv2.solvePnP(_object_points(board, view), _image_points(view), intr.K, intr.dist,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise SolveError("the floor view's board pose could not be solved")
    projected, _ = cv2.projectPoints(_object_points(board, view), rvec, tvec, intr.K, intr.dist)
    rms = float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - view.corners) ** 2, axis=1))))
    R_bc = cv2.Rodrigues(rvec)[0]
    down = R_bc[:, 2]  # the board's z points into the board: down, for a board face up on the floor
    height = float(down @ tvec.reshape(3)) + board_thickness_m
    if height <= 0:
        raise SolveError("the floor view puts the camera below the floor: is the board face down, or is the "
                         "view of a board held up rather than lying on the floor?")
    pitch = math.degrees(math.asin(float(np.clip(down[2], -1.0, 1.0))))
    roll = math.degrees(math.atan2(-float(down[0]), float(down[1])))
    return Floor(down=down, height_m=height, pitch_deg=pitch, roll_deg=roll, rms_px=rms)


def _board_pose_two_views(board: BoardSpec, first: BoardView, second: BoardView, tool_rig: Rig,
                          iterations: int = 30) -> tuple[np.ndarray, np.ndarray, float]:
    """The board's pose in the first camera's frame that best explains both cameras' corners.

    Starts from one camera's pose of the board (the camera that found more corners) and refines the
    six pose parameters by Levenberg-Marquardt on the reprojection errors in both cameras, the
    board's geometry known. Returns (R, t, rms px); board -> first camera.
    """
    cam_a, cam_b = tool_rig.pair
    R_ab, t_ab = cam_b.R @ cam_a.R.T, cam_b.t - cam_b.R @ cam_a.R.T @ cam_a.t  # first -> second camera
    obs = [(cam_a, first), (cam_b, second)]
    seed_cam, seed_view = max(obs, key=lambda o: len(o[1]))
    ok, rvec, tvec = cv2.solvePnP(board.corners_m()[seed_view.ids], seed_view.corners, seed_cam.K, seed_cam.dist)
    if not ok:
        raise SolveError("the floor view's board pose could not be solved")
    R0, t0 = cv2.Rodrigues(rvec)[0], tvec.reshape(3)
    if seed_cam is cam_b:  # board -> second camera  ==>  board -> first camera
        R0, t0 = R_ab.T @ R0, R_ab.T @ (t0 - t_ab)

    def residuals(x: np.ndarray) -> np.ndarray:
        R = cv2.Rodrigues(x[:3])[0]
        t = x[3:]
        out = []
        for cam, view, (Rc, tc) in ((cam_a, first, (np.eye(3), np.zeros(3))), (cam_b, second, (R_ab, t_ab))):
            rv = cv2.Rodrigues(Rc @ R)[0]
            proj, _ = cv2.projectPoints(board.corners_m()[view.ids], rv, Rc @ t + tc, cam.K, cam.dist)
            out.append((proj.reshape(-1, 2) - view.corners).ravel())
        return np.concatenate(out)

    x = np.concatenate([cv2.Rodrigues(R0)[0].ravel(), t0])
    r = residuals(x)
    damping = 1e-3
    for _ in range(iterations):
        J = np.empty((r.size, 6))
        for k in range(6):
            step = 1e-6 if k < 3 else 1e-6 * max(1.0, float(np.linalg.norm(x[3:])))
            dx = np.zeros(6)
            dx[k] = step
            J[:, k] = (residuals(x + dx) - r) / step
        A, g = J.T @ J, J.T @ r
        while True:
            delta = -np.linalg.solve(A + damping * np.diag(np.diag(A) + 1e-12), g)
            r_new = residuals(x + delta)
            if r_new @ r_new < r @ r:
                x, r, damping = x + delta, r_new, max(damping / 10, 1e-9)
                break
            damping *= 10
            if damping > 1e9:
                break
        if np.max(np.abs(delta)) < 1e-10 or damping > 1e9:
            break
    rms = float(np.sqrt(np.mean(r.reshape(-1, 2) ** 2 @ np.ones(2))))
    return cv2.Rodrigues(x[:3])[0], x[3:].copy(), rms


def floor_from_pair(board: BoardSpec, first: BoardView, second: BoardView, tool_rig: Rig, *,
                    board_thickness_m: float = 0.0) -> Floor:
    """Like :func:`floor_from_view`, from a floor view both cameras saw: the board's pose fitted to both
    cameras' corners at once (:func:`_board_pose_two_views`).

    Steadier than one camera's pose of a flat, foreshortened board, whose tilt one view leaves to
    perspective cues a few pixels deep: the second camera, a baseline away, sees the same corners
    from elsewhere. The result is in the first camera's frame (``tool_rig``'s first camera, posed anywhere).
    """
    R, t, rms = _board_pose_two_views(board, first, second, tool_rig)
    # R, t are already board -> first camera, whatever the rig's frame: applying the first camera's own
    # pose again was right only while it was the identity (a levelled rig gave twice the tilt)
    down = R[:, 2]  # the board's z points into the board: down, for a board face up
    height = float(down @ t) + board_thickness_m
    if height <= 0:
        raise SolveError("the floor view puts the camera below the floor: is the board face down?")
    pitch = math.degrees(math.asin(float(np.clip(down[2], -1.0, 1.0))))
    roll = math.degrees(math.atan2(-float(down[0]), float(down[1])))
    return Floor(down=down, height_m=height, pitch_deg=pitch, roll_deg=roll, rms_px=rms)


def board_distance_m(board: BoardSpec, view: BoardView, intr: Intrinsics) -> float:
    """How far the board's found corners' centre is from the camera (metres, in the board's scale)."""
    obj = _object_points(board, view)
    ok, rvec, tvec = cv2.solvePnP(obj, _image_points(view), intr.K, intr.dist)
    if not ok:
        return math.nan
    R, _ = cv2.Rodrigues(rvec)
    centre = R @ obj.reshape(-1, 3).mean(axis=0).astype(np.float64) + np.asarray(tvec, float).reshape(3)
    return float(np.linalg.norm(centre))


def median_board_distance_m(board: BoardSpec, views: Mapping[str, BoardView], intr: Intrinsics) -> float:
    """The median of :func:`board_distance_m` over ``views`` (NaN for none)."""
    distances = [d for d in (board_distance_m(board, v, intr) for v in views.values()) if math.isfinite(d)]
    return float(np.median(distances)) if distances else math.nan


def board_distance_warning(distance_m: float, volume: WorkingVolume, board: BoardSpec, baseline_m: float,
                           camera: str) -> str | None:
    """The warning for a board held, by the solve's scale, far nearer or farther than the working volume's depth
    range (:data:`BOARD_DISTANCE_SLACK`): most likely a ``square_m`` off by a factor (None where it is within)."""
    near = float(volume.min_corner[2]) / BOARD_DISTANCE_SLACK
    far = float(volume.max_corner[2]) * BOARD_DISTANCE_SLACK
    if not math.isfinite(distance_m) or near <= distance_m <= far:
        return None
    side = "nearer than" if distance_m < near else "farther than"
    return (f"scale: by the board's square_m ({1e3 * board.square_m:g} mm) the board was held a median "
            f"{distance_m:.2f} m from camera {camera!r}, {side} the {near:g}-{far:g} m expected for a working volume "
            f"{volume.min_corner[2]:g}-{volume.max_corner[2]:g} m ahead, and the cameras are {1e3 * baseline_m:.0f} mm "
            "apart: every length in the rig scales with square_m. Measure a printed square with a ruler: is square_m "
            "its side in metres (80 mm is 0.08)? If it is, check the baseline against a tape measure")


def _lens_problem(intr: Intrinsics) -> str | None:
    """Why the rig file's reader would refuse a solved lens (its principal point, a focal length, a distortion term),
    said with what to capture; None where it would not. Only the principal point was asked here: a distortion term
    past the reader's bound was refused as the rig file's field, naming a file not yet written, "a typo"."""
    advice = "the views do not pin the lens down: add views near and far, tilted, reaching the image's corners"
    return (principal_point_problem(intr.K, *intr.image_size, advice=advice)
            or focal_length_problem(intr.K, *intr.image_size, advice=advice)
            or distortion_problem(intr.dist, advice=advice))


def _round_or_none(value: float, digits: int) -> float | None:
    """``value`` rounded, None where it is not finite (the report is JSON: no NaN in it)."""
    return round(value, digits) if math.isfinite(value) else None


def _round(a: np.ndarray, digits: int = 6) -> list:
    return np.round(np.asarray(a, float), digits).tolist()


def _enough_besides_the_floor(camera: str, views: Mapping[str, BoardView], calib: Mapping[str, BoardView],
                              floor_view: str | None) -> None:
    """Refuse a camera with too few views once its floor view is set apart, saying so: the floor view levels the rig
    and does not enter the lens, and "found in 3 image(s); at least 4" read against "the board found in 4 of 4
    images" printed just before.

    :raises SolveError: fewer than :data:`MIN_VIEWS` views besides a floor view the camera found the board in.
    """
    if floor_view in views and len(calib) < MIN_VIEWS:
        raise SolveError(f"camera {camera!r}: the board was found in {len(calib)} image(s) besides the floor view "
                         f"{floor_view!r} (which levels the rig and does not enter the lens model); at least "
                         f"{MIN_VIEWS} are needed (15-30 is usual: near and far, tilted, reaching the image corners)")


def solve_rig(board: BoardSpec, views: Mapping[str, Mapping[str, BoardView]], names: tuple[str, str], *,
              lens: str = "standard", floor_view: str | None = None, board_thickness_m: float = 0.0,
              camera_height_m: float | None = None, pitch_deg: float = 0.0, roll_deg: float = 0.0,
              volume: WorkingVolume | None = None, rig_id: str = "rig", tangential: bool = True) -> RigSolution:
    """The levelled rig of the two cameras ``names`` from their views (camera -> view name -> view).

    Levelling: ``floor_view`` (a view name whose board lies on the floor, seen by the first camera,
    else the second) or ``camera_height_m`` with ``pitch_deg`` / ``roll_deg`` of the first camera.
    Views named ``floor_view`` are used for levelling only, not for the intrinsics.

    The rig's ``metadata["calibration"]`` records the board, the floor view, the board's thickness, the
    lens model and whether its tangential terms were fitted (``tangential``; False holds p1, p2 at 0).

    :raises SolveError: too few views, no levelling given, a floor view neither camera saw, a solved lens the
        rig file would refuse (a principal point far from the image centre, a focal length or distortion term past
        its bound).
    """
    if (floor_view is None) == (camera_height_m is None):
        raise SolveError("say where the floor is: a floor view (the board lying on the floor) or the first "
                         "camera's height above the floor (with its pitch and roll)")
    a, b = names
    for name in names:
        if name not in views:
            raise SolveError(f"no views of camera {name!r}; cameras with views: {sorted(views)}")
    if not (math.isfinite(board_thickness_m) and 0.0 <= board_thickness_m <= 0.1):
        raise SolveError(f"the board's thickness must be between 0 and 0.1 m, got {board_thickness_m!r}")
    calib = {cam: {n: v for n, v in views[cam].items() if n != floor_view} for cam in names}
    for cam in names:
        _enough_besides_the_floor(cam, views[cam], calib[cam], floor_view)
    intr = {cam: calibrate_intrinsics(board, calib[cam], lens=lens, camera=cam, tangential=tangential)
            for cam in names}
    for cam in names:  # the rig file refuses such a camera: say why here, not when it is read
        problem = _lens_problem(intr[cam])
        if problem:
            raise SolveError(f"camera {cam!r}: the solved lens model: {problem}")
    # a view dropped from a camera's intrinsics as an outlier is no better for the pair's pose
    kept = {cam: {n: v for n, v in calib[cam].items() if n not in intr[cam].dropped} for cam in names}
    pose = calibrate_pair(board, kept[a], kept[b], intr[a], intr[b], names=names)
    cams = (Camera(a, *intr[a].image_size, intr[a].K, intr[a].dist),
            Camera(b, *intr[b].image_size, intr[b].K, intr[b].dist, pose.R, pose.T))
    tool_rig = Rig(cams, LEVEL_VOLUME, rig_id=rig_id)
    if tool_rig.baseline_problem():  # the rig file's reader refuses such a pair: no file that cannot be loaded
        if tool_rig.baseline > MAX_BASELINE_M:  # the scale is the board's: a square_m far too large
            raise SolveError(f"cameras {a!r} and {b!r} came out {tool_rig.baseline:.4g} m apart (at most "
                             f"{MAX_BASELINE_M:g} m accepted): is the board's square_m ({board.square_m:g}) the side "
                             "of a printed square in metres?")
        raise SolveError(f"cameras {a!r} and {b!r} came out {1e3 * tool_rig.baseline:.1f} mm apart (at least "
                         f"{1e3 * MIN_BASELINE_M:.0f} mm needed): do both camera folders hold the same images, or "
                         "did one camera capture for both (the rig source's first and second)?")
    floor = None
    if floor_view is not None:
        seen_by = [cam for cam in names if floor_view in views[cam]]
        if not seen_by:
            raise SolveError(f"neither camera found the board in the floor view {floor_view!r}")
        for cam in seen_by:
            if views[cam][floor_view].image_size != intr[cam].image_size:
                raise SolveError(f"camera {cam!r}: the floor view is {views[cam][floor_view].image_size}, its other "
                                 f"views {intr[cam].image_size}: take every view at one image size")
        reference = names.index(seen_by[0])
        if len(seen_by) == 2:
            floor = floor_from_pair(board, views[a][floor_view], views[b][floor_view], tool_rig,
                                    board_thickness_m=board_thickness_m)
            method = "floor view, both cameras"
        else:
            floor = floor_from_view(board, views[seen_by[0]][floor_view], intr[seen_by[0]],
                                    board_thickness_m=board_thickness_m)
            method = "floor view, one camera"
        if not CAMERA_HEIGHT_RANGE_M[0] <= floor.height_m <= CAMERA_HEIGHT_RANGE_M[1]:  # as --camera-height
            raise SolveError(f"the floor view puts camera {seen_by[0]!r} {floor.height_m:.2f} m above the floor: "
                             "is the board lying flat on the floor, and is the board definition right?")
        rig = level_rig(tool_rig, camera_height_m=floor.height_m, pitch_deg=floor.pitch_deg,
                        roll_deg=floor.roll_deg, reference=reference, volume=volume)
        levelling = {"method": method, "view": floor_view, "camera": seen_by[0],
                     "camera_height_m": round(floor.height_m, 4), "pitch_deg": round(floor.pitch_deg, 3),
                     "roll_deg": round(floor.roll_deg, 3), "fit_rms_px": round(floor.rms_px, 4)}
    else:
        assert camera_height_m is not None
        rig = level_rig(tool_rig, camera_height_m=camera_height_m, pitch_deg=pitch_deg, roll_deg=roll_deg,
                        volume=volume)
        levelling = {"method": "measured", "camera": a, "camera_height_m": camera_height_m,
                     "pitch_deg": pitch_deg, "roll_deg": roll_deg}
    # what ``ghcal check`` needs to measure with the same board and floor view (docs/calibration.md)
    rig = Rig(rig.cameras, rig.volume, rig_id=rig.rig_id, metadata={
        **rig.metadata, "calibration": {"tool": "ghcal", "board": board.to_dict(), "floor_view": floor_view,
                                        "board_thickness_m": board_thickness_m, "lens_model": lens,
                                        "tangential": tangential}})
    pair_views = {n: kept[a][n] for n in pose.per_view_px}
    board_distance = median_board_distance_m(board, pair_views, intr[a])
    axes = [rig.camera(n).R[2] for n in names]
    convergence = math.degrees(math.acos(float(np.clip(axes[0] @ axes[1], -1.0, 1.0))))
    report: dict[str, Any] = {
        "board": board.to_dict(),
        "lens_model": lens,
        "tangential": tangential,
        "cameras": {
            cam: {"image_size": list(intr[cam].image_size), "views": len(intr[cam].per_view_px),
                  "dropped_views": list(intr[cam].dropped), "rms_px": round(intr[cam].rms_px, 4),
                  "coverage": round(intr[cam].coverage, 3), "K": _round(intr[cam].K, 4),
                  "focal_std_px": round(intr[cam].focal_std_px, 3),
                  "dist": _round(intr[cam].dist), "per_view_px": intr[cam].per_view_px}
            for cam in names},
        "pair": {"views": len(pose.per_view_px), "dropped_views": list(pose.dropped), "rms_px": round(pose.rms_px, 4),
                 "baseline_m": round(float(np.linalg.norm(pose.T)), 5),
                 "convergence_deg": round(convergence, 3), "board_distance_m": _round_or_none(board_distance, 3),
                 "per_view_px": pose.per_view_px},
        "levelling": levelling,
    }
    report["warnings"] = _warnings(report)
    if warning := board_distance_warning(board_distance, volume or LEVEL_VOLUME, board, tool_rig.baseline, a):
        report["warnings"].append(warning)
    if warning := sides_warning(rig):
        report["warnings"].append(warning)
    for cam in rig.pair:
        if cam.fold_inside_image():
            report["warnings"].append(fold_warning(cam))
    return RigSolution(rig=rig, report=report)


def fold_warning(cam: Camera) -> str:
    """The warning for a lens model that folds over inside the image, the fold said as an angle off the
    optical axis (its normalised radius, the tangent of that angle, meant nothing to a reader), naming the
    tangential or thin-prism coefficients where they fold it (:meth:`Camera.fold_terms`)."""
    limit = cam.lens_limit
    where = (f"{cam.name}: the solved lens model folds over inside the image, {math.degrees(math.atan(limit)):.0f} "
             f"degrees off the optical axis (normalised radius {limit:.2f})")
    if terms := cam.fold_terms():
        hold = ", or solve with --no-tangential to hold p1 and p2 at 0" if folded_by_tangential(terms) else ""
        return (f"{where}, by its tangential or thin-prism terms ({fold_terms_text(terms)}): the fit went wrong; "
                f"capture views that cover the whole frame, corners too, and solve again{hold}")
    return f"{where}: views did not reach the image corners; capture some there, or use --lens narrow"


def expected_sides(rig: Rig) -> tuple[Camera, Camera, bool]:
    """The pair's cameras as (expected on the left, expected on the right, by their names): by their names where
    they are named ``left`` and ``right`` (:data:`SIDE_NAMES`, in either order), else by the rig's order, the
    first on the left."""
    named = {cam.name.lower(): cam for cam in rig.pair}
    if set(named) == set(SIDE_NAMES):
        left, right = (named[side] for side in SIDE_NAMES)
        return left, right, True
    first, second = rig.pair
    return first, second, False


def _across_first_camera_m(rig: Rig, cam: Camera) -> float:
    """How far ``cam``'s centre lies along the first camera's x (to the right in its image), from that camera:
    the side the extrinsics give, levelled or not (a typed --roll 180 would turn the rig's x around)."""
    first = rig.pair[0]
    return float((first.R @ (cam.center - first.center))[0])


def sides_warning(rig: Rig) -> str | None:
    """The warning for a pair whose camera expected on the left (:func:`expected_sides`: by its name ``left``, else
    as the first camera) came out on the right of the other, along the first camera's x (None otherwise): the
    images of each in the other's folder (another tool that named the cameras the other way round) solve as well
    as the right ones, and the rig file gave each camera the other's lens and pose without a word. Before session
    65 only a pair named ``left`` and ``right`` was checked; ``cam_a`` and ``cam_b`` exchanged passed."""
    left, right, by_name = expected_sides(rig)
    across = _across_first_camera_m(rig, left) - _across_first_camera_m(rig, right)
    if not across > SIDES_SHARE * rig.baseline:
        return None
    if by_name:
        against, renamed = "against its name", "if the cameras are named against their sides, the rig is right as it is"
    else:
        against = "though the first camera of the pair, which the rig sources put on the left"
        renamed = f"if camera {left.name!r} is on the right on purpose, the rig is right as it is"
    return (f"sides: camera {left.name!r} came out {across:.3f} m to the right of {right.name!r} (along camera "
            f"{rig.pair[0].name!r}'s image x, seen from behind the cameras), {against}: if each camera's folder holds "
            "the other's images (a tool that named them the other way round), exchange the two folders' images and "
            f"solve again; {renamed}")


def typed_pitch_warning(pitch_deg: float, camera: str) -> str | None:
    """The warning for a typed ``--pitch`` outside ``USUAL_PITCH_DEG`` (None inside it), for ``solve`` and
    ``import`` alike: a level app or an inclinometer may read from the vertical, and 80 typed for 10
    levelled the rig looking at the floor, with no word."""
    if USUAL_PITCH_DEG[0] <= pitch_deg <= USUAL_PITCH_DEG[1]:
        return None
    return (f"--pitch {pitch_deg:g} degrees for camera {camera!r} is unusual for a rig filming people: it is the "
            "angle of the optical axis below the horizon (0 level, 90 straight down), not from the vertical")


def _warnings(report: dict[str, Any]) -> list[str]:
    out = []
    for cam, r in report["cameras"].items():
        if r["rms_px"] > 0.5:
            out.append(f"{cam}: reprojection error {r['rms_px']:.2f} px (usually < 0.5): blurred or moving images, "
                       "a board that is not flat, or a wrong board definition")
        if r["coverage"] < 0.5:
            out.append(f"{cam}: the board's corners covered {r['coverage']:.0%} of the image: move it into the "
                       "image's corners and edges, where the lens distorts most")
        if r.get("focal_std_px", 0.0) > WARN_FOCAL_STD_SHARE * min(r["K"][0][0], r["K"][1][1]):
            out.append(f"{cam}: the focal length is known to {r['focal_std_px']:.1f} px (over "
                       f"{WARN_FOCAL_STD_SHARE:.0%} of it): tilt the board more between views")
        if r["views"] < 10:
            out.append(f"{cam}: {r['views']} views (15-30 is usual): the lens model is weakly determined")
        if r["dropped_views"]:
            out.append(f"{cam}: views {r['dropped_views']} were dropped as outliers (blurred or moving?)")
    if report["pair"]["rms_px"] > 1.0:
        out.append(f"pair: reprojection error {report['pair']['rms_px']:.2f} px (usually < 1): were the two "
                   "cameras' images taken at the same instant?")
    if report["pair"]["dropped_views"]:
        out.append(f"pair: views {report['pair']['dropped_views']} were dropped as outliers (the two images not "
                   "taken at the same instant?)")
    lv = report["levelling"]
    if lv["method"].startswith("floor view") and not USUAL_PITCH_DEG[0] <= lv["pitch_deg"] <= USUAL_PITCH_DEG[1]:
        out.append(f"levelling: the floor view gives camera {lv['camera']!r} a pitch of {lv['pitch_deg']:.1f} "
                   "degrees, unusual for a rig filming people: was the board lying flat on the floor?")
    elif lv["method"] == "measured" and (warning := typed_pitch_warning(lv["pitch_deg"], lv["camera"])):
        out.append(f"levelling: {warning}")
    if report["pair"]["views"] < 8:
        out.append(f"pair: {report['pair']['views']} views seen by both cameras: the relative pose is weakly "
                   "determined")
    return out
