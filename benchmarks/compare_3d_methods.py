"""Compare the 3D joint methods (accuracy and cost) on held-out-like simulator sequences.

    .venv/bin/python benchmarks/compare_3d_methods.py --model-dir models            # the trained model
    .venv/bin/python benchmarks/compare_3d_methods.py --oracle                      # geometry floor, no model
    .venv/bin/python benchmarks/compare_3d_methods.py --heatmap-sources encoder --methods triangulate \
        --reprojection-gates 2,3,4,8,12                          # the reprojection gate's trade

For every method (triangulation, triangulation with the single-view fallback, volumetric query
at a few grid sizes, depth centroid) the estimator runs over the same pairs (a fresh track per
sequence, as a device would start) and the script reports MPJPE over the joints each method
found, the share of joints found, MPJPE on the joints *every* method found (the fair
comparison: a method that drops hard joints looks better otherwise), and the cost of the 3D
stage (median/p99 ms; the volumetric query graph runs inside it) and of the whole pair. It
prints a Markdown table for docs/runtime.md, headed by the model that produced it.

``--oracle`` replaces the model by the oracle session (benchmarks/bench_runtime_common.py):
the figures then measure the methods' own error floor on perfect model outputs, not the model.
Not a test; figures depend on the machine's load.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import checked_model_folder, model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from benchmarks.bench_runtime_common import OracleSession, contract_of, edge128_contract  # noqa: E402
from ghnerf_runtime.cli.output_path import ready_output_arg  # noqa: E402
from ghnerf_runtime.cli.simdata import (SEQUENCE_CACHE_HELP, load_sequences, percentiles,  # noqa: E402
                                        visibility_summary)
from ghnerf_runtime.config import EstimatorConfig, HeatmapsConfig, Joints3DConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator  # noqa: E402
from ghnerf_runtime.metrics import VISIBILITY_CLASSES, mpjpe, strict_json, visibility_class  # noqa: E402
from ghnerf_runtime.session import ModelSession  # noqa: E402

#: name -> Joints3DConfig overrides.
METHODS = {
    "triangulate": {"method": "triangulate"},
    "triangulate+fallback": {"method": "triangulate", "single_view_fallback": True},
    "volumetric-12": {"method": "volumetric", "grid": 12},
    "volumetric-16": {"method": "volumetric", "grid": 16},
    "volumetric-24": {"method": "volumetric", "grid": 24},
    "depth_centroid": {"method": "depth_centroid"},
}


def run_method(session, sequences, joints3d: Joints3DConfig, oracle: OracleSession | None, source: str = "rendered"):
    # the flip test off: as docs/runtime.md measured this, before it became the default
    cfg = EstimatorConfig(joints3d=joints3d, heatmaps=HeatmapsConfig(source=source, flip_test=False))
    preds, found, stage, total, tracked = [], [], [], [], []
    for seq in sequences:
        est = Estimator(session, seq.rig, cfg)
        for i in range(len(seq)):
            if oracle is not None:
                oracle.set_truth(seq.joints_3d[i], seq.visible[i])
            # in RAM, as a driver delivers: a view of the cache's memory map would time its page faults (disk
            # reads when the page cache is cold) in the first method's preprocess stage and pair total
            r = est.estimate((np.array(seq.images[i, 0]), np.array(seq.images[i, 1])), sequence=i)
            preds.append(r.joints_3d)
            found.append(~r.missing)
            stage.append(r.timing_ms.get("joints_3d", 0.0))
            total.append(r.timing_ms["total"])
            tracked.append(r.tracked)
    return np.array(preds), np.array(found), stage, total, np.array(tracked)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, help="default: models (not read with --oracle)")
    ap.add_argument("--oracle", action="store_true", help="perfect model outputs from the truth (no model needed)")
    ap.add_argument("--precision", default="auto", choices=("auto", "fp32", "int8"))
    ap.add_argument("--sequences", type=positive_count, default=10)
    ap.add_argument("--frames", type=positive_count, default=30)
    ap.add_argument("--methods", default=",".join(METHODS), help=f"comma list of {list(METHODS)}")
    ap.add_argument("--reprojection-gates", default="",
                    help="comma list of joints3d.max_reprojection_px values: one more `triangulate` row each "
                         "(the trade of joints found against their error; the default gate is 6)")
    ap.add_argument("--heatmap-sources", default="rendered",
                    help="comma list of rendered,encoder (the 2D heatmaps the methods start from)")
    ap.add_argument("--seen-motions", action="store_true")
    ap.add_argument("--cache", help=SEQUENCE_CACHE_HELP)
    ap.add_argument("--json", help="write the figures here")
    args = ap.parse_args(argv)
    if args.json:  # written after every method has run over every sequence: its place is settled first
        args.json = ready_output_arg(ap, args.json, "--json")
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    methods = dict(METHODS)
    for gate in (float(g) for g in args.reprojection_gates.split(",") if g):
        methods[f"triangulate, gate {gate:g} px"] = {"method": "triangulate", "max_reprojection_px": gate}
    names = [m for m in args.methods.split(",") if m] + [m for m in methods if m not in METHODS]
    if bad := [m for m in names if m not in methods]:
        ap.error(f"--methods: unknown {bad}; methods: {list(METHODS)}")

    sequences = load_sequences(args.sequences, args.frames, cache_dir=args.cache, seen_motions=args.seen_motions)
    truth = np.concatenate([np.asarray(s.joints_3d) for s in sequences])
    visible = np.concatenate([np.asarray(s.visible) for s in sequences])  # (pairs, 2, 25)
    vis_class = visibility_class(visible)
    sources = [h for h in args.heatmap_sources.split(",") if h]
    if args.oracle and sources != ["rendered"]:
        ap.error("--oracle models rendered heatmaps only")
    if args.model_dir is None:  # checked only where a model runs: --oracle runs none, a missing folder is fine
        args.model_dir = "models" if args.oracle else checked_model_folder(ap, "models")
    oracle = None
    if args.oracle:
        try:
            contract = contract_of(args.model_dir)
        except (FileNotFoundError, OSError):
            contract = edge128_contract()
        session = oracle = OracleSession(contract)
        model_line = "oracle session (perfect heatmaps from the simulator truth; no model)"
    else:
        graphs = ("encoder", "volume", "render_heat", "query")
        session = ModelSession.load(SessionConfig(model_dir=args.model_dir, precision=args.precision), graphs)
        card = session.card
        about = f"model card: {json.dumps(card)[:200]}" if card else "no model card: random weights?"
        model_line = (f"model `{args.model_dir}` ({session.contract.width}x{session.contract.height}, version "
                      f"{session.contract.model_version}, {about})")
    print(f"# 3D methods on {len(sequences)} held-out-like sequences x {args.frames} pairs; {model_line}; load "
          f"average {os.getloadavg()[0]:.2f}", flush=True)

    results = {}
    for source in sources:
        for name in names:
            t = time.perf_counter()
            j3 = replace(Joints3DConfig(), **methods[name])
            preds, found, stage, total, tracked = run_method(session, sequences, j3, oracle, source)
            label = name if sources == ["rendered"] else f"{source} heatmaps, {name}"
            results[label] = {"preds": preds, "found": found, "stage": stage, "total": total, "tracked": tracked}
            logging.info("%s done in %.1f s", label, time.perf_counter() - t)

    common = np.logical_and.reduce([r["found"] for r in results.values()])
    ones = np.ones(truth.shape[:2], bool)
    rows = []
    for name, r in results.items():
        own = mpjpe(r["preds"], truth, ones, pred_valid=r["found"])
        fair = mpjpe(r["preds"], truth, ones, pred_valid=common)
        cold = ~r["tracked"]
        cold_err = mpjpe(r["preds"][cold], truth[cold], ones[cold], pred_valid=r["found"][cold]) if cold.any() else None
        rows.append({"method": name, "mpjpe_mm": own.value, "found": float(r["found"].mean()),
                     "tracked_frac": float(r["tracked"].mean()),
                     "cold_mpjpe_mm": cold_err.value if cold_err else float("nan"),
                     "cold_found": float(r["found"][cold].mean()) if cold.any() else float("nan"),
                     "mpjpe_common_mm": fair.value, "common_joints": int(common.sum()),
                     "by_visibility": visibility_summary(own, visible, r["found"]),
                     "stage_ms": percentiles(r["stage"]), "total_ms": percentiles(r["total"])})
    print("\n| method | MPJPE (mm, own joints) | joints found | MPJPE on common joints (mm) "
          "| 3D stage ms median / p99 | pair ms median |")
    print("|---|---|---|---|---|---|")
    for row in rows:
        print(f"| {row['method']} | {row['mpjpe_mm']:.1f} | {100 * row['found']:.1f} % | {row['mpjpe_common_mm']:.1f} "
              f"({row['common_joints']} joints) | {row['stage_ms']['median']:.2f} / {row['stage_ms']['p99']:.2f} | "
              f"{row['total_ms']['median']:.1f} |")
    print("\n| method | pairs tracked | cold-start pairs: MPJPE (mm) / joints found |")
    print("|---|---|---|")
    for row in rows:
        print(f"| {row['method']} | {100 * row['tracked_frac']:.0f} % | {row['cold_mpjpe_mm']:.1f} / "
              f"{100 * row['cold_found']:.1f} % |")
    shares = ", ".join(f"{name.replace('_', ' ')} {100 * float((vis_class == k).mean()):.0f} %"
                       for k, name in enumerate(VISIBILITY_CLASSES))
    print(f"\nBy the cameras that see the joint (simulator truth: in the image, not hidden by the body; {shares} "
          "of the joints): MPJPE (mm) over the joints found / share found")
    print("\n| method | " + " | ".join(n.replace("_", " ") for n in VISIBILITY_CLASSES) + " |")
    print("|---|" + "---|" * len(VISIBILITY_CLASSES))
    for row in rows:
        print(f"| {row['method']} | " + " | ".join(
            f"{c['mpjpe_mm']:.1f} / {100 * c['found']:.1f} %" for c in row["by_visibility"].values()) + " |")
    if args.json:
        # strict JSON: a method that finds no joint has a NaN MPJPE, written as null
        args.json.write_text(strict_json({"model": model_line, "rows": rows,
                                          "sequences": [s.info for s in sequences]}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
