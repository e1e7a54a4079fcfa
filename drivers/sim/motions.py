"""Procedural, periodic motions that drive the skeleton.

A motion maps time to a :class:`Pose` (local joint rotations relative to the
rest pose, plus the pelvis position in the body frame). Every motion here is
built from sines of ``2*pi*t/period`` (and integer multiples), so
``pose(t) == pose(t + period_s)`` exactly up to rounding. Vertical contact
is not baked in: motions flagged ``grounded`` get their soles put on the
floor by the scene, and ``planted`` ones keep the feet's centre fixed, which
turns leg angles into plausible pelvis motion without inverse kinematics.

Angles follow the body frame (x left, y up, z forward): a positive rotation
about x tips an upward segment forwards and a downward segment backwards.

Not modelled: balance or dynamics, foot sliding correction during walking
(the stance foot may slide a few centimetres), finger or facial motion,
interaction with objects.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Callable, Protocol

import numpy as np

from drivers.sim.errors import SimConfigError
from drivers.sim.rotations import rot_x, rot_y, rot_z
from drivers.sim.skeleton import JOINT_ID, NUM_SKELETON_JOINTS, Skeleton

TAU = 2.0 * np.pi


@dataclass(frozen=True, eq=False)
class Pose:
    """A skeleton pose.

    Attributes:
        rotations: ``(17, 3, 3)`` local rotations (entry 0: pelvis orientation, heading included).
        root: ``(3,)`` pelvis position in the body frame (metres).
    """

    rotations: np.ndarray
    root: np.ndarray


class Motion(Protocol):
    """What the scene needs from a motion source (procedural or BVH)."""

    name: str
    period_s: float
    grounded: bool  # the scene puts the lowest sole point on the floor
    planted: bool  # the scene keeps the ankles' mean (x, z) where the rest pose has it

    def pose(self, t: float) -> Pose: ...


def _deg(x: float | np.ndarray) -> float | np.ndarray:
    return np.radians(x)


class _Builder:
    """Accumulates local rotations by joint name (readability helper for the motions)."""

    def __init__(self) -> None:
        self.R = np.broadcast_to(np.eye(3), (NUM_SKELETON_JOINTS, 3, 3)).copy()

    def set(self, joint: str, *rotations: np.ndarray) -> None:
        out = np.eye(3)
        for r in rotations:
            out = out @ r
        self.R[JOINT_ID[joint]] = out


def _arm(b: _Builder, side: str, abduct: float, flex: float, elbow: float, elbow_lift: float = 0.0) -> None:
    """Shoulder abduction (sideways raise) and flexion (forward raise), elbow bend, degrees.

    ``elbow`` bends the forearm forwards; ``elbow_lift`` bends it further in the arm's
    abduction plane (used by waving).
    """
    s = 1.0 if side == "l" else -1.0
    b.set(f"{side}_shoulder", rot_z(_deg(s * abduct)), rot_x(_deg(-flex)))
    b.set(f"{side}_elbow", rot_z(_deg(s * elbow_lift)), rot_x(_deg(-elbow)))


def _leg(b: _Builder, side: str, flex: float, knee: float, ankle: float = 0.0, abduct: float = 0.0) -> None:
    """Hip flexion (thigh forwards) and abduction, knee bend, ankle pitch (toes up > 0), degrees."""
    s = 1.0 if side == "l" else -1.0
    b.set(f"{side}_hip", rot_z(_deg(s * abduct)), rot_x(_deg(-flex)))
    b.set(f"{side}_knee", rot_x(_deg(knee)))
    b.set(f"{side}_ankle", rot_z(_deg(-s * abduct)), rot_x(_deg(-ankle)))


@dataclass(frozen=True)
class MotionParams:
    """Tunable amplitude/period of a procedural motion.

    Attributes:
        period_s: loop length in seconds at speed 1 (walk: one stride; the lap is
            ``strides_per_lap`` strides).
        amplitude: scales the motion's angles (1.0 = nominal).
        strides_per_lap: walk only: strides per circle lap; 0 walks on the spot.
        seed: freestyle only: picks its random joint trajectories (same seed, same motion).
    """

    period_s: float = 0.0  # 0 = the motion's default
    amplitude: float = 1.0
    strides_per_lap: int = 3
    seed: int = 0

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        if not (isinstance(self.period_s, (int, float)) and (self.period_s == 0 or 0.2 <= self.period_s <= 60)):
            raise SimConfigError("MotionParams.period_s", f"must be 0 (default) or in [0.2, 60] s, got {self.period_s!r}")
        if not (isinstance(self.amplitude, (int, float)) and 0.0 <= self.amplitude <= 1.5):
            raise SimConfigError("MotionParams.amplitude", f"must be in [0, 1.5], got {self.amplitude!r}")
        if not (isinstance(self.strides_per_lap, int) and 0 <= self.strides_per_lap <= 20):
            raise SimConfigError("MotionParams.strides_per_lap", f"must be an int in [0, 20], got {self.strides_per_lap!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or not 0 <= self.seed < 2**63:
            raise SimConfigError("MotionParams.seed", f"must be an int in [0, 2**63), got {self.seed!r}")


@dataclass(frozen=True, eq=False)
class ProceduralMotion:
    """A named procedural motion bound to one skeleton. Build with :func:`make_motion`."""

    name: str
    period_s: float
    grounded: bool
    planted: bool
    skeleton: Skeleton
    params: MotionParams
    _fn: Callable[["ProceduralMotion", float], Pose] = field(repr=False)

    def pose(self, t: float) -> Pose:
        return self._fn(self, float(t))

    @property
    def rest_root(self) -> np.ndarray:
        return self.skeleton.offsets[0].copy()


# ---------------------------------------------------------------- the motions
def _relaxed_arms(b: _Builder, amp: float, swing: float = 0.0) -> None:
    for side in ("r", "l"):
        _arm(b, side, abduct=7.0, flex=swing * (1 if side == "r" else -1), elbow=10.0 * amp + 4)


def _stand(m: ProceduralMotion, t: float) -> Pose:
    a, ph = m.params.amplitude, TAU * t / m.period_s
    b = _Builder()
    b.set("chest", rot_x(_deg(1.5 * a * np.sin(ph))))
    b.set("pelvis", rot_z(_deg(1.0 * a * np.sin(ph / 1.0))))
    b.set("head", rot_y(_deg(6 * a * np.sin(ph))), rot_x(_deg(3 * a * np.cos(ph))))
    _relaxed_arms(b, a, 2 * a * np.sin(ph))
    return Pose(b.R, m.rest_root)


def _walk(m: ProceduralMotion, t: float) -> Pose:
    a = m.params.amplitude
    n = m.params.strides_per_lap
    stride_t = m.period_s / max(n, 1)
    ph = TAU * t / stride_t  # gait phase: right heel strike at pi/2
    hip_amp = 24.0 * a
    b = _Builder()
    for side, off in (("r", 0.0), ("l", np.pi)):
        p = ph + off
        knee = 5.0 + 55.0 * a * max(0.0, np.cos(p + 0.4))
        _leg(b, side, flex=hip_amp * np.sin(p) + 4.0 * a, knee=knee, ankle=6.0 * a * np.sin(p + 0.5))
        arm_swing = -20.0 * a * np.sin(p)
        _arm(b, side, abduct=7.0, flex=arm_swing, elbow=15.0 + 12.0 * a * max(0.0, -np.sin(p)))
    heading = TAU * t / m.period_s if n > 0 else 0.0
    b.set("pelvis", rot_y(heading + _deg(5.0 * a * np.sin(ph))))
    b.set("spine", rot_x(_deg(3.0 * a)))
    b.set("chest", rot_y(_deg(-8.0 * a * np.sin(ph))))
    root = m.rest_root
    if n > 0:
        leg = m.skeleton.bone_length("r_knee") + m.skeleton.bone_length("r_ankle")
        stride = 2.0 * 2.0 * leg * np.sin(_deg(hip_amp)) * 0.9
        radius = n * stride / TAU
        root = root + radius * np.array([-np.cos(heading), 0.0, np.sin(heading)])
    return Pose(b.R, root)


def _wave(m: ProceduralMotion, t: float) -> Pose:
    a, ph = m.params.amplitude, TAU * t / m.period_s
    b = _Builder()
    _arm(b, "r", abduct=7 + 88.0 * a, flex=15.0 * a, elbow=5.0, elbow_lift=(55.0 + 28.0 * np.sin(ph)) * a)
    _arm(b, "l", abduct=7.0, flex=0.0, elbow=12.0)
    b.set("chest", rot_z(_deg(2.5 * a * np.sin(ph))))
    b.set("head", rot_z(_deg(-4.0 * a * np.sin(ph))), rot_x(_deg(3.0 * a)))
    return Pose(b.R, m.rest_root)


def _squat(m: ProceduralMotion, t: float) -> Pose:
    a = m.params.amplitude
    s = a * 0.5 * (1.0 - np.cos(TAU * t / m.period_s))
    lean, hip, knee = 35.0 * s, 115.0 * s, 110.0 * s
    b = _Builder()
    b.set("pelvis", rot_x(_deg(lean)))
    b.set("spine", rot_x(_deg(-5.0 * s)))
    b.set("head", rot_x(_deg(-20.0 * s)))
    for side in ("r", "l"):
        # Keep the soles flat: pelvis tilt - hip flexion + knee bend - ankle pitch = 0.
        _leg(b, side, flex=hip, knee=knee, ankle=lean - hip + knee)
        _arm(b, side, abduct=7.0, flex=90.0 * s, elbow=10.0)
    return Pose(b.R, m.rest_root)


def _arm_circles(m: ProceduralMotion, t: float) -> Pose:
    a, ph = m.params.amplitude, TAU * t / m.period_s
    b = _Builder()
    for side, sgn in (("r", 1.0), ("l", 1.0)):
        _arm(b, side, abduct=7 + 83.0 * a + 18.0 * a * np.cos(ph), flex=18.0 * a * np.sin(ph) * sgn, elbow=3.0)
    return Pose(b.R, m.rest_root)


def _reach(m: ProceduralMotion, t: float) -> Pose:
    a, ph = m.params.amplitude, TAU * t / m.period_s
    sr, sl = a * max(0.0, np.sin(ph)) ** 2, a * max(0.0, -np.sin(ph)) ** 2
    b = _Builder()
    _arm(b, "r", abduct=7 + 8 * sr, flex=135.0 * sr, elbow=12.0 + 30.0 * sl)
    _arm(b, "l", abduct=7 + 8 * sl, flex=135.0 * sl, elbow=12.0 + 30.0 * sr)
    b.set("spine", rot_x(_deg(12.0 * (sr + sl))))
    b.set("chest", rot_y(_deg(14.0 * (sl - sr))), rot_z(_deg(5.0 * (sl - sr))))
    b.set("head", rot_x(_deg(-15.0 * (sr + sl))))
    for side in ("r", "l"):
        _leg(b, side, flex=0.0, knee=2.0 * a, ankle=-18.0 * (sr + sl))
    return Pose(b.R, m.rest_root)


def _turn(m: ProceduralMotion, t: float) -> Pose:
    a, ph = m.params.amplitude, TAU * t / m.period_s
    b = _Builder()
    steps = 3.0 * ph  # each leg lifts 3 times per turn
    for side, off in (("r", 0.0), ("l", np.pi)):
        lift = max(0.0, np.sin(steps + off)) * a
        _leg(b, side, flex=22.0 * lift, knee=40.0 * lift, ankle=-5.0 * lift)
        _arm(b, side, abduct=9.0, flex=8.0 * a * np.sin(steps + off + np.pi), elbow=18.0)
    b.set("pelvis", rot_y(ph))
    b.set("head", rot_y(_deg(10.0 * a)))
    return Pose(b.R, m.rest_root)


def _jumping_jacks(m: ProceduralMotion, t: float) -> Pose:
    a = m.params.amplitude
    s = a * 0.5 * (1.0 - np.cos(TAU * t / m.period_s))
    b = _Builder()
    for side in ("r", "l"):
        _arm(b, side, abduct=7.0 + 150.0 * s, flex=10.0 * s, elbow=8.0 + 10.0 * s)
        _leg(b, side, flex=2.0 * s, knee=4.0 * s, abduct=14.0 * s)
    b.set("head", rot_x(_deg(-4.0 * s)))
    return Pose(b.R, m.rest_root)


#: Freestyle's degrees of freedom and their ranges in degrees (after the sagittal/frontal
#: ranges of motion of a healthy adult, trimmed where the capsule body would self-intersect).
_FREESTYLE_RANGES: tuple[tuple[str, float, float], ...] = (
    ("r_arm_abduct", 0.0, 170.0), ("r_arm_flex", -40.0, 170.0), ("r_elbow", 0.0, 140.0),
    ("l_arm_abduct", 0.0, 170.0), ("l_arm_flex", -40.0, 170.0), ("l_elbow", 0.0, 140.0),
    ("r_hip_flex", -20.0, 80.0), ("r_knee", 0.0, 110.0), ("r_hip_abduct", 0.0, 35.0), ("r_ankle", -20.0, 20.0),
    ("l_hip_flex", -20.0, 80.0), ("l_knee", 0.0, 110.0), ("l_hip_abduct", 0.0, 35.0), ("l_ankle", -20.0, 20.0),
    ("spine_flex", -10.0, 35.0), ("chest_twist", -30.0, 30.0), ("chest_side", -15.0, 15.0),
    ("head_yaw", -40.0, 40.0), ("head_pitch", -25.0, 25.0),
)
_FREESTYLE_HARMONICS = 3


@lru_cache(maxsize=256)
def _freestyle_curves(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Per degree of freedom: Fourier amplitudes ``(D, H)`` and phases ``(D, H)``, scaled so
    each curve spans exactly [-1, 1] over one period (checked on a dense grid)."""
    rng = np.random.default_rng([int(seed), 0xF5EE])
    k = np.arange(1, _FREESTYLE_HARMONICS + 1)
    amp = rng.normal(size=(len(_FREESTYLE_RANGES), _FREESTYLE_HARMONICS)) / k
    phase = rng.uniform(0.0, TAU, amp.shape)
    grid = np.linspace(0.0, TAU, 256, endpoint=False)
    s = np.einsum("dh,dhg->dg", amp, np.sin(k[None, :, None] * grid[None, None, :] + phase[..., None]))
    lo, hi = s.min(axis=1, keepdims=True), s.max(axis=1, keepdims=True)
    # Affine map of each curve onto [-1, 1]: scale the harmonics, keep the offset separately.
    scale = 2.0 / np.maximum(hi - lo, 1e-9)
    offset = -1.0 - lo[:, 0] * scale[:, 0]
    return np.concatenate([amp * scale, offset[:, None]], axis=1), phase


def _freestyle(m: ProceduralMotion, t: float) -> Pose:
    """Random, smooth whole-body movement: every joint angle of ``_FREESTYLE_RANGES`` follows its
    own periodic curve (three harmonics of the period, random amplitudes and phases drawn from
    ``params.seed``) that sweeps its whole range; ``amplitude`` scales the angles (0: rest pose).
    Covers poses no choreographed motion reaches (arms overhead, wide stances, twists), so a
    pose model trained on it sees the body's range of motion, not a handful of routines."""
    coef, phase = _freestyle_curves(int(m.params.seed))
    ph = TAU * t / m.period_s
    k = np.arange(1, _FREESTYLE_HARMONICS + 1)
    s = np.clip((coef[:, :-1] * np.sin(k * ph + phase)).sum(axis=1) + coef[:, -1], -1.0, 1.0)
    a = m.params.amplitude
    q = {}
    for (name, lo, hi), v in zip(_FREESTYLE_RANGES, s):
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        q[name] = float(np.clip(a * (mid + half * v), lo, hi))  # amplitude 0: the rest pose
    b = _Builder()
    for side in ("r", "l"):
        _arm(b, side, abduct=q[f"{side}_arm_abduct"], flex=q[f"{side}_arm_flex"], elbow=q[f"{side}_elbow"])
        _leg(b, side, flex=q[f"{side}_hip_flex"], knee=q[f"{side}_knee"], ankle=q[f"{side}_ankle"],
             abduct=q[f"{side}_hip_abduct"])
    b.set("spine", rot_x(_deg(q["spine_flex"])))
    b.set("chest", rot_y(_deg(q["chest_twist"])), rot_z(_deg(q["chest_side"])))
    b.set("head", rot_y(_deg(q["head_yaw"])), rot_x(_deg(q["head_pitch"])))
    return Pose(b.R, m.rest_root)


# name -> (function, default period, grounded, planted)
_MOTIONS: dict[str, tuple[Callable[[ProceduralMotion, float], Pose], float, bool, bool]] = {
    "stand": (_stand, 4.0, True, True),
    "walk": (_walk, 1.1, True, False),
    "wave": (_wave, 1.2, True, True),
    "squat": (_squat, 2.6, True, True),
    "arm_circles": (_arm_circles, 2.0, True, True),
    "reach": (_reach, 3.2, True, True),
    "turn": (_turn, 4.0, True, True),
    "jumping_jacks": (_jumping_jacks, 1.4, True, True),
    "freestyle": (_freestyle, 6.0, True, True),
}
MOTION_NAMES: tuple[str, ...] = tuple(_MOTIONS)


def make_motion(name: str, skeleton: Skeleton, params: MotionParams | None = None) -> ProceduralMotion:
    """Build the procedural motion ``name`` (one of :data:`MOTION_NAMES`) for ``skeleton``.

    Raises:
        SimConfigError: unknown name or bad parameters.
    """
    if name not in _MOTIONS:
        raise SimConfigError("motion", f"unknown motion {name!r}; choose one of {MOTION_NAMES} or a .bvh path")
    params = params or MotionParams()
    params.validate()
    fn, default_period, grounded, planted = _MOTIONS[name]
    period = float(params.period_s or default_period)
    if name == "walk":
        period *= max(params.strides_per_lap, 1)  # one lap of the circle
    return ProceduralMotion(name, period, grounded, planted, skeleton, params, fn)
