"""Does the runtime reproduce the training evaluation? Like-for-like on the dataset's held-out scenes.

    .venv/bin/python benchmarks/bench_runtime_vs_eval.py --model-dir models [--data data/edge128] [--limit 32] [--novel]

For each of the first ``--limit`` scenes of the dataset split (default ``val``), PCK@0.2 of the
two source views three ways:

* **A, dataset path** -- the stored crops (rendered at 2x and box-filtered), the stored crop
  cameras, near/far of the true body box + 0.1 m: what ``training/evaluate.py`` (``ghnerf-eval``)
  measures; A must equal its ``pck@0.2`` on the same scenes.
* **B, runtime preprocessing** -- the same scene re-rendered as full 640x480 camera frames
  (``drivers.sim``, same seed, rig and time), cropped by ``preprocess_image`` with the *stored*
  ROI; same cameras and near/far. B - A is the cost of the runtime's resampling (and of a
  different sensor-noise draw).
* **C, the estimator** -- ``Estimator.estimate`` on the full frames, its crop and sweep box placed
  from the true joints (as a track would): the runtime's own crops, margins, ray restriction and
  decoding, 2D compared in the original images.

With a model that exports encoder heatmaps (contract 1.1.0), each path is also scored with
``heatmaps.source = "encoder"`` (the encoder graph's own 2D heatmaps; C then triangulates).

With ``--novel`` (needs ``render_rgb``), the three paths also render the colour view *at the first
source camera* (the device's ``alpha = 0``) and score its masked PSNR: A and B at the stored crop
camera against the stored crop (as ``ghnerf-eval`` scores a view), C through ``Estimator.estimate``
with ``NovelViewRequest(alpha=0)`` (its own crop, sweep box and coarse/fine rays) against the
simulator's picture of the camera it rendered (``bench_runtime_common.truth_view``). This tells
the runtime's novel-view error apart from the scenes' difficulty. A scene with no view (C) or a
non-finite PSNR is left out of that path's mean and counted on its line (:func:`psnr_summary`).

A tool (imports ``training.data`` and ``drivers``); not a test.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from training.cli.dataset_split import check_dataset_split  # noqa: E402
from benchmarks.bench_runtime_common import truth_view  # noqa: E402
from ghnerf_runtime.config import (  # noqa: E402
    BEST_METHOD,
    EstimatorConfig,
    HeatmapsConfig,
    Joints3DConfig,
    NovelViewConfig,
    SessionConfig,
)
from ghnerf_runtime.contract import (  # noqa: E402
    near_far_from_box,
    ray_grid,
    source_centers,
    source_projections,
    target_inputs,
)
from ghnerf_runtime.estimator import Estimator  # noqa: E402
from ghnerf_runtime.geometry import Camera  # noqa: E402
from ghnerf_runtime.keypoints import decode_keypoints, heatmap_to_model_pixels  # noqa: E402
from ghnerf_runtime.metrics import capped_psnr, masked_psnr, pck  # noqa: E402
from ghnerf_runtime.novel_view import NovelViewRequest  # noqa: E402
from ghnerf_runtime.preprocess import Roi, build_undistort_crop_maps, preprocess_image  # noqa: E402
from ghnerf_runtime.session import ModelSession  # noqa: E402
from ghnerf_runtime.tracking import box_corners, track_from_joints  # noqa: E402


def _decode(session: ModelSession, images: np.ndarray, cams, near_far: np.ndarray, source: str = "rendered"):
    c = session.contract
    S, g = c.height, c.height // c.heatmap_stride
    env = {"images": images, "src_P": source_projections(cams, S, S), "src_centers": source_centers(cams),
           **target_inputs(cams, S, S), "near_far": near_far,
           "ray_uv": np.ascontiguousarray(np.broadcast_to(ray_grid(S, S, c.heatmap_stride), (2, g * g, 2)))}
    env.update(session.run("encoder", env))
    if source == "encoder":
        hm = env["encoder_heatmaps"]
    else:
        env.update(session.run("volume", env))
        hm = session.run("render_heat", env)["heatmaps"].reshape(2, g, g, -1).transpose(0, 3, 1, 2)
    kp = decode_keypoints(np.ascontiguousarray(hm))
    return heatmap_to_model_pixels(kp.uv, g, S), kp.valid


def _render_first_source(session: ModelSession, images: np.ndarray, cams, near_far: np.ndarray) -> np.ndarray:
    """``(S, S, 3)`` RGB: the colour branch at the first source's own crop camera, every pixel."""
    S = session.contract.height
    env = {"images": images, "src_P": source_projections(cams, S, S), "src_centers": source_centers(cams),
           **target_inputs(cams[:1], S, S), "near_far": near_far[:1],
           "ray_uv": np.ascontiguousarray(ray_grid(S, S, 1)[None], dtype=np.float32)}
    env.update(session.run("encoder", env))
    env.update(session.run("volume", env))
    return session.run("render_rgb", env)["rgb"].reshape(S, S, 3)


def psnr_summary(values: list[float | None]) -> dict:
    """Mean and median masked PSNR of one path's scenes, and what they leave out, by name.

    ``values`` holds one entry per scene: the view's PSNR, or None where the path produced no view
    (the estimator can return none). A missing or non-finite view (NaN: empty mask or a broken render)
    is left out of the mean but counted: before, a missing view vanished from C's mean, and a NaN made
    the mean NaN. +inf (identical images) is capped at :data:`PSNR_CAP_DB` (``ghnerf_runtime.metrics``, whose
    :func:`capped_psnr` ``ghnerf-eval`` uses too).

    Example:
        >>> psnr_summary([20.0, None, 30.0, float("nan")])
        {'mean': 25.0, 'median': 25.0, 'scored': 2, 'no_view': 1, 'nonfinite': 1}
    """
    no_view = sum(v is None for v in values)
    got = np.array([v for v in values if v is not None], np.float64)
    finite = capped_psnr(got[~np.isnan(got)])
    return {"mean": float(finite.mean()) if finite.size else float("nan"),
            "median": float(np.median(finite)) if finite.size else float("nan"),
            "scored": int(finite.size), "no_view": no_view, "nonfinite": int(np.isnan(got).sum())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--precision", default="auto", choices=("auto", "fp32", "int8"))
    ap.add_argument("--data", default="data/edge128")
    ap.add_argument("--split", default="val")
    ap.add_argument("--limit", type=positive_count, default=32)
    ap.add_argument("--novel", action="store_true", help="also score the colour view at the first source camera")
    args = ap.parse_args(argv)
    check_dataset_split(ap, args.data, args.split)  # before the model loads

    from drivers.sim import RigPlacement, random_scene
    from training.data.cache import ShardedSplit
    from training.data.splits import split_spec

    graphs = ("encoder", "volume", "render_heat") + (("render_rgb",) if args.novel else ())
    session = ModelSession.load(SessionConfig(model_dir=args.model_dir, precision=args.precision),
                                graphs)  # the encoder heatmaps (when present) come with the encoder
    S = session.contract.height
    split = ShardedSplit(args.data, args.split)
    motions = split_spec(args.split).motions
    sources = ["rendered"] + (["encoder"] if session.contract.encoder_heatmaps else [])
    rows = {(k, src): ([], [], [], []) for src in sources for k in "ABC"}
    diffs = []
    psnr: dict[str, list[float | None]] = {"A": [], "B": [], "C": []}  # per scene; None: no view
    for idx in range(min(args.limit, len(split))):
        a, meta = split.arrays(idx), split.metadata(idx)
        pl = dict(meta["placement"])
        placement = RigPlacement(**{**pl, "names": tuple(pl["names"]), "distortion": tuple(pl["distortion"])})
        rig = placement.build()
        scene = random_scene(meta["scene_seed"], volume=rig.volume, motions=motions)
        t = meta["t"]
        if not np.allclose(scene.joints_3d(t), a["joints_3d"], atol=1e-6):
            print(f"scene {idx}: re-rendered scene differs from the stored one; skipped", file=sys.stderr)
            continue
        cams = [Camera(f"src{i}", S, S, a["K"][i], np.zeros(5), a["R"][i], a["t"][i]) for i in range(2)]
        near_far = np.stack([near_far_from_box(cam, box_corners(a["bbox"]), 0.1) for cam in cams])
        stored = np.ascontiguousarray((a["images"][:2].astype(np.float32) / 255.0).transpose(0, 3, 1, 2))
        full = [scene.render(cam, t, with_truth=False)[0] for cam in rig.pair]
        ours = np.stack([preprocess_image(full[i], build_undistort_crop_maps(rig.pair[i], Roi(*a["roi"][i]), S),
                                          session.contract.normalisation) for i in range(2)])
        diffs.append(float(np.abs(stored - ours).mean() * 255))
        for src in sources:
            for key, images in (("A", stored), ("B", ours)):
                uv, ok = _decode(session, images, cams, near_far, src)
                for lst, v in zip(rows[key, src], (uv, a["joints_2d"][:2], a["visible"][:2], ok)):
                    lst.append(v)
            cfg = EstimatorConfig(heatmaps=HeatmapsConfig(source=src, flip_test=False),  # ghnerf-eval's main figure's
                                  joints3d=Joints3DConfig(method=BEST_METHOD[src]))
            est = Estimator(session, rig, cfg)
            est.tracker.track = track_from_joints(a["joints_3d"], np.ones(25), np.ones(25, bool), est.config.tracking)
            r = est.estimate(tuple(full))
            truth = np.stack([cam.project(a["joints_3d"])[0] for cam in rig.pair])
            pred = np.stack([r.joints_2d[n] for n in rig.names[:2]])
            found = ~np.stack([r.missing_2d[n] for n in rig.names[:2]])
            for lst, v in zip(rows["C", src], (pred, truth, a["visible"][:2], found)):
                lst.append(v)
        if args.novel:
            mask = np.unpackbits(np.asarray(a["masks"][0]), axis=-1).astype(bool)
            truth = np.where(mask[..., None], stored[0].transpose(1, 2, 0), np.float32(session.contract.background))
            for key, images in (("A", stored), ("B", ours)):
                rgb = _render_first_source(session, images, cams, near_far)
                psnr[key].append(masked_psnr(np.clip(rgb, 0.0, 1.0), truth, mask).value)
            # opaque_at 1: the raw composite, as paths A and B render it (the runtime's default un-dims it)
            raw_view = NovelViewConfig(enabled=True, opaque_at=1.0)
            with Estimator(session, rig, EstimatorConfig(heatmaps=HeatmapsConfig(flip_test=False),
                                                          novel_view=raw_view)) as est:
                est.tracker.track = track_from_joints(a["joints_3d"], np.ones(25), np.ones(25, bool), est.config.tracking)
                view = est.estimate(tuple(full), novel_view=NovelViewRequest(alpha=0.0)).novel_view
            if view is None:  # counted, not dropped: a view the runtime did not make must not flatter C
                psnr["C"].append(None)
            else:
                sim_truth, sim_mask = truth_view(scene, view.camera, t, float(session.contract.background))
                pred = view.image[..., ::-1].astype(np.float64) / 255.0
                psnr["C"].append(masked_psnr(pred, sim_truth, sim_mask).value)
    print(f"model {args.model_dir} ({args.precision}), {args.data}/{args.split}, {len(diffs)} scenes")
    labels = {"A": "dataset crops (= ghnerf-eval)", "B": "runtime preprocessing, stored ROI",
              "C": "Estimator, crop placed from the true joints"}
    for (key, src), (p, tr, v, ok) in rows.items():
        res = pck(np.array(p), np.array(tr), np.array(v), pred_valid=np.array(ok))
        print(f"  {key} {src + ' heatmaps':<17} {labels[key]:<46} PCK@0.2 {res.value:.3f}  "
              f"({res.num_evaluated} joints, {res.num_pred_missing} not decoded)")
    print(f"  mean |stored crop - runtime crop|: {np.mean(diffs):.2f} levels of 255")
    for key, values in psnr.items():
        if values:
            p = psnr_summary(values)
            print(f"  {key} novel view at the first source camera {labels[key]:<46} masked PSNR mean {p['mean']:.2f} "
                  f"dB, median {p['median']:.2f} ({p['scored']} scenes; {p['no_view']} without a view, "
                  f"{p['nonfinite']} not finite)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
