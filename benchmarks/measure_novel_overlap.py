"""What rendering the novel view alongside the keypoint stages (``novel_view.overlap``) gains.

    .venv/bin/python benchmarks/measure_novel_overlap.py --model-dir models [--precisions int8,auto]

On held-out-like simulator sequences, every pair is estimated with a 128x128 novel view
(alpha 0.5) twice per precision: with the view rendered in the worker thread during the decode
and 3D stages (``overlap`` on, the default) and after them (off). The two variants alternate
sequence by sequence (and swap order each time), so drifting machine load hits both alike.
Prints, per precision and variant, pairs/s over the counted pairs and the median / p99 wall
time per pair, the ratio of the medians, and checks that the joints are the same bit for bit
(the overlap must change nothing but the time). With ``--repeats N`` the whole comparison runs
N times and the pairs/s of each repeat are listed too (this machine's speed drifts by 10-20 %
over minutes; the spread says how much one figure can be trusted). Not a test.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from ghnerf_runtime.cli.simdata import SEQUENCE_CACHE_HELP, load_sequences, percentiles  # noqa: E402
from ghnerf_runtime.config import (  # noqa: E402
    EstimatorConfig,
    HeatmapsConfig,
    NovelViewConfig,
    SessionConfig,
)
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.novel_view import NovelViewRequest  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--precisions", default="int8,auto")
    ap.add_argument("--sequences", type=positive_count, default=10)
    ap.add_argument("--frames", type=positive_count, default=30)
    ap.add_argument("--warmup", type=non_negative_count, default=2,
                    help="pairs of each sequence not counted (cold start)")
    ap.add_argument("--repeats", type=positive_count, default=1)
    ap.add_argument("--cache", help=SEQUENCE_CACHE_HELP)
    args = ap.parse_args(argv)
    sequences = load_sequences(args.sequences, args.frames, cache_dir=args.cache)
    print(f"load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs; {len(sequences)} sequences x "
          f"{args.frames} pairs, {args.warmup} not counted per sequence")
    request = NovelViewRequest(alpha=0.5)
    for precision in args.precisions.split(","):
        base = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir, precision=precision),
                               heatmaps=HeatmapsConfig(flip_test=False),  # as docs/runtime.md measured it
                               novel_view=NovelViewConfig(enabled=True))
        session = load_session(base)
        variants = {"overlap": base, "after": replace(base, novel_view=replace(base.novel_view, overlap=False))}
        wall = {k: [] for k in variants}
        rates = {k: [] for k in variants}
        joints = {k: [] for k in variants}
        for rep in range(args.repeats):
            rep_wall = {k: [] for k in variants}
            for k, seq in enumerate(sequences):
                order = list(variants) if (k + rep) % 2 == 0 else list(variants)[::-1]
                for name in order:
                    with Estimator(session, seq.rig, variants[name]) as est:
                        for i in range(len(seq)):
                            # in RAM, as a driver delivers: not the cache's page faults in the first variant's wall
                            pair = (np.array(seq.images[i, 0]), np.array(seq.images[i, 1]))
                            t = time.perf_counter()
                            r = est.estimate(pair, sequence=i, novel_view=request)
                            dt = 1e3 * (time.perf_counter() - t)
                            if i >= args.warmup:
                                rep_wall[name].append(dt)
                            if rep == 0:
                                joints[name].append(np.concatenate([r.joints_3d.ravel(), r.confidence]))
            for name in variants:
                wall[name] += rep_wall[name]
                rates[name].append(1e3 * len(rep_wall[name]) / np.sum(rep_wall[name]))
        same = all(np.array_equal(a, b) for a, b in zip(joints["overlap"], joints["after"]))
        print(f"{precision}: {len(wall['overlap'])} pairs per variant; joints identical: {same}")
        for name in variants:
            t = percentiles(wall[name])
            each = ", ".join(f"{v:.1f}" for v in rates[name])
            print(f"  {name:<8} {1e3 * len(wall[name]) / np.sum(wall[name]):5.1f} pairs/s (per repeat: {each})   "
                  f"wall per pair median {t['median']:5.2f} / p99 {t['p99']:5.2f} ms")
        print(f"  median ratio overlap / after: {np.median(wall['overlap']) / np.median(wall['after']):.3f}")
    print(f"load average at the end {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
