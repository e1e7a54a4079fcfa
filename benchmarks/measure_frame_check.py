"""What the frame check measures on the bench's frames, on darker and noisier versions of them, and on garbage.

    .venv/bin/python benchmarks/measure_frame_check.py [--model-dir models] [--sequences 10] [--frames 30]
                                                       [--pairs-per-sequence 4]

The frame check (``ghnerf_runtime.estimator.check_crop``) rejects a camera's crop as ``flat`` below
``frame_check.min_std`` levels of standard deviation and as ``noise`` where more than ``frame_check.max_noise_ratio``
of its variance is pixel-to-pixel detail (``crop_statistics``) and more than ``frame_check.max_coarse_noise_ratio``
of its 2x2 block means' variance is (``coarse_detail_share``). This prints the measures and the check's verdicts
for each kind of frame below, over each camera's working-volume (cold) crop and a crop about the person as a
track would frame them (the joints' box, 1.2 times, plus 10 px), on a few pairs of each held-out-like bench
sequence (``ghnerf-bench runtime``'s). The scene kinds are the bench's frames made dim, low-contrast or noisy as a
sensor makes them (Gaussian noise of the given standard deviation, 8-bit levels), and dim scenes through a sensor
model: with ``light`` the share of the bench's light reaching the sensor and ``gain`` its amplification, a pixel
of level ``v`` collects ``N = v * light * E_PER_LEVEL`` photo-electrons, drawn from a Poisson law of that mean
(shot noise, ``sqrt(N)``), plus Gaussian read noise of ``READ_NOISE_E`` electrons, and reads
``(N + read) * gain / E_PER_LEVEL`` levels, rounded and clipped to 0-255 (a small webcam or OAK sensor: about
5,000 electrons full well at unity gain). The garbage kinds are what a broken stream delivers. Each kind's noise
is drawn afresh per frame from one seeded generator. A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from ghnerf_runtime.cli.simdata import load_sequences  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import (  # noqa: E402
    Estimator, check_crop, coarse_detail_share, crop_statistics, load_session)
from ghnerf_runtime.preprocess import Roi, preprocess_image  # noqa: E402

Frame = Callable[[np.ndarray, np.random.Generator], np.ndarray]


def _levels(x: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(x), 0, 255).astype(np.uint8)


def _dim(gain: float, noise: float = 0.0) -> Frame:
    return lambda im, rng: _levels(im * gain + (rng.normal(0.0, noise, im.shape) if noise else 0.0))


#: Photo-electrons per 8-bit level at unity gain (full well about 5,100 e-) and read noise, electrons rms.
E_PER_LEVEL = 20.0
READ_NOISE_E = 4.0


def _sensor(light: float, gain: float) -> Frame:
    """The scene with ``light`` of the bench's light, shot and read noise, amplified ``gain`` times."""
    def frame(im: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        photo = rng.poisson(im.astype(np.float64) * (light * E_PER_LEVEL))
        electrons = photo + rng.normal(0.0, READ_NOISE_E, im.shape)
        return _levels(electrons * (gain / E_PER_LEVEL))
    return frame


def _low_contrast(keep: float) -> Frame:
    return lambda im, rng: _levels(128.0 + (im.astype(np.float32) - 128.0) * keep)


def _uniform_noise(im: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return rng.integers(0, 256, im.shape, dtype=np.uint8)


def _grey_noise(sigma: float) -> Frame:
    return lambda im, rng: _levels(128.0 + rng.normal(0.0, sigma, im.shape))


def _block_noise(im: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Noise in 2x2 blocks, as a sensor binning or a half-resolution stream scaled up gives it."""
    h, w = im.shape[:2]
    half = rng.integers(0, 256, ((h + 1) // 2, (w + 1) // 2, im.shape[2]), dtype=np.uint8)
    return np.repeat(np.repeat(half, 2, axis=0), 2, axis=1)[:h, :w]


def _blurred_noise(sigma_px: float) -> Frame:
    """Uniform noise smoothed by a Gaussian of ``sigma_px`` pixels (a stream's garbage through a denoiser)."""
    return lambda im, rng: cv2.GaussianBlur(_uniform_noise(im, rng), (0, 0), sigma_px)


#: (kind, what it is, frame from the bench frame)
KINDS: tuple[tuple[str, str, Frame], ...] = (
    ("bench frame", "scene", lambda im, rng: im),
    ("dim x0.1", "scene", _dim(0.1)),
    ("dim x0.05", "scene", _dim(0.05)),
    ("contrast x0.15", "scene", _low_contrast(0.15)),
    ("+ noise 10", "scene", _dim(1.0, 10.0)),
    ("+ noise 25", "scene", _dim(1.0, 25.0)),
    ("+ noise 40", "scene", _dim(1.0, 40.0)),
    ("dim x0.1 + noise 2", "scene", _dim(0.1, 2.0)),
    ("dim x0.1 + noise 4", "scene", _dim(0.1, 4.0)),
    ("dim x0.2 + noise 6", "scene", _dim(0.2, 6.0)),
    ("+ noise 60", "scene", _dim(1.0, 60.0)),
    ("dim x0.1 + noise 8", "scene", _dim(0.1, 8.0)),
    ("light x0.1 gain x10", "scene", _sensor(0.1, 10.0)),
    ("light x0.02 gain x50", "scene", _sensor(0.02, 50.0)),
    ("light x0.01 gain x100", "scene", _sensor(0.01, 100.0)),
    ("light x0.005 gain x200", "scene", _sensor(0.005, 200.0)),
    ("light x0.0025 gain x400", "scene", _sensor(0.0025, 400.0)),
    ("uniform noise", "garbage", _uniform_noise),
    ("grey + noise 5", "garbage", _grey_noise(5.0)),
    ("grey + noise 20", "garbage", _grey_noise(20.0)),
    ("2x2 block noise", "garbage", _block_noise),
    ("noise blurred 0.7 px", "garbage", _blurred_noise(0.7)),
    ("noise blurred 1.5 px", "garbage", _blurred_noise(1.5)),
)


def person_roi(uv: np.ndarray) -> Roi | None:
    """A square window about the visible joints ``uv`` (distorted pixels, near enough), as a track frames them."""
    if len(uv) == 0:
        return None
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    side = float(np.max(hi - lo)) * 1.2 + 10.0
    centre = (lo + hi) / 2.0
    return Roi(int(centre[0] - side / 2.0), int(centre[1] - side / 2.0), max(1, int(side)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--sequences", type=positive_count, default=10)
    ap.add_argument("--frames", type=positive_count, default=30)
    ap.add_argument("--pairs-per-sequence", type=positive_count, default=4)
    args = ap.parse_args(argv)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir))
    session = load_session(cfg)
    rng = np.random.default_rng(0)
    measured = {kind: [] for kind, _, _ in KINDS}  # kind -> (std levels, detail share, coarse share, reason)
    for seq in load_sequences(args.sequences, args.frames):
        est = Estimator(session, seq.rig, cfg)
        for i in np.linspace(0, len(seq) - 1, args.pairs_per_sequence).round().astype(int):
            for c in (0, 1):
                image = np.asarray(seq.images[i, c])
                rois = [est.tracker.volume_regions.rois[c], person_roi(seq.joints_2d[i, c][seq.visible[i, c]])]
                for roi in (r for r in rois if r is not None):
                    maps, _ = est._crop(est._cams[c], roi)
                    for kind, _, frame in KINDS:
                        plane = preprocess_image(frame(image, rng), maps, session.contract.normalisation)[1]
                        stats = crop_statistics(plane, est._levels, maps.inside) or (0.0, float("inf"))
                        coarse = coarse_detail_share(plane, maps.inside)
                        measured[kind].append((*stats, coarse, check_crop(plane, est._levels, cfg.frame_check,
                                                                          maps.inside)[1]))
        est.close()
    fc = cfg.frame_check
    print(f"{args.sequences} bench sequences x {args.pairs_per_sequence} pairs x 2 cameras, cold and person crops; "
          f"the check: flat below {fc.min_std:g} levels, noise above a detail share of {fc.max_noise_ratio:g} "
          f"and a coarse (2x2 block means') share of {fc.max_coarse_noise_ratio:g}")
    print(f"{'kind':>24} {'':>7} {'crops':>5}  std levels min / median   detail share min / median / max   "
          f"coarse share min / median / max   rejected flat / noise / noise by the fine share alone")
    for kind, what, _ in KINDS:
        std = np.array([m[0] for m in measured[kind]])
        share = np.array([m[1] for m in measured[kind]])
        coarse = np.array([m[2] for m in measured[kind]])
        reasons = [m[3] for m in measured[kind]]
        fine_alone = sum(r != "flat" and s > fc.max_noise_ratio for r, s in zip(reasons, share))
        n = len(reasons)
        print(f"{kind:>24} {what:>7} {n:>5}  {std.min():10.1f} / {np.median(std):6.1f}   "
              f"{share.min():14.3f} / {np.median(share):.3f} / {share.max():.3f}   "
              f"{coarse.min():14.3f} / {np.median(coarse):.3f} / {coarse.max():.3f}   "
              f"{reasons.count('flat'):>9} / {reasons.count('noise')} / {fine_alone}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
