"""Triangulation, kornia-style: smoke, shapes, exceptions, accuracy, degenerate cases, solver agreement."""
from __future__ import annotations

import itertools

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ghnerf_runtime.errors import GeometryError, ShapeError
from ghnerf_runtime.geometry.camera import Camera, look_at
from ghnerf_runtime.geometry.triangulation import (
    MIN_BLOCK_VOLUME,
    TriangulationResult,
    TwoViewCameras,
    block_volume,
    check_two_views,
    solve_two_views,
    triangulate_dlt,
    triangulate_midpoint,
    triangulate_robust,
    triangulate_two_views,
)

K = np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]])
DIST = np.array([-0.18, 0.04, 0.0006, -0.0009, -0.003])
TARGET = np.array([0.0, -1.0, 3.0])


def generate_scene(num_cameras=2, num_joints=25, *, dist=None, seed=0, spread=1.0):
    """Cameras on an arc about 1.4 m high looking at a person-sized box around TARGET."""
    rng = np.random.default_rng(seed)
    cams = []
    for i, x in enumerate(np.linspace(-spread, spread, num_cameras)):
        eye = (x, -1.4 + 0.05 * i, 0.3 * abs(x))
        R, t = look_at(eye, TARGET)
        cams.append(Camera(f"c{i}", 640, 480, K, np.zeros(5) if dist is None else dist, R, t))
    points = TARGET + rng.uniform([-0.5, -0.8, -0.4], [0.5, 0.8, 0.4], size=(num_joints, 3))
    uv = np.stack([c.project(points)[0] for c in cams])  # (C, J, 2)
    return cams, points, uv


def assert_finite(res: TriangulationResult):
    for name in ("points", "reprojection_error", "ray_angle_deg"):
        assert np.all(np.isfinite(getattr(res, name))), name


# ----------------------------------------------------------------------------- smoke / shapes
@pytest.mark.parametrize("solver", [triangulate_dlt, triangulate_midpoint, triangulate_robust])
@pytest.mark.parametrize("num_cameras", [2, 3, 4])
def test_smoke(solver, num_cameras):
    cams, points, uv = generate_scene(num_cameras, 7)
    res = solver(uv, cams)
    assert res.points.shape == (7, 3) and res.points.dtype == np.float64
    assert res.reprojection_error.shape == (7, num_cameras)
    assert res.ray_angle_deg.shape == res.num_views.shape == res.valid.shape == (7,)
    assert res.used.shape == (7, num_cameras)
    assert res.valid.dtype == bool and np.issubdtype(res.num_views.dtype, np.integer)
    assert np.all(res.valid) and np.all(res.num_views == num_cameras)
    assert res.conditioning is res.ray_angle_deg


def test_batch_dims_and_float32():
    cams, points, uv = generate_scene(3, 5)
    uv_b = np.stack([uv, uv + 0.0])[None]  # (1, 2, C, J, 2)
    w = np.ones((1, 2, 3, 5))
    res = triangulate_dlt(uv_b.astype(np.float32), cams, w)
    assert res.points.shape == (1, 2, 5, 3) and res.reprojection_error.shape == (1, 2, 5, 3)
    np.testing.assert_allclose(res.points[0, 1], points, atol=2e-4)  # float32 pixel rounding
    single = triangulate_dlt(uv, cams)
    np.testing.assert_allclose(triangulate_dlt(uv_b, cams).points[0, 0], single.points, atol=1e-12)


def test_zero_joints():
    cams, _, uv = generate_scene(2, 3)
    res = triangulate_dlt(uv[:, :0], cams)
    assert res.points.shape == (0, 3) and res.valid.shape == (0,)


@pytest.mark.parametrize(
    "uv_shape, weights_shape, match",
    [
        ((2, 5), None, r"uv must have shape \(\.\.\., C, J, 2\)"),
        ((2, 5, 3), None, r"uv must have shape"),
        ((3, 5, 2), None, "3 cameras on axis -3 but 2 cameras"),
        ((2, 5, 2), (3, 5), "weights must broadcast"),
    ],
)
def test_shape_errors(uv_shape, weights_shape, match):
    cams, _, _ = generate_scene(2, 5)
    weights = None if weights_shape is None else np.ones(weights_shape)
    with pytest.raises(ShapeError, match=match):
        triangulate_dlt(np.zeros(uv_shape), cams, weights)


def test_camera_argument_errors():
    cams, _, uv = generate_scene(2, 5)
    with pytest.raises(ShapeError, match="one Camera"):
        triangulate_dlt(uv, cams[0])
    with pytest.raises(ShapeError, match="must not be empty"):
        triangulate_dlt(np.zeros((0, 5, 2)), [])
    with pytest.raises(ShapeError, match=r"\(C, 3, 4\)"):
        triangulate_dlt(uv, np.zeros((2, 3, 3)))
    with pytest.raises(ShapeError, match=r"cameras\[1\] projection matrix must have shape"):
        triangulate_dlt(uv, [cams[0].P, np.eye(3)])
    with pytest.raises(GeometryError, match=r"cameras\[1\].*finite"):
        triangulate_dlt(uv, [cams[0].P, np.full((3, 4), np.nan)])
    with pytest.raises(GeometryError, match=r"cameras\[0\].*singular"):
        triangulate_dlt(uv, [np.zeros((3, 4)), cams[1].P])
    with pytest.raises(GeometryError, match="no lens model"):
        triangulate_dlt(uv, [c.P for c in cams], undistorted=False)
    with pytest.raises(GeometryError, match="max_reprojection_error"):
        triangulate_robust(uv, cams, max_reprojection_error=0.0)


# ----------------------------------------------------------------------------- accuracy
@pytest.mark.parametrize("num_cameras", [2, 3, 5])
def test_noise_free_exact(num_cameras):
    cams, points, uv = generate_scene(num_cameras, 25)
    res = triangulate_dlt(uv, cams)
    np.testing.assert_allclose(res.points, points, atol=1e-9)
    assert res.reprojection_error.max() < 1e-8
    assert np.all(res.valid)


def test_noise_free_with_distortion():
    cams, points, uv = generate_scene(3, 25, dist=DIST)
    res = triangulate_dlt(uv, cams)  # distorted pixels, undistorted internally
    np.testing.assert_allclose(res.points, points, atol=1e-9)
    assert res.reprojection_error.max() < 1e-8
    # Ignoring the lens is measurably wrong: the test would catch a skipped undistortion.
    wrong = triangulate_dlt(uv, cams, undistorted=True)
    assert np.abs(wrong.points - points).max() > 1e-3


def test_pre_undistorted_pixels_and_projection_matrices():
    cams, points, uv = generate_scene(3, 25, dist=DIST)
    ideal = np.stack([c.undistort_pixels(uv[i]) for i, c in enumerate(cams)])
    res = triangulate_dlt(ideal, cams, undistorted=True)
    np.testing.assert_allclose(res.points, points, atol=1e-9)
    P = np.stack([c.P for c in cams])
    for cams_arg in (P, list(P)):
        np.testing.assert_allclose(triangulate_dlt(ideal, cams_arg).points, points, atol=1e-9)
    # Mixed: with undistorted=None the Camera entry would take distorted pixels.
    mixed = [cams[0], P[1], P[2]]
    np.testing.assert_allclose(triangulate_dlt(ideal, mixed, undistorted=True).points, points, atol=1e-9)
    uv_mixed = np.stack([uv[0], ideal[1], ideal[2]])
    np.testing.assert_allclose(triangulate_dlt(uv_mixed, mixed).points, points, atol=1e-9)
    # Projection matrices with arbitrary scale and sign give the same answer.
    res_s = triangulate_dlt(ideal, P * np.array([-3.0, 0.01, 7.0])[:, None, None])
    np.testing.assert_allclose(res_s.points, points, atol=1e-9)
    assert np.all(res_s.valid)


def test_agrees_with_cv2_triangulate_points():
    cams, points, uv = generate_scene(2, 25)
    rng = np.random.default_rng(3)
    noisy = uv + rng.normal(0, 0.7, uv.shape)
    X = cv2.triangulatePoints(cams[0].P, cams[1].P, noisy[0].T.copy(), noisy[1].T.copy())
    ours = triangulate_dlt(noisy, cams)
    # Different (but both linear) normalisations: agreement to well under the noise effect.
    np.testing.assert_allclose(ours.points, (X[:3] / X[3]).T, atol=3e-4)


def test_noisy_observations_bounded():
    cams, points, uv = generate_scene(2, 25, seed=1)
    rng = np.random.default_rng(1)
    sigma = 0.5
    res = triangulate_dlt(uv + rng.normal(0, sigma, uv.shape), cams)
    assert np.all(res.valid)
    err = np.linalg.norm(res.points - points, axis=-1)
    # Baseline 2 m at about 3 m with f = 600: depth error ~ sigma * Z^2 / (f * B) ~ 4 mm.
    assert np.median(err) < 0.006 and err.max() < 0.02
    assert res.mean_reprojection_error().max() < 4 * sigma


def test_noisy_more_views_help():
    errs = []
    for C in (2, 5):
        cams, points, uv = generate_scene(C, 200, seed=2)
        rng = np.random.default_rng(2)
        res = triangulate_dlt(uv + rng.normal(0, 1.0, uv.shape), cams)
        errs.append(np.sqrt(np.mean(np.sum((res.points - points) ** 2, -1))))
    assert errs[1] < errs[0]


def test_ray_angle_is_the_angle_at_the_point():
    cams, points, uv = generate_scene(2, 25)
    res = triangulate_dlt(uv, cams)
    a, b = points - cams[0].center, points - cams[1].center
    cos = np.abs(np.einsum("ij,ij->i", a, b)) / np.linalg.norm(a, axis=-1) / np.linalg.norm(b, axis=-1)
    np.testing.assert_allclose(res.ray_angle_deg, np.degrees(np.arccos(cos)), atol=1e-6)


# ----------------------------------------------------------------------------- weights
def test_weights_ignore_and_scale():
    cams, points, uv = generate_scene(3, 10)
    bad = uv.copy()
    bad[1, 4] += [30.0, 40.0]  # wrong detection, 50 px off
    w = np.ones((3, 10))
    w[1, 4] = 0.0
    res = triangulate_dlt(bad, cams, w)
    np.testing.assert_allclose(res.points, points, atol=1e-9)
    assert res.num_views[4] == 2 and not res.used[4, 1]
    assert res.reprojection_error[4, 1] == pytest.approx(50.0, abs=1e-6)  # reported though unused
    # A uniform weight scale changes nothing; NaN weight is "ignore".
    np.testing.assert_allclose(triangulate_dlt(uv, cams, np.full((3, 10), 0.3)).points, points, atol=1e-9)
    w[1, 4] = np.nan
    np.testing.assert_allclose(triangulate_dlt(bad, cams, w).points, points, atol=1e-9)
    # A small weight pulls the point less than a full one.
    w[1, 4] = 0.05
    low = triangulate_dlt(bad, cams, w).points[4]
    full = triangulate_dlt(bad, cams).points[4]
    assert np.linalg.norm(low - points[4]) < 0.3 * np.linalg.norm(full - points[4])


def test_weights_broadcast():
    cams, points, uv = generate_scene(2, 6)
    res = triangulate_dlt(uv, cams, np.array([1.0, 0.5])[:, None])
    np.testing.assert_allclose(res.points, points, atol=1e-9)


# ----------------------------------------------------------------------------- degenerate cases
@pytest.mark.parametrize("solver", [triangulate_dlt, triangulate_midpoint, triangulate_robust])
def test_degenerate_cases_are_invalid_and_finite(solver):
    cams, points, uv = generate_scene(2, 6)
    uv = uv.copy()
    w = np.ones((2, 6))
    uv[0, 0] = np.nan  # one view left
    w[1, 1] = 0.0  # one view left
    uv[:, 2] = np.nan  # no views
    uv[1, 3, 0] = np.inf
    uv[0, 4] = [1e300, -1e300]  # absurd but finite
    res = solver(uv, cams, w)
    assert_finite(res)
    assert res.valid[:4].tolist() == [False, False, False, False] and res.valid[5]
    assert res.num_views.tolist() == [1, 1, 0, 1, 2, 2]
    assert np.all(res.points[~res.valid] == 0.0)
    assert np.all(res.reprojection_error[~res.valid] == 0.0)
    np.testing.assert_allclose(res.points[5], points[5], atol=1e-9)


@pytest.mark.parametrize("solver", [triangulate_dlt, triangulate_midpoint])
def test_parallel_rays(solver):
    # Two cameras with the same orientation seeing a point at the same normalised
    # coordinates: the rays are parallel (the point is at infinity).
    cams = [Camera("a", 640, 480, K, t=[0.5, 0, 0]), Camera("b", 640, 480, K, t=[-0.5, 0, 0])]
    uv = np.array([[[400.0, 250.0]], [[400.0, 250.0]]])
    res = solver(uv, cams)
    assert not res.valid[0] and res.ray_angle_deg[0] == pytest.approx(0.0, abs=1e-9)
    assert_finite(res)
    # Nearly parallel (far point): below the threshold -> invalid; raising the threshold matters.
    uv2 = uv.copy()
    uv2[1, 0, 0] -= 0.5  # 0.5 px disparity, 1 m baseline -> 1200 m away, 0.05 deg
    res2 = solver(uv2, cams)
    assert not res2.valid[0] and 0 < res2.ray_angle_deg[0] < 0.1
    assert solver(uv2, cams, min_ray_angle_deg=0.01).valid[0]


@pytest.mark.parametrize("solver", [triangulate_dlt, triangulate_midpoint])
def test_point_behind_cameras(solver):
    cams, _, _ = generate_scene(2, 1)
    behind = np.array([[0.2, -1.2, -3.0]])  # behind both cameras (they look towards +z)
    uv = []
    for c in cams:  # project ignoring cheirality, as a bad matcher might "see" it
        ph = np.c_[behind, np.ones(1)] @ c.P.T
        uv.append(ph[:, :2] / ph[:, 2:])
    res = solver(np.stack(uv), cams, undistorted=True)
    assert not res.valid[0]
    assert_finite(res)


def test_coincident_centres_invalid():
    R, _ = look_at((0, -1, 0), (0.2, -1, 3))
    cams = [Camera("a", 640, 480, K, R=np.eye(3), t=[0, 1, 0]), Camera("b", 640, 480, K, R=R, t=-R @ [0, -1, 0])]
    uv = np.array([[[300.0, 200.0]], [[330.0, 210.0]]])
    res = triangulate_dlt(uv, cams)
    assert not res.valid[0]
    assert_finite(res)


def test_single_camera():
    cams, _, uv = generate_scene(2, 4)
    res = triangulate_dlt(uv[:1], cams[:1])
    assert not np.any(res.valid) and np.all(res.num_views == 1)
    assert_finite(res)


# ----------------------------------------------------------------------------- solver agreement
def test_dlt_and_midpoint_agree():
    cams, points, uv = generate_scene(2, 25)
    np.testing.assert_allclose(triangulate_midpoint(uv, cams).points, points, atol=1e-9)
    rng = np.random.default_rng(5)
    noisy = uv + rng.normal(0, 0.5, uv.shape)
    dlt, mid = triangulate_dlt(noisy, cams), triangulate_midpoint(noisy, cams)
    assert np.all(dlt.valid & mid.valid)
    np.testing.assert_allclose(dlt.points, mid.points, atol=1e-3)
    np.testing.assert_allclose(dlt.ray_angle_deg, mid.ray_angle_deg, atol=1e-12)


@pytest.mark.parametrize("target", [(0.3, -0.2, 50.0), (35.0, -20.0, 30.0), (-40.0, 5.0, -30.0)])
def test_midpoint_is_exact_for_near_parallel_rays(target):
    """Noise-free, a 1 mm baseline, a point 50 m away (rays 0.001 deg apart, under a min_ray_angle_deg of 0): the
    DLT was exact and the midpoint 38 um off (I - d d^T kept float64's 1e-16 of |d| != 1 along the ray, and its
    diagonal cancelled). Looking along z and obliquely (the mean-ray frame is not the camera's)."""
    target = np.array([target])
    R, t = look_at((0.0, 1.5, 0.0), target[0])
    offset = R.T @ [0.0005, 0.0, 0.0]  # along the cameras' own x axis
    cams = [Camera(n, 640, 480, K, R=R, t=-R @ (np.array([0.0, 1.5, 0.0]) + s * offset))
            for n, s in (("l", 1), ("r", -1))]
    uv = np.stack([c.project(target)[0] for c in cams])
    mid, dlt = triangulate_midpoint(uv, cams, min_ray_angle_deg=0), triangulate_dlt(uv, cams, min_ray_angle_deg=0)
    assert mid.valid[0] and dlt.valid[0] and mid.ray_angle_deg[0] < 0.002
    np.testing.assert_allclose(dlt.points, target, atol=1e-8)
    np.testing.assert_allclose(mid.points, target, atol=1e-8)


def test_midpoint_two_views_is_midpoint_of_common_perpendicular():
    cams, _, uv = generate_scene(2, 3)
    noisy = uv + np.array([[[3.0, -2.0]], [[-4.0, 1.0]]])
    res = triangulate_midpoint(noisy, cams)
    (o1, d1), (o2, d2) = cams[0].rays(noisy[0]), cams[1].rays(noisy[1])
    for j in range(3):
        # Closest points o1 + s d1, o2 + u d2: solve the 2x2 normal equations.
        A = np.array([[d1[j] @ d1[j], -d1[j] @ d2[j]], [d1[j] @ d2[j], -d2[j] @ d2[j]]])
        b = np.array([(o2[j] - o1[j]) @ d1[j], (o2[j] - o1[j]) @ d2[j]])
        s, u = np.linalg.solve(A, b)
        np.testing.assert_allclose(res.points[j], 0.5 * (o1[j] + s * d1[j] + o2[j] + u * d2[j]), atol=1e-9)


# ----------------------------------------------------------------------------- robust
def test_robust_drops_the_bad_view():
    cams, points, uv = generate_scene(4, 25, dist=DIST)
    bad = uv.copy()
    bad[2, 3] += [35.0, -20.0]
    bad[0, 7] += [-60.0, 10.0]
    res = triangulate_robust(bad, cams, max_reprojection_error=3.0)
    assert np.all(res.valid)
    np.testing.assert_allclose(res.points, points, atol=1e-8)
    assert not res.used[3, 2] and not res.used[7, 0] and res.used.sum() == 4 * 25 - 2
    # Plain DLT is pulled off by the outliers.
    assert np.linalg.norm(triangulate_dlt(bad, cams).points[3] - points[3]) > 1e-3


def test_robust_two_bad_views_of_five():
    cams, points, uv = generate_scene(5, 4)
    bad = uv.copy()
    bad[1, 2] += 40.0
    bad[3, 2] -= 30.0
    res = triangulate_robust(bad, cams, max_reprojection_error=2.0)
    assert res.valid[2] and res.num_views[2] == 3
    np.testing.assert_allclose(res.points[2], points[2], atol=1e-8)


def test_robust_two_views_that_disagree_are_invalid():
    cams, points, uv = generate_scene(2, 3)
    bad = uv.copy()
    bad[1, 1, 1] += 30.0  # vertical offset: violates the epipolar constraint
    res = triangulate_robust(bad, cams, max_reprojection_error=3.0)
    assert res.valid.tolist() == [True, False, True]
    assert_finite(res)


def test_robust_clean_data_unchanged():
    cams, _, uv = generate_scene(3, 10)
    rng = np.random.default_rng(0)
    noisy = uv + rng.normal(0, 0.3, uv.shape)
    np.testing.assert_allclose(triangulate_robust(noisy, cams).points, triangulate_dlt(noisy, cams).points)


# ----------------------------------------------------------------------------- property tests
rig_strategy = st.fixed_dictionaries(
    {
        "C": st.integers(2, 4),
        "eyes": st.lists(st.tuples(st.floats(-2, 2), st.floats(-2.2, -0.3), st.floats(-1.0, 1.0)), min_size=4, max_size=4),
        "f": st.floats(300, 1500),
        "k1": st.floats(-0.25, 0.1),
        "seed": st.integers(0, 2**16),
    }
)


def random_rig(p):
    cams = []
    for i in range(p["C"]):
        eye = np.array(p["eyes"][i]) + [0.25 * i, 0, 0]  # keep centres apart
        R, t = look_at(eye, TARGET)
        Ki = np.array([[p["f"], 0, 320], [0, p["f"] * 1.001, 240], [0, 0, 1]])
        cams.append(Camera(f"c{i}", 640, 480, Ki, [p["k1"], 0.01, 0, 0, 0], R, t))
    rng = np.random.default_rng(p["seed"])
    points = TARGET + rng.uniform(-0.6, 0.6, size=(8, 3))
    uv = np.stack([c.project(points)[0] for c in cams])
    return cams, points, uv


@settings(max_examples=40, deadline=None)
@given(rig_strategy)
def test_random_rigs_recover_points(p):
    cams, points, uv = random_rig(p)
    res = triangulate_dlt(uv, cams)
    ok = res.ray_angle_deg > 1.0  # generated eyes can be close; well-conditioned joints must be exact
    assert np.all(res.valid[ok])
    np.testing.assert_allclose(res.points[ok], points[ok], atol=1e-7)
    mid = triangulate_midpoint(uv, cams)
    np.testing.assert_allclose(mid.points[ok], points[ok], atol=1e-7)


@settings(max_examples=40, deadline=None)
@given(
    rig_strategy,
    st.lists(st.sampled_from([1.0, 0.0, 0.5, np.nan, np.inf, -1.0]), min_size=32, max_size=32),
    st.lists(st.sampled_from(["ok", "nan", "inf", "huge"]), min_size=32, max_size=32),
)
def test_outputs_always_finite(p, weights, corruption):
    cams, points, uv = random_rig(p)
    C, J = uv.shape[:2]
    w = np.array(weights[: C * J]).reshape(C, J) if C * J <= 32 else np.ones((C, J))
    uv = uv.copy()
    for k, kind in enumerate(corruption[: C * J]):
        c, j = divmod(k, J)
        if kind != "ok":
            uv[c, j] = {"nan": np.nan, "inf": np.inf, "huge": 1e200}[kind]
    for solver in (triangulate_dlt, triangulate_midpoint, triangulate_robust):
        res = solver(uv, cams, w)
        assert_finite(res)
        assert np.all(res.points[~res.valid] == 0)
        assert np.all(res.num_views[res.valid] >= 2)


_FIELDS = ("points", "reprojection_error", "ray_angle_deg", "num_views", "valid", "used")


def _two_view_case(p, weights, corruption):
    """A random two-camera pinhole rig (pixels already undistorted), noisy and corrupted."""
    cams, points, _ = random_rig(dict(p, C=2))
    pin = [c.without_distortion() for c in cams]
    rng = np.random.default_rng(p["seed"])
    uv = np.stack([c.project(points)[0] for c in pin]) + rng.normal(0, 3.0, (2, 8, 2))
    w = np.array(weights[:16]).reshape(2, 8)
    for k, kind in enumerate(corruption[:16]):
        if kind != "ok":
            uv[divmod(k, 8)] = {"nan": np.nan, "inf": np.inf, "huge": 1e200}[kind]
    return np.stack([c.P for c in pin]), uv, w


@settings(max_examples=60, deadline=None)
@given(
    rig_strategy,
    st.lists(st.sampled_from([1.0, 0.0, 0.5, 0.05, np.nan, np.inf, -1.0]), min_size=16, max_size=16),
    st.lists(st.sampled_from(["ok", "ok", "ok", "nan", "inf", "huge"]), min_size=16, max_size=16),
    st.sampled_from([None, 2.0, 6.0]),
)
def test_two_view_solver_equals_the_general_ones(p, weights, corruption, max_err):
    """The estimator's lean two-view path gives exactly what triangulate_dlt / _robust give."""
    P, uv, w = _two_view_case(p, weights, corruption)
    fast = triangulate_two_views(uv, P, w, max_reprojection_error=max_err)
    if max_err is None:
        ref = triangulate_dlt(uv, list(P), w, undistorted=True)
    else:
        ref = triangulate_robust(uv, list(P), w, undistorted=True, max_reprojection_error=max_err)
    assert_finite(fast)
    for name in _FIELDS:
        np.testing.assert_allclose(getattr(fast, name), getattr(ref, name), rtol=1e-7, atol=1e-9, err_msg=name)


def test_two_view_solver_is_exact_and_checks_its_arguments():
    cams, points, uv = generate_scene(2)
    P = np.stack([c.P for c in cams])
    res = triangulate_two_views(uv, P, np.ones((2, 25)))
    assert res.valid.all() and res.reprojection_error.max() < 1e-6
    np.testing.assert_allclose(res.points, points, atol=1e-9)
    with pytest.raises(ShapeError, match="uv"):
        triangulate_two_views(uv[:, :, :1], P, np.ones((2, 25)))
    with pytest.raises(ShapeError):
        triangulate_two_views(uv, P[:, :2], np.ones((2, 25)))
    singular = P.copy()
    singular[1, :, :3] = 0.0
    with pytest.raises(GeometryError, match=r"P\[1\] \(view 1\) projection matrix has a singular left 3x3 block"):
        triangulate_two_views(uv, singular, np.ones((2, 25)))


def test_docstring_examples():
    import doctest

    import ghnerf_runtime.geometry.triangulation as module

    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted >= 10 and result.failed == 0


def test_overflowing_weights_or_pixels_return_invalid_joints_instead_of_hanging():
    """Finite inputs whose DLT rows overflow (weights near the float maximum, pixels of 1e10 or 1e308): an inf
    in LAPACK's SVD can loop forever, so those joints must come back invalid, at once. Run in a subprocess
    so that a regression fails the test instead of hanging the suite."""
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent("""
        import numpy as np
        from ghnerf_runtime.geometry import Camera, look_at
        from ghnerf_runtime.geometry.triangulation import triangulate_dlt, triangulate_two_views
        K = [[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]]
        cams = [Camera(n, 640, 480, K, [], *look_at((x, -1.0, 0), (0, -1.0, 3))) for n, x in (("a", -0.5), ("b", 0.5))]
        P = np.stack([c.P for c in cams])
        good = np.stack([c.project(np.array([[0.1, -1.2, 3.0]]))[0] for c in cams])
        uv = np.concatenate([good, [[[1e10, 0.0]], [[320.0, 240.0]]], [[[1e308, 0.0]], [[320.0, 240.0]]]], axis=1)
        for w in (1.0, 1e300, np.finfo(float).max):
            W = np.full((2, 3), w)
            for f in (triangulate_dlt, triangulate_two_views):
                r = f(uv, P, W)
                assert np.isfinite(r.points).all(), (f.__name__, w, r.points)
                assert r.valid[0] and np.abs(r.points[0] - [0.1, -1.2, 3.0]).max() < 1e-6, (f.__name__, w, r)
                assert not r.valid[1:].any(), (f.__name__, w, r.valid)
        print("ok")
    """)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stdout + done.stderr


def test_extreme_weights_keep_the_solution_or_drop_the_view():
    """Weights are relative: equal huge or denormal ones change nothing (the midpoint's system overflowed to an
    invalid joint, and underflowed to LinAlgError); a view whose share underflows to 0 is not used (a joint of
    weights 1e308 and 1e-308 was valid from one ray, at an arbitrary depth); one with all but none of the say
    leaves the midpoint's system singular: invalid, not LinAlgError."""
    cams, points, uv = generate_scene(2, 4)
    P = np.stack([c.P for c in cams])
    w = np.array([[1e308, 5e-324, 1e308, 1.0], [1e308, 5e-324, 1e-308, 1e-300]])
    for solver in (triangulate_dlt, triangulate_midpoint, triangulate_robust):
        res = solver(uv, cams, w)
        assert res.valid[:2].all(), solver.__name__
        np.testing.assert_allclose(res.points[:2], points[:2], atol=1e-6)
        assert res.num_views[2] == 1 and not res.valid[2] and not res.used[2, 1], solver.__name__
    fast = triangulate_two_views(uv, P, w)
    assert fast.valid.tolist()[:3] == [True, True, False] and fast.num_views[2] == 1
    assert not triangulate_midpoint(uv, cams, w).valid[3]


@pytest.mark.parametrize("bad", [np.nan, -1.0, 91.0, "0.1"])
def test_thresholds_out_of_range_are_refused_by_name(bad):
    """A NaN min_ray_angle_deg made every joint invalid and a NaN max_reprojection_error of the two-view solver
    gated nothing, silently."""
    cams, _, uv = generate_scene(2, 3)
    P = np.stack([c.P for c in cams])
    for call in (lambda: triangulate_dlt(uv, cams, min_ray_angle_deg=bad),
                 lambda: triangulate_midpoint(uv, cams, min_ray_angle_deg=bad),
                 lambda: triangulate_robust(uv, cams, min_ray_angle_deg=bad),
                 lambda: triangulate_two_views(uv, P, np.ones((2, 3)), min_ray_angle_deg=bad)):
        with pytest.raises(GeometryError, match="min_ray_angle_deg"):
            call()
    if bad != 91.0:
        with pytest.raises(GeometryError, match="max_reprojection_error"):
            triangulate_two_views(uv, P, np.ones((2, 3)), max_reprojection_error=bad)


def test_a_view_that_cannot_see_the_point_past_its_lens_fold_is_not_counted_as_agreeing():
    """The middle camera's lens model folds at r = 0.874; the joint lies at r = 1.1 in it, where the model
    mirrors it onto pixel (626.5, 212.1). A (weak) detection there reprojected with error 0: the plain DLT
    called the joint valid with three agreeing views and the robust solver kept the view. Now the view that
    cannot see the point makes the DLT joint invalid (as a used camera behind the point does), and the
    robust solver drops that view instead of losing the joint."""
    cams = []
    for i, x in enumerate((-1.0, 0.0, 1.0)):
        R, t = look_at((x, -1.4 + 0.05 * i, 0.3 * abs(x)), TARGET)
        cams.append(Camera(f"c{i}", 640, 480, K, [-0.5, 0.05, 0.0, 0.0, 0.0] if i == 1 else np.zeros(5), R, t))
    mid = cams[1]
    assert mid.fold_radius == pytest.approx(0.874, abs=2e-3)
    points = np.array([mid.center + mid.R.T @ (np.array([1.1, -0.1, 1.0]) * 2.5), TARGET])
    uv = np.stack([c.project(points)[0] for c in cams])
    assert np.all(np.isnan(uv[1, 0])) and np.all(np.isfinite(np.delete(uv, 1, axis=0)))
    uv[1, 0] = mid.normalized_to_pixels(np.array([1.1, -0.1]))  # the mirrored pixel, inside the image
    assert np.all((uv[1, 0] > 0) & (uv[1, 0] < [640, 480]))
    w = np.array([[1.0, 1.0], [1e-3, 1.0], [1.0, 1.0]])
    dlt = triangulate_dlt(uv, cams, w)
    assert dlt.valid.tolist() == [False, True] and dlt.used[0].all()
    assert_finite(dlt)
    robust = triangulate_robust(uv, cams, w, max_reprojection_error=3.0)
    assert robust.valid.all() and robust.used[0].tolist() == [True, False, True] and robust.used[1].all()
    np.testing.assert_allclose(robust.points, points, atol=1e-9)
    assert robust.reprojection_error[0, 1] == 0.0  # not computed: that camera cannot see the point


def _two_views(uv, cams, **kw):
    return triangulate_two_views(uv, np.stack([c.P for c in cams]), np.ones(uv.shape[:2]), **kw)


@pytest.mark.parametrize("solver", [triangulate_dlt, triangulate_midpoint, triangulate_robust, _two_views])
def test_one_centre_or_one_line_is_invalid_even_with_no_angle_threshold(solver):
    """``min_ray_angle_deg=0`` (the config accepts it) let through what no angle can: two cameras at one centre,
    whose rays (1e-6 or 1e-3 px apart) meet only at that centre, came back valid micrometres in front of it;
    the same pixel through both, or a point on the line through two centres, valid anywhere on that line."""
    R, t = look_at((0.3, -1.0, 0.1), (0.0, -1.0, 4.0))
    same = [Camera("a", 640, 480, K, np.zeros(5), R, t), Camera("b", 640, 480, K, np.zeros(5), R, t)]
    uv = np.array([[[300.0, 200.0], [300.0, 200.0], [400.0, 300.0], [300.0, 200.0]],
                   [[300.0, 200.0], [300.0 + 1e-6, 200.0], [400.0 + 1e-3, 300.0], [300.0 + 1e-3, 200.0]]])
    res = solver(uv, same, min_ray_angle_deg=0.0)
    assert not res.valid.any() and not res.points.any()
    assert_finite(res)
    # distinct centres, the joint on the line through them: both rays are that line
    c1, c2 = np.array([-0.2, -1.0, 0.0]), np.array([0.1, -1.1, 0.5])
    cams = [Camera(n, 640, 480, K, np.zeros(5), *look_at(c, c1 + 4 * (c2 - c1) + [0.2, 0.1, 0.0]))
            for n, c in (("a", c1), ("b", c2))]
    X = c1 + np.array([[3.0], [6.0]]) * (c2 - c1)
    uv = np.stack([c.project(X)[0] for c in cams])
    assert np.isfinite(uv).all()
    res = solver(uv, cams, min_ray_angle_deg=0.0)
    assert not res.valid.any() and not res.points.any()
    # a real angle that small is kept: 1 mm of baseline, 1 km away (5.7e-5 degrees), noise-free
    far = [Camera(n, 640, 480, K, np.zeros(5), *look_at((x, -1.0, 0.0), (0.0, -1.0, 1000.0)))
           for n, x in (("a", -5e-4), ("b", 5e-4))]
    X = np.array([[0.05, -1.02, 1000.0]])
    res = solver(np.stack([c.project(X)[0] for c in far]), far, min_ray_angle_deg=0.0)
    assert res.valid.all() and 0 < res.ray_angle_deg[0] < 1e-4
    np.testing.assert_allclose(res.points, X, rtol=1e-3)


def test_one_centre_among_more_views_takes_the_other_centre_s_view():
    """A third view from a distinct centre restores depth: a joint is valid when two of its used views have
    distinct centres, whatever the others share."""
    cams, points, uv = generate_scene(2, 4)
    twin = Camera("twin", 640, 480, K, np.zeros(5), cams[0].R, cams[0].t)
    uv3 = np.concatenate([uv, uv[:1]])
    w = np.ones((3, 4))
    w[1, 2:] = 0.0  # joints 2, 3: only the two views from one centre
    res = triangulate_dlt(uv3, [cams[0], cams[1], twin], w, min_ray_angle_deg=0.0)
    assert res.valid.tolist() == [True, True, False, False]
    np.testing.assert_allclose(res.points[:2], points[:2], atol=1e-9)


@pytest.mark.parametrize("fx, size, shift", [(1e4, (8000, 6000), 0.0), (1e5, (8000, 6000), 0.0), (5.0, (8, 6), 0.0),
                                             (0.5, (4, 3), 0.0), (600.0, (640, 480), 1e5)])
def test_extreme_intrinsics_keep_float64_precision_for_float32_or_int_pixels(fx, size, shift):
    """The solvers work in float64 on conditioned pixels (principal point and focal length from the camera):
    a focal length of 1e5 px, a 4x3 image or a principal point 1e5 px off (a far crop) lose nothing; float32
    input costs only its own rounding (1e-7 relative of the pixel, about 1e-6 m here), not the solve's."""
    W, H = size
    Kx = np.array([[fx, 0.0, (W - 1) / 2 - shift], [0.0, fx, (H - 1) / 2 + shift], [0.0, 0.0, 1.0]])
    cams = [Camera(n, W, H, Kx, np.zeros(5), *look_at((x, -1.0, 0.0), TARGET)) for n, x in (("a", -0.15), ("b", 0.15))]
    points = TARGET + np.random.default_rng(3).uniform(-0.3, 0.3, size=(25, 3))
    uv = np.stack([c.project(points)[0] for c in cams])
    for solver in (triangulate_dlt, _two_views):
        np.testing.assert_allclose(solver(uv, cams).points, points, atol=1e-9)
        single = solver(uv.astype(np.float32), cams)
        assert single.valid.all() and single.points.dtype == np.float64
        # the error float32 pixels carry: their rounding, magnified by depth / (focal length * sin(angle))
        pixel_rounding = np.abs(uv.astype(np.float32).astype(np.float64) - uv).max()
        bound = 10 * pixel_rounding * 3.0 / (fx * np.sin(np.radians(single.ray_angle_deg.min()))) + 1e-12
        assert np.abs(single.points - points).max() < bound


def _same_results(got: TriangulationResult, want: TriangulationResult, context="") -> None:
    for name in _FIELDS:
        assert np.array_equal(getattr(got, name), getattr(want, name)), (context, name)
        assert getattr(got, name).dtype == getattr(want, name).dtype, (context, name)


def test_two_view_terms_given_or_not_the_answers_are_the_same_to_the_bit(monkeypatch):
    """The estimator triangulates with one pair of crop cameras twice a pair (the joints, the prior's inputs), and a
    tracked crop keeps its cameras: their terms (inverses, conditioning, centres), computed once by
    TwoViewCameras.from_P, give the answers computed on the spot, on other points and weights too; without them,
    every call computes them (no state kept between calls)."""
    from ghnerf_runtime.geometry import triangulation

    cams, _, uv = generate_scene(2, seed=3)
    P = np.stack([c.P for c in cams])
    rng = np.random.default_rng(0)
    cases = [(uv + rng.normal(0, s, uv.shape), rng.uniform(0.05, 1.0, (2, 25))) for s in (0.0, 0.5, 4.0)]
    calls = []
    real = triangulation._conditioning_similarity
    monkeypatch.setattr(triangulation, "_conditioning_similarity", lambda p: calls.append(1) or real(p))
    fresh = [triangulate_two_views(u, P, w, max_reprojection_error=3.0) for u, w in cases]
    assert len(calls) == len(cases)
    calls.clear()
    terms = TwoViewCameras.from_P(P)
    for (u, w), want in zip(cases, fresh):
        got = triangulate_two_views(u, P.copy(), w, max_reprojection_error=3.0, cameras=terms)  # the same matrices
        _same_results(got, want)
    assert len(calls) == 1


def test_two_view_terms_are_those_of_the_matrices_not_of_the_array():
    """The terms keep a copy of the matrices: a caller's array changed in place after from_P is other cameras, and
    terms of other matrices are refused by name; a singular pair is refused every time."""
    cams, _, uv = generate_scene(2, seed=4)
    P = np.stack([c.P for c in cams])
    terms = TwoViewCameras.from_P(P)
    assert terms.is_for(P) and terms.is_for(P.tolist()) and not terms.P.flags.writeable
    P[:, 0, 3] += 60.0  # both cameras moved 0.1 m along their x axis (f = 600 px)
    assert not terms.is_for(P)
    with pytest.raises(GeometryError, match="other matrices"):
        triangulate_two_views(uv, P, np.ones((2, 25)), cameras=terms)
    _same_results(triangulate_two_views(uv, P, np.ones((2, 25)), cameras=TwoViewCameras.from_P(P)),
                  triangulate_two_views(uv, P, np.ones((2, 25))))
    singular = P.copy()
    singular[1, :, :3] = 0.0
    for _ in range(2):
        with pytest.raises(GeometryError, match=r"P\[1\] \(view 1\) projection matrix has a singular left 3x3 block"):
            triangulate_two_views(uv, singular, np.ones((2, 25)))
    with pytest.raises(ShapeError, match=r"\(2, 3, 4\)"):
        TwoViewCameras.from_P(P[:1])


def _two_view_thresholds_case():
    cams, _, uv = generate_scene(2, seed=5)
    P = np.stack([c.P for c in cams])
    uv = uv + np.random.default_rng(2).normal(0, 0.3, uv.shape)
    w = np.full((2, 25), 0.7)
    angles = triangulate_two_views(uv, P, w, min_ray_angle_deg=0.0).ray_angle_deg
    return uv, P, w, (0.0, float(np.median(angles)), float(angles.max()) + 1.0)  # all joints, about half, none


def test_one_solve_checked_at_several_thresholds_answers_as_fresh_solves(monkeypatch):
    """The estimator solves one pair's peaks once (solve_two_views) and checks the solve for the joints
    (joints3d.min_ray_angle_deg) and for the prior's inputs (the default): the DLT runs once, each check's
    threshold is its own, and each result is its own writable arrays, equal to the bit to a fresh solve's."""
    uv, P, w, thresholds = _two_view_thresholds_case()
    fresh = {angle: triangulate_two_views(uv, P, w, min_ray_angle_deg=angle) for angle in thresholds}
    calls = []
    real = np.linalg.svd
    monkeypatch.setattr(np.linalg, "svd", lambda *a, **k: calls.append(1) or real(*a, **k))
    solution = solve_two_views(uv, P, w)
    got = {angle: check_two_views(solution, min_ray_angle_deg=angle) for angle in thresholds}
    again = triangulate_two_views(uv.copy(), P.copy(), w.copy(), min_ray_angle_deg=thresholds[1], solution=solution)
    assert len(calls) == 1
    assert [int(got[a].valid.sum()) for a in thresholds] == [25, 13, 0]  # each call's own threshold
    _same_results(again, fresh[thresholds[1]])
    for angle, res in got.items():
        _same_results(res, fresh[angle], angle)
        for name in _FIELDS:
            getattr(res, name).flags.writeable = True  # (raises on a read-only array)
    got[thresholds[0]].ray_angle_deg[:] = -1.0  # a caller's change reaches no later answer
    assert np.array_equal(check_two_views(solution, min_ray_angle_deg=thresholds[1]).ray_angle_deg,
                          fresh[thresholds[1]].ray_angle_deg)
    uv[0, 0, 0] += 1.0  # and the solve keeps its own copy of the inputs: the caller's later change is other peaks
    assert not solution.solves(uv, P, w)


def test_a_solve_of_other_inputs_is_not_reused_and_no_call_reuses_another_s(monkeypatch):
    """A solve passed for other peaks, weights or matrices is solved afresh (the answer is the inputs' own), and
    the same inputs twice without a solve passed are solved twice: the module keeps no last solve."""
    uv, P, w, thresholds = _two_view_thresholds_case()
    solution = solve_two_views(uv, P, w)
    other_w = w.copy()
    other_w[1, 3] = 0.0  # the prior's inputs' weights differ from the joints' where a peak is weak
    other_uv = uv.copy()
    other_uv[0, 0, 0] += 0.25
    other_P = P.copy()
    other_P[0, 0, 3] += 1.0
    calls = []
    real = np.linalg.svd
    monkeypatch.setattr(np.linalg, "svd", lambda *a, **k: calls.append(1) or real(*a, **k))
    for u, p, weights in ((uv, P, other_w), (other_uv, P, w), (uv, other_P, w)):
        assert not solution.solves(u, p, weights)
        calls.clear()
        got = triangulate_two_views(u, p, weights, solution=solution)
        assert len(calls) == 1
        _same_results(got, triangulate_two_views(u, p, weights))
    calls.clear()
    for _ in range(2):
        triangulate_two_views(uv, P, w)
    assert len(calls) == 2


def test_every_two_view_camera_term_is_read_by_the_solve_or_the_check():
    """TwoViewCameras keeps what the solve and the check read, nothing else (its determinants were kept and never
    read: their sign is in depth_scale)."""
    import dataclasses
    import inspect
    import re

    from ghnerf_runtime.geometry import triangulation

    readers = "".join(inspect.getsource(f) for f in (triangulation._solve_two_views, triangulation.check_two_views,
                                                     TwoViewCameras.is_for))
    unread = [f.name for f in dataclasses.fields(TwoViewCameras)
              if not re.search(rf"\b(?:cams|self)\.{f.name}\b", readers)]
    assert not unread, unread


@pytest.mark.parametrize("focal_px", [1e-3, 1.0, 500.0, 1e5, 1e7])
def test_extreme_rigs_give_finite_answers_and_valid_joints_only_where_the_geometry_fixes_them(focal_px):
    """Property sweep at the extremes: focal lengths 1e-3..1e7 px, principal points up to 1e7 px outside a
    640x480 image, baselines 1e-9..10 m, points 1e-3..1e4 m away (near-parallel rays included). Every solver
    answers finitely; a joint it calls valid is where the noise-free rays meet, to rounding magnified by the
    rays' angle (the pixels' rounding, 1e-16 of a pixel 1e7 px off centre, is 1e-6 focal lengths of 1e-3 px);
    the estimator's two-view solver on the projection matrices equals the general DLT on them, or every solver
    refuses those cameras by name, Camera objects and matrices alike (GeometryError: a left 3x3 block singular
    to rounding, block_volume: a focal length of 1e-3 px 1e7 px off centre)."""
    rng = np.random.default_rng(int(focal_px * 1000) % 2**32)
    for shift in (0.0, 1e4, 1e7):
        K_ = np.array([[focal_px, 0.0, 320.0 + shift], [0.0, focal_px, 240.0 - shift], [0.0, 0.0, 1.0]])
        for baseline in (1e-9, 1e-4, 0.1, 10.0):
            for distance in (1e-3, 1.0, 1e4):
                aim = np.array([0.0, 0.0, distance])
                cams = [Camera(n, 640, 480, K_, np.zeros(5), *look_at((x, 0.0, 0.0), aim))
                        for n, x in (("a", -baseline / 2), ("b", baseline / 2))]
                points = aim + rng.uniform(-0.3, 0.3, (25, 3)) * distance
                uv = np.stack([c.project(points, distort=False)[0] for c in cams])
                case = (focal_px, shift, baseline, distance)
                P = np.stack([c.P for c in cams])
                if not np.all(block_volume(P) > MIN_BLOCK_VOLUME):  # 1e-3 px 1e7 px off centre: rounding
                    v = int(np.argmin(block_volume(P) > MIN_BLOCK_VOLUME))  # the first view refused
                    for solve in (triangulate_dlt, triangulate_midpoint, triangulate_robust):
                        with pytest.raises(GeometryError, match=rf"cameras\[{v}\] .* has a singular left 3x3 block"):
                            solve(uv, cams)
                    with pytest.raises(GeometryError, match=rf"P\[{v}\] \(view {v}\) projection matrix has a singular"):
                        triangulate_two_views(uv, P, np.ones((2, 25)))
                    continue
                for res in (triangulate_dlt(uv, cams), triangulate_midpoint(uv, cams),
                            triangulate_robust(uv, cams, max_reprojection_error=5.0)):
                    assert_finite(res)
                    ok = res.valid
                    if baseline < 1e-3 * distance:  # rays under 0.1 degrees apart: no depth, whatever they say
                        assert not ok.any(), case
                    error = np.linalg.norm(res.points[ok] - points[ok], axis=-1) / np.linalg.norm(points[ok], axis=-1)
                    # the pixels' own rounding (eps * |uv|, in focal lengths) and the solve's, over the rays' angle
                    rounding = np.finfo(float).eps * np.abs(uv).max() / focal_px + 1e-12
                    assert np.all(error <= 1e3 * rounding / np.sin(np.radians(res.ray_angle_deg[ok]))), case
                fast = triangulate_two_views(uv, P, np.ones((2, 25)))
                assert_finite(fast)
                ref = triangulate_dlt(uv, list(P), undistorted=True)
                assert np.array_equal(fast.valid, ref.valid), case
                np.testing.assert_allclose(fast.points, ref.points, rtol=1e-7, atol=1e-9 * distance, err_msg=str(case))


@pytest.mark.parametrize("dist", [[0.0, 0.0, 0.3, 0.0], [0.1, 0.01, 0.3, -0.3, 0.01]])
def test_a_lens_folded_by_its_tangential_terms_gives_no_valid_joint_off_its_point(dist):
    """Distortion within the rig file's bound whose tangential terms fold the lens model inside its radial fold:
    a point on the folded side was projected, undistorted to another point's ray, and triangulated valid and up to
    a metre off (its reprojection error under a pixel). Now its pixel is NaN: the joint is missing or exact."""
    Kw = np.array([[320.0, 0.0, 319.5], [0.0, 320.0, 239.5], [0.0, 0.0, 1.0]])
    cams = [Camera(n, 640, 480, Kw, dist, *look_at((x, -1.0, 0.0), TARGET)) for n, x in (("a", -0.2), ("b", 0.2))]
    points = TARGET + np.random.default_rng(8).uniform([-2.5, -2.0, -1.0], [2.5, 2.0, 1.0], size=(200, 3))
    uv = np.stack([c.project(points)[0] for c in cams])
    for res in (triangulate_dlt(uv, cams), triangulate_robust(uv, cams, max_reprojection_error=2.0)):
        assert res.valid.sum() > 20
        np.testing.assert_allclose(res.points[res.valid], points[res.valid], atol=1e-6)


@pytest.mark.parametrize("fx, fy", [(10.0, 10.0), (1e6, 1e6), (10.0, 1e6), (1e6, 10.0)])
@pytest.mark.parametrize("shift", [0.0, 1e5, 1e7])
def test_every_camera_accepts_from_10_px_to_1e6_px_is_solved_from_its_matrices_too(fx, fy, shift):
    """The matrices' singularity check is scale-invariant (block_volume): a Camera 10 px or 1e6 px long, with
    pixels 1e5 times taller than wide, or its principal point 1e7 px outside the image, was refused as 'singular'
    by TwoViewCameras.from_P and the general solvers' matrix path (|det M| <= 1e-12 |M|^3), while the solvers took
    the Camera itself. Now both paths solve it, to the same points: on 1x1 to 20000x20000 px images, baselines of
    1 mm to 100 m, points 1 cm to 1 km away."""
    rng = np.random.default_rng(3)
    for (W, H), (baseline, distance) in itertools.product([(1, 1), (640, 480), (20000, 20000)],
                                                          [(1e-3, 0.01), (0.2, 3.0), (100.0, 1000.0)]):
        K_ = np.array([[fx, 0.0, (W - 1) / 2 + shift], [0.0, fy, (H - 1) / 2 - shift], [0.0, 0.0, 1.0]])
        aim = np.array([0.0, 0.0, distance])
        cams = [Camera(n, W, H, K_, np.zeros(5), *look_at((x, 0.0, 0.0), aim)) for n, x in
                (("a", -baseline / 2), ("b", baseline / 2))]
        points = aim + rng.uniform(-0.1, 0.1, (25, 3)) * distance
        uv = np.stack([c.project(points, distort=False)[0] for c in cams])
        P = np.stack([c.P for c in cams])
        case = (W, baseline, distance)
        assert np.all(block_volume(P) > MIN_BLOCK_VOLUME), case
        fast = triangulate_two_views(uv, P, np.ones((2, 25)))
        general = triangulate_dlt(uv, list(P), undistorted=True)
        of_cameras = triangulate_dlt(uv, cams)
        for res in (fast, general, of_cameras):
            assert res.valid.all(), case
            np.testing.assert_allclose(res.points, points, rtol=0, atol=1e-4 * distance, err_msg=str(case))
        np.testing.assert_allclose(fast.points, general.points, rtol=1e-9, atol=1e-12, err_msg=str(case))


@pytest.mark.parametrize("scale", [1e-8, 1.0, 1e8])
def test_a_singular_block_is_refused_at_any_scale(scale):
    """Truly degenerate matrices are still refused by both paths, by name: a zero block, a zero third row (a camera
    at infinity), two parallel rows, and a third row that is the first over a focal length (rank 2: its conditioned
    row is rounding; np.linalg.inv raised a bare LinAlgError on it before)."""
    P = np.stack([c.P for c in generate_scene(2, 1)[0]]) * scale
    bad = []
    for change in ("zero", "row3", "parallel", "rank2"):
        Q = P.copy()
        if change == "zero":
            Q[1, :, :3] = 0.0
        elif change == "row3":
            Q[1, 2, :3] = 0.0
        elif change == "parallel":
            Q[1, 1, :3] = Q[1, 0, :3] * (1 + 1e-14)
        else:
            Q[1, 2, :3] = Q[1, 0, :3] / 600.0
        bad.append(Q)
    for Q in bad:
        assert not block_volume(Q)[1] > MIN_BLOCK_VOLUME
        with pytest.raises(GeometryError, match=r"P\[1\] \(view 1\) projection matrix has a singular left 3x3 block "
                                                r"\(camera at infinity\): its conditioned rows span a volume of"):
            TwoViewCameras.from_P(Q)
        with pytest.raises(GeometryError, match=r"cameras\[1\] projection matrix has a singular left 3x3 block"):
            triangulate_dlt(np.full((2, 1, 2), 300.0), list(Q), undistorted=True)


@pytest.mark.parametrize("fx, skew, cx", [(1e-20, 0.0, 320.0), (500.0, 0.0, 1e300), (500.0, 1e20, 320.0)])
def test_a_camera_whose_matrix_is_singular_to_rounding_is_refused_by_name(fx, skew, cx):
    """Camera takes any finite K with fx, fy > 0, so its P can lose the focal length to rounding (1e-20 px beside a
    principal point at 320 px, or a principal point at 1e300 px) or have its pixel axes nearly parallel (a skew of
    1e20): the general solvers took the Camera unchecked and np.linalg.inv raised a bare LinAlgError (or every joint
    came back invalid), while the same matrices were refused by name. Now every solver refuses the camera, by name."""
    K_ = np.array([[fx, skew, cx], [0.0, fx, 240.0], [0.0, 0.0, 1.0]])
    cams = [Camera(n, 640, 480, K_, np.zeros(5), *look_at((x, 0.0, 0.0), (0.0, 0.0, 3.0))) for n, x in
            (("left", -0.1), ("right", 0.1))]
    uv = np.full((2, 3, 2), 300.0)
    for solve in (triangulate_dlt, triangulate_midpoint, triangulate_robust):
        with pytest.raises(GeometryError, match=r"cameras\[0\] \(camera 'left'\) projection matrix has a singular"):
            solve(uv, cams)
    with pytest.raises(GeometryError, match=r"P\[0\] \(view 0\) projection matrix has a singular left 3x3 block"):
        triangulate_two_views(uv, np.stack([c.P for c in cams]), np.ones((2, 3)))


@pytest.mark.parametrize("change", ["nan", "inf", "zero block", "zero third row"])
@pytest.mark.parametrize("view", [0, 1])
def test_the_two_view_terms_and_the_general_solvers_refuse_a_matrix_in_one_message(change, view):
    """TwoViewCameras.from_P repeated the general solvers' finite and block_volume check with messages of its own
    ('projection matrices must be finite with a regular left 3x3 block', naming no view when one was not finite).
    Now both run one check: the same words, the view named (P[v] there, cameras[v] here), why, and its matrix."""
    P = np.stack([c.P for c in generate_scene(2, 1)[0]])
    if change == "nan":
        P[view, 1, 3] = np.nan
    elif change == "inf":
        P[view, 0, 0] = -np.inf
    elif change == "zero block":
        P[view, :, :3] = 0.0
    else:
        P[view, 2, :3] = 0.0
    with pytest.raises(GeometryError) as two_view:
        TwoViewCameras.from_P(P)
    with pytest.raises(GeometryError) as general:
        triangulate_dlt(np.full((2, 1, 2), 300.0), list(P), undistorted=True)
    message = str(two_view.value)
    assert message == str(general.value).replace(f"cameras[{view}]", f"P[{view}] (view {view})"), message
    why = "must be finite" if change in ("nan", "inf") else "has a singular left 3x3 block"
    assert message.startswith(f"P[{view}] (view {view}) projection matrix {why}"), message
    assert message.endswith(f"got {P[view].tolist()}"), message


@pytest.mark.parametrize("origin", [0.0, 1e3, 1e5], ids=["at the origin", "1 km off", "100 km off"])
@pytest.mark.parametrize("baseline", [0.02, 0.075])
def test_a_narrow_rig_far_from_its_origin_triangulates_as_at_it(origin, baseline):
    """The DLT is conditioned in pixels, not in the rig frame: a 2 cm pair 100 km from its origin (a rig file's
    origin is a convention nothing enforces) still recovers a subject 3 m away to a micrometre (2e-7 m at
    100 km), and a subject 25 m away along the baseline, whose rays meet at 0.004 degrees, is invalid, not far off."""
    offset = np.array([origin, 0.0, origin])
    cams = [Camera(n, 640, 480, K, np.zeros(5), *look_at(offset + (x, -1.4, 0.0), offset + (0.0, -1.0, 3.0)))
            for n, x in (("a", -baseline / 2), ("b", baseline / 2))]
    P = np.stack([c.P for c in cams])
    rng = np.random.default_rng(5)
    for target, valid in (((0.0, -1.0, 3.0), True), ((25.0, -1.4, 0.5), False)):
        points = offset + target + rng.uniform(-0.3, 0.3, (25, 3))
        uv = np.stack([c.project(points, distort=False)[0] for c in cams])
        for res in (triangulate_dlt(uv, cams), triangulate_midpoint(uv, cams), triangulate_robust(uv, cams),
                    triangulate_two_views(uv, P, np.ones((2, 25)))):
            assert_finite(res)
            assert np.all(res.valid == valid), (target, res.ray_angle_deg)
            assert np.linalg.norm(res.points[res.valid] - points[res.valid], axis=-1).max(initial=0.0) < 1e-6
