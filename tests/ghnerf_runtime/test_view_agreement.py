"""The two views' agreement before the reprojection gate (``joints3d.triangulate_joints_checked``,
``PairResult.reprojection_px_median``) and the lower triangulated foot (``PairResult.lowest_foot_m``):
what tells the daemon that a camera moved since calibration (docs/calibration.md, "When the rig no longer fits")."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks.measure_calibration_drift import turned
from ghnerf_runtime.body25 import FEET, FLOOR_JOINTS, JOINT_INDEX
from ghnerf_runtime.config import Joints3DConfig
from ghnerf_runtime.geometry import Camera, look_at
from ghnerf_runtime.geometry.triangulation import triangulate_two_views
from ghnerf_runtime.joints3d import Joints3D, lower_foot_m, lowest_height_m, triangulate_joints, \
    triangulate_joints_checked
from tests.ghnerf_runtime.sim_takes import shipped_model_take

REPO = Path(__file__).resolve().parents[2]
MODELS = REPO / "models"
K = [[100.0, 0, 63.5], [0, 100.0, 63.5], [0, 0, 1]]


def _cams() -> list[Camera]:
    return [Camera(n, 128, 128, K, [], *look_at((x, -1.0, 0), (0, -1.0, 3))) for n, x in (("a", -0.5), ("b", 0.5))]


def _joints(n: int = 12) -> np.ndarray:
    rng = np.random.default_rng(3)
    return np.column_stack([rng.uniform(-0.3, 0.3, n), rng.uniform(-1.8, 0.0, n), rng.uniform(2.8, 3.2, n)])


def _views(cams, X):
    return np.stack([c.project(X)[0] for c in cams])


def _tilted(cams: list[Camera], degrees: float) -> list[Camera]:
    a = np.radians(degrees)
    Rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    b = cams[1]
    return [cams[0], Camera(b.name, b.width, b.height, b.K, b.dist, Rx @ b.R, Rx @ b.t)]


def test_the_error_of_joints_the_gate_drops_is_still_measured():
    """A camera tilted 3 degrees puts every joint past a 2 px gate: no joint is reported, but the views'
    disagreement is (only the reported joints, the gate's survivors, would never show more than the gate)."""
    cams, X = _cams(), _joints()
    uv, conf, ok = _views(cams, X), np.full((2, len(X)), 0.9), np.ones((2, len(X)), bool)
    cfg = Joints3DConfig(max_reprojection_px=2.0)
    joints, agreement = triangulate_joints_checked(uv, conf, ok, _tilted(cams, 3.0), cfg)
    assert not joints.valid.any()
    assert agreement.joints == len(X) and agreement.gated == len(X)
    assert agreement.median_px > 2.0
    fit, true = triangulate_joints_checked(uv, conf, ok, cams, cfg)
    assert fit.valid.all() and true.median_px < 1e-6 and true.gated == 0


def test_the_error_grows_with_the_tilt():
    cams, X = _cams(), _joints()
    uv, conf, ok = _views(cams, X), np.full((2, len(X)), 0.9), np.ones((2, len(X)), bool)
    medians = [triangulate_joints_checked(uv, conf, ok, _tilted(cams, d), Joints3DConfig())[1].median_px
               for d in (0.0, 0.5, 1.0, 2.0)]
    assert medians == sorted(medians) and medians[0] < 1e-6 and medians[-1] > 1.5


def test_only_joints_strong_in_both_views_are_measured_and_too_few_say_nothing():
    cams, X = _cams(), _joints(8)
    uv, ok = _views(cams, X), np.ones((2, 8), bool)
    conf = np.full((2, 8), 0.9)
    conf[1, :5] = 0.2  # weak in the second view: an empty room's phantom peaks are so
    _, agreement = triangulate_joints_checked(uv, conf, ok, _tilted(cams, 2.0), Joints3DConfig(), 0.35, 3)
    assert agreement.joints == 3 and agreement.median_px is not None
    _, few = triangulate_joints_checked(uv, conf, ok, _tilted(cams, 2.0), Joints3DConfig(), 0.35, 4)
    assert few.joints == 3 and few.median_px is None


def test_the_joints_are_the_gated_solver_s():
    """The gate applied after the solve keeps triangulate_joints' joints as the solver's own gate made them."""
    cams, X = _cams(), _joints(20)
    uv = _views(cams, X) + np.random.default_rng(5).normal(0, 1.0, (2, 20, 2))
    uv[1, ::3, 1] += 20.0  # off their epipolar lines: past the gate
    conf, ok = np.full((2, 20), 0.8), np.ones((2, 20), bool)
    cfg = Joints3DConfig()
    got = triangulate_joints(uv, conf, ok, cams, cfg)
    ref = triangulate_two_views(uv, np.stack([c.P for c in cams]), conf, max_reprojection_error=cfg.max_reprojection_px,
                                min_ray_angle_deg=cfg.min_ray_angle_deg)
    assert 0 < ref.valid.sum() < 20
    np.testing.assert_array_equal(got.valid, ref.valid)
    np.testing.assert_allclose(got.points, ref.points)
    np.testing.assert_allclose(got.reprojection_px, ref.reprojection_error)


@pytest.mark.skipif(not (MODELS / "model_card.json").is_file(), reason="no trained model: models/model_card.json")
def test_the_shipped_model_s_pairs_tell_a_tilted_rig_file_from_the_true_one():
    """The simulator films through the true rig; the estimator given the rig with its second camera tilted 2
    degrees finds joints still (the gate lets them through), but its pairs' agreement says the rig moved."""
    from ghnerf_runtime.estimator import Estimator

    cfg, session, rig, shots = shipped_model_take((0.0, 0.1, 0.2, 0.3))
    medians = {}
    for name, r in (("true", rig), ("tilted", turned(rig, 1, "tilt", 2.0))):
        with Estimator(session, r, cfg) as est:
            results = [est.estimate(images, timestamp_s=0.1 * k) for k, images in enumerate(shots)]
        assert all(res.reprojection_px_median is not None for res in results)
        assert all(res.to_json()["reprojection_px_median"] == round(res.reprojection_px_median, 3) for res in results)
        medians[name] = float(np.median([res.reprojection_px_median for res in results]))
        assert np.mean([res.num_found for res in results]) > 15  # silently wrong, not missing
    assert medians["true"] < 0.5 < 1.5 < medians["tilted"], medians


def test_the_lowest_foot_is_the_largest_y_of_the_foot_joints_found():
    points = np.zeros((25, 3))
    points[:, 1] = -1.0  # the rig frame: y down, the floor at y = 0
    points[JOINT_INDEX["LHeel"], 1], points[JOINT_INDEX["RBigToe"], 1] = 0.03, -0.05
    points[JOINT_INDEX["Nose"], 1] = 0.5  # lower than any foot, but no foot joint
    valid = np.ones(25, bool)
    j3 = Joints3D(points, np.ones(25, np.float32), valid, np.zeros((25, 2)))
    assert lowest_height_m(j3, FLOOR_JOINTS) == pytest.approx(-0.03)  # 3 cm below the floor
    valid[JOINT_INDEX["LHeel"]] = False
    assert lowest_height_m(Joints3D(points, np.ones(25, np.float32), valid, np.zeros((25, 2))), FLOOR_JOINTS) == pytest.approx(0.05)
    valid[list(FLOOR_JOINTS)] = False
    assert lowest_height_m(Joints3D(points, np.ones(25, np.float32), valid, np.zeros((25, 2))), FLOOR_JOINTS) is None


def test_the_lower_foot_is_the_median_of_its_joints_and_a_lone_joint_is_no_foot():
    """The floor check's figure since session 56: per foot the median height of its joints (two at least), less
    their median on a foot flat on the floor; the lower foot's. One noisy joint far below the floor moves the
    lowest joint, not the median of three; a foot lifted or seen by one joint only is not measured."""
    points = np.zeros((25, 3))
    points[:, 1] = -1.0
    for name, h in (("RAnkle", 0.075), ("RBigToe", 0.04), ("RSmallToe", 0.04), ("RHeel", 0.02)):
        points[JOINT_INDEX[name], 1] = -h  # flat on the floor: y down
    points[JOINT_INDEX["RHeel"], 1] = 0.12  # one noisy joint 12 cm below the floor
    for name in ("LAnkle", "LBigToe", "LSmallToe", "LHeel"):
        points[JOINT_INDEX[name], 1] = -0.3  # lifted
    valid = np.ones(25, bool)
    j3 = lambda v: Joints3D(points, np.ones(25, np.float32), v, np.zeros((25, 2)))  # noqa: E731
    assert lower_foot_m(j3(valid), FEET, 0.04) == pytest.approx(0.0)  # the right foot's median: 0.04
    assert lowest_height_m(j3(valid), FLOOR_JOINTS) == pytest.approx(-0.12)  # what the figure was before
    valid[[JOINT_INDEX[n] for n in ("RAnkle", "RBigToe", "RSmallToe")]] = False  # the right foot: the heel alone
    assert lower_foot_m(j3(valid), FEET, 0.04) == pytest.approx(0.26)  # the lifted left foot, not a lone joint
    valid[[JOINT_INDEX[n] for n in ("LAnkle", "LBigToe", "LSmallToe")]] = False
    assert lower_foot_m(j3(valid), FEET, 0.04) is None


@pytest.mark.skipif(not (MODELS / "model_card.json").is_file(), reason="no trained model: models/model_card.json")
def test_a_one_degree_pan_is_flagged_within_the_window_and_the_true_rig_is_not():
    """The daemon's floor check on a simulated take through the shipped model: with the second camera's rig entry
    panned 1 degree, or the first camera's -1 degree, the median over ``calibration_window`` (30) pairs of
    ``lowest_foot_m`` is past ``calibration_max_floor_m`` (0.05 m) by the window's last pair (0.09 and 0.08 m below
    the floor); through the true rig it is not (0.01 m below). Before session 56 the figure was the lowest foot joint,
    against 0.1 m: on this take 0.03 m above the floor through the true rig, 0.05 and 0.04 m below for these pans,
    under the limit. (The pans the other way read 0.045 and 0.05 m above the floor here, at the limit: a 1 degree
    pan is caught in most placements, not all: docs/calibration.md, "The feet on the floor".)"""
    from firmware_host.daemon.calibration_watch import FloorWatch
    from firmware_host.daemon.config import CALIBRATION_MAX_FLOOR_M, CALIBRATION_WINDOW
    from ghnerf_runtime.estimator import Estimator

    cfg, session, rig, shots = shipped_model_take([0.1 * k for k in range(CALIBRATION_WINDOW)])
    for camera, degrees in ((1, 0.0), (1, 1.0), (0, -1.0)):
        watch = FloorWatch(CALIBRATION_WINDOW, CALIBRATION_MAX_FLOOR_M)
        with Estimator(session, turned(rig, camera, "pan", degrees), cfg) as est:
            feet = [est.estimate(images, timestamp_s=0.1 * k).lowest_foot_m for k, images in enumerate(shots)]
        for foot in feet:
            watch.add(foot)
        assert len(watch.values) == CALIBRATION_WINDOW, feet  # every pair measured its feet: one window
        assert watch.suspect is (degrees != 0), (camera, degrees, watch.median)


@pytest.mark.skipif(not (MODELS / "model_card.json").is_file(), reason="no trained model: models/model_card.json")
def test_the_shipped_model_s_triangulated_feet_tell_a_panned_rig_file_and_cut_feet_say_nothing():
    """Through the true rig the lower triangulated foot stands on the floor; with the second camera's rig entry
    panned 2 degrees the views still meet (reprojection_px_median as low) but the feet sink 0.08 m or more below
    it, or float as far above it panned the other way. The reported joints are the skeleton prior's, whose feet stay
    near the floor whatever the calibration: the figure is the triangulation's. Frames that cut the feet off
    (the model puts their peaks at the frame's edge, up to 0.8 m above the floor) give no figure."""
    from ghnerf_runtime.estimator import Estimator
    from ghnerf_runtime.geometry import Rig

    cfg, session, rig, shots = shipped_model_take((0.0, 0.1, 0.2, 0.3))
    feet, reported, px = {}, {}, {}
    for name, r in (("true", rig), ("pan", turned(rig, 1, "pan", 2.0)), ("pan back", turned(rig, 1, "pan", -2.0))):
        with Estimator(session, r, cfg) as est:
            results = [est.estimate(images, timestamp_s=0.1 * k) for k, images in enumerate(shots)]
        assert all(res.lowest_foot_m is not None for res in results)
        feet[name] = float(np.median([res.lowest_foot_m for res in results]))
        px[name] = float(np.median([res.reprojection_px_median for res in results]))
        reported[name] = float(np.median([-res.joints_3d[[j for j in FLOOR_JOINTS if not res.missing[j]], 1].max()
                                          for res in results]))
    assert abs(feet["true"]) < 0.05 and feet["pan"] < -0.08 and feet["pan back"] > 0.08, feet
    assert px["pan"] < 0.5 and px["pan back"] < 0.5, px  # the views still meet: the px check is blind to it
    assert abs(reported["pan"]) < 0.05, reported  # the prior's feet hide the pan
    for keep in (0.7, 0.6):  # the lower 30 or 40 % of each frame gone: the feet just out of view, or far
        rows = int(keep * rig.pair[0].height)
        cams = tuple(type(c)(c.name, c.width, rows, c.K, c.dist, c.R, c.t) for c in rig.cameras)
        with Estimator(session, Rig(cams, rig.volume, rig.rig_id), cfg) as est:
            results = [est.estimate([np.ascontiguousarray(im[:rows]) for im in images], timestamp_s=0.1 * k)
                       for k, images in enumerate(shots)]
        assert all(res.num_found > 10 for res in results)  # someone is there, feet placed by the prior or not
        assert all(res.lowest_foot_m is None for res in results), (keep, [res.lowest_foot_m for res in results])
