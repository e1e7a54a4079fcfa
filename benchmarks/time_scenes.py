"""What a pair costs in each kind of scene: nobody in view, someone still, walking, far and near.

    .venv/bin/python benchmarks/time_scenes.py [--model-dir models] [--pairs 60] [--novel-view]
                                               [--scenes empty,still,walk,far,near] [--config runtime.json]

Each scene is a simulated rig's pairs read in order on a manual clock (``policy=all``, so every run sees the same
pairs and prints the same joints checksum) through one estimator with the runtime's defaults (or ``--config``):

* ``empty``: a textured room with nobody in view (scene seed 1's room with its person left out,
  ``benchmarks/empty_rooms.py``; until session 65 the person stood 3 m behind the rig, which moved the room back: the
  cameras faced its near wall); every pair passes the frame check, so the model runs and the presence gate says
  nobody (the same pair, with the capture times of 30 fps);
* ``still``: someone standing still (``motion=stand``, seed 0);
* ``walk``: someone walking on the spot (``motion=walk``, seed 3): the tracked crop moves most pairs;
* ``far``, ``near``: someone waving 6 m and 1.5 m from the rig (small in the frame, filling it).

``--novel-view`` asks a novel view (the default request) of every pair. Prints per scene the median wall time per
pair of ``total`` and of each ``timing_ms`` stage (a pair without the stage counts 0 ms), the median CPU time per
pair of the calling thread, and the checksum of the reported 3D joints. Not a test.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
import drivers  # noqa: E402
import drivers.sim as sim  # noqa: E402
from benchmarks.empty_rooms import empty_room_pair  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, load_config  # noqa: E402
from ghnerf_runtime.estimator import Estimator  # noqa: E402
from ghnerf_runtime.novel_view import NovelViewRequest  # noqa: E402

#: The rig URL of each scene with someone in view (``empty`` is rendered: no URL puts nobody in view).
SCENE_URLS = {
    "still": "sim://?fps=30&seed=0&motion=stand&policy=all",
    "walk": "sim://?fps=30&seed=3&motion=walk&policy=all",
    "far": "sim://?fps=30&seed=0&motion=wave&distance=6&policy=all",
    "near": "sim://?fps=30&seed=0&motion=wave&distance=1.5&policy=all",
}
SCENES = ("empty", *SCENE_URLS)
#: The empty room's scene seed: its room, its person left out.
EMPTY_ROOM_SEED = 1
FPS = 30.0


def scene_pairs(scene: str, count: int):
    """The scene's rig and ``count`` pairs: ``[(images, timestamp_s)]``."""
    if scene == "empty":
        rig = sim.RigPlacement().build()
        images = empty_room_pair(rig, EMPTY_ROOM_SEED)
        return rig, [(images, i / FPS) for i in range(count)]
    source = drivers.create_rig_source(SCENE_URLS[scene], clock=drivers.ManualClock())
    source.open()
    try:
        pairs = []
        for _ in range(count):
            pair = source.read(timeout_s=1.0)
            pairs.append((tuple(np.copy(image) for image in pair.images), pair.timestamps_ns[0] * 1e-9))
        return source.rig, pairs
    finally:
        source.close()


def time_scene(estimator: Estimator, pairs, novel_view: NovelViewRequest | None) -> dict:
    """Each pair's ``timing_ms``, calling-thread CPU ms and the joints checksum over the scene's pairs."""
    timings, cpu_ms, checksum = [], [], 0.0
    for images, timestamp_s in pairs:
        c0 = time.thread_time()
        result = estimator.estimate(images, timestamp_s=timestamp_s, novel_view=novel_view)
        cpu_ms.append(1e3 * (time.thread_time() - c0))
        timings.append(result.timing_ms)
        checksum += float(np.sum(np.asarray(result.joints_3d)[~np.asarray(result.missing)]))
    return {"timings": timings, "cpu_ms": cpu_ms, "checksum": checksum}


def summary_line(scene: str, run: dict) -> str:
    timings = run["timings"]
    stages = sorted({k for t in timings for k in t if k != "total"})
    medians = " ".join(f"{k} {np.median([t.get(k, 0.0) for t in timings]):.2f}" for k in stages)
    return (f"{scene:6s} total {np.median([t['total'] for t in timings]):6.2f} ms  CPU {np.median(run['cpu_ms']):6.2f} "
            f"ms  | {medians} | checksum {run['checksum']:.6f}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model-dir", type=model_folder_option, default="models")
    parser.add_argument("--pairs", type=positive_count, default=60)
    parser.add_argument("--scenes", default=",".join(SCENES), help=f"comma-separated, of {', '.join(SCENES)}")
    parser.add_argument("--novel-view", action="store_true", help="ask a novel view of every pair")
    parser.add_argument("--config", default=None, help="estimator config, JSON (docs/runtime.md)")
    args = parser.parse_args(argv)
    scenes = args.scenes.split(",")
    if unknown := [s for s in scenes if s not in SCENES]:
        parser.error(f"--scenes: unknown {unknown}; known: {', '.join(SCENES)}")
    if args.pairs < 1:
        parser.error(f"--pairs must be >= 1, got {args.pairs}")
    config = load_config(args.config) if args.config else EstimatorConfig()
    config = replace(config, session=replace(config.session, model_dir=str(args.model_dir)))
    if args.novel_view:
        config = replace(config, novel_view=replace(config.novel_view, enabled=True))
    request = NovelViewRequest() if args.novel_view else None
    print(f"{args.pairs} pairs a scene, {'a novel view asked of each' if request else 'keypoints'}; per-pair medians")
    for scene in scenes:
        rig, pairs = scene_pairs(scene, args.pairs)
        with Estimator.from_config(rig, config) as estimator:
            print(summary_line(scene, time_scene(estimator, pairs, request)), flush=True)
    print(f"load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
