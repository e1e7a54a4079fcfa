"""Synthetic multi-view samples from the simulated human scene (``drivers.sim``).

Sample ``index`` of a split is a pure function of ``(split, dataset_seed, index, config)``:
its *scene seed* (``SplitSpec.scene_seed``) drives the simulator (body, clothes, room,
motion, light, sensor: ``random_scene``) and, through an independent stream, everything
chosen here:

1. **Rig**: ``SplitSpec.placement`` (``RigPlacement.random``: 0.1-1.8 m baselines, 2.2-4 m
   away, 60-90 degree lenses; the baseline respects the split's bands). The subject stands in
   the rig's working volume (``random_scene(volume=rig.volume)``).
2. **Time** ``t`` uniform over the motion's period.
3. **Views**: the two rig cameras (sources ``src0``, ``src1``), then ``novel_views`` cameras
   (``novel0``...) on a circle around the subject: random azimuth (full circle), elevation,
   radius and field of view, aimed at the subject's box centre (+ jitter), square images.
4. **ROIs**, as the runtime makes them: by default from the *previous* frame's joints
   (the truth ``lag`` seconds earlier plus Gaussian noise, standing in for the tracker's
   estimate) with a random margin (``roi_from_joints``); in ``cold_start_fraction`` of the
   samples the sources' ROIs come from the working volume (``roi_from_volume``), as on the
   runtime's first frame. Novel views always use the joint ROI.
5. **Render** each view at its crop camera (``training.data.views.render_view``).

Torch-free.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import asdict, dataclass, replace

import numpy as np

from drivers.sim import SimScene, random_scene
from ghnerf_runtime.geometry import Camera, Rig, intrinsics_from_fov, look_at
from ghnerf_runtime.preprocess import Roi, roi_from_joints, roi_from_volume
from training.data.errors import DataConfigError, DataError
from training.data.sample import NUM_SOURCES, Sample
from training.data.splits import SplitSpec, check_dataset_seed
from training.data.views import render_view

#: Stream id of this module's draws (the simulator uses 1..4 for its own streams of a seed).
_SAMPLE_STREAM = 101


@dataclass(frozen=True)
class SyntheticConfig:
    """How synthetic samples are drawn and rendered.

    Attributes:
        resolution: crop side ``S`` in pixels (multiple of 8, 32..512).
        supersample: render factor before the ``INTER_AREA`` reduction (1..4).
        novel_views: novel target cameras per sample (0..4), after the two sources.
        cold_start_fraction: share of samples whose source ROIs come from the working volume.
        margin_frac: ``(lo, hi)`` uniform range of ``roi_from_joints``' ``margin_frac``.
        track_lag_s: ``(lo, hi)`` uniform range of the age of the joints the ROI is built from.
        track_noise_m: standard deviation of the per-joint noise of those joints (metres).
        min_roi_size: ``roi_from_joints``' smallest ROI side (full-image pixels).
        novel_radius_m, novel_elevation_deg, novel_hfov_deg: ``(lo, hi)`` uniform ranges of the
            novel cameras' distance to the subject, elevation above it and horizontal field of view.
        novel_image_size: side of the novel cameras' (square, virtual) full image.
        novel_aim_jitter_m: standard deviation of the novel cameras' aim point around the box centre.
        freestyle_share: share of ``train`` scenes that move ``freestyle`` (random trajectories over
            the body's range of motion) instead of a routine; 0: the routines only
            (``training.data.splits.split_spec``).
    """

    resolution: int = 128
    supersample: int = 2
    novel_views: int = 2
    cold_start_fraction: float = 0.2
    margin_frac: tuple[float, float] = (0.1, 0.35)
    track_lag_s: tuple[float, float] = (0.0, 1.0 / 15.0)
    track_noise_m: float = 0.02
    min_roi_size: int = 64
    novel_radius_m: tuple[float, float] = (2.5, 4.5)
    novel_elevation_deg: tuple[float, float] = (-5.0, 35.0)
    novel_hfov_deg: tuple[float, float] = (45.0, 70.0)
    novel_image_size: int = 512
    novel_aim_jitter_m: float = 0.1
    freestyle_share: float = 0.0

    def __post_init__(self) -> None:
        def fail(name: str, message: str) -> None:
            raise DataConfigError(f"SyntheticConfig.{name}", message)

        def integer(name: str, lo: int, hi: int) -> None:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
                fail(name, f"must be an int in [{lo}, {hi}], got {v!r}")

        def number(name: str, lo: float, hi: float) -> None:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and lo <= v <= hi):
                fail(name, f"must be a number in [{lo}, {hi}], got {v!r}")

        def interval(name: str, lo: float, hi: float) -> None:
            v = getattr(self, name)
            ok = isinstance(v, (tuple, list)) and len(v) == 2 and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)
            if not ok or not lo <= v[0] <= v[1] <= hi:
                fail(name, f"must be a (lo, hi) pair with {lo} <= lo <= hi <= {hi}, got {v!r}")

        integer("resolution", 32, 512)
        if self.resolution % 8:
            fail("resolution", f"must be a multiple of 8 (masks are bit-packed), got {self.resolution}")
        integer("supersample", 1, 4)
        integer("novel_views", 0, 4)
        integer("min_roi_size", 1, 4096)
        integer("novel_image_size", 64, 4096)
        number("cold_start_fraction", 0.0, 1.0)
        number("track_noise_m", 0.0, 0.5)
        number("novel_aim_jitter_m", 0.0, 1.0)
        number("freestyle_share", 0.0, 0.95)
        interval("margin_frac", 0.0, 2.0)
        interval("track_lag_s", 0.0, 1.0)
        interval("novel_radius_m", 1.0, 10.0)
        interval("novel_elevation_deg", -30.0, 80.0)
        interval("novel_hfov_deg", 20.0, 120.0)

    @property
    def view_names(self) -> tuple[str, ...]:
        return tuple(f"src{i}" for i in range(NUM_SOURCES)) + tuple(f"novel{i}" for i in range(self.novel_views))

    def to_json(self) -> dict:
        out = {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}
        if out["freestyle_share"] == 0.0:
            del out["freestyle_share"]  # keeps the manifests of datasets made before it existed valid
        return out

    @classmethod
    def from_json(cls, data: dict) -> "SyntheticConfig":
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(data) - known)
        if unknown:
            raise DataConfigError(f"SyntheticConfig.{unknown[0]}", f"unknown key; known keys: {sorted(known)}")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items()})


@dataclass(frozen=True)
class _Track:
    """The (simulated) tracker state a ROI is built from."""

    joints: np.ndarray  # (25, 3) previous-frame estimate
    margin_frac: float
    lag_s: float


def _fingerprint(obj) -> str:
    return hashlib.sha1(repr(obj).encode()).hexdigest()[:16]


def _novel_camera(name: str, centre: np.ndarray, rng: np.random.Generator, config: SyntheticConfig) -> tuple[Camera, dict]:
    az = float(rng.uniform(0.0, 360.0))
    el = float(rng.uniform(*config.novel_elevation_deg))
    radius = float(rng.uniform(*config.novel_radius_m))
    hfov = float(rng.uniform(*config.novel_hfov_deg))
    aim = centre + rng.normal(0.0, config.novel_aim_jitter_m, 3)
    a, e = np.radians(az), np.radians(el)
    # Azimuth 0 is on the rig's side of the subject (-z); the rig frame is y-down.
    eye = centre + radius * np.array([np.cos(e) * np.sin(a), -np.sin(e), -np.cos(e) * np.cos(a)])
    R, t = look_at(eye, aim)
    n = config.novel_image_size
    camera = Camera(name, n, n, intrinsics_from_fov(n, n, hfov), R=R, t=t)
    return camera, {"azimuth_deg": az, "elevation_deg": el, "radius_m": radius, "hfov_deg": hfov}


def _joint_roi(camera: Camera, track: _Track, config: SyntheticConfig) -> Roi | None:
    return roi_from_joints(camera, track.joints, np.ones(len(track.joints)), track.margin_frac,
                           min_size=config.min_roi_size)


def _source_cameras(rig: Rig) -> list[Camera]:
    return [replace(cam, name=f"src{i}") for i, cam in enumerate(rig.cameras[:NUM_SOURCES])]


def make_sample(spec: SplitSpec, dataset_seed: int, index: int, config: SyntheticConfig) -> Sample:
    """Sample ``index`` of split ``spec`` (deterministic; see the module docstring)."""
    check_dataset_seed(dataset_seed)
    scene_seed = spec.scene_seed(dataset_seed, index)
    rng = np.random.default_rng([scene_seed, _SAMPLE_STREAM])
    placement = spec.placement(rng)
    rig = placement.build()
    scene: SimScene = random_scene(scene_seed, volume=rig.volume, motions=spec.motions,
                                   motion_weights=spec.motion_weights)
    t = float(rng.uniform(0.0, scene.period_s))
    cold = bool(rng.uniform() < config.cold_start_fraction)
    lag = float(rng.uniform(*config.track_lag_s))
    margin = float(rng.uniform(*config.margin_frac))
    previous = scene.joints_3d(t - lag) + rng.normal(0.0, config.track_noise_m, (25, 3))
    track = _Track(previous, margin, lag)
    joints = scene.joints_3d(t)
    lo, hi = scene.bounding_box(t)

    cameras: list[tuple[Camera, Roi, bool]] = []
    for cam in _source_cameras(rig):
        roi = None if cold else _joint_roi(cam, track, config)
        cameras.append((cam, roi if roi is not None else roi_from_volume(cam, rig.volume), roi is None))
    novel_meta = []
    for k in range(config.novel_views):
        cam, meta = _novel_camera(f"novel{k}", 0.5 * (lo + hi), rng, config)
        roi = _joint_roi(cam, track, config) or roi_from_joints(cam, joints, np.ones(25), 0.2)
        if roi is None:
            raise DataError(f"sample {index}: the subject is outside novel camera {k} (scene seed {scene_seed})")
        cameras.append((cam, roi, False))
        novel_meta.append(meta)

    views = tuple(render_view(scene, cam, roi, t, joints, resolution=config.resolution,
                              supersample=config.supersample, roi_from_volume=from_volume)
                  for cam, roi, from_volume in cameras)
    cfg = scene.config
    metadata = {
        "source": "synthetic",
        "split": spec.name,
        "index": int(index),
        "dataset_seed": int(dataset_seed),
        "scene_seed": int(scene_seed),
        "motion": str(cfg.motion),
        "t": t,
        "period_s": float(scene.period_s),
        "speed": float(cfg.speed),
        "heading_deg": float(cfg.heading_deg),
        "position_xz": [float(v) for v in cfg.position_xz],
        "background": bool(cfg.background),
        "placement": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(placement).items()},
        "novel_cameras": novel_meta,
        "cold_start": cold,
        "margin_frac": margin,
        "track_lag_s": lag,
        "body": asdict(scene.skeleton.params),
        "body_fingerprint": _fingerprint(scene.skeleton.params),
        "appearance_fingerprint": _fingerprint(scene.appearance),
    }
    return Sample(views, joints, np.ones(25, dtype=bool), np.stack([lo, hi]), metadata)


__all__ = ["SyntheticConfig", "make_sample"]
