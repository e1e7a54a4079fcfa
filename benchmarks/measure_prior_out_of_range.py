"""The skeleton prior on poses it was never trained on: lying, upside down, very tall, far away.

    .venv/bin/python benchmarks/measure_prior_out_of_range.py [--model-dir models/ghnerf] [--scenes 12]
        [--noise-px 1.0]

The prior learnt upright people 2.2-4 m from the rig (docs/dataset.md). Here val-split scenes of the simulator
are posed otherwise, their joints projected exactly into crop cameras made as the runtime makes them, with
Gaussian pixel noise (not the encoder's errors: the absolute figures are the noise model's, the comparison
between rows is the point), and fed to the prior and to plain triangulation. Per pose: the share of joints
under the runtime's default gate (``joints3d.max_prior_error_m``), their mean true error and mean expected
error, and the triangulation's median true error. A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drivers.sim import random_scene  # noqa: E402
from ghnerf_runtime.config import Joints3DConfig  # noqa: E402
from ghnerf_runtime.joints3d import triangulate_joints  # noqa: E402
from ghnerf_runtime.preprocess import crop_camera, roi_from_joints  # noqa: E402
from ghnerf_runtime.skeleton_prior import FILE_NAME, SkeletonPrior  # noqa: E402
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
    ap.add_argument("--model-dir", default="models/ghnerf")
    ap.add_argument("--scenes", type=int, default=12)
    ap.add_argument("--noise-px", type=float, default=1.0)
    args = ap.parse_args(argv)
    prior = SkeletonPrior.load(Path(args.model_dir) / FILE_NAME)
    cfg = Joints3DConfig()
    spec = split_spec("val")
    print(f"{'pose':32s} {'gated':>6s} {'true err':>9s} {'expected':>9s} {'triangulated':>13s}")
    for name, pose in POSES.items():
        err, expected, tri_err = [], [], []
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
        e, x = np.concatenate(err), np.concatenate(expected)
        print(f"{name:32s} {np.mean(~np.isnan(e)):6.2f} {1e3 * np.nanmean(e):7.0f}mm {1e3 * np.nanmean(x):7.0f}mm "
              f"{1e3 * np.median(np.concatenate(tri_err)):11.0f}mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
