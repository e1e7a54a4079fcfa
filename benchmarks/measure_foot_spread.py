"""How far the floor check's foot joints lie from the person's own body, on the true rig.

    .venv/bin/python benchmarks/measure_foot_spread.py [--model-dir models] [--sequences 10] [--frames 30]

The floor check (``PairResult.lowest_foot_m``) takes its feet before the working volume's box gates since session 56
and keeps those within ``estimator._FLOOR_BODY_M`` across the floor (x, z) of the median of the person's
triangulated joints instead (``joints3d.near_the_body``; docs/calibration.md, "A camera panned far"). This films the
bench's held-out-like sequences (``measure_calibration_drift``'s) through the true rig and prints, for every foot joint
of each pass's triangulation (before any gate but the reprojection gate), its distance from that median: over those
the box gates keep (a person's own feet) and, one by one, over those they drop (mostly a foot paired with a wrong
peak). A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from ghnerf_runtime.body25 import FLOOR_JOINTS  # noqa: E402
from ghnerf_runtime.cli.simdata import SEQUENCE_CACHE_HELP, load_sequences  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import _FLOOR_BODY_M, Estimator, load_session  # noqa: E402
from ghnerf_runtime.joints3d import Joints3D  # noqa: E402


class _Measured(Estimator):
    """The estimator, recording each pass's first box gating (the triangulation's, in ``_joints_3d``): every foot
    joint's distance across the floor from the median of the valid joints, and whether the boxes kept it."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.kept: list[float] = []
        self.dropped: list[float] = []
        self._first = True

    def _joints_3d(self, *args, **kwargs):
        self._first = True  # the gating that follows is the triangulation's
        return super()._joints_3d(*args, **kwargs)

    def _gate_to_boxes(self, j3: Joints3D, regions) -> Joints3D:
        out = super()._gate_to_boxes(j3, regions)
        if self._first and j3.valid.any():
            self._first = False
            centre = np.median(j3.points[j3.valid][:, [0, 2]], axis=0)
            far = np.linalg.norm(j3.points[:, [0, 2]] - centre, axis=-1)
            for j in FLOOR_JOINTS:
                if j3.valid[j]:
                    (self.kept if out.valid[j] else self.dropped).append(float(far[j]))
        return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--sequences", type=positive_count, default=10)
    ap.add_argument("--frames", type=positive_count, default=30)
    ap.add_argument("--cache", help=SEQUENCE_CACHE_HELP)
    args = ap.parse_args(argv)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir))
    session = load_session(cfg)
    kept: list[float] = []
    dropped: list[float] = []
    for seq in load_sequences(args.sequences, args.frames, cache_dir=args.cache):
        t0, fps = float(seq.info["t0"]), float(seq.info["fps"])
        with _Measured(session, seq.rig, cfg) as est:
            for i in range(len(seq)):
                est.estimate([np.array(seq.images[i, 0]), np.array(seq.images[i, 1])], timestamp_s=t0 + i / fps)
            kept += est.kept
            dropped += est.dropped
    k = np.asarray(kept, float)
    print(f"{args.sequences} held-out-like sequences x {args.frames} pairs, {args.model_dir}, the true rig: foot "
          f"joints' distance across the floor from the median of the person's triangulated joints (m; the floor check keeps "
          f"those within {_FLOOR_BODY_M:g}):")
    if k.size:
        print(f"  kept by the box gates: {k.size}, median {np.median(k):.2f}, p99 {np.percentile(k, 99):.2f}, "
              f"max {k.max():.2f}")
    print(f"  dropped by the box gates: {len(dropped)}: {', '.join(f'{d:.2f}' for d in sorted(dropped)) or 'none'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
