"""Where the demo's milliseconds per pair go: every ``PairResult.timing_ms`` key over the demo's scene.

    .venv/bin/python benchmarks/time_demo_stages.py [--model-dir models] [--pairs 91] [--config runtime.json]
                                                    [--profile 25] [--url sim://...] [--live 3]

The scene is ``make demo``'s (``sim://?fps=30&seed=0&motion=wave``, the shipped model, the runtime's defaults
unless ``--config`` says otherwise), but read in order on a manual clock (``policy=all``): every pair is
estimated, none skipped, so two runs see the same pairs and print the same joints, whatever the machine's load
(the demo under ``latest`` skips the pairs that wait, which differ run to run; ``--live SECONDS`` reads as the
demo does, on the real clock, for the stages of the pairs it estimates). Prints, over the pairs, the
median and p90 of each stage key (a pair without the stage counts 0 ms; ``pairs`` says on how many it ran), of
``total``, and of what no stage covers (``uncovered``: ``total`` minus the sum of the stages, the code between
them); the CPU time per pair, of all the process's threads and of the calling thread (onnxruntime's and the flip
test's lane thread are the rest), which other jobs on the host slow far less than the wall clock, and on Linux
each thread's (which threads take the cores: two busy threads on two cores, or more); and the 3D
joints' checksum (the sum of the reported joints' coordinates over all pairs), so a change meant to leave the
joints alone can be checked against it. ``--profile N`` also runs cProfile over the estimates, timed by the
calling thread's CPU clock (so other jobs' load does not enter it), and prints its top ``N`` functions by own
time, then the estimator's own functions by cumulative time (the stages' and the code between them). Not a test.
"""
from __future__ import annotations

import argparse
import cProfile
import io
import math
import os
import pstats
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
import drivers  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, load_config  # noqa: E402
from ghnerf_runtime.estimator import Estimator  # noqa: E402

#: The demo's rig (firmware_host.demo.DEFAULT_URL), every pair delivered in order.
SCENE_URL = "sim://?fps=30&seed=0&motion=wave&policy=all"
#: What the demo reads (firmware_host.demo.DEFAULT_URL: the newest pair first, on the real clock): ``--live``.
DEMO_URL = "sim://?fps=30&seed=0&motion=wave"
#: The demo's 3 s at 30 fps delivered about 91 pairs.
DEFAULT_PAIRS = 91


@dataclass
class Run:
    """What the estimates of one run gave."""

    timings: list[dict[str, float]] = field(default_factory=list)  # each pair's timing_ms
    checksum: float = 0.0  # the sum of the reported 3D joints' coordinates (m), all pairs
    wall_s: float = 0.0  # of the estimate calls alone
    cpu_s: float = 0.0  # the process's CPU time (every thread) during them
    caller_cpu_s: float = 0.0  # the calling thread's
    skipped: int = 0  # pairs the rig dropped for newer ones (--live, under the demo's ``latest`` policy)
    threads_cpu_s: list[float] = field(default_factory=list)  # each thread's CPU time during the estimates, most first


def _threads_cpu_s() -> dict[str, float]:
    """This process's threads' CPU time (s) by thread id, from /proc (Linux; elsewhere empty): which of the threads
    onnxruntime, OpenCV and the estimator start take the cores while the estimates run."""
    tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    out = {}
    for task in Path("/proc/self/task").glob("*"):
        try:
            fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:  # a thread that ended meanwhile (or no /proc)
            continue
        out[task.name] = (int(fields[11]) + int(fields[12])) / tick  # utime + stime
    return out


def _config(args: argparse.Namespace) -> EstimatorConfig:
    cfg = load_config(args.config) if args.config else EstimatorConfig()
    return replace(cfg, session=replace(cfg.session, model_dir=str(args.model_dir)))


def run(args: argparse.Namespace) -> Run:
    """Estimate the scene's pairs: ``args.pairs`` of them in order on the rig's manual clock, or, with
    ``args.live``, for that many seconds of real time as the demo does (the newest pair the rig has delivered)."""
    live = args.live is not None
    source = drivers.create_rig_source(args.url, **({} if live else {"clock": drivers.ManualClock()}))
    source.open()
    out = Run()
    profiler = cProfile.Profile(time.thread_time) if args.profile else None
    try:
        with Estimator.from_config(source.rig, _config(args)) as estimator:
            threads_before = _threads_cpu_s()
            deadline = time.monotonic() + (args.live or 0.0)
            while time.monotonic() < deadline if live else len(out.timings) < args.pairs:
                pair = source.read(timeout_s=1.0)
                t0, c0, m0 = time.perf_counter(), time.process_time(), time.thread_time()
                if profiler is not None:
                    profiler.enable()
                result = estimator.estimate(pair.images, sequence=pair.sequence,
                                            timestamp_s=pair.timestamps_ns[0] * 1e-9)
                if profiler is not None:
                    profiler.disable()
                out.wall_s += time.perf_counter() - t0
                out.cpu_s += time.process_time() - c0
                out.caller_cpu_s += time.thread_time() - m0
                out.timings.append(dict(result.timing_ms))
                out.checksum += float(np.sum(np.asarray(result.joints_3d)[~np.asarray(result.missing)]))
            out.skipped = source.stats.pairs_dropped
            after = _threads_cpu_s()
            out.threads_cpu_s = sorted((t - threads_before.get(tid, 0.0) for tid, t in after.items()), reverse=True)
    finally:
        source.close()
    if profiler is not None:
        _print_profile(profiler, args.profile)
    return out


def _print_profile(profiler: cProfile.Profile, top: int) -> None:
    """The functions with the most own time, then the estimator's own by cumulative time (the calling thread's
    CPU time: a run on the flip test's lane thread shows as the wait for it, ``acquire``, at ~0)."""
    stats = pstats.Stats(profiler, stream=io.StringIO())
    stats.sort_stats("tottime")
    out = io.StringIO()
    stats.stream = out
    stats.print_stats(top)
    print(f"cProfile over the estimates (the calling thread's CPU time), top {top} by own time (tottime):")
    print("\n".join(line for line in out.getvalue().splitlines()[4:] if line.strip()))
    out = io.StringIO()
    stats.stream = out
    stats.sort_stats("cumulative").print_stats(r"estimator\.py|tracking\.py|smoothing\.py|joints3d\.py", top)
    print(f"\ncProfile, the estimator's own functions by cumulative time (top {top}):")
    print("\n".join(line for line in out.getvalue().splitlines()[4:] if line.strip()))


def summarise(timings: list[dict[str, float]]) -> list[tuple[str, int, float, float]]:
    """(key, pairs with it, median ms, p90 ms) of each stage, ``total`` and ``uncovered``, stages by median."""
    stages = sorted({k for t in timings for k in t if k != "total"})
    rows = []
    for k in stages:
        vals = np.array([t.get(k, 0.0) for t in timings])
        rows.append((k, sum(k in t for t in timings), float(np.median(vals)), float(np.percentile(vals, 90))))
    rows.sort(key=lambda r: -r[2])
    total = np.array([t["total"] for t in timings])
    uncovered = total - np.array([sum(v for k, v in t.items() if k != "total") for t in timings])
    n = len(timings)
    rows.append(("uncovered", n, float(np.median(uncovered)), float(np.percentile(uncovered, 90))))
    rows.append(("total", n, float(np.median(total)), float(np.percentile(total, 90))))
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model-dir", type=model_folder_option, default="models")
    parser.add_argument("--pairs", type=positive_count, default=DEFAULT_PAIRS,
                        help="pairs to estimate (the demo's 3 s: 91)")
    parser.add_argument("--url", default=None,
                        help=f"the rig (default: {SCENE_URL}; with --live the demo's own, {DEMO_URL})")
    parser.add_argument("--live", type=float, default=None, metavar="SECONDS",
                        help="read the rig on the real clock for SECONDS, the newest pair each time, as the demo "
                             "does (--pairs is then unused; the pairs estimated, and so the checksum, vary run to run)")
    parser.add_argument("--config", default=None, help="estimator config, JSON (docs/runtime.md)")
    parser.add_argument("--profile", type=non_negative_count, default=0, metavar="N",
                        help="print cProfile's top N functions")
    args = parser.parse_args(argv)
    if args.live is not None and not (math.isfinite(args.live) and args.live > 0):
        parser.error(f"--live must be a finite number of seconds > 0, got {args.live}")
    if args.url is None:
        args.url = DEMO_URL if args.live is not None else SCENE_URL
    r = run(args)
    n = len(r.timings)
    if not n:
        print(f"no pair was estimated in {args.live} s", file=sys.stderr)
        return 1
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"{n} pairs of {args.url} through {args.model_dir}"
          f"{' with ' + args.config if args.config else ' (runtime defaults)'}; load average {load}")
    print(f"{'stage':16s} {'pairs':>5s} {'median ms':>10s} {'p90 ms':>8s}")
    for key, count, med, p90 in summarise(r.timings):
        print(f"{key:16s} {count:5d} {med:10.2f} {p90:8.2f}")
    print(f"wall {r.wall_s:.2f} s for the estimates ({n / max(r.wall_s, 1e-9):.1f} pairs/s); CPU per pair "
          f"{1e3 * r.cpu_s / n:.1f} ms, all threads ({1e3 * r.caller_cpu_s / n:.1f} ms the calling thread's); "
          f"joints checksum {r.checksum:.6f}"
          + (f"; {r.skipped} pairs skipped for newer ones" if args.live is not None else ""))
    if r.threads_cpu_s:  # (the clock ticks are 10 ms: a thread's few ms show as 0 or 10)
        busy = [f"{1e3 * t / n:.1f}" for t in r.threads_cpu_s if t > 0]
        print(f"CPU per pair by thread (ms; {len(r.threads_cpu_s)} threads, {len(busy)} ran): {', '.join(busy)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
