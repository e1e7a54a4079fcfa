"""A body-shaped proxy of the subject's surface from its 3D joints, ray-cast into any camera.

GHNeRF's cost volume only matches what both cameras see; on a view from behind the subject the
first surface along a ray is one neither camera saw, and its depth there is off by about 6 cm
(median). The 3D joints are known far better (the skeleton prior: about 24 mm median), and a body is
roughly a set of rounded limbs around them: rounded cones along the limbs and hands and feet,
ellipsoids for the torso and head, sized by a template of an average adult times one girth scale.
Ray casting is exact (``ghnerf_runtime.geometry.raycast``). Measured in docs/training.md, "A body
proxy from the joints": 21 mm median depth error on novel views from the model's joints, against
56 mm for the model's own depth.

numpy only.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ghnerf_runtime.body25 import JOINT_INDEX as J
from ghnerf_runtime.body25 import NUM_JOINTS
from ghnerf_runtime.errors import GeometryError, ShapeError
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.raycast import RayGrid, rasterize

__all__ = ["ProxyTemplate", "BodyProxy", "proxy_body", "proxy_depth"]


@dataclass(frozen=True, eq=False)
class BodyProxy:
    """The proxy's primitives (``ghnerf_runtime.geometry.raycast.Primitives``) in some frame."""

    ell_center: np.ndarray
    ell_axes: np.ndarray
    ell_radii: np.ndarray
    cone_a: np.ndarray
    cone_b: np.ndarray
    cone_ra: np.ndarray
    cone_rb: np.ndarray

    def transformed(self, R: np.ndarray, t: np.ndarray) -> "BodyProxy":
        """The same primitives after the rigid map ``x -> R @ x + t``."""
        return BodyProxy(self.ell_center @ R.T + t, R @ self.ell_axes, self.ell_radii,
                         self.cone_a @ R.T + t, self.cone_b @ R.T + t, self.cone_ra, self.cone_rb)

    @property
    def empty(self) -> bool:
        return len(self.ell_center) + len(self.cone_a) == 0


@dataclass(frozen=True)
class ProxyTemplate:
    """Radii (metres, an average adult) and torso proportions of the proxy; ``scale`` in
    :func:`proxy_body` multiplies the girths (limb radii, torso and hand and foot thickness).

    Tuned on the simulator's training split, true joints and depth (``python -m training.body_proxy
    tune``): the simulated bodies are built of the same kinds of primitives, so this fits them better
    than it would fit clothed people."""

    upper_arm: tuple[float, float] = (0.062, 0.044)
    lower_arm: tuple[float, float] = (0.044, 0.031)
    thigh: tuple[float, float] = (0.112, 0.068)
    shin: tuple[float, float] = (0.066, 0.041)
    neck: float = 0.055
    hand_length: float = 0.140
    hand_radius: float = 0.036
    foot_radius: float = 0.041
    chest_width: float = 0.94   # chest half-width over half the shoulder distance
    chest_depth: float = 0.109  # chest half-depth
    hip_width: float = 1.79     # pelvis half-width over half the hip distance
    hip_depth: float = 0.109
    torso_height: float = 0.44  # each torso ellipsoid's half-height over the neck-to-mid-hip length
    head_width: float = 1.05    # head half-width over half the ear distance
    head_height: float = 1.43   # head half-height over its half-width
    head_depth: float = 1.20    # head half-depth over its half-width


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v)
    return v / n if n > 1e-9 else v


def _frame(up: np.ndarray, side: np.ndarray) -> np.ndarray:
    """Columns (side, up, forward): orthonormal, ``up`` exact, ``side`` made orthogonal to it."""
    y = _unit(up)
    x = _unit(side - (side @ y) * y)
    return np.stack([x, y, np.cross(x, y)], axis=1)


def proxy_body(joints: np.ndarray, valid: np.ndarray, template: ProxyTemplate = ProxyTemplate(),
               scale: float = 1.0) -> BodyProxy:
    """The proxy's primitives for BODY_25 ``joints (25, 3)`` (primitives on invalid joints are left out).

    Raises:
        ShapeError: ``joints`` is not ``(25, 3)`` with ``(25,)`` ``valid`` flags.
        GeometryError: ``scale`` is not a positive finite number (NaN gave NaN primitives whose windows
            were the whole view; 0 or less, radii of 0 or inside out).
    """
    j = np.asarray(joints, np.float64)
    if j.shape != (NUM_JOINTS, 3) or np.shape(valid) != (NUM_JOINTS,):
        raise ShapeError(f"proxy_body: joints must be ({NUM_JOINTS}, 3) with ({NUM_JOINTS},) valid flags, got "
                         f"{j.shape} and {np.shape(valid)}")
    if not (np.isfinite(scale) and scale > 0):
        raise GeometryError(f"proxy_body: scale (the girth factor) must be a positive finite number, got {scale!r}")
    ok = np.asarray(valid, bool) & np.isfinite(j).all(axis=-1)
    j = np.where(ok[:, None], j, 0.0)
    t, s = template, float(scale)
    cones: list[tuple[np.ndarray, np.ndarray, float, float]] = []
    ells: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def cone(a: int, b: int, ra: float, rb: float) -> None:
        if ok[a] and ok[b] and np.linalg.norm(j[b] - j[a]) > abs(ra - rb) + 1e-4:
            cones.append((j[a], j[b], ra, rb))

    for side in "RL":
        sh, el, wr = J[f"{side}Shoulder"], J[f"{side}Elbow"], J[f"{side}Wrist"]
        hip, kn, an = J[f"{side}Hip"], J[f"{side}Knee"], J[f"{side}Ankle"]
        cone(sh, el, s * t.upper_arm[0], s * t.upper_arm[1])
        cone(el, wr, s * t.lower_arm[0], s * t.lower_arm[1])
        cone(hip, kn, s * t.thigh[0], s * t.thigh[1])
        cone(kn, an, s * t.shin[0], s * t.shin[1])
        if ok[el] and ok[wr]:  # the hand continues the forearm
            tip = j[wr] + t.hand_length * _unit(j[wr] - j[el])
            cones.append((j[wr], tip, s * t.hand_radius, 0.8 * s * t.hand_radius))
        heel, toes = J[f"{side}Heel"], [J[f"{side}BigToe"], J[f"{side}SmallToe"]]
        if ok[heel] and ok[toes].all():
            front = j[toes].mean(0)
            cones.append((j[heel], front, s * t.foot_radius, 0.8 * s * t.foot_radius))
            if ok[an]:
                cones.append((j[an], 0.5 * (j[heel] + front), 0.8 * s * t.foot_radius, s * t.foot_radius))
    neck, mid = J["Neck"], J["MidHip"]
    rs, ls, rh, lh = J["RShoulder"], J["LShoulder"], J["RHip"], J["LHip"]
    if ok[[neck, mid, rs, ls, rh, lh]].all():
        up = j[neck] - j[mid]
        length = np.linalg.norm(up)
        side = (j[ls] - j[rs]) + (j[lh] - j[rh])
        R = _frame(up, side)
        half_h = t.torso_height * length
        shoulders, hips = 0.5 * np.linalg.norm(j[ls] - j[rs]), 0.5 * np.linalg.norm(j[lh] - j[rh])
        chest_c = j[neck] - (0.5 * length - 0.5 * half_h) * R[:, 1]
        ells.append((chest_c, R, np.array([t.chest_width * shoulders, half_h, s * t.chest_depth])))
        pelvis_c = j[mid] + 0.5 * half_h * R[:, 1]
        ells.append((pelvis_c, R, np.array([t.hip_width * hips, half_h, s * t.hip_depth])))
        cone(rs, ls, s * t.neck, s * t.neck)  # the shoulders' bar, as thick as the neck
    ears, nose = [J["REar"], J["LEar"]], J["Nose"]
    if ok[ears].all() and ok[neck]:
        centre = j[ears].mean(0)
        half_w = t.head_width * 0.5 * np.linalg.norm(j[ears[1]] - j[ears[0]])
        R = _frame(centre - j[neck], j[ears[1]] - j[ears[0]])
        if ok[nose] and (j[nose] - centre) @ R[:, 2] < 0:
            R = R * np.array([-1.0, 1.0, -1.0])  # keep it right-handed, forward towards the nose
        ells.append((centre, R, half_w * np.array([1.0, t.head_height, t.head_depth])))
        cones.append((j[neck], centre, s * t.neck, s * t.neck))
    return _posed(ells, cones)


def _posed(ells, cones) -> "BodyProxy":
    E, C = len(ells), len(cones)
    return BodyProxy(
        ell_center=np.array([e[0] for e in ells], np.float64).reshape(E, 3),
        ell_axes=np.array([e[1] for e in ells], np.float64).reshape(E, 3, 3),
        ell_radii=np.array([e[2] for e in ells], np.float64).reshape(E, 3),
        cone_a=np.array([c[0] for c in cones], np.float64).reshape(C, 3),
        cone_b=np.array([c[1] for c in cones], np.float64).reshape(C, 3),
        cone_ra=np.array([c[2] for c in cones], np.float64),
        cone_rb=np.array([c[3] for c in cones], np.float64),
    )


def proxy_depth(body: BodyProxy, camera: Camera) -> np.ndarray:
    """``(H, W)`` camera-z depth of the proxy in ``camera`` (rig frame); 0 where nothing is hit."""
    if body.empty:
        return np.zeros((camera.height, camera.width))
    depth = rasterize(body.transformed(camera.R, camera.t), RayGrid.for_camera(camera)).depth
    return np.where(np.isfinite(depth), depth, 0.0)
