"""Median render time of the simulated scene: a 640x480 pair of the default rig, and single
small target views (128x128, 256x256) as the training dataset renders them.

Usage: ``.venv/bin/python benchmarks/bench_sim_render.py [--repeats 60] [--motion walk] [--no-truth]``

Each measurement renders a new scene time (so poses are never reused); "cached" views reuse a
camera (its rays and room background are cached), "fresh" views use a new camera every time.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script without installing

from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from drivers.errors import DriverError  # noqa: E402
from drivers.sim import RigPlacement, SceneConfig, SimScene  # noqa: E402
from drivers.sim.motions import MOTION_NAMES  # noqa: E402
from ghnerf_runtime.geometry import Camera, intrinsics_from_fov, look_at  # noqa: E402


def _median_ms(fn, repeats: int) -> tuple[float, float]:
    fn(-1)  # warm-up: caches, allocator
    times = []
    for i in range(repeats):
        start = time.perf_counter()
        fn(i)
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times)), 1e3 * float(np.min(times))


def _view(size: int, k: int) -> Camera:
    a = 0.7 * k
    eye = [2.5 * np.sin(a), -1.0 - 0.3 * np.cos(1.3 * k), 3.0 - 2.5 * np.cos(a)]
    R, t = look_at(eye, [0.0, -0.9, 3.0])
    return Camera(f"target{k}", size, size, intrinsics_from_fov(size, size, 45.0), np.zeros(5), R, t)


def motion_option(text: str) -> str:
    """An argparse ``type=`` for ``--motion``: a procedural motion's name, or a ``.bvh`` file the scene loads
    (``--motion nope`` was the scene config's SimConfigError traceback)."""
    if not text.lower().endswith(".bvh"):
        if text not in MOTION_NAMES:
            raise argparse.ArgumentTypeError(f"unknown motion {text!r}: one of {', '.join(MOTION_NAMES)}, "
                                             "or a .bvh file")
        return text
    try:  # the file is read once more for the run: a small text file, and parsing stays free of state
        SimScene(SceneConfig(seed=1, motion=text))
    except DriverError as e:  # no such file, a malformed clip: the message names the file (and line)
        raise argparse.ArgumentTypeError(str(e)) from None
    return text


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=positive_count, default=60)
    parser.add_argument("--motion", type=motion_option, default="walk",
                        help=f"one of {', '.join(MOTION_NAMES)}, or a .bvh file (default walk)")
    parser.add_argument("--no-truth", action="store_true", help="render images only")
    args = parser.parse_args()
    truth = not args.no_truth
    rig = RigPlacement().build()
    scene = SimScene(SceneConfig(seed=1, motion=args.motion))
    dt = 1.0 / 30.0
    rows = [("pair 2x640x480 (default rig)", lambda i: scene.render_batch(rig.pair, 10 + i * dt, with_truth=truth))]
    rows.append(("single 640x480", lambda i: scene.render(rig.cameras[0], 10 + i * dt, with_truth=truth)))
    for size in (128, 256):
        cam = _view(size, 0)
        rows.append((f"single {size}x{size}, cached camera", lambda i, c=cam: scene.render(c, 10 + i * dt, with_truth=truth)))
        rows.append((f"single {size}x{size}, fresh camera", lambda i, s=size: scene.render(_view(s, i + 2), 10 + i * dt, with_truth=truth)))
    print(f"motion={args.motion} truth={truth} repeats={args.repeats}")
    print(f"{'case':42s} {'median ms':>10s} {'min ms':>8s}")
    for name, fn in rows:
        med, best = _median_ms(fn, args.repeats)
        print(f"{name:42s} {med:10.2f} {best:8.2f}")


if __name__ == "__main__":
    main()
