"""Sensor model: exposure gain, read + shot noise and 8-bit quantisation of gamma-encoded images.

Noise and exposure jitter are drawn from a generator seeded by
``(scene seed, camera name, time in microseconds)``, so a frame re-rendered
with the same inputs is bit-identical, while the two cameras and successive
frames get independent noise. Gaussian noise comes from a 256-entry
inverse-CDF table indexed by random bytes: exact Gaussian quantiles, tails
cut at 2.9 sigma, about 20x faster than ``Generator.standard_normal``.

Not modelled: motion blur, rolling shutter, Bayer demosaicing, vignetting,
lens flare, hot pixels, compression artefacts, auto-exposure dynamics.
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass
from statistics import NormalDist

import cv2
import numpy as np

from drivers.sim.errors import SimConfigError

GAMMA = 2.2
# Inverse-CDF table: byte k -> the Gaussian quantile at (k + 0.5) / 256, rescaled to unit variance.
_Q = np.array([NormalDist().inv_cdf((k + 0.5) / 256.0) for k in range(256)], dtype=np.float64)
NOISE_LUT = (_Q / _Q.std()).astype(np.float32)


@dataclass(frozen=True)
class SensorModel:
    """How radiance becomes an 8-bit image.

    Attributes:
        exposure: linear gain on scene radiance (1.0 = nominal; 2.0 one stop brighter).
        exposure_jitter: standard deviation of the per-frame, per-camera log2 gain (stops).
        read_noise: standard deviation of signal-independent noise, in 8-bit levels.
        shot_noise: signal-dependent variance per level (variance = read^2 + shot * level).
    """

    exposure: float = 1.0
    exposure_jitter: float = 0.0
    read_noise: float = 1.5
    shot_noise: float = 0.0

    def __post_init__(self) -> None:
        for name, lo, hi in (("exposure", 0.05, 20.0), ("exposure_jitter", 0.0, 2.0), ("read_noise", 0.0, 50.0), ("shot_noise", 0.0, 10.0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or not lo <= v <= hi:
                raise SimConfigError(f"SensorModel.{name}", f"must be a number in [{lo}, {hi}], got {v!r}")

    def rng(self, seed: int, camera: str, t: float) -> np.random.Generator:
        """The generator for one frame of one camera."""
        t_us = int(round(float(t) * 1e6)) & 0xFFFF_FFFF_FFFF_FFFF
        return np.random.default_rng([int(seed) & 0xFFFF_FFFF_FFFF_FFFF, zlib.crc32(camera.encode()), t_us])

    def capture(self, display: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Display-space image ``(H, W, 3)`` float32 (gamma-encoded, 1.0 = white at exposure 1)
        -> uint8 image (same channel order)."""
        gain = self.exposure
        if self.exposure_jitter > 0:
            gain *= 2.0 ** (self.exposure_jitter * float(rng.standard_normal()))
        # A gain on radiance is a gain of gain^(1/gamma) on gamma-encoded values.
        scale = 255.0 * gain ** (1.0 / GAMMA)
        if self.read_noise > 0 or self.shot_noise > 0:
            raw = rng.bit_generator.random_raw((display.size + 7) // 8).view(np.uint8)[: display.size]
            noise = cv2.LUT(raw.reshape(display.shape), NOISE_LUT)
            if self.shot_noise > 0:
                img = display * np.float32(scale)
                sigma = cv2.sqrt(np.float32(self.read_noise**2) + np.float32(self.shot_noise) * np.maximum(img, np.float32(0)))
                img += noise * sigma
            else:
                img = cv2.scaleAdd(display, scale, noise * np.float32(self.read_noise))
        else:
            img = display * np.float32(scale)
        # Clamp negatives, then round and saturate to 8 bits.
        img = cv2.threshold(img, 0.0, 0.0, cv2.THRESH_TOZERO)[1]
        return cv2.convertScaleAbs(img)
