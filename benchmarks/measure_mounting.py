"""Cameras mounted rolled about their optical axis: on their side, upside down, or a little crooked.

    .venv/bin/python benchmarks/measure_mounting.py [--model-dir models] [--sequences 6] [--frames 15]
                                                    [--rolls 0,30,90,180]

The model was trained on upright views. ``roi.upright`` (on by default) rotates each camera's crop so
that the rig's down is the picture's down, so a camera on its side, upside down or crooked gives the
model an upright person. This renders the
bench's held-out-like scenes (``ghnerf-bench runtime``'s recipe: held-out motions, random rig
placements) through the same rig with both cameras rolled by each angle, runs the runtime with
``roi.upright`` on and off, and prints per roll: 3D joints found per pair, MPJPE of those, PCK@0.2 of
the 2D joints in each camera's own (rolled) pixels. A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from ghnerf_runtime.cli.simdata import HELD_OUT_BASELINE_M, HELD_OUT_MOTIONS, SEED_BASE  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, RoiConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.geometry import Camera, Rig  # noqa: E402
from ghnerf_runtime.metrics import pck  # noqa: E402


def rolled(rig: Rig, degrees: float) -> Rig:
    """``rig`` with each camera turned ``degrees`` about its optical axis (a quarter turn swaps the
    sensor's sides), the principal point at the image centre."""
    if degrees == 0:
        return rig
    a = np.radians(degrees)
    Rz = np.array([[np.cos(a), np.sin(a), 0.0], [-np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    cams = []
    for c in rig.cameras:
        W, H = (c.height, c.width) if round(degrees) % 180 == 90 else (c.width, c.height)
        K = np.array([[c.K[0, 0], 0.0, (W - 1) / 2], [0.0, c.K[1, 1], (H - 1) / 2], [0.0, 0.0, 1.0]])
        cams.append(Camera(c.name, W, H, K, c.dist, Rz @ c.R, Rz @ c.t))
    return Rig(tuple(cams), rig.volume, rig.rig_id)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--sequences", type=positive_count, default=6)
    ap.add_argument("--frames", type=positive_count, default=15)
    ap.add_argument("--rolls", default="0,30,90,180", help="comma-separated roll angles, degrees")
    args = ap.parse_args(argv)
    import drivers.sim as sim  # a tool: the runtime library never imports drivers

    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir))
    session = load_session(cfg)
    rolls = [float(r) for r in args.rolls.split(",")]
    runs = [(r, up) for r in rolls for up in ((True,) if r == 0 else (True, False))]
    tally = {run: {"found": [], "err": [], "p": [], "t": [], "v": [], "f": []} for run in runs}
    roll_of = {}
    for k in range(args.sequences):
        seed = SEED_BASE + k  # the bench's recipe (ghnerf_runtime.cli.simdata)
        rng = np.random.default_rng([seed, 7])
        base = sim.RigPlacement.random(rng, width=640, height=480)
        rig = replace(base, baseline_m=float(rng.uniform(*HELD_OUT_BASELINE_M))).build(rig_id=f"bench-{k}")
        scene = sim.random_scene(seed, volume=rig.volume, motions=HELD_OUT_MOTIONS)
        t0 = float(rng.uniform(0.0, scene.period_s))
        times = [t0 + i / 30.0 for i in range(args.frames)]
        for roll in rolls:
            mounted = rolled(rig, roll)
            shots = [[scene.render(c, t) for c in mounted.pair] for t in times]
            for up in (True,) if roll == 0 else (True, False):
                est = Estimator(session, mounted, replace(cfg, roi=RoiConfig(upright=up)))
                roll_of[(roll, up)] = [round(st.roll_deg, 1) + 0.0 for st in est._cams]
                acc = tally[(roll, up)]
                for t, pair in zip(times, shots):
                    r = est.estimate([image for image, _ in pair], timestamp_s=t)
                    ok = ~r.missing
                    acc["found"].append(int(ok.sum()))
                    acc["err"] += list(1000 * np.linalg.norm(r.joints_3d[ok] - scene.joints_3d(t)[ok], axis=1))
                    for cam, (_, truth) in zip(mounted.pair, pair):
                        acc["p"].append(r.joints_2d[cam.name])
                        acc["t"].append(truth.joints_2d)
                        acc["v"].append(truth.visible)
                        acc["f"].append(~r.missing_2d[cam.name])
                est.close()
    print(f"{args.sequences} held-out-like sequences x {args.frames} pairs, {args.model_dir}, both cameras rolled:")
    for (roll, up), acc in tally.items():
        score = pck(*(np.array(acc[n]) for n in "ptv"), pred_valid=np.array(acc["f"]))
        mpjpe = float(np.mean(acc["err"])) if acc["err"] else float("nan")
        print(f"  roll {roll:5.0f} deg, roi.upright {'on ' if up else 'off'} (crops rotated {roll_of[(roll, up)]}): "
              f"3D joints found {np.mean(acc['found']):4.1f} / 25 a pair, MPJPE {mpjpe:6.1f} mm, "
              f"2D PCK@0.2 {score.value:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
