"""Estimator results (and simulator ground truth) as joint-stream frames, for the demo and the daemon."""
from __future__ import annotations

import numpy as np

import drivers
from firmware_host.protocol.messages import JointFrame
from ghnerf_runtime.estimator import PairResult

__all__ = ["estimate_frame", "truth_frame"]


def truth_frame(pair: drivers.FramePair) -> JointFrame | None:
    """The simulator's ground-truth 3D joints of ``pair`` (confidence 1), or None when it carries none."""
    if pair.joints_3d is None:
        return None
    joints = np.concatenate([pair.joints_3d, np.ones((len(pair.joints_3d), 1))], axis=1)
    return JointFrame(
        sequence=pair.sequence,
        capture_time_us=pair.frames[0].timestamp_ns // 1000,
        joint_set=0,
        joints_3d=joints,
    )


def estimate_frame(pair: drivers.FramePair, result: PairResult) -> JointFrame:
    """The estimate as a sink frame: missing joints are NaN with confidence 0 (missing on the wire).

    The 2D joints are keyed by camera index in ``pair.frames`` order (the rig's pair order), which is
    the order of the names a sink announces in HELLO (``open_sink(url, cameras=...)``).
    """
    missing = np.asarray(result.missing, bool)
    xyz = np.where(missing[:, None], np.nan, result.joints_3d)
    conf = np.where(missing, 0.0, result.confidence)
    joints_2d = {}
    for index, frame in enumerate(pair.frames):
        m2 = np.asarray(result.missing_2d[frame.camera], bool)
        uv = np.where(m2[:, None], np.nan, result.joints_2d[frame.camera])
        joints_2d[index] = np.column_stack([uv, np.where(m2, 0.0, result.confidence_2d[frame.camera])])
    return JointFrame(
        sequence=pair.sequence,
        capture_time_us=pair.frames[0].timestamp_ns // 1000,
        joint_set=0,
        joints_3d=np.column_stack([xyz, conf]),
        joints_2d=joints_2d,
    )
