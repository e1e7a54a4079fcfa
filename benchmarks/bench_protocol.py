"""Time the joint-protocol encoder: one BODY_25 frame from floats to wire bytes.

    python benchmarks/bench_protocol.py [--frames 20000] [--repeats 7]

Measures quantisation + packing + CRC-16 + COBS + delimiter (``encode(joints_message(frame))``),
and for reference the stream decoder on the same bytes and the VMC output's
per-frame work (bone solve + OSC bundle), which runs on the sink's worker thread. Prints the median time
per frame over ``--repeats`` runs and the frames per second it implies.
Figures go in docs/protocol.md with the command that produced them.
"""
from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from firmware_host.protocol import JointFrame, StreamDecoder, encode, joints_message  # noqa: E402
from firmware_host.sinks.vmc_osc import build_bundle  # noqa: E402
from firmware_host.sinks.vmc_pose import solve_pose  # noqa: E402


def _frames(n: int) -> list[JointFrame]:
    rng = np.random.default_rng(0)
    joints = rng.normal(0, 0.5, (n, 25, 4)) + [0, 0, 3, 0]
    joints[..., 3] = rng.random((n, 25))
    joints[:, 3, :3] = np.nan  # one missing joint, as in real output
    return [JointFrame(i, 1_000_000 + i * 33_333, 0, joints[i]) for i in range(n)]


def _time_per_item(fn, items: list, repeats: int) -> float:
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for item in items:
            fn(item)
        runs.append((time.perf_counter() - t0) / len(items))
    return statistics.median(runs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=positive_count, default=20000)
    ap.add_argument("--repeats", type=positive_count, default=7)
    args = ap.parse_args()
    frames = _frames(args.frames)
    encode_s = _time_per_item(lambda f: encode(joints_message(f, f.capture_time_us + 40_000)), frames, args.repeats)
    wire = [encode(joints_message(f, 0)) for f in frames]
    decoder = StreamDecoder()
    decode_s = _time_per_item(decoder.feed, wire, args.repeats)
    vmc_frames = frames[: max(1, args.frames // 50)]
    vmc_s = _time_per_item(lambda f: build_bundle(solve_pose(f.joints_3d), 0.0), vmc_frames, args.repeats)
    print(f"python {platform.python_version()} numpy {np.__version__} on {platform.machine()}, "
          f"{args.frames} frames x {args.repeats} runs, {len(wire[0])} wire bytes per frame")
    print(f"encode (quantise+pack+crc+cobs): median {encode_s * 1e6:.1f} us/frame = {1 / encode_s:,.0f} frames/s")
    print(f"decode (stream decoder):          median {decode_s * 1e6:.1f} us/frame = {1 / decode_s:,.0f} frames/s")
    print(f"vmc (bone solve + OSC bundle):    median {vmc_s * 1e6:.1f} us/frame = {1 / vmc_s:,.0f} frames/s")


if __name__ == "__main__":
    main()
