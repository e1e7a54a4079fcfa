"""The two cameras' inputs exchanged on a symmetric rig: what the runtime reports, and how soon the daemon's checks say so.

    PYTHONPATH=$PWD /work/main/.venv/bin/python benchmarks/measure_exchanged_cameras.py [--model-dir models]
                                                                   [--sequences 10] [--frames 30] [--window 30]

The simulator films the bench's held-out-like scenes (``ghnerf-bench runtime``'s recipe and cache: held-out motions,
random rig placements, every rig symmetric about its centre plane, both cameras aimed at one point). Each sequence is
estimated twice with the daemon's default estimator settings: as filmed, and with the two frames of every pair
exchanged (the left camera's fed as the right's). Per setting it prints the 3D joints found, the MPJPE, the per-pair
handedness (``PairResult.handedness``: +1 a person, -1 a mirror image; the pairs that have one), the medians over
``--window`` consecutive figures of one sequence, and per sequence the daemon's three calibration checks run over its
pairs (:mod:`firmware_host.daemon.calibration_watch`, the daemon's limits, a ``--window`` window each): the
sequences each flagged, and for the handedness check the pairs read until it did. Only sequences with a full window
of handedness figures are judged (the daemon waits for a full window). A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from firmware_host.daemon.calibration_watch import CalibrationWatch, FloorWatch, HandednessWatch  # noqa: E402
from firmware_host.daemon.config import CALIBRATION_MAX_FLOOR_M, CALIBRATION_MAX_MIRROR, CALIBRATION_MAX_PX  # noqa: E402
from ghnerf_runtime.cli.simdata import load_sequences  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402

SETTINGS = ("as filmed", "exchanged")


def watches(w: int) -> dict:
    """The daemon's three checks, each over ``w`` figures."""
    return {"px": CalibrationWatch(w, CALIBRATION_MAX_PX), "floor": FloorWatch(w, CALIBRATION_MAX_FLOOR_M),
            "hand": HandednessWatch(w, CALIBRATION_MAX_MIRROR)}


def run_sequence(est: Estimator, seq, exchanged: bool) -> list:
    """Each pair's result, the frames exchanged or not."""
    t0, fps = float(seq.info["t0"]), float(seq.info["fps"])
    out = []
    for i in range(len(seq)):
        left, right = np.array(seq.images[i, 0]), np.array(seq.images[i, 1])
        out.append(est.estimate([right, left] if exchanged else [left, right], timestamp_s=t0 + i / fps))
    return out


def judge(results: list, window: int) -> dict:
    """The three checks over one sequence's results: which flagged, and the pair the handedness check flagged at."""
    hands = [r.handedness for r in results if r.handedness is not None]
    checks = watches(window)
    flagged_at = None
    for n, r in enumerate(results, 1):
        checks["px"].add(r.reprojection_px_median)
        checks["floor"].add(r.lowest_foot_m)
        if checks["hand"].add(r.handedness) and flagged_at is None:
            flagged_at = n
    return {"hands": hands, "flagged_at": flagged_at,
            "ever": {k: c.suspect or (k == "hand" and flagged_at is not None) for k, c in checks.items()}}


def rolling_medians(values: list, window: int) -> list:
    v = np.asarray(values, float)
    if v.size <= window:
        return [float(np.median(v))] if v.size else []
    return [float(np.median(v[k:k + window])) for k in range(v.size - window + 1)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", default="models")
    ap.add_argument("--sequences", type=int, default=10)
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--window", type=int, default=30, help="figures per window (health.calibration_window)")
    ap.add_argument("--per-sequence", action="store_true", help="also a line per sequence: its handedness figures' "
                                                               "median as filmed and exchanged")
    ap.add_argument("--cache", help="sequence cache folder (default ~/.cache/ghnerf-bench)")
    args = ap.parse_args(argv)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir))
    session = load_session(cfg)
    tally = {s: {"found": [], "err": [], "hands": [], "rolled": [], "pairs": 0, "judged": 0, "flags": [],
                 "flagged_at": []} for s in SETTINGS}
    for seq in load_sequences(args.sequences, args.frames, cache_dir=args.cache):
        line = (f"  sequence {seq.info['index']:3d} ({seq.info['motion']}, {seq.info['distance_m']:.2f} m away, "
                f"baseline {seq.info['baseline_m']:.2f} m):")
        for setting in SETTINGS:
            acc = tally[setting]
            with Estimator(session, seq.rig, cfg) as est:
                results = run_sequence(est, seq, setting == "exchanged")
            for i, r in enumerate(results):
                ok = ~r.missing
                acc["found"].append(int(ok.sum()))
                acc["err"] += list(1000 * np.linalg.norm(r.joints_3d[ok] - seq.joints_3d[i][ok], axis=1))
            acc["pairs"] += len(results)
            verdict = judge(results, args.window)
            h = verdict["hands"]
            line += f" {setting} {len(h):3d} figures, median " + (f"{np.median(h):5.2f}" if h else "    -") + ";"
            acc["hands"] += verdict["hands"]
            acc["rolled"] += rolling_medians(verdict["hands"], args.window)
            if len(verdict["hands"]) >= args.window:  # the daemon judges full windows only
                acc["judged"] += 1
                acc["flags"].append(verdict["ever"])
                if verdict["flagged_at"] is not None:
                    acc["flagged_at"].append(verdict["flagged_at"])
        if args.per_sequence:
            print(line)
    print(f"{args.sequences} held-out-like sequences x {args.frames} pairs, {args.model_dir}, windows of {args.window} "
          f"figures (handedness: +1 a person, -1 a mirror image; limit -{CALIBRATION_MAX_MIRROR:g}):")
    print(f"  {'setting':>9} | 3D joints | MPJPE mm | pairs with a figure | per pair: median   p10   p90 | windows: "
          f"min   max | sequences judged | flagged by px / floor / handedness | pairs to flag: median max")
    for setting, acc in tally.items():
        h, roll = np.asarray(acc["hands"], float), np.asarray(acc["rolled"], float)
        per = f"{np.median(h):6.2f} {np.percentile(h, 10):5.2f} {np.percentile(h, 90):5.2f}" if h.size else "     -"
        rolled = f"{roll.min():5.2f} {roll.max():5.2f}" if roll.size else "    -     -"
        counts = " / ".join(str(sum(f[k] for f in acc["flags"])) for k in ("px", "floor", "hand"))
        at = acc["flagged_at"]
        when = f"{np.median(at):5.0f} {max(at):4d}" if at else "    -    -"
        mpjpe = f"{np.mean(acc['err']):8.1f}" if acc["err"] else f"{'-':>8}"
        print(f"  {setting:>9} | {np.mean(acc['found']):5.1f}/25 | {mpjpe} | {h.size:5d}/{acc['pairs']:<5d}"
              f"       | {' ' * 9}{per} | {' ' * 5}{rolled} | {acc['judged']:8d}/{args.sequences:<7d} | "
              f"{counts:>34} | {' ' * 9}{when}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
