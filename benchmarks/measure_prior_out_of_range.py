"""The skeleton prior on poses it was never trained on: lying, upside down, very tall, far away.

    .venv/bin/python benchmarks/measure_prior_out_of_range.py [--model-dir models/ghnerf] [--scenes 12]
        [--noise-px 1.0] [--limits 0.15,0.25] [--prior FILE]
    .venv/bin/python benchmarks/measure_prior_out_of_range.py --held-out out/s52/data [--scenes 256]

The prior learnt upright people 2.2-4 m from the rig (docs/dataset.md). Here val-split scenes of the simulator
are posed otherwise, their joints projected exactly into crop cameras made as the runtime makes them, with
Gaussian pixel noise (not the encoder's errors: the absolute figures are the noise model's, the comparison
between rows is the point), and fed to the prior and to plain triangulation. Per pose: the share of joints
under the runtime's default gate (``joints3d.max_prior_error_m``), their mean true error and mean expected
error, and the triangulation's median true error; then the prior's disagreement with the triangulation
(``skeleton_prior.disagreement_m``, the runtime's ``joints3d.max_prior_disagreement_m`` check): its spread over
the scenes and the share of scenes over each of ``--limits`` (those the runtime reports as triangulated).

``--held-out DATA``: the same check in distribution, on the 2D joints a device gives: the first ``--scenes`` of
DATA's ``val`` split through the folder's int8 ``human`` graph (flip-tested, decoded as the runtime decodes
them; what ``training.device_joints`` caches), then the prior and the triangulation. Per limit: the pairs
that would fall back, and the MPJPE over the joints reported (the prior's within ``max_prior_error_m``, the
triangulated ones where a pair falls back) with the share of the true joints found. A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import checked_model_folder  # noqa: E402
from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from drivers.sim import random_scene  # noqa: E402
from ghnerf_runtime.config import Joints3DConfig  # noqa: E402
from ghnerf_runtime.joints3d import triangulate_joints  # noqa: E402
from ghnerf_runtime.preprocess import crop_camera, roi_from_joints  # noqa: E402
from ghnerf_runtime.skeleton_prior import FILE_NAME, MIN_CHECK_JOINTS, SkeletonPrior, disagreement_m  # noqa: E402
from training.data.splits import split_spec  # noqa: E402

SIZE = 128  # the shipped model's input side


def _turned(X: np.ndarray, axis: int, deg: float) -> np.ndarray:
    """``X`` turned about its mean by ``deg`` about rig axis ``axis``, then set on the floor (y down, floor y=0)."""
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    i, j = [k for k in range(3) if k != axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    m = X.mean(0)
    Y = (X - m) @ R.T + m
    return Y + [0.0, -0.05 - Y[:, 1].max(), 0.0]


def _scaled(X: np.ndarray, k: float) -> np.ndarray:
    """``X`` k times as large, standing where it stood."""
    m = X.mean(0) * [1.0, 0.0, 1.0]
    return (X - m) * k + m


POSES = {
    "upright (as trained)": lambda X, rig: X,
    "lying (turned 90 deg about x)": lambda X, rig: _turned(X, 0, 90.0),
    "lying (turned 90 deg about z)": lambda X, rig: _turned(X, 2, 90.0),
    "upside down": lambda X, rig: _turned(X, 2, 180.0),
    "1.7 times as tall": lambda X, rig: _scaled(X, 1.7),
    "10 m farther": lambda X, rig: X + 10.0 * _away(X, rig),
}


def _away(X: np.ndarray, rig) -> np.ndarray:
    d = (X.mean(0) - 0.5 * (rig.cameras[0].center + rig.cameras[1].center)) * [1.0, 0.0, 1.0]
    return d / np.linalg.norm(d)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model-dir", help="default: models/ghnerf (not read with --prior: checked after parsing)")
    ap.add_argument("--scenes", type=positive_count, default=12)
    ap.add_argument("--noise-px", type=float, default=1.0)
    ap.add_argument("--limits", default="0.15,0.25", help="disagreement limits (m) to count the pairs over")
    ap.add_argument("--held-out", metavar="DATA", help="measure the check on DATA's val scenes instead")
    ap.add_argument("--prior", metavar="FILE", help=f"the prior to measure (default: the model folder's {FILE_NAME}; "
                                                    "not with --held-out, which runs the folder's)")
    args = ap.parse_args(argv)
    if args.prior and args.held_out:
        ap.error("--prior measures poses out of range; --held-out runs the model folder's own prior")
    if not args.prior:  # checked only where it is read: --prior reads no model folder, given or not
        args.model_dir = checked_model_folder(ap, args.model_dir or "models/ghnerf")
    try:
        limits = [float(x) for x in args.limits.split(",")]
    except ValueError:
        ap.error(f"--limits: comma-separated metres expected, got {args.limits!r}")
    if args.held_out:
        return held_out(args.held_out, Path(args.model_dir), args.scenes, limits)
    prior = SkeletonPrior.load(Path(args.prior) if args.prior else Path(args.model_dir) / FILE_NAME)
    cfg = Joints3DConfig()
    spec = split_spec("val")
    print(f"{'pose':32s} {'gated':>6s} {'true err':>9s} {'expected':>9s} {'triangulated':>13s}  "
          f"disagreement min/median/max  " + "  ".join(f"> {x:g} m" for x in limits))
    for name, pose in POSES.items():
        err, expected, tri_err, apart = [], [], [], []
        for seed in range(args.scenes):
            rng = np.random.default_rng([seed, 7])
            rig = spec.placement(rng).build()
            scene = random_scene(spec.scene_seed(0, seed), volume=rig.volume, motions=spec.motions,
                                 motion_weights=spec.motion_weights)
            X = pose(scene.joints_3d(float(rng.uniform(0.0, scene.period_s))), rig)
            rois = [roi_from_joints(cam, X, np.ones(len(X)), 0.2, 64) for cam in rig.cameras[:2]]
            if any(r is None for r in rois):
                continue
            crops = [crop_camera(cam, roi, SIZE) for cam, roi in zip(rig.cameras[:2], rois)]
            uv = np.stack([c.project(X, distort=False)[0] for c in crops]) + rng.normal(0, args.noise_px,
                                                                                         (2, len(X), 2))
            seen = np.all((uv >= 0) & (uv <= SIZE - 1), axis=-1)
            conf = np.where(seen, 0.8, 0.0)
            est = prior.estimate(uv, conf, seen, [c.P for c in crops])
            kept = est.expected_error_m <= cfg.max_prior_error_m
            err.append(np.where(kept, np.linalg.norm(est.points - X, axis=-1), np.nan))
            expected.append(np.where(kept, est.expected_error_m, np.nan))
            tri = triangulate_joints(uv, conf, seen, crops, cfg)
            tri_err.append(np.linalg.norm(tri.points - X, axis=-1)[tri.valid])
            d = disagreement_m(est.points, tri.points, tri.valid)
            apart.append(np.nan if d is None else d)  # nan: too few joints triangulated to check (never falls back)
        e, x, a = np.concatenate(err), np.concatenate(expected), 1e3 * np.array(apart)
        print(f"{name:32s} {np.mean(~np.isnan(e)):6.2f} {1e3 * np.nanmean(e):7.0f}mm {1e3 * np.nanmean(x):7.0f}mm "
              f"{1e3 * np.median(np.concatenate(tri_err)):11.0f}mm  {np.nanmin(a):5.0f} / {np.nanmedian(a):4.0f} / "
              f"{np.nanmax(a):4.0f} mm  " + "  ".join(f"{np.sum(a > 1e3 * x):3d}/{len(a)}" for x in limits))
    return 0


def held_out(data: str, model_dir: Path, scenes: int, limits: list[float]) -> int:
    """The check on held-out scenes through the device's 2D joints (module docstring)."""
    from ghnerf_runtime.keypoints import decode_keypoints, heatmap_to_model_pixels
    from training.data.torch_dataset import MultiViewDataset
    from training.evaluate import OnnxRenderer, flip_tested

    renderer = OnnxRenderer(model_dir, "int8", 1)
    if renderer.skeleton_prior is None:
        print(f"error: {model_dir} has no skeleton prior the runtime accepts", file=sys.stderr)
        return 2
    ds = MultiViewDataset(data, split="val")
    cfg = Joints3DConfig()
    n = min(scenes, len(ds))
    truth, true_ok, prior_pts, reported, tri_pts, tri_ok, apart = ([] for _ in range(7))
    for i in range(n):
        scene = {k: v.numpy() for k, v in ds[i].items()}
        heat = flip_tested(renderer, scene, renderer.encoder_heatmaps(scene)).astype(np.float32)
        kp = decode_keypoints(heat)
        uv = heatmap_to_model_pixels(kp.uv, heat.shape[-1], renderer.height)
        P = np.asarray(scene["src_P"], np.float64)
        est = renderer.skeleton_prior.estimate(np.where(kp.valid[..., None], uv, 0.0), kp.confidence, kp.valid, P)
        tri = triangulate_joints(uv, kp.confidence, kp.valid, list(P), cfg)
        d = disagreement_m(est.points, tri.points, tri.valid)
        for acc, v in zip((truth, true_ok, prior_pts, reported, tri_pts, tri_ok, apart),
                          (scene["joints_3d"], scene["joints_3d_valid"], est.points,
                           est.expected_error_m <= cfg.max_prior_error_m, tri.points, tri.valid,
                           np.nan if d is None else d)):
            acc.append(np.asarray(v))
    T, ok, Pp, Rp, Xt, Xv, a = (np.stack(v) for v in (truth, true_ok, prior_pts, reported, tri_pts, tri_ok, apart))
    ok = ok.astype(bool)
    e_prior, e_tri = np.linalg.norm(Pp - T, axis=-1), np.linalg.norm(Xt - T, axis=-1)
    am = 1e3 * a
    print(f"{n} val scenes of {data}, {model_dir} (int8, flip-tested 2D joints): the prior's disagreement with the "
          f"triangulation, median {np.nanmedian(am):.1f} mm, 90/99 % {np.nanpercentile(am, 90):.1f} / "
          f"{np.nanpercentile(am, 99):.1f} mm, max {np.nanmax(am):.1f} mm (over {int(np.isfinite(am).sum())} pairs "
          f"with {MIN_CHECK_JOINTS}+ triangulated joints; triangulated joints per pair: min {int(Xv.sum(1).min())})")
    for limit in [np.inf] + limits:
        back = a > limit  # nan (too few joints) compares False: keeps the prior, as the runtime does
        found = np.where(back[:, None], Xv, Rp) & ok
        err = np.where(back[:, None], e_tri, e_prior)
        name = "no check" if limit == np.inf else f"limit {limit:g} m"
        print(f"  {name:14s} pairs falling back {int(back.sum()):3d}/{n}  MPJPE over the joints reported "
              f"{1e3 * err[found].mean():6.2f} mm (median {1e3 * np.median(err[found]):5.1f}), found "
              f"{100 * found.sum() / ok.sum():6.2f} %"
              + (f"  (scenes {np.flatnonzero(back).tolist()})" if 0 < back.sum() <= 5 else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
