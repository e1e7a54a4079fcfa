"""ROI, crop camera and undistort-crop maps: checked against OpenCV and against rendered dots."""
from __future__ import annotations

import doctest

import cv2
import numpy as np
import pytest

from ghnerf_runtime import preprocess
from ghnerf_runtime.contract import Normalisation
from ghnerf_runtime.errors import GeometryError, ShapeError
from ghnerf_runtime.geometry.camera import Camera, look_at
from ghnerf_runtime.geometry.rig import WorkingVolume
from ghnerf_runtime.keypoints import KeypointDecoderConfig, decode_keypoints
from ghnerf_runtime.preprocess import (
    Roi, apply_crop_maps, build_undistort_crop_maps, crop_camera, preprocess_image, roi_from_joints,
    roi_from_volume, undistorted_image_bounds, upright_roll_deg,
)

K = np.array([[560.0, 0.0, 331.0], [0.0, 556.0, 236.5], [0.0, 0.0, 1.0]])
DIST = np.array([-0.24, 0.07, 0.0009, -0.0012, -0.01])
VOLUME = WorkingVolume([-1.0, -2.0, 2.0], [1.0, 0.0, 4.0])


def make_camera(dist=DIST, K=K) -> Camera:
    R, t = look_at((0.3, -1.2, -0.4), (0.0, -0.9, 3.0))
    return Camera("left", 640, 480, K, dist, R, t)


def smooth_image(h=480, w=640) -> np.ndarray:
    """Low-frequency colour pattern: interpolation differences stay well below a grey level."""
    yy, xx = np.mgrid[:h, :w].astype(np.float64)
    img = np.stack([
        128 + 100 * np.sin(xx / 23.0) * np.cos(yy / 31.0),
        128 + 90 * np.cos((xx + yy) / 41.0),
        128 + 80 * np.sin(xx / 53.0 - yy / 29.0),
    ], axis=-1)
    return np.clip(img, 0, 255).astype(np.uint8)


# --------------------------------------------------------------------------- ROI
def test_doctests():
    result = doctest.testmod(preprocess, raise_on_error=False)
    assert result.attempted >= 4 and result.failed == 0, result  # 4 examples when written


@pytest.mark.parametrize("args", [(0, 0, 0), (0.5, 0, 10), (0, 0, -3), (True, 0, 4),
                                  (float("nan"), 0, 4), (0, float("inf"), 4), (0, 0, None)])  # were bare errors
def test_roi_validation(args):
    with pytest.raises(GeometryError):
        Roi(*args)


def test_roi_transforms_are_inverse_and_match_crop_camera():
    cam = make_camera()
    roi = Roi(-20, 35, 333)
    uv = np.random.default_rng(0).uniform(-50, 600, size=(4, 5, 2))
    model = roi.image_to_model(uv, 128)
    np.testing.assert_allclose(roi.model_to_image(model, 128), uv, atol=1e-9)
    A = roi.affine(128)
    np.testing.assert_allclose(uv @ A[:, :2].T + A[:, 2], model, atol=1e-9)
    # The crop camera's projection is the ideal projection pushed through the ROI transform.
    X = np.random.default_rng(1).uniform([-0.8, -1.8, 2.2], [0.8, -0.1, 3.8], size=(30, 3))
    crop = crop_camera(cam, roi, 128)
    ideal, _ = cam.project(X, distort=False)
    np.testing.assert_allclose(crop.project(X)[0], roi.image_to_model(ideal, 128), atol=1e-8)
    assert crop.size == (128, 128) and not crop.has_distortion


def test_roi_from_volume_contains_projected_volume_and_is_square():
    cam = make_camera()
    volume = WorkingVolume([-0.5, -1.9, 2.5], [0.5, 0.0, 3.5])  # fully in view
    roi = roi_from_volume(cam, volume)
    uv, _ = cam.project(volume.corners(), distort=False)
    assert np.all(uv >= [roi.x0 - 0.5, roi.y0 - 0.5]) and np.all(uv <= [roi.x0 + roi.size - 0.5,
                                                                       roi.y0 + roi.size - 0.5])
    assert roi.size <= np.max(uv.max(0) - uv.min(0)) + 2  # tight: only rounding slack
    # Same ROI from the corner array; a margin grows it.
    assert roi_from_volume(cam, volume.corners()) == roi
    assert roi_from_volume(cam, volume, margin=0.2).size > roi.size


def test_roi_from_volume_clips_to_the_image_and_keeps_the_square():
    cam = make_camera()
    roi = roi_from_volume(cam, VOLUME)  # the working volume overflows the view
    lo, hi = undistorted_image_bounds(cam)
    uv, _ = cam.project(VOLUME.corners(), distort=False)
    visible_lo, visible_hi = np.maximum(uv.min(0), lo), np.minimum(uv.max(0), hi)
    assert roi.x0 - 0.5 <= visible_lo[0] and roi.x0 + roi.size - 0.5 >= visible_hi[0]
    assert roi.y0 - 0.5 <= visible_lo[1] and roi.y0 + roi.size - 0.5 >= visible_hi[1]
    assert roi.size <= np.max(hi - lo) + 2


def test_roi_from_volume_behind_camera():
    cam = make_camera()
    # A box around the camera: part of it is behind; the ROI is the whole (square) view.
    around = WorkingVolume([-1.0, -2.5, -1.5], [1.0, 0.5, 4.0])
    roi = roi_from_volume(cam, around)
    lo, hi = undistorted_image_bounds(cam)
    assert roi.size == pytest.approx(np.max(hi - lo), abs=2)
    behind = WorkingVolume([-1.0, -2.0, -4.0], [1.0, 0.0, -2.0])
    with pytest.raises(GeometryError, match="behind"):
        roi_from_volume(cam, behind)
    with pytest.raises(GeometryError, match="outside the image"):
        roi_from_volume(cam, WorkingVolume([20.0, -2.0, 2.0], [22.0, 0.0, 4.0]))
    with pytest.raises(ShapeError):
        roi_from_volume(cam, np.zeros((8, 2)))


def test_roi_from_joints_3d_and_2d_agree_and_track():
    cam = make_camera()
    rng = np.random.default_rng(2)
    joints = rng.uniform([-0.3, -1.7, 2.8], [0.3, -0.1, 3.2], size=(25, 3))
    conf = np.ones(25)
    conf[:3] = 0.0  # ignored joints
    joints[:3] = [5.0, 5.0, 50.0]
    roi3 = roi_from_joints(cam, joints, conf, margin_frac=0.1)
    uv, _ = cam.project(joints)
    roi2 = roi_from_joints(cam, uv, conf, margin_frac=0.1)
    assert roi3 == roi2
    ideal, _ = cam.project(joints[3:], distort=False)
    span = ideal.max(0) - ideal.min(0)
    assert roi3.size == pytest.approx(1.2 * span.max(), abs=2)
    assert np.all(ideal >= [roi3.x0, roi3.y0]) and np.all(ideal <= [roi3.x0 + roi3.size, roi3.y0 + roi3.size])
    # min_size, too few joints, shape checks.
    assert roi_from_joints(cam, joints[3:6], np.ones(3), min_size=200).size == 200
    assert roi_from_joints(cam, joints, np.zeros(25)) is None
    assert roi_from_joints(cam, np.full((25, 2), np.nan), np.ones(25)) is None
    with pytest.raises(ShapeError):
        roi_from_joints(cam, joints, np.ones(24))


def test_roi_from_joints_leaves_out_confident_joints_behind_the_camera():
    # a 3D joint behind the camera (or nearer than the near plane) has no pixel: it is left out, not
    # turned into NaN (a ValueError) or a huge ROI
    cam = make_camera()
    rng = np.random.default_rng(5)
    joints = rng.uniform([-0.3, -1.7, 2.8], [0.3, -0.1, 3.2], size=(25, 3))
    conf = np.ones(25)
    want = roi_from_joints(cam, joints[2:], conf[2:], margin_frac=0.1)
    joints[0] = cam.center - 1.5 * cam.R[2]  # 1.5 m behind
    joints[1] = cam.center + 0.01 * cam.R[2] + 0.02 * cam.R[0]  # 1 cm in front: inside the near plane
    assert cam.to_camera(joints[:2])[:, 2].max() < preprocess.NEAR_PLANE
    assert roi_from_joints(cam, joints, conf, margin_frac=0.1) == want
    assert roi_from_joints(cam, joints[:4], conf[:4], min_joints=3) is None  # two usable joints only


def test_roi_from_joints_leaves_out_a_joint_whose_pixel_overflows():
    # 1e307 m to the side, 3 m ahead: Camera.project gives NaN (its pixel overflows float64); it was inf, and
    # the ROI became the whole frame
    cam = Camera("c", 640, 480, K, DIST)  # at the origin, looking along z: no rounding of the huge point
    rng = np.random.default_rng(5)
    joints = rng.uniform([-0.3, -0.8, 2.8], [0.3, 0.8, 3.2], size=(25, 3))
    conf = np.ones(25)
    want = roi_from_joints(cam, joints[1:], conf[1:], margin_frac=0.1)
    joints[0] = [1e307, 0.0, 3.0]
    assert np.all(np.isnan(cam.project(joints[0], distort=False)[0]))
    assert roi_from_joints(cam, joints, conf, margin_frac=0.1) == want


# -------------------------------------------------------------------------- maps
def _reference_crop(image, cam, roi, out_size, interpolation):
    """cv2.undistort to the ideal camera, crop the ROI, resize: three passes."""
    und = cv2.undistort(image, cam.K, cam.dist)
    crop = und[roi.y0:roi.y0 + roi.size, roi.x0:roi.x0 + roi.size]
    return cv2.resize(crop, (out_size, out_size), interpolation=interpolation)


@pytest.mark.parametrize("size, interpolation, level", [(150, cv2.INTER_LINEAR, 0), (256, cv2.INTER_AREA, 1),
                                                        (400, cv2.INTER_AREA, 2)])
def test_maps_agree_with_cv2_undistort_crop_resize(size, interpolation, level):
    cam = make_camera()
    image = smooth_image()
    roi = Roi(180, 40, size)
    maps = build_undistort_crop_maps(cam, roi, 128)
    assert maps.level == level and maps.map_x.dtype == np.float32 and maps.map_x.shape == (128, 128)
    ours = apply_crop_maps(image, maps).astype(np.float64)
    ref = _reference_crop(image, cam, roi, 128, interpolation).astype(np.float64)
    diff = np.abs(ours - ref)[2:-2, 2:-2]
    assert diff.mean() < 0.6 and diff.max() <= 4, (diff.mean(), diff.max())


def test_level_zero_maps_are_plain_remap_tables():
    cam = make_camera()
    roi = Roi(180, 40, 140)
    maps = build_undistort_crop_maps(cam, roi, 128)
    assert maps.level == 0
    crop = crop_camera(cam, roi, 128)
    expected = cam.normalized_to_pixels(crop.pixels_to_normalized(crop.pixel_grid()), distort=True)
    np.testing.assert_allclose(maps.map_x, expected[..., 0], atol=1e-3)
    np.testing.assert_allclose(maps.map_y, expected[..., 1], atol=1e-3)
    image = smooth_image()
    direct = cv2.remap(image, maps.map_x, maps.map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    assert np.abs(direct.astype(int) - apply_crop_maps(image, maps).astype(int)).max() <= 1


def test_skewed_camera_uses_the_camera_model():
    Ks = K.copy()
    Ks[0, 1] = 3.0
    cam = make_camera(K=Ks)
    roi = Roi(40, -20, 560)
    maps = build_undistort_crop_maps(cam, roi, 128, antialias=False)
    crop = crop_camera(cam, roi, 128)
    X = np.array([[0.1, -1.0, 3.0], [-0.4, -1.5, 2.6]])
    uv_model, _ = crop.project(X)
    uv_frame, _ = cam.project(X)
    # Sample the maps bilinearly at the model pixel: it must point at the frame pixel.
    got = [cv2.remap(m, uv_model[:, :1].astype(np.float32), uv_model[:, 1:].astype(np.float32),
                     cv2.INTER_LINEAR)[:, 0] for m in (maps.map_x, maps.map_y)]
    np.testing.assert_allclose(np.stack(got, -1), uv_frame, atol=0.01)


def _render_dots(cam: Camera, points: np.ndarray, sigma_px: float) -> np.ndarray:
    uv, _ = cam.project(points)
    yy, xx = np.mgrid[:cam.height, :cam.width].astype(np.float64)
    img = np.zeros((cam.height, cam.width))
    for u, v in uv:
        img += 255 * np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * sigma_px ** 2))
    return np.clip(img, 0, 255).astype(np.uint8)


@pytest.mark.parametrize(("antialias", "roll"), [(True, 0.0), (False, 0.0), (True, 90.0), (False, 180.0), (True, -33.0)])
def test_dot_lands_where_crop_camera_projects_it(antialias, roll):
    cam = make_camera()
    roi = Roi(60, -30, 512)  # scale 4: two box levels when antialiased; partly off the frame
    points = np.array([[0.0, -1.0, 3.0], [-0.7, -1.5, 2.6], [0.6, -0.3, 2.4], [0.5, -1.8, 3.4]])
    sigma_model = 2.0
    frame = _render_dots(cam, points, sigma_px=sigma_model * roi.size / 128)
    maps = build_undistort_crop_maps(cam, roi, 128, antialias=antialias, roll_deg=roll)
    assert maps.level == (2 if antialias else 0)
    crop = apply_crop_maps(frame, maps).astype(np.float32) / 255.0
    expected, _ = crop_camera(cam, roi, 128, roll).project(points)
    for uv in expected:  # decode each dot in its own window so the others do not compete
        heat = np.zeros_like(crop)
        u, v = np.round(uv).astype(int)
        heat[v - 8:v + 9, u - 8:u + 9] = crop[v - 8:v + 9, u - 8:u + 9]
        kp = decode_keypoints(heat[None], KeypointDecoderConfig(sigma=0.0))
        assert kp.valid[0]
        # A box pre-reduction seen at a slant blurs the dot a little unevenly: the peak refinement
        # then errs up to 0.13 px (0.01 px without the pre-reduction); the geometry itself is exact.
        tolerance = 0.15 if antialias and roll % 90 else 0.1
        assert np.linalg.norm(kp.uv[0] - uv) < tolerance, (kp.uv[0], uv)


@pytest.mark.parametrize("supersample", [2, 3])
@pytest.mark.parametrize("roll", [0.0, -33.0])
def test_dot_lands_where_crop_camera_projects_it_when_supersampled(supersample, roll):
    """The supersampled crop (maps at f S, box means back to S) keeps the crop camera's geometry: no half-pixel
    shift from the f x f reduction."""
    cam = make_camera()
    roi = Roi(60, -30, 512)
    points = np.array([[0.0, -1.0, 3.0], [-0.7, -1.5, 2.6], [0.6, -0.3, 2.4], [0.5, -1.8, 3.4]])
    frame = _render_dots(cam, points, sigma_px=2.0 * roi.size / 128)
    maps = build_undistort_crop_maps(cam, roi, 128, roll_deg=roll, supersample=supersample)
    assert maps.out_size == 128 and maps.map_x.shape == (128 * supersample,) * 2
    crop = apply_crop_maps(frame, maps).astype(np.float32) / 255.0
    assert crop.shape == (128, 128)
    expected, _ = crop_camera(cam, roi, 128, roll).project(points)
    for uv in expected:
        heat = np.zeros_like(crop)
        u, v = np.round(uv).astype(int)
        heat[v - 8:v + 9, u - 8:u + 9] = crop[v - 8:v + 9, u - 8:u + 9]
        kp = decode_keypoints(heat[None], KeypointDecoderConfig(sigma=0.0))
        assert kp.valid[0] and np.linalg.norm(kp.uv[0] - uv) < 0.1, (kp.uv[0], uv)


@pytest.mark.parametrize("roi", [Roi(150, 100, 288), Roi(120, 40, 384), Roi(200, 150, 200)])
def test_supersampled_crop_is_the_crop_training_renders(roi):
    """The synthetic training crops are point samples of the crop camera at 2S, box-reduced to S
    (``training/data/views.py``). A frame of a sharp pattern (periods of 7 and 9 frame pixels, 2-4 model
    pixels at these ROIs' scales 1.6-3) cropped with ``supersample=2`` gives that crop within ~3 levels (mean
    absolute); the one-sample remap (box steps + bilinear) blurred it away from it by 9-31 levels."""
    cam = Camera("c", 640, 480, [[400, 0, 319.5], [0, 400, 239.5], [0, 0, 1]], np.zeros(5))

    def pattern(u, v):
        return np.clip(np.round(128 + 60 * np.sin(2 * np.pi * u / 7.0) + 60 * np.sin(2 * np.pi * v / 9.0 + 1.0)),
                       0, 255).astype(np.uint8)

    vv, uu = np.mgrid[:480, :640].astype(np.float64)
    frame = pattern(uu, vv)
    hi = crop_camera(cam, roi, 256)
    uv = cam.normalized_to_pixels(hi.pixels_to_normalized(hi.pixel_grid()), distort=False)
    rendered = cv2.resize(pattern(uv[..., 0], uv[..., 1]), (128, 128), interpolation=cv2.INTER_AREA).astype(float)
    ours = apply_crop_maps(frame, build_undistort_crop_maps(cam, roi, 128, supersample=2)).astype(float)
    assert np.abs(ours - rendered).mean() < 3.5
    one = apply_crop_maps(frame, build_undistort_crop_maps(cam, roi, 128)).astype(float)
    assert np.abs(one - rendered).mean() > 8.0  # the blur the supersampling removes


def test_the_estimator_supersamples_its_crops_by_default():
    from ghnerf_runtime.config import ConfigError, RoiConfig

    assert RoiConfig().supersample == 2
    with pytest.raises(ConfigError, match="supersample"):
        RoiConfig(supersample=0)


def test_padding_outside_the_frame_is_zero():
    cam = make_camera(dist=np.zeros(5))
    maps = build_undistort_crop_maps(cam, Roi(-320, 0, 640), 128)
    out = apply_crop_maps(np.full((480, 640, 3), 200, np.uint8), maps)
    # The square leaves the frame on the left (x < 0) and at the bottom (y >= 480): zeros there.
    assert np.all(out[:, :60] == 0) and np.all(out[100:] == 0) and np.all(out[:90, 70:] == 200)


@pytest.mark.parametrize("roi, antialias, supersample", [
    (Roi(-320, 0, 640), True, 1), (Roi(-320, 0, 640), False, 1), (Roi(500, 380, 300), True, 1),
    (Roi(100, 50, 300), True, 1), (Roi(-320, 0, 640), True, 2), (Roi(500, 380, 300), True, 2),
    (Roi(100, 50, 300), True, 2)])
def test_inside_marks_exactly_the_pixels_that_show_the_frame(roi, antialias, supersample):
    """``CropMaps.inside``: a pixel it marks reads the frame alone (no blend with the zero padding), and the
    pixels it leaves out read padding (all but those within the fixed-point maps' 1/32 pixel of the edge); a
    crop inside the frame has ``inside`` None (every pixel)."""
    cam = make_camera()
    maps = build_undistort_crop_maps(cam, roi, 128, antialias=antialias, supersample=supersample)
    out = apply_crop_maps(np.full((480, 640), 200, np.uint8), maps)
    if maps.inside is None:
        assert np.all(out == 200)
        return
    assert np.all(out[maps.inside] == 200)
    assert (~maps.inside).sum() > 0 and np.mean(out[~maps.inside] < 200) > 0.97


def test_box_steps_keep_the_frame_edge_when_its_side_is_not_a_multiple_of_the_factor():
    """A crop wider than a 1000x600 frame at 16x (four box steps): neither side is a multiple of 16. The window
    once dropped the frame's last 8 columns and rows (shown as padding); now it reads them, its box steps padded
    by the frame's edge, and past the edge the model input is zeros as without the box steps."""
    K1 = np.array([[700.0, 0.0, 499.5], [0.0, 700.0, 299.5], [0.0, 0.0, 1.0]])
    cam = Camera("wide", 1000, 600, K1, np.zeros(5), np.eye(3), np.zeros(3))
    roi = Roi(0, -200, 1000)
    maps = build_undistort_crop_maps(cam, roi, 64)
    assert maps.level == 4 and maps.window == (0, 0, 1008, 608)
    frame = np.full((600, 1000), 200, np.uint8)
    out = apply_crop_maps(frame, maps)
    plain = apply_crop_maps(frame, build_undistort_crop_maps(cam, roi, 64, antialias=False))
    # The last column samples frame x = 991.7 and row 50 frame y = 592.2: frame (they read zeros before).
    assert np.all(out[13:51, -1] == 200) and np.all(out[50, :] == 200)
    # Below the frame (y >= 600) zeros; from row 13 down, pixel for pixel what the plain remap shows (row 12
    # blends the top edge with the padding in both, a little differently).
    assert np.all(out[51:] == 0) and np.array_equal(out[13:], plain[13:])
    assert np.all(out[maps.inside] == 200) and maps.inside[13:51, 1:].all()  # column 0 blends the left edge


# ---------------------------------------------------------------- normalisation
def test_preprocess_image_channel_order_and_normalisation():
    cam = make_camera()
    maps = build_undistort_crop_maps(cam, Roi(200, 100, 128), 64)
    frame = np.empty((480, 640, 3), np.uint8)
    frame[...] = (10, 20, 30)  # B, G, R
    rgb = preprocess_image(frame, maps, Normalisation())
    assert rgb.shape == (3, 64, 64) and rgb.dtype == np.float32 and rgb.flags.c_contiguous
    np.testing.assert_allclose(rgb[:, 32, 32], [30 / 255, 20 / 255, 10 / 255], atol=1e-6)
    bgr = preprocess_image(frame, maps, Normalisation(channel_order="BGR"))
    np.testing.assert_allclose(bgr[:, 32, 32], [10 / 255, 20 / 255, 30 / 255], atol=1e-6)
    host = Normalisation(mean=(0.5, 0.4, 0.3), std=(0.2, 0.25, 0.5), mean_std_in_graph=False,
                         value_range=(0.0, 1.0))
    x = preprocess_image(frame, maps, host)
    np.testing.assert_allclose(x[:, 32, 32], (np.array([30, 20, 10]) / 255 - [0.5, 0.4, 0.3]) / [0.2, 0.25, 0.5],
                               atol=1e-5)
    sym = preprocess_image(frame, maps, Normalisation(value_range=(-1.0, 1.0)))
    np.testing.assert_allclose(sym[:, 32, 32], np.array([30, 20, 10]) / 127.5 - 1, atol=1e-6)


@pytest.mark.parametrize("frame", [np.zeros((480, 640), np.uint8), np.zeros((480, 640, 3), np.float32),
                                   np.zeros((240, 320, 3), np.uint8)])
def test_preprocess_image_rejects_wrong_frames(frame):
    maps = build_undistort_crop_maps(make_camera(), Roi(200, 100, 128), 64)
    with pytest.raises(ShapeError):
        preprocess_image(frame, maps, Normalisation())


def test_a_wide_lens_that_folds_inside_the_image_still_gets_a_footprint_and_blank_folds():
    K_wide = np.array([[640.0, 0.0, 640.0], [0.0, 640.0, 400.0], [0.0, 0.0, 1.0]])
    R, t = look_at((0.3, -1.2, -0.4), (0.0, -0.9, 3.0))
    cam = Camera("wide", 1280, 800, K_wide, [-0.28, 0.09, 0.0, 0.0, -0.013], R, t)
    lo, hi = undistorted_image_bounds(cam)  # the corners cannot be undistorted: NaN there crashed this
    assert np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo < 0) and hi[0] > 1280
    assert roi_from_volume(cam, VOLUME).size > 0
    # A window reaching past the fold radius: the forward model would fold back onto the picture there
    # (a mirrored ring); those model pixels must be blank, as outside the frame.
    roi = Roi(-700, -400, 2700)
    crop = crop_camera(cam, roi, 64)
    xy = crop.pixels_to_normalized(crop.pixel_grid())
    past = np.hypot(xy[..., 0], xy[..., 1]) >= cam.fold_radius
    assert past.any() and (~past).any()
    frame = np.full((800, 1280), 200, np.uint8)
    out = apply_crop_maps(frame, build_undistort_crop_maps(cam, roi, 64))
    assert np.all(out[past] == 0)
    centre = np.hypot(xy[..., 0], xy[..., 1]) < 0.5
    assert centre.any() and np.all(out[centre] == 200)


@pytest.mark.parametrize("skew", [0.0, 2.0], ids=["opencv-maps", "skewed"])
@pytest.mark.parametrize("dist", [[0.0, 0.0, 0.3, 0.0], [0.0] * 8 + [1.0, 0.0, 0.0, 0.0]], ids=["p1", "s1"])
def test_a_crop_of_a_lens_folded_by_its_tangential_or_prism_terms_samples_nothing_beyond_the_fold(dist, skew):
    """The crop warp masked past the radial fold only: crop pixels past the nearer fold of strong tangential or
    thin-prism terms sampled frame pixels that a ray on the unfolded side shows (duplicated picture, over half
    of this crop). Now every crop pixel that samples the frame has its ray within the lens (Camera.within_lens,
    the limit project and undistortion use), and samples the pixel that undistorts to that ray."""
    R, t = look_at((0.3, -1.2, -0.4), (0.0, -0.9, 3.0))
    cam = Camera("wide", 640, 480, [[320.0, skew, 319.5], [0.0, 320.0, 239.5], [0.0, 0.0, 1.0]], dist, R, t)
    roi = Roi(80, 0, 480)  # the middle of the frame: half of it past the fold
    crop = crop_camera(cam, roi, 96)
    xy = crop.pixels_to_normalized(crop.pixel_grid())
    maps = build_undistort_crop_maps(cam, roi, 96, antialias=False)
    sampled = maps.map_x > -1e5  # not sent off every frame
    seen = sampled & (maps.map_x >= 0) & (maps.map_x <= 639) & (maps.map_y >= 0) & (maps.map_y <= 479)
    assert seen.sum() > 1000 and (~cam.within_lens(xy)).sum() > 1000
    assert cam.within_lens(xy[sampled]).all()
    rays = cam.pixels_to_normalized(np.stack([maps.map_x[seen], maps.map_y[seen]], axis=-1).astype(np.float64))
    np.testing.assert_allclose(rays, xy[seen], atol=1e-3)  # float32 maps, at the fold's nearly flat edge: 6e-5


@pytest.mark.parametrize("mounted_deg", [0, 10, 180, -170, 90, -90, -80])
def test_upright_roll_undoes_the_mounting_roll(mounted_deg):
    """A camera rolled about its optical axis: the crop rotation that shows the rig's down as the picture's down."""
    R, t = look_at((0.3, -1.2, -0.4), (0.0, -0.9, 3.0))
    a = np.radians(mounted_deg)  # the camera frame rolled about its z axis
    Rz = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    cam = Camera("rolled", 640, 480, K, DIST, Rz @ R, Rz @ t)
    roll = upright_roll_deg(cam)
    assert (roll - mounted_deg + 180) % 360 - 180 == pytest.approx(0.0, abs=1e-6)
    upright = crop_camera(cam, Roi(0, 0, 480), 128, roll)
    head, feet = upright.project(np.array([[0.0, -1.7, 3.0], [0.0, 0.0, 3.0]]))[0]
    assert feet[1] - head[1] > 20 * abs(feet[0] - head[0])  # a standing person stands straight in the crop
    looking_down = Camera("down", 640, 480, K, DIST, np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]), np.zeros(3))
    assert upright_roll_deg(looking_down) == 0.0


@pytest.mark.parametrize("roll", [0.0, 30.0, -45.0, 90.0])
def test_a_rotated_crop_is_sized_for_what_it_shows(roll):
    """A standing body seen through a camera rolled by roll: the crop rotated upright holds all of it,
    with the margin asked for, and not much more."""
    R, t = look_at((0.3, -1.2, -0.4), (0.0, -0.9, 3.0))
    a = np.radians(roll)
    Rz = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    cam = Camera("rolled", 640, 480, K, DIST, Rz @ R, Rz @ t)
    assert upright_roll_deg(cam) == pytest.approx(roll, abs=1e-9)
    body = np.array([[0.0, y, 3.0] for y in np.linspace(-1.7, 0.0, 18)] + [[-0.3, -1.4, 3.0], [0.3, -1.4, 3.0]])
    roi = roi_from_joints(cam, body, np.ones(len(body)), margin_frac=0.1, min_size=8, roll_deg=roll)
    crop = crop_camera(cam, roi, 128, roll)
    uv, _ = crop.project(body)
    assert np.all(uv >= 0) and np.all(uv <= 127)  # all of the body in the crop
    height = uv[:, 1].max() - uv[:, 1].min()
    assert 0.75 * 128 <= height <= 0.9 * 128  # the body fills the crop's height less the margins
    assert uv[:18, 1].argmin() == 0  # upright: the head on top
    vol = roi_from_volume(cam, VOLUME, roll_deg=roll)
    corners = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-2.0, 0.0) for z in (2.0, 4.0)])
    inside = crop_camera(cam, vol, 128, roll).project(corners)[0]
    lo, hi = undistorted_image_bounds(cam)
    assert vol.size <= 1.5 * max(hi - lo)  # a rotated crop of the volume stays about the image's size
    assert np.all(np.isfinite(inside))


@pytest.mark.parametrize("out_size", [float("nan"), float("inf"), None, "64"])
def test_an_out_size_that_is_no_whole_number_is_named(out_size):
    with pytest.raises(GeometryError, match="out_size must be a positive integer"):  # nan, inf: bare errors
        build_undistort_crop_maps(make_camera(), Roi(200, 100, 128), out_size)


@pytest.mark.parametrize("frame, why", [
    (np.zeros((480, 640, 3), np.int64), "dtype"), (np.zeros((480, 640, 3), bool), "dtype"),
    (np.zeros((480, 640), np.float16), "dtype"), (np.zeros((480, 640, 3), np.int8), "dtype"),
    (np.zeros((480, 640, 0), np.uint8), "channels"), (np.zeros((480, 640, 200), np.uint8), "channels"),
])
@pytest.mark.parametrize("size", [64, 256])  # without and with the box steps
def test_apply_crop_maps_names_a_frame_opencv_cannot_take(frame, why, size):
    maps = build_undistort_crop_maps(make_camera(), Roi(200, 100, size), 64)
    with pytest.raises(ShapeError, match=why) as e:  # was a bare cv2.error
        apply_crop_maps(frame, maps)
    assert str(frame.shape) in str(e.value) or str(frame.dtype) in str(e.value)


def test_compact_maps_crop_the_same_without_the_float_tables():
    """CropMaps.compact (what the estimator caches): no float tables, the same crop, frame mask and size."""
    from ghnerf_runtime.geometry.camera import Camera
    from ghnerf_runtime.preprocess import Roi, apply_crop_maps, build_undistort_crop_maps

    cam = Camera("c", 960, 600, [[700.0, 0, 480], [0, 700.0, 300], [0, 0, 1]], [-0.1, 0.02, 0, 0, 0])
    image = np.random.default_rng(0).integers(0, 256, (600, 960, 3), dtype=np.uint8)
    for roi, f in ((Roi(200, 100, 300), 2), (Roi(-100, -50, 400), 2), (Roi(300, 200, 128), 1)):
        maps = build_undistort_crop_maps(cam, roi, 128, supersample=f)
        small = maps.compact()
        assert small.map_x is None and small.map_y is None and small.out_size == maps.out_size == 128
        assert np.array_equal(apply_crop_maps(image, small), apply_crop_maps(image, maps))
        assert (small.inside is None) == (maps.inside is None)
        assert small.inside is None or np.array_equal(small.inside, maps.inside)


# --------------------------------------------------- extremes (session 51's numerical review)
def test_a_crop_far_off_the_frame_is_black_not_an_overflow():
    """A crop a billion pixels off a small frame: the lens polynomial sent the maps past float32 (inf), and
    rounding the box steps' window to a pixel raised a bare OverflowError. Nothing of the frame shows there."""
    cam = Camera("small", 7, 5, [[7.0, 0, 3.0], [0, 7.0, 2.0], [0, 0, 1]], [-0.2, 0.05, 0, 0, 0])
    for roi in (Roi(10**9, 10**9, 64), Roi(-10**9, 0, 64)):
        for supersample in (1, 2):
            maps = build_undistort_crop_maps(cam, roi, 16, supersample=supersample)
            out = apply_crop_maps(np.full((5, 7, 3), 200, np.uint8), maps)
            assert out.shape == (16, 16, 3) and not out.any()
            assert maps.inside is not None and not maps.inside.any()


def test_a_volume_reaching_far_around_the_camera_crops_the_whole_image():
    """A working volume of +-1e15 m (the rig file takes it: only an overflowing size is refused) holds the
    camera: where its edges cross the near plane, rounding left the crossing at depth 0 (x / 0 = inf, and
    0 skew * inf = NaN), so the ROI raised a bare "cannot convert float NaN to integer"."""
    cam = make_camera(dist=np.zeros(5))
    whole = roi_from_volume(cam, WorkingVolume([-1e3] * 3, [1e3] * 3))
    for extent in (1e15, 1e20, 1e200):
        assert roi_from_volume(cam, WorkingVolume([-extent] * 3, [extent] * 3)) == whole
    lo, hi = undistorted_image_bounds(cam)
    assert whole.size >= np.max(hi - lo)
    with pytest.raises(GeometryError, match="too large"):
        roi_from_volume(cam, VOLUME, margin=1.7e308)  # the grown corners overflow


@pytest.mark.parametrize("roll", [float("nan"), float("inf"), -float("inf")])
def test_a_roll_that_is_not_finite_is_named(roll):
    """NaN made a crop camera of NaNs (every mapped joint NaN), inf a bare "math domain error"."""
    cam = make_camera()
    with pytest.raises(GeometryError, match="finite"):
        crop_camera(cam.without_distortion(), Roi(100, 50, 300), 128, roll)
    with pytest.raises(GeometryError, match="finite"):
        roi_from_joints(cam, np.array([[100.0, 100], [300, 200], [200, 400]]), np.ones(3), roll_deg=roll)
    with pytest.raises(GeometryError, match="finite"):
        build_undistort_crop_maps(cam, Roi(100, 50, 300), 128, roll_deg=roll)


def test_a_min_size_that_is_not_finite_is_named():
    with pytest.raises(GeometryError, match="min_size"):  # was a bare "cannot convert float NaN to integer"
        roi_from_joints(make_camera(), np.array([[100.0, 100], [300, 200], [200, 400]]), np.ones(3),
                        min_size=float("nan"))


@pytest.mark.parametrize("channels", [None, 1, 2, 4])
@pytest.mark.parametrize("dtype, value", [(np.uint8, 200), (np.uint16, 60000), (np.float32, 0.5), (np.float64, -3.0)])
def test_frames_of_any_taken_layout_keep_their_shape_and_values(channels, dtype, value):
    """Grayscale, 1, 2 and 4 channels, uint16 and float frames, negative-stride and read-only views: the crop
    has the frame's channel axis and dtype (a (H, W, 1) frame came back (S, S): OpenCV drops that axis)."""
    cam = make_camera()
    shape = (480, 640) if channels is None else (480, 640, channels)
    frame = np.full(shape, value, dtype)[:, ::-1]  # a negative-stride view
    frame.flags.writeable = False
    for roi, supersample in ((Roi(200, 100, 128), 1), (Roi(-100, -60, 300), 2)):
        maps = build_undistort_crop_maps(cam, roi, 64, supersample=supersample)
        out = apply_crop_maps(frame, maps)
        assert out.shape == (64, 64) + shape[2:] and out.dtype == dtype
        inside = np.ones((64, 64), bool) if maps.inside is None else maps.inside
        assert np.all(out[inside] == value) and np.all(out[~inside] * np.sign(value) <= abs(value))


def test_a_gaussian_peak_round_trips_through_crops_that_pass_the_frame_edge():
    """A Gaussian dot drawn in the (distorted) frame at a known sub-pixel place, cropped (undistort, crop past
    the frame's edge, black padding, supersampled as the estimator does), decoded, and mapped back to frame
    pixels with ``model_to_image_pixels``: within 0.05 model pixels of where it was drawn. The mapping itself
    is exact (1e-6 px), also for crops a billion pixels off."""
    from ghnerf_runtime.keypoints import model_to_image_pixels

    cam = make_camera()
    yy, xx = np.mgrid[:480, :640].astype(np.float64)
    rng = np.random.default_rng(51)
    for roi, size, roll in ((Roi(-100, -60, 300), 128, 0.0), (Roi(400, 300, 300), 128, 30.0),
                            (Roi(-200, -200, 1000), 128, 0.0), (Roi(-50, 300, 256), 32, 0.0)):
        assert roi.x0 < 0 or roi.y0 < 0 or roi.x0 + roi.size > 640 or roi.y0 + roi.size > 480
        maps = build_undistort_crop_maps(cam, roi, size, roll_deg=roll, supersample=2)
        sigma = 2.0 * roi.size / size  # 2 model pixels
        drawn = 0
        for q in rng.uniform(6, size - 7, (40, 2)):
            p = model_to_image_pixels(q, cam, roi, size, roll_deg=roll)
            if not (3 * sigma < p[0] < 639 - 3 * sigma and 3 * sigma < p[1] < 479 - 3 * sigma):
                continue  # on the padding, or cut by the frame's edge
            dot = np.clip(255 * np.exp(-((xx - p[0]) ** 2 + (yy - p[1]) ** 2) / (2 * sigma ** 2)), 0, 255)
            crop = apply_crop_maps(dot.astype(np.uint8), maps).astype(np.float32) / 255
            kp = decode_keypoints(crop[None], KeypointDecoderConfig(sigma=0.0))
            assert kp.valid[0] and np.linalg.norm(kp.uv[0] - q) < 0.05, (roi, q, kp.uv[0])
            back = model_to_image_pixels(kp.uv, cam, roi, size, valid=kp.valid, roll_deg=roll)[0]
            assert np.linalg.norm(back - p) < 0.05 * roi.size / size
            drawn += 1
            if drawn == 4:
                break
        assert drawn == 4, roi
    pinhole = cam.without_distortion()
    for roi in (Roi(-100, -60, 300), Roi(10**9, -10**9, 64)):
        crop = crop_camera(pinhole, roi, 128)
        uv = rng.uniform(-0.5, 127.5, (20, 2))
        back = roi.image_to_model(model_to_image_pixels(uv, pinhole, roi, 128), 128)
        np.testing.assert_allclose(back, uv, atol=1e-6)
        if roi.size > 64:  # (a billion pixels off, the rays graze the image plane: 3D points lose precision)
            origin, direction = pinhole.rays(roi.model_to_image(uv, 128))  # points on those pixels' rays
            np.testing.assert_allclose(crop.project(origin + 2.0 * direction)[0], uv, atol=1e-6)


def _body_px(x_centre: float) -> np.ndarray:
    """A standing person's joints (pixels of a lens-free camera): 300 px tall, 100 px wide."""
    ys = np.linspace(100.0, 400.0, 12)
    return np.concatenate([np.stack([np.full(12, x_centre), ys], axis=1), [[x_centre - 50, 180], [x_centre + 50, 180]]])


@pytest.mark.parametrize("roll", [0.0, 30.0])
def test_a_box_past_the_frame_edge_is_cropped_as_the_policy_says(roll):
    """A person whose box runs past the frame's left edge: ``clip`` squares what the frame shows (the person
    off-centre), ``centre`` keeps the whole box's square (the person at the crop's centre, the size the same as
    inside the frame), ``shift`` moves that square inside the frame (no black)."""
    cam = make_camera(dist=np.zeros(5))
    lo, hi = undistorted_image_bounds(cam)
    inside = {e: roi_from_joints(cam, _body_px(320.0), np.ones(14), 0.125, 8, roll_deg=roll, edge_crop=e)
              for e in ("clip", "centre", "shift")}
    assert len(set(inside.values())) == 1  # a box well inside the frame: all three policies agree
    body = _body_px(20.0)  # its left 30 px (and the margin) past the frame
    rois = {e: roi_from_joints(cam, body, np.ones(14), 0.125, 8, roll_deg=roll, edge_crop=e)
            for e in ("clip", "centre", "shift")}
    turned = body @ preprocess.image_rotation(roll).T  # the box as the turned crop sees it
    centre = preprocess.image_rotation(roll).T @ (0.5 * (turned.min(axis=0) + turned.max(axis=0)))
    for e, roi in rois.items():
        assert abs(roi.size - inside["clip"].size) <= 1, e  # the same scale as inside the frame
        off = np.abs(np.array([roi.x0, roi.y0]) + (roi.size - 1) / 2 - centre)
        if e == "centre":
            assert np.all(off <= 1.0)
        elif e == "shift" or roll == 0.0:  # (turned 30 degrees, clipping the one joint out moves little)
            assert off[0] > 20.0, e  # moved inward, the person off-centre
    turn = np.abs(preprocess.image_rotation(roll)).sum(axis=1) * rois["shift"].size / 2  # half-extent
    mid = np.array([rois["shift"].x0, rois["shift"].y0]) + (rois["shift"].size - 1) / 2
    assert mid[0] - turn[0] >= lo[0] - 1.0  # the shifted square leaves the frame nowhere on the left
    assert rois["centre"].x0 <= rois["clip"].x0 < rois["shift"].x0


@pytest.mark.parametrize("roll", [0.0, 30.0])
@pytest.mark.parametrize("corner", [(0, 0), (639, 0), (0, 479), (639, 479)], ids=str)
def test_a_small_person_at_the_frame_corner_is_shifted_inside_whole(roll, corner):
    """``shift`` with a box smaller than ``min_size`` (a far person, 30 px tall, at a corner of the frame): the
    square grown to ``min_size`` is the one moved inside. It was moved as the box's own small square, then grown
    about that centre: half of the 64 px crop past the frame, the black (or faded) band ``shift`` is chosen to
    avoid."""
    cam = make_camera(dist=np.zeros(5))
    lo, hi = undistorted_image_bounds(cam)
    inward = np.sign(np.array([320.0, 240.0]) - corner)
    body = np.array(corner, np.float64) + inward * np.array([[2.0, 2.0], [10.0, 30.0], [6.0, 16.0]])
    roi = roi_from_joints(cam, body, np.ones(3), 0.125, 64, roll_deg=roll, edge_crop="shift")
    assert roi.size >= 64
    half = np.abs(preprocess.image_rotation(roll)).sum(axis=1) * roi.size / 2  # the turned square's half-extent
    mid = np.array([roi.x0, roi.y0]) + (roi.size - 1) / 2
    assert np.all(mid - half >= lo - 0.5) and np.all(mid + half <= hi + 0.5), (roi, lo, hi)


def test_the_edge_crop_policy_is_checked():
    with pytest.raises(GeometryError, match="edge_crop"):
        roi_from_joints(make_camera(), _body_px(320.0), np.ones(14), edge_crop="pad")


@pytest.mark.parametrize("roi, supersample", [(Roi(-60, 100, 200), 1), (Roi(-300, -50, 700), 1),
                                              (Roi(-300, -50, 700), 2), (Roi(500, 300, 260), 2)])
def test_the_edge_pad_fill_repeats_the_frame_edge_past_it(roi, supersample):
    """``pad_fill="edge"``: where the crop runs past the frame, it shows the frame's nearest edge pixel, not 0
    (the shipped model reads a black band as much worse than that: docs/runtime.md, "A person at the frame's
    edge"); what lies inside the frame, and ``inside``, are as with black padding."""
    cam = make_camera(dist=np.zeros(5))
    image = np.full((480, 640, 3), 40, np.uint8)
    image[:, :8] = (200, 150, 100)  # a bright left edge, a dim bottom-right corner
    image[-8:, -8:] = (10, 20, 30)
    black = build_undistort_crop_maps(cam, roi, 64, supersample=supersample)
    edge = build_undistort_crop_maps(cam, roi, 64, supersample=supersample, pad_fill="edge")
    assert black.inside is not None and np.array_equal(black.inside, edge.inside)
    a, b = apply_crop_maps(image, black), apply_crop_maps(image, edge)
    assert np.array_equal(a[black.inside], b[black.inside])
    out = ~black.inside
    assert np.mean(a[out] == 0) > 0.8  # black (but for bilinear taps into the frame along its edge)
    assert np.all(b[out].min(axis=-1) >= 10)  # the frame's edge, not 0
    if roi.x0 < 0:
        assert np.all(b[16:-16, 1] == (200, 150, 100))  # left of the frame: its left edge repeated
    else:
        assert np.all(b[-2, -2] == (10, 20, 30))  # past the bottom-right corner: the corner pixel


@pytest.mark.parametrize("fill", ["edge", "fade"])
def test_a_pad_fill_changes_nothing_for_a_crop_inside_the_frame(fill):
    cam = make_camera()
    image = smooth_image()
    black = build_undistort_crop_maps(cam, Roi(200, 100, 200), 64, supersample=2)
    filled = build_undistort_crop_maps(cam, Roi(200, 100, 200), 64, supersample=2, pad_fill=fill)
    assert black.inside is None and filled.inside is None and filled.fade is None
    assert np.array_equal(apply_crop_maps(image, black), apply_crop_maps(image, filled))


def test_the_pad_fill_and_the_fade_s_reach_are_checked():
    cam = make_camera()
    with pytest.raises(GeometryError, match="pad_fill"):
        build_undistort_crop_maps(cam, Roi(200, 100, 200), 64, pad_fill="mirror")
    for bad in (-0.1, 1.5, float("nan"), "0.1"):
        with pytest.raises(GeometryError, match="pad_fade"):
            build_undistort_crop_maps(cam, Roi(200, 100, 200), 64, pad_fill="fade", pad_fade=bad)


@pytest.mark.parametrize("roi, supersample", [(Roi(-60, 100, 200), 1), (Roi(-300, -50, 700), 1),
                                              (Roi(-300, -50, 700), 2), (Roi(500, 300, 260), 2)])
def test_the_fade_pad_fill_fades_the_frame_edge_into_the_crop_mean(roi, supersample):
    """``pad_fill="fade"``: inside the frame the crop (and ``inside``) is black padding's; past the edge it shows
    the frame's edge pixel, blended into the crop's in-frame mean colour by ``pad_fade`` crop sides out (the
    shipped model reads that as much better than black or the edge alone: docs/runtime.md, "A person at the
    frame's edge")."""
    cam = make_camera(dist=np.zeros(5))
    image = np.full((480, 640, 3), 40, np.uint8)
    image[:, :8] = (200, 150, 100)  # a bright left edge, a dim bottom-right corner
    image[-8:, -8:] = (10, 20, 30)
    black = build_undistort_crop_maps(cam, roi, 64, supersample=supersample)
    fade = build_undistort_crop_maps(cam, roi, 64, supersample=supersample, pad_fill="fade", pad_fade=0.1)
    assert black.inside is not None and np.array_equal(black.inside, fade.inside)
    a, b = apply_crop_maps(image, black), apply_crop_maps(image, fade)
    assert b.shape == a.shape and b.dtype == np.uint8
    assert np.array_equal(a[black.inside], b[black.inside])  # the frame itself untouched
    mean = a[black.inside].reshape(-1, 3).mean(axis=0)
    # Model pixel centres and their distance past the frame, in crop sides (no lens: undistorted = frame pixels).
    u = roi.x0 + (np.arange(64) + 0.5) * roi.size / 64 - 0.5
    v = roi.y0 + (np.arange(64) + 0.5) * roi.size / 64 - 0.5
    dx = np.maximum(np.maximum(-u, u - 639), 0)[None, :]
    dy = np.maximum(np.maximum(-v, v - 479), 0)[:, None]
    beyond = np.hypot(dx, dy) / roi.size
    far = beyond > 0.1 + 2 / 64  # wholly faded, bilinear taps and box means included
    assert far.sum() > 100 and np.all(np.abs(b[far] - mean) <= 1.0)
    if roi.x0 < 0:  # just left of the frame: nearly its left edge, fading towards the mean further out
        col = int(np.flatnonzero(~black.inside[32]).max())  # the model column nearest the frame's left edge
        near = b[16:-16, col].astype(float)
        assert np.all(np.abs(near - (200, 150, 100)) < np.abs(near - mean))
        row = b[32, : col + 1, 0].astype(int)
        assert np.all(np.diff(row) >= -1) and row[-1] > row[0] + 50
    else:  # past the bottom-right corner: the corner pixel, fading into the mean
        assert np.all(np.abs(b[-1, -1].astype(int) - mean) < np.abs(np.array((10, 20, 30)) - mean))


def test_the_fade_pad_fill_at_zero_shows_the_crop_mean_past_the_edge_in_any_frame_type():
    cam = make_camera(dist=np.zeros(5))
    roi = Roi(-300, -50, 700)
    maps = build_undistort_crop_maps(cam, roi, 64, supersample=2, pad_fill="fade", pad_fade=0.0)
    image = smooth_image()
    for frame in (image, image[:, :, :1], image[:, :, 0], image.astype(np.float32), image.astype(np.uint16)):
        black = apply_crop_maps(frame, build_undistort_crop_maps(cam, roi, 64, supersample=2))
        out = apply_crop_maps(frame, maps)
        assert out.shape == black.shape and out.dtype == frame.dtype
        inside = maps.inside
        np.testing.assert_array_equal(out[inside], black[inside])
        far = np.zeros_like(inside)
        far[:, : 64 * 300 // 700 - 2] = True  # left of the frame, clear of the boundary's box means
        mean = black[inside].reshape(int(inside.sum()), -1).astype(np.float64).mean(axis=0)
        np.testing.assert_allclose(out[far].reshape(int(far.sum()), -1), np.broadcast_to(mean, (int(far.sum()),
                                   mean.size)), atol=1.0)


# ---------------------------------------------------------------- the maps' reductions (session 67: speed)
@pytest.mark.parametrize("dtype", [np.float32, np.float64])  # the fade's weights are float32, at 0 reach float64
@pytest.mark.parametrize("f", [1, 2, 3, 4, 5, 7, 8, 9])
def test_block_means_are_numpy_s_block_means_to_the_bit(f, dtype):
    """The strided adds give numpy's own block means (the crops the model sees do not move), for the block sides
    the config takes (1-4) and past them (8 on: numpy's unrolled sums, left to numpy). Bit for bit with the pinned
    numpy on the hosts measured; a last-bit rounding apart is allowed, since numpy's summation order may follow the
    CPU's SIMD (an ARM board's numpy may sum otherwise), and that moves no crop by a visible amount."""
    rng = np.random.default_rng(f)
    n = 96 // f
    # non-negative, as the fade's weights are: any summation order is then within f * f roundings of another
    values = (rng.uniform(0.0, 1.0, (n * f, n * f)) * 10.0 ** rng.uniform(-8, 0, (n * f, n * f))).astype(dtype)
    want = values.reshape(n, f, n, f).mean(axis=(1, 3))
    got = preprocess._block_means(values, f)
    assert got.dtype == want.dtype and got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=f * f * np.finfo(dtype).eps, atol=0)


@pytest.mark.parametrize("f", [1, 2, 3, 4])
def test_block_all_is_numpy_s_block_all(f):
    rng = np.random.default_rng(10 + f)
    n = 96 // f
    mask = rng.uniform(size=(n * f, n * f)) < 0.97  # blocks both whole and not
    want = mask.reshape(n, f, n, f).all(axis=(1, 3))
    assert want.any() and not want.all()
    np.testing.assert_array_equal(preprocess._block_all(mask, f), want)


def test_distance_past_frame_is_the_hypot_of_the_offsets_to_the_frame():
    """The hypot taken only past a corner, ``|dx| + |dy|`` elsewhere, yet the same numbers as ``np.hypot`` over the
    whole plane (0 inside, past one edge, past a corner, the overflow marker, inf and NaN as they were)."""
    rng = np.random.default_rng(3)
    map_x = rng.uniform(-80.0, 720.0, (64, 64)).astype(np.float32)
    map_y = rng.uniform(-60.0, 540.0, (64, 64)).astype(np.float32)
    map_x[0, :4] = [preprocess._OUTSIDE, np.inf, -np.inf, 639.0]
    map_y[1, :2] = [preprocess._OUTSIDE, 479.0]
    map_x[2, :3], map_y[2, :3] = [np.nan, np.nan, np.inf], [0.0, -5.0, np.nan]  # none reach it, but as hypot
    map_x[3, :2], map_y[3, :2] = [-3.0, 700.0], [-4.0, 500.0]  # past a corner: the hypot itself
    want = np.hypot(map_x - np.clip(map_x, 0, 639), map_y - np.clip(map_y, 0, 479))
    got = preprocess._distance_past_frame(map_x, map_y, (640, 480))
    assert got.dtype == want.dtype and np.array_equal(got, want, equal_nan=True)
    assert got[~np.isnan(got)].tobytes() == want[~np.isnan(want)].tobytes()
    within = rng.uniform(0.0, 639.0, (64, 64)).astype(np.float32), rng.uniform(0.0, 479.0, (64, 64)).astype(np.float32)
    inside = preprocess._distance_past_frame(*within, (640, 480))
    assert inside.dtype == np.float32 and not inside.any()
