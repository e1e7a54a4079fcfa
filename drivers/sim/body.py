"""Procedural body: ellipsoids and rounded cones attached to the skeleton, plus BODY_25 landmarks.

Every primitive is rigidly attached to one skeleton joint's frame, so posing
the body is one rigid transform per primitive (no skinning). Limbs are
rounded cones (the convex hull of two spheres), which gives tapered, smooth
limbs with exact analytic ray intersection; torso, head, hands and feet are
ellipsoids. Face and foot joints of BODY_25 (nose, eyes, ears, toes, heels)
are points on the head / nose / foot surfaces, so they move with those parts.

Not modelled: skin or cloth deformation (joints bend by interpenetration of
rigid parts), fingers, hair strands, garments' thickness or folds.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivers.sim.skeleton import HEAD_TOP_ABOVE_HEAD_JOINT, JOINT_ID, Skeleton
from ghnerf_runtime.body25 import JOINT_NAMES, NUM_JOINTS

# Part ids 1..N as written into CameraTruth.part_labels (0 is background).
PART_NAMES: tuple[str, ...] = (
    "torso", "head", "neck",
    "r_upper_arm", "r_lower_arm", "r_hand", "l_upper_arm", "l_lower_arm", "l_hand",
    "r_thigh", "r_shin", "r_foot", "l_thigh", "l_shin", "l_foot",
)
PART_ID: dict[str, int] = {name: i + 1 for i, name in enumerate(PART_NAMES)}

# Clothing zones: the appearance decides what each zone wears (see appearance.py).
ZONES: tuple[str, ...] = (
    "torso_top", "torso_bottom", "neck", "head", "nose", "hair",
    "upper_arm", "lower_arm", "hand", "thigh", "shin", "foot",
)


@dataclass(frozen=True)
class Ellipsoid:
    """An ellipsoid in the frame of ``joint``: ``center`` (3,), ``radii`` (3,) along the frame axes."""

    joint: int
    center: tuple[float, float, float]
    radii: tuple[float, float, float]
    part: int
    zone: str


@dataclass(frozen=True)
class RoundCone:
    """Convex hull of two spheres (``a``, ``ra``) and (``b``, ``rb``) in the frame of ``joint``."""

    joint: int
    a: tuple[float, float, float]
    b: tuple[float, float, float]
    ra: float
    rb: float
    part: int
    zone: str


@dataclass(frozen=True, eq=False)
class PosedBody:
    """The body's primitives posed in some frame (body or rig), ready to render.

    Primitive ids: ellipsoids first (``0..E-1``), then rounded cones (``E..E+C-1``).

    Attributes:
        ell_center: ``(E, 3)``; ell_axes: ``(E, 3, 3)`` columns are the local axes;
            ell_radii: ``(E, 3)``.
        cone_a, cone_b: ``(C, 3)`` sphere centres; cone_ra, cone_rb: ``(C,)`` radii.
        to_rest_R, to_rest_t: ``(E+C, 3, 3)``, ``(E+C, 3)``: maps a point on primitive k back to
            the rest pose (``R @ x + t``), used as a texture coordinate that sticks to the body.
        joints: ``(25, 3)`` BODY_25 joints.
        joint_normals: ``(25, 3)`` outward surface normal of joints that lie on the surface (face
            and foot joints), zero for joints inside the body.
    """

    ell_center: np.ndarray
    ell_axes: np.ndarray
    ell_radii: np.ndarray
    cone_a: np.ndarray
    cone_b: np.ndarray
    cone_ra: np.ndarray
    cone_rb: np.ndarray
    to_rest_R: np.ndarray
    to_rest_t: np.ndarray
    joints: np.ndarray
    joint_normals: np.ndarray

    def transformed(self, R: np.ndarray, t: np.ndarray) -> "PosedBody":
        """The same body after the rigid map ``x -> R @ x + t``."""
        return PosedBody(
            ell_center=self.ell_center @ R.T + t,
            ell_axes=R @ self.ell_axes,
            ell_radii=self.ell_radii,
            cone_a=self.cone_a @ R.T + t,
            cone_b=self.cone_b @ R.T + t,
            cone_ra=self.cone_ra,
            cone_rb=self.cone_rb,
            to_rest_R=self.to_rest_R @ R.T,
            to_rest_t=self.to_rest_t - np.einsum("kab,b->ka", self.to_rest_R @ R.T, t),
            joints=self.joints @ R.T + t,
            joint_normals=self.joint_normals @ R.T,
        )

    def bounding_spheres(self) -> tuple[np.ndarray, np.ndarray]:
        """``(E+C, 3)`` centres and ``(E+C,)`` radii of spheres that contain each primitive."""
        c = np.concatenate([self.ell_center, 0.5 * (self.cone_a + self.cone_b)])
        half = 0.5 * np.linalg.norm(self.cone_b - self.cone_a, axis=-1)
        r = np.concatenate([self.ell_radii.max(axis=-1), half + np.maximum(self.cone_ra, self.cone_rb)])
        return c, r

    def bounding_box(self) -> tuple[np.ndarray, np.ndarray]:
        """Exact axis-aligned box ``(min (3,), max (3,))`` of all primitives."""
        # Ellipsoid extent along world axis i: norm of row i of (axes * radii).
        ext = np.linalg.norm(self.ell_axes * self.ell_radii[:, None, :], axis=-1)
        lo = [self.ell_center - ext, self.cone_a - self.cone_ra[:, None], self.cone_b - self.cone_rb[:, None]]
        hi = [self.ell_center + ext, self.cone_a + self.cone_ra[:, None], self.cone_b + self.cone_rb[:, None]]
        return np.min(np.concatenate(lo), axis=0), np.max(np.concatenate(hi), axis=0)


def ellipsoid_surface_point(center: np.ndarray, radii: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Point where the ray from an axis-aligned ellipsoid's centre along ``direction`` leaves it."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    s = 1.0 / np.linalg.norm(d / np.asarray(radii, dtype=np.float64))
    return np.asarray(center, dtype=np.float64) + s * d


class BodyModel:
    """The body of one simulated person: primitives, landmarks and per-joint radii.

    Args:
        skeleton: the person's skeleton (proportions).
        long_hair: add a hair volume behind the head and neck.
    """

    def __init__(self, skeleton: Skeleton, *, long_hair: bool = False) -> None:
        self.skeleton = skeleton
        self.rest_positions = skeleton.rest_positions()
        self.ellipsoids, self.cones = _build_primitives(skeleton, long_hair)
        self.landmark_joint, self.landmark_offset, self.landmark_normal = _build_landmarks(skeleton, self.ellipsoids)
        self.joint_radius = _joint_radii(skeleton)
        self._ell_joint = np.array([e.joint for e in self.ellipsoids])
        self._ell_center = np.array([e.center for e in self.ellipsoids], dtype=np.float64)
        self._ell_radii = np.array([e.radii for e in self.ellipsoids], dtype=np.float64)
        self._cone_joint = np.array([c.joint for c in self.cones])
        self._cone_a = np.array([c.a for c in self.cones], dtype=np.float64)
        self._cone_b = np.array([c.b for c in self.cones], dtype=np.float64)
        self._cone_ra = np.array([c.ra for c in self.cones], dtype=np.float64)
        self._cone_rb = np.array([c.rb for c in self.cones], dtype=np.float64)
        self.prim_joint = np.concatenate([self._ell_joint, self._cone_joint])
        self.prim_part = np.array([p.part for p in self.primitives], dtype=np.uint8)
        self.prim_zone = tuple(p.zone for p in self.primitives)
        # Foot ellipsoids, for putting the soles on the floor.
        self.foot_ellipsoids = np.array([i for i, e in enumerate(self.ellipsoids) if e.zone == "foot"])

    @property
    def primitives(self) -> tuple[Ellipsoid | RoundCone, ...]:
        return tuple(self.ellipsoids) + tuple(self.cones)

    @property
    def num_primitives(self) -> int:
        return len(self.ellipsoids) + len(self.cones)

    def joints(self, G: np.ndarray, P: np.ndarray) -> np.ndarray:
        """BODY_25 joints ``(..., 25, 3)`` from skeleton globals ``G (..., 17, 3, 3)``, ``P (..., 17, 3)``."""
        Gj = G[..., self.landmark_joint, :, :]
        return P[..., self.landmark_joint, :] + np.einsum("...kab,kb->...ka", Gj, self.landmark_offset)

    def sole_height(self, G: np.ndarray, P: np.ndarray) -> float:
        """Lowest point of both feet (body frame, y up) for a posed skeleton."""
        j = self._ell_joint[self.foot_ellipsoids]
        Gf = G[j]
        centers = P[j] + np.einsum("kab,kb->ka", Gf, self._ell_center[self.foot_ellipsoids])
        # y-extent of an ellipsoid with axes Gf and radii r: norm of row y of (Gf * r).
        ext = np.linalg.norm(Gf[:, 1, :] * self._ell_radii[self.foot_ellipsoids], axis=-1)
        return float(np.min(centers[:, 1] - ext))

    def settle(self, G: np.ndarray, P: np.ndarray, *, ground: bool, plant: bool) -> np.ndarray:
        """Shift the posed skeleton: soles onto the floor (``ground``), ankles' centre fixed (``plant``).

        Returns the shifted positions ``(17, 3)``; rotations are unchanged.
        """
        shift = np.zeros(3)
        if plant:
            ankles = [JOINT_ID["r_ankle"], JOINT_ID["l_ankle"]]
            shift[[0, 2]] = self.rest_positions[ankles].mean(axis=0)[[0, 2]] - P[ankles].mean(axis=0)[[0, 2]]
        if ground:
            shift[1] = -self.sole_height(G, P)
        return P + shift

    def pose(self, G: np.ndarray, P: np.ndarray) -> PosedBody:
        """Place every primitive for skeleton globals ``G (17, 3, 3)``, ``P (17, 3)`` (body frame)."""
        Ge, Gc = G[self._ell_joint], G[self._cone_joint]
        Gall = G[self.prim_joint]
        to_rest_R = np.swapaxes(Gall, -1, -2)
        to_rest_t = self.rest_positions[self.prim_joint] - np.einsum("kab,kb->ka", to_rest_R, P[self.prim_joint])
        return PosedBody(
            ell_center=P[self._ell_joint] + np.einsum("kab,kb->ka", Ge, self._ell_center),
            ell_axes=Ge,
            ell_radii=self._ell_radii,
            cone_a=P[self._cone_joint] + np.einsum("kab,kb->ka", Gc, self._cone_a),
            cone_b=P[self._cone_joint] + np.einsum("kab,kb->ka", Gc, self._cone_b),
            cone_ra=self._cone_ra,
            cone_rb=self._cone_rb,
            to_rest_R=to_rest_R,
            to_rest_t=to_rest_t,
            joints=self.joints(G, P),
            joint_normals=np.einsum("kab,kb->ka", G[self.landmark_joint], self.landmark_normal),
        )


def _build_primitives(sk: Skeleton, long_hair: bool) -> tuple[list[Ellipsoid], list[RoundCone]]:
    p, u = sk.params, sk.scale
    g = p.girth
    J = JOINT_ID
    off = sk.offsets
    hs = p.head_size

    def v(*xyz: float) -> tuple[float, float, float]:
        return tuple(float(c) * u for c in xyz)  # nominal-stature units -> metres

    E: list[Ellipsoid] = []
    C: list[RoundCone] = []
    torso = PART_ID["torso"]
    E.append(Ellipsoid(J["pelvis"], v(0, 0.03, -0.008), v(0.094 * p.hip_width * g, 0.07, 0.066 * g), torso, "torso_bottom"))
    E.append(Ellipsoid(J["spine"], v(0, 0.05, 0.002), v(0.088 * g, 0.11, 0.062 * g), torso, "torso_top"))
    E.append(Ellipsoid(J["chest"], v(0, 0.04, 0.0), v(0.097 * p.shoulder_width * np.sqrt(g), 0.098, 0.066 * g), torso, "torso_top"))
    head_c = np.array(v(0, 0.06 * hs, 0.012))
    head_r = np.array(v(0.047 * hs, 0.5 * HEAD_TOP_ABOVE_HEAD_JOINT * hs + 0.0025, 0.057 * hs))
    head_c[1] = HEAD_TOP_ABOVE_HEAD_JOINT * hs * u - head_r[1]  # crown exactly at the stature
    E.append(Ellipsoid(J["head"], tuple(head_c), tuple(head_r), PART_ID["head"], "head"))
    nose_tip_dir = np.array([0.0, -0.3, 1.0])
    nose_base = ellipsoid_surface_point(head_c, head_r, nose_tip_dir)
    nose_r = np.array(v(0.0085 * hs, 0.014 * hs, 0.011 * hs))
    nose_c = nose_base - np.array([0.0, 0.0, 0.35 * nose_r[2]])
    E.append(Ellipsoid(J["head"], tuple(nose_c), tuple(nose_r), PART_ID["head"], "nose"))
    if long_hair:
        E.append(Ellipsoid(J["head"], tuple(head_c + np.array(v(0, -0.05, -0.03))), v(0.05 * hs, 0.085 * hs, 0.042 * hs), PART_ID["head"], "hair"))
    for side, s in (("r", -1.0), ("l", 1.0)):
        E.append(Ellipsoid(J[f"{side}_wrist"], v(0, -0.048 * p.arm_length, 0.004), v(0.017, 0.05 * p.arm_length, 0.028), PART_ID[f"{side}_hand"], "hand"))
        E.append(Ellipsoid(J[f"{side}_ankle"], v(s * 0.004, -0.019, 0.043), v(0.031, 0.02, 0.077), PART_ID[f"{side}_foot"], "foot"))

    # Rounded cones: shoulders' line, neck, arms, legs.
    rs, ls = off[J["r_shoulder"]], off[J["l_shoulder"]]
    C.append(RoundCone(J["chest"], tuple(rs * 0.86), tuple(ls * 0.86), 0.036 * u * np.sqrt(g), 0.036 * u * np.sqrt(g), torso, "torso_top"))
    C.append(RoundCone(J["neck"], v(0, -0.01, -0.004), tuple(off[J["head"]] + np.array(v(0, 0.02, -0.004))), 0.034 * u * np.sqrt(g), 0.03 * u * np.sqrt(g), PART_ID["neck"], "neck"))
    for side in ("r", "l"):
        C.append(RoundCone(J[f"{side}_shoulder"], (0.0, 0.0, 0.0), tuple(off[J[f"{side}_elbow"]]), 0.034 * u * g, 0.024 * u * g, PART_ID[f"{side}_upper_arm"], "upper_arm"))
        C.append(RoundCone(J[f"{side}_elbow"], (0.0, 0.0, 0.0), tuple(off[J[f"{side}_wrist"]]), 0.025 * u * g, 0.016 * u * np.sqrt(g), PART_ID[f"{side}_lower_arm"], "lower_arm"))
        C.append(RoundCone(J[f"{side}_hip"], v(0, 0.005, -0.004), tuple(off[J[f"{side}_knee"]]), 0.06 * u * g, 0.034 * u * g, PART_ID[f"{side}_thigh"], "thigh"))
        C.append(RoundCone(J[f"{side}_knee"], (0.0, 0.0, 0.0), tuple(off[J[f"{side}_ankle"]]), 0.037 * u * g, 0.021 * u * np.sqrt(g), PART_ID[f"{side}_shin"], "shin"))
    for c in C:
        # The hull of two spheres needs |ra - rb| < |b - a|; every limb above satisfies it widely.
        assert abs(c.ra - c.rb) < np.linalg.norm(np.subtract(c.b, c.a)) or c.ra == c.rb
    return E, C


def _build_landmarks(sk: Skeleton, ellipsoids: list[Ellipsoid]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """BODY_25 joint -> (skeleton joint, offset and surface normal in that joint's frame)."""
    J = JOINT_ID
    head = next(e for e in ellipsoids if e.zone == "head")
    nose = next(e for e in ellipsoids if e.zone == "nose")
    feet = {("r" if e.joint == J["r_ankle"] else "l"): e for e in ellipsoids if e.zone == "foot"}
    joint = np.zeros(NUM_JOINTS, dtype=np.int64)
    offset = np.zeros((NUM_JOINTS, 3))
    normal = np.zeros((NUM_JOINTS, 3))

    def put(name: str, j: int, o=(0.0, 0.0, 0.0), on: Ellipsoid | None = None) -> None:
        k = JOINT_NAMES.index(name)
        joint[k] = j
        offset[k] = o
        if on is not None:  # gradient of the (axis-aligned) ellipsoid's implicit function
            g = (np.asarray(o) - np.asarray(on.center)) / np.asarray(on.radii) ** 2
            normal[k] = g / np.linalg.norm(g)

    put("Neck", J["neck"])
    put("MidHip", J["pelvis"])
    for side, S in (("r", "R"), ("l", "L")):
        for ours, theirs in (("shoulder", "Shoulder"), ("elbow", "Elbow"), ("wrist", "Wrist"), ("hip", "Hip"), ("knee", "Knee"), ("ankle", "Ankle")):
            put(f"{S}{theirs}", J[f"{side}_{ours}"])
    # Nose tip: the front-most point of the nose ellipsoid.
    put("Nose", J["head"], np.add(nose.center, (0.0, 0.0, nose.radii[2])), nose)
    for S, s in (("R", -1.0), ("L", 1.0)):
        put(f"{S}Eye", J["head"], ellipsoid_surface_point(head.center, head.radii, (s * 0.36, 0.06, 1.0)), head)
        put(f"{S}Ear", J["head"], ellipsoid_surface_point(head.center, head.radii, (s * 1.0, -0.06, -0.08)), head)
        foot = feet[S.lower()]
        # Medial is towards the body's midline: -x for the left foot, +x for the right.
        put(f"{S}BigToe", J[f"{S.lower()}_ankle"], ellipsoid_surface_point(foot.center, foot.radii, (-s * 0.25, 0.05, 1.0)), foot)
        put(f"{S}SmallToe", J[f"{S.lower()}_ankle"], ellipsoid_surface_point(foot.center, foot.radii, (s * 0.6, 0.05, 0.75)), foot)
        put(f"{S}Heel", J[f"{S.lower()}_ankle"], ellipsoid_surface_point(foot.center, foot.radii, (0.0, -0.15, -1.0)), foot)
    return joint, offset, normal


def _joint_radii(sk: Skeleton) -> np.ndarray:
    """How deep each BODY_25 joint sits below the body surface (metres), for visibility tests."""
    u, g = sk.scale, sk.params.girth
    depth = {
        "Neck": 0.07 * g, "MidHip": 0.07 * g,
        "RShoulder": 0.04 * g, "LShoulder": 0.04 * g, "RElbow": 0.024 * g, "LElbow": 0.024 * g,
        "RWrist": 0.017 * g, "LWrist": 0.017 * g, "RHip": 0.06 * g, "LHip": 0.06 * g,
        "RKnee": 0.034 * g, "LKnee": 0.034 * g, "RAnkle": 0.022 * g, "LAnkle": 0.022 * g,
    }
    return np.array([depth.get(name, 0.0) * u for name in JOINT_NAMES])
