"""``ghnerf_runtime.body_lie``: how a skeleton lies against gravity and the cameras' lines of sight, the rule the
crop turn search keeps a turned pass by (docs/turn-search.md, "Refusing what no turn rights", "Gradual rolls").

Synthetic stick bodies: the head-and-shoulders joints half a metre one way along an axis from a centre, the hips
and legs half a metre the other, every other joint missing. The rig frame's y is down (along gravity), so standing
is axis (0, -1, 0). Two cameras 1.2 m up at the origin look along +z at the body 3 m ahead. The estimator's own
tests (test_estimator_turn_search.py) ask the same rules of a simulated person's whole skeleton."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ghnerf_runtime.body25 import JOINT_INDEX, JOINT_NAMES
from ghnerf_runtime.body_lie import KEPT_TURN_SECTOR_DEG, KEPT_TURN_STEP_DEG, TURN_LIE_TOLERANCE_DEG, \
    TURN_MIN_FROM_SIGHT_DEG, across_the_views, body_axis, lies_as_kept_turn, lies_as_turned, tilt_from_up_deg
from ghnerf_runtime.joints3d import Joints3D

UPPER = ("Nose", "Neck", "RShoulder", "LShoulder", "REye", "LEye", "REar", "LEar")
LOWER = ("MidHip", "RHip", "LHip", "RKnee", "LKnee", "RAnkle", "LAnkle")
CENTRES = [np.array([-0.1, -1.2, 0.0]), np.array([0.1, -1.2, 0.0])]
AHEAD = np.array([0.0, 0.0, 3.0])


def _tilted(degrees: float, towards=(1.0, 0.0, 0.0)) -> np.ndarray:
    """The unit axis tilted ``degrees`` from straight up (0, -1, 0) towards the horizontal unit vector ``towards``
    (x: across both views, z: along their lines of sight)."""
    t = math.radians(degrees)
    return math.sin(t) * np.asarray(towards, np.float64) + math.cos(t) * np.array([0.0, -1.0, 0.0])


def _stick(axis, at=AHEAD, upper=UPPER, lower=LOWER, half_m: float = 0.5) -> Joints3D:
    """A body whose ``upper`` joints lie ``half_m`` along ``axis`` from ``at`` and whose ``lower`` ones lie as far the
    other way; the others missing."""
    n = len(JOINT_NAMES)
    points = np.zeros((n, 3))
    valid = np.zeros(n, bool)
    for names, sign in ((upper, 1.0), (lower, -1.0)):
        for name in names:
            points[JOINT_INDEX[name]] = np.asarray(at, np.float64) + sign * half_m * np.asarray(axis, np.float64)
            valid[JOINT_INDEX[name]] = True
    return Joints3D(points, valid.astype(np.float32), valid, np.zeros((n, 2)))


def test_the_body_axis_points_from_the_legs_to_the_head():
    np.testing.assert_allclose(body_axis(_stick(_tilted(0.0))), [0.0, -1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(body_axis(_stick(_tilted(90.0))), [1.0, 0.0, 0.0], atol=1e-12)
    # one found joint of each group is enough; the missing ones' zeros do not pull the centroids
    one_each = _stick(_tilted(180.0), upper=("Neck",), lower=("RAnkle",))
    np.testing.assert_allclose(body_axis(one_each), [0.0, 1.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("upper, lower", [((), LOWER), (UPPER, ()), ((), ())])
def test_no_head_and_shoulders_or_no_hips_and_legs_gives_no_axis_and_no_lie(upper, lower):
    """Arms alone (wrists, elbows) say nothing of how the body lies: no axis, and neither rule takes the pass, even
    with an axis to roll on from."""
    j3 = _stick(_tilted(90.0), upper=upper, lower=lower)
    j3.valid[JOINT_INDEX["RWrist"]] = j3.valid[JOINT_INDEX["LElbow"]] = True
    j3.points[JOINT_INDEX["RWrist"]] = AHEAD + [0.3, 0.0, 0.0]
    assert body_axis(j3) is None
    assert not lies_as_turned(j3, CENTRES)
    assert not lies_as_kept_turn(j3, CENTRES, (90, 90), np.array([1.0, 0.0, 0.0]))


def test_coincident_centroids_give_no_axis():
    """The upper and lower joints' centroids together (a crumpled misread): no direction, not a zero vector whose
    angles would be NaN."""
    assert body_axis(_stick(_tilted(90.0), half_m=0.0)) is None
    assert body_axis(_stick(_tilted(90.0), half_m=1e-8)) is None
    assert not lies_as_turned(_stick(_tilted(90.0), half_m=0.0), CENTRES)


@pytest.mark.parametrize("degrees", [0.0, 45.0, 90.0, 135.0, 180.0])
def test_tilt_from_up(degrees):
    assert tilt_from_up_deg(_tilted(degrees)) == pytest.approx(degrees, abs=1e-9)
    assert tilt_from_up_deg(_tilted(degrees, towards=(0.0, 0.0, -1.0))) == pytest.approx(degrees, abs=1e-9)


def test_tilt_from_up_takes_an_axis_a_rounding_past_unit_length():
    """A unit axis rounded a hair past length 1 along y is straight up or down, not a math domain error."""
    assert tilt_from_up_deg(np.array([0.0, -(1.0 + 1e-12), 0.0])) == 0.0
    assert tilt_from_up_deg(np.array([0.0, 1.0 + 1e-12, 0.0])) == 180.0


@pytest.mark.parametrize("degrees, lies", [
    (90.0, True),  # level across the views
    (-90.0, True),
    (90.0 - TURN_LIE_TOLERANCE_DEG + 1.0, True),  # within the tolerance of level
    (90.0 + TURN_LIE_TOLERANCE_DEG - 1.0, True),
    (90.0 - TURN_LIE_TOLERANCE_DEG - 1.0, False),  # tilted halfway: no turn rights it
    (90.0 + TURN_LIE_TOLERANCE_DEG + 1.0, False),
    (180.0 - TURN_LIE_TOLERANCE_DEG - 1.0, False),
    (180.0 - TURN_LIE_TOLERANCE_DEG + 1.0, True),  # upside down, leaning
    (180.0, True),
    (0.0, False),  # standing
])
def test_a_turned_pass_lies_level_or_upside_down(degrees, lies):
    assert lies_as_turned(_stick(_tilted(degrees)), CENTRES) is lies


@pytest.mark.parametrize("degrees", [90.0, -90.0, 80.0])
def test_a_body_along_the_line_of_sight_is_not_a_turned_body(degrees):
    """Level, but pointing at the cameras (or away): no view shows its length for a turn to right."""
    along = _stick(_tilted(degrees, towards=(0.0, 0.0, 1.0)))
    assert not lies_as_turned(along, CENTRES)
    assert not across_the_views(body_axis(along), AHEAD, CENTRES)


def test_the_line_of_sight_rule_asks_every_camera():
    """A body across one camera's view but along the other's line of sight is refused: a turn of both crops is
    kept only as a pair."""
    axis = _tilted(90.0)
    beside = AHEAD + np.array([3.0, 1.2, 0.0])  # a camera to the side sees the level body along its line of sight
    assert across_the_views(axis, AHEAD, CENTRES)
    assert not across_the_views(axis, AHEAD, [CENTRES[0], beside])
    # exactly along the line of sight: refused, never a math domain error (from this camera |cos| rounds to
    # 1.0000000000000002)
    camera = np.array([0.5, -0.9, -1.8])
    sight = AHEAD - camera
    assert not across_the_views(sight / np.linalg.norm(sight), AHEAD, [camera])


def test_a_camera_at_the_centroid_has_no_line_of_sight_and_says_nothing():
    """A camera centre on the joints' centroid (a wild misread) gives no direction to measure from: that camera is
    left out rather than dividing by zero, and the other camera decides."""
    for axis, lies in ((_tilted(90.0), True), (_tilted(90.0, towards=(0.0, 0.0, 1.0)), False)):
        j3 = _stick(axis)
        centroid = j3.points[j3.valid].mean(axis=0)  # 8 upper joints and 7 lower: not AHEAD
        assert lies_as_turned(j3, [centroid, CENTRES[1]]) is lies  # the other camera decides
        assert across_the_views(body_axis(j3), centroid, [centroid])
        assert across_the_views(body_axis(j3), centroid, [centroid + 1e-9])  # within a micrometre: no direction


def test_the_sight_rule_s_limit():
    """The axis must be at least ``TURN_MIN_FROM_SIGHT_DEG`` from each line of sight (one camera on the axis of
    the body's centre, so that the angle is exact)."""
    camera = np.zeros(3)
    at = np.array([0.0, 0.0, 3.0])
    for off, across in ((1.0, True), (-1.0, False)):
        t = math.radians(TURN_MIN_FROM_SIGHT_DEG + off)
        assert across_the_views(np.array([math.sin(t), 0.0, math.cos(t)]), at, [camera]) is across


def test_a_kept_turn_keeps_what_the_search_keeps_without_a_last_axis():
    for degrees in (90.0, 180.0, 130.0, 45.0):
        body = _stick(_tilted(degrees))
        assert lies_as_kept_turn(body, CENTRES, (90, 90), None) is lies_as_turned(body, CENTRES)


@pytest.mark.parametrize("step, kept", [
    (KEPT_TURN_STEP_DEG - 5.0, True),  # rolled on a few degrees from the last pass kept through the turn
    (-(KEPT_TURN_STEP_DEG - 5.0), True),
    (KEPT_TURN_STEP_DEG + 5.0, False),  # jumped there in one pair
    (-(KEPT_TURN_STEP_DEG + 5.0), False),
])
def test_a_kept_turn_keeps_a_roll_and_refuses_a_jump(step, kept):
    """130 degrees from upright: tilted halfway, the search's rule refuses it; through a kept quarter turn it is a
    roll when the pass before was near."""
    body = _stick(_tilted(130.0))
    assert not lies_as_turned(body, CENTRES)
    assert lies_as_kept_turn(body, CENTRES, (90, 90), _tilted(130.0 + step)) is kept


def test_the_same_axis_again_is_a_roll_of_nothing():
    """The last axis the body's own (the dot product may round a hair past 1): kept, not a math domain error."""
    body = _stick(_tilted(130.0, towards=(1.0, 0.0, 1e-3)))
    axis = body_axis(body)
    assert lies_as_kept_turn(body, CENTRES, (90, 90), axis)
    assert lies_as_kept_turn(body, CENTRES, (90, 90), axis * (1.0 + 1e-12))


@pytest.mark.parametrize("turns, degrees, kept", [
    ((90, 90), 90.0 + KEPT_TURN_SECTOR_DEG - 1.0, True),  # a quarter turn covers 45-135 degrees
    ((90, 90), 90.0 + KEPT_TURN_SECTOR_DEG + 1.0, False),  # nearer the half turn
    ((90, 90), 90.0 - KEPT_TURN_SECTOR_DEG + 1.0, True),
    ((90, 90), 90.0 - KEPT_TURN_SECTOR_DEG - 1.0, False),  # nearer upright
    ((270, 270), 50.0, True),  # a quarter turn either way
    ((-90, 0), 50.0, True),  # a turn given as negative degrees; a view not turned asks nothing
    ((450, 0), 50.0, True),
    ((180, 180), 180.0 - KEPT_TURN_SECTOR_DEG + 1.0, True),  # a half turn covers 135-180
    ((180, 180), 180.0 - KEPT_TURN_SECTOR_DEG - 1.0, False),
    ((180, 90), 130.0, True),  # within some view's sector
    ((0, 0), 130.0, False),  # no turn kept: nothing to roll on through
    ((0, 0), 40.0, False),  # upright crops have no sector about upright
    ((360, 0), 40.0, False),
])
def test_a_kept_turn_s_roll_stays_within_the_turn_s_sector(turns, degrees, kept):
    body = _stick(_tilted(degrees))
    assert lies_as_kept_turn(body, CENTRES, turns, _tilted(degrees + 3.0)) is kept


def test_a_roll_onto_a_line_of_sight_is_not_kept():
    """Rolled on a few degrees and within the turn's sector, but pointing at the cameras: still refused."""
    body = _stick(_tilted(130.0, towards=(0.0, 0.0, 1.0)))
    assert not across_the_views(body_axis(body), AHEAD, CENTRES)
    assert not lies_as_kept_turn(body, CENTRES, (90, 90), _tilted(127.0, towards=(0.0, 0.0, 1.0)))
    # the same roll across the views is kept
    assert lies_as_kept_turn(_stick(_tilted(130.0)), CENTRES, (90, 90), _tilted(127.0))


@pytest.mark.parametrize("degrees, towards, near", [
    (65.0, (1.0, 0.0, 0.0), True),  # lying down across the views, 5 degrees short of the window
    (61.0, (1.0, 0.0, 0.0), True),  # 9 short
    (55.0, (1.0, 0.0, 0.0), False),  # 15 short: still bending over
    (75.0, (1.0, 0.0, 0.0), False),  # in the window: lies_as_turned keeps it, nothing to be near
    (115.0, (1.0, 0.0, 0.0), False),  # past lying toward upside down: where people along a sight line read
    (150.0, (1.0, 0.0, 0.0), False),  # short of upside down: the same
    (65.0, (0.0, 0.0, -1.0), False),  # tilted along the line of sight: no turn rights it, however far it rolls
])
def test_a_refused_body_nearly_lying_across_the_views(degrees, towards, near):
    """``nears_a_turned_lie`` (``degrees_short_of_lying``: how far): a refused turned pass of a person lying down,
    up to ``TURN_NEAR_LIE_DEG`` short of the lying window (the search's early retry after a failed search,
    docs/turn-search.md, "A body nearly lying")."""
    from ghnerf_runtime.body_lie import TURN_NEAR_LIE_DEG, degrees_short_of_lying, nears_a_turned_lie

    assert TURN_NEAR_LIE_DEG == 10.0
    j3 = _stick(_tilted(degrees, towards))
    assert nears_a_turned_lie(j3, CENTRES) is near
    short = degrees_short_of_lying(j3, CENTRES)  # how far short: the early searches' "rolling in" compares it
    assert short is None if not near else short == pytest.approx(90.0 - TURN_LIE_TOLERANCE_DEG - degrees)
    if near:
        assert not lies_as_turned(j3, CENTRES)  # only ever asked of a refused pass


@pytest.mark.parametrize("last_deg, read_deg, flipped", [
    (135.0, -15.0, True),  # the cartwheel's lost quarter turn, read upright as someone standing: 150 degrees
    (175.0, 0.0, True),  # upside down, read standing
    (135.0, 155.0, False),  # rolled on 20 degrees
    (90.0, 0.0, False),  # lying across, then standing: 90, not turned over
    (90.0, -25.0, False),  # 115: under the 120-degree bar
])
def test_an_upright_read_turned_over_against_the_last_kept_pass(last_deg, read_deg, flipped):
    """``reads_flipped``: no body turns over in one pair, so an upright read more than 120 degrees
    (``TURN_FLIPPED_READ_DEG``) from the last pass kept through a lost turn is a misread."""
    from ghnerf_runtime.body_lie import reads_flipped

    assert reads_flipped(_stick(_tilted(read_deg)), _tilted(last_deg)) is flipped


def test_a_read_without_a_body_axis_is_not_turned_over():
    """No head and shoulders found: no axis, nothing to say the body turned over."""
    from ghnerf_runtime.body_lie import reads_flipped

    assert not reads_flipped(_stick(_tilted(0.0), upper=()), _tilted(135.0))


@pytest.mark.parametrize("last_deg, lost, may", [
    (135.0, (90, 90), True),  # the cartwheel leaving the quarter turn: 45 degrees from the half turn
    (110.0, (90, 270), True),  # 70: within a step and a sector
    (100.0, (90, 90), False),  # 80: no
    (90.0, (90, 90), False),  # lying across
    (175.0, (180, 180), False),  # upside down: 85 from the quarter turn
    (135.0, (180, 180), True),  # leaving the half turn toward lying
    (135.0, (90, 180), False),  # both other turns lost (views turned differently)
])
def test_another_turn_may_hold_a_body_rolled_on_from_a_lost_turn(last_deg, lost, may):
    """``another_turn_may_hold``: a turn other than the lost ones within a step (25 degrees) and a sector (45) of the
    last kept pass's tilt, as ``lies_as_kept_turn`` could keep."""
    from ghnerf_runtime.body_lie import another_turn_may_hold

    assert another_turn_may_hold(_tilted(last_deg), lost) is may
