"""Re-tune the runtime's accuracy knobs for the shipped model on sequences the bench never uses.

    .venv/bin/python benchmarks/tune_runtime_knobs.py [--model-dir models] [--sequences 30] [--frames 30]
                                                      [--only NAME,NAME] [--every N]

The decoder's Gaussian filter and subpixel refinement, its threshold and the triangulation's reprojection
gate were tuned on the first model. This runs every variant below (one setting changed from the
defaults each) on two sets of held-out-like sequences and prints, per set, PCK@0.2 (both images),
MPJPE over the joints found, MPJPE over the joints both cameras see, the share found, the jitter
(``metrics.acceleration_error``, mm per pair squared; the pairs carry their capture times, as
``smoothing`` needs) and the MPJPE of the joints moving fast (``FAST_M_PER_S``), where a smoothing
filter's lag would show:

* the *tuning* set: sequences drawn as ``ghnerf-bench runtime`` draws them but from other scene seeds
  (``TUNE_SEED_BASE``: other rigs, bodies, clothes), where a choice is made;
* the *bench* set: ``ghnerf-bench runtime``'s own sequences, where the choice is only checked.

A tool, not a test; the figures and the choice are in docs/runtime.md ("Re-tuning the decoder").
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from ghnerf_runtime.cli.simdata import SEED_BASE, Accuracy, load_sequences  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, config_from_dict, config_to_dict  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.metrics import mpjpe  # noqa: E402

#: Scene seeds of the tuning set: far from the bench's (SEED_BASE + k) and from every dataset split.
TUNE_SEED_BASE = SEED_BASE + 2 ** 40

#: name -> overrides of the default configuration (one knob each; "default" is the reference).
VARIANTS: dict[str, dict] = {
    "default": {},
    "decoder.sigma 0": {"decoder": {"sigma": 0.0}},
    "decoder.sigma 0.5": {"decoder": {"sigma": 0.5}},
    "decoder.sigma 0.75": {"decoder": {"sigma": 0.75}},
    "decoder.sigma 1.25": {"decoder": {"sigma": 1.25}},
    "decoder.sigma 1.5": {"decoder": {"sigma": 1.5}},
    "decoder.refine centroid": {"decoder": {"refine": "centroid"}},
    "decoder.threshold 0.05": {"decoder": {"threshold": 0.05}},
    "decoder.threshold 0.2": {"decoder": {"threshold": 0.2}},
    "joints3d.max_reprojection_px 2": {"joints3d": {"max_reprojection_px": 2.0}},
    "joints3d.max_reprojection_px 3": {"joints3d": {"max_reprojection_px": 3.0}},
    "joints3d.max_reprojection_px 4": {"joints3d": {"max_reprojection_px": 4.0}},
    "joints3d.max_reprojection_px 5": {"joints3d": {"max_reprojection_px": 5.0}},
    "joints3d.max_reprojection_px 9": {"joints3d": {"max_reprojection_px": 9.0}},
    "roi.joint_margin_frac 0.05": {"roi": {"joint_margin_frac": 0.05}},
    "roi.joint_margin_frac 0.075": {"roi": {"joint_margin_frac": 0.075}},
    "roi.joint_margin_frac 0.1": {"roi": {"joint_margin_frac": 0.1}},
    "roi.joint_margin_frac 0.125": {"roi": {"joint_margin_frac": 0.125}},
    "roi.joint_margin_frac 0.25": {"roi": {"joint_margin_frac": 0.25}},
    # crops sampled once per pixel (before session 48) against 2x2 and box-reduced, as training rendered them
    "roi.supersample 1": {"roi": {"supersample": 1}},
    "roi.supersample 3": {"roi": {"supersample": 3}},
    # a cold pair that found someone run again on the subject's crop (on by default since session 48)
    "tracking.refine_cold_start off": {"tracking": {"refine_cold_start": False}},
    "tracking.refine_cold_start on": {"tracking": {"refine_cold_start": True}},
    # the skeleton prior (a model folder with skeleton_prior.onnx): off, and its expected-error gate
    "joints3d.skeleton_prior off": {"joints3d": {"skeleton_prior": "off"}},
    "joints3d.max_prior_error_m 0.05": {"joints3d": {"max_prior_error_m": 0.05}},
    "joints3d.max_prior_error_m 0.075": {"joints3d": {"max_prior_error_m": 0.075}},
    "joints3d.max_prior_error_m 0.1": {"joints3d": {"max_prior_error_m": 0.1}},
    "joints3d.max_prior_error_m 0.15": {"joints3d": {"max_prior_error_m": 0.15}},
    "joints3d.max_prior_error_m 0.2": {"joints3d": {"max_prior_error_m": 0.2}},
    "joints3d.max_prior_error_m 10": {"joints3d": {"max_prior_error_m": 10.0}},
    "joints3d.max_prior_disagreement_m 0.25": {"joints3d": {"max_prior_disagreement_m": 0.25}},
    "joints3d.max_prior_disagreement_m 0.15": {"joints3d": {"max_prior_disagreement_m": 0.15}},
    "joints3d.max_prior_disagreement_m 0.35": {"joints3d": {"max_prior_disagreement_m": 0.35}},
    "joints3d.max_prior_disagreement_m 0.45": {"joints3d": {"max_prior_disagreement_m": 0.45}},
    "joints3d.prior_flip_test off": {"joints3d": {"prior_flip_test": False}},
    "joints3d.prior_flip_test off + max_prior_error_m 10": {"joints3d": {"prior_flip_test": False,
                                                                         "max_prior_error_m": 10.0}},
    # temporal smoothing of the reported joints (One Euro on the pairs' capture times; beta in Hz per m/s;
    # on by default since session 19, min_cutoff_hz 1, beta 10)
    "smoothing off": {"smoothing": {"enabled": False}},
    "smoothing.beta 30": {"smoothing": {"beta": 30.0}},
    "smoothing.beta 3": {"smoothing": {"beta": 3.0}},
    "smoothing.beta 3 + min_cutoff_hz 0.5": {"smoothing": {"beta": 3.0, "min_cutoff_hz": 0.5}},
    "smoothing.beta 1": {"smoothing": {"beta": 1.0}},
    "smoothing.beta 1 + min_cutoff_hz 2": {"smoothing": {"beta": 1.0, "min_cutoff_hz": 2.0}},
    "smoothing.beta 1 + min_cutoff_hz 0.5": {"smoothing": {"beta": 1.0, "min_cutoff_hz": 0.5}},
    "smoothing.beta 0.3": {"smoothing": {"beta": 0.3}},
    "smoothing.min_cutoff_hz 0.5": {"smoothing": {"min_cutoff_hz": 0.5}},
    "smoothing.min_cutoff_hz 2": {"smoothing": {"min_cutoff_hz": 2.0}},
}


def _merged(base: dict, overrides: dict) -> dict:
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in base.items()}
    for section, values in overrides.items():
        out[section] = {**out[section], **values}
    return out


#: A joint moving faster than this (true speed, m/s) is "fast": where a smoothing filter's lag would show.
FAST_M_PER_S = 1.0


def true_speed(joints_3d: np.ndarray, fps: float) -> np.ndarray:
    """``(F, J)`` speed of the true joints, m/s: central differences, one-sided at the ends."""
    return np.linalg.norm(np.gradient(np.asarray(joints_3d, np.float64), axis=0), axis=-1) * fps


def score(session, cfg: EstimatorConfig, sequences, every: int = 1) -> dict:
    """Every ``every``-th pair of each sequence (a slower camera: ``30 / every`` fps), on its capture time."""
    acc = Accuracy()
    fast = []  # per pair: (reported, true, true speed over FAST_M_PER_S, found) for the fast joints' MPJPE
    for seq in sequences:
        fps = float(seq.info.get("fps", 30.0))
        speed = true_speed(seq.joints_3d, fps)
        with Estimator(session, seq.rig, cfg) as est:
            for k, i in enumerate(range(0, len(seq), every)):
                r = est.estimate((np.asarray(seq.images[i, 0]), np.asarray(seq.images[i, 1])), sequence=k,
                                 timestamp_s=i / fps)
                # the jitter is per delivered pair: pair k follows pair k - 1
                acc.add_truth(r, seq.joints_3d[i], seq.joints_2d[i], seq.visible[i], frame=(id(seq), k))
                fast.append((r.joints_3d, seq.joints_3d[i], speed[i] > FAST_M_PER_S, ~r.missing))
    s = acc.summary()
    reported, true, is_fast, found = (np.array(a) for a in zip(*fast))
    fast_mp = mpjpe(reported, true, is_fast, pred_valid=found)
    return {"pck": s["pck@0.2"], "mpjpe": s["mpjpe_mm"], "seen": s["mpjpe_by_visibility"]["all_views"]["mpjpe_mm"],
            "found": s["found_3d_frac"], "jitter": s["jitter_mm"],
            "fast": fast_mp.value, "fast_share": fast_mp.num_evaluated / max(s["mpjpe_evaluated"], 1)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--precision", default="int8", choices=("auto", "fp32", "int8"))
    ap.add_argument("--sequences", type=positive_count, default=30)
    ap.add_argument("--frames", type=positive_count, default=30)
    ap.add_argument("--only", help="comma list of variant names (default: all)")
    ap.add_argument("--every", type=positive_count, default=1,
                    help="use every n-th pair of each sequence: a camera at 30/n fps (the jitter is then per such "
                         "pair, so compare it only between runs of the same n)")
    args = ap.parse_args(argv)
    if args.every < 1:
        ap.error(f"--every: a pair count of at least 1, got {args.every}")
    names = args.only.split(",") if args.only else list(VARIANTS)
    if unknown := [n for n in names if n not in VARIANTS]:
        ap.error(f"--only: no variant named {unknown}; the variants are {list(VARIANTS)}")
    base = config_to_dict(EstimatorConfig())
    base["session"].update(model_dir=args.model_dir, precision=args.precision)
    session = load_session(config_from_dict(base))
    sets = {"tuning": load_sequences(args.sequences, args.frames, seed_base=TUNE_SEED_BASE),
            "bench": load_sequences(args.sequences, args.frames)}
    print(f"{args.sequences} sequences x {args.frames} pairs per set at {30 / args.every:g} fps (every "
          f"{args.every}), {args.precision}, the defaults otherwise "
          f"(flip test {'on' if base['heatmaps']['flip_test'] else 'off'}); PCK@0.2 / MPJPE found / MPJPE both "
          f"cameras see / found / jitter (mean |second difference of the error|, mm per pair^2) / MPJPE of the "
          f"joints found moving faster than {FAST_M_PER_S:g} m/s (where a filter's lag shows; their share)",
          flush=True)
    for name in names:
        cfg = config_from_dict(_merged(base, VARIANTS[name]))
        cells = []
        for label, sequences in sets.items():
            r = score(session, cfg, sequences, args.every)
            cells.append(f"{label} {r['pck']:.3f} / {r['mpjpe']:.1f} / {r['seen']:.1f} mm / {100 * r['found']:.1f} % "
                         f"/ jitter {r['jitter']:.1f} / fast {r['fast']:.1f} mm ({100 * r['fast_share']:.0f} %)")
        print(f"{name:<34} " + " | ".join(cells), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
