"""What the novel view's coarse silhouette pass (and its sparse interior) saves, and what it changes in the image.

    .venv/bin/python benchmarks/measure_novel_rays.py --model-dir models [--sequences 4 --frames 30]
                                                      [--interior-stride 2] [--config runtime.json]

On held-out-like simulator sequences, with the shipped model's own joints tracking the subject,
each pair's novel view (alpha 0.5, 128x128, stride 1) is rendered twice at the same camera:
with every ray of the subject box (``silhouette_stride`` 0) and with the coarse pass
(``silhouette_stride`` 4: every 4th pixel of the box first, then only the opaque cells,
dilated), and, with ``--interior-stride N``, a third time with the coarse pass and the subject's
interior rendered every N-th pixel (``interior_stride``; its edge cells at stride 1). Prints the
rays rendered, the ``novel_render`` time (median / p99 ms) of each, and
the PSNR of each image against the all-rays image (how much of the picture the
skipped rays carried), and the median accumulated opacity of the all-rays renders (how much of the
box the model fills, i.e. why the coarse pass tests colour rather than opacity). Not a test.
"""
from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.config_field import config_field  # noqa: E402
from ghnerf_runtime.cli.numbers import finite_number  # noqa: E402
from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from benchmarks.bench_runtime_common import RenderTap  # noqa: E402
from ghnerf_runtime.cli.simdata import SEQUENCE_CACHE_HELP, load_sequences, percentiles  # noqa: E402
from ghnerf_runtime.config import (  # noqa: E402
    EstimatorConfig,
    HeatmapsConfig,
    NovelViewConfig,
    load_config,
)
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.metrics import masked_psnr  # noqa: E402
from ghnerf_runtime.novel_view import NovelViewRequest  # noqa: E402


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR of two 8-bit images over every pixel (``inf`` when identical)."""
    return masked_psnr(a.astype(np.float64), b.astype(np.float64), np.ones(a.shape[:2], bool), data_range=255.0).value


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--precision", default="auto", choices=("auto", "fp32", "int8"))
    ap.add_argument("--sequences", type=positive_count, default=4)
    ap.add_argument("--frames", type=positive_count, default=30)
    ap.add_argument("--silhouette-stride", type=positive_count, default=4)
    ap.add_argument("--min-diff", type=config_field(NovelViewConfig, "silhouette_min_diff", finite_number),
                    help="silhouette_min_diff (default: the config's)")
    ap.add_argument("--dilate", type=config_field(NovelViewConfig, "silhouette_dilate"),
                    help="silhouette_dilate (default: the config's)")
    ap.add_argument("--interior-stride", type=non_negative_count, default=0,
                    help="also render with the interior at this stride (0: not; default)")
    ap.add_argument("--cache", help=SEQUENCE_CACHE_HELP)
    ap.add_argument("--config", help="estimator config JSON (ghnerf_runtime.config; the novel view is enabled "
                                     "whatever it says; --model-dir/--precision/--silhouette-stride still apply)")
    args = ap.parse_args(argv)
    # without --config: the flip test off, as docs/runtime.md measured it
    base = load_config(args.config) if args.config else EstimatorConfig(heatmaps=HeatmapsConfig(flip_test=False))
    cfg = replace(base, session=replace(base.session, model_dir=args.model_dir, precision=args.precision),
                  novel_view=replace(base.novel_view, enabled=True, silhouette_stride=args.silhouette_stride))
    if args.min_diff is not None:
        cfg = replace(cfg, novel_view=replace(cfg.novel_view, silhouette_min_diff=args.min_diff))
    if args.dilate is not None:
        cfg = replace(cfg, novel_view=replace(cfg.novel_view, silhouette_dilate=args.dilate))
    coarse = replace(cfg.novel_view, interior_stride=0)
    variants = {"all box rays": replace(coarse, silhouette_stride=0), "coarse pass": coarse}
    if args.interior_stride:
        variants[f"+ interior /{args.interior_stride}"] = replace(coarse, interior_stride=args.interior_stride)
    sequences = load_sequences(args.sequences, args.frames, cache_dir=args.cache)
    session = load_session(cfg)
    tap = RenderTap(session)  # the all-rays variant renders exactly the box, once per pair
    print(f"model {args.model_dir} ({ {g: f.precision for g, f in session.files.items()} }), "
          f"load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs", flush=True)
    rays = {k: [] for k in variants}
    ms = {k: [] for k in variants}
    quality = {k: [] for k in list(variants)[1:]}
    for seq in sequences:
        # One estimator per variant on the same session: the keypoints, hence the novel camera and box,
        # are the same in both (the estimator is deterministic); only the novel view's rays differ.
        ests = {name: Estimator(tap if name == "all box rays" else session, seq.rig, replace(cfg, novel_view=nv))
                for name, nv in variants.items()}
        for i in range(len(seq)):
            pair = (np.asarray(seq.images[i, 0]), np.asarray(seq.images[i, 1]))
            images = {}
            for name, e in ests.items():
                r = e.estimate(pair, novel_view=NovelViewRequest(alpha=0.5))
                if r.novel_view is None:
                    break
                rays[name].append(r.novel_view.rays)
                ms[name].append(r.timing_ms["novel_render"])
                images[name] = r.novel_view.image
            if len(images) == len(variants):
                for name in quality:
                    quality[name].append(psnr(images[name], images["all box rays"]))
    c = session.contract  # the model's size (the shipped one's is 128x128)
    print(f"{len(quality['coarse pass'])} pairs; novel view {c.width}x{c.height}, stride 1")
    for name in variants:
        t = percentiles(ms[name])
        print(f"  {name:<18} rays median {np.median(rays[name]):7.0f}   novel_render {t['median']:6.2f} / "
              f"{t['p99']:6.2f} ms")
    for name, values in quality.items():
        q = np.asarray(values)
        finite = q[np.isfinite(q)]
        print(f"  PSNR {name} vs all box rays: median {np.median(q):.1f} dB, min "
              f"{(finite.min() if finite.size else float('inf')):.1f} dB, identical in {int(np.sum(~np.isfinite(q)))} "
              f"of {q.size} pairs")
    if tap.runs:
        print(f"  accumulated opacity over the box's rays (all-rays renders): median "
              f"{np.median(np.concatenate([acc.ravel() for _, acc in tap.runs])):.2f}")
    for name in quality:
        ratio = np.median(ms[name]) / np.median(ms["all box rays"])
        print(f"  novel_render time ratio ({name} / all box rays): {ratio:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
