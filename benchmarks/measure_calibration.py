"""How close ``ghcal`` gets to the rig it filmed: rendered calibration captures, solved, compared with the truth.

    .venv/bin/python benchmarks/measure_calibration.py [--seeds 0,1,2,3,4] [--count 15] [--edge-count 6]

For each seed, ``calibration.render.calibration_views`` renders the views a careful user takes of
``example_rig()`` (two 960x600 cameras, 75 degrees, a mild barrel lens, 0.6 m apart at 1.4 m) with
the default board (9x6 squares of 80 mm): ``count`` views both cameras see, ``edge_count`` per
camera in its image corners, one of the board on the floor. ``ghcal``'s solver runs on what the
detector found, levelled by the floor view and, for comparison, by the true height and tilt typed
in. Printed per seed and as medians: focal length and principal point error, camera centre and
orientation error after levelling, baseline error, reprojection errors. A tool, not a test.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.counts import positive_count, seed_list  # noqa: E402
from calibration.board import BoardSpec  # noqa: E402
from calibration.detect import BoardDetector  # noqa: E402
from calibration.render import calibration_views, example_rig  # noqa: E402
from calibration.solve import solve_rig  # noqa: E402


def _angle_deg(R: np.ndarray) -> float:
    return math.degrees(math.acos(float(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))


def _errors(solved, truth) -> dict[str, float]:
    out = {"focal_pct": 0.0, "principal_px": 0.0, "centre_mm": 0.0, "rotation_deg": 0.0}
    for cam in truth.pair:
        est = solved.camera(cam.name)
        out["focal_pct"] = max(out["focal_pct"], 100 * abs(est.K[0, 0] / cam.K[0, 0] - 1))
        out["principal_px"] = max(out["principal_px"], float(np.max(np.abs(est.K[:2, 2] - cam.K[:2, 2]))))
        out["centre_mm"] = max(out["centre_mm"], 1000 * float(np.linalg.norm(est.center - cam.center)))
        out["rotation_deg"] = max(out["rotation_deg"], _angle_deg(est.R @ cam.R.T))
    out["baseline_mm"] = 1000 * abs(solved.baseline - truth.baseline)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=seed_list, default="0,1,2,3,4")
    ap.add_argument("--count", type=positive_count, default=15)
    ap.add_argument("--edge-count", type=positive_count, default=6)
    args = ap.parse_args()
    truth = example_rig()
    board = BoardSpec()
    detector = BoardDetector(board)
    left = truth.camera("left")
    true_pitch = math.degrees(math.asin(float(left.R[2] @ np.array([0.0, 1.0, 0.0]))))
    rows = {"floor view": [], "measured": []}
    print("seed  levelling   focal %  pp px  centre mm  rot deg  baseline mm  rms px (left/right/pair)")
    for seed in args.seeds:
        t0 = time.monotonic()
        images = calibration_views(truth, board, count=args.count, edge_count=args.edge_count, seed=seed)
        views = {cam: {n: v for n, im in per.items() if (v := detector.detect(im)) is not None}
                 for cam, per in images.items()}
        for kind, kw in (("floor view", {"floor_view": "floor"}),
                         ("measured", {"camera_height_m": float(-left.center[1]), "pitch_deg": true_pitch})):
            sol = solve_rig(board, views, ("left", "right"), **kw)
            err = _errors(sol.rig, truth)
            rows[kind].append(err)
            r = sol.report
            print(f"{seed:4d}  {kind:10s}  {err['focal_pct']:7.3f}  {err['principal_px']:5.2f}  {err['centre_mm']:9.1f}"
                  f"  {err['rotation_deg']:7.3f}  {err['baseline_mm']:11.2f}  {r['cameras']['left']['rms_px']:.3f}/"
                  f"{r['cameras']['right']['rms_px']:.3f}/{r['pair']['rms_px']:.3f}"
                  f"  ({r['levelling']['method']}; {len(views['left'])}+{len(views['right'])} views found, "
                  f"{time.monotonic() - t0:.0f} s)")
    for kind, errs in rows.items():
        med = {k: float(np.median([e[k] for e in errs])) for k in errs[0]}
        print(f"median over {len(errs)} seeds, levelled by {kind}: focal {med['focal_pct']:.3f} %, principal point "
              f"{med['principal_px']:.2f} px, camera centre {med['centre_mm']:.1f} mm, orientation "
              f"{med['rotation_deg']:.3f} deg, baseline {med['baseline_mm']:.2f} mm (worst camera of the two)")


if __name__ == "__main__":
    main()
