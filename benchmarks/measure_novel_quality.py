"""How good the device's novel view is: the runtime's image against the simulator's picture of that camera.

    .venv/bin/python benchmarks/measure_novel_quality.py --model-dir models [--sequences 10 --every 6]

``ghnerf-eval`` scores novel views at cameras anywhere on a circle around the subject, many of
them looking at sides neither rig camera sees. The device renders its novel view *between* its two
cameras (``NovelViewRequest.alpha``). This script measures that view, through the runtime: on
held-out-like simulator sequences (the bench's, ``ghnerf_runtime.cli.simdata``) the estimator
tracks the subject with the model's own joints and renders the novel view at each ``--alphas``
(0 and 1: the rig cameras' own viewpoints) and each ``--strides`` (1: every pixel of the 128x128
view; 2: a quarter of the rays, upsampled). The simulator then renders the same camera (4x
supersampled, area-averaged to 128x128) from the sequence's scene at the pair's time, and the
script prints the masked PSNR and SSIM (``ghnerf_runtime.metrics``, inside the simulator's subject
mask, the truth composited over the model background as ``ghnerf-eval`` does) and the
``novel_render`` time of each variant, median over the pairs. It also prints the model's accumulated
opacity on the rays of the coarse pass (every 4th pixel of the subject box, stride-1 variants) split by
the simulator's mask: a clean model is opaque on the subject (1) and empty around it (0); black fog
around the subject costs the colour loss nothing over a black background, and fog in front of it dims
it. ``--proxy-blend off,on``, ``--painter off,auto`` and ``--matte off,on`` compare the recolouring over
the body proxy, the learnt painter and the fog matte (docs/novel-view.md); the ``whole view`` column is the
PSNR over every pixel of the view (the truth over the background), which sees the fog around the subject
that the masked PSNR does not. Not a test.
"""
from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from benchmarks.bench_runtime_common import RenderTap, truth_view  # noqa: E402
from drivers.sim import random_scene  # noqa: E402
from ghnerf_runtime.cli.simdata import (HELD_OUT_MOTIONS, SEEN_MOTIONS, SEQUENCE_CACHE_HELP,  # noqa: E402
                                        load_sequences, percentiles)
from ghnerf_runtime.config import EstimatorConfig, HeatmapsConfig, load_config  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.metrics import masked_psnr, masked_ssim  # noqa: E402
from ghnerf_runtime.novel_view import NovelViewRequest  # noqa: E402
from ghnerf_runtime.tracking import track_from_joints  # noqa: E402

def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--precision", default="auto", choices=("auto", "fp32", "int8"))
    ap.add_argument("--sequences", type=positive_count, default=10)
    ap.add_argument("--frames", type=positive_count, default=30)
    ap.add_argument("--every", type=positive_count, default=6, help="score every N-th pair (all pairs are tracked)")
    ap.add_argument("--alphas", default="0,0.5,1", help="comma list: 0 = the first rig camera, 1 = the second")
    ap.add_argument("--strides", default="1,2", help="comma list of novel_view.stride values")
    ap.add_argument("--proxy-blend", default="off",
                    help="comma list of novel_view.proxy_blend values, off and/or on (default: off)")
    ap.add_argument("--painter", default="off",
                    help="comma list of novel_view.painter values, off and/or auto (default: off; auto uses the model "
                         "folder's novel_painter.onnx)")
    ap.add_argument("--matte", default="off",
                    help="comma list of novel_view.matte values, off and/or on (default: off)")
    ap.add_argument("--config", help="estimator config JSON (ghnerf_runtime.config; the novel view is enabled "
                                     "whatever it says; --model-dir/--precision still apply)")
    ap.add_argument("--seen-motions", action="store_true")
    ap.add_argument("--track-from-truth", action="store_true",
                    help="place each pair's crop and sweep box from the previous pair's true joints (as "
                         "ghnerf-bench runtime --track-from-truth): the view without the model's own tracking error")
    ap.add_argument("--cache", help=SEQUENCE_CACHE_HELP)
    args = ap.parse_args(argv)
    alphas = [float(a) for a in args.alphas.split(",")]
    strides = [int(s) for s in args.strides.split(",")]
    blends = [{"off": False, "on": True}[b.strip()] for b in args.proxy_blend.split(",")]
    painters = [p.strip() for p in args.painter.split(",")]
    mattes = [{"off": False, "on": True}[m.strip()] for m in args.matte.split(",")]
    # without --config: the flip test off, as docs/runtime.md measured this, before it became the default
    base = load_config(args.config) if args.config else EstimatorConfig(heatmaps=HeatmapsConfig(flip_test=False))
    cfg = replace(base, session=replace(base.session, model_dir=args.model_dir, precision=args.precision),
                  novel_view=replace(base.novel_view, enabled=True, painter="auto" if "auto" in painters else "off"))
    sequences = load_sequences(args.sequences, args.frames, seen_motions=args.seen_motions, cache_dir=args.cache)
    session = RenderTap(load_session(cfg))
    if set(painters) - {"off", "auto"} or ("auto" in painters and session.novel_painter is None):
        raise SystemExit(f"--painter {args.painter}: off and/or auto, auto with a model folder that has "
                         "novel_painter.onnx (python -m training.learnt_fill export)")
    background = float(session.contract.background)
    print(f"model {args.model_dir} ({ {g: f.precision for g, f in session.files.items()} }), "
          f"load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs", flush=True)
    variants = [(a, s, b, p, m) for a in alphas for s in strides for b in blends for p in painters for m in mattes]
    scores = {v: {"psnr": [], "ssim": [], "whole": [], "ms": [], "proxy_ms": [], "paint_ms": [], "matte_ms": [],
                  "seq": []} for v in variants}
    opacity = {"subject": [], "around": []}  # coarse-pass rays of the stride-1 views
    motions = SEEN_MOTIONS if args.seen_motions else HELD_OUT_MOTIONS
    for seq in sequences:
        scene = random_scene(int(seq.info["scene_seed"]), volume=seq.rig.volume, motions=motions)
        first, _ = scene.render(seq.rig.pair[0], float(seq.info["t0"]), with_truth=False)
        if not np.array_equal(first, np.asarray(seq.images[0, 0])):
            raise SystemExit(f"sequence {seq.info['index']}: the rebuilt scene does not reproduce the cached frames "
                             "(stale cache? pass --cache off)")
        ests = {v: Estimator(session, seq.rig, replace(cfg, novel_view=replace(cfg.novel_view, stride=v[1],
                                                                                proxy_blend=v[2], painter=v[3],
                                                                                matte=v[4])))
                for v in variants}
        truths: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
        for i in range(len(seq)):
            t = float(seq.info["t0"]) + i / float(seq.info["fps"])
            pair = (np.asarray(seq.images[i, 0]), np.asarray(seq.images[i, 1]))
            for (alpha, stride, blend, painter, matte), est in ests.items():
                if args.track_from_truth and i > 0:
                    est.tracker.track = track_from_joints(seq.joints_3d[i - 1], np.ones(25), np.ones(25, bool),
                                                          est.config.tracking, i - 1)
                session.runs.clear()
                r = est.estimate(pair, novel_view=NovelViewRequest(alpha=alpha))
                if r.novel_view is None or i % args.every:
                    continue
                cam = r.novel_view.camera
                key = np.round(cam.P, 9).tobytes()  # the strides of one alpha share the camera
                if key not in truths:
                    truths[key] = truth_view(scene, cam, t, background)
                truth, mask = truths[key]
                if not mask.any():
                    continue
                pred = r.novel_view.image[..., ::-1].astype(np.float64) / 255.0
                s = scores[(alpha, stride, blend, painter, matte)]
                s["psnr"].append(masked_psnr(pred, truth, mask).value)
                s["whole"].append(masked_psnr(pred, truth, np.ones_like(mask)).value)
                s["ssim"].append(masked_ssim(pred, truth, mask).value)
                s["ms"].append(r.timing_ms["novel_render"])
                s["proxy_ms"].append(r.timing_ms.get("novel_proxy", 0.0))
                s["paint_ms"].append(r.timing_ms.get("novel_paint", 0.0))
                s["matte_ms"].append(r.timing_ms.get("novel_matte", 0.0))
                s["seq"].append(int(seq.info["index"]))
                plain = stride == 1 and not blend and painter == "off" and matte == mattes[0]
                if plain and len(session.runs) == 2:  # coarse pass + fine pass
                    uv, acc = session.runs[0]
                    px = np.clip(np.rint(uv).astype(int), 0, mask.shape[0] - 1)
                    on = mask[px[:, 1], px[:, 0]]
                    opacity["subject"].append(acc[on])
                    opacity["around"].append(acc[~on])
    print(f"{len(sequences)} sequences x {args.frames} pairs, one pair in {args.every} scored; novel view "
          f"{session.contract.width}x{session.contract.height}; masked against the simulator's render")
    print("| alpha | stride | proxy_blend | painter | matte | pairs | PSNR dB median (mean) | SSIM median "
          "| whole view PSNR median (mean) | novel_render ms median / p99 | novel_paint ms median "
          "| novel_proxy ms median | novel_matte ms median |")
    print("|---" * 13 + "|")
    for (alpha, stride, blend, painter, matte), s in scores.items():
        on, mat = ("on" if blend else "off"), ("on" if matte else "off")
        if not s["psnr"]:
            print(f"| {alpha:g} | {stride} | {on} | {painter} | {mat} | 0 |" + " – |" * 7)
            continue
        tm = percentiles(s["ms"])
        print(f"| {alpha:g} | {stride} | {on} | {painter} | {mat} | {len(s['psnr'])} | {np.median(s['psnr']):.2f} "
              f"({np.mean(s['psnr']):.2f}) | {np.median(s['ssim']):.3f} | {np.median(s['whole']):.2f} "
              f"({np.mean(s['whole']):.2f}) | {tm['median']:.1f} / {tm['p99']:.1f} | "
              f"{np.median(s['paint_ms']):.1f} | {np.median(s['proxy_ms']):.1f} | {np.median(s['matte_ms']):.1f} |")
    first = scores[variants[0]]
    if first["psnr"]:  # how much the scenes differ: one mean per sequence
        seq, p = np.array(first["seq"]), np.array(first["psnr"])
        means = np.array([p[seq == k].mean() for k in np.unique(seq)])
        print(f"per sequence (alpha {variants[0][0]:g}, stride {variants[0][1]}, proxy_blend {variants[0][2]}, "
              f"painter {variants[0][3]}, matte {variants[0][4]}): mean PSNR min {means.min():.2f}, "
              f"median {np.median(means):.2f}, max {means.max():.2f} dB over {means.size} sequences "
              f"(standard error of the overall mean {means.std(ddof=1) / np.sqrt(means.size) if means.size > 1 else 0:.2f} dB)")
    if opacity["subject"]:
        on, off = np.concatenate(opacity["subject"]), np.concatenate(opacity["around"])
        print(f"accumulated opacity, coarse-pass rays of the stride-1 views: on the subject mean {on.mean():.2f} "
              f"(median {np.median(on):.2f}, {on.size} rays), around it in the box mean {off.mean():.2f} "
              f"(median {np.median(off):.2f}, {off.size} rays)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
