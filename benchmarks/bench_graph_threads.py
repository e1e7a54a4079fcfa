"""How many intra-op threads each graph should run with: 1 against 2, on the graphs' real inputs.

    .venv/bin/python benchmarks/bench_graph_threads.py --model-dir models [--rounds 15]

The estimator runs a few held-out-like simulator pairs with a novel view (encoder heatmaps) and
with rendered heatmaps, and every graph call's inputs are recorded (the coarse and the fine
novel-view passes of ``render_rgb`` included, so the mix of ray counts is the real one). Then,
for each graph file (fp32 and int8), a 1-thread and a 2-thread session (per-session pools, no
spinning, as the runtime opens them) replay those inputs, alternating in rounds so drifting
machine load hits both alike. Prints the median ms per call of each and their ratio.

The question: do graphs made of many small per-sample operators (the render heads) lose more to
waking a second worker for every operator than they gain from it? On the 2-core target the
answer was "not enough to matter" (docs/runtime.md), so one ``SessionConfig.threads`` serves
every graph. Not a test.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
import onnxruntime as ort

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.bench_runtime_common import SessionTap  # noqa: E402
from ghnerf_runtime.cli.simdata import SEQUENCE_CACHE_HELP, load_sequences  # noqa: E402
from ghnerf_runtime.config import (  # noqa: E402
    EstimatorConfig, HeatmapsConfig, Joints3DConfig, NovelViewConfig, PresenceConfig, SessionConfig,
)
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.novel_view import NovelViewRequest  # noqa: E402
from ghnerf_runtime.session import resolve_model_dir  # noqa: E402


class _FeedTap(SessionTap):
    """The session, keeping the inputs of every graph call (the novel view's, run on its lanes, included)."""

    def __init__(self, session, feeds: dict):
        super().__init__(session)
        self.feeds = feeds

    def record(self, graph, feeds, out):
        names = self._session.contract.graph(graph).input_names
        self.feeds.setdefault(graph, []).append({n: np.array(feeds[n]) for n in names})


def capture(model_dir: str, sequences, pairs: int) -> dict[str, list[dict]]:
    """Inputs of every graph call over ``pairs`` pairs per sequence, both heatmap paths."""
    feeds: dict[str, list[dict]] = {}
    for source, method in (("encoder", "triangulate"), ("rendered", "depth_centroid")):
        # the presence gate off: a pair it says shows nobody has no novel view, and the graphs are timed on the
        # inputs of views, whoever the model finds (the tiny test export finds nobody)
        cfg = EstimatorConfig(session=SessionConfig(model_dir=model_dir, warmup=False),
                              heatmaps=HeatmapsConfig(source=source, flip_test=False),  # as docs measured it
                              joints3d=Joints3DConfig(method=method),
                              novel_view=NovelViewConfig(enabled=True), presence=PresenceConfig(enabled=False))
        tap = _FeedTap(load_session(cfg), feeds)
        for seq in sequences:
            est = Estimator(tap, seq.rig, cfg)
            for i in range(min(pairs, len(seq))):
                # Encoder heatmaps: keypoint-only pairs (the human graph) and pairs with a novel view.
                novel = source == "encoder" and i % 2 == 1
                est.estimate((np.asarray(seq.images[i, 0]), np.asarray(seq.images[i, 1])),
                             novel_view=NovelViewRequest(alpha=0.5) if novel else None)
    return feeds


def _open(path: Path, threads: int) -> ort.InferenceSession:
    so = ort.SessionOptions()
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])


def _replay_ms(sess: ort.InferenceSession, calls: list[dict]) -> float:
    """Mean ms per call over one pass through ``calls``."""
    t = time.perf_counter()
    for feeds in calls:
        sess.run(None, feeds)
    return 1e3 * (time.perf_counter() - t) / len(calls)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", default="models")
    ap.add_argument("--sequences", type=int, default=3)
    ap.add_argument("--pairs", type=int, default=6, help="pairs per sequence whose inputs are recorded")
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--graphs", default="human,encoder,volume,render_rgb,render_heat")
    ap.add_argument("--cache", help=SEQUENCE_CACHE_HELP)
    args = ap.parse_args(argv)
    folder = resolve_model_dir(args.model_dir)
    feeds = capture(args.model_dir, load_sequences(args.sequences, 30, cache_dir=args.cache), args.pairs)
    print(f"model {folder}, load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs, {args.rounds} rounds")
    print(f"{'graph file':<24} {'calls':>5} {'1 thread ms':>12} {'2 threads ms':>13} {'2/1':>6}")
    for graph in args.graphs.split(","):
        calls = feeds.get(graph)
        if not calls:
            print(f"{graph:<24} (not run by the estimator with this model)")
            continue
        for name in (f"{graph}.onnx", f"{graph}.int8.onnx"):
            if not (folder / name).is_file():
                continue
            sessions = {n: _open(folder / name, n) for n in (1, 2)}
            for s in sessions.values():
                _replay_ms(s, calls[:3])  # warm-up
            ms: dict[int, list[float]] = {1: [], 2: []}
            for r in range(args.rounds):
                for n in ((1, 2) if r % 2 == 0 else (2, 1)):
                    ms[n].append(_replay_ms(sessions[n], calls))
            one, two = float(np.median(ms[1])), float(np.median(ms[2]))
            print(f"{name:<24} {len(calls):>5} {one:>12.2f} {two:>13.2f} {two / one:>6.2f}", flush=True)
    print(f"load average at the end {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
