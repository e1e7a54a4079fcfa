"""Joints from scenes under heavy sensor noise: what a dim room at high gain gives once the frame check lets it in.

    .venv/bin/python benchmarks/measure_noisy_scenes.py [--model-dir models] [--sequences 10] [--frames 10]
                                                        [--rooms 16] [--kinds "bench frame,+ noise 40,..."]

Runs the held-out-like bench sequences (``ghnerf-bench runtime``'s) through the shipped model (int8, the runtime's
defaults) with both cameras' frames made into each scene kind of ``benchmarks/measure_frame_check.py`` (its
Gaussian noise and its sensor model of shot and read noise after a gain), twice: under the frame check's rule
(``frame_check.max_coarse_noise_ratio`` at its default) and under the fine detail share alone (the rule before
session 65, ``max_coarse_noise_ratio: 0``). Prints per kind and rule the share of camera frames rejected as noise,
PCK@0.2 of the 2D joints of both cameras (a joint not reported counts as wrong), the share of visible joints
reported, the MPJPE of the 3D joints reported (with the share of pairs that report any), and the false alarms: of
``--rooms`` empty textured rooms (``benchmarks/empty_rooms.py``) with both frames of the kind, how many report
a person (any 2D or 3D joint), and how many views passed the check. Each run keeps its own
estimator, so tracking runs as on the device; each kind's noise is drawn from one seeded generator per kind, the
same for both rules. A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from benchmarks.empty_rooms import empty_room_pair  # noqa: E402
from benchmarks.measure_frame_check import KINDS  # noqa: E402
from ghnerf_runtime.cli.simdata import load_sequences  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.frame_reasons import NOISE  # noqa: E402
from ghnerf_runtime.metrics import mpjpe, pck  # noqa: E402

DEFAULT_KINDS = ("bench frame", "+ noise 40", "+ noise 60", "dim x0.1 + noise 4", "dim x0.1 + noise 8",
                 "light x0.005 gain x200", "light x0.0025 gain x400")


def score(est: Estimator, seq, frame, rng: np.random.Generator) -> dict[str, float]:
    """Run one sequence with both frames made by ``frame``; the figures of :func:`main`'s table, summed."""
    names = est.camera_names
    pred, true, vis, found, p3, t3, f3 = [], [], [], [], [], [], []
    noise = pairs_3d = 0
    for i in range(len(seq)):
        r = est.estimate([frame(np.asarray(seq.images[i, c]), rng) for c in (0, 1)], sequence=i)
        noise += sum(r.frame_reason[n] == NOISE for n in names)
        pairs_3d += int(not r.missing.all())
        for c, n in enumerate(names):
            pred.append(r.joints_2d[n]), true.append(seq.joints_2d[i, c])
            vis.append(seq.visible[i, c]), found.append(~r.missing_2d[n])
        p3.append(r.joints_3d), t3.append(seq.joints_3d[i]), f3.append(~r.missing)
    vis_a, found_a = np.array(vis), np.array(found)
    p = pck(np.array(pred), np.array(true), vis_a, pred_valid=found_a)
    m = mpjpe(np.array(p3), np.array(t3), np.ones((len(t3), 25), bool), pred_valid=np.array(f3))
    return {"frames": 2 * len(seq), "noise": noise, "correct": p.num_correct, "evaluated": p.num_evaluated,
            "found": int((found_a & vis_a).sum()), "visible": int(vis_a.sum()), "pairs": len(seq),
            "pairs_3d": pairs_3d, "mm_sum": float(m.errors[m.evaluated].sum()), "mm_n": m.num_evaluated}


def false_alarms(est: Estimator, rooms: int, frame, rng: np.random.Generator) -> tuple[int, int]:
    """Of ``rooms`` empty rooms (scene seeds 1..N) with both frames made by ``frame``: how many report a person,
    and how many of their views passed the frame check."""
    alarms = passed = 0
    for seed in range(1, rooms + 1):
        est.reset()
        r = est.estimate([frame(im, rng) for im in empty_room_pair(est.rig, seed)])
        alarms += int(not r.missing.all() or not all(m.all() for m in r.missing_2d.values()))
        passed += sum(bool(ok) for ok in r.frame_ok.values())
    return alarms, passed


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--sequences", type=positive_count, default=10)
    ap.add_argument("--frames", type=positive_count, default=10)
    ap.add_argument("--rooms", type=non_negative_count, default=16)
    ap.add_argument("--kinds", default=",".join(DEFAULT_KINDS))
    args = ap.parse_args(argv)
    frames = {kind: frame for kind, _, frame in KINDS}
    kinds = [k.strip() for k in args.kinds.split(",")]
    unknown = [k for k in kinds if k not in frames]
    if unknown:
        ap.error(f"--kinds: unknown kind(s) {unknown}; known: {list(frames)}")
    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir, precision="int8"))
    rules = {"fine and coarse": cfg,
             "fine alone": replace(cfg, frame_check=replace(cfg.frame_check, max_coarse_noise_ratio=0.0))}
    session = load_session(cfg)
    sequences = load_sequences(args.sequences, args.frames)
    import drivers.sim as sim  # a tool: the runtime library never imports drivers

    room_rig = sim.RigPlacement().build()
    print(f"{args.sequences} held-out-like sequences x {args.frames} pairs, int8, both cameras' frames of each kind")
    print(f"{'kind':>24} {'rule':>16}  rejected as noise  PCK@0.2 (2D)  visible found  MPJPE mm (pairs with 3D)  "
          f"empty rooms reporting a person (views passed)")
    for kind in kinds:
        for rule, rule_cfg in rules.items():
            rng = np.random.default_rng(0)
            total: dict[str, float] = {}
            for seq in sequences:
                est = Estimator(session, seq.rig, rule_cfg)
                for key, value in score(est, seq, frames[kind], rng).items():
                    total[key] = total.get(key, 0) + value
                est.close()
            room_est = Estimator(session, room_rig, rule_cfg)
            alarms, passed = false_alarms(room_est, args.rooms, frames[kind], rng)
            room_est.close()
            mm = total["mm_sum"] / total["mm_n"] if total["mm_n"] else float("nan")
            print(f"{kind:>24} {rule:>16}  {total['noise'] / total['frames']:17.3f}  "
                  f"{total['correct'] / total['evaluated']:12.3f}  {total['found'] / total['visible']:13.3f}  "
                  f"{mm:8.1f} ({total['pairs_3d'] / total['pairs']:.2f})  "
                  f"{alarms:>3} of {args.rooms} ({passed} of {2 * args.rooms})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
