"""A camera bumped after calibration: how far the two views' peaks stay from meeting in 3D.

    .venv/bin/python benchmarks/measure_calibration_drift.py [--model-dir models] [--sequences 4] [--frames 10]
                                                             [--degrees 0.25,0.5,1,2] [--axes tilt,pan,roll]
                                                             [--window 10] [--max-floor-m 0.1] [--camera 1]
                                                             [--lift-m 0,0.01,0.02,0.03,0.04]

The simulator films the bench's held-out-like scenes (``ghnerf-bench runtime``'s recipe: held-out motions,
random rig placements) through the true rig; the estimator is given that rig with the second camera (``--camera
0``: the first) turned by each angle about one of its own axes (``tilt``: about its x axis, the picture moves up
or down; ``pan``: about its y axis, sideways, along the epipolar lines of a level rig; ``roll``: about its optical axis), as
a rig file that no longer fits a camera knocked on its mount. Per setting it prints, over the pairs that
were measured (``PairResult.reprojection_px_median`` not None), the per-pair median reprojection error
before the gate (model-input pixels): its median, 90th percentile and largest; the median over
``--window`` consecutive measured pairs of one sequence (what the daemon compares with
``health.calibration_max_px``) at its smallest and largest; 3D joints found per pair and the MPJPE of those.
A second table gives the floor check's figure: per pair with a triangulated foot
(``PairResult.lowest_foot_m``, the lower foot's height above the floor: the median of its ankle, heel and toes less
``joints3d.foot_standing_m``, by default ``config.FOOT_STANDING_M``, metres), its median, 10th
and 90th percentiles, and the median over ``--window`` consecutive such pairs of one sequence (what the daemon
compares with ``health.calibration_max_floor_m``) at its smallest, median and largest, the largest distance of that
median from the floor (either way), how many of those windows are short (a sequence with fewer pairs with a foot than
``--window``: one window of them all, which the daemon, waiting for a full window, would not judge), and the share
of those medians further than ``--max-floor-m`` from it (the windows the daemon would flag), next to the simulated people's own lower foot (the median height of its true
joints, which ``FOOT_STANDING_M`` stands for, and the lowest true foot joint).

``--lift-m`` (comma-separated metres) measures shoes' soles or a mat instead of a turned camera: each sequence is
rendered again with the person raised by each height above the floor (the posed body moved up rigidly, the rig, the
room and its floor as they were, the sensor noise the same: 0 is the cached sequence itself), through the true rig;
a row each, the turns not run. Its floor rows add the windows past each limit once ``joints3d.foot_standing_m`` is
set to the default plus the lift (what ``ghnerf-daemon --measure-floor`` has a user set; the figure less the lift).
Rendering costs about 0.25 s a pair on a 2-core machine (docs/calibration.md, "Shoes, mats: the standing foot").

A last line counts the crop turn searches (``Estimator.turn_searches``) over every row's pairs; ``--no-turn-search``
sets ``roi.turn_search`` off, to see whether the search moves the tables.
A tool, not a test.
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
from ghnerf_runtime.body25 import FEET, FLOOR_JOINTS  # noqa: E402
from ghnerf_runtime.cli.simdata import SEQUENCE_CACHE_HELP, load_sequences  # noqa: E402
from ghnerf_runtime.config import FOOT_STANDING_M, EstimatorConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from firmware_host.daemon.config import CALIBRATION_MAX_FLOOR_M  # noqa: E402
from ghnerf_runtime.geometry import Camera, Rig  # noqa: E402
from ghnerf_runtime.joints3d import Joints3D, lower_foot_m  # noqa: E402

#: Camera axis (in its own frame: x right, y down, z forward) each kind of bump turns about.
AXES = {"tilt": 0, "pan": 1, "roll": 2}


def turned(rig: Rig, camera: int, axis: str, degrees: float) -> Rig:
    """``rig`` with camera ``camera`` turned ``degrees`` about its own ``axis`` (``AXES``), its centre kept."""
    if degrees == 0:
        return rig
    a = np.radians(degrees)
    i, j = [k for k in range(3) if k != AXES[axis]]
    turn = np.eye(3)
    turn[i, i] = turn[j, j] = np.cos(a)
    turn[i, j], turn[j, i] = -np.sin(a), np.sin(a)
    cams = list(rig.cameras)
    c = cams[camera]
    cams[camera] = Camera(c.name, c.width, c.height, c.K, c.dist, turn @ c.R, turn @ c.t)
    return Rig(tuple(cams), rig.volume, rig.rig_id)


def lifted_images(seq, lift_m: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """The pairs of ``seq`` (a bench sequence) rendered again with its person raised ``lift_m`` metres (the rig frame
    is y down: y less the lift), the rig, room and sensor noise unchanged; 0 gives the cached pairs."""
    if lift_m == 0:
        return [(np.array(seq.images[i, 0]), np.array(seq.images[i, 1])) for i in range(len(seq))]
    from ghnerf_runtime.cli.simdata import bench_rig_and_scene
    from benchmarks.measure_lying_rendered import render_pair

    rig, scene, t0, _ = bench_rig_and_scene(int(seq.info["index"]))
    if rig.rig_id != seq.rig.rig_id or t0 != float(seq.info["t0"]):
        raise ValueError(f"sequence {seq.info['index']}: the bench's recipe no longer renders the cached sequence")
    up = np.array([0.0, -lift_m, 0.0])
    fps = float(seq.info["fps"])
    return [render_pair(scene, rig, scene.posed(t0 + i / fps).transformed(np.eye(3), up), t0 + i / fps)[0]
            for i in range(len(seq))]


def rolling_medians(values: list[float], window: int) -> list[float]:
    """The medians over every ``window`` consecutive values (over all of them when fewer)."""
    v = np.asarray(values, float)
    if v.size <= window:
        return [float(np.median(v))] if v.size else []
    return [float(np.median(v[k:k + window])) for k in range(v.size - window + 1)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--sequences", type=positive_count, default=4)
    ap.add_argument("--frames", type=positive_count, default=10)
    ap.add_argument("--degrees", default="0.25,0.5,1,2", help="comma-separated turns of the second camera")
    ap.add_argument("--axes", default="tilt,pan,roll", help=f"comma-separated, of {list(AXES)}")
    ap.add_argument("--window", type=positive_count, default=10, help="pairs of the rolling median")
    ap.add_argument("--max-floor-m", default=str(CALIBRATION_MAX_FLOOR_M),
                    help="the floor check's limit the windows are counted against (health.calibration_max_floor_m); "
                         "comma-separated: a column each")
    ap.add_argument("--camera", type=int, choices=(0, 1), default=1,
                    help="the camera whose rig entry is turned (rig order: 0 the first, 1 the second)")
    ap.add_argument("--cache", help=SEQUENCE_CACHE_HELP)
    ap.add_argument("--lift-m", help="comma-separated heights (m, 0 to 0.3) the person is raised above the floor "
                                     "(a sole, a mat), a row each through the true rig; the turns are not run")
    ap.add_argument("--no-turn-search", action="store_true",
                    help="roi.turn_search off (on by default for a model with encoder heatmaps); either way the "
                         "searches run are counted (docs/calibration.md, \"The crop turn search and these figures\")")
    args = ap.parse_args(argv)
    lifts = []
    if args.lift_m is not None:
        try:
            lifts = [float(v) for v in str(args.lift_m).split(",")]
        except ValueError:
            ap.error(f"--lift-m: {args.lift_m!r} is not a comma-separated list of metres")
        if any(not 0 <= v <= 0.3 for v in lifts):  # (a NaN fails too)
            ap.error(f"--lift-m: {args.lift_m!r}: each height must be a number of metres in [0, 0.3]")
    try:
        limits = [float(v) for v in str(args.max_floor_m).split(",")]
    except ValueError:
        ap.error(f"--max-floor-m: {args.max_floor_m!r} is not a comma-separated list of metres")
    if not limits or any(not np.isfinite(v) or v <= 0 for v in limits):
        ap.error(f"--max-floor-m: {args.max_floor_m!r}: each limit must be a positive number of metres")
    axes = args.axes.split(",")
    if unknown := [a for a in axes if a not in AXES]:
        ap.error(f"--axes: {unknown} not of {list(AXES)}")
    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir))
    if args.no_turn_search:
        cfg = replace(cfg, roi=replace(cfg.roi, turn_search=False))
    session = load_session(cfg)
    searching = cfg.roi.search_for(getattr(session.contract, "encoder_heatmaps", False)).turn_search
    searches = 0  # Estimator.turn_searches summed over every setting's estimators
    if lifts:
        settings = [("lifted", h) for h in lifts]
    else:
        settings = [("true rig", 0.0)] + [(a, float(d)) for a in axes for d in args.degrees.split(",")]
    tally = {s: {"px": [], "roll": [], "found": [], "err": [], "pairs": 0, "foot": [], "foot_roll": [], "short": 0}
             for s in settings}
    # the bench's sequences (ghnerf-bench runtime's recipe and cache), filmed by the true rig
    truth_foot = []  # the simulated people's own lowest foot joint (where they stand, whatever the estimate)
    truth_lower = []  # their lower foot's median joint height (what FOOT_STANDING_M stands for)
    for seq in load_sequences(args.sequences, args.frames, cache_dir=args.cache):
        truth_foot += list(-np.asarray(seq.joints_3d)[:, list(FLOOR_JOINTS), 1].max(axis=1))
        truth_lower += [lower_foot_m(Joints3D(j, np.ones(len(j)), np.ones(len(j), bool), np.zeros((len(j), 2))),
                                     FEET, 0.0) for j in np.asarray(seq.joints_3d)]
        t0, fps = float(seq.info["t0"]), float(seq.info["fps"])
        for axis, deg in settings:
            acc = tally[(axis, deg)]
            lift = deg if axis == "lifted" else 0.0
            pairs = lifted_images(seq, lift)
            truth = np.asarray(seq.joints_3d) - np.array([0.0, lift, 0.0])  # y down: raised is y less the lift
            rig = turned(seq.rig, args.camera, axis, deg) if axis in AXES else seq.rig
            with Estimator(session, rig, cfg) as est:
                seq_px, seq_foot = [], []
                for i in range(len(seq)):
                    r = est.estimate(list(pairs[i]), timestamp_s=t0 + i / fps)
                    acc["pairs"] += 1
                    ok = ~r.missing
                    acc["found"].append(int(ok.sum()))
                    acc["err"] += list(1000 * np.linalg.norm(r.joints_3d[ok] - truth[i][ok], axis=1))
                    if r.reprojection_px_median is not None:
                        seq_px.append(r.reprojection_px_median)
                    if r.lowest_foot_m is not None:
                        seq_foot.append(r.lowest_foot_m)
                searches += est.turn_searches
            acc["px"] += seq_px
            acc["roll"] += rolling_medians(seq_px, args.window)  # within a sequence: the daemon's window
            acc["foot"] += seq_foot
            acc["foot_roll"] += rolling_medians(seq_foot, args.window)
            acc["short"] += 0 < len(seq_foot) < args.window  # a window the daemon, waiting for a full one, never judges
    print(f"{args.sequences} held-out-like sequences x {args.frames} pairs, {args.model_dir}, "
          + ("the person raised above the floor, the true rig" if lifts else
             f"the {('first', 'second')[args.camera]} camera's rig entry turned")
          + f" (model-input px, {session.contract.height} px crops):")
    print(f"  {'setting':>14} | measured | per-pair median px: median   p90    max | rolling {args.window}: min    max | "
          f"3D joints | MPJPE mm")
    for (axis, deg), acc in tally.items():
        px = np.asarray(acc["px"], float)
        name = setting_name(axis, deg)
        stats = (f"{np.median(px):6.2f} {np.percentile(px, 90):6.2f} {px.max():6.2f}" if px.size
                 else f"{'-':>6} {'-':>6} {'-':>6}")
        roll = f"{min(acc['roll']):6.2f} {max(acc['roll']):6.2f}" if acc["roll"] else f"{'-':>6} {'-':>6}"
        mpjpe = f"{np.mean(acc['err']):6.1f}" if acc["err"] else f"{'-':>6}"
        print(f"  {name:>14} | {px.size:4d}/{acc['pairs']:<3d} | {' ' * 19}{stats} | {' ' * 4}{roll} | "
              f"{np.mean(acc['found']):5.1f}/25 | {mpjpe}")
    tf = np.asarray(truth_foot, float)
    tl = np.asarray(truth_lower, float)
    print(f"the lower triangulated foot's height above the floor (m; the floor is y = 0 of the rig frame; the median "
          f"of its joints less FOOT_STANDING_M {FOOT_STANDING_M:g}; of every pair, the true lower foot's median joint "
          f"height: median {np.median(tl):.3f}, p10 {np.percentile(tl, 10):.3f}, p90 {np.percentile(tl, 90):.3f}; "
          f"the true lowest foot joint: median {np.median(tf):.3f}, p10 {np.percentile(tf, 10):.3f}, "
          f"p90 {np.percentile(tf, 90):.3f}" + ("; a lifted row's truth is higher by its lift" if lifts else "") + "):")
    print(f"  {'setting':>14} | with a foot | per-pair: median    p10    p90 | rolling {args.window}: min median    max"
          f" | furthest from 0 | short | " + " | ".join(f"past {v:g} m" for v in limits)
          + "".join(f" | set {FOOT_STANDING_M:g}+lift: past {v:g} m" for v in limits if lifts))
    for (axis, deg), acc in tally.items():
        foot, roll = np.asarray(acc["foot"], float), np.asarray(acc["foot_roll"], float)
        stats = (f"{np.median(foot):7.3f} {np.percentile(foot, 10):6.3f} {np.percentile(foot, 90):6.3f}" if foot.size
                 else f"{'-':>7} {'-':>6} {'-':>6}")
        # joints3d.foot_standing_m raised by the lift moves every figure down by it (lower_foot_m subtracts it)
        fixed = roll - (deg if axis == "lifted" else 0.0)
        past = " | ".join(f"{int((np.abs(roll) > v).sum()):4d}/{roll.size:<4d}" for v in limits)
        past += "".join(f" | {' ' * 14}{int((np.abs(fixed) > v).sum()):4d}/{roll.size:<4d}" for v in limits if lifts)
        rolled = (f"{roll.min():6.3f} {np.median(roll):6.3f} {roll.max():6.3f} | {' ' * 9}{np.abs(roll).max():6.3f} | "
                  f"{acc['short']:5d} | {past}" if roll.size else f"{'-':>6} {'-':>6} {'-':>6} | {' ' * 9}{'-':>6} | "
                  f"{'-':>5} | "
                  + " | ".join(f"{'-':>9}" for _ in limits) + "".join(f" | {'-':>23}" for _ in limits if lifts))
        print(f"  {setting_name(axis, deg):>14} | {foot.size:5d}/{acc['pairs']:<5d} | {' ' * 9}{stats} | "
              f"{' ' * 4}{rolled}")
    pairs = sum(acc["pairs"] for acc in tally.values())
    print(f"roi.turn_search {'on' if searching else 'off'}: {searches} crop turn searches in the {pairs} pairs")
    return 0


def setting_name(kind: str, value: float) -> str:
    """A row's name: ``true rig``, ``pan 1 deg`` (a turn of ``--axes``) or ``lifted 0.02 m`` (``--lift-m``)."""
    if kind == "lifted":
        return f"lifted {value:g} m"
    return kind if not value else f"{kind} {value:g} deg"


if __name__ == "__main__":
    sys.exit(main())
