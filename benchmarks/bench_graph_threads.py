"""How many intra-op threads each graph should run with: 1 against 2, on the graphs' real inputs.

    .venv/bin/python benchmarks/bench_graph_threads.py --model-dir models [--rounds 15] [--warmup 2]

The estimator runs a few held-out-like simulator pairs with a novel view (encoder heatmaps) and
with rendered heatmaps, and every graph call's inputs are recorded (the coarse and the fine
novel-view passes of ``render_rgb`` included, so the mix of ray counts is the real one). Then,
for each graph file (fp32 and int8), a 1-thread and a 2-thread session (per-session pools, no
spinning, as the runtime opens them) replay those inputs. All the sessions are open at once and
every round replays every one of them, a graph's four one after another, in an order turned
every two rounds and reversed every other round, after ``--warmup`` untimed rounds of the same
kind (every session, every input shape): drifting machine load and the place in the round hit
every file and thread count alike. Prints per graph file the median ms per call at 1 and 2
threads and the median (25th-75th percentile) of the rounds' own 2/1 ratios; then per graph with
both files the rounds' int8/fp32 ratios. Where the two files are the same bytes (``volume``: it
stays fp32 in the int8 file) that line is the bench's control: it should read about 1.00.

Until session 68 the bench timed each file's rounds in a block, fp32 then int8, after three
warm-up calls: the identical ``volume`` files came 1.5x apart in one run, the later one faster or
slower as the host's load moved (tests/benchmarks/test_bench_graph_threads.py).

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

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
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


#: One timed session: (graph, file name, intra-op threads).
Variant = tuple[str, str, int]


def _rotated(items: list, turn: int, every: int = 1) -> list:
    """``items`` turned by one place every ``every`` pairs of turns, and reversed on odd turns: any two items run
    in both orders over each two turns, and every item takes every place over ``2 * every * len(items)`` turns,
    so neither load drifting within a round nor the place after another graph's run favours one of them."""
    k = (turn // 2 // every) % len(items)
    order = items[k:] + items[:k]
    return order[::-1] if turn % 2 else order


def round_order(variants: dict[str, list[Variant]], turn: int) -> list[Variant]:
    """The sessions of one round: each graph's files and thread counts one after another (their ratios compare
    runs made close in time), turned every two rounds; the graphs' order turned more slowly, so that the two
    turns do not move in step and each session meets every place within its graph."""
    if not variants:  # no graph the estimator ran
        return []
    every = max(len(vs) for vs in variants.values())
    return [v for graph in _rotated(list(variants), turn, every) for v in _rotated(variants[graph], turn)]


def measure(sessions: dict[Variant, object], feeds: dict[str, list[dict]], rounds: int,
            warmup: int) -> dict[Variant, list[float]]:
    """Per session, the ms per call of each timed round; before them ``warmup`` untimed rounds in the same
    interleaved order, so every session has run every input shape equally often before its first timing."""
    variants: dict[str, list[Variant]] = {}
    for v in sessions:
        variants.setdefault(v[0], []).append(v)
    for turn in range(warmup):
        for v in round_order(variants, turn):
            _replay_ms(sessions[v], feeds[v[0]])
    ms: dict[Variant, list[float]] = {v: [] for v in sessions}
    for turn in range(rounds):
        for v in round_order(variants, warmup + turn):
            ms[v].append(_replay_ms(sessions[v], feeds[v[0]]))
    return ms


def ratio_spread(num: list[float], den: list[float]) -> tuple[float, float, float]:
    """Median, 25th and 75th percentile of the per-round ratios ``num / den`` (runs of one round are close in
    time, so drifting load cancels in each ratio, where a ratio of medians would keep it)."""
    r = np.asarray(num) / np.asarray(den)
    return float(np.median(r)), float(np.percentile(r, 25)), float(np.percentile(r, 75))


def _spread(s: tuple[float, float, float]) -> str:
    return f"{s[0]:>6.2f} {s[1]:>5.2f}-{s[2]:<5.2f}"


def _same_bytes(a: Path, b: Path) -> bool:
    return a.stat().st_size == b.stat().st_size and a.read_bytes() == b.read_bytes()


def _files(folder: Path, graph: str) -> list[str]:
    return [n for n in (f"{graph}.onnx", f"{graph}.int8.onnx") if (folder / n).is_file()]


def print_threads(ms: dict[Variant, list[float]], feeds: dict[str, list[dict]]) -> None:
    """One row per graph file: median ms at 1 and 2 threads, and the per-round 2/1 ratio with its spread."""
    print(f"{'graph file':<24} {'calls':>5} {'1 thread ms':>12} {'2 threads ms':>13} {'2/1':>6} p25-p75")
    for (graph, name, threads) in ms:
        if threads != 1:
            continue
        one, two = ms[(graph, name, 1)], ms[(graph, name, 2)]
        print(f"{name:<24} {len(feeds[graph]):>5} {np.median(one):>12.2f} {np.median(two):>13.2f} "
              f"{_spread(ratio_spread(two, one))}".rstrip())


def print_precisions(ms: dict[Variant, list[float]], folder: Path) -> None:
    """Per graph with both files, the per-round int8/fp32 ratio at each thread count; a pair of identical files
    is the control: anything but about 1.0 there is bias or noise of the bench, not a difference of the graphs."""
    graphs = [g for (g, name, threads) in ms if threads == 1 and name == f"{g}.int8.onnx"]
    if not graphs:
        return
    print(f"{'int8/fp32 per round':<24} {'1 thread':>6} {'p25-p75':<11} {'2 threads':>6} p25-p75")
    for graph in graphs:
        cells = " ".join(_spread(ratio_spread(ms[(graph, f"{graph}.int8.onnx", n)], ms[(graph, f"{graph}.onnx", n)]))
                         for n in (1, 2))
        same = _same_bytes(folder / f"{graph}.onnx", folder / f"{graph}.int8.onnx")
        print(f"{graph:<24} {cells}".rstrip() + ("  control: identical files, expect 1.00" if same else ""))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--sequences", type=positive_count, default=3)
    ap.add_argument("--pairs", type=positive_count, default=6, help="pairs per sequence whose inputs are recorded")
    ap.add_argument("--rounds", type=positive_count, default=15)
    ap.add_argument("--warmup", type=non_negative_count, default=2,
                    help="untimed rounds (every session, every call) before them")
    ap.add_argument("--graphs", default="human,encoder,volume,render_rgb,render_heat")
    ap.add_argument("--cache", help=SEQUENCE_CACHE_HELP)
    args = ap.parse_args(argv)
    folder = resolve_model_dir(args.model_dir)
    feeds = capture(args.model_dir, load_sequences(args.sequences, 30, cache_dir=args.cache), args.pairs)
    graphs = args.graphs.split(",")
    sessions = {(graph, name, threads): _open(folder / name, threads)
                for graph in graphs if feeds.get(graph) for name in _files(folder, graph) for threads in (1, 2)}
    print(f"model {folder}, load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs, {args.rounds} rounds "
          f"after {args.warmup} warm-up rounds; every round runs every graph file at 1 and 2 threads, order turned "
          f"each round; ratios: median of the rounds' own ratios", flush=True)
    ms = measure(sessions, feeds, args.rounds, args.warmup)
    print_threads(ms, feeds)
    print_precisions(ms, folder)
    for graph in graphs:
        if not feeds.get(graph):
            print(f"{graph:<24} (not run by the estimator with this model)")
    print(f"load average at the end {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
