"""What the frame check costs per camera crop: a scene, a scene under heavy sensor noise, and garbage.

    .venv/bin/python benchmarks/time_frame_check.py [--size 128] [--repeats 2000] [--rounds 5]

Times ``ghnerf_runtime.estimator.check_crop`` on a model-input plane of ``--size`` pixels a side (half of it
padding, as a crop reaching past the frame's edge has, with ``CropMaps.inside``) and, for comparison, the fine
statistics alone (``crop_statistics``, all the check asked before session 65). A scene passes on its fine detail
share; a noisy scene and garbage exceed it, so the check also measures their 2x2 block means
(``coarse_detail_share``). Prints the median over ``--rounds`` rounds of the microseconds per call. Not a test.
"""
from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from ghnerf_runtime.config import FrameCheckConfig  # noqa: E402
from ghnerf_runtime.estimator import check_crop, crop_statistics  # noqa: E402


def planes(size: int) -> dict[str, np.ndarray]:
    """A smooth scene, the same under per-pixel noise of 38 levels, and uniform noise (values 0-1)."""
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[:size, :size]
    scene = 0.5 + 0.3 * np.sin(xx / 9.0) * np.cos(yy / 13.0)
    return {"scene": scene.astype(np.float32),
            "noisy scene": (scene + rng.normal(0.0, 0.15, scene.shape)).astype(np.float32),
            "uniform noise": rng.random(scene.shape).astype(np.float32)}


def microseconds(call: Callable[[], object], repeats: int, rounds: int) -> float:
    per_round = []
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(repeats):
            call()
        per_round.append((time.perf_counter() - start) / repeats * 1e6)
    return float(np.median(per_round))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=positive_count, default=128)
    ap.add_argument("--repeats", type=positive_count, default=2000)
    ap.add_argument("--rounds", type=positive_count, default=5)
    args = ap.parse_args(argv)
    cfg = FrameCheckConfig()
    inside = np.zeros((args.size, args.size), bool)
    inside[:, args.size // 2:] = True
    print(f"{'plane':>14}  verdict   check_crop us   crop_statistics us   (median of {args.rounds} rounds)")
    for name, plane in planes(args.size).items():
        plane = np.where(inside, plane, 0.0).astype(np.float32)
        verdict = check_crop(plane, 255.0, cfg, inside)[1] or "ok"
        check = microseconds(lambda: check_crop(plane, 255.0, cfg, inside), args.repeats, args.rounds)
        fine = microseconds(lambda: crop_statistics(plane, 255.0, inside), args.repeats, args.rounds)
        print(f"{name:>14}  {verdict:>7}   {check:13.1f}   {fine:18.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
