"""How many pairs :class:`drivers.pairing.FramePairer` forms, and how far apart their frames are, for two
cameras at different rates or with jitter; beside it the offline reference: every frame known in advance,
the closest two frames (within tolerance) paired first, then the next closest, and so on.

Usage: ``.venv/bin/python benchmarks/measure_pairing.py [--seconds 60] [--seeds 5]``

Frames reach the pairer in capture order (as ``sim://`` delivers them) and a reader takes each pair at
once. Per scenario it prints pairs formed, mean and max |dt| (ms), the frames of each camera left
unpaired, summed over the seeds, and how long the pairer held a pair back (ms of capture time from its
later frame to the frame that let it decide; median and max). The figures are a function of the options only.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script without installing

from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from ghnerf_runtime.cli.seconds import positive_seconds  # noqa: E402
from drivers.frames import Frame  # noqa: E402
from drivers.pairing import DropPolicy, FramePairer, PairingConfig  # noqa: E402

IMG = np.zeros((1, 1, 3), np.uint8)

#: (name, fps of a, fps of b, offset of b in ms, jitter in ms, tolerance in ms): 20 ms and 16.7 ms are
#: opencv://'s default tolerances (half a period of the slower camera), 11 ms the default elsewhere.
SCENARIOS = [
    ("30 vs 25 fps", 30.0, 25.0, 0.0, 0.0, 20.0),
    ("30 vs 25 fps, 1 ms jitter", 30.0, 25.0, 0.0, 1.0, 20.0),
    ("30 vs 30 fps, 3 ms jitter", 30.0, 30.0, 0.0, 3.0, 11.0),
    ("30 vs 30 fps, 3 ms jitter, offset 8 ms", 30.0, 30.0, 8.0, 3.0, 16.7),
    ("30 vs 30 fps, 3 ms jitter, offset 14 ms", 30.0, 30.0, 14.0, 3.0, 16.7),
]


def stamps(fps: float, offset_ms: float, jitter_ms: float, seconds: float, rng: np.random.Generator) -> np.ndarray:
    """Capture times (ns) of one camera; jitter clipped to 45 % of a period, as ``sim://`` does."""
    period = 1e9 / fps
    n = int(seconds * fps)
    jitter = np.clip(rng.normal(0.0, jitter_ms * 1e6, n), -0.45 * period, 0.45 * period) if jitter_ms else np.zeros(n)
    return np.round(np.arange(n) * period + offset_ms * 1e6 + jitter).astype(np.int64)


def online(a: np.ndarray, b: np.ndarray, tolerance_ms: float) -> tuple[list[int], list[int]]:
    """|dt| (ns) of each pair the pairer forms, the frames fed in capture order, the stream ended at the end;
    and each pair's wait: the capture time of the frame whose arrival released it, less its later frame's."""
    pairer = FramePairer(("a", "b"), PairingConfig(tolerance_ms=tolerance_ms, policy=DropPolicy.ALL))
    events = sorted([(int(t), 0, "a", k) for k, t in enumerate(a)] + [(int(t), 1, "b", k) for k, t in enumerate(b)])
    gaps: list[int] = []
    waits: list[int] = []

    def take(now_ns: int | None) -> None:
        while (item := pairer.pop()) is not None:
            gaps.append(abs(item[1].timestamp_ns - item[2].timestamp_ns))
            if now_ns is not None:  # not at the end of the stream
                waits.append(now_ns - max(item[1].timestamp_ns, item[2].timestamp_ns))

    for t, _, cam, k in events:
        pairer.push(Frame(camera=cam, image=IMG, timestamp_ns=t, index=k))
        take(t)
    if hasattr(pairer, "flush"):  # the pairer before the nearest-partner policy had nothing to flush
        pairer.flush()
        take(None)
    return gaps, waits


def reference(a: np.ndarray, b: np.ndarray, tolerance_ms: float) -> list[int]:
    """Offline: the closest remaining two frames in tolerance first (only neighbours in time can be closest)."""
    merged = sorted([(int(t), 0) for t in a] + [(int(t), 1) for t in b])
    edges = sorted((merged[i + 1][0] - merged[i][0], i) for i in range(len(merged) - 1)
                   if merged[i][1] != merged[i + 1][1] and merged[i + 1][0] - merged[i][0] <= tolerance_ms * 1e6)
    used = [False] * len(merged)
    gaps = []
    for gap, i in edges:
        if not used[i] and not used[i + 1]:
            used[i] = used[i + 1] = True
            gaps.append(gap)
    return gaps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=positive_seconds, default=60.0)
    parser.add_argument("--seeds", type=positive_count, default=5)
    args = parser.parse_args()
    print(f"{'scenario':42s} {'tol ms':>6s} {'method':9s} {'pairs':>6s} {'mean|dt|':>8s} {'max|dt|':>8s} "
          f"{'unpaired a/b':>12s} {'wait ms':>12s}")
    for name, fps_a, fps_b, offset, jitter, tol in SCENARIOS:
        results: dict[str, list[int]] = {"pairer": [], "reference": []}
        waits: list[int] = []
        frames = [0, 0]
        for seed in range(args.seeds):
            rng = np.random.default_rng(seed)
            a = stamps(fps_a, 0.0, jitter, args.seconds, rng)
            b = stamps(fps_b, offset, jitter, args.seconds, rng)
            frames[0] += a.size
            frames[1] += b.size
            gaps, held = online(a, b, tol)
            results["pairer"] += gaps
            waits += held
            results["reference"] += reference(a, b, tol)
        for method, gaps in results.items():
            g = np.asarray(gaps) / 1e6
            wait = (f"{np.median(waits) / 1e6:5.1f} / {np.max(waits) / 1e6:4.1f}"
                    if method == "pairer" and waits else "")
            print(f"{name:42s} {tol:6.1f} {method:9s} {g.size:6d} {g.mean():8.2f} {g.max():8.2f} "
                  f"{frames[0] - g.size:>6d}/{frames[1] - g.size:<5d} {wait:>12s}")


if __name__ == "__main__":
    main()
