"""The daemon left running: memory, threads and throughput over time, through repeated camera unplugs.

    .venv/bin/python benchmarks/soak_daemon.py [--minutes 20] [--unplug-every-s 30] [--sample-s 60]

Runs :class:`firmware_host.daemon.Daemon` in this process on ``sim://`` (320x240, the shipped model,
a ``memory://`` sink drained as a receiver would) with the second camera unplugged every
``--unplug-every-s`` seconds (``unplug_after_s``: the daemon reopens the rig each time). Every
``--sample-s`` it prints the process's resident memory, its thread count, pairs estimated in that
interval, rig opens so far and the sink's dropped count. A leak per reopen shows as memory or
threads climbing with the opens; a tool, not a test.
"""
from __future__ import annotations

import argparse
import logging
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from firmware_host.daemon import Daemon, daemon_config_from_dict  # noqa: E402
from firmware_host.daemon.notify import SystemdNotifier  # noqa: E402


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=20.0)
    ap.add_argument("--unplug-every-s", type=float, default=30.0)
    ap.add_argument("--sample-s", type=float, default=60.0)
    ap.add_argument("--model-dir", default=str(Path(__file__).resolve().parents[1] / "models"))
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)  # the unplugs' warnings would bury the table
    url = f"sim://?fps=30&seed=0&motion=wave&width=320&height=240&unplug_after_s={args.unplug_every_s}"
    cfg = daemon_config_from_dict({"rig": {"url": url, "reopen_min_s": 0.05},
                                   "sinks": ["memory://?max_bytes=8388608"],
                                   "estimator": {"session": {"model_dir": args.model_dir}}})
    daemon = Daemon(cfg, notifier=SystemdNotifier({}))
    stop = threading.Event()
    thread = threading.Thread(target=daemon.run, args=(stop,), daemon=True)
    thread.start()
    start = time.monotonic()
    print(f"soak: {args.minutes:g} min, unplug every {args.unplug_every_s:g} s; {url}")
    print("   t min   RSS MB  threads  pairs/s  opens  lost  sink dropped")
    last_t, last_n = start, 0
    while time.monotonic() - start < args.minutes * 60:
        time.sleep(args.sample_s)
        for sink in daemon.sinks.values():
            sink.read()  # drained, as a receiver reads a UART
        now, n = time.monotonic(), daemon.health.pairs_estimated
        stats = daemon.sink_stats()
        dropped = sum(s["dropped"] for s in stats.values())
        print(f"{(now - start) / 60:8.1f} {rss_mb():8.1f} {threading.active_count():8d} "
              f"{(n - last_n) / (now - last_t):8.1f} {daemon.health.rig_opens:6d} {daemon.health.rig_lost:5d} "
              f"{dropped:13d}", flush=True)
        last_t, last_n = now, n
    stop.set()
    thread.join(timeout=30)
    print(f"stopped: {daemon.health.pairs_estimated} pairs estimated, {daemon.health.rig_opens} opens, "
          f"{daemon.health.estimate_errors} estimate errors")


if __name__ == "__main__":
    main()
