"""How far apart the detected corners of one board pose's two images lie, against two poses' images.

    .venv/bin/python benchmarks/measure_repeated_views.py [--seeds 0,1,2] [--count 15] [--edge-count 6]

``ghcal solve`` counts once an image that shows the board as an earlier one of its camera does
(:data:`calibration.solve.REPEAT_PX`): every corner the two share within that many pixels. The threshold must
sit above what one pose gives twice and below what two poses a person captured give. On ``ghcal synth``'s
rendered views of ``example_rig()`` with the default board (``calibration.render.calibration_views``, as the
tests make them) this prints, per camera view, the largest corner distance (over the ids both images found)
between:

* the PNG and the same image re-saved as JPEG at quality 95, 85 and 75 (a re-saved image);
* the pose rendered twice with other sensor noise (a still board exposed twice, or a burst's two frames);
* the pose with the board moved 1, 2 and 5 mm along its own x (a nudge: still the same pose to the lens's fit);
* each view and the nearest other view of the capture (distinct poses).

and how many ids the two images of one pose did not share. A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.counts import non_negative_count, positive_count, seed_list  # noqa: E402
from calibration.board import BoardSpec  # noqa: E402
from calibration.detect import BoardDetector, BoardView  # noqa: E402
from calibration.render import board_poses_both_see, calibration_views, example_rig, render_board  # noqa: E402
from calibration.solve import corner_gaps  # noqa: E402


def _largest_px(a: BoardView, b: BoardView) -> tuple[float, int]:
    """The largest distance over the ids both found (``same_pose``'s measure), and how many ids only one of them
    found."""
    gaps = corner_gaps(a, b)
    largest = float(gaps.max()) if gaps.size else float("inf")
    return largest, len(a) + len(b) - 2 * gaps.size


def _resaved(image: np.ndarray, quality: int) -> np.ndarray:
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    return cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)


def _same_pose_rows(rig, board: BoardSpec, detector: BoardDetector, count: int, seed: int) -> dict[str, list]:
    rows: dict[str, list] = {"noise": [], "jpeg95": [], "jpeg85": [], "jpeg75": [], "move1mm": [], "move2mm": [],
                             "move5mm": []}
    for k, (R, t) in enumerate(board_poses_both_see(rig, board, count, seed).values()):
        for cam in rig.pair:
            image = render_board(cam, board, R, t, seed=1000 * seed + 2 * k)
            view = detector.detect(image)
            if view is None:
                continue
            again = detector.detect(render_board(cam, board, R, t, seed=1000 * seed + 2 * k + 1))
            if again is not None:
                rows["noise"].append(_largest_px(view, again))
            for quality in (95, 85, 75):
                if (resaved := detector.detect(_resaved(image, quality))) is not None:
                    rows[f"jpeg{quality}"].append(_largest_px(view, resaved))
            for mm in (1, 2, 5):
                moved = detector.detect(render_board(cam, board, R, t + R[:, 0] * mm / 1000, seed=1000 * seed + 2 * k))
                if moved is not None:
                    rows[f"move{mm}mm"].append(_largest_px(view, moved))
    return rows


def _nearest_other_px(views: dict[str, BoardView]) -> list[float]:
    names = sorted(views)
    nearest = []
    for name in names:
        gaps = [_largest_px(views[name], views[other])[0] for other in names if other != name]
        nearest.append(min(gaps))
    return nearest


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=seed_list, default="0,1,2")
    ap.add_argument("--count", type=positive_count, default=15)
    ap.add_argument("--edge-count", type=positive_count, default=6)
    ap.add_argument("--same-pose", type=non_negative_count, default=6,
                    help="poses per seed rendered twice, re-saved and moved")
    args = ap.parse_args(argv)
    rig, board = example_rig(), BoardSpec()
    detector = BoardDetector(board)
    same: dict[str, list] = {}
    nearest: list[float] = []
    for seed in args.seeds:
        for key, rows in _same_pose_rows(rig, board, detector, args.same_pose, seed).items():
            same.setdefault(key, []).extend(rows)
        rendered = calibration_views(rig, board, count=args.count, edge_count=args.edge_count, seed=seed)
        for cam, images in rendered.items():
            found = {n: v for n, im in images.items() if n != "floor" and (v := detector.detect(im)) is not None}
            nearest.extend(_nearest_other_px(found))
    seeds = ",".join(map(str, args.seeds))
    print(f"largest corner distance between two images, px (seeds {seeds}, example_rig, default board):")
    for key, rows in same.items():
        gaps = np.array([g for g, _ in rows])
        unshared = np.array([u for _, u in rows])
        print(f"  one pose, {key:8s}: {len(rows):3d} views, median {np.median(gaps):.3f}, 90th pct "
              f"{np.percentile(gaps, 90):.3f}, max {gaps.max():.3f}; ids found in one image only: median "
              f"{np.median(unshared):.0f}, max {unshared.max()} (of {len(board.corners_m())})")
    near = np.array(nearest)
    print(f"  distinct poses, nearest other view: {near.size} views, min {near.min():.1f}, 10th pct "
          f"{np.percentile(near, 10):.1f}, median {np.median(near):.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
