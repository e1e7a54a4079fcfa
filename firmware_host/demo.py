"""The main job on the simulated rig, as far as it exists today (``make demo``).

Opens a rig by URL (default: the simulated two-camera rig), reads frame pairs
in real time for a few seconds, and shows the rig at work:

* delivered pairs per second, pair skew and the driver's counters;
* the last pair with its ground-truth 2D joints drawn, written as a PNG;
* the ground-truth 3D joints, printed and streamed through a joint-stream sink
  (``file://`` JSON lines by default) exactly as the estimator's joints will be.

The model stage (issue: runtime) replaces the ground truth with estimates; until
then every joint printed or streamed here is labelled ground truth.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

import drivers
from drivers.sim.demo import draw_truth
from firmware_host.protocol.messages import JointFrame
from firmware_host.sinks import open_sink
from ghnerf_runtime.body25 import JOINT_NAMES

DEFAULT_URL = "sim://?fps=30&seed=0&motion=wave"


def _annotated(pair: drivers.FramePair) -> np.ndarray:
    panels = []
    for frame in pair.frames:
        panel = draw_truth(frame.image, frame.truth) if frame.truth is not None else frame.image.copy()
        label = f"{frame.camera}  pair {pair.sequence}"
        cv2.putText(panel, label, (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 2, cv2.LINE_AA)
        panels.append(panel)
    return np.hstack(panels)


def _joint_frame(pair: drivers.FramePair) -> JointFrame | None:
    if pair.joints_3d is None:
        return None
    joints = np.concatenate([pair.joints_3d, np.ones((len(pair.joints_3d), 1))], axis=1)
    return JointFrame(
        sequence=pair.sequence,
        capture_time_us=pair.frames[0].timestamp_ns // 1000,
        joint_set=0,
        joints_3d=joints,
    )


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default=DEFAULT_URL, help="rig URL (sim://, replay://DIR, depthai://)")
    parser.add_argument("--seconds", type=float, default=3.0, help="how long to read pairs")
    parser.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder")
    parser.add_argument("--sink", default=None, help="joint-stream sink URL (default: file://OUT/joints.jsonl)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    sink_url = args.sink or f"file://{(args.out / 'joints.jsonl').resolve()}"

    print(f"opening {args.url} (the first open pre-renders the motion loop; later opens use the cache)")
    t0 = time.monotonic()
    with drivers.open_rig(args.url) as source, open_sink(sink_url) as sink:
        print(f"open in {time.monotonic() - t0:.2f} s; cameras {list(source.rig.names)}, "
              f"baseline {source.rig.baseline:.2f} m")
        arrivals, skews, last = [], [], None
        deadline = time.monotonic() + args.seconds
        while time.monotonic() < deadline:
            pair = source.read(timeout_s=1.0)
            arrivals.append(time.monotonic())
            skews.append(pair.skew_ns / 1e6)
            frame = _joint_frame(pair)
            if frame is not None:
                sink.send(frame)
            last = pair
        stats = source.stats
    sink_stats = sink.stats()

    intervals = np.diff(arrivals)
    fps = 1.0 / statistics.median(intervals) if len(intervals) else float("nan")
    print(f"read {len(arrivals)} pairs in {args.seconds:.1f} s: median {fps:.2f} pairs/s, "
          f"median skew {statistics.median(skews):.2f} ms")
    print(f"driver counters: {stats}")
    print(f"sink {sink_url}: {sink_stats}")
    png = args.out / "sim_pair.png"
    if last is not None and cv2.imwrite(str(png), _annotated(last)):
        print(f"wrote {png} (pair {last.sequence} with its ground-truth 2D joints)")
    if last is not None and last.joints_3d is not None:
        print("ground-truth BODY_25 joints of that pair, rig frame (m; x right, y down, z forward):")
        for name, (x, y, z) in zip(JOINT_NAMES, last.joints_3d):
            print(f"  {name:10s} {x:+.3f} {y:+.3f} {z:+.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
