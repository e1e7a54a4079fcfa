"""Data types: the sink input (``JointFrame``) and the decoded wire messages.

``JointFrame`` carries floats as the estimator produces them. The wire messages
carry the quantised integers exactly as they travel, so the Python and C
decoders can be compared field for field (``to_json`` gives the canonical form
used by the test vectors).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Union

import numpy as np

from firmware_host.protocol.constants import ALL_SCENE_FLAGS, MAX_JOINTS, PROTOCOL_VERSION, U64_MAX, Flags, MsgType
from ghnerf_runtime.plain_values import is_true_false, whole_number_or_none


def _whole(name: str, value: object, lo: int | None = None, hi: int | None = None) -> int:
    """A JointFrame field that goes on the wire as an integer (numpy integers too) within [lo, hi], as a Python int:
    a numpy integer kept as given failed the file:// sink's JSON in its worker, the frame lost. True/False is refused
    (``sequence=True`` went out as frame 1)."""
    if is_true_false(value):
        raise ValueError(f"JointFrame.{name} must be a whole number, not true/false, got {value!r}")
    number = whole_number_or_none(value)
    if number is None:
        raise ValueError(f"JointFrame.{name} must be a whole number, got {value!r}")
    if (lo is not None and number < lo) or (hi is not None and number > hi):
        raise ValueError(f"JointFrame.{name} must be in [{lo}, {hi}], got {value!r}")
    return number


def _joint_values(name: str, values: object, columns: int) -> None:
    """A (J, columns) array of real numbers (integers or floats; NaN and inf are a missing joint): a bool array went
    out as 1 m joints of confidence 1, an array of objects or text failed in the sink's worker or as missing joints,
    and complex numbers lost their imaginary part with only a warning."""
    a = np.asarray(values)
    if a.ndim != 2 or a.shape[1] != columns:
        raise ValueError(f"JointFrame.{name} must have shape (J, {columns}), got {a.shape}")
    if a.dtype.kind not in "iuf":
        raise ValueError(f"JointFrame.{name} must hold real numbers (an integer or float array), got dtype {a.dtype}")
    _joint_count(name, a.shape[0])


@dataclass(frozen=True)
class JointFrame:
    """One estimated pose, the input of every sink.

    Coordinates are in the rig frame: x right, y down, z forward (away from the
    cameras), metres, origin as defined by the rig file.
    """

    sequence: int
    """Frame counter of the producer; gaps in it are frames that never reached a receiver."""
    capture_time_us: int
    """Capture time of the frame pair, monotonic microseconds (same clock as the sinks' ``clock_us``)."""
    joint_set: int
    """0 = BODY_25 (OpenPose order)."""
    joints_3d: np.ndarray
    """(J, 4) float: x, y, z in metres and confidence 0..1; NaN or confidence 0 = missing."""
    joints_2d: Mapping[Union[str, int], np.ndarray] = field(default_factory=dict)
    """Optional per-camera (J, 3) float: u, v in pixels and confidence 0..1, keyed by camera name or by index
    (a Python or numpy integer) into the cameras the sink announces."""
    scene_flags: int = 0
    """What the estimate is (``Flags`` SEVERAL_PEOPLE, PRIOR_FALLBACK, SINGLE_VIEW, CALIBRATION_SUSPECT,
    SOMEONE_ELSE), sent in the header flags of the frame's JOINTS and JOINTS_2D; the link's own DECIMATED / DROPPED
    are the sink's."""

    def __post_init__(self) -> None:
        # Checked here, at send(): a float or negative time failed only in the sink's worker, and was then
        # kept for every HELLO/STATUS, so the link announced nothing until a good frame came.
        for name, lo, hi in (("sequence", None, None), ("capture_time_us", 0, U64_MAX), ("joint_set", 0, 0xFF),
                             ("scene_flags", 0, 0xFF)):
            object.__setattr__(self, name, _whole(name, getattr(self, name), lo, hi))
        if int(self.scene_flags) & ~ALL_SCENE_FLAGS:
            # A link bit (DECIMATED, DROPPED) or a reserved one set here would tell receivers something untrue.
            raise ValueError(f"JointFrame.scene_flags 0x{int(self.scene_flags):02x} sets bits other than the "
                             f"scene flags 0x{ALL_SCENE_FLAGS:02x} ({Flags(ALL_SCENE_FLAGS)!r})")
        _joint_values("joints_3d", self.joints_3d, 4)
        for cam, uv in self.joints_2d.items():
            if is_true_false(cam):  # True indexed camera 1
                raise ValueError(f"JointFrame.joints_2d key {cam!r}: a camera name or index, not true/false")
            _joint_values(f"joints_2d[{cam!r}]", uv, 3)


def _joint_count(name: str, count: int) -> None:
    """At most MAX_JOINTS joints, what a packet carries: checked when the frame is made, in the producer's thread.
    More (65) failed only as an EncodeError inside a protocol sink's worker, one logged traceback per frame."""
    if count > MAX_JOINTS:
        raise ValueError(f"JointFrame.{name} has {count} joints: the joint stream carries at most {MAX_JOINTS} "
                         f"per frame (MAX_JOINTS, docs/protocol.md)")


@dataclass(frozen=True)
class Header:
    version: int
    msg_type: int
    flags: int
    seq: int
    capture_us: int
    send_us: int

    def to_json(self) -> dict[str, Any]:
        return {
            "version": self.version,
            "flags": self.flags,
            "seq": self.seq,
            "capture_us": self.capture_us,
            "send_us": self.send_us,
        }


def make_header(msg_type: MsgType, seq: int, capture_us: int, send_us: int, flags: int = 0) -> Header:
    return Header(PROTOCOL_VERSION, int(msg_type), int(flags), seq, capture_us, send_us)


@dataclass(frozen=True, eq=False)
class Joints:
    """JOINTS: 3D joints in millimetres. Arrays: xyz_mm (J,3) int16, conf (J,) uint8, missing (J,) bool."""

    header: Header
    joint_set: int
    xyz_mm: np.ndarray
    conf: np.ndarray
    missing: np.ndarray

    def to_json(self) -> dict[str, Any]:
        rows = [
            [int(x), int(y), int(z), int(c), int(m)]
            for (x, y, z), c, m in zip(self.xyz_mm.tolist(), self.conf.tolist(), self.missing.tolist(), strict=True)
        ]
        return {"type": "JOINTS", **self.header.to_json(), "joint_set": self.joint_set, "joints": rows}

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Joints) and self.to_json() == other.to_json()


@dataclass(frozen=True, eq=False)
class Joints2D:
    """JOINTS_2D: one camera's 2D joints. uv_q (J,2) int16 in quarter pixels, conf, missing."""

    header: Header
    camera: int
    joint_set: int
    uv_q: np.ndarray
    conf: np.ndarray
    missing: np.ndarray

    def to_json(self) -> dict[str, Any]:
        rows = [
            [int(u), int(v), int(c), int(m)]
            for (u, v), c, m in zip(self.uv_q.tolist(), self.conf.tolist(), self.missing.tolist(), strict=True)
        ]
        return {
            "type": "JOINTS_2D",
            **self.header.to_json(),
            "camera": self.camera,
            "joint_set": self.joint_set,
            "joints": rows,
        }

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Joints2D) and self.to_json() == other.to_json()


@dataclass(frozen=True)
class Status:
    header: Header
    fps_centi: int  # frames per second x 100 actually sent on this link
    latency_us: int  # send_us - capture_us of the latest frame
    dropped: int  # frames dropped by this sender (queue overflow + failed writes), total
    decimated: int  # frames skipped on purpose to fit the link, total
    fault: int  # constants.Fault

    def to_json(self) -> dict[str, Any]:
        return {
            "type": "STATUS",
            **self.header.to_json(),
            "fps_centi": self.fps_centi,
            "latency_us": self.latency_us,
            "dropped": self.dropped,
            "decimated": self.decimated,
            "fault": self.fault,
        }


@dataclass(frozen=True)
class Hello:
    header: Header
    protocol_version: int
    joint_set: int
    joint_count: int
    units: int  # constants.Units
    frame: int  # constants.CoordFrame
    rig_id: str
    cameras: tuple[str, ...]

    def to_json(self) -> dict[str, Any]:
        return {
            "type": "HELLO",
            **self.header.to_json(),
            "protocol_version": self.protocol_version,
            "joint_set": self.joint_set,
            "joint_count": self.joint_count,
            "units": self.units,
            "frame": self.frame,
            "rig_id": self.rig_id,
            "cameras": list(self.cameras),
        }


Message = Union[Joints, Joints2D, Status, Hello]
