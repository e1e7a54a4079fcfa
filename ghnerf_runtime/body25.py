"""The BODY_25 joint set (OpenPose order), used by every layer that names joints."""
from __future__ import annotations

JOINT_NAMES: tuple[str, ...] = (
    "Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist",
    "MidHip", "RHip", "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle", "REye", "LEye",
    "REar", "LEar", "LBigToe", "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel",
)
NUM_JOINTS = len(JOINT_NAMES)
JOINT_INDEX: dict[str, int] = {name: i for i, name in enumerate(JOINT_NAMES)}

# Limbs as (parent, child) index pairs, the OpenPose BODY_25 drawing order.
LIMBS: tuple[tuple[int, int], ...] = (
    (1, 8), (1, 2), (1, 5), (2, 3), (3, 4), (5, 6), (6, 7), (8, 9), (9, 10), (10, 11),
    (8, 12), (12, 13), (13, 14), (1, 0), (0, 15), (15, 17), (0, 16), (16, 18),
    (14, 19), (19, 20), (14, 21), (11, 22), (22, 23), (11, 24),
)

#: Joint index of each joint's mirror image (RShoulder <-> LShoulder, ...): a horizontally flipped
#: image shows the person's right side where a left side would be.
FLIP_INDEX: tuple[int, ...] = tuple(
    JOINT_INDEX[("L" + n[1:]) if n.startswith("R") else ("R" + n[1:]) if n.startswith("L") else n]
    for n in JOINT_NAMES
)

#: Joint groups for per-part scores (``ghnerf-eval`` reports PCK per part: the arms, thin and fast,
#: are where a small model fails first).
BODY_PARTS: dict[str, tuple[int, ...]] = {
    "head": tuple(JOINT_INDEX[n] for n in ("Nose", "REye", "LEye", "REar", "LEar")),
    "torso": tuple(JOINT_INDEX[n] for n in ("Neck", "RShoulder", "LShoulder", "MidHip", "RHip", "LHip")),
    "arms": tuple(JOINT_INDEX[n] for n in ("RElbow", "RWrist", "LElbow", "LWrist")),
    "legs": tuple(JOINT_INDEX[n] for n in ("RKnee", "RAnkle", "LKnee", "LAnkle")),
    "feet": tuple(JOINT_INDEX[n] for n in ("LBigToe", "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel")),
}

#: The joints nearest the floor of a person standing, walking or sitting: the ankles and the feet (FEET's, both
#: feet together). The daemon's floor check (firmware_host.daemon.calibration_watch) reads them by foot (FEET).
FLOOR_JOINTS: tuple[int, ...] = tuple(JOINT_INDEX[n] for n in ("RAnkle", "LAnkle")) + BODY_PARTS["feet"]
#: The floor joints of each foot, the right then the left: the floor check measures the lower foot's height by the
#: median of its joints (ghnerf_runtime.joints3d.lower_foot_m).
FEET: tuple[tuple[int, ...], tuple[int, ...]] = tuple(
    tuple(JOINT_INDEX[side + n] for n in ("Ankle", "BigToe", "SmallToe", "Heel")) for side in "RL")

# Torso joints used for the PCK reference length (see docs/metrics.md).
NECK, MID_HIP = JOINT_INDEX["Neck"], JOINT_INDEX["MidHip"]
