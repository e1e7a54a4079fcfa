"""What the drivers deliver: frames, frame pairs and (from simulated or recorded rigs) ground truth."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ghnerf_runtime.geometry import Rig


@dataclass(frozen=True, eq=False)
class CameraTruth:
    """Per-camera ground truth rendered with a simulated frame.

    Attributes:
        joints_2d: ``(25, 2)`` BODY_25 joint pixels in this camera's (distorted) image.
        visible: ``(25,)`` bool: in the image, in front of the camera and not occluded by the body.
        mask: ``(H, W)`` bool foreground (person) mask.
        depth: ``(H, W)`` float32 camera-z depth in metres, ``inf`` on background.
        part_labels: ``(H, W)`` uint8 body-part id (0 = background; ids in ``drivers.sim.body.PART_NAMES``).
    """

    joints_2d: np.ndarray
    visible: np.ndarray
    mask: np.ndarray
    depth: np.ndarray
    part_labels: np.ndarray


@dataclass(frozen=True, eq=False)
class Frame:
    """One image from one camera.

    Attributes:
        camera: the camera's name in the rig.
        image: ``(H, W, 3)`` uint8, BGR (OpenCV order).
        timestamp_ns: monotonic capture time in nanoseconds (host clock domain).
        index: the camera's own frame counter (gaps mean the camera dropped frames).
        truth: ground truth when the backend has it (simulated or recorded-with-truth).
        scene_time_s: for simulated frames, the scene time the image shows.
        joints_3d: ``(25, 3)`` ground-truth joints in the rig frame (metres) at this capture, when known.
    """

    camera: str
    image: np.ndarray
    timestamp_ns: int
    index: int
    truth: CameraTruth | None = None
    scene_time_s: float | None = None
    joints_3d: np.ndarray | None = None

    def __post_init__(self) -> None:
        # a NumPy integer stamp (a backend's int64 array) held as Python's: the pairer's differences of two int64
        # stamps far apart (a clock that wrapped, one camera's reset) overflowed, warning and pairing on wrapped values
        if isinstance(self.timestamp_ns, np.integer):
            object.__setattr__(self, "timestamp_ns", int(self.timestamp_ns))


@dataclass(frozen=True, eq=False)
class FramePair:
    """Two synchronised frames of the rig's stereo pair.

    Attributes:
        frames: the two frames, in the order of ``rig.pair``.
        sequence: increasing pair number assigned by the driver (gaps: pairs dropped).
        rig: the calibrated rig the frames belong to.
    """

    frames: tuple[Frame, Frame]
    sequence: int
    rig: Rig

    @property
    def joints_3d(self) -> np.ndarray | None:
        """Ground-truth ``(25, 3)`` joints at the first camera's capture time, when known."""
        return self.frames[0].joints_3d

    @property
    def images(self) -> tuple[np.ndarray, np.ndarray]:
        return self.frames[0].image, self.frames[1].image

    @property
    def timestamps_ns(self) -> tuple[int, int]:
        return self.frames[0].timestamp_ns, self.frames[1].timestamp_ns

    @property
    def skew_ns(self) -> int:
        """Capture-time difference between the two frames."""
        return abs(self.frames[0].timestamp_ns - self.frames[1].timestamp_ns)

    def frame(self, camera: str) -> Frame:
        for f in self.frames:
            if f.camera == camera:
                return f
        raise KeyError(f"pair {self.sequence} has no frame from camera {camera!r}")
