"""One still pair, no track: the cold crop's estimate, and the same pair run again on what it found.

    .venv/bin/python benchmarks/measure_still_pairs.py [--model-dir models] [--sequences 30] [--every 10]

``ghnerf-run --images`` estimates a single pair, which has no previous pair to place its crop: the crop
and the plane sweep span the whole working volume, coarser than the subject box the model was trained
on. ``tracking.refine_cold_start`` runs such a pair again on the subject's crop and box. This takes
pairs of the bench's held-out-like sequences (``ghnerf-bench runtime``'s) one at a time, each as a
still pair (the estimator reset before it), and prints the MPJPE of the reported joints, the share
found and the time per pair, with the refinement off and on. A tool, not a test.
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
from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from ghnerf_runtime.cli.simdata import load_sequences  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--sequences", type=positive_count, default=30)
    ap.add_argument("--frames", type=positive_count, default=30)
    ap.add_argument("--every", type=positive_count, default=10, help="take every n-th pair of each sequence")
    args = ap.parse_args(argv)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir))
    session = load_session(cfg)
    rows = {False: ([], [], []), True: ([], [], [])}  # refine -> errors (mm), found, ms
    pairs = 0
    for seq in load_sequences(args.sequences, args.frames):
        ests = {r: Estimator(session, seq.rig, replace(cfg, tracking=replace(cfg.tracking, refine_cold_start=r)))
                for r in rows}
        for i in range(0, len(seq), args.every):
            pairs += 1
            images = [np.array(seq.images[i, 0]), np.array(seq.images[i, 1])]
            for refine, est in ests.items():
                est.reset()  # a still pair: no track
                t = time.perf_counter()
                r = est.estimate(images)
                rows[refine][2].append(1e3 * (time.perf_counter() - t))
                ok = ~r.missing
                rows[refine][0].extend(1000 * np.linalg.norm(r.joints_3d[ok] - seq.joints_3d[i][ok], axis=1))
                rows[refine][1].append(ok.mean())
        for est in ests.values():
            est.close()
    print(f"{pairs} still pairs of {args.sequences} held-out-like sequences (every {args.every}th pair), {args.model_dir}:")
    for refine, (err, found, ms) in rows.items():
        print(f"  refine_cold_start {'on ' if refine else 'off'}: MPJPE {np.mean(err):6.1f} mm (median "
              f"{np.median(err):5.1f}), joints found {np.mean(found):.3f}, {np.median(ms):5.1f} ms median per pair")
    return 0


if __name__ == "__main__":
    sys.exit(main())
