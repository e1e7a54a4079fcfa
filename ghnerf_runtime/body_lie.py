"""How a body lies against gravity and the cameras' lines of sight: what the crop turn search (``roi.turn_search``,
:class:`~ghnerf_runtime.estimator.Estimator`) asks of a turned pass's skeleton before keeping it.

A crop turn shows the encoder someone lying across a view, or upside down, as upright; a body it does not right
(lying along a line of sight, tilted halfway) the encoder reads as an upright person across the picture, a wrong
skeleton (docs/turn-search.md, "Refusing what no turn rights" and "Gradual rolls"). Whether a skeleton lies as a turn
rights a body is geometry alone: joints in the rig frame (y down, along gravity) and the cameras' centres in, a
yes or no out, no estimator state and no model. It lives here, apart from the estimator, so that it reads and is
tested on its own.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ghnerf_runtime.body25 import JOINT_INDEX
from ghnerf_runtime.joints3d import Joints3D

__all__ = ["KEPT_TURN_SECTOR_DEG", "KEPT_TURN_STEP_DEG", "TURN_LIE_TOLERANCE_DEG", "TURN_MIN_FROM_SIGHT_DEG",
           "TURN_FLIPPED_READ_DEG", "TURN_NEAR_LIE_DEG", "across_the_views", "another_turn_may_hold",
           "axis_angle_deg", "body_axis", "degrees_short_of_lying", "lies_as_kept_turn", "lies_as_turned",
           "nears_a_turned_lie", "reads_flipped", "tilt_from_up_deg"]

#: roi.turn_search: a turned pass is kept only when its body lies as a turn can right (:func:`lies_as_turned`):
#: level or upside down within this many degrees (its body axis against gravity). In a one-off look at the 30 bench
#: scenes (benchmarks/measure_lying_rendered.py's poses, 15 pairs each), the turned passes the search kept of people
#: lying across the view were 83-97 degrees from upright, upside down 170-179; 5 of the 10 it kept of people lying
#: along the line of sight 124-150, 0.55-1.2 m off (the encoder's upright person across the picture, rising off the
#: floor toward the cameras). docs/turn-search.md, "Refusing what no turn rights".
TURN_LIE_TOLERANCE_DEG = 20.0
#: roi.turn_search: and at least this many degrees from each camera's line of sight to it: a body along a view's line
#: of sight shows that view no length to turn upright. The kept passes above: 61-89 degrees from the nearer line of
#: sight lying across and upside down (an upright body is 90 less the view's pitch), 4 of those lying along 19-31
#: (level, 0.24-0.42 m off).
TURN_MIN_FROM_SIGHT_DEG = 45.0
#: roi.turn_search: a kept turn's passes (:func:`lies_as_kept_turn`) keep it while the body's tilt from upright lies
#: within this many degrees of the turn: half of a quarter turn, where the next turn (or upright) would show it as
#: upright. benchmarks/measure_lying_rendered.py --rolls measures it (docs/turn-search.md, "Gradual rolls").
KEPT_TURN_SECTOR_DEG = 45.0
#: roi.turn_search: and only while its body axis moves at most this many degrees from the pass kept through the turn
#: the pair before (a roll, not a jump; a pair that kept none drops the axis, Estimator._kept_turn_axis). In
#: benchmarks/measure_lying_rendered.py --rolls (30 pairs, 3-6 degrees a pair) the passes only the looser rule keeps
#: moved 0-18 degrees from the pass before (a one-off look, docs/turn-search.md); the
#: turned pass of a person rolled rigidly from across the view onto a line of sight (bench scene 21,
#: tests/ghnerf_runtime/test_estimator_turn_search.py) 44.
KEPT_TURN_STEP_DEG = 25.0
#: roi.turn_search: a refused turned pass whose body lies across the views tilted up to this many degrees short of
#: lying (:func:`nears_a_turned_lie`) marks a person lying down who may roll into the window at the next pair. In
#: benchmarks/measure_lying_rendered.py --rolls (a one-off look, docs/turn-search.md, "A body nearly lying") the
#: searches that failed on a person lying down refused their turned pass at 54-69 degrees from upright, those kept
#: read 71-86 (one 100); the refused passes of people lying along a line of sight that lay across the views read
#: 127-160.
TURN_NEAR_LIE_DEG = 10.0
#: roi.turn_search: an upright pass whose body axis lies more than this many degrees from that of the last pass kept
#: through a turn the pair lost reads the body turned over (:func:`reads_flipped`): no body turns so far in one pair.
#: In benchmarks/measure_lying_rendered.py --rolls (a one-off look, docs/turn-search.md, "A turn lost past 135
#: degrees") the upright passes after a lost turn that found someone read 11-17 degrees from the kept pass, but the
#: cartwheel's past 150 degrees (bench scene 10), the upside-down body read as someone standing: 150. Over 90,
#: not 90: someone lying across the view who stands up in a pair reads about 90 from the kept pass.
TURN_FLIPPED_READ_DEG = 120.0
#: the joints whose centroids give a body's axis (:func:`body_axis`): the head and shoulders, the hips and legs
_AXIS_UPPER = tuple(JOINT_INDEX[n] for n in ("Nose", "Neck", "RShoulder", "LShoulder", "REye", "LEye", "REar",
                                             "LEar"))
_AXIS_LOWER = tuple(JOINT_INDEX[n] for n in ("MidHip", "RHip", "LHip", "RKnee", "LKnee", "RAnkle", "LAnkle"))


def body_axis(j3: Joints3D) -> np.ndarray | None:
    """The unit vector from the centroid of ``j3``'s found lower-body joints (hips, knees, ankles) to that of its
    found upper-body joints (head, neck, shoulders): which way the body points. ``None`` without a found joint in
    either group, or with the two centroids together."""
    upper = [j for j in _AXIS_UPPER if j3.valid[j]]
    lower = [j for j in _AXIS_LOWER if j3.valid[j]]
    if not upper or not lower:
        return None
    d = j3.points[upper].mean(axis=0) - j3.points[lower].mean(axis=0)
    n = float(np.linalg.norm(d))
    return d / n if n > 1e-6 else None


def tilt_from_up_deg(axis: np.ndarray) -> float:
    """How far body axis ``axis`` (a unit vector, rig frame: y down along gravity) points from straight up (0
    standing, 90 level, 180 upside down)."""
    return math.degrees(math.acos(float(np.clip(-axis[1], -1.0, 1.0))))


def across_the_views(axis: np.ndarray, centroid: np.ndarray, centres: Sequence[np.ndarray]) -> bool:
    """Whether body axis ``axis`` at ``centroid`` lies at least :data:`TURN_MIN_FROM_SIGHT_DEG` from each camera's
    line of sight to it (``centres``: the cameras' centres): a body along a view's line of sight shows that view no
    length for a crop turn to right."""
    for c in centres:
        sight = centroid - np.asarray(c, np.float64)
        n = float(np.linalg.norm(sight))
        if n > 1e-6 and math.degrees(math.acos(min(1.0, abs(float(sight @ axis)) / n))) < TURN_MIN_FROM_SIGHT_DEG:
            return False
    return True


def lies_as_turned(j3: Joints3D, centres: Sequence[np.ndarray]) -> bool:
    """Whether ``j3``, a turned pass's joints (``roi.turn_search``), lie as a crop turn rights a body: the body axis
    (:func:`body_axis`) level or upside down within :data:`TURN_LIE_TOLERANCE_DEG` (the rig frame's y is down,
    along gravity), and at least :data:`TURN_MIN_FROM_SIGHT_DEG` from each camera's line of sight to the found
    joints' centroid (``centres``: the cameras' centres). A turn shows the encoder someone lying across a view or
    upside down as upright; a body it does not right (lying along the line of sight) it reads as an upright person
    across the picture, a skeleton that stands tilted off the floor or runs along a view's line of sight, 0.24-1.2 m
    off (docs/turn-search.md, "Refusing what no turn rights"). No axis (no head and shoulders, or no hips and legs found):
    nothing says how the body lies, and the pass is not taken."""
    axis = body_axis(j3)
    if axis is None:
        return False
    from_up = tilt_from_up_deg(axis)
    if abs(from_up - 90.0) > TURN_LIE_TOLERANCE_DEG and from_up < 180.0 - TURN_LIE_TOLERANCE_DEG:
        return False  # neither lying nor upside down: tilted halfway, no body a turn rights
    return across_the_views(axis, j3.points[j3.valid].mean(axis=0), centres)


def degrees_short_of_lying(j3: Joints3D, centres: Sequence[np.ndarray]) -> float | None:
    """How many degrees (over 0, at most :data:`TURN_NEAR_LIE_DEG`) short of the lying window ``j3`` lies when
    :func:`nears_a_turned_lie`; else ``None``."""
    axis = body_axis(j3)
    if axis is None:
        return None
    short_of_lying = (90.0 - TURN_LIE_TOLERANCE_DEG) - tilt_from_up_deg(axis)
    if not 0.0 < short_of_lying <= TURN_NEAR_LIE_DEG:
        return None
    if not across_the_views(axis, j3.points[j3.valid].mean(axis=0), centres):
        return None
    return short_of_lying


def nears_a_turned_lie(j3: Joints3D, centres: Sequence[np.ndarray]) -> bool:
    """Whether ``j3``, a turned pass's joints that :func:`lies_as_turned` refused, lie across the views and tilted
    from upright toward lying, short of the window by at most :data:`TURN_NEAR_LIE_DEG`: a person lying down, read
    through the turn at the tilt the turned pass gives (in the rolls the refused passes' tilt was the body's within
    a few degrees), who a few degrees more of roll brings into the window. Only the side from upright: the bands
    short of upside down, and past lying toward it, hold the readings of people lying along a line of sight
    (127-160 degrees, across the views), whom no turn rights. How far short: :func:`degrees_short_of_lying`."""
    return degrees_short_of_lying(j3, centres) is not None


def lies_as_kept_turn(j3: Joints3D, centres: Sequence[np.ndarray], turns: Sequence[int],
                      last_axis: np.ndarray | None) -> bool:
    """Whether ``j3``, a pass through a kept turn's crops (``turns``: each view's, degrees), still lies as that
    turn rights a body: as :func:`lies_as_turned` asks (how the turn was found), or rolled on from the last pass
    kept through it (``last_axis``, its :func:`body_axis`; ``None``: none) by at most :data:`KEPT_TURN_STEP_DEG`,
    across the views, and tilted from upright within :data:`KEPT_TURN_SECTOR_DEG` of some view's turn (a quarter
    turn either way 45-135 degrees, a half turn 135-180: the turn still shows the body nearer upright than upright
    crops or the next turn would). A person kept turned who rolls on (up onto an elbow, through a cartwheel) passes
    a few degrees a pair through tilts the search's windows refuse, and the turn reads them better than upright
    crops; refused there, the pair went cold through upright crops, whose search refused its turned passes too.
    A pass that jumps there (a person lying across the view who rolled onto a line of sight, read through the
    turned crops as the encoder's upright person across the picture: 44 degrees in one pair in bench scene 21) is
    not kept (docs/turn-search.md, "Gradual rolls")."""
    if lies_as_turned(j3, centres):
        return True
    axis = body_axis(j3)
    if axis is None or last_axis is None:
        return False
    if axis_angle_deg(axis, last_axis) > KEPT_TURN_STEP_DEG:
        return False  # not rolled on from the last pass: a jump
    from_up = tilt_from_up_deg(axis)
    if not any(abs(from_up - min(t % 360, 360 - t % 360)) <= KEPT_TURN_SECTOR_DEG for t in turns if t % 360):
        return False  # nearer upright or another turn: not this turn's body
    return across_the_views(axis, j3.points[j3.valid].mean(axis=0), centres)


def axis_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """The angle between two unit body axes (:func:`body_axis`), degrees (0-180)."""
    return math.degrees(math.acos(float(np.clip(a @ b, -1.0, 1.0))))


def reads_flipped(j3: Joints3D, last_axis: np.ndarray) -> bool:
    """Whether ``j3``, an upright pass's joints in the pair that lost a kept turn, reads the body turned over against
    ``last_axis`` (the :func:`body_axis` of the last pass kept through that turn): more than
    :data:`TURN_FLIPPED_READ_DEG` from it. No body turns over in one pair; upright crops read a body past 135 degrees
    (the cartwheel toward upside down) as someone standing, strongly, feet where the head is (docs/turn-search.md,
    "A turn lost past 135 degrees"). No axis (no head and shoulders, or no hips and legs found): no."""
    axis = body_axis(j3)
    return axis is not None and axis_angle_deg(axis, last_axis) > TURN_FLIPPED_READ_DEG


def _turn_tilt_deg(turn: int) -> int:
    """The tilt from upright (0-180 degrees) of a body that a crop turn of ``turn`` degrees shows upright."""
    t = turn % 360
    return min(t, 360 - t)


def another_turn_may_hold(last_axis: np.ndarray, lost: Sequence[int]) -> bool:
    """Whether a turn other than the views' ``lost`` ones could keep a pass rolled on from ``last_axis``, the last pass
    kept through them, as :func:`lies_as_kept_turn` asks (a step of at most :data:`KEPT_TURN_STEP_DEG`, within
    :data:`KEPT_TURN_SECTOR_DEG` of that turn's tilt): the cartwheel that lost the quarter turn at 135 degrees, near
    the half turn's sector. Not someone lying across the view (90) or upside down (175) who got up: no other turn
    lies that near."""
    lost_tilts = {_turn_tilt_deg(t) for t in lost if t % 360}
    tilt = tilt_from_up_deg(last_axis)
    return any(abs(tilt - other) <= KEPT_TURN_SECTOR_DEG + KEPT_TURN_STEP_DEG
               for other in (90, 180) if other not in lost_tilts)
