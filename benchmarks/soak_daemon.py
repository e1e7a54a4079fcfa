"""The daemon left running: memory, threads and throughput over time, through repeated camera unplugs
and config reloads.

    .venv/bin/python benchmarks/soak_daemon.py [--minutes 20] [--unplug-every-s 30] [--sample-s 60]
                                               [--reload-every-s 0] [--fps 30]

Runs :class:`firmware_host.daemon.Daemon` in this process on ``sim://`` (320x240, the shipped model,
a ``memory://`` sink drained as a receiver would) with the second camera unplugged every
``--unplug-every-s`` seconds (``unplug_after_s``: the daemon reopens the rig each time). Every
``--sample-s`` it prints the process's resident memory, its thread count, pairs estimated in that
interval, rig opens so far and the sink's dropped count. With ``--reload-every-s`` it also reloads
the config that often (as SIGHUP does), cycling through three files: the first, one that adds a
sink and changes the smoothing (the estimator rebuilt on the loaded graphs), and one that changes
the session's threads (the model loaded again). A leak per reopen or per reload shows as memory or
threads climbing with the opens or the reloads; a tool, not a test.
"""
from __future__ import annotations

import argparse
import logging
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.seconds import positive_seconds  # noqa: E402
from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
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
    ap.add_argument("--sample-s", type=positive_seconds, default=60.0)
    ap.add_argument("--reload-every-s", type=float, default=0.0, help="0: never")
    ap.add_argument("--fps", type=float, default=30.0, help="the simulated rig's rate (lower: a light soak)")
    ap.add_argument("--model-dir", type=model_folder_option,
                    default=str(Path(__file__).resolve().parents[1] / "models"))
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)  # the unplugs' warnings would bury the table
    url = f"sim://?fps={args.fps:g}&seed=0&motion=wave&width=320&height=240&unplug_after_s={args.unplug_every_s}"
    base = {"rig": {"url": url, "reopen_min_s": 0.05}, "sinks": ["memory://?max_bytes=8388608"],
            "estimator": {"session": {"model_dir": args.model_dir}}}
    cycle = [daemon_config_from_dict(base),
             daemon_config_from_dict({**base, "sinks": base["sinks"] + ["memory://?max_bytes=8388609"],
                                      "estimator": {**base["estimator"], "smoothing": {"beta": 5.0}}}),
             daemon_config_from_dict({**base, "estimator": {"session": {**base["estimator"]["session"],
                                                                        "threads": 1}}})]
    reloads_asked = [0]

    def next_config():
        reloads_asked[0] += 1
        return cycle[reloads_asked[0] % len(cycle)]

    daemon = Daemon(cycle[0], notifier=SystemdNotifier({}), reload_config=next_config)
    stop = threading.Event()
    thread = threading.Thread(target=daemon.run, args=(stop,), daemon=True)
    thread.start()
    start = time.monotonic()
    reload_every = args.reload_every_s if args.reload_every_s > 0 else float("inf")
    print(f"soak: {args.minutes:g} min, unplug every {args.unplug_every_s:g} s, reload every {reload_every:g} s; "
          f"{url}")
    print("   t min   RSS MB  threads  pairs/s  opens  lost  reloads  sink dropped")
    last_t, last_n, next_reload, next_sample = start, 0, start + reload_every, start + args.sample_s
    while time.monotonic() - start < args.minutes * 60:
        time.sleep(max(0.0, min(next_sample, next_reload) - time.monotonic()))
        if time.monotonic() >= next_reload:
            daemon.request_reload()
            next_reload += reload_every
        if time.monotonic() < next_sample:
            continue
        next_sample += args.sample_s
        for sink in daemon.sinks.values():
            sink.read()  # drained, as a receiver reads a UART
        now, n = time.monotonic(), daemon.health.pairs_estimated
        stats = daemon.sink_stats()
        dropped = sum(s["dropped"] for s in stats.values())
        print(f"{(now - start) / 60:8.1f} {rss_mb():8.1f} {threading.active_count():8d} "
              f"{(n - last_n) / (now - last_t):8.1f} {daemon.health.rig_opens:6d} {daemon.health.rig_lost:5d} "
              f"{daemon.health.reloads:8d} {dropped:13d}", flush=True)
        last_t, last_n = now, n
    stop.set()
    thread.join(timeout=30)
    print(f"stopped: {daemon.health.pairs_estimated} pairs estimated, {daemon.health.rig_opens} opens, "
          f"{daemon.health.estimate_errors} estimate errors, {daemon.health.reloads} reloads "
          f"({daemon.health.reload_failures} refused)")


if __name__ == "__main__":
    main()
