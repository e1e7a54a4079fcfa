"""What ``tracking.cold_tiles_below_share`` costs: per-pair time of cold pairs, with people and in empty rooms.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/measure_cold_tiles.py [--model-dir models] [--sequences 6]
        [--frames 10] [--rooms 6] [--pairs 5] --rigs docs/examples/rig.json,synth_rig.json

Per rig file, the runtime's defaults against the same with ``cold_tiles_below_share = 0`` (no tiles), the two
interleaved pair by pair, each its own estimator: ``--sequences`` of the bench's held-out people drawn in the rig's
volume (as ``benchmarks/measure_baseline.py --rigs`` films them, ``--frames`` pairs each, one estimator per sequence)
and ``--rooms`` empty rooms (``benchmarks/empty_rooms.py``, the rig's view of a scene's room with nobody in it,
``--pairs`` pairs each, every one cold). It prints the median ms of the people's cold pairs (those that began without
a track: the first of each sequence, and every one after a pair that found nobody), how many there were, the mean ms
per pair over all the people's pairs, the share of pairs with no joint, the empty rooms' median ms per pair and
their pairs that reported a joint (a phantom), the ratios of the two configs and the passes through a tile. A tool,
not a test.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.empty_rooms import empty_room_pair  # noqa: E402
from benchmarks.measure_baseline import bench_scene_in  # noqa: E402
from ghnerf_runtime.cli.simdata import SEED_BASE  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, SessionConfig, TrackingConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.rig_file import load_rig  # noqa: E402


def timed(est: Estimator, images) -> tuple[float, bool, bool]:
    """(ms, whether the pair began without a track, whether it found no joint) of one pair."""
    cold = est.tracker.track is None
    t = time.perf_counter()
    result = est.estimate(images)
    return 1e3 * (time.perf_counter() - t), cold, bool(result.missing.all())


def people_pairs(rig, k: int, frames: int):
    """Bench sequence ``k``'s person drawn in ``rig``'s volume, ``frames`` pairs at 30 fps (measure_baseline's)."""
    scene, t0 = bench_scene_in(rig, k)
    return [[scene.render(cam, t0 + i / 30.0, with_truth=False)[0] for cam in rig.pair] for i in range(frames)]


def measure(session, configs: dict, rig, streams) -> dict:
    """Per config: (cold pairs' ms, empty or not-empty marks, tile passes); ``streams`` is a list of pair lists, each
    run by one fresh estimator per config, the configs interleaved pair by pair."""
    out = {name: {"ms": [], "cold_ms": [], "no_joint": [], "tiles": 0} for name in configs}
    for pairs in streams:
        ests = {name: Estimator(session, rig, cfg) for name, cfg in configs.items()}
        for images in pairs:
            for name, est in ests.items():
                ms, cold, none = timed(est, images)
                out[name]["ms"].append(ms)
                out[name]["no_joint"].append(none)
                if cold:
                    out[name]["cold_ms"].append(ms)
        for name, est in ests.items():
            out[name]["tiles"] += est.cold_tile_passes
            est.close()
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", default="models")
    ap.add_argument("--precision", default="int8")
    ap.add_argument("--sequences", type=int, default=6)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--rooms", type=int, default=6)
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--rigs", default="docs/examples/rig.json", help="rig files, comma-separated")
    args = ap.parse_args(argv)
    base = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir, precision=args.precision))
    configs = {"tiles (default)": base,
               "no tiles": EstimatorConfig(session=base.session, tracking=TrackingConfig(cold_tiles_below_share=0.0))}
    session = load_session(base)
    print(f"{args.precision}; {args.sequences} people x {args.frames} pairs, {args.rooms} empty rooms x {args.pairs} "
          "pairs; median ms per pair, the configs interleaved")
    print("| rig file | config | people's cold pairs | their median ms | people's mean ms per pair | pairs with no "
          "joint | empty-room median ms | empty-room pairs with a joint | tile passes (people / rooms) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for path in [p for p in args.rigs.split(",") if p.strip()]:
        rig = load_rig(path, warn=False)
        people = measure(session, configs, rig, [people_pairs(rig, k, args.frames) for k in range(args.sequences)])
        rooms = measure(session, configs, rig,
                        [[empty_room_pair(rig, SEED_BASE + r, 0.2)] * args.pairs for r in range(args.rooms)])
        for name in configs:
            p, r = people[name], rooms[name]
            print(f"| {path} | {name} | {len(p['cold_ms'])} | {np.median(p['cold_ms']):.1f} | {np.mean(p['ms']):.1f} | "
                  f"{np.mean(p['no_joint']):.3f} | {np.median(r['ms']):.1f} | {len(r['ms']) - sum(r['no_joint'])} of "
                  f"{len(r['ms'])} | {p['tiles']} / {r['tiles']} |",
                  flush=True)
        on, off = (people[n] for n in configs), (rooms[n] for n in configs)
        (p_on, p_off), (r_on, r_off) = on, off
        print(f"| {path} | ratio | | {np.median(p_on['cold_ms']) / np.median(p_off['cold_ms']):.2f} | "
              f"{np.mean(p_on['ms']) / np.mean(p_off['ms']):.2f} | | "
              f"{np.median(r_on['ms']) / np.median(r_off['ms']):.2f} | | |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
