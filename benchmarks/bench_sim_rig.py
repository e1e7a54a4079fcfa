"""Benchmark: does ``sim://`` deliver its nominal frame rate in real time on this machine?

Opens the simulated rig on the real clock twice: first with an empty cache (so
the loop is rendered: open time and render time per pair), then again from the
disk cache (open time only), and reads pairs for ``--seconds`` after the second
open. Prints figures; not a test.

    .venv/bin/python benchmarks/bench_sim_rig.py [--options "fps=30&width=640&height=480"] [--seconds 10]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.seconds import positive_seconds  # noqa: E402
from drivers import create_rig_source, open_rig  # noqa: E402
from drivers.errors import DriverError  # noqa: E402
from drivers.url import RigUrl  # noqa: E402


def sim_options(text: str) -> str:
    """An argparse ``type=`` for ``--options``: ``sim://`` query options the simulated rig takes, checked as it
    checks them before it renders (``--options fps=abc`` was the rig URL's RigConfigError traceback). ``cache=`` is
    this script's own: the first open fills an empty temporary folder, the second reads it."""
    url = f"sim://?{text}"
    try:
        if "cache" in RigUrl.parse(url).options:
            raise argparse.ArgumentTypeError(f"{text!r}: cache= is this script's own (a fresh temporary folder); "
                                             "leave it out")
        create_rig_source(url)  # unopened: nothing rendered, nothing held
    except DriverError as e:  # the message names the option and its value
        raise argparse.ArgumentTypeError(str(e)) from None
    return text


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--options", type=sim_options, default="fps=30&width=640&height=480",
                        help="sim:// query options")
    parser.add_argument("--seconds", type=positive_seconds, default=10.0, help="how long to read pairs")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="bench-sim-cache-") as cache:
        url = f"sim://?{args.options}&cache={cache}"
        print(f"url: {url}")
        print(f"cpus: {os.cpu_count()}")

        t0 = time.perf_counter()
        cold = open_rig(url)
        cold_open = time.perf_counter() - t0
        report = cold.fill_report
        frames_per_cam = cold.loop_frames
        cold.close()

        t0 = time.perf_counter()
        source = open_rig(url)
        warm_open = time.perf_counter() - t0
        fps = source.options.timing.fps

        arrivals, stamps, skews, latencies, sequences = [], [], [], [], []
        end = time.monotonic() + args.seconds
        with source:
            while time.monotonic() < end:
                pair = source.read(timeout_s=1.0)
                now = time.monotonic_ns()
                arrivals.append(now)
                stamps.append(pair.frames[0].timestamp_ns)
                skews.append(pair.skew_ns)
                latencies.append(now - max(pair.timestamps_ns))
                sequences.append(pair.sequence)
            stats = source.stats

    intervals = np.diff(arrivals) / 1e6
    w, h = source.rig.pair[0].size
    print(f"loop: {source.period_s:.2f} s = {frames_per_cam} frames per camera at {fps:g} fps, {w}x{h}")
    print(f"render time per pair (cache fill, one render thread's view): {2 * report.render_s_per_frame * 1e3:.1f} ms "
          f"(a {fps:g} fps period is {1e3 / fps:.1f} ms)")
    print(f"open, cold (pre-render {report.frames} frames on {source.options.workers} threads): {cold_open:.2f} s")
    print(f"open, from the disk cache: {warm_open:.2f} s")
    print(f"pairs read in {args.seconds:g} s: {len(arrivals)} "
          f"(pair sequence {sequences[0]}..{sequences[-1]}, pairs dropped by the LATEST policy: {stats.pairs_dropped})")
    print(f"delivered rate: median inter-pair interval {np.median(intervals):.2f} ms = {1e3 / np.median(intervals):.2f} fps; "
          f"mean rate {1e9 * (len(arrivals) - 1) / (arrivals[-1] - arrivals[0]):.2f} fps; "
          f"p99 interval {np.percentile(intervals, 99):.2f} ms")
    print(f"capture-stamp interval median: {np.median(np.diff(stamps)) / 1e6:.2f} ms")
    print(f"pair skew: median {np.median(skews) / 1e6:.3f} ms, max {max(skews) / 1e6:.3f} ms")
    print(f"delivery latency (read return - capture stamp): median {np.median(latencies) / 1e6:.2f} ms, "
          f"p99 {np.percentile(latencies, 99) / 1e6:.2f} ms")
    print(f"drops: simulated {stats.simulated_drops}, overruns {stats.overruns}, unpaired {stats.unpaired}, "
          f"camera gaps {stats.camera_gaps}")


if __name__ == "__main__":
    main()
