"""Where the simulated rig's two cameras stand: a validated description that builds a :class:`Rig`.

Default (chosen for GHNeRF-style wide-baseline input at the size the device
runs): two 640x480 cameras, 80 degree horizontal field of view, 1.2 m apart,
1.3 m above the floor, both aimed at a point 0.95 m high and 3.0 m in front
of the rig, so the optical axes converge at about 23 degrees. The working
volume is the box 2-4 m in front of the rig and +-0.8 m to the sides, floor
to 2.1 m high: a 2.0 m person standing anywhere inside it is entirely in
both images (tested).

Not modelled: lens vignetting, rolling shutter, sensor tilt, focus blur.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from drivers.sim.errors import SimConfigError
from ghnerf_runtime.geometry import Camera, Rig, WorkingVolume, intrinsics_from_fov, look_at


@dataclass(frozen=True)
class RigPlacement:
    """Two-camera rig geometry, in rig-frame metres (x right, y down, z forward).

    Attributes:
        baseline_m: distance between the camera centres (0.05 to 4 m).
        convergence_deg: angle between the optical axes; ``None`` aims both cameras at the
            target point (``distance_m`` ahead, ``target_height_m`` high).
        camera_height_m: height of the cameras above the floor (0.3 to 3 m).
        distance_m: distance from the rig to the subject's standing position (1 to 8 m).
        target_height_m: height the cameras look at (0 to 2.5 m).
        width, height: image size per camera in pixels.
        hfov_deg: horizontal field of view (20 to 150 degrees).
        distortion: OpenCV coefficients ``k1 k2 p1 p2 [k3 ...]`` for both cameras (``()``: none).
        volume_half_width_m: working volume half-extent along x.
        volume_depth_m: working volume extent along z, centred on ``distance_m``.
        names: the two camera names.
    """

    baseline_m: float = 1.2
    convergence_deg: float | None = None
    camera_height_m: float = 1.3
    distance_m: float = 3.0
    target_height_m: float = 0.95
    width: int = 640
    height: int = 480
    hfov_deg: float = 80.0
    distortion: tuple[float, ...] = ()
    volume_half_width_m: float = 0.8
    volume_depth_m: float = 2.0
    names: tuple[str, str] = field(default=("left", "right"))

    def __post_init__(self) -> None:
        def check(name: str, lo: float, hi: float) -> None:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or not lo <= value <= hi:
                raise SimConfigError(f"RigPlacement.{name}", f"must be a number in [{lo}, {hi}], got {value!r}")

        check("baseline_m", 0.05, 4.0)
        check("camera_height_m", 0.3, 3.0)
        check("distance_m", 1.0, 8.0)
        check("target_height_m", 0.0, 2.5)
        check("hfov_deg", 20.0, 150.0)
        check("volume_half_width_m", 0.1, 5.0)
        check("volume_depth_m", 0.2, 10.0)
        if self.distance_m - self.volume_depth_m / 2 < 0.5:
            raise SimConfigError("RigPlacement.volume_depth_m", f"puts the working volume within 0.5 m of the rig ({self.volume_depth_m} m deep at {self.distance_m} m)")
        if self.convergence_deg is not None:
            check("convergence_deg", -10.0, 120.0)
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 16 <= value <= 8192:
                raise SimConfigError(f"RigPlacement.{name}", f"must be an int in [16, 8192], got {value!r}")
        dist = tuple(self.distortion)
        if len(dist) not in (0, 4, 5, 8) or not all(isinstance(c, (int, float)) and np.isfinite(c) and abs(c) < 5 for c in dist):
            raise SimConfigError("RigPlacement.distortion", f"must be 0, 4, 5 or 8 finite coefficients (|c| < 5), got {self.distortion!r}")
        if len(self.names) != 2 or not all(isinstance(n, str) and n for n in self.names) or self.names[0] == self.names[1]:
            raise SimConfigError("RigPlacement.names", f"must be two distinct non-empty names, got {self.names!r}")

    @property
    def target(self) -> np.ndarray:
        """The point both cameras look at (rig frame)."""
        return np.array([0.0, -self.target_height_m, self.distance_m])

    def build(self, rig_id: str = "sim") -> Rig:
        """The :class:`Rig`: cameras at ``x = -+baseline/2`` (``names[0]`` on the left, -x)."""
        K = intrinsics_from_fov(self.width, self.height, self.hfov_deg)
        cams = []
        for name, sign in zip(self.names, (-1.0, 1.0)):
            eye = np.array([sign * self.baseline_m / 2, -self.camera_height_m, 0.0])
            if self.convergence_deg is None:
                target = self.target
            else:
                # Toe each camera in by half the convergence angle, pitched at the target height.
                yaw = -sign * np.radians(self.convergence_deg) / 2
                target = eye + np.array([np.sin(yaw), 0.0, np.cos(yaw)]) * self.distance_m
                target[1] = -self.target_height_m
            R, t = look_at(eye, target)
            cams.append(Camera(name, self.width, self.height, K, np.asarray(self.distortion or np.zeros(5), float), R, t))
        hw, hd = self.volume_half_width_m, self.volume_depth_m / 2
        volume = WorkingVolume((-hw, -2.1, self.distance_m - hd), (hw, 0.05, self.distance_m + hd))
        return Rig(tuple(cams), volume, rig_id, metadata={"source": "drivers.sim.placement", "placement": repr(self)})

    @classmethod
    def random(cls, rng: np.random.Generator, *, width: int = 640, height: int = 480) -> "RigPlacement":
        """A random but sensible rig for training data (narrow to wide baselines, 2-4 m)."""
        distance = float(rng.uniform(2.2, 4.0))
        return cls(
            baseline_m=float(rng.uniform(0.1, 1.8)),
            camera_height_m=float(rng.uniform(0.8, 2.0)),
            distance_m=distance,
            target_height_m=float(rng.uniform(0.8, 1.1)),
            width=width,
            height=height,
            hfov_deg=float(rng.uniform(60.0, 90.0)),
            volume_half_width_m=0.5,
            volume_depth_m=1.0,
        )
