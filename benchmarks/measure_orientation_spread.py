"""How far apart a camera's solved board orientations lie, for solves that land near the true focal length and for
those that do not.

    .venv/bin/python benchmarks/measure_orientation_spread.py [--seeds 40] [--views 8,15] [--tilts 3,5,8,12,20,30]
        [--one-axis]

``calibrate_intrinsics`` refuses views whose board orientations, as the solve poses them, span less than
:data:`calibration.solve.MIN_ORIENTATION_SPREAD_DEG` (the largest angle between two views' board normals): views all
held square-on fit a short focal length with the board held close as well as the truth, and OpenCV's standard
deviation of that focal length says nothing there. Each case projects the 7x5 board of
``tests/calibration/test_degenerate_solves.py`` through that file's 640x480 lens (f 500 px, no distortion) in
``--views`` whole views, 1-2.5 m away, turned up to ``tilt`` degrees about both in-plane axes (``--one-axis``: about
the horizontal one only; and up to 20 about the optical axis), 0.2 px noise, and solves it with the standard lens
model as the solve does. The figures ignore the spread check itself: the solve is OpenCV's, the spread measured on
its rotations. Printed per tilt and view count: the solves the focal standard deviation refuses, and of the others
those within 10 % of 500 px and those further off, each with the least and largest spread and how many spread under
the limit; then each solve further off that spreads past it, its focal length as a multiple of the truth, its focal
standard deviation as a share of its focal length (the report warns past
:data:`calibration.solve.WARN_FOCAL_STD_SHARE`) and its largest distortion term. A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calibration.board import BoardSpec  # noqa: E402
from ghnerf_runtime.cli.counts import positive_count, positive_count_list  # noqa: E402
from ghnerf_runtime.cli.numbers import number_list  # noqa: E402
from calibration.solve import (MAX_FOCAL_STD_SHARE, MIN_ORIENTATION_SPREAD_DEG,  # noqa: E402
                               orientation_spread_deg)

BOARD = BoardSpec(squares_x=7, squares_y=5, square_m=0.08, marker_m=0.06)
SIZE = (640, 480)
K = np.array([[500.0, 0.0, 319.5], [0.0, 500.0, 239.5], [0.0, 0.0, 1.0]])


def _views(rng: np.random.Generator, count: int, tilt_deg: float, one_axis: bool) -> list[np.ndarray]:
    """``count`` whole views' corners (pixels) of the board turned up to ``tilt_deg`` from square-on (about the
    horizontal axis only where ``one_axis``)."""
    corners = BOARD.corners_m()
    centre = np.array([*np.array(BOARD.size_m) / 2, 0.0])
    views: list[np.ndarray] = []
    while len(views) < count:
        up = tilt_deg * rng.uniform(-1, 1)  # drawn first: the seeds' views of both axes as before --one-axis
        across = 0.0 if one_axis else tilt_deg * rng.uniform(-1, 1)
        rvec = np.radians([up, across, rng.uniform(-20, 20)])
        R = cv2.Rodrigues(rvec)[0]
        t = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.2, 0.2), rng.uniform(1.0, 2.5)]) - R @ centre
        uv = cv2.projectPoints(corners, cv2.Rodrigues(R)[0], t, K, None)[0].reshape(-1, 2)
        uv = uv + rng.normal(0.0, 0.2, uv.shape)
        if np.all((uv > 0) & (uv < np.array(SIZE) - 1)):
            views.append(uv.astype(np.float32).reshape(-1, 1, 2))
    return views


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=positive_count, default=40)
    parser.add_argument("--views", type=positive_count_list, default="8,15")
    parser.add_argument("--tilts", type=number_list, default="3,5,8,12,20,30")
    parser.add_argument("--one-axis", action="store_true", help="tilt the board about the horizontal axis only")
    args = parser.parse_args()
    obj = BOARD.corners_m().astype(np.float32).reshape(-1, 1, 3)
    for tilt in args.tilts:
        for count in args.views:
            refused, near, far, passed = 0, [], [], []  # passed: (focal ratio, std share, largest |distortion|)
            for seed in range(args.seeds):
                views = _views(np.random.default_rng(seed), count, tilt, args.one_axis)
                _, Ks, dist, rvecs, _, std, _, _ = cv2.calibrateCameraExtended([obj] * count, views, SIZE, None, None)
                focal, focal_std = float(min(Ks[0, 0], Ks[1, 1])), float(np.max(std[:2]))
                if not focal_std <= MAX_FOCAL_STD_SHARE * focal:
                    refused += 1
                    continue
                spread = orientation_spread_deg(rvecs)
                off = abs(Ks[0, 0] / K[0, 0] - 1) > 0.1
                (far if off else near).append(spread)
                if off and spread >= MIN_ORIENTATION_SPREAD_DEG:
                    passed.append((Ks[0, 0] / K[0, 0], focal_std / focal, float(np.max(np.abs(dist)))))
            said = ", ".join(f"{what} {len(s)} (spread {min(s):.1f}-{max(s):.1f} deg, "
                             f"{sum(x < MIN_ORIENTATION_SPREAD_DEG for x in s)} under {MIN_ORIENTATION_SPREAD_DEG:g})"
                             if s else f"{what} 0"
                             for what, s in (("within 10 %", near), ("further off", far)))
            past = "; further off and spread past it: " + ", ".join(f"f x{r:.2f} std {s:.1%} |dist| {d:.3g}"
                                                                      for r, s, d in passed)
            print(f"tilt {tilt:g} deg, {count} views: refused by the focal std {refused}; {said}"
                  + (past if passed else ""))


if __name__ == "__main__":
    main()
