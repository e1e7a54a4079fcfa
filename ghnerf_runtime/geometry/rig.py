"""A rig: named calibrated cameras plus the working volume where a person can stand."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ghnerf_runtime.bound_text import past_bound
from ghnerf_runtime.errors import GeometryError
from ghnerf_runtime.geometry.camera import Camera, check_last_dim

#: The shortest stereo baseline the runtime accepts. Real rigs have centimetres to a metre; a shorter one is a
#: calibration that never placed the cameras (at 1 cm and 3 m, one pixel of disparity is about 0.5 m of depth).
MIN_BASELINE_M = 0.01
#: The longest stereo baseline the runtime accepts. The model learnt 0.1-1.8 m and the bench's rigs are about a
#: metre; a rig whose translations are in millimetres but read as metres has its pair a thousand times too far
#: apart (the example rig's 7.5 cm: 75 m), and one of 1e200 overflowed the baseline to inf, both accepted.
MAX_BASELINE_M = 10.0


@dataclass(frozen=True, eq=False)
class WorkingVolume:
    """Axis-aligned box in the rig frame (metres) where the subject can be."""

    min_corner: np.ndarray
    max_corner: np.ndarray

    def __post_init__(self) -> None:
        lo = np.asarray(self.min_corner, dtype=np.float64).reshape(-1)
        hi = np.asarray(self.max_corner, dtype=np.float64).reshape(-1)
        if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise GeometryError(f"working volume corners must be finite 3-vectors, got {lo.tolist()}, {hi.tolist()}")
        if np.any(hi <= lo):
            raise GeometryError(f"working volume max {hi.tolist()} must exceed min {lo.tolist()} on every axis")
        with np.errstate(over="ignore"):
            span = np.concatenate([hi - lo, hi + lo])  # the size and (twice) the centre
        if not np.all(np.isfinite(span)):  # corners of +-1e308: its size or centre overflowed to inf
            raise GeometryError(f"working volume from {lo.tolist()} to {hi.tolist()} is too large for float64")
        for name, value in (("min_corner", lo), ("max_corner", hi)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def center(self) -> np.ndarray:
        return 0.5 * (self.min_corner + self.max_corner)

    @property
    def size(self) -> np.ndarray:
        return self.max_corner - self.min_corner

    def corners(self) -> np.ndarray:
        """The 8 corners ``(8, 3)``."""
        lo, hi = self.min_corner, self.max_corner
        idx = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)])
        return np.where(idx == 1, hi, lo)

    def contains(self, points: np.ndarray) -> np.ndarray:
        points = check_last_dim("points", points, 3)
        return np.all((points >= self.min_corner) & (points <= self.max_corner), axis=-1)

    def grown(self, margin: float) -> "WorkingVolume":
        return WorkingVolume(self.min_corner - margin, self.max_corner + margin)


@dataclass(frozen=True, eq=False)
class Rig:
    """Two or more named cameras sharing the rig frame, plus the working volume.

    Camera order is meaningful: the first two cameras are the stereo pair the
    drivers deliver and the model consumes.
    """

    cameras: tuple[Camera, ...]
    volume: WorkingVolume
    rig_id: str = "rig"
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        cameras = tuple(self.cameras)
        if len(cameras) < 2:
            raise GeometryError(f"a rig needs at least two cameras, got {len(cameras)}")
        names = [c.name for c in cameras]
        if len(set(names)) != len(names):
            raise GeometryError(f"camera names must be unique, got {names}")
        object.__setattr__(self, "cameras", cameras)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.cameras)

    def camera(self, name: str) -> Camera:
        for cam in self.cameras:
            if cam.name == name:
                return cam
        raise KeyError(f"rig {self.rig_id!r} has no camera {name!r}; cameras: {list(self.names)}")

    def __getitem__(self, name: str) -> Camera:
        return self.camera(name)

    @property
    def pair(self) -> tuple[Camera, Camera]:
        """The first two cameras: the stereo pair."""
        return self.cameras[0], self.cameras[1]

    @property
    def baseline(self) -> float:
        """Distance between the pair's centres, metres (``inf`` where it overflows float64)."""
        a, b = self.pair
        with np.errstate(over="ignore", invalid="ignore"):  # translations of 1e200: inf, refused by baseline_problem
            distance = float(np.linalg.norm(a.center - b.center))
        return distance if not np.isnan(distance) else np.inf

    def far_camera_problem(self) -> tuple[int, str] | None:
        """The first camera after the pair whose centre lies farther than :data:`MAX_BASELINE_M` from the first
        camera's, and why; or None. The pair's bound, for the same reason: translations in millimetres read as
        metres (or of 1e200) were refused for the pair and loaded for a third camera."""
        first = self.cameras[0]
        for k, cam in enumerate(self.cameras[2:], start=2):
            with np.errstate(over="ignore", invalid="ignore"):  # translations of 1e200: inf
                distance = float(np.linalg.norm(cam.center - first.center))
            if not distance <= MAX_BASELINE_M:  # NaN too
                shown = past_bound(distance, MAX_BASELINE_M, 4)  # never "10 m" for 10.00001 m
                return k, (f"camera {cam.name!r} is {shown} m from camera {first.name!r} (at most "
                           f"{MAX_BASELINE_M:g} m accepted, as between the pair's): translations in millimetres read "
                           "as metres? The rig's translations are in metres")
        return None

    def baseline_problem(self) -> str | None:
        """Why the pair cannot triangulate (its centres closer than :data:`MIN_BASELINE_M`), or why its translations
        are not metres (farther apart than :data:`MAX_BASELINE_M`), or None."""
        baseline = self.baseline
        if MIN_BASELINE_M <= baseline <= MAX_BASELINE_M:
            return None
        a, b = self.pair
        if baseline > MAX_BASELINE_M:
            return (f"cameras {a.name!r} and {b.name!r} are {past_bound(baseline, MAX_BASELINE_M, 4)} m apart "
                    f"(at most {MAX_BASELINE_M:g} m accepted): translations in millimetres read as metres? The rig's "
                    "translations are in metres (a foreign file's are converted with units_to_metres, 0.001 for "
                    "millimetres)")
        shown_mm = past_bound(baseline * 1e3, MIN_BASELINE_M * 1e3, 1, "f")  # never "10.0 mm" for 9.99999 mm
        return (f"cameras {a.name!r} and {b.name!r} are {shown_mm} mm apart (at least "
                f"{MIN_BASELINE_M * 1e3:.0f} mm needed): two views from one point give no depth, so every joint would "
                "be missing. Were only the intrinsics calibrated, or one camera's pose copied to both? Solve the "
                "pair's extrinsics (ghcal solve)")

    def projection_matrices(self) -> np.ndarray:
        """``(C, 3, 4)`` projection matrices for undistorted pixels."""
        return np.stack([c.P for c in self.cameras])
