"""Drive our skeleton with any BVH clip: joint-name mapping, rest-pose alignment, looping playback.

Mapping: BVH names are normalised (namespace such as ``mixamorig:`` dropped,
case and punctuation ignored, ``Left``/``Right``/``L``/``R``/``_l``/``.R``
side markers recognised) and matched against aliases covering the CMU,
Mixamo, Truebones/Motionbuilder and Unreal conventions. The chest is the
lowest common ancestor of the two upper arms, and the spine the joint midway
between hips and chest, so spine chains of any length work.

Retargeting: the clip's axes (up, left) are read from its rest pose, so Y-up
and Z-up files both work. Each mapped joint takes the clip's global rotation,
corrected by the fixed rotation between the two rest poses (a T-pose clip
drives our arms-down rest pose correctly), and then swung so that each of our
bones points exactly where the clip's corresponding bone points. Our bone
lengths are kept; the root translation is scaled by the ratio of hip heights,
and the clip's floor is taken to be at height 0 (checked against the feet).

Not modelled: foot-contact clean-up (feet may slide or float slightly when
proportions differ), finger and face joints, several characters per file.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.sim.bvh import BvhClip, BvhJoint, load_bvh
from drivers.sim.errors import BvhError
from drivers.sim.motions import Pose
from drivers.sim.rotations import align_vectors, matrix_to_euler, matrix_to_quat, quat_nlerp, quat_to_matrix, rot_z
from drivers.sim.skeleton import JOINT_ID, JOINTS, PARENTS, Skeleton

# Aliases per joint, in priority order ("arm" before "shoulder": Mixamo's Shoulder is the clavicle).
_CENTRE_ALIASES = {
    "pelvis": ("hips", "hip", "pelvis", "root", "bip01pelvis"),
    "neck": ("neck", "neck1", "neck01", "necklower"),
    "head": ("head",),
}
_SIDED_ALIASES = {
    "shoulder": ("arm", "upperarm", "uparm", "humerus", "shoulder"),
    "elbow": ("forearm", "lowerarm", "elbow", "radius"),
    "wrist": ("hand", "wrist"),
    "hip": ("upleg", "upperleg", "thigh", "hip", "femur"),
    "knee": ("leg", "lowerleg", "knee", "shin", "calf", "tibia"),
    "ankle": ("foot", "ankle"),
    "toe": ("toebase", "toe", "toes", "ball", "toe0"),
}
REQUIRED = ("pelvis",) + tuple(f"{s}_{j}" for s in "rl" for j in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle"))

# Which of our joints each joint's bone points at (None: a leaf, whose direction is _LEAF_DIRS).
_PRIMARY_CHILD = {
    "pelvis": "spine", "spine": "chest", "chest": "neck", "neck": "head", "head": None,
    "r_shoulder": "r_elbow", "r_elbow": "r_wrist", "r_wrist": None,
    "l_shoulder": "l_elbow", "l_elbow": "l_wrist", "l_wrist": None,
    "r_hip": "r_knee", "r_knee": "r_ankle", "r_ankle": None,
    "l_hip": "l_knee", "l_knee": "l_ankle", "l_ankle": None,
}
# Where the chain's bone points when its primary child is not in the file (a one-joint spine, no neck):
# the next of our joints up the chain that is, never the clip joint's first child (often a thigh).
_CHAIN_TARGETS = {"pelvis": ("spine", "chest", "neck", "head"), "spine": ("chest", "neck", "head"),
                  "chest": ("neck", "head"), "neck": ("head",)}
FOOT_DIR = np.array([0.0, -0.45, 1.0]) / np.linalg.norm([0.0, -0.45, 1.0])
_LEAF_DIRS = {"head": np.array([0.0, 1.0, 0.0]), "r_wrist": np.array([0.0, -1.0, 0.0]), "l_wrist": np.array([0.0, -1.0, 0.0]),
              "r_ankle": FOOT_DIR, "l_ankle": FOOT_DIR}


def normalize_name(name: str) -> tuple[str, str]:
    """``(side, base)`` of a BVH joint name: side is ``"l"``, ``"r"`` or ``""``.

    >>> normalize_name("mixamorig:LeftForeArm"), normalize_name("upperarm_r"), normalize_name("RHip")
    (('l', 'forearm'), ('r', 'upperarm'), ('r', 'hip'))
    """
    raw = name.split(":")[-1].split("|")[-1]
    side = ""
    m = re.match(r"^([LR])(?=[A-Z])(.+)$", raw)  # LHip, RForeArm (CamelCase single letter)
    if m:
        side, raw = m.group(1).lower(), m.group(2)
    low = raw.lower()
    if not side:
        m = re.match(r"^(left|right)[\s_.\-]*(.+)$", low) or re.match(r"^([lr])[\s_.\-]+(.+)$", low)
        if m:
            side, low = m.group(1)[0], m.group(2)
    if not side:
        m = re.match(r"^(.+?)[\s_.\-]+(left|right|l|r)$", low) or re.match(r"^(.+?)(left|right)$", low)
        if m:
            side, low = m.group(2)[0], m.group(1)
    return side, re.sub(r"[^a-z0-9]", "", low)


def map_joints(clip: BvhClip) -> dict[str, int]:
    """Our joint name (and ``r_toe``/``l_toe``) -> index of the clip joint that drives it.

    Raises:
        BvhError: a required joint (pelvis, shoulders, elbows, wrists, hips, knees, ankles)
            has no match; the message lists the clip's joint names.
    """
    keys = [normalize_name(j.name) for j in clip.joints]
    found: dict[str, int] = {}

    def find(side: str, aliases: tuple[str, ...]) -> int | None:
        for alias in aliases:
            for k, key in enumerate(keys):
                if key == (side, alias):
                    return k
        return None

    for ours, aliases in _CENTRE_ALIASES.items():
        k = find("", aliases)
        if k is not None:
            found[ours] = k
    for side in ("r", "l"):
        for ours, aliases in _SIDED_ALIASES.items():
            k = find(side, aliases)
            if k is not None:
                found[f"{side}_{ours}"] = k
    missing = [j for j in REQUIRED if j not in found]
    if missing:
        raise BvhError(clip.source, None, f"cannot map joints {missing} to this BVH's joints {list(clip.names)}")
    # Chest: lowest common ancestor of both upper arms; spine: midway between hips and chest.
    chain_r, chain_l = _ancestors(clip, found["r_shoulder"]), _ancestors(clip, found["l_shoulder"])
    common = [k for k in chain_r if k in chain_l]
    if common and common[0] != found["pelvis"]:
        found["chest"] = common[0]
        chain = _ancestors(clip, common[0])
        between = chain[1 : chain.index(found["pelvis"])] if found["pelvis"] in chain else []
        if between:
            found["spine"] = between[len(between) // 2]
    return found


def _ancestors(clip: BvhClip, k: int) -> list[int]:
    """``k`` and its ancestors, nearest first."""
    out = []
    while k >= 0:
        out.append(k)
        k = clip.joints[k].parent
    return out


def _leaf_direction(clip: BvhClip, rest: np.ndarray, k: int) -> np.ndarray | None:
    """Rest direction of clip joint ``k``'s own bone: towards its children (a hand's fingers: the middle
    finger, else the mean of all but the thumb, which rigs often list first), else to its End Site."""
    children = clip.children(k)
    names = [clip.joints[c].name.lower() for c in children]
    children = ([c for c, n in zip(children, names) if "middle" in n]
                or [c for c, n in zip(children, names) if "thumb" not in n] or children)
    dirs = [rest[c] - rest[k] for c in children]
    dirs = [d / np.linalg.norm(d) for d in dirs if np.linalg.norm(d) > 1e-9]
    if dirs and np.linalg.norm(np.mean(dirs, axis=0)) > 1e-6:
        return np.mean(dirs, axis=0)
    if clip.joints[k].end_site is not None:
        return clip.joints[k].end_site.copy()
    return None


@dataclass(frozen=True, eq=False)
class Retargeted:
    """Per-frame local rotations ``(F, 17, 3, 3)`` and pelvis positions ``(F, 3)`` (body frame)."""

    rotations: np.ndarray
    roots: np.ndarray
    frame_time: float
    mapping: dict[str, str]


def retarget(clip: BvhClip, skeleton: Skeleton, *, in_place: bool = True) -> Retargeted:
    """Retarget every frame of ``clip`` onto ``skeleton``.

    Args:
        in_place: remove the clip's net horizontal travel (a least-squares line) and centre it,
            so the person stays where the scene puts them; ``False`` keeps the clip's horizontal
            root path (scaled).
    """
    found = map_joints(clip)
    Gb, Pb = clip.forward()
    P0_clip = clip.rest_positions()
    C = _clip_axes(clip, P0_clip, found)
    Gb = C @ Gb @ C.T
    Pb = Pb @ C.T
    P0 = P0_clip @ C.T
    rest = skeleton.rest_positions()
    F = clip.num_frames
    G = np.empty((F, len(JOINTS), 3, 3))
    for j, name in enumerate(JOINTS):
        parent = PARENTS[j]
        b = found.get(name)
        if b is None:
            G[:, j] = G[:, parent] if parent >= 0 else np.eye(3)
            continue
        child = _PRIMARY_CHILD[name]
        if child is not None:
            target = next((c for c in _CHAIN_TARGETS.get(name, (child,)) if c in found), child)
            ours = rest[JOINT_ID[target]] - rest[j]
            child_b = found.get(target)
        else:
            ours = _LEAF_DIRS[name]
            child_b = found.get(name.replace("ankle", "toe")) if name.endswith("ankle") else None
        if child_b is not None:
            theirs = P0[child_b] - P0[b]
        else:
            leaf = _leaf_direction(clip, P0_clip, b)
            theirs = None if leaf is None else C @ leaf
        A = np.eye(3) if theirs is None else align_vectors(ours, theirs)
        Gj = Gb[:, b] @ A
        if child_b is not None:
            Gj = align_vectors(Gj @ ours, Pb[:, child_b] - Pb[:, b]) @ Gj
        G[:, j] = Gj
    parents = np.array([max(p, 0) for p in PARENTS])
    L = np.swapaxes(G[:, parents], -1, -2) @ G
    L[:, 0] = G[:, 0]
    scale = _scale(rest, P0, found, clip.source)
    roots = scale * Pb[:, found["pelvis"]]
    # Vertical: most files put their floor at height 0; trust that unless our ankles would then
    # go below the floor or never come near it, in which case the lowest ankle over the clip is
    # put at our rest ankle height.
    ankles = [JOINT_ID["r_ankle"], JOINT_ID["l_ankle"]]
    ank_off = skeleton.forward(L, np.zeros((F, 3)))[1][:, ankles, 1]
    lowest = float(np.min(roots[:, None, 1] + ank_off))
    if not 0.0 < lowest < rest[ankles, 1].mean() + 0.15:
        roots[:, 1] += rest[ankles, 1].mean() - lowest
    if in_place:
        f = np.arange(F, dtype=np.float64)
        for axis in (0, 2):
            slope, icpt = np.polyfit(f, roots[:, axis], 1) if F > 1 else (0.0, roots[0, axis])
            roots[:, axis] -= slope * f + icpt
        roots[:, [0, 2]] += rest[0, [0, 2]]
    mapping = {ours: clip.joints[k].name for ours, k in found.items()}
    return Retargeted(L, roots, clip.frame_time, mapping)


def _clip_axes(clip: BvhClip, P0: np.ndarray, found: dict[str, int]) -> np.ndarray:
    """Rotation taking clip coordinates to the body frame (x left, y up, z forward)."""
    top = found.get("head", found.get("neck", found.get("chest", found["l_shoulder"])))
    up = P0[top] - P0[found["pelvis"]]
    left = (P0[found["l_hip"]] - P0[found["r_hip"]]) + (P0[found["l_shoulder"]] - P0[found["r_shoulder"]])
    if np.linalg.norm(up) < 1e-9:
        raise BvhError(clip.source, None, "rest pose has the head at the hips; cannot tell which way is up")
    up = up / np.linalg.norm(up)
    left = left - (left @ up) * up
    if np.linalg.norm(left) < 1e-9:
        raise BvhError(clip.source, None, "rest pose has left and right limbs on top of each other; cannot tell left from right")
    left /= np.linalg.norm(left)
    # Files are authored on coordinate axes (Y-up or Z-up); snap near-axis estimates so a rest
    # pose that leans slightly does not tilt the whole clip.
    up, left = _snap(up), _snap(left)
    if abs(up @ left) > 1e-9:
        left = left - (left @ up) * up
        left /= np.linalg.norm(left)
    return np.stack([left, up, np.cross(left, up)])


def _snap(v: np.ndarray, max_deg: float = 25.0) -> np.ndarray:
    """``v`` (unit) replaced by the nearest signed coordinate axis when within ``max_deg``."""
    i = int(np.argmax(np.abs(v)))
    if abs(v[i]) >= np.cos(np.radians(max_deg)):
        out = np.zeros(3)
        out[i] = np.sign(v[i])
        return out
    return v


def _scale(rest: np.ndarray, P0: np.ndarray, found: dict[str, int], source: str) -> float:
    ours = rest[JOINT_ID["pelvis"], 1] - rest[[JOINT_ID["r_ankle"], JOINT_ID["l_ankle"]], 1].mean()
    theirs = P0[found["pelvis"], 1] - P0[[found["r_ankle"], found["l_ankle"]], 1].mean()
    if theirs <= 1e-9:
        raise BvhError(source, None, "rest pose has the hips at or below the ankles")
    return float(ours / theirs)


class BvhMotion:
    """A BVH clip playing in a loop on our skeleton (implements the scene's ``Motion``).

    The loop length is ``frames * frame_time``: the last frame blends back into the first over
    one frame time, so a clip authored as one cycle (without repeating its first frame) loops
    seamlessly. Between frames, joint rotations are interpolated on the unit quaternion sphere.

    Args:
        source: a ``.bvh`` path or a parsed :class:`BvhClip`.
        skeleton: the body to drive.
        in_place: see :func:`retarget`.
    """

    grounded = False
    planted = False

    def __init__(self, source: str | Path | BvhClip, skeleton: Skeleton, *, in_place: bool = True) -> None:
        clip = source if isinstance(source, BvhClip) else load_bvh(source)
        self.clip = clip
        self.name = Path(clip.source).stem if clip.source != "<string>" else "bvh"
        result = retarget(clip, skeleton, in_place=in_place)
        self.mapping = result.mapping
        self._quats = matrix_to_quat(result.rotations)
        self._roots = result.roots
        self.frame_time = clip.frame_time
        self.period_s = clip.num_frames * clip.frame_time

    def pose(self, t: float) -> Pose:
        F = len(self._roots)
        f = (float(t) % self.period_s) / self.frame_time
        i0 = int(np.floor(f)) % F
        i1 = (i0 + 1) % F
        alpha = f - np.floor(f)
        q = quat_nlerp(self._quats[i0], self._quats[i1], alpha)
        root = (1 - alpha) * self._roots[i0] + alpha * self._roots[i1]
        return Pose(quat_to_matrix(q), root)


# ------------------------------------------------------------------- exporting
CMU_NAMES = {
    "pelvis": "Hips", "spine": "Spine", "chest": "Spine1", "neck": "Neck", "head": "Head",
    "r_shoulder": "RightArm", "r_elbow": "RightForeArm", "r_wrist": "RightHand",
    "l_shoulder": "LeftArm", "l_elbow": "LeftForeArm", "l_wrist": "LeftHand",
    "r_hip": "RightUpLeg", "r_knee": "RightLeg", "r_ankle": "RightFoot",
    "l_hip": "LeftUpLeg", "l_knee": "LeftLeg", "l_ankle": "LeftFoot",
}


def clip_from_poses(
    skeleton: Skeleton,
    rotations: np.ndarray,
    roots: np.ndarray,
    frame_time: float,
    *,
    order: str = "zxy",
    t_pose: bool = True,
    units: float = 100.0,
    prefix: str = "",
) -> BvhClip:
    """Export poses of our skeleton as a BVH clip with CMU/Mixamo joint names.

    Args:
        rotations: ``(F, 17, 3, 3)`` local rotations; roots: ``(F, 3)`` pelvis positions.
        order: Euler channel order written for every joint (e.g. ``"zxy"``, CMU's).
        t_pose: write a T-pose rest (arms out sideways), as most BVH files have.
        units: file units per metre (100: centimetres).
        prefix: prepended to every name (``"mixamorig:"`` gives Mixamo names).
    """
    rotations = np.asarray(rotations, dtype=np.float64)
    G, _ = skeleton.forward(rotations, np.zeros((len(rotations), 3)))
    # T-pose: arm chains' rest offsets turned out by 90 degrees; their globals turned back.
    Q = np.broadcast_to(np.eye(3), (len(JOINTS), 3, 3)).copy()
    if t_pose:
        for side, s in (("r", -1.0), ("l", 1.0)):
            for part in ("shoulder", "elbow", "wrist"):
                Q[JOINT_ID[f"{side}_{part}"]] = rot_z(s * np.pi / 2)
    Gb = G @ np.swapaxes(Q, -1, -2)
    parents = np.array([max(p, 0) for p in PARENTS])
    Lb = np.swapaxes(Gb[:, parents], -1, -2) @ Gb
    Lb[:, 0] = Gb[:, 0]
    ends = {"head": np.array([0.0, 0.125 * skeleton.scale * skeleton.params.head_size, 0.0]),
            "r_wrist": np.array([0.0, -0.1 * skeleton.scale, 0.0]), "l_wrist": np.array([0.0, -0.1 * skeleton.scale, 0.0]),
            "r_ankle": FOOT_DIR * 0.075 * skeleton.scale, "l_ankle": FOOT_DIR * 0.075 * skeleton.scale}  # ball of the foot
    joints = []
    rot_channels = tuple(f"{a.upper()}rotation" for a in order)
    for j, name in enumerate(JOINTS):
        parent = PARENTS[j]
        # A joint's offset lives in its parent's rest frame, which the T-pose turned by Q[parent].
        offset = skeleton.offsets[j] if parent < 0 else Q[parent] @ skeleton.offsets[j]
        end = ends.get(name)
        joints.append(BvhJoint(
            prefix + CMU_NAMES[name], parent, offset * units,
            (("Xposition", "Yposition", "Zposition") if parent < 0 else ()) + rot_channels,
            None if end is None else (Q[j] @ end) * units,
        ))
    cols = []
    for j in range(len(JOINTS)):
        if PARENTS[j] < 0:
            cols.append(np.asarray(roots, dtype=np.float64) * units)
        cols.append(matrix_to_euler(Lb[:, j], order))
    return BvhClip(tuple(joints), float(frame_time), np.concatenate(cols, axis=1), "<export>")

