"""The pair solve through every lens term, and ``ghcal check`` failing a rig that does not fit.

Board corners are projected exactly through known cameras (no rendering, no detection), so each
case runs in well under a second and the truth is known to the digit.
"""
from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from calibration import cli
from calibration.board import BoardSpec, load_board
from calibration.check import CheckLimits, check_failures, check_rig
from calibration.detect import BoardView
from calibration.render import board_pose_facing, example_rig
from calibration.errors import SolveError
from calibration.solve import Intrinsics, _lens_terms_flags, calibrate_intrinsics, calibrate_pair
from ghnerf_runtime.geometry.camera import Camera, intrinsics_from_fov, look_at
from ghnerf_runtime.geometry.rig import Rig

BOARD = BoardSpec(squares_x=7, squares_y=5, square_m=0.12, marker_m=0.09)


def _views(rig: Rig, poses: dict, noise_px: float = 0.0, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    out = {cam.name: {} for cam in rig.pair}
    for name, (R, t) in poses.items():
        corners = BOARD.corners_m() @ R.T + t
        for cam in rig.pair:
            uv, _ = cam.project(corners)
            out[cam.name][name] = BoardView(np.arange(len(uv)), uv + rng.normal(0.0, noise_px, uv.shape), cam.size)
    return out


def _facing_poses(rig: Rig, count: int, seed: int) -> dict:
    """Board poses both cameras see whole, spread over depth and angle."""
    rng = np.random.default_rng(seed)
    mid = 0.5 * (rig.pair[0].center + rig.pair[1].center)
    forward = rig.pair[0].R[2] + rig.pair[1].R[2]
    forward /= np.linalg.norm(forward)
    poses = {}
    while len(poses) < count:
        depth = rng.uniform(1.0, 2.2)
        centre = mid + depth * forward + np.array([rng.uniform(-0.4, 0.4) * depth, rng.uniform(-0.25, 0.25) * depth, 0])
        R, t = board_pose_facing(BOARD, centre, mid, yaw_deg=rng.uniform(-35, 35), pitch_deg=rng.uniform(-35, 35),
                                 spin_deg=rng.uniform(-25, 25))
        corners = BOARD.corners_m() @ R.T + t
        inside = True
        for cam in rig.pair:
            uv, _ = cam.project(corners)
            inside &= bool(np.all(np.isfinite(uv)) and np.all((uv > 2) & (uv < [cam.width - 3, cam.height - 3])))
        if inside:
            poses[f"{len(poses):03d}"] = (R, t)
    return poses


def _relative_t(first: Camera, second: Camera) -> np.ndarray:
    return second.t - second.R @ first.R.T @ first.t


def test_the_pair_is_solved_through_a_rational_lens():
    # a wide lens whose k4-k6 matter: the pair solve once projected through the first five terms only,
    # and put the second camera tens of centimetres off with a pair error of tens of pixels
    dist = np.array([-0.3, 0.1, 0.0, 0.0, 0.0, 0.2, 0.05, 0.01])
    cams = []
    for name, x in (("left", -0.3), ("right", 0.3)):
        R, t = look_at([x, -1.4, 0.0], [0.0, -0.6, 2.5])
        cams.append(Camera(name, 960, 600, intrinsics_from_fov(960, 600, 90.0), dist, R, t))
    rig = Rig(tuple(cams), example_rig().volume)
    views = _views(rig, _facing_poses(rig, 12, seed=1), noise_px=0.1, seed=2)
    intr = {cam.name: Intrinsics(K=cam.K, dist=dist, rms_px=0.1, per_view_px={}, dropped=(), coverage=1.0,
                                 image_size=cam.size) for cam in cams}
    pose = calibrate_pair(BOARD, views["left"], views["right"], intr["left"], intr["right"])
    assert pose.rms_px < 0.3, pose.rms_px
    assert np.linalg.norm(pose.T - _relative_t(*cams)) < 0.005, (pose.T, _relative_t(*cams))
    assert pose.dropped == ()
    # the rational model solved is its 8 terms (OpenCV gave 14, six held at 0, into the rig file and report)
    solved = calibrate_intrinsics(BOARD, views["left"], lens="rational")
    assert solved.dist.size == 8 and solved.rms_px < 0.3
    assert {lens: calibrate_intrinsics(BOARD, views["left"], lens=lens).dist.size
            for lens in ("standard", "narrow")} == {"standard": 5, "narrow": 5}


def test_a_pair_whose_shared_corners_are_one_row_is_not_used():
    # Each camera found two rows of the board, each pair of rows off one line as the detector demands,
    # but the corners both found are a single row: no pose. It was solved with the others (a pair error
    # of 1e106 px where it could not be dropped) or dropped as a pair not taken at the same instant.
    rig = example_rig()
    intr = {cam.name: Intrinsics(K=cam.K, dist=cam.dist, rms_px=0.1, per_view_px={}, dropped=(), coverage=1.0,
                                 image_size=cam.size) for cam in rig.pair}
    views = _views(rig, _facing_poses(rig, 6, seed=3), noise_px=0.05, seed=4)
    per_row = BOARD.squares_x - 1
    for cam, rows in (("left", (0, 1)), ("right", (1, 2))):
        v = views[cam]["000"]
        keep = np.isin(v.ids // per_row, rows)
        views[cam]["000"] = BoardView(v.ids[keep], v.corners[keep], v.image_size)
    pose = calibrate_pair(BOARD, views["left"], views["right"], intr["left"], intr["right"])
    assert pose.dropped == () and sorted(pose.per_view_px) == ["001", "002", "003", "004", "005"]
    assert pose.rms_px < 0.2 and np.linalg.norm(pose.T - _relative_t(*rig.pair)) < 0.005
    four = {cam: {n: v for n, v in views[cam].items() if n < "004"} for cam in views}  # three usable pairs
    with pytest.raises(SolveError, match="both saw the board in 3 image pair"):
        calibrate_pair(BOARD, four["left"], four["right"], intr["left"], intr["right"])


@pytest.mark.parametrize("pairs,seed", [(5, 1), (6, 3)])
def test_one_unsynchronised_pair_among_few_is_found_though_its_error_does_not_stand_out(pairs, seed):
    # Its right image of another instant drags the whole fit: every pair at 6-18 px, the bad one not the
    # worst or not three times the median, so nothing was dropped and the second camera came out ~1.4 m off.
    rig = example_rig()
    intr = {cam.name: Intrinsics(K=cam.K, dist=cam.dist, rms_px=0.1, per_view_px={}, dropped=(), coverage=1.0,
                                 image_size=cam.size) for cam in rig.pair}
    views = _views(rig, _facing_poses(rig, pairs + 1, seed=seed), noise_px=0.2, seed=seed)
    other = f"{pairs:03d}"
    views["right"]["000"] = views["right"].pop(other)
    del views["left"][other]
    pose = calibrate_pair(BOARD, views["left"], views["right"], intr["left"], intr["right"])
    assert pose.dropped == ("000",) and pose.rms_px < 0.4, (pose.dropped, pose.per_view_px)
    assert np.linalg.norm(pose.T - _relative_t(*rig.pair)) < 0.005


def _with_unsynchronised(rig: Rig, pairs: int, bad: int, seed: int) -> dict:
    """``pairs`` shared views whose first ``bad`` have their right image from another instant."""
    views = _views(rig, _facing_poses(rig, pairs + bad, seed=seed), noise_px=0.2, seed=seed)
    for k in range(bad):
        other = f"{pairs + k:03d}"
        views["right"][f"{k:03d}"] = views["right"].pop(other)
        del views["left"][other]
    return views


@pytest.mark.parametrize("seed", [0, 3])
def test_a_bad_pair_among_the_fewest_stops_the_solve(seed):
    # Exactly MIN_VIEWS pairs, one unsynchronised: nothing could be dropped, so the pose was solved with it
    # (the second camera 0.4-1.7 m off, the pair error 11-26 px) and the rig file written with a warning.
    rig = example_rig()
    intr = {cam.name: Intrinsics(K=cam.K, dist=cam.dist, rms_px=0.1, per_view_px={}, dropped=(), coverage=1.0,
                                 image_size=cam.size) for cam in rig.pair}
    views = _with_unsynchronised(rig, 4, 1, seed)
    with pytest.raises(SolveError) as e:
        calibrate_pair(BOARD, views["left"], views["right"], intr["left"], intr["right"], names=("left", "right"))
    message = str(e.value)
    assert "image pair '000' does not fit" in message and "3 good pair(s) of 4" in message
    assert "capture 1 more view(s)" in message, message
    # the same four pairs, in sync, solve
    views = _views(rig, _facing_poses(rig, 4, seed=seed), noise_px=0.2, seed=seed)
    pose = calibrate_pair(BOARD, views["left"], views["right"], intr["left"], intr["right"])
    assert pose.dropped == () and np.linalg.norm(pose.T - _relative_t(*rig.pair)) < 0.005


@pytest.mark.parametrize("pairs, bad, seed, words", [
    (6, 2, 0, ["'001' does not fit", "'000' were dropped already", "More than a quarter of the 6 pairs",
               "retake '000', '001'"]),
    (8, 3, 3, ["'001' does not fit", "'000', '002' were dropped already", "More than a quarter of the 8 pairs"]),
])
def test_bad_pairs_beyond_what_may_be_dropped_stop_the_solve(pairs, bad, seed, words):
    # once the pairs allowed were dropped, the next bad one was kept: the pose solved with it (16 px, 0.5 m
    # off for six pairs), and only a warning
    rig = example_rig()
    intr = {cam.name: Intrinsics(K=cam.K, dist=cam.dist, rms_px=0.1, per_view_px={}, dropped=(), coverage=1.0,
                                 image_size=cam.size) for cam in rig.pair}
    views = _with_unsynchronised(rig, pairs, bad, seed=seed)
    with pytest.raises(SolveError) as e:
        calibrate_pair(BOARD, views["left"], views["right"], intr["left"], intr["right"])
    assert all(w in str(e.value) for w in words), str(e.value)


@pytest.mark.parametrize("size,flags", [(4, 0), (5, 0), (8, cv2.CALIB_RATIONAL_MODEL),
                                         (12, cv2.CALIB_RATIONAL_MODEL | cv2.CALIB_THIN_PRISM_MODEL),
                                         (14, cv2.CALIB_RATIONAL_MODEL | cv2.CALIB_THIN_PRISM_MODEL
                                          | cv2.CALIB_TILTED_MODEL)])
def test_every_lens_term_given_is_used(size, flags):
    assert _lens_terms_flags(np.zeros(5), np.zeros(size)) == flags


@pytest.fixture(scope="module")
def level_rig() -> Rig:
    """A pair looking level, its floor view on the floor 2.2 m ahead."""
    cams = []
    for name, x in (("left", -0.3), ("right", 0.3)):
        R, t = look_at([x, -1.4, 0.0], [0.0, -1.0, 2.5])
        cams.append(Camera(name, 960, 600, intrinsics_from_fov(960, 600, 75.0), [-0.12, 0.03, 0.001, -0.0005, 0.0],
                           R, t))
    return Rig(tuple(cams), example_rig().volume)


@pytest.fixture(scope="module")
def level_views(level_rig) -> dict:
    poses = _facing_poses(level_rig, 6, seed=5)
    x, z = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])  # face up: the board's z points down
    R = np.stack([x, np.cross(z, x), z], axis=1)
    poses["floor"] = (R, np.array([0, 0, 2.2]) - R @ np.array([BOARD.size_m[0] / 2, BOARD.size_m[1] / 2, 0]))
    return _views(level_rig, poses)


def test_the_rig_that_was_filmed_fits(level_rig, level_views):
    report = check_rig(level_rig, BOARD, level_views)
    assert report["untriangulated"] == 0 and report["corners"] == 7 * 24
    assert abs(report["floor"]["height_mm_median"]) < 1.0
    assert check_failures(report) == []


def test_a_camera_turned_far_fails_and_the_report_stays_json(level_rig, level_views):
    # turned 20 degrees outward, the two rays of a corner no longer meet in front of both cameras: the
    # check measured from the fill value, got NaN pixels and a zero scale, and passed the rig
    right = level_rig.camera("right")
    turn = cv2.Rodrigues(np.array([0.0, math.radians(-20.0), 0.0]))[0]
    turned = Rig((level_rig.camera("left"), right.with_pose(turn @ right.R, turn @ right.t)), level_rig.volume)
    report = check_rig(turned, BOARD, level_views)
    assert report["corners"] == 7 * 24 and report["corners"] // 2 < report["untriangulated"] < report["corners"]
    assert math.isfinite(report["reprojection_px_rms"])
    reasons = check_failures(report)
    assert any(f"{report['untriangulated']} of 168 corners do not triangulate" in r for r in reasons), reasons
    json.dumps(report, allow_nan=False)


def test_a_report_with_nothing_measured_fails():
    report = {"pairs": 1, "corners": 24, "untriangulated": 24, "reprojection_px_rms": None, "scale": None,
              "per_view": {"000": {"corners": 24, "untriangulated": 24}}}
    assert check_failures(report) == ["24 of 24 corners do not triangulate in front of both cameras (view(s) 000)",
                                      "no corner could be reprojected"]


def test_a_tilted_rig_fails_on_the_floor(level_rig, level_views):
    # the whole rig tilted 3 degrees on its mount: the pair's pose, hence pixels and scale, are intact
    tilt = cv2.Rodrigues(np.array([math.radians(3.0), 0.0, 0.0]))[0]
    tilted = Rig(tuple(c.with_pose(c.R @ tilt.T, c.t) for c in level_rig.cameras), level_rig.volume)
    report = check_rig(tilted, BOARD, level_views)
    assert report["reprojection_px_rms"] < 0.01 and abs(report["scale"] - 1.0) < 1e-4
    assert abs(report["floor"]["height_mm_median"]) > 50
    reasons = check_failures(report)
    assert len(reasons) == 1 and "off the floor" in reasons[0], reasons
    assert check_failures(report, CheckLimits(max_floor_mm=1000.0)) == []


def test_the_board_file_measured_on_the_print_is_not_overwritten(tmp_path, capsys):
    assert cli.main(["board", "--out", str(tmp_path)]) == 0
    spec = tmp_path / "board.json"
    measured = {**json.loads(spec.read_text()), "square_m": 0.0787, "marker_m": 0.059}
    spec.write_text(json.dumps(measured))
    capsys.readouterr()
    assert cli.main(["board", "--out", str(tmp_path)]) == 2  # the defaults again
    assert "defines another board" in capsys.readouterr().err
    assert load_board(spec).square_m == 0.0787
    assert cli.main(["board", "--out", str(tmp_path), "--board", str(spec)]) == 0  # printed again, as measured
    assert load_board(spec).square_m == 0.0787
    assert cli.main(["board", "--out", str(tmp_path), "--force"]) == 0
    assert load_board(spec) == BoardSpec()


def test_the_floor_view_is_the_one_named(level_rig, level_views):
    # only a view literally named 'floor' was measured, while solve takes --floor-view NAME
    renamed = {cam: {("ground" if n == "floor" else n): v for n, v in views.items()}
               for cam, views in level_views.items()}
    assert "floor" not in check_rig(level_rig, BOARD, renamed)
    report = check_rig(level_rig, BOARD, renamed, floor_view="ground")
    assert report["floor"]["view"] == "ground" and abs(report["floor"]["height_mm_median"]) < 1.0
