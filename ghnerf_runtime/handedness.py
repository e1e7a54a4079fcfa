"""Whether a triangulated skeleton is a person or a person's mirror image: the cameras' inputs exchanged.

On a rig whose two cameras are mirror images of each other about its centre plane (the usual side-by-side rig,
both aimed at one point), the left camera's frames fed as the right's still meet in 3D: the calibration's view
agreement and the floor stay near a true rig's (docs/calibration.md, "Cameras exchanged"). Each image's 2D joints are
right (the model reads left and right from appearance) but the depths are reflected about the point the cameras
aim at, and the triangulated skeleton is the person's mirror image: its facing direction, taken from its
left-to-right axis and its up axis, points to its back, where the nose and the toes are not.

:func:`handedness` reads that from a pair's triangulated joints (before the skeleton prior, which was trained on
people and answers a person's handedness whatever the triangulation: measured, it hid the mirror entirely). The
figure is in the body's own frame, so turning round, bending or a handstand leave it as it is; a mirror image turns
its sign. A body lying (:data:`LYING_BAND_DEG`), or whose found joints span too little of its width to give its left
(:data:`MIN_LEFT_SPAN_M`: side-on) gives none: there the model's left and right are not to be trusted; nor does a
torso wider than one body's (:data:`MAX_TORSO_SPAN_M`: another person's joints mixed in). A few dot products a pair.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ghnerf_runtime.body25 import JOINT_INDEX

__all__ = ["handedness", "LEFTWARD_PAIRS", "TORSO_SPANS", "FORWARD_CUES", "BACK_JOINTS", "LYING_BAND_DEG",
           "MIN_LEFT_SPAN_M", "MAX_TORSO_SPAN_M"]

_J = JOINT_INDEX
#: (a, b) pairs whose ``a - b`` points to the person's left: the shoulders and hips, through the neck and the mid-hip
#: too (the model's peaks often miss one side's shoulder or hip where the other side's and the middle are found), and
#: the knees and ankles. Summed as they are, so the longer spans weigh more: a span's depth error is about the same
#: whatever its length, and a shoulder's 0.18 m to the neck alone swung the axis by 45 degrees and more at 3.5 m. With
#: the legs and the spans' lengths 702 of 900 pairs gave a figure (587 with the torso's unit vectors alone), and the
#: least separated take read +0.14 / -0.02 as filmed / exchanged (+0.07 / +0.07): ``benchmarks/
#: measure_exchanged_cameras.py --sequences 30 --frames 30 --per-sequence``, session 65.
LEFTWARD_PAIRS: tuple[tuple[int, int], ...] = (
    (_J["LShoulder"], _J["Neck"]), (_J["Neck"], _J["RShoulder"]), (_J["LShoulder"], _J["RShoulder"]),
    (_J["LHip"], _J["MidHip"]), (_J["MidHip"], _J["RHip"]), (_J["LHip"], _J["RHip"]),
    (_J["LKnee"], _J["RKnee"]), (_J["LAnkle"], _J["RAnkle"]))
#: The :data:`LEFTWARD_PAIRS` across the torso (the shoulders and hips, through the neck and the mid-hip): one body's
#: width bounds them, where the knees and ankles spread as far as a stride (one person's up to 0.8 m on the bench's
#: takes as filmed).
TORSO_SPANS: tuple[tuple[int, int], ...] = LEFTWARD_PAIRS[:6]
_TOP = _J["Neck"]
_SHOULDERS = (_J["LShoulder"], _J["RShoulder"])
_HIPS = (_J["MidHip"], _J["LHip"], _J["RHip"])
_KNEES = (_J["LKnee"], _J["RKnee"])
#: (front, back) joint groups whose mean front minus mean back points the way the person faces: the nose ahead of the
#: neck, each foot's toes ahead of its ankle (looking down or lying keeps both ahead in the body's frame).
FORWARD_CUES: tuple[tuple[tuple[int, ...], tuple[int, ...]], ...] = (
    ((_J["Nose"],), (_J["Neck"],)),
    ((_J["RBigToe"], _J["RSmallToe"]), (_J["RAnkle"],)),
    ((_J["LBigToe"], _J["LSmallToe"]), (_J["LAnkle"],)),
)
#: Joints the model finds only on a person's back: a heel at the presence threshold in both views shows the cameras the
#: backs of the feet (on the bench's 30-pair takes none of 240 pairs of a person facing the rig had one, 63 % of 326
#: facing away and 95 % of 900 with the back to the rig did). There the model reads a back as a front in some takes,
#: left and right the other way round with a nose on the back of the head: a true mirror image on a true rig (a
#: 300-pair take with the back to the rig was flagged after 35 pairs, its windows -0.34 to -0.01; of four such takes
#: exchanged one was flagged, two read above 0). Such a pair gives no figure rather than a wrong one:
#: ``benchmarks/measure_exchanged_cameras.py --sequences 30 --frames 30 [--heading-deg 180]`` and ``--only 10 11 25 28
#: --frames 300 --heading-deg 180``, session 66 (docs/calibration.md, "Cameras exchanged").
BACK_JOINTS: tuple[int, ...] = (_J["LHeel"], _J["RHeel"])
#: A body whose up axis lies within this many degrees of level (tilted 45 to 135 degrees from upright; the rig frame's
#: y is along gravity) gives no figure: someone lying, where the model reads left and right the other way round in a
#: view in some takes (its crops turned by ``roi.turn_search`` or not), most of all lying face up or down. Measured
#: (``benchmarks/measure_exchanged_cameras.py --sequences 20 --frames 30 --pose lying_z`` and ``--only 2 6 3 7
#: --frames 150 --pose lying_z``, session 66): lying across the view the true rig's per-pair median was +0.62 but the
#: exchanged rig's -0.08 (no sign to read), and two 150-pair takes of a person lying face down or up on the true rig
#: read -0.29 and -0.23 over about 100 figures each: flagged as exchanged. Upright people tilt under 11 degrees on the
#: bench's motions (their truth), and upside down (a handstand, 180) the figure kept its sign (+0.76 / -0.72).
LYING_BAND_DEG = 45.0
_LEVEL_MAX_UP_Y = math.sin(math.radians(LYING_BAND_DEG))  # |up . gravity| of an axis within the band of level
#: Shortest sum of the found :data:`LEFTWARD_PAIRS` spans (metres) that gives a left axis: joints that span less of the
#: body's width than this give no figure. Side-on the cameras see one side: the far shoulder and hip hidden, the left
#: axis came from the ankles (or a near half-span) a few centimetres apart along the line of sight, and its sign was
#: noise or the model's labels (the near foot read as the far one in both views): the true rig of sequence 25 at heading
#: 270 was flagged after 103 pairs (windows down to -0.64). With the rule it reads +0.89 to +0.91 over 62 figures of
#: 150, the exchanged rig is still flagged (after 43 pairs), and the bench's takes keep 547 of their 548 figures (13 of
#: 13 exchanged takes judged flagged): ``benchmarks/measure_exchanged_cameras.py --only 25 --frames 150 --heading-deg
#: 270`` and ``--sequences 30 --frames 30``, session 66 (docs/calibration.md, "Cameras exchanged").
MIN_LEFT_SPAN_M = 0.1
_MIN_LEFT_SPAN_SQ = MIN_LEFT_SPAN_M ** 2  # (squared once: the summed span is compared squared on every pair)
#: Longest of the found :data:`TORSO_SPANS` (metres) that gives a figure: a torso wider than this is not one body's
#: (shoulders about 0.4 m apart, plus the triangulation's depth error at the working volume's far end, up to 0.43 m
#: on a hip: ``two_people.SLACK_DEPTH_BASELINES``). With a second person beside the subject the runtime does not
#: always call the pair ``several_people``, and a shoulder or hip paired with the other person's peak in one view
#: lies far off along the line of sight: a short take's window read -0.19 against the -0.2 limit before this bound,
#: +0.22 after; it drops 16 of 154 figures as filmed and 28 of 176 exchanged there
#: (``benchmarks/measure_exchanged_cameras.py --sequences 20 --frames 30 --second 1.0,0.4``, session 67). One
#: person's torso spans stayed under it in 540 of 547 figures of the bench's takes as filmed (``--sequences 30
#: --frames 30``; docs/calibration.md, "Cameras exchanged").
MAX_TORSO_SPAN_M = 0.8
_MAX_TORSO_SPAN_SQ = MAX_TORSO_SPAN_M ** 2
#: Shortest span (metres) given a direction: joints closer than a micrometre are one point (a repeated peak).
_TINY_M = 1e-6


def _unit(v: np.ndarray) -> np.ndarray | None:
    n = float(np.sqrt(v @ v))  # (np.linalg.norm's overhead is most of a 3-vector's cost)
    return v / n if n > _TINY_M else None


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of two 3-vectors, without its argument handling (a fifth of this module's cost a pair)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _mean_of(points: np.ndarray, found: np.ndarray, joints: Sequence[int]) -> np.ndarray | None:
    idx = [j for j in joints if found[j]]
    return points[idx].mean(axis=0) if idx else None


def _wider_than_a_body(points: np.ndarray, found: np.ndarray) -> bool:
    """Whether a found :data:`TORSO_SPANS` span is longer than :data:`MAX_TORSO_SPAN_M`: joints of two people."""
    for a, b in TORSO_SPANS:
        if found[a] and found[b]:
            span = points[a] - points[b]
            if float(span @ span) > _MAX_TORSO_SPAN_SQ:
                return True
    return False


def _body_axes(points: np.ndarray, found: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The person's leftward and upward unit axes from the found torso joints (None: too few of them, the leftward
    spans summing under :data:`MIN_LEFT_SPAN_M`, or a torso span over :data:`MAX_TORSO_SPAN_M`)."""
    leftward = [points[a] - points[b] for a, b in LEFTWARD_PAIRS if found[a] and found[b]]
    top = points[_TOP] if found[_TOP] else _mean_of(points, found, _SHOULDERS)
    bottom = _mean_of(points, found, _HIPS)
    if bottom is None:
        bottom = _mean_of(points, found, _KNEES)
    if not leftward or top is None or bottom is None:
        return None
    summed = sum(leftward)
    if float(summed @ summed) < _MIN_LEFT_SPAN_SQ:  # too little of the body's width to tell its left by
        return None
    if _wider_than_a_body(points, found):  # another person's shoulder or hip mixed in
        return None
    left, up = _unit(summed), _unit(top - bottom)
    return None if left is None or up is None else (left, up)


def _lies(up: np.ndarray) -> bool:
    """Whether unit up axis ``up`` (rig frame, y down along gravity) lies within :data:`LYING_BAND_DEG` of level
    (a reflection in depth, the cameras exchanged, leaves its height as it is: both rigs drop the same pairs)."""
    return abs(float(up[1])) < _LEVEL_MAX_UP_Y


def handedness(points: np.ndarray, found: np.ndarray) -> float | None:
    """How much a skeleton faces the way a person's left and up axes say it should: +1 a person, -1 a mirror image.

    The mean over :data:`FORWARD_CUES` with their joints found of the cue's unit direction dotted with the facing
    direction ``left x up`` (the rig frame is x right, y down, z forward: right-handed): the cosine between them,
    times the sine of the angle between the unit left and up axes (a skewed torso reads weaker). Within [-1, 1]
    (clipped: a cue straight ahead read 1 + 2e-16 by rounding, which ``PairResult`` refused). ``None`` when the
    torso gives no axes (its found spans summing under :data:`MIN_LEFT_SPAN_M` of width among them: side-on, one
    side seen; or one torso span over :data:`MAX_TORSO_SPAN_M`: two people's joints) or no cue is found, when a heel
    is (:data:`BACK_JOINTS`: the person's back to the rig, where the model's left and right and its nose are not to be
    trusted), or when the body lies (:data:`LYING_BAND_DEG`).

    Args:
        points: ``(25, 3)`` BODY_25 joints, metres.
        found: ``(25,)`` bool, the joints to read (those triangulated from confident peaks).

    Example:
        >>> from ghnerf_runtime.body25 import JOINT_INDEX as J
        >>> P = np.zeros((25, 3)); ok = np.zeros(25, bool)
        >>> for name, p in {"Neck": (0, -1.5, 0), "MidHip": (0, -1, 0), "LHip": (0.1, -1, 0), "RHip": (-0.1, -1, 0),
        ...                 "Nose": (0, -1.6, -0.1)}.items():  # facing the cameras (-z), the person's left at +x
        ...     P[J[name]], ok[J[name]] = p, True
        >>> round(handedness(P, ok), 2), round(handedness(P * [1, 1, -1], ok), 2)  # and its mirror in depth
        (0.71, -0.71)
    """
    if any(found[j] for j in BACK_JOINTS):
        return None
    axes = _body_axes(points, found)
    if axes is None:
        return None
    left, up = axes
    if _lies(up):
        return None
    facing = _cross(left, up)
    cosines = []
    for front, back in FORWARD_CUES:
        ahead, behind = _mean_of(points, found, front), _mean_of(points, found, back)
        cue = None if ahead is None or behind is None else _unit(ahead - behind)
        if cue is not None:
            cosines.append(float(np.dot(cue, facing)))
    return min(1.0, max(-1.0, sum(cosines) / len(cosines))) if cosines else None  # (np.clip: 5 us of a scalar)
