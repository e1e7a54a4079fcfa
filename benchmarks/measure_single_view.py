"""2D joints of one camera when the other's frame is unusable (``frame_check.single_view_2d``).

    .venv/bin/python benchmarks/measure_single_view.py [--model-dir models] [--sequences 10] [--rooms 16]
                                                       [--bad black|saturated|noise] [--no-flip-test]
                                                       [--no-view-track]

A pair whose one crop fails the frame check (a covered lens, a camera blinded by the sun, a broken
stream) has no 3D joints, but the other camera's 2D joints still come from the encoder heatmaps.
This scores them on the held-out-like bench sequences (``ghnerf-bench runtime``'s): every pair is
run three times, as it is, and with each camera's frame replaced by a bad one in turn; it prints
PCK@0.2 and the share of visible joints found for the good camera, beside the same camera's
figures in the normal two-view run, with the pairs per second of each. First it counts the cold
(working-volume) crops of the sequences' rigs that reach past the frame's edge, and how many of them
would pass an all-255 frame if the frame check also looked at the zero padding. Then the false alarms:
empty simulated rooms with one camera bad, and how many of them report a person (the presence gate
on the good view's own peaks). The rooms are textured rooms with nobody in them
(``benchmarks/empty_rooms.py``), whose good view passes the frame check and goes to the model; until
session 65 they were black frames, which the frame check rejected too, so no view reached the model.
Each run keeps its own estimator, so single-view pairs start cold, as on the device. A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from benchmarks.empty_rooms import empty_room_pair  # noqa: E402
from ghnerf_runtime.cli.simdata import load_sequences  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, HeatmapsConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, check_crop, load_session  # noqa: E402
from ghnerf_runtime.metrics import pck  # noqa: E402
from ghnerf_runtime.preprocess import build_undistort_crop_maps, preprocess_image  # noqa: E402


def bad_frame(kind: str, shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    if kind == "black":
        return np.zeros(shape, np.uint8)
    if kind == "saturated":
        return np.full(shape, 255, np.uint8)
    return rng.integers(0, 256, shape, dtype=np.uint8)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--precision", default="int8", choices=("auto", "fp32", "int8"))
    ap.add_argument("--sequences", type=positive_count, default=10)
    ap.add_argument("--frames", type=positive_count, default=30)
    ap.add_argument("--rooms", type=non_negative_count, default=16,
                    help="empty rooms (scene seeds 1..N), each camera bad in turn")
    ap.add_argument("--bad", default="black", choices=("black", "saturated", "noise"))
    ap.add_argument("--flip-test", action=argparse.BooleanOptionalAction, default=None,
                    help="heatmaps.flip_test (default: the runtime's, on)")
    ap.add_argument("--no-view-track", action="store_true",
                    help="single-view pairs cropped from the working volume every time (tracking off in those runs)")
    args = ap.parse_args(argv)
    heatmaps = HeatmapsConfig() if args.flip_test is None else HeatmapsConfig(flip_test=args.flip_test)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir, precision=args.precision), heatmaps=heatmaps)
    session = load_session(cfg)
    rng = np.random.default_rng(0)
    runs = {"both": None, "camera 0 bad": 1, "camera 1 bad": 0}  # run -> the good camera scored (None: both)
    scored = {name: {c: ([], [], [], []) for c in (0, 1)} for name in runs}  # pred, true, visible, found
    seconds = {name: 0.0 for name in runs}
    pairs = 0
    sequences = load_sequences(args.sequences, args.frames)
    crops = past_edge = fooled = 0
    for seq in sequences:
        est = Estimator(session, seq.rig, cfg)
        cold = est.tracker.regions()
        for c, roi in enumerate(cold.rois):
            maps = build_undistort_crop_maps(seq.rig.pair[c], roi, session.contract.height)
            white = preprocess_image(np.full(seq.images.shape[2:], 255, np.uint8), maps, session.contract.normalisation)
            crops += 1
            past_edge += maps.inside is not None
            fooled += check_crop(white[1], est._levels, cfg.frame_check)[0]  # without CropMaps.inside
    print(f"cold crops: {past_edge} of {crops} reach past the frame's edge; {fooled} would pass an all-255 frame "
          f"if the frame check looked at the padding too")
    for seq in sequences:
        ests = {name: Estimator(session, seq.rig, cfg if good is None or not args.no_view_track else
                                replace(cfg, tracking=replace(cfg.tracking, enabled=False)))
                for name, good in runs.items()}
        for i in range(len(seq)):
            pairs += 1
            for name, good in runs.items():
                images = [np.array(seq.images[i, 0]), np.array(seq.images[i, 1])]
                if good is not None:
                    images[1 - good] = bad_frame(args.bad, images[1 - good].shape, rng)
                t = time.perf_counter()
                r = ests[name].estimate(images, sequence=i)
                seconds[name] += time.perf_counter() - t
                if good is not None and (r.frame_ok[ests[name].camera_names[1 - good]]
                                         or not r.missing.all()):
                    raise SystemExit(f"the bad frame ({args.bad}) passed the frame check or gave 3D joints")
                for c in ((0, 1) if good is None else (good,)):
                    cam = ests[name].camera_names[c]
                    for lst, value in zip(scored[name][c], (r.joints_2d[cam], seq.joints_2d[i, c],
                                                            seq.visible[i, c], ~r.missing_2d[cam])):
                        lst.append(value)
        for est in ests.values():
            est.close()
    print(f"{pairs} pairs of {args.sequences} held-out-like sequences, {args.precision}, the other camera's frame "
          f"{args.bad}{', flip test' if cfg.heatmaps.flip_test else ', no flip test'}:")
    for name, good in runs.items():
        for c in ((0, 1) if good is None else (good,)):
            p, t, v, f = (np.array(a) for a in scored[name][c])
            score = pck(p, t, v, pred_valid=f)
            found = float(f[v].mean())
            print(f"  {name:>12}: camera {c} PCK@0.2 {score.value:.3f}, visible joints found {found:.3f}")
        print(f"  {name:>12}: {pairs / seconds[name]:.1f} pairs/s")
    import drivers.sim as sim  # a tool: the runtime library never imports drivers

    rig = sim.RigPlacement().build()
    est = Estimator(session, rig, cfg)
    alarms = checked = 0  # checked: good views the frame check let through to the model
    for seed in range(1, args.rooms + 1):
        pair = empty_room_pair(rig, seed)
        for bad in (0, 1):
            images = list(pair)
            images[bad] = bad_frame(args.bad, images[bad].shape, rng)
            est.reset()
            r = est.estimate(images)
            alarms += int(not all(r.missing_2d[n].all() for n in r.missing_2d))
            checked += r.frame_ok[est.camera_names[1 - bad]]
    est.close()
    print(f"empty rooms with one camera {args.bad}: {alarms} of {2 * args.rooms} report a person "
          f"({checked} of {2 * args.rooms} good views passed the frame check)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
