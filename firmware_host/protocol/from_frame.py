"""JointFrame (floats from the estimator) -> wire messages."""
from __future__ import annotations

import operator
from collections.abc import Sequence
from typing import Optional

from firmware_host.protocol.constants import U32_MAX, MsgType
from firmware_host.protocol.messages import JointFrame, Joints, Joints2D, make_header
from firmware_host.protocol.quantize import quantise_joints_2d, quantise_joints_3d


def wire_seq(sequence: int) -> int:
    """Producer sequence -> the u32 on the wire (wraps; receivers count gaps modulo 2**32)."""
    return sequence & U32_MAX


def joints_message(frame: JointFrame, send_us: int, flags: int = 0) -> Joints:
    """JOINTS of ``frame``: its header flags are the link's ``flags`` and the frame's own ``scene_flags``."""
    xyz, conf, missing = quantise_joints_3d(frame.joints_3d)
    header = make_header(MsgType.JOINTS, wire_seq(frame.sequence), frame.capture_time_us, send_us,
                         int(flags) | int(frame.scene_flags))
    return Joints(header, frame.joint_set, xyz, conf, missing)


def _as_number(key: object) -> Optional[int]:
    """A ``joints_2d`` key that numbers its camera: a Python or numpy integer (keys taken from ``np.arange``
    or an array's indices were np.int64, looked up as names and left out); None for a name."""
    if isinstance(key, str):
        return None
    try:
        return operator.index(key)  # type: ignore[arg-type]
    except TypeError:
        return None


def camera_index(key: str | int, cameras: Sequence[str]) -> int:
    """Index of a ``joints_2d`` key: integers index ``cameras`` (the order announced in HELLO),
    names are looked up in it. :raises KeyError: a camera HELLO does not announce."""
    number = _as_number(key)
    if number is not None:
        if not 0 <= number < len(cameras):
            raise KeyError(f"camera index {key} is not among the {len(cameras)} announced cameras {list(cameras)!r}")
        return number
    try:
        return list(cameras).index(key)  # type: ignore[arg-type]
    except ValueError:
        raise KeyError(f"camera {key!r} is not in the announced cameras {list(cameras)!r}") from None


def is_announced(key: str | int, cameras: Sequence[str]) -> bool:
    """Whether :func:`camera_index` knows ``key``."""
    number = _as_number(key)
    return 0 <= number < len(cameras) if number is not None else key in cameras


def joints2d_messages(
    frame: JointFrame, send_us: int, cameras: Sequence[str], flags: int = 0
) -> list[Joints2D]:
    out = []
    for key in sorted(frame.joints_2d, key=lambda k: camera_index(k, cameras)):
        uv, conf, missing = quantise_joints_2d(frame.joints_2d[key])
        header = make_header(MsgType.JOINTS_2D, wire_seq(frame.sequence), frame.capture_time_us, send_us,
                             int(flags) | int(frame.scene_flags))
        out.append(Joints2D(header, camera_index(key, cameras), frame.joint_set, uv, conf, missing))
    return out
