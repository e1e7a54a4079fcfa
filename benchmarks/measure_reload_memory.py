"""Resident memory across reloads that load the model again, without running the daemon.

    .venv/bin/python benchmarks/measure_reload_memory.py [--loads 12] [--pairs 20] [--model-dir models]
        [--mmap-threshold N] [--main-thread] [--no-trim] [--no-gc] [--same-key]
        [--ort no_cpu_arena|no_mem_pattern|env_allocator] [--arena-max N]

Does what the daemon's reload does when ``estimator.session`` changes (``Daemon._reload``): loads the
model's sessions with :func:`ghnerf_runtime.estimator.load_session` while the old ones still run, builds
an :class:`~ghnerf_runtime.estimator.Estimator` on them for the simulated rig, estimates ``--pairs``
pairs of ``sim://`` (320x240, read once at the start), then drops the old estimator and sessions and
calls :func:`firmware_host.daemon.memory.return_freed_memory`. The loads alternate ``session.threads``
2 and 1, as ``benchmarks/soak_daemon.py --reload-every-s`` does, in a thread of their own as there
(``--main-thread``: as ``ghnerf-daemon`` runs them). glibc's mmap threshold is fixed first as
``Daemon._load_model`` fixes it (``--mmap-threshold 0``: left to glibc, as before). It prints VmRSS
(``/proc/self/status``) and glibc's account of its heap (``mallinfo2``: in use, free, mapped) after each
load (an even ``--loads`` ends on the first load's threads, so the first and last figures compare). It ends
with what tells a leak from a level: resident memory at loads 10, half-way and last (loads on the last one's
threads, as the two thread counts sit some megabytes apart), and its slope over the last half of the loads
in KB a load, fitted on each thread count's loads (a least-squares line), and the same slope of what glibc
holds in use (heap in use and mapped blocks: what a leak adds to, and the heap's free space does not). The
first figure, taken before any reload trimmed the heap, also holds what opening ``sim://`` left: with no loop
in its disk cache it renders the loop first, and the run then starts tens of MB higher and stays higher
throughout. The other options try one change at a time: ``--no-trim`` / ``--no-gc`` leave out the trim or the
collection, ``--same-key`` keeps the loaded sessions (what a reload whose session key did not change
does), ``--ort`` patches the sessions' options (an experiment: the daemon does not set them), and
``--arena-max N`` caps glibc's malloc arenas (``mallopt(M_ARENA_MAX, N)``) before anything loads.
A tool, not a test: run it alone, each option in a process of its own.
"""
from __future__ import annotations

import argparse
import ctypes
import ctypes.util
import gc
import sys
import threading
import time
from pathlib import Path
from typing import Sequence

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.counts import bounded_count, non_negative_count, positive_count
from ghnerf_runtime.cli.model_folder import model_folder_option

M_MMAP_THRESHOLD, M_ARENA_MAX = -3, -8  # glibc's malloc.h
#: The upper limit of M_MMAP_THRESHOLD on 64 bits (man mallopt: DEFAULT_MMAP_THRESHOLD_MAX). Below 0 is no size:
#: glibc reads -5 as a size_t near 2**64 (glibc 2.36 took it, returning 1), so the run measured no mapped blocks.
MMAP_THRESHOLD_MAX = 32 << 20


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


class _MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks",
                                               "uordblks", "fordblks", "keepcost")]


def glibc_heap_mb() -> tuple[float, float, float] | None:
    """glibc's own account (``mallinfo2``, every arena): heap in use and free, and memory in mmapped chunks
    (None without glibc)."""
    try:
        f = ctypes.CDLL(ctypes.util.find_library("c")).mallinfo2
    except (OSError, AttributeError, TypeError):
        return None
    f.restype = _MallInfo2
    m, mb = f(), 1 << 20
    return m.uordblks / mb, m.fordblks / mb, m.hblkhd / mb


def heap_mb() -> str:
    heap = glibc_heap_mb()
    return "" if heap is None else " ".join(f"{v:6.1f}" for v in heap)


def patch_session_options(which: str) -> None:
    """Wrap ``ghnerf_runtime.session._session_options`` so every session loaded from now on has ``which``."""
    import onnxruntime as ort

    from ghnerf_runtime import session as session_mod

    plain = session_mod._session_options

    def patched(config):
        so = plain(config)
        if which == "no_cpu_arena":
            so.enable_cpu_mem_arena = False
        elif which == "no_mem_pattern":
            so.enable_mem_pattern = False
        elif which == "env_allocator":
            so.add_session_config_entry("session.use_env_allocators", "1")
        return so

    if which == "env_allocator":  # one arena in onnxruntime's environment, shared by every session
        ort.create_and_register_allocator(ort.OrtMemoryInfo("Cpu", ort.OrtAllocatorType.ORT_ARENA_ALLOCATOR, 0,
                                                            ort.OrtMemType.DEFAULT), None)
    session_mod._session_options = patched


def on_last_threads(load: int, last: int) -> int:
    """``load``, or the next one when it ran on the other thread count than ``last`` (the counts alternate)."""
    return min(load + (last - load) % 2, last)


def threads_text(count: int) -> str:
    return f"{count} thread" + ("" if count == 1 else "s")


def marks_line(rss: dict[int, float], threads: dict[int, int]) -> str:
    """RSS at loads 10, half-way and last, each on the last load's threads."""
    last = max(rss)
    marks = sorted({on_last_threads(n, last) for n in (min(10, last), max(last // 2, 1), last)})
    return (f"RSS at loads {' / '.join(map(str, marks))} ({threads_text(threads[last])}): "
            f"{' / '.join(f'{rss[n]:.1f}' for n in marks)} MB")


def slope_kb_per_load(loads: Sequence[int], rss_mb: Sequence[float]) -> float:
    """The least-squares slope of RSS against the load number, in KB a load (nan under two loads)."""
    if len(loads) < 2:
        return float("nan")
    return float(np.polyfit(np.asarray(loads, float), np.asarray(rss_mb, float), 1)[0]) * 1024


def slope_line(what: str, mb: dict[int, float], threads: dict[int, int]) -> str:
    """The slope of ``mb`` over the last half of the loads, one per thread count: a leak climbs in both, a
    level is ~0."""
    last = max(mb)
    half = [n for n in sorted(mb) if n > last // 2]
    parts = []
    for count in sorted({threads[n] for n in half}, reverse=True):
        mine = [n for n in half if threads[n] == count]
        parts.append(f"{slope_kb_per_load(mine, [mb[n] for n in mine]):+.1f} KB a load at {threads_text(count)} "
                     f"({len(mine)} loads)")
    return f"slope over loads {half[0]}-{last}, {what}: " + ", ".join(parts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--loads", type=positive_count, default=12, help="model loads after the first")
    ap.add_argument("--pairs", type=positive_count, default=20, help="pairs estimated on each load's sessions")
    ap.add_argument("--model-dir", type=model_folder_option,
                    default=str(Path(__file__).resolve().parents[1] / "models"))
    ap.add_argument("--no-trim", action="store_true", help="no malloc_trim after a load (gc only)")
    ap.add_argument("--no-gc", action="store_true", help="no gc.collect before the trim")
    ap.add_argument("--same-key", action="store_true", help="keep the loaded sessions (estimator rebuilt only)")
    ap.add_argument("--ort", choices=["no_cpu_arena", "no_mem_pattern", "env_allocator"])
    ap.add_argument("--arena-max", type=non_negative_count, default=0,
                    help="mallopt(M_ARENA_MAX, N) first (0: glibc's default)")
    ap.add_argument("--mmap-threshold", type=bounded_count(0, MMAP_THRESHOLD_MAX), default=None,
                    help="mallopt(M_MMAP_THRESHOLD, N) first, N bytes up to 32 MiB (default: the daemon's, "
                         "memory.MMAP_THRESHOLD; 0: glibc's own, which rises as mapped blocks are freed, as before the "
                         "daemon fixed it)")
    ap.add_argument("--main-thread", action="store_true",
                    help="load and estimate in the main thread, as ghnerf-daemon (default: in a thread of its own, "
                         "as soak_daemon.py runs the daemon)")
    args = ap.parse_args()
    if args.main_thread:
        measure(args)
        return
    failed: list[BaseException] = []

    def work() -> None:
        try:
            measure(args)
        except BaseException as e:  # raised again below, in the main thread
            failed.append(e)

    worker = threading.Thread(target=work, name="measure-reloads")
    worker.start()
    worker.join()
    if failed:
        raise failed[0]


def measure(args: argparse.Namespace) -> None:
    if args.arena_max:
        libc = ctypes.CDLL(ctypes.util.find_library("c"))
        print(f"mallopt(M_ARENA_MAX, {args.arena_max}) -> {libc.mallopt(M_ARENA_MAX, args.arena_max)}")
    from firmware_host.daemon import memory

    if args.mmap_threshold is None:  # as Daemon._load_model does
        print(f"memory.pin_mmap_threshold() -> {memory.pin_mmap_threshold()} ({memory.MMAP_THRESHOLD} bytes)")
    elif args.mmap_threshold:
        libc = ctypes.CDLL(ctypes.util.find_library("c"))
        done = libc.mallopt(M_MMAP_THRESHOLD, args.mmap_threshold)
        print(f"mallopt(M_MMAP_THRESHOLD, {args.mmap_threshold}) -> {done}")
    import drivers
    from firmware_host.daemon import daemon_config_from_dict
    from ghnerf_runtime.estimator import Estimator, load_session

    if args.ort:
        patch_session_options(args.ort)
    if args.no_gc:  # gc.collect itself, for this whole process: the trim's collection left out
        gc.collect = lambda *a: 0
    url = "sim://?fps=30&seed=0&motion=wave&width=320&height=240"
    base = {"rig": {"url": url}, "sinks": ["memory://"], "estimator": {"session": {"model_dir": args.model_dir}}}
    configs = [daemon_config_from_dict(base).estimator,
               daemon_config_from_dict({**base, "estimator": {"session": {"model_dir": args.model_dir,
                                                                          "threads": 1}}}).estimator]
    source = drivers.open_rig(url)
    try:
        rig = source.rig
        pairs = [source.read(timeout_s=5.0) for _ in range(args.pairs)]
    finally:
        source.close()
    print(f"before any load: {rss_mb():.1f} MB")

    def run(est: Estimator) -> None:
        for p in pairs:
            est.estimate(p.images, sequence=p.sequence, timestamp_s=p.timestamps_ns[0] * 1e-9)

    session = load_session(configs[0])
    estimator = Estimator(session, rig, configs[0])
    run(estimator)
    print(f"load 0: {rss_mb():.1f} MB; glibc used/free/mmap {heap_mb()} MB")
    first = rss_mb()
    print(" load  threads  RSS MB  change  trimmed  load s   used   free   mmap (glibc, MB)")
    rss: dict[int, float] = {}
    live: dict[int, float] = {}  # glibc's blocks in use, heap and mapped: what a leak adds to
    threads: dict[int, int] = {}
    for i in range(1, args.loads + 1):
        cfg = configs[0] if args.same_key else configs[i % 2]
        t0 = time.monotonic()
        new_session = session if args.same_key else load_session(cfg)  # the old one still held, as in a reload
        new_estimator = Estimator(new_session, rig, cfg)
        took = time.monotonic() - t0
        estimator.close()
        replaced = new_session is not session
        session, estimator = new_session, new_estimator
        del new_session, new_estimator
        trimmed = False
        if replaced and not args.no_trim:
            trimmed = memory.return_freed_memory()
        elif replaced:
            gc.collect()
        run(estimator)
        now = rss_mb()
        rss[i], threads[i] = now, cfg.session.threads
        heap = glibc_heap_mb()
        if heap is not None:
            live[i] = heap[0] + heap[2]
        print(f"{i:5d} {cfg.session.threads:8d} {now:7.1f} {now - first:+7.1f} {str(trimmed):>8} {took:7.2f} "
              f"{heap_mb()}", flush=True)
    print(f"after {args.loads} loads: {first:.1f} -> {rss_mb():.1f} MB "
          f"({(rss_mb() - first) / max(args.loads, 1):+.2f} MB a load)")
    if rss:
        print(marks_line(rss, threads))
        print(slope_line("RSS", rss, threads))
    if live:
        print(slope_line("glibc in use (used + mmap)", live, threads))


if __name__ == "__main__":
    main()
