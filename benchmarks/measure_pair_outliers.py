"""What bad image pairs do to ``ghcal``'s pair solve, and how far each pair alone agrees with the truth.

    .venv/bin/python benchmarks/measure_pair_outliers.py [--seeds 20]

The figures behind the pair rules of docs/calibration.md (``calibration/solve.py``,
``calibration/consensus.py``), on projected board corners (no rendering, 0.2 px noise), built as
``tests/calibration/test_pair_and_check.py`` builds them: ``example_rig()``, a 7x5 board of 120 mm
squares 1-2.2 m away, the true intrinsics. A pair is made bad by taking its second image from another
view (unsynchronised) or of the board moved a few centimetres. Printed:

1. each pair's own pose of the second camera (``pair_relative_pose``) against the truth, good and
   bad pairs apart (10 pairs, 3 unsynchronised, each seed);
2. two unsynchronised pairs of five: OpenCV's joint fit of all five (what the one-at-a-time rule
   kept) and what ``calibrate_pair`` does now;
3. the worst pair error of clean pairs (5-15 pairs);
4. boards moved 1-8 cm between the two images of two pairs of five or eight.

A tool, not a test; about 20 s.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from calibration.board import BoardSpec  # noqa: E402
from calibration.consensus import pair_relative_pose  # noqa: E402
from calibration.detect import BoardView  # noqa: E402
from calibration.errors import SolveError  # noqa: E402
from calibration.render import board_poses_both_see, example_rig  # noqa: E402
from calibration.solve import Intrinsics, calibrate_pair  # noqa: E402

BOARD = BoardSpec(squares_x=7, squares_y=5, square_m=0.12, marker_m=0.09)
RIG = example_rig()
INTR = {c.name: Intrinsics(K=c.K, dist=c.dist, rms_px=0.1, per_view_px={}, dropped=(), coverage=1.0,
                           image_size=c.size) for c in RIG.pair}
A, B = RIG.pair
R_TRUE = B.R @ A.R.T
T_TRUE = B.t - R_TRUE @ A.t


def _views(poses: dict, noise_px: float, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    out = {cam.name: {} for cam in RIG.pair}
    for name, (R, t) in poses.items():
        corners = BOARD.corners_m() @ R.T + t
        for cam in RIG.pair:
            uv, _ = cam.project(corners)
            out[cam.name][name] = BoardView(np.arange(len(uv)), uv + rng.normal(0.0, noise_px, uv.shape), cam.size)
    return out


def _facing_poses(count: int, seed: int) -> dict:
    return board_poses_both_see(RIG, BOARD, count, seed)


def _unsynchronised(pairs: int, bad: int, seed: int) -> dict:
    views = _views(_facing_poses(pairs + bad, seed), 0.2, seed)
    for k in range(bad):
        views["right"][f"{k:03d}"] = views["right"].pop(f"{pairs + k:03d}")
        del views["left"][f"{pairs + k:03d}"]
    return views


def _moved(pairs: int, bad: int, shift_m: float, seed: int) -> dict:
    poses = _facing_poses(pairs, seed)
    views = _views(poses, 0.2, seed)
    rng = np.random.default_rng(seed + 100)
    for k in range(bad):
        R, t = poses[f"{k:03d}"]
        step = rng.normal(size=3)
        views["right"][f"{k:03d}"] = _views({"x": (R, t + shift_m * step / np.linalg.norm(step))}, 0.2,
                                            seed + 7)["right"]["x"]
    return views


def _joint_fit(views: dict) -> tuple[float, float]:
    """OpenCV's fit of every shared pair: (pair rms px, error of T mm)."""
    names = sorted(set(views["left"]) & set(views["right"]))
    obj = [BOARD.corners_m().astype(np.float32).reshape(-1, 1, 3) for _ in names]
    img = {c: [views[c][n].corners.astype(np.float32).reshape(-1, 1, 2) for n in names] for c in views}
    result = cv2.stereoCalibrateExtended(obj, img["left"], img["right"], A.K.copy(), A.dist.copy(), B.K.copy(),
                                         B.dist.copy(), A.size, np.eye(3), np.zeros((3, 1)),
                                         flags=cv2.CALIB_FIX_INTRINSIC)
    return float(result[0]), 1e3 * float(np.linalg.norm(result[6].reshape(3) - T_TRUE))


def _verdict(views: dict) -> str:
    try:
        pose = calibrate_pair(BOARD, views["left"], views["right"], INTR["left"], INTR["right"])
    except SolveError as e:
        return "refused: " + str(e).split(": ", 1)[1][:70]
    return (f"solved, dropped {list(pose.dropped)}, {pose.rms_px:.2f} px (worst {max(pose.per_view_px.values()):.2f}),"
            f" T off {1e3 * np.linalg.norm(pose.T - T_TRUE):.0f} mm")


def _spread(values: list[float]) -> str:
    v = np.asarray(values)
    return f"min {v.min():.1f} median {np.median(v):.1f} p95 {np.percentile(v, 95):.1f} max {v.max():.1f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=positive_count, default=20)
    args = parser.parse_args()

    print("1. each pair's own pose against the truth (10 pairs, 3 unsynchronised)")
    off = {"good": ([], []), "bad": ([], [])}
    for seed in range(args.seeds):
        views = _unsynchronised(10, 3, seed)
        for name in sorted(views["left"]):
            R, t = pair_relative_pose(BOARD, views["left"][name], views["right"][name], views["left"][name].ids,
                                      A.K, A.dist, B.K, B.dist)
            mm, deg = off["bad" if name < "003" else "good"]
            mm.append(1e3 * float(np.linalg.norm(t - T_TRUE)))
            deg.append(float(np.degrees(np.linalg.norm(cv2.Rodrigues(R @ R_TRUE.T)[0]))))
    for kind, (mm, deg) in off.items():
        print(f"   {kind} ({len(mm)}): mm {_spread(mm)}; deg {_spread(deg)}")

    print("2. two unsynchronised pairs of five")
    for seed in range(6):
        views = _unsynchronised(5, 2, seed)
        rms, t_mm = _joint_fit(views)
        print(f"   seed {seed}: all five fitted: {rms:.1f} px, T off {t_mm:.0f} mm; now {_verdict(views)}")

    print("3. clean pairs (0.2 px noise): the worst pair error")
    worst = []
    for pairs in (5, 8, 10, 15):
        for seed in range(6):
            pose = calibrate_pair(BOARD, *(_views(_facing_poses(pairs, seed), 0.2, seed)[c] for c in ("left", "right")),
                                  INTR["left"], INTR["right"])
            worst.append(max(pose.per_view_px.values()))
    print(f"   {len(worst)} solves: {_spread(worst)} px")

    print("4. boards moved between the two images of some pairs")
    for pairs, bad in ((5, 2), (8, 2)):
        for shift in (0.01, 0.02, 0.04, 0.08):
            for seed in range(3):
                verdict = _verdict(_moved(pairs, bad, shift, seed))
                print(f"   {bad} of {pairs} moved {100 * shift:.0f} cm, seed {seed}: {verdict}")


if __name__ == "__main__":
    main()
