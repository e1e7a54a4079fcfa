"""The simulated person's kinematic skeleton: proportions, rest pose and forward kinematics.

Body frame (used by the skeleton, the body model and the motions): metres,
X = the person's left, Y = up, Z = the person's forward, origin on the floor
below the pelvis. The scene maps it into the rig frame (y down, z away from
the cameras). The rest pose stands upright with the arms hanging straight
down (an "I-pose"); joint rotations are relative to it.

Bone lengths follow anthropometric fractions of stature (Drillis & Contini,
as tabulated by Winter, *Biomechanics and Motor Control of Human Movement*),
scaled so that the top of the head is exactly ``height_m`` above the floor.

Not modelled: clavicles, spine bending inside a segment, fingers, toe joints
and soft-tissue deformation.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from drivers.sim.errors import SimConfigError

JOINTS: tuple[str, ...] = (
    "pelvis", "spine", "chest", "neck", "head",
    "r_shoulder", "r_elbow", "r_wrist", "l_shoulder", "l_elbow", "l_wrist",
    "r_hip", "r_knee", "r_ankle", "l_hip", "l_knee", "l_ankle",
)
PARENTS: tuple[int, ...] = (-1, 0, 1, 2, 3, 2, 5, 6, 2, 8, 9, 0, 11, 12, 0, 14, 15)
JOINT_ID: dict[str, int] = {name: i for i, name in enumerate(JOINTS)}
NUM_SKELETON_JOINTS = len(JOINTS)

# Head top above the skull-base ("head") joint, as a fraction of the nominal stature; the body
# model's head ellipsoid uses the same number so that its crown is the person's height.
HEAD_TOP_ABOVE_HEAD_JOINT = 0.125


@dataclass(frozen=True)
class BodyParams:
    """Body proportions. Every factor is relative to an average adult (1.0).

    Attributes:
        height_m: stature, floor to the top of the head (1.5 to 2.0 m).
        girth: scales torso width/depth and limb radii (0.75 to 1.4).
        shoulder_width: scales the distance between the shoulder joints (0.85 to 1.2).
        hip_width: scales the distance between the hip joints and the pelvis width (0.85 to 1.2).
        leg_length: leg share of the stature (0.92 to 1.08).
        arm_length: arm length relative to the stature (0.92 to 1.08).
        head_size: head size relative to the stature (0.9 to 1.1).
    """

    height_m: float = 1.75
    girth: float = 1.0
    shoulder_width: float = 1.0
    hip_width: float = 1.0
    leg_length: float = 1.0
    arm_length: float = 1.0
    head_size: float = 1.0

    _RANGES = {
        "height_m": (1.5, 2.0),
        "girth": (0.75, 1.4),
        "shoulder_width": (0.85, 1.2),
        "hip_width": (0.85, 1.2),
        "leg_length": (0.92, 1.08),
        "arm_length": (0.92, 1.08),
        "head_size": (0.9, 1.1),
    }

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            lo, hi = self._RANGES[f.name]
            if not isinstance(value, (int, float)) or not np.isfinite(value) or not lo <= value <= hi:
                raise SimConfigError(f"BodyParams.{f.name}", f"must be a number in [{lo}, {hi}], got {value!r}")

    @classmethod
    def random(cls, rng: np.random.Generator) -> "BodyParams":
        """Random proportions within the documented ranges (girth and widths correlated mildly)."""
        girth = float(np.clip(rng.normal(1.0, 0.12), 0.78, 1.35))
        return cls(
            height_m=float(rng.uniform(1.5, 2.0)),
            girth=girth,
            shoulder_width=float(np.clip(rng.normal(1.0, 0.06) + 0.15 * (girth - 1.0), 0.86, 1.19)),
            hip_width=float(np.clip(rng.normal(1.0, 0.06) + 0.15 * (girth - 1.0), 0.86, 1.19)),
            leg_length=float(rng.uniform(0.94, 1.06)),
            arm_length=float(rng.uniform(0.94, 1.06)),
            head_size=float(rng.uniform(0.92, 1.08)),
        )


@dataclass(frozen=True, eq=False)
class Skeleton:
    """Rest offsets of the 17 joints of :data:`JOINTS` for one body.

    Attributes:
        params: the proportions it was built from.
        offsets: ``(17, 3)`` rest offset of each joint from its parent (body frame, metres);
            the root's offset is its rest position.
        scale: metres per unit of nominal stature (``height_m`` divided by the nominal height).
    """

    params: BodyParams
    offsets: np.ndarray
    scale: float

    @classmethod
    def from_params(cls, params: BodyParams) -> "Skeleton":
        p = params
        leg = p.leg_length
        ankle_h = 0.039
        shin, thigh = 0.246 * leg, 0.245 * leg
        hip_h = ankle_h + shin + thigh
        # The trunk absorbs what the legs do not take, so the nominal stature stays ~1.0.
        trunk = 0.29 + (0.491 - 0.491 * leg) * 0.9
        arm = p.arm_length
        off = np.zeros((NUM_SKELETON_JOINTS, 3))
        off[JOINT_ID["pelvis"]] = (0.0, hip_h, 0.0)
        off[JOINT_ID["spine"]] = (0.0, 0.28 * trunk, -0.006)
        off[JOINT_ID["chest"]] = (0.0, 0.38 * trunk, 0.004)
        off[JOINT_ID["neck"]] = (0.0, 0.34 * trunk, 0.002)
        off[JOINT_ID["head"]] = (0.0, 0.052, 0.006)
        for side, sign in (("r", -1.0), ("l", 1.0)):
            off[JOINT_ID[f"{side}_shoulder"]] = (sign * 0.105 * p.shoulder_width, 0.30 * trunk, -0.004)
            off[JOINT_ID[f"{side}_elbow"]] = (0.0, -0.186 * arm, 0.0)
            off[JOINT_ID[f"{side}_wrist"]] = (0.0, -0.146 * arm, 0.0)
            off[JOINT_ID[f"{side}_hip"]] = (sign * 0.05 * p.hip_width, 0.0, 0.0)
            off[JOINT_ID[f"{side}_knee"]] = (0.0, -thigh, 0.0)
            off[JOINT_ID[f"{side}_ankle"]] = (0.0, -shin, -0.004)
        nominal_top = hip_h + 0.28 * trunk + 0.38 * trunk + 0.34 * trunk + 0.052 + HEAD_TOP_ABOVE_HEAD_JOINT * p.head_size
        scale = p.height_m / nominal_top
        off *= scale
        off.setflags(write=False)
        return cls(params=params, offsets=off, scale=float(scale))

    # ----------------------------------------------------------------- queries
    def rest_positions(self) -> np.ndarray:
        """``(17, 3)`` joint positions in the rest pose (body frame)."""
        pos = np.zeros((NUM_SKELETON_JOINTS, 3))
        for j, parent in enumerate(PARENTS):
            pos[j] = self.offsets[j] if parent < 0 else pos[parent] + self.offsets[j]
        return pos

    def bone_length(self, joint: str) -> float:
        """Length of the bone from ``joint``'s parent to ``joint``."""
        return float(np.linalg.norm(self.offsets[JOINT_ID[joint]]))

    def forward(self, rotations: np.ndarray, root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics.

        Args:
            rotations: ``(..., 17, 3, 3)`` local joint rotations relative to the rest pose; entry 0
                is the pelvis' orientation in the body frame (heading included).
            root: ``(..., 3)`` pelvis position in the body frame.

        Returns:
            ``(global_rotations (..., 17, 3, 3), positions (..., 17, 3))``.
        """
        rotations = np.asarray(rotations, dtype=np.float64)
        root = np.asarray(root, dtype=np.float64)
        G = np.empty_like(rotations)
        P = np.empty(rotations.shape[:-2] + (3,))
        for j, parent in enumerate(PARENTS):
            if parent < 0:
                G[..., j, :, :] = rotations[..., j, :, :]
                P[..., j, :] = root
            else:
                G[..., j, :, :] = G[..., parent, :, :] @ rotations[..., j, :, :]
                P[..., j, :] = P[..., parent, :] + np.einsum("...ab,b->...a", G[..., parent, :, :], self.offsets[j])
        return G, P
