"""BODY_25 joints -> Unity humanoid bone rotations for the VMC protocol (pure numpy).

Frames
------
Rig frame (input): x right, y down, z forward (away from the cameras), metres;
right-handed, like an OpenCV camera. Unity (output): x right, y up, z forward,
metres; left-handed. The conversion keeps every physical direction and flips
the sign of y:

    p_unity = (x_rig, -y_rig, z_rig)

A rotation R_rig becomes S R_rig S with S = diag(1, -1, 1); for a quaternion
(x, y, z, w) that is (-x, y, -z, w). This module converts positions first and
then does all rotation maths in Unity coordinates, so no rotation needs
converting. Quaternions are (x, y, z, w) as VMC sends them; the formulas are
the usual Hamilton ones, which are also Unity's.

Rest pose
---------
Rotations are relative to a T-pose facing Unity +z (a VRM "normalised" avatar,
whose bones all have identity rotation in that pose), so each bone has a rest
direction: arms point to -x (left) / +x (right), spine and neck +y, legs -y,
feet +z. A person facing the cameras faces rig -z, so their Hips carry a 180
degree yaw (unless the vmc:// ``facing=camera`` option turned the joints round
first: ``vmc_view``).

How each bone is solved
-----------------------
- Hips: a frame from the hip line (RHip - LHip = right) and the spine
  (MidHip -> Neck = up). Chest: the same from the shoulder line. Spine: half
  way between them (slerp), which spreads torso twist over the two bones.
- Limbs, Neck and Foot: the parent's rotation followed by the shortest arc
  that turns the parent-rotated rest direction onto the observed segment
  (swing only: BODY_25 has no joint that shows the twist of a limb).
- Head: a frame from the ears (right) and ear-centre -> nose (forward).
- Hands: identity local rotation (BODY_25 has no hand joints).
A bone whose joints are missing (NaN, confidence <= 0, or a coordinate the binary
wire cannot carry: ``xyz_fits_the_wire``, the encoder's own rule) is left out, so
receivers keep its last pose; its children are left out too. Without Hips no bone is sent.

Local position of each bone is its anchor joint relative to its parent's
anchor, in the parent's rotated frame, so forward kinematics from Root/Pos
reproduces the measured skeleton. Spine and Chest have no BODY_25 joint; they
are anchored at 10 % and 45 % of the way from MidHip to Neck.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Optional

import numpy as np

from firmware_host.protocol.quantize import xyz_fits_the_wire
from ghnerf_runtime.body25 import JOINT_INDEX as J

# ---- frames and quaternions (batch-first: (..., 3) points, (..., 4) quaternions) ----

_FLIP_Y = np.array([1.0, -1.0, 1.0])
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def rig_to_unity(points: np.ndarray) -> np.ndarray:
    """(..., 3) rig-frame points -> Unity points (flip y)."""
    return np.asarray(points, dtype=np.float64) * _FLIP_Y


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    # np.cross costs ~20 us per call on 3-vectors (axis juggling); this is ~3x cheaper.
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a*b of (..., 4) (x, y, z, w) quaternions: rotate by b, then a."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def quat_conj(q: np.ndarray) -> np.ndarray:
    return np.asarray(q, np.float64) * np.array([-1.0, -1.0, -1.0, 1.0])


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (..., 3) vectors by unit (..., 4) quaternions."""
    q = np.asarray(q, np.float64)
    u, w = q[..., :3], q[..., 3:]
    v = np.asarray(v, np.float64)
    t = 2.0 * _cross(u, v)
    return v + w * t + _cross(u, t)


def quat_from_matrix(m: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix (columns = rotated x, y, z axes) -> unit quaternion, w >= 0."""
    m = np.asarray(m, np.float64)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    # Shepperd's method: divide by the largest of the four candidates for stability.
    if tr > 0:
        s = 2.0 * np.sqrt(1.0 + tr)
        v = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        v = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        v = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        v = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    q = np.array(v, dtype=np.float64)
    q /= np.linalg.norm(q)
    return q if q[3] >= 0 else -q


def quat_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Shortest-arc rotation taking direction a onto direction b (both (3,), any length)."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    d = float(np.dot(a, b))
    if d < -1.0 + 1e-9:  # opposite: any axis perpendicular to a, 180 degrees
        axis = _cross(a, np.array([1.0, 0.0, 0.0]))
        if np.linalg.norm(axis) < 1e-6:
            axis = _cross(a, np.array([0.0, 1.0, 0.0]))
        axis /= np.linalg.norm(axis)
        return np.array([*axis, 0.0])
    q = np.array([*_cross(a, b), 1.0 + d])
    return q / np.linalg.norm(q)


def quat_slerp(a: np.ndarray, b: np.ndarray, t: float) -> np.ndarray:
    d = float(np.dot(a, b))
    if d < 0:  # take the short way round
        b, d = -b, -d
    if d > 0.9995:
        q = a + t * (b - a)
        return q / np.linalg.norm(q)
    theta = np.arccos(d)
    return (np.sin((1 - t) * theta) * a + np.sin(t * theta) * b) / np.sin(theta)


def _nonzero(v: np.ndarray) -> bool:
    return bool(np.linalg.norm(v) > 1e-6)


def frame_from_axes(right: np.ndarray, up: np.ndarray) -> Optional[np.ndarray]:
    """Rotation whose x axis is ``right`` and whose y axis is ``up`` made orthogonal to it
    (z = x cross y, forward). None when the axes are degenerate."""
    if not (_nonzero(right) and _nonzero(up)):
        return None
    x = right / np.linalg.norm(right)
    y = up - np.dot(up, x) * x
    n = np.linalg.norm(y)
    if not np.isfinite(n) or n < 1e-6:
        return None
    y /= n
    return quat_from_matrix(np.stack([x, y, _cross(x, y)], axis=1))


def frame_from_right_forward(right: np.ndarray, forward: np.ndarray) -> Optional[np.ndarray]:
    if not (_nonzero(right) and _nonzero(forward)):
        return None
    x = right / np.linalg.norm(right)
    z = forward - np.dot(forward, x) * x
    n = np.linalg.norm(z)
    if not np.isfinite(n) or n < 1e-6:
        return None
    z /= n
    return quat_from_matrix(np.stack([x, _cross(z, x), z], axis=1))


# ---- the skeleton -----------------------------------------------------------------------

UP, DOWN, LEFT, RIGHT, FORWARD = (
    np.array(v, np.float64) for v in ([0, 1, 0], [0, -1, 0], [-1, 0, 0], [1, 0, 0], [0, 0, 1])
)

# Unity HumanBodyBones names in parent-before-child order, with their parent here.
BONE_PARENTS: dict[str, Optional[str]] = {
    "Hips": None,
    "Spine": "Hips",
    "Chest": "Spine",
    "Neck": "Chest",
    "Head": "Neck",
    "LeftUpperArm": "Chest",
    "LeftLowerArm": "LeftUpperArm",
    "LeftHand": "LeftLowerArm",
    "RightUpperArm": "Chest",
    "RightLowerArm": "RightUpperArm",
    "RightHand": "RightLowerArm",
    "LeftUpperLeg": "Hips",
    "LeftLowerLeg": "LeftUpperLeg",
    "LeftFoot": "LeftLowerLeg",
    "RightUpperLeg": "Hips",
    "RightLowerLeg": "RightUpperLeg",
    "RightFoot": "RightLowerLeg",
}


@dataclass(frozen=True)
class BonePose:
    name: str
    local_position: np.ndarray  # (3,) metres, Unity axes, in the parent's frame
    local_rotation: np.ndarray  # (4,) x, y, z, w relative to the parent
    global_rotation: np.ndarray  # (4,) relative to the T-pose, for tests and debugging
    anchor: np.ndarray  # (3,) Unity position of the bone's origin


@dataclass(frozen=True)
class VmcPose:
    root_position: np.ndarray  # (3,) hips (MidHip) in Unity metres
    bones: dict[str, BonePose]  # only the bones that could be solved, parents first


class _Joints:
    """Unity-frame joint lookup that knows which joints are missing."""

    def __init__(self, joints_3d: np.ndarray) -> None:
        with np.errstate(over="ignore"):  # a long double past float64's range is inf, missing below: nothing to warn
            j = np.asarray(joints_3d, np.float64)
        if j.ndim != 2 or j.shape[1] != 4 or j.shape[0] < len(J):
            raise ValueError(f"joints_3d must have shape (25, 4) for BODY_25, got {j.shape}")
        self.p = rig_to_unity(j[:, :3])
        # A joint the binary wire cannot carry is missing here too, by the encoder's own rule on the rig frame's
        # coordinates (its range is not symmetric): it reached the receiver as a root or bone offset of 1e20 m,
        # and past float32's range (3.4e38) python-osc raised OverflowError on every frame.
        self.ok = xyz_fits_the_wire(j[:, :3]) & (j[:, 3] > 0)

    def get(self, *names: str) -> Optional[list[np.ndarray]]:
        idx = [J[n] for n in names]
        return [self.p[i] for i in idx] if all(self.ok[i] for i in idx) else None

    def mid(self, a: str, b: str) -> Optional[np.ndarray]:
        pts = self.get(a, b)
        return None if pts is None else (pts[0] + pts[1]) / 2


def _swing(parent_global: np.ndarray, rest: np.ndarray, segment: Optional[np.ndarray]) -> Optional[np.ndarray]:
    """Global rotation: the parent's, then the shortest arc onto the observed segment."""
    if segment is None or not _nonzero(segment):
        return None
    return quat_mul(quat_between(quat_rotate(parent_global, rest), segment), parent_global)


def _segment(js: _Joints, a: str, b: str) -> Optional[tuple[np.ndarray, np.ndarray]]:
    pts = js.get(a, b)
    return None if pts is None else (pts[0], pts[1] - pts[0])


def solve_pose(joints_3d: np.ndarray) -> Optional[VmcPose]:
    """(25, 4) BODY_25 joints in the rig frame (metres, confidence) -> bone poses.

    Returns None when the hips cannot be solved (MidHip, Neck and a left/right
    pair of hips or shoulders are needed).
    """
    js = _Joints(joints_3d)
    torso = js.get("MidHip", "Neck")
    if torso is None:
        return None
    mid_hip, neck = torso
    up = neck - mid_hip
    hips_lr = js.get("LHip", "RHip")
    shoulders_lr = js.get("LShoulder", "RShoulder")
    hip_right = hips_lr[1] - hips_lr[0] if hips_lr else None
    chest_right = shoulders_lr[1] - shoulders_lr[0] if shoulders_lr else None
    right = hip_right if hip_right is not None else chest_right  # shoulders stand in for hips
    hips_q = frame_from_axes(right, up) if right is not None else None
    if hips_q is None:
        return None
    chest_q = frame_from_axes(chest_right, up) if chest_right is not None else None
    if chest_q is None:
        chest_q = hips_q  # no shoulders: an untwisted torso

    glob: dict[str, np.ndarray] = {"Hips": hips_q}
    anchor: dict[str, np.ndarray] = {"Hips": mid_hip}
    glob["Spine"] = quat_slerp(hips_q, chest_q, 0.5)
    anchor["Spine"] = mid_hip + 0.10 * up
    glob["Chest"] = chest_q
    anchor["Chest"] = mid_hip + 0.45 * up

    ear_mid = js.mid("LEar", "REar")
    if ear_mid is not None:
        neck_q = _swing(chest_q, UP, ear_mid - neck)
        if neck_q is not None:
            glob["Neck"], anchor["Neck"] = neck_q, neck
            ears, nose = js.get("LEar", "REar"), js.get("Nose")
            head_q = frame_from_right_forward(ears[1] - ears[0], nose[0] - ear_mid) if ears and nose else None
            if head_q is not None:
                glob["Head"], anchor["Head"] = head_q, (neck + ear_mid) / 2

    def limb(names: tuple[str, str, str], joints: tuple[str, str, str], rest: np.ndarray, parent: str,
             third: Callable[[np.ndarray], Optional[np.ndarray]]) -> None:
        upper, lower, end = names
        a, b, c = joints
        seg = _segment(js, a, b)
        if seg is None or (q := _swing(glob[parent], rest, seg[1])) is None:
            return
        glob[upper], anchor[upper] = q, seg[0]
        seg = _segment(js, b, c)
        if seg is None or (q := _swing(glob[upper], rest, seg[1])) is None:
            return
        glob[lower], anchor[lower] = q, seg[0]
        end_q = third(glob[lower])
        if end_q is not None:
            glob[end], anchor[end] = end_q, seg[0] + seg[1]

    limb(("LeftUpperArm", "LeftLowerArm", "LeftHand"), ("LShoulder", "LElbow", "LWrist"), LEFT, "Chest",
         lambda parent: parent)
    limb(("RightUpperArm", "RightLowerArm", "RightHand"), ("RShoulder", "RElbow", "RWrist"), RIGHT, "Chest",
         lambda parent: parent)
    for side, s in (("Left", "L"), ("Right", "R")):
        def foot(parent: np.ndarray, s: str = s) -> Optional[np.ndarray]:
            toes = js.mid(f"{s}BigToe", f"{s}SmallToe")
            heel = js.get(f"{s}Heel")
            if toes is None or heel is None:
                return None
            return _swing(parent, FORWARD, toes - heel[0])

        limb((f"{side}UpperLeg", f"{side}LowerLeg", f"{side}Foot"), (f"{s}Hip", f"{s}Knee", f"{s}Ankle"), DOWN,
             "Hips", foot)

    bones: dict[str, BonePose] = {}
    for name, parent in BONE_PARENTS.items():
        if name not in glob or (parent is not None and parent not in bones):
            continue  # unsolved, or its parent is: receivers keep their last pose
        if parent is None:
            local_q, local_p = glob[name], np.zeros(3)
        else:
            inv = quat_conj(glob[parent])
            local_q = quat_mul(inv, glob[name])
            local_p = quat_rotate(inv, anchor[name] - anchor[parent])
        bones[name] = BonePose(name, local_p, local_q / np.linalg.norm(local_q), glob[name], anchor[name])
    return VmcPose(root_position=mid_hip, bones=bones)


def keep_hemisphere(pose: Optional[VmcPose], last: dict[str, np.ndarray]) -> Optional[VmcPose]:
    """``pose`` with each local rotation's sign chosen to be nearest the one sent last (``last``, by bone name,
    updated here). q and -q are the same rotation, but the solver's sign jumps wherever w crosses 0: a person
    facing the cameras has Hips at a 180 degree yaw, so the sign flipped with every frame's noise, and a
    receiver that smooths or interpolates component-wise swung the avatar round through the T-pose."""
    if pose is None:
        return None
    bones: dict[str, BonePose] = {}
    for name, bone in pose.bones.items():
        q = bone.local_rotation
        prev = last.get(name)
        if prev is not None and float(np.dot(q, prev)) < 0:
            q = -q
            bone = replace(bone, local_rotation=q)
        last[name] = q
        bones[name] = bone
    return VmcPose(root_position=pose.root_position, bones=bones)
