"""How latency falls with the region rendered and with the outputs requested.

    .venv/bin/python benchmarks/bench_runtime_regions.py --model-dir models [--repeats 40]

Part 1, per graph: ``render_heat`` (the two source views, B = 2) and ``render_rgb`` (one novel
view, B = 1) timed against the number of rays, i.e. the side of the square block of the ray
grid that covers the subject (the whole grid is the untracked case).

Part 2, end to end on held-out-like sequences with the subject *tracked from the truth* (the
previous pair's true joints place the crop, as the trained model's own joints would; random
weights never find a subject, so without this the tracked path would not run): keypoints only
with all rays vs the subject's rays, and with each extra output (novel view at stride 2 / 1,
colour + heatmaps, volumetric 3D). Prints medians and p99 in ms. Not a test.
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

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from ghnerf_runtime.cli.bench import STAGE_GROUPS  # noqa: E402
from ghnerf_runtime.cli.simdata import SEQUENCE_CACHE_HELP, load_sequences, percentiles  # noqa: E402
from ghnerf_runtime.config import (  # noqa: E402
    EstimatorConfig,
    HeatmapsConfig,
    Joints3DConfig,
    NovelViewConfig,
    RaysConfig,
    SessionConfig,
)
from ghnerf_runtime.contract import GRAPH_NAMES  # noqa: E402
from ghnerf_runtime.estimator import Estimator  # noqa: E402
from ghnerf_runtime.novel_view import NovelViewRequest  # noqa: E402
from ghnerf_runtime.rays import block_ray_uv  # noqa: E402
from ghnerf_runtime.session import ModelSession, warmup_feeds  # noqa: E402
from ghnerf_runtime.tracking import track_from_joints  # noqa: E402

#: Every stage of the novel view (graphs, proxy, painter, matte, compose): ghnerf-bench's "novel view" column.
NOVEL_VIEW_STAGES = STAGE_GROUPS["novel view"]


def _time(fn, repeats: int) -> dict:
    fn()
    fn()
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        ts.append(1e3 * (time.perf_counter() - t))
    return percentiles(ts)


def graph_scaling(session: ModelSession, repeats: int) -> None:
    c = session.contract
    S, stride = c.height, c.heatmap_stride
    grid = S // stride
    two = warmup_feeds(c, targets=2)
    two.update(session.run("encoder", two))
    two.update(session.run("volume", two))
    print(f"\nrender_heat, B=2 (both sources), {session.precision('render_heat')}: rays per view -> ms median / p99")
    for side in sorted({max(2, grid // 4), grid // 2, (3 * grid) // 8, (5 * grid) // 8, (3 * grid) // 4, grid}):
        r0 = (grid - side) // 2
        two["ray_uv"] = np.stack([block_ray_uv((r0, r0, side, side), stride)] * 2)
        p = _time(lambda: session.run("render_heat", two), repeats)
        print(f"  {side:>3}x{side:<3} = {side * side:>5} rays ({100 * side * side / grid ** 2:5.1f} %): "
              f"{p['median']:6.2f} / {p['p99']:6.2f}", flush=True)
    if not session.has("render_rgb"):
        return
    one = warmup_feeds(c, targets=1, ray_stride=1)
    one.update({k: two[k] for k in ("feat_s1", "feat_s2", "feat_s4", "human_feat") if k in two})
    one.update(session.run("volume", one))
    print(f"\nrender_rgb, B=1 (novel view), {session.precision('render_rgb')}: rays -> ms median / p99")
    for side in (S // 4, (3 * S) // 8, S // 2, (5 * S) // 8, (3 * S) // 4, S):
        r0 = (S - side) // 2
        one["ray_uv"] = block_ray_uv((r0, r0, side, side), 1)[None]
        p = _time(lambda: session.run("render_rgb", one), repeats)
        print(f"  {side:>3}x{side:<3} = {side * side:>5} rays ({100 * side * side / S ** 2:5.1f} %): "
              f"{p['median']:6.2f} / {p['p99']:6.2f}", flush=True)


def end_to_end(session: ModelSession, sequences, warmup: int) -> None:
    # the ray-region experiment is about rendered heatmaps; the default encoder path is the last rows
    base = EstimatorConfig(heatmaps=HeatmapsConfig(source="rendered"), joints3d=Joints3DConfig(method="depth_centroid"),
                           novel_view=NovelViewConfig(enabled=True))
    encoder = replace(base, heatmaps=HeatmapsConfig(source="encoder", flip_test=False),  # as docs/runtime.md measured it
                      joints3d=Joints3DConfig(method="triangulate"))
    cases = [
        ("keypoints, all rays (untracked crop)", base, None, False),
        ("keypoints, all rays", replace(base, rays=RaysConfig(restrict_to_subject=False)), None, True),
        ("keypoints, subject rays", base, None, True),
        ("+ novel view stride 2, subject rays", replace(base, novel_view=NovelViewConfig(enabled=True, stride=2)),
         NovelViewRequest(), True),
        ("+ novel view stride 1, all rays", replace(base, novel_view=NovelViewConfig(enabled=True,
                                                                                   rays_in_box_only=False)),
         NovelViewRequest(), True),
        ("+ novel view stride 1, subject rays", base, NovelViewRequest(), True),
        ("+ novel view colour+heatmaps (render)", replace(base, novel_view=NovelViewConfig(enabled=True,
                                                                                          heatmaps=True)),
         NovelViewRequest(overlay="heatmap"), True),
        ("keypoints, volumetric 3D (query 16^3)", replace(base, joints3d=Joints3DConfig(method="volumetric")),
         None, True),
        ("encoder heatmaps (default): keypoints", encoder, None, True),
        ("encoder heatmaps: + novel view stride 1", encoder, NovelViewRequest(), True),
        ("encoder heatmaps: + novel view stride 2", replace(encoder, novel_view=NovelViewConfig(enabled=True, stride=2)),
         NovelViewRequest(), True),
    ]
    print(f"\nend to end over {sum(len(s) for s in sequences)} pairs ({warmup} warm-up), ms median / p99 "
          "[render_heat, novel, total], pairs/s:")
    for label, cfg, request, truth_track in cases:
        if cfg.novel_view.heatmaps and not session.has("render"):
            continue
        if cfg.joints3d.method == "volumetric" and not session.has("query"):
            continue
        heat, novel, total = [], [], []
        n, wall = 0, 0.0
        for seq in sequences:
            est = Estimator(session, seq.rig, cfg)
            for i in range(len(seq)):
                if truth_track and i > 0:
                    est.tracker.track = track_from_joints(seq.joints_3d[i - 1], np.ones(25), np.ones(25, bool),
                                                          cfg.tracking, i - 1)
                images = (np.array(seq.images[i, 0]), np.array(seq.images[i, 1]))  # in RAM, as a driver delivers
                t = time.perf_counter()
                r = est.estimate(images, novel_view=request)
                dt = time.perf_counter() - t
                n += 1
                if n <= warmup:
                    continue
                wall += dt
                heat.append(r.timing_ms.get("render_heat", 0.0))
                novel.append(sum(r.timing_ms.get(k, 0.0) for k in NOVEL_VIEW_STAGES))
                total.append(r.timing_ms["total"])
        h, v, t_ = percentiles(heat), percentiles(novel), percentiles(total)
        print(f"  {label:<42} {h['median']:6.2f}/{h['p99']:6.2f}  {v['median']:6.2f}/{v['p99']:6.2f}  "
              f"{t_['median']:6.2f}/{t_['p99']:6.2f}  {len(total) / wall:5.1f}/s", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--precision", default="auto", choices=("auto", "fp32", "int8"))
    ap.add_argument("--repeats", type=positive_count, default=40)
    ap.add_argument("--sequences", type=positive_count, default=4)
    ap.add_argument("--frames", type=positive_count, default=30)
    ap.add_argument("--warmup", type=non_negative_count, default=5)
    ap.add_argument("--cache", help=SEQUENCE_CACHE_HELP)
    ap.add_argument("--skip-graphs", action="store_true")
    ap.add_argument("--skip-end-to-end", action="store_true")
    args = ap.parse_args(argv)
    graphs = [g for g in GRAPH_NAMES if ModelSession.has_graph_file(args.model_dir, g)]
    session = ModelSession.load(SessionConfig(model_dir=args.model_dir, precision=args.precision), graphs)
    print(f"model {args.model_dir} ({args.precision}: {({g: f.precision for g, f in session.files.items()})}), "
          f"load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs", flush=True)
    if not args.skip_graphs:
        graph_scaling(session, args.repeats)
    if not args.skip_end_to_end:
        end_to_end(session, load_sequences(args.sequences, args.frames, cache_dir=args.cache), args.warmup)
    return 0


if __name__ == "__main__":
    sys.exit(main())
