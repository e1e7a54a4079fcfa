"""``ghnerf-bench``: runtime latency and accuracy on held-out-like simulator sequences (a tool).

Subcommands::

    ghnerf-bench runtime [--model-dir models] [--sequences 10] [--frames 30] [--precisions fp32,int8,auto]
    ghnerf-bench sim-pair --out examples/sim       # the reproducible example of docs/runtime.md

Every row runs the runtime's own defaults (``EstimatorConfig()``, what ``ghnerf-run`` and the daemon run
without a config file: encoder heatmaps, triangulation, the flip test...) but for what its options name;
``--heatmap-sources rendered`` scores the rendered heatmaps (with their best method, ``depth_centroid``).

``runtime`` renders the sequences once (cached in ``$XDG_CACHE_HOME/ghnerf-bench``, else
``~/.cache/ghnerf-bench``: ``--cache``), then for every
precision and for "keypoints" and "keypoints + novel view" runs the estimator over every pair
and prints each stage's median and p99 (ms), the end-to-end median/p99 and throughput, and the
accuracy against the simulator's truth (PCK@0.2 in both images, MPJPE in the rig frame, with
the counts of missing joints, and the jitter of the 3D joints: ``metrics.acceleration_error``), and
each sequence's first pair alone (its cold start, which ``tracking.refine_cold_start`` runs twice): its
accuracy and its stages' times, and the startup it does not count (the model's load, each estimator's build).
The pairs carry their capture times (frame number / fps), as ``smoothing`` needs. The rows take
turns sequence by sequence, so drifts in the machine's speed hit them alike. The first pairs of
each row are warm-up and not counted. Not a timed test: the figures depend on the machine and its
load (the load average is printed).

This module is a tool, not the runtime library: it imports ``drivers`` (through
:mod:`ghnerf_runtime.cli.simdata`) only inside the commands.
"""
from __future__ import annotations

import argparse
import itertools
import json
import logging
import math
import os
import shutil
import sys
import time
from dataclasses import replace

import numpy as np

from ghnerf_runtime.cli.counts import ascii_integer
from ghnerf_runtime.cli.model_folder import model_dir_source, named_by_source
from ghnerf_runtime.cli.numbers import finite_number
from ghnerf_runtime.cli.output_path import OutputPathError, existing_ancestor, model_file_clash, ready_output
from ghnerf_runtime.config import BEST_METHOD, HEATMAP_SOURCES, THREE_D_METHODS, EstimatorConfig
from ghnerf_runtime.errors import ConfigError, ModelLoadError, RuntimeErrorBase
from ghnerf_runtime.estimator import (KEYPOINT_STAGES, NOVEL_MATTE_STAGE, NOVEL_PAINT_STAGE, NOVEL_PROXY_STAGE,
                                      NOVEL_STAGES, Estimator, load_session)
from ghnerf_runtime.metrics import strict_json
from ghnerf_runtime.novel_view import NovelViewRequest
from ghnerf_runtime.pipeline import NovelViewPipeline
from ghnerf_runtime.rig_file import write_text_atomic
from ghnerf_runtime.tracking import track_from_joints
from ghnerf_runtime.path_check import user_path

log = logging.getLogger("ghnerf-bench")

__all__ = ["main", "run_runtime_bench", "row_base_config", "STAGE_GROUPS"]

#: Printed columns: the issue's stage names -> estimator stage keys.
STAGE_GROUPS = {
    "preprocess": ("preprocess",),
    "encoders": ("encoder", "encoder_flip", "turn_search", "scan"),
    "depth (volume)": ("volume",),
    "rendering (heat)": ("render_heat",),
    "decoding (2D+3D)": ("decode_2d", "joints_3d"),
    "novel view": (*NOVEL_STAGES, NOVEL_PAINT_STAGE, NOVEL_PROXY_STAGE, NOVEL_MATTE_STAGE),
    "total": ("total",),
}
#: The totals of the pairs after each sequence's first (a stream's steady state), beside ``total``.
STEADY = "total after the first pair"
#: Each sequence's first pair alone (its cold start): its stages, as ``f"{COLD} {key}"`` in :func:`run_pairs`'
#: lists, and grouped as ``STAGE_GROUPS`` under ``COLD`` in a row.
COLD = "first pair"
#: The ms to build each sequence's estimator (before its first pair, not counted in its time): the startup a
#: device pays once, with the model's load (``model_load_ms``), before its first frame.
ESTIMATOR_START = "estimator start"


def run_pairs(estimator: Estimator, sequences, *, novel: bool, warmup: int, oracle=None,
              accuracy=None, track_from_truth: bool = False, pipeline: bool = False, first_pair_accuracy=None
              ) -> tuple[dict[str, list[float]], float]:
    """Run the estimator over every pair of every sequence (a fresh track per sequence).

    ``pipeline``: through a :class:`~ghnerf_runtime.pipeline.NovelViewPipeline` (each novel view finished while
    the next pair is estimated); a call's time counts for the pair it estimated, and the sequence's last view's
    wait counts for that pair too.

    ``track_from_truth``: before each pair (but the first of a sequence), the track is set from
    the previous pair's *true* joints, as a trained model's own joints would set it; this times
    the tracked path (smaller crops, subject rays only) with untrained weights.

    ``first_pair_accuracy``: scores each sequence's first pair alone (its cold start), warm-up or not: the
    warm-up is a matter of timing, and a row's first sequence would otherwise lose its first pair.

    Returns per-stage lists of ms (warm-up pairs excluded) and the wall time of the counted pairs;
    ``ESTIMATOR_START`` holds each sequence's estimator's build time, ``STEADY`` the totals of the pairs after
    each sequence's first (a stream's steady state: the first pair starts cold, and with
    ``tracking.refine_cold_start`` runs twice), ``f"{COLD} {key}"`` each counted first pair's stage ``key``.
    """
    stages: dict[str, list[float]] = {k: [] for k in (*KEYPOINT_STAGES, *NOVEL_STAGES, NOVEL_PAINT_STAGE, NOVEL_PROXY_STAGE,
                                                      NOVEL_MATTE_STAGE, "total")}
    steady: list[float] = []
    cold: dict[str, list[float]] = {k: [] for k in stages}
    request = NovelViewRequest(alpha=0.5) if novel else None
    wall = 0.0
    n = 0
    counted: set[tuple[int, int]] = set()  # (sequence, pair) past the warm-up

    def add(k_seq: int, seq, result) -> None:
        i = result.sequence
        if i == 0 and first_pair_accuracy is not None:
            first_pair_accuracy.add(result, seq, i)
        if (k_seq, i) not in counted:
            return
        _append_timings(stages, result.timing_ms)
        if i > 0:
            steady.append(result.timing_ms.get("total", 0.0))
        else:
            _append_timings(cold, result.timing_ms)
        if accuracy is not None:
            accuracy.add(result, seq, i)

    starts: list[float] = []
    for k_seq, seq in enumerate(sequences):
        t = time.perf_counter()
        est = Estimator(estimator.session, seq.rig, estimator.config)
        starts.append(1e3 * (time.perf_counter() - t))
        with est, NovelViewPipeline(est) as pipe:
            for i in range(len(seq)):
                images = (np.array(seq.images[i, 0]), np.array(seq.images[i, 1]))  # in RAM, as a driver delivers
                if oracle is not None:
                    oracle.set_truth(seq.joints_3d[i], seq.visible[i])
                if track_from_truth and i > 0:
                    est.tracker.track = track_from_joints(seq.joints_3d[i - 1], np.ones(25), np.ones(25, bool),
                                                          est.config.tracking, i - 1)
                t = time.perf_counter()
                kwargs = dict(sequence=i, novel_view=request, timestamp_s=i / float(seq.info.get("fps", 30.0)))
                results = pipe.submit(images, **kwargs) if pipeline else [est.estimate(images, **kwargs)]
                if pipeline and i == len(seq) - 1:
                    results += pipe.flush()
                dt = time.perf_counter() - t
                n += 1
                if n > warmup:
                    wall += dt
                    counted.add((k_seq, i))
                for result in results:
                    add(k_seq, seq, result)
    stages[STEADY] = steady
    stages[ESTIMATOR_START] = starts
    stages.update({f"{COLD} {k}": v for k, v in cold.items()})
    return stages, wall


def _append_timings(lists: dict[str, list[float]], timing_ms: dict[str, float]) -> None:
    """One pair's ms appended to each stage's list (0 for a stage the pair did not run)."""
    for k, values in lists.items():
        values.append(timing_ms.get(k, 0.0))


def _row(stages: dict[str, list[float]], wall: float) -> dict:
    from ghnerf_runtime.cli.simdata import percentiles

    out = _grouped(stages)
    out[STEADY] = percentiles(stages.get(STEADY, []))
    out[COLD] = _grouped(stages, f"{COLD} ")
    out[ESTIMATOR_START] = percentiles(stages.get(ESTIMATOR_START, []))
    count = len(stages["total"])
    out["pairs"] = count
    out["pairs_per_s"] = count / wall if wall > 0 else float("nan")
    return out


def _grouped(stages: dict[str, list[float]], prefix: str = "") -> dict:
    """Median and p99 of each ``STAGE_GROUPS`` column over the pairs of ``stages``' lists named ``prefix + key``."""
    from ghnerf_runtime.cli.simdata import percentiles

    have = bool(stages.get(prefix + "total"))
    return {name: percentiles(np.sum([stages.get(prefix + k, []) for k in keys], axis=0) if have else [])
            for name, keys in STAGE_GROUPS.items()}


def row_base_config(args, precision: str, source: str) -> EstimatorConfig:
    """One (precision, heatmap source) row's config before its on/off splits: the runtime's own defaults
    (``EstimatorConfig()``, what ``ghnerf-run`` and the daemon run without a config file) with only what the
    bench's options name set on them, so a row the options leave alone runs what the device runs."""
    runtime = EstimatorConfig()
    return replace(
        runtime,
        session=replace(runtime.session, model_dir=args.model_dir, precision=precision, threads=args.threads,
                        thread_pool=args.thread_pool, allow_spinning=args.allow_spinning),
        heatmaps=replace(runtime.heatmaps, source=source),
        joints3d=replace(runtime.joints3d, method=args.method or BEST_METHOD[source]),
        # loaded for every row, so the keypoints and novel rows of a source share one session
        novel_view=replace(runtime.novel_view, enabled=True, stride=args.novel_stride or runtime.novel_view.stride))


def _load_row_session(args, cfg: EstimatorConfig):
    """A row's session, a model folder it cannot use named by ``--model-dir`` (the session words it as
    ``session.model_dir``, which the bench has no way to set)."""
    try:
        return load_session(cfg)
    except ModelLoadError as e:
        where = model_dir_source(args.model_dir, None, cfg.session.model_dir)  # (the bench reads no config file)
        raise ModelLoadError(named_by_source(where, e, cfg.session.model_dir)) from None


class RenderPlanError(ValueError):
    """The sequences to render would not fit where they go (the cache's disk, or memory without a cache)."""


def announce_rendering(args) -> None:
    """Say what rendering the uncached sequences costs before it starts (``--sequences 10000`` was hours of
    silence, then a full disk), and refuse when they cannot fit: the cache's free disk, or with ``--cache off``
    (every image held in memory) the free memory."""
    from ghnerf_runtime.cli.simdata import sequence_bytes, sequence_cache_folder, sequences_to_render

    folder = sequence_cache_folder(args.sequences, args.frames, cache_dir=args.cache, seen_motions=args.seen_motions)
    count = sequences_to_render(folder, args.sequences)
    if count == 0:
        return
    needed = count * sequence_bytes(args.frames)
    where = f"in {folder}" if folder is not None else "in memory (--cache off)"
    print(f"rendering {count} of {args.sequences} sequences x {args.frames} pairs first: about "
          f"{count * args.frames * RENDER_S_PER_PAIR / 60:.1f} min, {needed / 1e9:.2f} GB {where}", flush=True)
    free = _free_bytes(folder)
    if needed > free:
        raise RenderPlanError(f"--sequences {args.sequences} --frames {args.frames}: {needed / 1e9:.1f} GB of "
                              f"images to render {where}, but {free / 1e9:.1f} GB is free there; fewer or "
                              "shorter sequences, or --cache on a bigger disk")


#: seconds to render one pair (two 640x480 views): 0.03-0.04 s on session 63's host (-v logs each sequence's)
RENDER_S_PER_PAIR = 0.04


def available_memory_bytes(meminfo: str = "/proc/meminfo") -> int:
    """Memory a new allocation can have: Linux's ``MemAvailable``, which counts the page cache the kernel gives
    back. Free pages alone (``SC_AVPHYS_PAGES``) leave that cache out, so a host whose files fill its memory (a
    Raspberry Pi after a take was copied) read a few hundred MB free and ``--cache off`` was refused; they are
    the answer only where ``meminfo`` has no such line."""
    try:
        with open(meminfo, encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024  # (kB)
    except (OSError, ValueError, IndexError):
        pass
    return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def _free_bytes(folder) -> int:
    """Free space where the sequences go: the cache folder's disk (its nearest existing parent), else memory."""
    if folder is None:
        return available_memory_bytes()
    return shutil.disk_usage(existing_ancestor(folder)).free


def run_runtime_bench(args) -> dict:
    """Every (precision, heatmap source, mode) row, interleaved sequence by sequence.

    This shared machine runs 10-20 % faster or slower for tens of seconds at a time; running
    the rows one after another would hand each row a different machine. Instead each sequence
    is run by every row in turn (the order rotating from one sequence to the next), so every
    row sees the same mix of fast and slow spells and the rows compare. The first ``warmup``
    pairs of each row are not counted.
    """
    from ghnerf_runtime.cli.simdata import Accuracy, depth_per_disparity_px, load_sequences

    # The model and every row's config first (a missing model folder, --threads 0, a bad interior stride), the
    # sequences after: those take minutes to render on a cold cache, and an error named after them wasted those.
    load_average_start = os.getloadavg()
    model_desc = None
    rows = []
    for precision, source in itertools.product(args.precisions, args.heatmap_sources):
        cfg = row_base_config(args, precision, source)
        t_load = time.perf_counter()
        session = _load_row_session(args, cfg)
        model_load_ms = 1e3 * (time.perf_counter() - t_load)
        model_desc = session.describe()
        flips = (args.flip_tests or [None]) if source == "encoder" else [None]
        follows = (args.follow_encoder or [None]) if source == "rendered" else [None]
        priors = (args.skeleton_priors or [None]) if cfg.joints3d.method == "triangulate" else [None]
        prior_flips = (args.prior_flip_tests or [None]) if cfg.joints3d.method == "triangulate" else [None]
        smooths = args.smoothing or [None]
        presences = args.presence_gates or [None]
        # the search scores the turns by the encoder heatmaps: a model without them refuses it (no row)
        searches = (args.turn_searches or [None]) if getattr(session.contract, "encoder_heatmaps", False) else [None]
        sides = (args.flip_side_by_side or [None]) if source == "encoder" else [None]
        refines = args.refine_cold_starts or [None]
        # the scan reads the encoder heatmaps too: a model without them refuses it (no row)
        scans = (args.scan_every_s or [None]) if getattr(session.contract, "encoder_heatmaps", False) else [None]
        for mode, flip, follow, prior, prior_flip, smooth, side, presence, search, refine, scan in itertools.product(
                args.modes, flips, follows, priors, prior_flips, smooths, sides, presences, searches, refines,
                scans):
            if flip is False and side is not None and side != sides[0]:
                continue  # without the flip test there is nothing to run side by side: one row
            if prior is False and prior_flip is not None and prior_flip != prior_flips[0]:
                continue  # without the prior its flip test changes nothing: one row
            flip_cfg = cfg if flip is None else replace(cfg, heatmaps=replace(cfg.heatmaps, flip_test=flip))
            if prior is not None:
                flip_cfg = replace(flip_cfg, joints3d=replace(flip_cfg.joints3d,
                                                              skeleton_prior="on" if prior else "off"))
            if prior_flip is not None:
                flip_cfg = replace(flip_cfg, joints3d=replace(flip_cfg.joints3d, prior_flip_test=prior_flip))
            if follow is not None:
                flip_cfg = replace(flip_cfg, tracking=replace(flip_cfg.tracking, follow_encoder=follow))
            if smooth is not None:
                flip_cfg = replace(flip_cfg, smoothing=replace(flip_cfg.smoothing, enabled=smooth))
            if presence is not None:
                flip_cfg = replace(flip_cfg, presence=replace(flip_cfg.presence, enabled=presence))
            if scan is not None:
                flip_cfg = replace(flip_cfg, presence=replace(flip_cfg.presence, scan_every_s=scan))
            if side is not None:
                flip_cfg = replace(flip_cfg, heatmaps=replace(flip_cfg.heatmaps, flip_test_side_by_side=side))
            if search is not None:
                flip_cfg = replace(flip_cfg, roi=replace(flip_cfg.roi, turn_search=search))
            if refine is not None:
                flip_cfg = replace(flip_cfg, tracking=replace(flip_cfg.tracking, refine_cold_start=refine))
            novel_rows = itertools.product(args.novel_interior_strides or [None], args.proxy_blends or [None],
                                           args.painters or [None], args.novel_pipelines or [None],
                                           args.novel_lanes or [None]) \
                if mode == "novel" else [(None, None, None, None, None)]
            for interior, blend, paint, piped, lanes in novel_rows:
                row_cfg = flip_cfg if interior is None else \
                    replace(flip_cfg, novel_view=replace(flip_cfg.novel_view, interior_stride=interior))
                if blend is not None:
                    row_cfg = replace(row_cfg, novel_view=replace(row_cfg.novel_view, proxy_blend=blend))
                if paint is not None:
                    row_cfg = replace(row_cfg, novel_view=replace(row_cfg.novel_view, painter="on" if paint else "off"))
                if lanes is not None:
                    row_cfg = replace(row_cfg, novel_view=replace(row_cfg.novel_view, lanes=lanes))
                rows.append({"precision": precision, "source": source, "mode": mode, "cfg": row_cfg,
                             "session": session, "stages": {}, "wall": 0.0, "accuracy": Accuracy(), "seen": 0,
                             "model_load_ms": model_load_ms,
                             "first_pair_accuracy": Accuracy(),
                             "flip_label": flip is not None, "follow_label": follow is not None,
                             "prior_label": prior is not None, "prior_flip_label": prior_flip is not None,
                             "smoothing_label": smooth is not None, "proxy_label": blend is not None,
                             "presence_label": presence is not None, "turn_search_label": search is not None,
                             "side_label": side is not None, "refine_label": refine is not None,
                             "scan_label": scan is not None,
                             "painter_label": paint is not None,
                             "pipeline": bool(piped), "pipeline_label": piped is not None,
                             "lanes_label": lanes is not None})
    announce_rendering(args)
    sequences = load_sequences(args.sequences, args.frames, cache_dir=args.cache, seen_motions=args.seen_motions)
    depth_per_px = [1000 * depth_per_disparity_px(s.rig, s.info["distance_m"]) for s in sequences]
    baselines = [s.rig.baseline for s in sequences]
    print(f"rigs: baseline {min(baselines):.2f}-{max(baselines):.2f} m, "
          f"subject at {min(s.info['distance_m'] for s in sequences):.1f}-"
          f"{max(s.info['distance_m'] for s in sequences):.1f} m: 1 px of disparity error there is "
          f"{min(depth_per_px):.0f}-{max(depth_per_px):.0f} mm of depth (median {np.median(depth_per_px):.0f}; "
          f"z^2 / (f b))", flush=True)
    report = {"model_dir": args.model_dir, "thread_pool": args.thread_pool, "allow_spinning": args.allow_spinning,
              "pairs_per_run": sum(len(s) for s in sequences) - args.warmup, "interleaved": True,
              "sequences": [{**s.info, "depth_mm_per_disparity_px": d} for s, d in zip(sequences, depth_per_px)],
              "method": args.method, "runs": [], "model": model_desc,
              "load_average_start": load_average_start, "cpus": os.cpu_count()}
    loads = []
    for k, seq in enumerate(sequences):
        for row in rows[k % len(rows):] + rows[:k % len(rows)]:
            est = Estimator(row["session"], seq.rig, row["cfg"])  # run_pairs makes one per sequence from it
            warmup = max(0, args.warmup - row["seen"])
            stages, wall = run_pairs(est, [seq], novel=(row["mode"] == "novel"), warmup=warmup,
                                     accuracy=row["accuracy"], track_from_truth=args.track_from_truth,
                                     pipeline=row["pipeline"], first_pair_accuracy=row["first_pair_accuracy"])
            row["seen"] += len(seq)
            row["wall"] += wall
            for key, values in stages.items():
                row["stages"].setdefault(key, []).extend(values)
        loads.append(os.getloadavg()[0])
    for row in rows:
        cfg, session = row["cfg"], row["session"]
        out = {"precision": row["precision"], "mode": "keypoints" if row["mode"] == "keypoints" else "keypoints+novel",
               "heatmaps": row["source"], "method": cfg.joints3d.method, "track_from_truth": args.track_from_truth,
               "flip_test": cfg.flips_encoder_heatmaps, "flip_label": row["flip_label"],
               "follow_encoder": cfg.tracking.follow_encoder, "follow_label": row["follow_label"],
               "skeleton_prior": cfg.joints3d.uses_skeleton_prior(getattr(session, "skeleton_prior", None) is not None),
               "prior_label": row["prior_label"], "prior_flip_test": cfg.joints3d.prior_flip_test,
               "prior_flip_label": row["prior_flip_label"],
               "smoothing": cfg.smoothing.enabled, "smoothing_label": row["smoothing_label"],
               "presence": cfg.presence.enabled, "presence_label": row["presence_label"],
               # as the estimator ran it: unset (the default), on where the model has encoder heatmaps
               "turn_search": cfg.roi.search_for(getattr(session.contract, "encoder_heatmaps", False)).turn_search,
               "turn_search_label": row["turn_search_label"],
               "flip_side_by_side": cfg.heatmaps.flip_test_side_by_side, "side_label": row["side_label"],
               "refine_cold_start": cfg.tracking.refine_cold_start, "refine_label": row["refine_label"],
               "scan_every_s": cfg.presence.scan_every_s, "scan_label": row["scan_label"],
               **({"novel_stride": cfg.novel_view.stride, "novel_interior_stride": cfg.novel_view.interior_stride,
                   "proxy_blend": cfg.novel_view.proxy_blend, "proxy_label": row["proxy_label"],
                   "painter": cfg.novel_view.uses_painter(getattr(session, "novel_painter", None) is not None),
                   "painter_label": row["painter_label"],
                   "pipeline": row["pipeline"], "pipeline_label": row["pipeline_label"],
                   "novel_lanes": cfg.novel_view.lanes, "lanes_label": row["lanes_label"]}
                  if row["mode"] == "novel" else {}),
               "files": {g: f.precision for g, f in session.files.items()}, **_row(row["stages"], row["wall"]),
               "model_load_ms": row["model_load_ms"],
               "accuracy": row["accuracy"].summary(),
               "accuracy_first_pair": _first_pair_summary(row["first_pair_accuracy"]),
               "load_average": float(np.mean(loads))}
        report["runs"].append(out)
        _print_row(out)
    return report


def _first_pair_summary(accuracy) -> dict:
    """The first pairs' accuracy with their count (no jitter: one pair per sequence chains no frames)."""
    summary = accuracy.summary()
    summary.pop("jitter_mm", None)
    summary.pop("jitter_evaluated", None)
    return {**summary, "pairs": len(accuracy.p3)} if summary else {}


def _print_row(row: dict) -> None:
    cols = _columns(row)
    if STEADY in row:
        cols += f" (after the first {row[STEADY]['median']:.2f}/{row[STEADY]['p99']:.2f})"
    tracked = " (tracked from truth)" if row.get("track_from_truth") else ""
    if row.get("flip_label"):
        tracked += " flip" if row["flip_test"] else " no-flip"
    if row.get("follow_label"):
        tracked += " follow-enc" if row["follow_encoder"] else " follow-own"
    if row.get("prior_label"):
        tracked += " prior" if row["skeleton_prior"] else " no-prior"
    if row.get("prior_flip_label") and row.get("skeleton_prior"):
        tracked += " prior-flip" if row["prior_flip_test"] else " prior-no-flip"
    if row.get("smoothing_label"):
        tracked += " smooth" if row["smoothing"] else " no-smooth"
    if row.get("presence_label"):
        tracked += " presence" if row["presence"] else " no-presence"
    if row.get("turn_search_label"):
        tracked += " turn-search" if row["turn_search"] else " no-turn-search"
    if row.get("side_label") and row.get("flip_test"):
        tracked += " flip-side-by-side" if row["flip_side_by_side"] else " flip-in-turn"
    if row.get("refine_label"):
        tracked += " refine-cold" if row["refine_cold_start"] else " no-refine-cold"
    if row.get("scan_label"):
        tracked += f" scan/{row['scan_every_s']:g}s" if row["scan_every_s"] else " no-scan"
    if row.get("proxy_label"):
        tracked += " proxy-blend" if row["proxy_blend"] else " no-proxy-blend"
    if row.get("painter_label"):
        tracked += " painter" if row["painter"] else " no-painter"
    if row.get("lanes_label"):
        tracked += " lanes" if row["novel_lanes"] else " no-lanes"
    if row.get("pipeline_label"):
        tracked += " pipelined" if row["pipeline"] else " one-by-one"
    if row.get("novel_interior_stride") and row["novel_interior_stride"] > row.get("novel_stride", 1):
        tracked += f" interior/{row['novel_interior_stride']}"
    acc = row["accuracy"]
    print(f"{row['precision']:>4} {row['heatmaps']:>8}/{row['method']:<14} {row['mode'] + tracked:<16} "
          f"ms median/p99: {cols} | "
          f"{row['pairs_per_s']:.1f} pairs/s | "
          f"PCK@0.2 {acc.get('pck@0.2', float('nan')):.3f} MPJPE {acc.get('mpjpe_mm', float('nan')):.1f} mm "
          f"(3D found {acc.get('found_3d_frac', float('nan')):.2f}) jitter {acc.get('jitter_mm', float('nan')):.1f} "
          f"mm/pair^2 | load {row['load_average']:.2f}", flush=True)
    if by := acc.get("mpjpe_by_visibility"):
        print("      MPJPE by the cameras that see the joint: " + ", ".join(
            f"{name.replace('_', ' ')} {c['mpjpe_mm']:.1f} mm ({100 * c['share']:.0f} % of joints, "
            f"{100 * c['found']:.0f} % found, confidence median {c.get('confidence_median', float('nan')):.2f})"
            for name, c in by.items()), flush=True)
    if first := row.get("accuracy_first_pair"):  # the cold start alone: what tracking.refine_cold_start acts on
        print(f"      each sequence's first pair ({first['pairs']} pairs): PCK@0.2 "
              f"{first.get('pck@0.2', float('nan')):.3f} MPJPE {first['mpjpe_mm']:.1f} mm "
              f"(3D found {first['found_3d_frac']:.2f})", flush=True)
    if (cold := row.get(COLD)) and not math.isnan(cold["total"]["median"]):
        print(f"      each sequence's first pair past the warm-up, ms median/p99: {_columns(cold)}", flush=True)
    if start := row.get(ESTIMATOR_START):
        print(f"      startup, not counted in the pairs: the model loaded in {row['model_load_ms']:.0f} ms (warm-up "
              f"runs included), each sequence's estimator built in {start['median']:.1f} ms median (p99 "
              f"{start['p99']:.1f})", flush=True)
    if e2 := acc.get("error_2d_px"):
        print(f"      2D error of the visible joints decoded: median {e2['median']:.1f} px, p90 {e2['p90']:.1f} px "
              f"(original image pixels)", flush=True)
    if sw := acc.get("left_right_swaps"):
        views = enumerate(zip(sw["by_view"], sw["by_view_evaluated"]))
        print("      left/right pairs swapped in 2D: " + ", ".join(
            f"view {c} {_percent(f, 1)} ({n} pairs)" for c, (f, n) in views)
            + f" of the pairs decoded there; in every view alike {_percent(sw['all_views_frac'], 2)} "
              f"({sw['all_views_evaluated']} pairs)", flush=True)


def _columns(groups: dict) -> str:
    """``"preprocess 1.20/3.40 encoders ..."``: each ``STAGE_GROUPS`` column's median/p99 ms."""
    return " ".join(f"{name.split(' ')[0]} {groups[name]['median']:.2f}/{groups[name]['p99']:.2f}"
                    for name in STAGE_GROUPS)


def _percent(share: float, digits: int) -> str:
    """``"12.5 %"``; ``"n/a"`` for the nan share of no pairs."""
    return f"{100 * share:.{digits}f} %" if np.isfinite(share) else "n/a"


def _refuse_repeats(items: list, text: str) -> list:
    """A comma list's items, refused when one comes twice: each item is a row (or a set of rows), and a repeated
    one ran the same rows again under the same label, a table of lookalike rows at twice the cost."""
    if repeated := sorted({_as_typed(v) for v in items if items.count(v) > 1}):
        raise argparse.ArgumentTypeError(f"{text!r}: {', '.join(repeated)} given twice: each value is a row, "
                                         "give it once")
    return items


def _as_typed(value) -> str:
    """An item as the help spells it: on/off for a boolean (``on,1`` repeats on)."""
    if isinstance(value, bool):
        return "on" if value else "off"
    return str(value)


def _word_list(text: str) -> list[str]:
    """A comma list of words; empty items (``int8,,fp32``) are left out."""
    return _refuse_repeats([p for p in text.split(",") if p], text)


def _on_off_list(text: str) -> list[bool]:
    words = {"1": True, "on": True, "0": False, "off": False}
    if bad := [p for p in text.split(",") if p and p not in words]:
        raise argparse.ArgumentTypeError(f"{bad}: expected on, off, 1 or 0")
    return _refuse_repeats([words[p] for p in text.split(",") if p], text)


def _seconds_list(text: str) -> list[float]:
    try:  # ASCII and finite: float() took '\u0663' and '1_0' as numbers
        values = [finite_number(p) for p in text.split(",") if p]
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a comma list of seconds") from None
    if any(v < 0 for v in values):
        raise argparse.ArgumentTypeError(f"{text!r}: seconds must be finite and 0 or more")
    return _refuse_repeats(values, text)


def _int_list(text: str) -> list[int]:
    try:  # ASCII digits: int() took '\u0662' as 2
        values = [ascii_integer(p) for p in text.split(",") if p]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a comma list of integers") from None
    return _refuse_repeats(values, text)


# the options that set only the novel rows: given without a novel mode, nothing would use them
NOVEL_ONLY_OPTIONS = ("novel_stride", "novel_interior_strides", "proxy_blends", "painters", "novel_pipelines",
                      "novel_lanes")


def novel_option_error(args) -> str | None:
    """Why the novel-only options cannot run as given, or None: a novel-only option without the novel mode
    (ghnerf-run refuses its novel options without --novel-view alike), or an interior stride the runtime's
    config refuses. Checked before the model loads, whatever the modes: a bad value is never passed over."""
    runtime = EstimatorConfig().novel_view
    for interior in args.novel_interior_strides or []:
        try:
            replace(runtime, enabled=True, stride=args.novel_stride or runtime.stride, interior_stride=interior)
        except ConfigError as e:
            return f"--novel-interior-strides {interior}: {e}"
    given = ["--" + name.replace("_", "-") for name in NOVEL_ONLY_OPTIONS if getattr(args, name) is not None]
    if given and "novel" not in args.modes:
        return (f"{', '.join(given)} without the novel mode (--modes {','.join(args.modes)}): there is no novel "
                "row to apply it to; add novel to --modes")
    return None


def _configs(value) -> str:
    """A default of the runtime's config as the help says it: on/off for a boolean, unset for None."""
    if isinstance(value, bool):
        return "the config's, " + ("on" if value else "off")
    return "the config's, " + ("unset" if value is None else str(value))


def _best_methods() -> str:
    return ", ".join(f"{method} with {source} heatmaps" for source, method in BEST_METHOD.items())


def build_parser() -> argparse.ArgumentParser:
    from ghnerf_runtime.cli.simdata import SEQUENCE_CACHE_HELP

    # every "the config's" default below is read from the runtime's own defaults, never restated
    runtime = EstimatorConfig()
    ap = argparse.ArgumentParser(prog="ghnerf-bench", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    rt = sub.add_parser("runtime", help="per-stage latency and accuracy of the estimator")
    rt.add_argument("--model-dir", type=user_path, default="models", help="model folder (default: %(default)s)")
    rt.add_argument("--sequences", type=int, default=10, help="held-out-like sequences (one rig and subject each)")
    rt.add_argument("--frames", type=int, default=30, help="pairs per sequence (30 fps)")
    # the defaults are named: every precision and both modes make six rows a source, which a reader should expect
    rt.add_argument("--precisions", default="fp32,int8,auto", type=_word_list,
                    help="comma list of graph precisions, one row each (default: %(default)s)")
    rt.add_argument("--modes", default="keypoints,novel", type=_word_list,
                    help="comma list of keypoints (keypoints alone), novel (keypoints and the novel view), one row "
                         "each (default: %(default)s)")
    rt.add_argument("--method", choices=THREE_D_METHODS,
                    help=f"3D method (default: each source's best, {_best_methods()}; the runtime's "
                         f"joints3d.method is {runtime.joints3d.method})")
    rt.add_argument("--heatmap-sources", default=runtime.heatmaps.source,
                    type=_word_list,
                    help=f"comma list of {','.join(HEATMAP_SOURCES)}, one set of rows each (default: %(default)s, "
                         "the runtime's heatmaps.source, what the device runs; rendered scores the heatmaps "
                         "rendered through the depth volume)")
    # None when not given, so a novel-only option given without a novel row is told apart from its default
    rt.add_argument("--novel-stride", type=int, default=None, choices=(1, 2, 4),
                    help=f"novel_view.stride of the novel rows (default: {_configs(runtime.novel_view.stride)})")
    rt.add_argument("--novel-interior-strides", default=None, type=_int_list,
                    help="comma list of novel_view.interior_stride values, one keypoints+novel row each "
                         f"(interleaved like the other rows; default: {_configs(runtime.novel_view.interior_stride)})")
    rt.add_argument("--flip-tests", default=None,
                    type=_on_off_list,
                    help="comma list of heatmaps.flip_test values (on,off or 1,0), one row each for the encoder "
                         f"heatmaps (interleaved like the other rows; default: {_configs(runtime.heatmaps.flip_test)})")
    rt.add_argument("--follow-encoder", default=None, type=_on_off_list,
                    help="comma list of tracking.follow_encoder values (on,off), one row each for the rendered "
                         f"heatmaps (interleaved; default: {_configs(runtime.tracking.follow_encoder)})")
    rt.add_argument("--skeleton-priors", default=None, type=_on_off_list,
                    help="comma list of joints3d.skeleton_prior values (on,off), one row each for triangulation "
                         f"(interleaved; default: {_configs(runtime.joints3d.skeleton_prior)}; auto: on when the "
                         "model folder has the prior)")
    rt.add_argument("--prior-flip-tests", default=None, type=_on_off_list,
                    help="comma list of joints3d.prior_flip_test values (on,off), one row each for triangulation "
                         "with the skeleton prior (interleaved; default: "
                         f"{_configs(runtime.joints3d.prior_flip_test)})")
    rt.add_argument("--smoothing", default=None, type=_on_off_list,
                    help="comma list of smoothing.enabled values (on,off), one row each (interleaved; default: "
                         f"{_configs(runtime.smoothing.enabled)})")
    rt.add_argument("--presence-gates", default=None, type=_on_off_list,
                    help="comma list of presence.enabled values (on,off), one row each (interleaved; default: "
                         f"{_configs(runtime.presence.enabled)}). A pair the gate says shows nobody has no novel "
                         "view: off views every pair")
    rt.add_argument("--turn-searches", default=None, type=_on_off_list,
                    help="comma list of roi.turn_search values (on,off), one row each (interleaved; default: "
                         f"{_configs(runtime.roi.turn_search)}: on for a model with encoder heatmaps, off for one "
                         "without, which gets no such rows)")
    rt.add_argument("--scan-every-s", default=None, type=_seconds_list, metavar="SECONDS",
                    help="comma list of presence.scan_every_s values (0: off), one row each (interleaved; default: "
                         f"the config's {runtime.presence.scan_every_s:g}): the working volume scanned for anyone "
                         "besides the tracked subject that often, its time in the encoders column (stage 'scan'); "
                         "a model without encoder heatmaps gets no such rows")
    rt.add_argument("--flip-side-by-side", default=None, type=_on_off_list,
                    help="comma list of heatmaps.flip_test_side_by_side values (on,off), one row each for the "
                         "encoder heatmaps with the flip test (interleaved; default: "
                         f"{_configs(runtime.heatmaps.flip_test_side_by_side)})")
    rt.add_argument("--refine-cold-starts", default=None, type=_on_off_list,
                    help="comma list of tracking.refine_cold_start values (on,off), one row each (interleaved; "
                         f"default: {_configs(runtime.tracking.refine_cold_start)}: a cold pair that finds the "
                         "subject runs again on it)")
    rt.add_argument("--proxy-blends", default=None, type=_on_off_list,
                    help="comma list of novel_view.proxy_blend values (on,off), one novel row each (default: "
                         f"{_configs(runtime.novel_view.proxy_blend)})")
    rt.add_argument("--painters", default=None, type=_on_off_list,
                    help="comma list of novel_view.painter values (on,off), one novel row each; on needs the model "
                         f"folder's novel_painter.onnx (default: {_configs(runtime.novel_view.painter)})")
    rt.add_argument("--novel-pipelines", default=None, type=_on_off_list,
                    help="comma list of on,off: one novel row each run through ghnerf_runtime.pipeline."
                         "NovelViewPipeline (each pair's view finished while the next pair is estimated) or "
                         "one pair at a time (default: one at a time)")
    rt.add_argument("--novel-lanes", default=None, type=_on_off_list,
                    help="comma list of novel_view.lanes values (on,off), one novel row each (default: "
                         f"{_configs(runtime.novel_view.lanes)})")
    rt.add_argument("--threads", type=int, default=runtime.session.threads,
                    help="onnxruntime intra-op threads (default: %(default)s)")
    rt.add_argument("--thread-pool", default=runtime.session.thread_pool, choices=("per_session", "global"))
    rt.add_argument("--allow-spinning", action="store_true", help="per-session pools whose workers spin")
    rt.add_argument("--warmup", type=int, default=10, help="pairs not counted at the start of each run")
    rt.add_argument("--track-from-truth", action="store_true",
                    help="place each crop from the previous pair's true joints (times the tracked path with an "
                         "untrained model; accuracy is then not the estimator's own)")
    rt.add_argument("--seen-motions", action="store_true", help="training motions instead of the held-out ones")
    rt.add_argument("--cache", type=user_path, help=SEQUENCE_CACHE_HELP)
    rt.add_argument("--json", type=user_path, help="write the full report here")
    sp = sub.add_parser("sim-pair", help="write a simulated pair (or short clip) and its rig file")
    sp.add_argument("--out", type=user_path, required=True)
    sp.add_argument("--frames", type=int, default=1, help="at least 1; >1 writes <camera>.mp4 clips instead of PNGs")
    sp.add_argument("--seed", type=int, default=3)
    sp.add_argument("--motion", default="wave")
    sp.add_argument("--t", type=float, default=0.4, help="scene time of the first frame (s)")
    ap.add_argument("-v", "--verbose", action="store_true")
    return ap


def _sim_pair(args) -> int:
    """``sim-pair``: the simulator's errors (an unknown ``--motion``...) are bad input: exit 2 with the message."""
    from drivers.errors import DriverError  # tool only: the runtime library never imports drivers
    from ghnerf_runtime.cli.simdata import write_sim_example

    if args.frames < 1:
        print(f"ghnerf-bench: error: --frames must be at least 1, got {args.frames}", file=sys.stderr)
        return 2
    try:  # a path through a file or a link to nothing: was OSError's bare "[Errno 17] File exists"
        ready_output(args.out, "--out", "folder")
    except OutputPathError as e:
        print(f"ghnerf-bench: error: {e}", file=sys.stderr)
        return 2
    try:
        paths = write_sim_example(args.out, seed=args.seed, motion=args.motion, t=args.t, frames=args.frames)
    except DriverError as e:
        print(f"ghnerf-bench: error: {e}", file=sys.stderr)
        return 2
    print(json.dumps(paths, indent=2))
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        if args.command == "sim-pair":
            return _sim_pair(args)
        # an empty list would leave no row to run, found only after the sequences are rendered
        if not args.heatmap_sources or any(h not in HEATMAP_SOURCES for h in args.heatmap_sources):
            print(f"ghnerf-bench: error: heatmap sources are {','.join(HEATMAP_SOURCES)}", file=sys.stderr)
            return 2
        bad = [p for p in args.precisions if p not in ("fp32", "int8", "auto")]
        if (bad or not args.precisions or not args.modes
                or any(m not in ("keypoints", "novel") for m in args.modes)):
            print("ghnerf-bench: error: precisions are fp32,int8,auto and modes keypoints,novel", file=sys.stderr)
            return 2
        if why := novel_option_error(args):
            print(f"ghnerf-bench: error: {why}", file=sys.stderr)
            return 2
        if args.sequences < 1 or args.frames < 1 or args.warmup < 0:
            print("ghnerf-bench: error: --sequences and --frames must be at least 1, --warmup at least 0",
                  file=sys.stderr)
            return 2
        if args.sequences * args.frames <= args.warmup:
            print(f"ghnerf-bench: error: {args.sequences} x {args.frames} pairs leave none after --warmup "
                  f"{args.warmup}: nothing would be timed", file=sys.stderr)
            return 2
        if clash := model_file_clash({"--json": args.json}, args.model_dir, f"--model-dir {args.model_dir}"):
            print(f"ghnerf-bench: error: {clash}", file=sys.stderr)
            return 2
        if args.json:  # written after the whole bench: its place is settled first
            args.json = ready_output(args.json, "--json")
        if args.cache and args.cache != "off":  # a file there was "[Errno 20] Not a directory: '<it>/seq-...'"
            ready_output(args.cache, "--cache", "folder")
        print(f"load average {os.getloadavg()}, {os.cpu_count()} CPUs; model {args.model_dir}", flush=True)
        report = run_runtime_bench(args)
        if args.json:  # whole or not at all (an earlier report left as it was): a Ctrl-C in the write cut it short
            text = strict_json(report, indent=2)  # NaN becomes null
            write_text_atomic(args.json, text + "\n")
        return 0
    except BrokenPipeError:  # `ghnerf-bench ... | head`: was "error: [Errno 32] Broken pipe" and status 2
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit's flush
        if args.command == "runtime" and args.json:  # asked for, and the bench ended before writing it
            print("ghnerf-bench: stopped: stdout was closed; no report written", file=sys.stderr)
            return 2
        return 0
    except (RuntimeErrorBase, OSError, OutputPathError, RenderPlanError) as e:
        print(f"ghnerf-bench: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # the --json report is written only when the bench ends: nothing half-written
        print("ghnerf-bench: stopped (Ctrl-C); no report written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
