"""The estimator's pure pieces: ray blocks, ROI snapping, tracks, 3D methods, novel cameras, frame check."""
from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from ghnerf_runtime.config import FrameCheckConfig, Joints3DConfig, RoiConfig, TrackingConfig
from ghnerf_runtime.errors import ConfigError, GeometryError, ShapeError
from ghnerf_runtime.estimator import check_crop, coarse_detail_share, crop_statistics
from ghnerf_runtime.geometry import Camera, look_at
from ghnerf_runtime.joints3d import depth_centroid_joints, query_grid, triangulate_joints, volumetric_joints
from ghnerf_runtime.keypoints import model_to_heatmap_pixels
from ghnerf_runtime.novel_view import interpolate_camera, slerp_rotation
from ghnerf_runtime.preprocess import Roi
from ghnerf_runtime.rays import block_ray_uv, box_block, common_blocks, scatter_block
from ghnerf_runtime.tracking import SubjectTracker, rays_in_box, snap_roi, track_from_joints

K128 = [[150.0, 0.0, 63.5], [0.0, 150.0, 63.5], [0.0, 0.0, 1.0]]
REPO = Path(__file__).resolve().parents[2]


def _cams():
    return [Camera(n, 128, 128, K128, [], *look_at((x, -1.2, 0.0), (0.0, -1.0, 3.0))) for n, x in (("a", -0.5),
                                                                                                    ("b", 0.5))]


def _joints(n=25, seed=0):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-0.3, 0.3, n), rng.uniform(-1.7, -0.2, n), rng.uniform(2.8, 3.2, n)])


# ------------------------------------------------------------------ rays
def test_blocks_share_one_size_stay_inside_and_cover_their_box():
    raw = [(3, 5, 10, 7), (0, 20, 13, 12), (25, 0, 7, 3)]
    out = common_blocks(raw, 32, 32, align=4)
    assert len({(b[2], b[3]) for b in out}) == 1 and out[0][2:] == (16, 12)
    for (r0, c0, rh, cw), orig in zip(out, raw):
        assert 0 <= r0 and r0 + rh <= 32 and 0 <= c0 and c0 + cw <= 32
        # the common block still covers the original
        assert r0 <= orig[0] and orig[0] + orig[2] <= r0 + rh and c0 <= orig[1] and orig[1] + orig[3] <= c0 + cw
    assert common_blocks([(3, 5, 10, 7), None], 32, 32) == [(0, 0, 32, 32)] * 2  # unknown: the whole grid


def test_block_rays_scatter_back_to_their_cells():
    block = (4, 6, 3, 5)
    uv = block_ray_uv(block, 4)
    assert uv.shape == (15, 2) and uv[0].tolist() == [25.5, 17.5]  # cell (4, 6) centre in model pixels
    grid = scatter_block(np.arange(15.0), block, 32, 32, fill=-1.0)
    assert grid[4, 6] == 0.0 and grid[6, 10] == 14.0 and (grid == -1.0).sum() == 32 * 32 - 15


def test_box_block_covers_the_projected_box():
    cam = _cams()[0]
    box = np.array([[-0.3, -1.8, 2.8], [0.3, -0.1, 3.2]])
    r0, c0, rh, cw = box_block(cam, box, 4, margin_cells=0)
    uv, _ = cam.project(np.array([[x, y, z] for x in box[:, 0] for y in box[:, 1] for z in box[:, 2]]))
    cells = model_to_heatmap_pixels(uv, 32, 128)
    assert cells[:, 0].min() >= c0 - 0.5 and cells[:, 0].max() <= c0 + cw - 0.5
    assert box_block(cam, box + [0, 0, -10.0], 4) is None  # behind the camera


def test_box_block_names_a_box_that_is_not_a_finite_min_max_pair():
    """A NaN corner reached ``int(np.floor(nan))``: numpy's bare "cannot convert float NaN to integer"."""
    cam = _cams()[0]
    for box in ([[np.nan, -1.0, 2.0], [0.0, 0.0, 3.0]], [[0.0, -1.0, 2.0], [np.inf, 0.0, 3.0]], [[0.0, -1.0, 2.0]]):
        with pytest.raises(ShapeError, match=r"box must be a finite \(2, 3\) array"):
            box_block(cam, np.array(box), 4)


def test_box_block_of_a_box_reaching_behind_or_off_the_image():
    cam = _cams()[0]
    centre, forward = cam.center, cam.R[2]  # the camera's position and optical axis (rig frame)
    across = np.stack([centre - 0.3 * forward - 0.2, centre + 2.0 * forward + 0.2])
    across = np.stack([across.min(axis=0), across.max(axis=0)])  # corners on both sides of the camera plane
    z = cam.to_camera(np.array([[x, y, w] for x in across[:, 0] for y in across[:, 1] for w in across[:, 2]]))[:, 2]
    assert (z <= 0).any() and (z > 0).any()
    assert box_block(cam, across, 4) == (0, 0, 32, 32)  # unbounded projection: the whole grid
    aside = centre + 3.0 * forward + 5.0 * cam.R[0]  # 3 m ahead, 5 m to the right: in front, out of view
    off = np.stack([aside - 0.2, aside + 0.2])
    assert (cam.to_camera(off)[:, 2] > 0).all()
    assert box_block(cam, off, 4) is None and box_block(cam, off, 4, margin_cells=2) is None


# ------------------------------------------------------------------ tracking
@pytest.mark.parametrize("roi", [Roi(13, -7, 101), Roi(0, 0, 64), Roi(-3, 250, 333)])
def test_snap_roi_only_grows_onto_the_grid(roi):
    s = snap_roi(roi, 8)
    assert s.x0 % 8 == 0 and s.y0 % 8 == 0 and s.size % 8 == 0
    assert s.x0 <= roi.x0 and s.y0 <= roi.y0
    assert s.x0 + s.size >= roi.x0 + roi.size and s.y0 + s.size >= roi.y0 + roi.size
    assert s.size - roi.size < 16


def test_track_needs_enough_confident_joints_and_a_plausible_box():
    cfg = TrackingConfig(min_joints=6, box_margin_m=0.2)
    j = _joints()
    conf = np.full(25, 0.9)
    valid = np.ones(25, bool)
    t = track_from_joints(j, conf, valid, cfg)
    assert t is not None and np.allclose(t.box, [j.min(0) - 0.2, j.max(0) + 0.2])
    few = valid.copy()
    few[5:] = False
    assert track_from_joints(j, conf, few, cfg) is None
    assert track_from_joints(j, np.full(25, 0.05), valid, cfg) is None  # below min_confidence
    far = j.copy()
    far[0] = [30.0, 0.0, 3.0]
    assert track_from_joints(far, conf, valid, cfg) is None  # a 30 m box is nobody


def test_a_joint_not_found_keeps_its_place_in_the_track_moved_with_the_body():
    """The crop framed the joints found alone: a hidden part (legs behind a table) shrank it to the rest, and when
    the part came back it lay outside every later crop. It is carried, moved by the body's step, while the
    track holds; found again, it is where it is found; a carried joint that would make an implausible box is not."""
    cfg = TrackingConfig(min_joints=6, box_margin_m=0.2)
    j, conf, all_ = _joints(), np.full(25, 0.9), np.ones(25, bool)
    first = track_from_joints(j, conf, all_, cfg)
    upper = all_.copy()
    upper[15:] = False  # ten joints hidden
    step = np.array([0.05, 0.0, -0.02])
    second = track_from_joints(j + step, conf, upper, cfg, previous=first)
    assert second.valid.all() and np.array_equal(second.carried, ~upper)
    np.testing.assert_allclose(second.joints, j + step)  # the hidden ones moved with the body
    np.testing.assert_allclose(second.box, [(j + step).min(0) - 0.2, (j + step).max(0) + 0.2])
    third = track_from_joints(j + 2 * step, conf, upper, cfg, previous=second)  # still hidden: still carried
    np.testing.assert_allclose(third.joints, j + 2 * step)
    back = j + 3 * step
    back[20] += 0.01
    fourth = track_from_joints(back, conf, all_, cfg, previous=third)
    assert not fourth.carried.any() and np.array_equal(fourth.joints, back)  # found again: where it is found
    # hidden inside the crop (unseen False): remembered, not carried, so the crop is what the joints found make it;
    # once its place falls outside the crop it is carried, and stays so until found
    inside = track_from_joints(j, conf, upper, cfg, previous=first, unseen=np.zeros(25, bool))
    assert np.array_equal(inside.valid, upper) and np.array_equal(inside.known, all_)
    np.testing.assert_allclose(inside.box, [j[upper].min(0) - 0.2, j[upper].max(0) + 0.2])
    outside = track_from_joints(j, conf, upper, cfg, previous=inside, unseen=~upper)
    assert outside.valid.all() and np.array_equal(outside.carried, ~upper)
    sticky = track_from_joints(j, conf, upper, cfg, previous=outside, unseen=np.zeros(25, bool))
    assert sticky.valid.all()
    with pytest.raises(ShapeError, match=r"confidence and valid must have shape \(25,\)"):
        track_from_joints(j, conf[:24], all_, cfg)  # was numpy's broadcasting ValueError
    outlier = j.copy()
    outlier[24] = [2.5, -1.0, 3.0]  # found once 2.5 m to the side (a box of 2.8 m with it)
    odd = track_from_joints(outlier, conf, all_, cfg)
    reach = j.copy()
    reach[0] = [-0.6, -1.0, 3.0]  # a hand reaches the other way: carried on, the outlier made a 3.1 m box
    moved = track_from_joints(reach, conf, upper, cfg, previous=odd)
    assert moved is not None and not moved.carried.any() and np.array_equal(moved.valid, upper)
    np.testing.assert_allclose(moved.box, [reach[upper].min(0) - 0.2, reach[upper].max(0) + 0.2])


def test_view_track_crops_one_camera_around_its_2d_joints():
    """A single-view pair's 2D joints place that camera's next crop; the other camera and the sweep box stay on
    the working volume; a 3D track, or too few confident joints, ends the view track."""
    sim = pytest.importorskip("drivers.sim")
    rig = sim.RigPlacement().build()
    tracker = SubjectTracker(rig, TrackingConfig(min_joints=6), RoiConfig())
    cold = tracker.regions()
    uv, _ = rig.pair[1].project(_joints() + [0.0, 0.0, 0.0])
    assert tracker.update_view(1, uv, np.full(25, 0.9))
    r = tracker.regions()
    assert not r.tracked and r.rois[0] == cold.rois[0] and np.array_equal(r.box, cold.box)
    assert r.rois[1].size < cold.rois[1].size
    lo, hi = rig.pair[1].undistort_pixels(uv).min(0), rig.pair[1].undistort_pixels(uv).max(0)
    assert r.rois[1].x0 <= lo[0] and r.rois[1].y0 <= lo[1]
    assert r.rois[1].x0 + r.rois[1].size >= hi[0] and r.rois[1].y0 + r.rois[1].size >= hi[1]
    assert not tracker.update_view(1, uv, np.full(25, 0.05))  # below min_confidence: cold again
    assert tracker.regions() is tracker._volume
    tracker.update_view(0, uv, np.full(25, 0.9))
    tracker.update(_joints(), np.full(25, 0.9), np.ones(25, bool))
    assert tracker.view_track is None and tracker.regions().tracked


def test_a_2d_joint_at_exactly_min_confidence_counts_for_the_view_track():
    """The 3D track counts joints with confidence >= tracking.min_confidence; the view track asked for more
    (roi_from_joints' strict >), so the same joints at exactly the threshold carried one and not the other."""
    sim = pytest.importorskip("drivers.sim")
    rig = sim.RigPlacement().build()
    cfg = TrackingConfig(min_joints=6, min_confidence=0.5)
    uv, _ = rig.pair[1].project(_joints())
    conf = np.zeros(25)
    conf[:6] = 0.5  # exactly min_joints joints, exactly at min_confidence; the rest missing
    assert track_from_joints(_joints(), conf, conf > 0, cfg) is not None
    tracker = SubjectTracker(rig, cfg, RoiConfig())
    assert tracker.update_view(1, uv, conf)
    conf[5] = np.nextafter(0.5, 0.0)  # one below: too few
    assert not tracker.update_view(1, uv, conf)


def test_rays_in_box_gives_where_each_crossing_ray_enters_and_leaves_the_box():
    """Each ray through a pixel that crosses the box in front of the camera: its entry and exit, on the ray and on
    the box's faces; a ray that misses the box gives nothing; from a camera inside the box a ray enters at its
    centre."""
    cam = _cams()[0]
    box = np.array([[-1.0, -2.0, 2.0], [1.0, 0.0, 4.0]])
    pixels = np.array([[63.5, 63.5], [20.0, 100.0], [127.0, 0.0]])
    points = rays_in_box(cam, pixels, box)
    assert points.shape == (6, 3)
    near, far = points[:3], points[3:]
    _, dirs = cam.rays(pixels)
    for p in (near, far):
        np.testing.assert_allclose(np.cross(p - cam.center, dirs), 0.0, atol=1e-9)  # on its ray
        assert (p >= box[0] - 1e-9).all() and (p <= box[1] + 1e-9).all()
        assert (np.isclose(p, box[0]) | np.isclose(p, box[1])).any(axis=1).all()  # on a face
    assert (np.einsum("ij,ij->i", far - near, dirs) > 0).all()  # entry before exit
    assert len(rays_in_box(cam, pixels, box - [0.0, 0.0, 10.0])) == 0  # the box behind the camera
    inside = rays_in_box(cam, pixels[:1], np.array([[-2.0, -3.0, -1.0], [2.0, 1.0, 4.0]]))
    np.testing.assert_allclose(inside[0], cam.center)


def test_a_person_seen_by_one_camera_only_crops_the_other_along_their_rays():
    """``update_view(other_on_rays=True)`` (both frames passed, one camera alone found the person): the other
    camera's next crop frames where the seen joints' rays cross the working volume, wherever along them the person
    stands, and not the whole volume, whose crop drew a person 4.47 m ahead on ``ghcal synth``'s rig too small to
    find (docs/rig-file.md, session 69). A rejected frame's camera (the default) stays on the volume; a 3D track, a
    reset or too few joints end it."""
    render = pytest.importorskip("calibration.render")
    rig = render.synth_rig()
    tracker = SubjectTracker(rig, TrackingConfig(min_joints=6), RoiConfig())
    cold = tracker.regions()
    far = _joints() + [-0.2, 0.0, 1.3]  # 4.1-4.5 m ahead
    uv, _ = rig.pair[0].project(far)
    assert tracker.update_view(0, uv, np.full(25, 0.9))
    assert tracker.regions().rois[1] == cold.rois[1]
    assert tracker.update_view(0, uv, np.full(25, 0.9), other_on_rays=True)
    r = tracker.regions()
    assert not r.tracked and np.array_equal(r.box, cold.box) and r.rois[0] == tracker.view_track[1]
    crop = r.rois[1]
    assert crop.size < 0.4 * cold.rois[1].size, (crop, cold.rois[1])
    eye = rig.pair[0].center
    for scale in (1.0, 0.6, 1.1):  # the same rays' points nearer or farther, inside the volume
        seen, _ = rig.pair[1].project(eye + scale * (far - eye), distort=False)
        assert (seen >= [crop.x0, crop.y0]).all() and (seen <= np.add([crop.x0, crop.y0], crop.size)).all(), scale
    assert not tracker.update_view(0, uv, np.full(25, 0.05), other_on_rays=True)
    assert tracker.view_other is None and tracker.regions() is tracker._volume
    tracker.update_view(0, uv, np.full(25, 0.9), other_on_rays=True)
    tracker.update(far, np.full(25, 0.9), np.ones(25, bool))
    assert tracker.view_other is None and tracker.regions().tracked
    tracker.update_view(0, uv, np.full(25, 0.9), other_on_rays=True)
    tracker.reset()
    assert tracker.view_other is None and tracker.regions() is tracker._volume


def test_rays_camera_names_the_camera_whose_crop_is_on_the_rays():
    """``SubjectTracker.rays_camera``: the camera whose crop in the regions given is ``view_other`` (the estimator
    judges that crop's frame by the camera's whole-volume crop when the frame check rejects it, session 70); None
    without a crop on the rays, for regions that do not hold it, and for a tracked pair's."""
    render = pytest.importorskip("calibration.render")
    rig = render.synth_rig()
    tracker = SubjectTracker(rig, TrackingConfig(min_joints=6), RoiConfig())
    uv, _ = rig.pair[1].project(_joints() + [0.0, 0.0, 1.0])
    assert tracker.rays_camera(tracker.regions()) is None
    tracker.update_view(1, uv, np.full(25, 0.9))  # a rejected frame's camera stays on the volume
    assert tracker.rays_camera(tracker.regions()) is None
    tracker.update_view(1, uv, np.full(25, 0.9), other_on_rays=True)
    regions = tracker.regions()
    assert tracker.rays_camera(regions) == 0 and regions.rois[0] == tracker.view_other
    assert tracker.rays_camera(tracker.volume_regions) is None
    assert tracker.rays_camera(dataclasses.replace(regions, tracked=True)) is None


def test_a_tracker_follows_another_trackers_track_with_its_own_crops():
    """``SubjectTracker.follow`` (``roi.turn_search`` checking another turn of a tracked person): the other
    tracker's track, its crops planned for this tracker's rolls, nothing kept of this tracker's own view track or
    last crops."""
    sim = pytest.importorskip("drivers.sim")
    rig = sim.RigPlacement().build()
    upright = SubjectTracker(rig, TrackingConfig(min_joints=6), RoiConfig())
    turned = SubjectTracker(rig, TrackingConfig(min_joints=6), RoiConfig(), (90.0, 90.0))
    assert turned.update(_joints(), np.full(25, 0.9), np.ones(25, bool))
    uv, _ = rig.pair[1].project(_joints())
    upright.update_view(1, uv, np.full(25, 0.9))
    upright.follow(turned.track)
    assert upright.track is turned.track and upright.view_track is None
    mine, theirs = upright.regions(), turned.regions()
    assert mine.tracked and np.array_equal(mine.box, theirs.box)
    fresh = SubjectTracker(rig, TrackingConfig(min_joints=6), RoiConfig())
    fresh.track = turned.track
    assert fresh.regions().rois == mine.rois  # as if the track were its own: planned for its own rolls


# ------------------------------------------------------------------ 3D methods
def test_triangulation_gates_views_that_disagree():
    cams = _cams()
    X = _joints(5)
    uv = np.stack([c.project(X)[0] for c in cams])
    # Off the epipolar line (the baseline is horizontal): the DLT splits 20 px into ~10 px per view.
    uv[1, 2] += [0.0, 20.0]
    uv[1, 3] += [9.0, 0.0]  # along the epipolar line: only depth changes, no reprojection error
    r = triangulate_joints(uv, np.full((2, 5), 0.7), np.ones((2, 5), bool), cams, Joints3DConfig())
    assert r.valid.tolist() == [True, True, False, True, True]
    ok = np.array([True, True, False, False, True])
    assert np.allclose(r.points[ok], X[ok], atol=1e-6) and not r.points[2].any()
    assert r.reprojection_px[3].max() < 1.0 and abs(r.points[3, 2] - X[3, 2]) > 0.05
    low = np.full((2, 5), 0.7)
    low[0, 0] = 0.05  # below min_view_confidence: one view only
    assert not triangulate_joints(uv, low, np.ones((2, 5), bool), cams, Joints3DConfig()).valid[0]


def test_triangulation_drops_a_joint_too_far_for_its_baseline():
    """A joint 30 m from a 10 cm baseline (rays 0.19 degrees apart) came back valid: the solvers' own gate
    (0.1 degree) only rejects the numerically degenerate, and one pixel there is metres of depth."""
    cams = [Camera(n, 128, 128, K128, [], *look_at((x, -1.2, 0.0), (0.0, -1.2, 30.0))) for n, x in (("a", -0.05),
                                                                                                     ("b", 0.05))]
    X = np.array([[0.0, -1.2, 3.0], [0.2, -1.0, 30.0]])
    uv = np.stack([c.project(X)[0] for c in cams])
    a, b = (X[1] - c.center for c in cams)
    assert round(float(np.degrees(np.arccos(a @ b / np.linalg.norm(a) / np.linalg.norm(b)))), 2) == 0.19
    conf, seen = np.full((2, 2), 0.8), np.ones((2, 2), bool)
    r = triangulate_joints(uv, conf, seen, cams, Joints3DConfig())
    assert r.valid.tolist() == [True, False]  # missing as any other: 0, confidence 0
    assert not r.points[1].any() and r.confidence[1] == 0 and np.allclose(r.points[0], X[0], atol=1e-6)
    kept = triangulate_joints(uv, conf, seen, cams, Joints3DConfig(min_ray_angle_deg=0.1))  # the old gate
    assert kept.valid.all() and np.allclose(kept.points, X, atol=1e-4)
    three = cams + [Camera("c", 128, 128, K128, [], *look_at((0.0, -1.1, 0.0), (0.0, -1.2, 30.0)))]
    uv3 = np.stack([c.project(X)[0] for c in three])  # the robust solver (more views) is gated the same way
    r3 = triangulate_joints(uv3, np.full((3, 2), 0.8), np.ones((3, 2), bool), three, Joints3DConfig())
    assert r3.valid.tolist() == [True, False]
    for bad in (-1.0, 91.0, float("nan")):
        with pytest.raises(ConfigError, match="min_ray_angle_deg"):
            Joints3DConfig(min_ray_angle_deg=bad)


def test_triangulation_with_no_angle_gate_still_gives_no_joint_from_one_centre():
    """``joints3d.min_ray_angle_deg: 0`` (accepted) turned two crop cameras at one centre into joints: the
    two-view DLT's point for rays from one centre a hair apart is that centre, or anywhere on the ray."""
    a = _cams()[0]
    twin = Camera("b", 128, 128, K128, [], a.R, a.t)
    uv = np.stack([a.project(_joints(5))[0]] * 2)
    uv[1, :3] += [1e-6, 0.0]  # a micro-pixel apart: meeting at the centre
    r = triangulate_joints(uv, np.full((2, 5), 0.8), np.ones((2, 5), bool), [a, twin],
                           Joints3DConfig(min_ray_angle_deg=0.0))
    assert not r.valid.any() and not r.points.any() and not r.confidence.any()


def test_triangulation_names_peaks_given_joints_first_or_not_numeric():
    """Peaks (J, C, 2) with a matching (J, C) confidence passed the shape check and failed inside the two-view
    solver with its own names (or, for three cameras, as 25 cameras); ragged or text peaks raised numpy's bare
    ValueError."""
    cams = _cams()
    uv = np.stack([c.project(_joints(25))[0] for c in cams])
    conf, seen = np.full((25, 2), 0.8), np.ones((25, 2), bool)
    with pytest.raises(ShapeError, match=r"uv_model has 25 views on axis 0 \(shape \(25, 2, 2\)\) but 2 cameras"):
        triangulate_joints(uv.transpose(1, 0, 2), conf, seen, cams, Joints3DConfig())
    with pytest.raises(ShapeError, match="uv must be a numeric array"):
        triangulate_joints([[[1.0, 2.0]], [[1.0, 2.0, 3.0]]], np.ones((2, 1)), np.ones((2, 1), bool), cams,
                           Joints3DConfig())
    with pytest.raises(ShapeError, match="confidence must be a numeric array"):
        triangulate_joints(uv, [["high"] * 25] * 2, seen.T, cams, Joints3DConfig())
    # int and float32 pixels are pixels: the joints of the same values in float64
    for kind in (np.float32, np.int64):
        given = np.rint(uv).astype(kind) if kind is np.int64 else uv.astype(kind)
        r = triangulate_joints(given, conf.T, seen.T, cams, Joints3DConfig())
        ref = triangulate_joints(given.astype(np.float64), conf.T, seen.T, cams, Joints3DConfig())
        assert r.valid.all() and r.points.dtype == np.float64 and np.array_equal(r.points, ref.points)


def test_the_ray_angle_gate_keeps_every_joint_of_the_example_rig():
    """The default sits below the smallest angle of a joint the estimator keeps on docs/examples/rig.json
    (7.5 cm baseline): seen by both cameras, within ``max_outside_box_m`` of the working volume (docs/runtime.md)."""
    from ghnerf_runtime.rig_file import load_rig

    rig = load_rig(REPO / "docs" / "examples" / "rig.json")
    cfg = Joints3DConfig()
    lo = rig.volume.min_corner - cfg.max_outside_box_m
    hi = rig.volume.max_corner + cfg.max_outside_box_m
    grid = np.stack(np.meshgrid(*[np.linspace(lo[k], hi[k], 41) for k in range(3)], indexing="ij"), -1).reshape(-1, 3)
    seen = np.ones(len(grid), bool)
    for cam in rig.pair:
        uv, _ = cam.project(grid)
        seen &= np.isfinite(uv).all(-1) & (uv >= 0).all(-1) & (uv[:, 0] < cam.width) & (uv[:, 1] < cam.height)
    a, b = (grid[seen] - cam.center for cam in rig.pair)
    angle = np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.abs((a * b).sum(-1))))
    assert round(float(angle.min()), 2) == 0.71  # the figure docs/runtime.md gives
    assert cfg.min_ray_angle_deg < angle.min()


def test_triangulated_confidence_is_the_geometric_mean_of_any_number_of_views():
    K = [[150.0, 0.0, 63.5], [0.0, 150.0, 63.5], [0.0, 0.0, 1.0]]
    cams = [Camera(f"c{i}", 128, 128, K, [], *look_at((x, -1.2, 0.0), (0.0, -1.0, 3.0)))
            for i, x in enumerate((-0.5, 0.0, 0.5))]
    X = _joints(2)
    uv = np.stack([c.project(X)[0] for c in cams])
    conf = np.array([[0.8, 0.9], [0.8, 0.5], [0.8, 0.6]])
    r = triangulate_joints(uv, conf, np.ones((3, 2), bool), cams, Joints3DConfig())
    assert r.valid.all()
    np.testing.assert_allclose(r.confidence, [0.8, (0.9 * 0.5 * 0.6) ** (1 / 3)], rtol=1e-6)  # was 0.716 for 0.8s
    two = triangulate_joints(uv[:2], conf[:2], np.ones((2, 2), bool), cams[:2], Joints3DConfig())
    np.testing.assert_allclose(two.confidence, [0.8, np.sqrt(0.45)], rtol=1e-6)


def test_volumetric_refinement_is_exact_for_gaussian_responses():
    box = np.array([[-0.5, -1.9, 2.6], [0.5, 0.1, 3.4]])
    pts, shape = query_grid(box, 12)
    assert pts.shape == (np.prod(shape), 3)
    X = _joints(25, seed=3)
    d2 = ((pts[:, None, :] - X[None]) ** 2).sum(-1)
    heat = np.exp(-d2 / (2 * 0.06 ** 2))[None].repeat(2, axis=0)
    r = volumetric_joints(heat, pts, shape, Joints3DConfig())
    assert r.valid.all() and np.abs(r.points - X).max() < 1e-3
    flat = volumetric_joints(np.full_like(heat, 0.01), pts, shape, Joints3DConfig(min_volumetric_response=0.1))
    assert not flat.valid.any() and not flat.points.any()
    # a strong but flat or flooded response is no peak either (its argmax would be the grid's first cell)
    for flooded in (np.full_like(heat, 0.6), np.maximum(heat, 0.5)):
        r = volumetric_joints(flooded, pts, shape, Joints3DConfig())
        assert not r.valid.any() and not r.confidence.any()


def test_volumetric_extremes_give_a_confidence_in_zero_one_or_a_missing_joint():
    """Responses past 1 reported a confidence past it (1e30 reached the JSON); a NaN or inf cell was zeroed, so
    a joint whose true peak was that cell was placed at the next-best cell instead of being missing, as the
    2D decoder makes it."""
    box = np.array([[-0.5, -1.9, 2.6], [0.5, 0.1, 3.4]])
    pts, shape = query_grid(box, 12)
    X = _joints(3, seed=4)
    heat = np.exp(-((pts[:, None, :] - X[None]) ** 2).sum(-1) / (2 * 0.06 ** 2))[None].repeat(2, axis=0)
    heat[:, :, 0] *= 1e30
    best = heat[0, :, 1].argmax()
    heat[1, best, 1] = np.nan  # joint 1's peak cell, in one source volume
    heat[:, best + 1, 2] = np.inf
    r = volumetric_joints(heat, pts, shape, Joints3DConfig())
    assert r.valid.tolist() == [True, False, False]
    assert r.confidence[0] == 1.0 and np.abs(r.points[0] - X[0]).max() < 1e-3
    assert not r.points[1:].any() and not r.confidence[1:].any()


def test_depth_centroid_reads_no_cells_for_a_peak_off_the_map_nor_weighs_negative_heat():
    """A peak given off the map (or NaN) was clamped to the map's edge and the edge's cells became a valid
    joint; a negative heatmap value was squared into a positive weight (-0.95 pulled a joint 1.6 m deep)."""
    cams = _cams()
    hm = np.zeros((2, 1, 32, 32))
    hm[:, 0, 0:3, 0:3] = 0.9  # something in the corner
    depth = np.full((2, 32, 32), 3.0)
    conf, valid = np.full((2, 1), 0.8), np.ones((2, 1), bool)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the NaN's cast to int warned
        for u in (np.nan, -40.0, 1e30, -0.51, 31.5):
            r = depth_centroid_joints(hm, depth, np.full((2, 1, 2), u), conf, valid, cams, 128, Joints3DConfig())
            assert not r.valid.any() and not r.points.any(), u
    inside = depth_centroid_joints(hm, depth, np.full((2, 1, 2), -0.49), conf, valid, cams, 128, Joints3DConfig())
    assert inside.valid.all()  # rounds to cell 0: on the map
    hm = np.zeros((2, 1, 32, 32))
    hm[:, 0, 16, 16] = 0.9
    alone = depth_centroid_joints(hm, depth, np.full((2, 1, 2), 16.0), conf, valid, cams, 128, Joints3DConfig())
    hm[:, 0, 18, 18] = -0.95
    depth[:, 18, 18] = 6.0
    r = depth_centroid_joints(hm, depth, np.full((2, 1, 2), 16.0), conf, valid, cams, 128, Joints3DConfig())
    np.testing.assert_allclose(r.points, alone.points, atol=1e-12)
    hm[:, 0] = -1.0  # negative everywhere: no weight anywhere
    assert not depth_centroid_joints(hm, depth, np.full((2, 1, 2), 16.0), conf, valid, cams, 128,
                                     Joints3DConfig()).valid.any()



@pytest.mark.parametrize("seed", range(3))
def test_hostile_model_outputs_give_finite_3d_joints_with_a_confidence_in_zero_one(seed):
    """Property sweep of the two model-output readers: float16, float32 and float64 heatmaps, depths and grid
    responses sprinkled with NaN, infinities, negatives, denormals and float32's largest values (a corrupt model
    output; sometimes every cell), and peaks off the map or not finite. No warning, every point finite, every
    confidence in [0, 1], a joint with no confidence missing."""
    rng = np.random.default_rng(seed)
    specials = np.array([np.nan, np.inf, -np.inf, 3.4e38, -3.4e38, 1e-40, 0.0, 2.5, -3.0, 65504.0])
    cams, cfg = _cams(), Joints3DConfig()
    grid, shape = query_grid(np.array([[-0.5, -1.9, 2.6], [0.5, 0.1, 3.4]]), 8)

    def corrupt(a):
        hit = rng.uniform(size=a.shape) < rng.choice([0.0, 0.05, 0.5, 1.0])
        a[hit] = rng.choice(specials, int(hit.sum()))
        with np.errstate(over="ignore"):  # (float32's largest is inf in float16: one more infinity)
            return a.astype(rng.choice([np.float16, np.float32, np.float64]))

    def check(r):
        assert np.isfinite(r.points).all() and np.isfinite(r.reprojection_px).all()
        assert np.all((r.confidence >= 0) & (r.confidence <= 1)) and not np.any(r.valid & (r.confidence == 0))

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for _ in range(40):
            heat, depth = corrupt(rng.uniform(0, 1, (2, 4, 32, 32))), corrupt(rng.uniform(1, 5, (2, 32, 32)))
            peaks = rng.uniform(-2.0, 34.0, (2, 4, 2))
            off = rng.uniform(size=(2, 4)) < 0.2
            peaks[off] = rng.choice(specials, (int(off.sum()), 2))
            check(depth_centroid_joints(heat, depth, peaks, rng.uniform(0, 1.2, (2, 4)), rng.uniform(size=(2, 4)) < 0.9,
                                        cams, 128, cfg))
            check(volumetric_joints(corrupt(rng.uniform(0, 1, (2, len(grid), 3))), grid, shape, cfg))

def test_peak_values_outside_zero_one_give_no_3d_confidence_outside_it():
    """A peak value of 1.5 gave a triangulated confidence of 1.1 (Joints3D.confidence is in [0, 1]); inf is
    no peak at all."""
    cams = _cams()
    X = _joints(3)
    uv = np.stack([c.project(X)[0] for c in cams])
    conf = np.array([[1.5, np.inf, 1.0], [0.8, 0.8, 1e30]])
    r = triangulate_joints(uv, conf, np.ones((2, 3), bool), cams, Joints3DConfig())
    assert r.valid.tolist() == [True, False, True]
    np.testing.assert_allclose(r.confidence, [np.sqrt(0.8), 0.0, 1.0], rtol=1e-6)


def test_depth_centroid_recovers_points_from_rendered_depth():
    cams = _cams()
    X = _joints(4, seed=5)
    hm = np.zeros((2, 4, 32, 32))
    depth = np.zeros((2, 32, 32))
    peaks = np.zeros((2, 4, 2))
    for c, cam in enumerate(cams):
        uv, z = cam.project(X)
        cells = np.rint(model_to_heatmap_pixels(uv, 32, 128)).astype(int)
        for j, (cx, cy) in enumerate(cells):
            hm[c, j, cy, cx] = 1.0
            depth[c, cy, cx] = z[j]
            peaks[c, j] = (cx, cy)
    r = depth_centroid_joints(hm, depth, peaks, np.full((2, 4), 0.9), np.ones((2, 4), bool), cams, 128,
                              Joints3DConfig(surface_offset_m=0.0))
    assert r.valid.all()
    # Cell-centre quantisation: within one heatmap cell (4 model px ~ 8 cm at 3 m with f = 150).
    assert np.abs(r.points - X).max() < 0.08


# ------------------------------------------------------------------ novel camera
def test_interpolated_camera_slerps_and_lerps():
    a, b = _cams()
    R0 = slerp_rotation(a.R, b.R, 0.0)
    assert np.allclose(R0, a.R, atol=1e-9) and np.allclose(slerp_rotation(a.R, b.R, 1.0), b.R, atol=1e-9)
    mid = interpolate_camera(a, b, 0.5)
    assert np.allclose(mid.center, 0.5 * (a.center + b.center))
    assert np.allclose(mid.R @ mid.R.T, np.eye(3), atol=1e-9)
    # Slerp: the middle rotation is half the geodesic distance from both ends.

    def angle(R1, R2):
        return np.degrees(np.arccos(np.clip((np.trace(R1.T @ R2) - 1) / 2, -1, 1)))

    assert angle(mid.R, a.R) == pytest.approx(angle(a.R, b.R) / 2, abs=1e-6)
    assert angle(mid.R, b.R) == pytest.approx(angle(a.R, b.R) / 2, abs=1e-6)


def _landscape_and_side_mounted():
    """A 640x480 camera and one whose 640x480 sensor is mounted on its side (upright: 480x640)."""
    K = [[500.0, 0.0, 331.5], [0.0, 500.0, 232.5], [0.0, 0.0, 1.0]]  # principal point off centre
    a = Camera("a", 640, 480, K, [], *look_at((-0.5, -1.2, 0.0), (0.0, -1.0, 3.0)))
    side = Camera("b", 640, 480, [[420.0, 0.0, 311.5], [0.0, 420.0, 247.5], [0.0, 0.0, 1.0]], [],
                  *look_at((0.5, -1.2, 0.0), (0.0, -1.0, 3.0), up=(1.0, 0.0, 0.0)))
    return a, side.quarter_turned(1)


def test_interpolated_camera_keeps_square_pixels_between_images_of_different_shapes():
    a, b = _landscape_and_side_mounted()
    assert (a.size, b.size) == ((640, 480), (480, 640))
    for alpha in (0.0, 0.5, 1.0):
        K = interpolate_camera(a, b, alpha).K
        assert K[0, 0] == pytest.approx(K[1, 1], rel=1e-12), alpha  # per-axis resizing gave aspect 1.78 at 1
    # at alpha 1: b's view, scaled by one factor (0.75, to fit 640 rows in 480) about the images' centres
    end = interpolate_camera(a, b, 1.0)
    assert end.size == a.size and np.allclose(end.R, b.R) and np.allclose(end.center, b.center)
    X = _joints()
    uv_b, _ = b.project(X)
    uv, _ = end.project(X)
    expected = 0.75 * (uv_b - [(480 - 1) / 2, (640 - 1) / 2]) + [(640 - 1) / 2, (480 - 1) / 2]
    np.testing.assert_allclose(uv, expected, atol=1e-9)


def test_interpolated_camera_of_one_shape_is_unchanged_and_extrapolation_keeps_a_positive_focal_length():
    from dataclasses import replace

    from ghnerf_runtime.novel_view import fit_intrinsics

    a, b = _cams()
    small = b.resized(64, 64)  # one shape: the uniform fit is Camera.resized
    np.testing.assert_allclose(fit_intrinsics(small, 128, 128), b.K, atol=1e-12)
    wide = replace(a, K=np.array([[400.0, 0.0, 63.5], [0.0, 400.0, 63.5], [0.0, 0.0, 1.0]]))  # f 400 vs 150
    assert interpolate_camera(wide, b, 1.5).K[0, 0] == pytest.approx(25.0)  # -0.5 * 400 + 1.5 * 150
    with pytest.raises(GeometryError, match="novel-alpha"):
        interpolate_camera(wide, b, 2.0)  # -400 + 2 * 150 = -100: a mirrored camera
    with pytest.raises(GeometryError, match="alpha -1"):
        interpolate_camera(b, wide, -1.0)


# ------------------------------------------------------------------ frame check
def test_frame_check_flags_flat_and_noise_but_not_images():
    cfg = FrameCheckConfig()
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[:128, :128]
    image = (0.5 + 0.3 * np.sin(xx / 9.0) * np.cos(yy / 13.0)).astype(np.float32)
    assert check_crop(image, 255.0, cfg) == (True, "")
    assert check_crop(np.full((128, 128), 0.5, np.float32), 255.0, cfg) == (False, "flat")
    assert check_crop(rng.random((128, 128)).astype(np.float32), 255.0, cfg) == (False, "noise")
    bad = image.copy()
    bad[3, 3] = np.nan
    assert check_crop(bad, 255.0, cfg) == (False, "non-finite")
    assert check_crop(np.zeros((128, 128), np.float32), 255.0, FrameCheckConfig(enabled=False)) == (True, "")


def test_the_frame_checks_statistics_are_what_its_verdict_compares():
    """``crop_statistics``: the standard deviation in levels and the detail share that ``check_crop`` holds to its
    thresholds (``benchmarks/measure_frame_check.py`` prints them), over the pixels that show the frame."""
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[:128, :128]
    image = (0.5 + 0.3 * np.sin(xx / 9.0) * np.cos(yy / 13.0)).astype(np.float32)
    std, share = crop_statistics(image, 255.0)
    assert std == pytest.approx(255.0 * float(image.std()), rel=1e-5) and share < 0.01
    noise = rng.random((128, 128)).astype(np.float32)
    assert crop_statistics(noise, 255.0)[1] > FrameCheckConfig().max_noise_ratio
    assert crop_statistics(np.full((8, 8), 0.5, np.float32), 255.0) == (0.0, float("inf"))
    assert crop_statistics(image, 255.0, np.zeros(image.shape, bool)) is None
    half = np.zeros(image.shape, bool)
    half[:, :64] = True
    padded = np.where(half, noise, 0.0).astype(np.float32)  # zero padding beside the frame's noise
    assert crop_statistics(padded, 255.0, half)[0] == pytest.approx(255.0 * float(noise[:, :64].std()), rel=1e-5)


def test_frame_check_judges_only_the_pixels_that_show_the_frame():
    """A saturated (or black) frame under a crop that reaches past the frame's edge: the zero padding gives the
    plane contrast, so only ``inside`` tells it is flat; an image in the same crop still passes."""
    cfg = FrameCheckConfig()
    inside = np.zeros((128, 128), bool)
    inside[:, 40:] = True  # the crop's left third is padding
    saturated = np.where(inside, 1.0, 0.0).astype(np.float32)
    assert check_crop(saturated, 255.0, cfg) == (True, "")  # what the padding fooled
    assert check_crop(saturated, 255.0, cfg, inside) == (False, "flat")
    yy, xx = np.mgrid[:128, :128]
    image = np.where(inside, 0.5 + 0.3 * np.sin(xx / 9.0) * np.cos(yy / 13.0), 0.0).astype(np.float32)
    assert check_crop(image, 255.0, cfg, inside) == (True, "")
    noise = np.where(inside, np.random.default_rng(0).random((128, 128)), 0.0).astype(np.float32)
    assert check_crop(noise, 255.0, cfg, inside) == (False, "noise")
    assert check_crop(image, 255.0, cfg, np.zeros((128, 128), bool)) == (False, "flat")  # shows nothing


def test_frame_check_keeps_a_scene_under_heavy_sensor_noise_and_rejects_every_kind_of_garbage():
    """A dim scene at high gain: per-pixel noise puts more than ``max_noise_ratio`` of the crop's variance in
    pixel-to-pixel detail (the rule before session 65 said ``noise``), but the 2x2 block means keep the scene
    (``coarse_detail_share``). Noise per pixel, in 2x2 blocks, smoothed, or a pixel checkerboard stays ``noise``."""
    cfg = FrameCheckConfig()
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[:128, :128]
    scene = (0.5 + 0.3 * np.sin(xx / 9.0) * np.cos(yy / 13.0)).astype(np.float32)
    noisy = (scene + rng.normal(0.0, 0.15, scene.shape)).astype(np.float32)  # sensor noise of 38 levels
    assert crop_statistics(noisy, 255.0)[1] > cfg.max_noise_ratio  # the fine share alone calls it noise
    assert coarse_detail_share(noisy) < 0.3
    assert check_crop(noisy, 255.0, cfg) == (True, "")
    inside = np.zeros(scene.shape, bool)
    inside[:, 40:] = True  # padding beside the frame does not change the verdict
    assert check_crop(np.where(inside, noisy, 0.0).astype(np.float32), 255.0, cfg, inside) == (True, "")
    assert check_crop(noisy, 255.0, FrameCheckConfig(max_coarse_noise_ratio=0.0)) == (False, "noise")  # old rule
    blocks = np.repeat(np.repeat(rng.random((64, 64)), 2, axis=0), 2, axis=1).astype(np.float32)
    smoothed = cv2.GaussianBlur(rng.random((128, 128)).astype(np.float32), (0, 0), 0.7)
    checkerboard = ((xx + yy) % 2).astype(np.float32)  # no variance left in its block means
    garbage = {"uniform": rng.random((128, 128)).astype(np.float32), "2x2 blocks": blocks,
               "smoothed": smoothed, "checkerboard": checkerboard}
    for name, plane in garbage.items():
        assert check_crop(plane, 255.0, cfg) == (False, "noise"), name
        assert check_crop(np.where(inside, plane, 0.0).astype(np.float32), 255.0, cfg, inside) == (False, "noise"), \
            name
    assert coarse_detail_share(checkerboard) == float("inf")
    assert coarse_detail_share(noisy[:127, :127]) == pytest.approx(coarse_detail_share(noisy[:126, :126]))


def test_frame_check_config_names_a_coarse_noise_ratio_out_of_range():
    with pytest.raises(ConfigError, match="max_coarse_noise_ratio"):
        FrameCheckConfig(max_coarse_noise_ratio=1.5)
    with pytest.raises(ConfigError, match="max_coarse_noise_ratio"):
        FrameCheckConfig(max_coarse_noise_ratio=float("nan"))


def test_a_skewed_camera_on_its_side_still_gives_an_upright_pinhole():
    """The novel view interpolates the sources' upright pinholes; a skewed K cannot be quarter-turned exactly."""
    from ghnerf_runtime.estimator import _CameraState
    from ghnerf_runtime.geometry.camera import Camera

    cam = Camera("side", 480, 640, [[600.0, 3.0, 240.0], [0.0, 600.0, 320.0], [0.0, 0.0, 1.0]], [-0.1, 0.01, 0.0, 0.0])
    for roll in (90.0, -90.0, 180.0):
        upright = _CameraState(cam, roll).upright_pinhole
        assert not upright.has_distortion and np.allclose(upright.center, cam.center)


def test_the_tracked_crop_follows_roi_edge_crop():
    """A track running past camera 0's left edge: ``roi.edge_crop`` "centre" keeps the whole projected box's
    square (the crop centred on the person, more of it past the frame), "clip" squares what the frame shows."""
    sim = pytest.importorskip("drivers.sim")
    from ghnerf_runtime.tracking import plan_regions

    rig = sim.RigPlacement().build()
    cam = rig.pair[0]
    joints = _joints() - 2.4 * np.asarray(cam.R)[0]  # moved along the camera's x: part of it past u = 0
    uv = cam.project(joints, distort=False)[0]
    assert uv[:, 0].min() < 0 < uv[:, 0].max()
    track = track_from_joints(joints, np.full(25, 0.9), np.ones(25, bool), TrackingConfig(min_joints=6))
    rois = {e: plan_regions(rig, track, RoiConfig(edge_crop=e, snap_px=1)).rois[0] for e in ("clip", "centre")}
    mid = {e: r.x0 + (r.size - 1) / 2 for e, r in rois.items()}
    box_mid = 0.5 * (uv[:, 0].min() + uv[:, 0].max())
    assert abs(mid["centre"] - box_mid) <= 1.0 < mid["clip"] - box_mid
    assert abs(rois["centre"].size - rois["clip"].size) <= 1  # the same scale


def test_the_estimator_s_import_loads_numpy_ma_before_the_first_pair():
    """``np.median`` (the views' agreement, every pair) imports ``numpy.ma`` on its first call: 10-70 ms that
    ``benchmarks/time_demo_stages.py`` found on the first pair. Importing the estimator loads it, so the model's load
    pays it rather than the first pair a daemon streams (a fresh interpreter: this one's tests may have loaded it)."""
    import subprocess
    import sys

    code = "import sys, ghnerf_runtime.estimator; print('numpy.ma' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "True", out.stdout


def test_box_block_of_a_finite_box_projecting_past_float64():
    """A finite box whose corners project past float64's pixels (NaN from ``Camera.project``) reached
    ``int(np.floor(nan))``: numpy's bare ValueError."""
    cam = Camera("c", 128, 128, K128)  # at the origin, looking along +z
    box = np.array([[1e307, 0.0, 1e-5], [1e307, 0.0, 2e-5]])  # just in front of the camera, 1e307 m to its right
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert box_block(cam, box, 4) == (0, 0, 32, 32)  # unbounded projection: the whole grid


@pytest.mark.parametrize("alpha", [float("nan"), float("inf"), None])
def test_slerp_rotation_names_an_alpha_that_is_no_finite_number(alpha):
    """A NaN alpha gave a NaN rotation without a word (None a bare TypeError)."""
    a, b = _cams()
    with pytest.raises(GeometryError, match=r"slerp_rotation: alpha must be a finite number, got (nan|inf|None)"):
        slerp_rotation(a.R, b.R, alpha)


@pytest.mark.parametrize("alpha", [True, False, np.True_, np.array(True)])
def test_slerp_rotation_refuses_true_false_as_alpha(alpha):
    """True was read as alpha 1.0 (sessions 73-74), as the estimator's capture time refuses it."""
    a, b = _cams()
    with pytest.raises(GeometryError, match=r"slerp_rotation: alpha must be a finite number, got (np\.)?"
                                            r"(array\()?(True|False)"):
        slerp_rotation(a.R, b.R, alpha)
