"""Median time per call of the triangulation solvers, at the estimator's size (25 joints, one frame).

    .venv/bin/python benchmarks/time_triangulation.py [--calls 2000] [--rounds 5]

``two_views`` is what ``joints3d.triangulate_joints`` calls every pair (two crop cameras, projection
matrices), every term computed on the spot; ``two_views, crop terms kept`` the same with the crop cameras'
``TwoViewCameras`` computed once (the estimator keeps them while its crops keep their cameras), and ``two_views,
the solve checked again`` the skeleton prior's inputs' use of the pair's solve of the same peaks (``check_two_views``
with another ray-angle threshold: the DLT not run again); ``dlt`` and ``midpoint`` are the general solvers with
two and three ``Camera`` objects, and ``robust`` the three-view one with one wrong view to drop. Each row is the
median over ``--rounds`` of the mean per call over ``--calls`` calls, in microseconds; one host, whatever else
runs on it. To compare two versions of ``ghnerf_runtime``, run this file from each checkout (it imports the package
it sits beside).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from ghnerf_runtime.geometry.camera import Camera, look_at  # noqa: E402
from ghnerf_runtime.geometry.triangulation import (  # noqa: E402
    TwoViewCameras,
    check_two_views,
    solve_two_views,
    triangulate_dlt,
    triangulate_midpoint,
    triangulate_robust,
    triangulate_two_views,
)

K = np.array([[150.0, 0.0, 63.5], [0.0, 150.0, 63.5], [0.0, 0.0, 1.0]])  # a 128 px crop camera


def scene(num_cameras: int, seed: int = 0):
    """Cameras on a 1 m arc looking at 25 joints of a standing person 3 m away, and their noisy peaks."""
    rng = np.random.default_rng(seed)
    cams = [Camera(f"c{i}", 128, 128, K, [], *look_at((x, -1.2, 0.0), (0.0, -1.0, 3.0)))
            for i, x in enumerate(np.linspace(-0.5, 0.5, num_cameras))]
    points = np.column_stack([rng.uniform(-0.3, 0.3, 25), rng.uniform(-1.7, -0.2, 25), rng.uniform(2.8, 3.2, 25)])
    uv = np.stack([c.project(points)[0] for c in cams]) + rng.normal(0.0, 0.5, (num_cameras, 25, 2))
    conf = rng.uniform(0.3, 1.0, (num_cameras, 25))
    return cams, uv, conf


def time_call(fn, calls: int, rounds: int) -> float:
    """Median over ``rounds`` of the mean seconds per call of ``fn()`` over ``calls`` calls."""
    fn()  # warm-up (imports, caches)
    means = []
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(calls):
            fn()
        means.append((time.perf_counter() - start) / calls)
    return float(np.median(means))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=positive_count, default=2000, help="calls per round (default 2000)")
    parser.add_argument("--rounds", type=positive_count, default=5, help="rounds; the median is printed (default 5)")
    args = parser.parse_args(argv)
    if args.calls < 1 or args.rounds < 1:
        parser.error(f"--calls and --rounds must be at least 1, got {args.calls} and {args.rounds}")

    two, uv2, conf2 = scene(2)
    three, uv3, conf3 = scene(3)
    bad3 = uv3.copy()
    bad3[1, ::3] += 30.0  # every third joint wrong in the middle view: the robust solver drops it
    P2 = np.stack([c.P for c in two])

    terms = TwoViewCameras.from_P(P2)
    solution = solve_two_views(uv2, P2, conf2, cameras=terms)
    cases = {
        "two_views (2 matrices)": lambda: triangulate_two_views(uv2, P2, conf2, min_ray_angle_deg=0.5),
        "two_views, crop terms kept": lambda: triangulate_two_views(uv2, P2, conf2, min_ray_angle_deg=0.5,
                                                                    cameras=terms),
        "two_views, the solve checked again": lambda: check_two_views(solution),
        "dlt (2 cameras)": lambda: triangulate_dlt(uv2, two, conf2),
        "dlt (3 cameras)": lambda: triangulate_dlt(uv3, three, conf3),
        "midpoint (3 cameras)": lambda: triangulate_midpoint(uv3, three, conf3),
        "robust (3 cameras, one wrong)": lambda: triangulate_robust(bad3, three, conf3, max_reprojection_error=4.0),
    }
    print(f"25 joints, median of {args.rounds} rounds of {args.calls} calls (us per call)")
    for name, fn in cases.items():
        print(f"{name:<32} {time_call(fn, args.calls, args.rounds) * 1e6:8.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
