"""The path of a view between the rig's cameras (``novel_view.path``): the line, the orbit round the axes' pivot,
and ``auto``; the pivot's fall-backs (the subject, then the line)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ghnerf_runtime.config import ConfigError, EstimatorConfig, NovelViewConfig, config_from_dict
from ghnerf_runtime.errors import GeometryError
from ghnerf_runtime.geometry import Camera, intrinsics_from_fov, look_at
from ghnerf_runtime.geometry.orbit import (AXES_PIVOT_DROP_M, AXES_PIVOT_HOLD_M, PARALLEL_AXES_DEG, axes_angle_deg,
                                           axes_pivot, in_front, subject_pivot)
from ghnerf_runtime.novel_view import AUTO_ORBIT_MIN_ANGLE_DEG, HALF_TURN_BAND_DEG, interpolate_camera, novel_pivot
from ghnerf_runtime.rig_file import load_rig

REPO = Path(__file__).resolve().parents[2]
K = intrinsics_from_fov(128, 128, 60.0)


def _cam(name: str, eye, target, up=(0.0, -1.0, 0.0), K=K) -> Camera:
    return Camera(name, 128, 128, K, [], *look_at(eye, target, up))


def _facing(distance_a: float = 3.0, distance_b: float = 3.0):
    """Two cameras 180 degrees apart on the x axis, both aimed at a subject at the origin."""
    return _cam("a", (-distance_a, 0.0, 0.0), (0.0, 0.0, 0.0)), _cam("b", (distance_b, 0.0, 0.0), (0.0, 0.0, 0.0))


def _around(angle_deg: float, radius: float = 3.0, subject=(0.0, -0.95, 3.0)):
    """Two cameras ``radius`` from ``subject``, ``angle_deg`` apart round it, 1.3 m high, aimed at it."""
    subject = np.asarray(subject)
    cams = []
    for name, sign in (("a", -1.0), ("b", 1.0)):
        yaw = np.radians(sign * angle_deg / 2)
        eye = subject + radius * np.array([np.sin(yaw), 0.0, -np.cos(yaw)])
        eye[1] = -1.3
        cams.append(_cam(name, eye, subject))
    return cams


def _looks_at(camera: Camera, point: np.ndarray) -> bool:
    direction = (point - camera.center) / np.linalg.norm(point - camera.center)
    return bool(np.allclose(camera.R[2], direction, atol=1e-9))


def _rotation_ok(R: np.ndarray) -> bool:
    return bool(np.allclose(R @ R.T, np.eye(3), atol=1e-9) and np.linalg.det(R) == pytest.approx(1.0, abs=1e-9))


# ------------------------------------------------------------------ the defect and its fix
def test_facing_cameras_orbit_round_the_subject_where_the_line_goes_through_it():
    a, b = _facing()
    subject = np.zeros(3)
    # collinear axes have no nearest point: the subject's centre is the pivot
    assert axes_pivot(a, b) is None
    pivot = novel_pivot(a, b, "orbit", subject)
    np.testing.assert_array_equal(pivot, subject)
    orbit = interpolate_camera(a, b, 0.5, pivot=pivot)
    line = interpolate_camera(a, b, 0.5)
    np.testing.assert_allclose(line.center, subject, atol=1e-12)  # the old defect: the view from inside the body
    assert np.linalg.norm(orbit.center - pivot) == pytest.approx(3.0, abs=1e-9)  # as far as the ends
    assert _looks_at(orbit, pivot)
    uv, depth = orbit.project(pivot[None], distort=False)
    np.testing.assert_allclose(uv[0], K[:2, 2], atol=1e-6)  # the pivot in the middle of the picture
    assert depth[0] == pytest.approx(3.0)
    for alpha in (0.1, 0.25, 0.75, 0.9):  # the whole way round, never nearer
        cam = interpolate_camera(a, b, alpha, pivot=pivot)
        assert np.linalg.norm(cam.center - pivot) == pytest.approx(3.0, abs=1e-9) and _looks_at(cam, pivot)


def test_cameras_round_the_subject_orbit_its_pivot_at_the_lerped_distance():
    """Cameras 150 degrees apart round the subject, tilted down at it (axes 147 degrees apart, crossing at it):
    the pivot is the subject without being told; the distance to it is lerped when the two differ."""
    subject = np.array([0.0, -0.95, 3.0])
    a, b = _around(150.0)
    np.testing.assert_allclose(axes_pivot(a, b), subject, atol=1e-9)
    np.testing.assert_allclose(novel_pivot(a, b, "auto"), subject, atol=1e-9)
    line = interpolate_camera(a, b, 0.5)
    assert np.linalg.norm(line.center - subject) < 0.9  # the line's camera nearly in the subject's box
    ra = np.linalg.norm(a.center - subject)
    far = _cam("b", subject + 2.0 * (b.center - subject), subject)  # b twice as far
    for alpha in (0.25, 0.5, 0.75):
        cam = interpolate_camera(a, far, alpha, pivot=subject)
        assert np.linalg.norm(cam.center - subject) == pytest.approx((1 - alpha) * ra + alpha * 2 * ra, abs=1e-9)
        assert _looks_at(cam, subject)


def test_the_ends_are_the_rig_cameras_exactly():
    """Skew axes (the pivot on neither), different focal lengths: alpha 0 and 1 are the two cameras."""
    a = _cam("a", (-1.0, -1.2, 0.0), (0.1, -1.0, 3.0))
    Kb = K.copy()
    Kb[0, 0] = Kb[1, 1] = 1.3 * K[0, 0]
    b = _cam("b", (1.5, -1.4, 0.5), (-0.2, -0.9, 3.2), K=Kb)
    pivot = novel_pivot(a, b, "orbit")
    assert pivot is not None and not _looks_at(a, pivot) and not _looks_at(b, pivot)
    for alpha, cam in ((0.0, a), (1.0, b)):
        end = interpolate_camera(a, b, alpha, pivot=pivot)
        np.testing.assert_allclose(end.center, cam.center, atol=1e-12)
        np.testing.assert_allclose(end.R, cam.R, atol=1e-12)
        np.testing.assert_allclose(end.K, cam.K, atol=1e-12)


@pytest.mark.parametrize("alpha", [-1.0, -0.3, 0.0, 0.2, 0.5, 0.8, 1.0, 1.4, 2.0])
def test_the_orbit_camera_is_a_proper_rotation(alpha):
    rng = np.random.default_rng(7)
    subject = np.array([0.0, -1.0, 3.0])
    checked = 0
    for _ in range(40):
        eyes = subject + rng.uniform(-3, 3, (2, 3)) * [1, 0.2, 1]
        a, b = (_cam(n, e, subject + rng.normal(0, 0.2, 3)) for n, e in zip("ab", eyes))
        pivot = novel_pivot(a, b, "orbit", subject)
        if pivot is None:
            continue
        try:
            cam = interpolate_camera(a, b, alpha, pivot=pivot)
        except GeometryError as e:  # far out, two cameras at very different distances: refused, never mirrored
            assert "extrapolates the distances" in str(e) and not 0 <= alpha <= 1
            continue
        assert _rotation_ok(cam.R) and np.all(np.isfinite(cam.center))
        checked += 1
    assert checked >= 20


def _level_facing(angle_deg: float, aim_off_m: float, subject=(0.0, -0.95, 3.0)):
    """Two level cameras 3 m from ``subject``, ``angle_deg`` apart round it; b aimed ``aim_off_m`` to its left."""
    subject = np.asarray(subject)
    yaw = np.radians(angle_deg / 2)
    eye_a = subject + 3.0 * np.array([-np.sin(yaw), 0.0, -np.cos(yaw)])
    eye_b = subject + 3.0 * np.array([np.sin(yaw), 0.0, -np.cos(yaw)])
    left_of_b = np.cross(subject - eye_b, [0.0, 1.0, 0.0])
    return _cam("a", eye_a, subject), _cam("b", eye_b, subject + aim_off_m * left_of_b / np.linalg.norm(left_of_b))


@pytest.mark.parametrize("aim_off_m", [0.0, 0.01, 0.03])
@pytest.mark.parametrize("angle_deg", [175.0, 178.0, 179.0, 179.9, 180.0])
def test_near_antiparallel_axes_aimed_off_keep_the_pivot_on_the_subject(angle_deg, aim_off_m):
    """The axes' nearest point moves along them by the offset over the tangent of the angle from antiparallel
    (1.2 m for 3 cm at 178 degrees; at 180 the two axes meet at b, 3 m off): with the subject known, the pivot
    stays on it (within the axes' own offset) and the halfway camera 3 m out, not inside the subject or at b."""
    subject = np.array([0.0, -0.95, 3.0])
    a, b = _level_facing(angle_deg, aim_off_m, subject)
    assert axes_angle_deg(a, b) > 174.9
    pivot = novel_pivot(a, b, "auto", subject + [0.0, -0.075, 0.0])  # the volume's centre, 7.5 cm above the aim
    assert pivot is not None
    assert np.linalg.norm(pivot - subject) <= max(aim_off_m, 1e-4)  # (the damping: 5 um towards the anchor)
    half = interpolate_camera(a, b, 0.5, pivot=pivot)
    assert np.linalg.norm(half.center - subject) == pytest.approx(3.0, abs=0.03)
    uv, depth = half.project(subject[None], distort=False)
    assert depth[0] > 2.9 and np.all(np.abs(uv[0] - K[:2, 2]) < 3.0)  # the subject in the middle of the picture


def test_the_pivot_keeps_the_axes_nearest_point_where_it_is_well_conditioned():
    """Skew axes 90 degrees apart: the subject 1 m off moves the pivot by under a millimetre."""
    a = _cam("a", (-3.0, -1.2, 3.0), (0.0, -1.0, 3.0))
    b = _cam("b", (0.0, -1.4, 0.0), (0.1, -0.9, 3.0))
    np.testing.assert_allclose(subject_pivot(a, b, np.array([0.5, -0.3, 3.6])), axes_pivot(a, b), atol=1e-3)


def _toed_in(convergence_deg: float, baseline_m: float = 1.2):
    """Two cameras side by side (``baseline_m`` apart on x, 1.3 m high), each toed in by half ``convergence_deg``
    and pitched at 0.95 m high 3 m along its axis (the simulator's ``sim://?convergence=``)."""
    cams = []
    for name, sign in (("a", -1.0), ("b", 1.0)):
        eye = np.array([sign * baseline_m / 2, -1.3, 0.0])
        yaw = -sign * np.radians(convergence_deg) / 2
        target = eye + 3.0 * np.array([np.sin(yaw), 0.0, np.cos(yaw)])
        target[1] = -0.95
        cams.append(_cam(name, eye, target))
    return cams


@pytest.mark.parametrize("convergence_deg", [75.0, 90.0, 120.0])
def test_side_by_side_cameras_toed_in_past_60_degrees_orbit_the_subject_not_their_axes_crossing(convergence_deg):
    """Toed in past 60 degrees, the axes cross 1-1.6 m in front of the cameras, 2.4 m or so before a subject 3 m
    out; round that point the view swung out, 6-9 % further from the subject than the cameras (3.26 m for 3.07 at
    90 degrees, halfway). Round the subject, every view between is as far from it as the cameras and sees it as
    the slerp of how they do: in the middle of the picture halfway."""
    a, b = _toed_in(convergence_deg)
    subject = np.array([0.0, -0.95, 3.0])
    assert axes_angle_deg(a, b) > AUTO_ORBIT_MIN_ANGLE_DEG
    crossing = axes_pivot(a, b)
    assert crossing[2] < 1.1 and np.linalg.norm(crossing - subject) > 1.9  # between the cameras and the subject
    pivot = novel_pivot(a, b, "auto", subject)
    np.testing.assert_allclose(pivot, subject, atol=1e-12)
    ends = np.linalg.norm(a.center - subject)
    assert np.linalg.norm(b.center - subject) == pytest.approx(ends, abs=1e-12)
    for alpha in (0.25, 0.5, 0.75):
        cam = interpolate_camera(a, b, alpha, pivot=pivot)
        assert np.linalg.norm(cam.center - subject) == pytest.approx(ends, abs=1e-9), alpha
    half = interpolate_camera(a, b, 0.5, pivot=pivot)
    uv, depth = half.project(subject[None], distort=False)
    (uv_a,), _ = a.project(subject[None], distort=False)
    assert abs(uv_a[0] - K[0, 2]) > 20  # the rig's cameras see it well to the side (27-60 degrees)
    assert uv[0][0] == pytest.approx(K[0, 2], abs=1e-6)  # halfway: across the middle of the picture
    assert abs(uv[0][1] - K[1, 2]) <= abs(uv_a[1] - K[1, 2]) + 1e-6  # and as high as the cameras see it
    assert depth[0] > 0.99 * ends


def test_the_pivot_leaves_the_axes_crossing_for_the_subject_between_half_a_metre_and_a_metre():
    """Toed in 90 degrees (axes crossing at z 0.6 m): a subject within AXES_PIVOT_HOLD_M of the crossing leaves the
    pivot on it; from AXES_PIVOT_DROP_M on the pivot is the subject; between, it leaves the crossing at twice the
    subject's pace, so a subject walking away from the crossing moves the pivot without a jump."""
    a, b = _toed_in(90.0)
    crossing = axes_pivot(a, b)
    away = np.array([0.0, 0.0, 1.0])
    previous = None
    for off in np.linspace(0.0, 2.0, 81):  # 2.5 cm steps
        subject = crossing + off * away
        pivot = novel_pivot(a, b, "auto", subject)
        point = subject_pivot(a, b, subject)  # the crossing, damped by 0.02 % of the way to the subject
        assert np.linalg.norm(point - crossing) < 1e-3 * max(off, 1.0)
        off = np.linalg.norm(point - subject)
        if off <= AXES_PIVOT_HOLD_M:
            np.testing.assert_allclose(pivot, point, atol=1e-12)
        elif off >= AXES_PIVOT_DROP_M:
            np.testing.assert_allclose(pivot, subject, atol=1e-12)
        else:
            moved = AXES_PIVOT_DROP_M * (off - AXES_PIVOT_HOLD_M) / (AXES_PIVOT_DROP_M - AXES_PIVOT_HOLD_M)
            np.testing.assert_allclose(pivot, point + moved * (subject - point) / off, atol=1e-12)
        if previous is not None:  # 2.5 cm of the subject moves the pivot by at most 5 cm (the blend's slope)
            assert np.linalg.norm(pivot - previous) <= 0.025 * 2 + 1e-9
        previous = pivot


def test_axes_crossing_at_the_subject_keep_their_pivot_while_the_box_centre_moves_with_the_pose():
    """Cameras 90 degrees round the subject, aimed at it: a box centre moved 0.4 m (arms raised, a crouch) leaves
    the pivot where the axes cross, as before session 55."""
    subject = np.array([0.0, -0.95, 3.0])
    a, b = _around(90.0)
    for centre in (subject, subject + [0.0, -0.4, 0.0], subject + [0.25, 0.2, -0.25]):
        np.testing.assert_allclose(novel_pivot(a, b, "auto", centre), subject, atol=1e-3)


def _halfway_side(yaw_b: float, tilt: float = 0.0, roll_b: float = 0.0) -> float:
    """The z of the orbit's halfway camera between a at x = -3 and b at x = +3 round the origin, b turned by
    ``yaw_b`` (radians, about the rig's up) from facing a; both tilted ``tilt`` down; b rolled by ``roll_b``."""
    def cam(name, x, yaw, roll):
        R, _ = look_at((x, 0.0, 0.0), (0.0, 0.0, 0.0))
        c, s = np.cos(yaw), np.sin(yaw)
        R = R @ np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])  # turned about the rig's y
        ct, st = np.cos(tilt), np.sin(tilt)
        R = np.array([[1.0, 0.0, 0.0], [0.0, ct, -st], [0.0, st, ct]]) @ R  # pitched about its own x
        cr, sr = np.cos(roll), np.sin(roll)
        R = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]]) @ R  # rolled about its own axis
        return Camera(name, 128, 128, K, [], R, -R @ np.array([x, 0.0, 0.0]))

    a, b = cam("a", -3.0, 0.0, 0.0), cam("b", 3.0, yaw_b, roll_b)
    return float(interpolate_camera(a, b, 0.5, pivot=np.zeros(3)).center[2])


def test_the_view_between_cameras_a_half_turn_apart_turns_one_way_whatever_the_rounding():
    """Calibrations a hair either side of 180 degrees (and of a tenth of one) used to send the view round the
    subject's near or far side by their last digits; within HALF_TURN_BAND_DEG it is counterclockwise seen from
    above (a's right: the near side, z < 0), also for cameras tilted down at the subject. Past it, the shorter way."""
    for tilt in (0.0, np.radians(6.65)):
        for yaw in (0.0, 1e-12, -1e-12, 1e-6, -1e-6, np.radians(0.3), -np.radians(0.3)):
            assert _halfway_side(yaw, tilt) < -2.5, (tilt, yaw)
    bend = np.radians(HALF_TURN_BAND_DEG)
    assert _halfway_side(1.5 * bend) < -2.5 < 2.5 < _halfway_side(-1.5 * bend)  # b turned either way: shorter
    # b upside down: the turn's axis is horizontal (the rig's forward): one way too
    sides = {np.sign(_halfway_side(yaw, 0.0, np.pi)) for yaw in (0.0, 1e-12, -1e-12, 1e-6, -1e-6)}
    assert len(sides) == 1


# ------------------------------------------------------------------ fall-backs
def test_parallel_axes_fall_back_to_the_subject_then_to_the_line():
    a = _cam("a", (-0.5, -1.2, 0.0), (-0.5, -1.2, 3.0))
    b = _cam("b", (0.5, -1.2, 0.0), (0.5, -1.2, 3.0))  # side by side, both straight ahead
    assert axes_angle_deg(a, b) == pytest.approx(0.0, abs=1e-6) and axes_pivot(a, b) is None
    assert novel_pivot(a, b, "orbit") is None  # no subject: the line
    for alpha in (0.25, 0.5):
        np.testing.assert_allclose(interpolate_camera(a, b, alpha, pivot=None).center,
                                   (1 - alpha) * a.center + alpha * b.center)
    subject = np.array([0.0, -1.0, 3.0])
    # with the subject: on the axes' plane, between them, as far out as the subject (parallel axes fix no depth)
    np.testing.assert_allclose(novel_pivot(a, b, "orbit", subject), [0.0, -1.2, 3.0], atol=1e-4)
    # just short of parallel: without the subject, a pivot of its own far out (PARALLEL_AXES_DEG is the limit);
    # with it, still the subject's depth (the axes' nearest point is ill-conditioned along them)
    tilt = 2 * PARALLEL_AXES_DEG
    c = _cam("c", (0.5, -1.2, 0.0), (0.5 - 3.0 * np.tan(np.radians(tilt)), -1.2, 3.0))
    pivot = novel_pivot(a, c, "orbit")
    assert pivot is not None and pivot[2] == pytest.approx(1.0 / np.tan(np.radians(tilt)), rel=1e-6)
    pivot = novel_pivot(a, c, "orbit", subject)
    x_c = 0.5 - 3.0 * np.tan(np.radians(tilt))  # c's axis at the subject's depth
    np.testing.assert_allclose(pivot, [(x_c - 0.5) / 2, -1.2, 3.0], atol=1e-4)


def test_a_pivot_behind_a_camera_falls_back():
    # toed out: the axes' nearest point is behind both cameras
    a = _cam("a", (-0.5, -1.2, 0.0), (-2.0, -1.2, 3.0))
    b = _cam("b", (0.5, -1.2, 0.0), (2.0, -1.2, 3.0))
    behind = axes_pivot(a, b)
    assert behind is not None and not in_front(a, behind) and not in_front(b, behind)
    assert novel_pivot(a, b, "orbit") is None  # the line
    assert novel_pivot(a, b, "orbit", np.array([0.0, -1.0, -3.0])) is None  # the subject behind them too: the line
    subject = np.array([0.0, -1.0, 3.0])
    np.testing.assert_array_equal(novel_pivot(a, b, "orbit", subject), subject)
    # behind one camera only: b looks away from the point a's axis crosses
    c = _cam("c", (0.5, -1.2, 4.0), (0.0, -1.2, 6.0))
    cross = axes_pivot(a, c)
    assert cross is not None and not (in_front(a, cross) and in_front(c, cross))
    assert novel_pivot(a, c, "orbit") is None
    with pytest.raises(GeometryError, match="not in front"):
        interpolate_camera(a, c, 0.5, pivot=cross)


def test_an_extrapolated_distance_that_is_not_positive_is_an_error_naming_alpha():
    a, b = _facing(1.0, 3.0)
    assert interpolate_camera(a, b, -0.4, pivot=np.zeros(3)) is not None  # 1.4 * 1 - 0.4 * 3 = 0.2 m
    with pytest.raises(GeometryError, match="alpha -1"):
        interpolate_camera(a, b, -1.0, pivot=np.zeros(3))  # 2 * 1 - 3 = -1 m


# ------------------------------------------------------------------ auto and the config
def test_auto_orbits_only_past_the_threshold():
    assert AUTO_ORBIT_MIN_ANGLE_DEG == 60.0  # the figure docs/novel-view.md justifies
    narrow, wide = _around(50.0), _around(70.0)
    assert axes_angle_deg(*narrow) < AUTO_ORBIT_MIN_ANGLE_DEG < axes_angle_deg(*wide)
    assert novel_pivot(*narrow, "auto") is None and novel_pivot(*narrow, "orbit") is not None
    assert novel_pivot(*wide, "auto") is not None
    assert novel_pivot(*wide, "line") is None


def test_auto_keeps_the_line_for_the_rigs_of_the_documented_figures():
    """docs/examples/rig.json, the simulator's default rig and the widest ``RigPlacement.random`` rig (1.8 m
    baseline at 2.2 m): their novel-view figures were measured on the line."""
    sim = pytest.importorskip("drivers.sim")
    widest = sim.RigPlacement(baseline_m=1.8, distance_m=2.2, camera_height_m=0.8, target_height_m=0.8,
                              volume_depth_m=1.0).build()
    for rig in (load_rig(REPO / "docs" / "examples" / "rig.json"), sim.RigPlacement().build(), widest):
        assert axes_angle_deg(*rig.pair) < 45.0
        assert novel_pivot(*rig.pair, "auto", rig.volume.min_corner / 2 + rig.volume.max_corner / 2) is None
    assert NovelViewConfig().path == "auto"


def test_the_path_is_validated_naming_the_field():
    for path in ("line", "orbit", "auto"):
        assert NovelViewConfig(path=path).path == path
    with pytest.raises(ConfigError, match="path.*'arc'"):
        NovelViewConfig(path="arc")
    with pytest.raises(ConfigError, match=r"^novel_view\.path"):
        config_from_dict({"novel_view": {"path": "Orbit"}})
    with pytest.raises(ConfigError, match=r"novel_view\.path"):
        config_from_dict({"novel_view": {"path": None}})
    with pytest.raises(ConfigError, match=r"^novel_view\.path"):
        novel_pivot(*_facing(), "circle")
    line = EstimatorConfig(novel_view=NovelViewConfig(path="line"))
    assert config_from_dict({"novel_view": {"path": "line"}}) == line


def test_docstring_examples():
    import doctest

    import ghnerf_runtime.geometry.orbit as module

    result = doctest.testmod(module)
    assert result.attempted >= 4 and result.failed == 0, result
