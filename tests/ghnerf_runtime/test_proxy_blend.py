"""The body proxy built from 3D joints (``ghnerf_runtime.body_proxy``) and the novel view recoloured at its
depth (``ghnerf_runtime.proxy_blend``), against the simulator's truth."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from ghnerf_runtime.body25 import JOINT_INDEX
from ghnerf_runtime.body_proxy import BodyProxy, proxy_body, proxy_depth
from ghnerf_runtime.config import ConfigError, NovelViewConfig
from ghnerf_runtime.contract import Normalisation
from ghnerf_runtime.errors import ShapeError
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.metrics import masked_psnr
from ghnerf_runtime.novel_view import interpolate_camera, novel_target
from ghnerf_runtime.preprocess import Roi, build_undistort_crop_maps, preprocess_image
from ghnerf_runtime.proxy_blend import model_input_to_rgb, proxy_blend

pytest.importorskip("drivers.sim")  # the shot fixture renders with the simulator


def test_the_proxy_of_the_true_joints_lies_on_the_simulated_body(shot):
    joints, _, _, target, _, truth = shot
    depth = proxy_depth(proxy_body(joints, np.ones(25, bool)), target)
    hit = depth > 0
    assert (hit & truth.mask).sum() / (hit | truth.mask).sum() > 0.8
    assert np.median(np.abs(depth - truth.depth)[hit & truth.mask]) < 0.02


def test_the_blend_at_the_proxy_depth_gives_the_subject_its_own_colours(shot):
    joints, sources, rgb, target, image, truth = shot
    grey = np.full((128, 128, 3), 77, np.uint8)
    out = proxy_blend(grey, target, proxy_body(joints, np.ones(25, bool)), sources, rgb)
    r = out.replaced
    assert r.sum() > 1000 and (r & truth.mask).sum() / r.sum() > 0.85  # it recolours the subject
    assert np.array_equal(out.image[~r], grey[~r])  # and nothing else
    pred, want = out.image[..., ::-1] / 255.0, image[..., ::-1] / 255.0
    assert masked_psnr(pred, want, r & truth.mask).value > 23.0
    assert np.array_equal(r, r & (out.depth > 0))


def test_at_a_source_cameras_own_viewpoint_its_pixels_are_copied(shot):
    """The angular weights: on the first source's own rays its colour dominates, whatever the proxy's depth
    error, so the blend there is that source's image."""
    joints, sources, rgb, _, _, _ = shot
    out = proxy_blend(np.zeros((128, 128, 3), np.uint8), sources[0], proxy_body(joints, np.ones(25, bool)),
                      sources, rgb)
    r = out.replaced
    assert r.sum() > 1000
    assert masked_psnr(out.image[..., ::-1] / 255.0, rgb[0].astype(np.float64), r).value > 35.0


def test_pixels_no_source_sees_within_the_angle_keep_the_picture(shot):
    joints, sources, rgb, target, _, _ = shot
    body = proxy_body(joints, np.ones(25, bool))
    image = np.full((128, 128, 3), 5, np.uint8)
    wide = proxy_blend(image, target, body, sources, rgb, max_angle_deg=60.0)
    narrow = proxy_blend(image, target, body, sources, rgb, max_angle_deg=1.0)  # halfway: both sources ~10 deg off
    assert wide.replaced.sum() > 1000 and not narrow.replaced.any()
    assert np.array_equal(narrow.image, image)
    with pytest.raises(ConfigError, match="proxy_max_angle_deg"):
        NovelViewConfig(proxy_max_angle_deg=200.0)


def test_only_the_region_given_is_recoloured(shot):
    joints, sources, rgb, target, _, truth = shot
    body = proxy_body(joints, np.ones(25, bool))
    out = proxy_blend(np.zeros((128, 128, 3), np.uint8), target, body, sources, rgb, region=truth.mask)
    assert out.replaced.any() and not out.replaced[~truth.mask].any()
    with pytest.raises(ShapeError, match="region must be"):
        proxy_blend(np.zeros((128, 128, 3), np.uint8), target, body, sources, rgb, region=truth.mask[:64])


def test_a_source_behind_the_body_lends_no_colour(shot):
    """Visibility: a surface point is coloured only by sources whose own proxy depth there is its depth."""
    joints, sources, rgb, target, _, _ = shot
    body = proxy_body(joints, np.ones(25, bool))
    # the same target seen from behind the subject: the rig's cameras see only its other side
    behind = novel_target(interpolate_camera(*[_mirror(c, joints) for c in sources], 0.5), _box(joints), 128)
    out = proxy_blend(np.zeros((128, 128, 3), np.uint8), behind, body, sources, rgb)
    front = proxy_blend(np.zeros((128, 128, 3), np.uint8), target, body, sources, rgb)
    assert out.replaced.sum() < 0.5 * front.replaced.sum()
    assert (out.depth > 0).sum() > 0.5 * (front.depth > 0).sum()  # the proxy is there, unseen


def _box(joints):
    return np.stack([joints.min(0) - 0.15, joints.max(0) + 0.15])


def _mirror(camera, joints):
    """``camera`` moved to the other side of the subject (its centre mirrored through the body's), looking at it."""
    from ghnerf_runtime.geometry.camera import Camera, look_at

    centre = joints.mean(0)
    R, t = look_at(2 * centre - camera.center, centre)
    return Camera("behind", camera.width, camera.height, camera.K, np.zeros(5), R, t)


def test_missing_joints_drop_their_parts_and_no_joints_leave_the_view_alone(shot):
    joints, sources, rgb, target, _, _ = shot
    valid = np.ones(25, bool)
    valid[[JOINT_INDEX["LKnee"], JOINT_INDEX["RKnee"]]] = False
    fewer = proxy_body(joints, valid)
    assert len(fewer.cone_a) == len(proxy_body(joints, np.ones(25, bool)).cone_a) - 4
    nan = joints.copy()
    nan[JOINT_INDEX["LWrist"]] = np.nan  # a NaN joint counts as missing, never a NaN depth
    assert np.isfinite(proxy_depth(proxy_body(nan, np.ones(25, bool)), target)).all()
    empty = proxy_body(joints, np.zeros(25, bool))
    assert isinstance(empty, BodyProxy) and empty.empty
    image = np.full((128, 128, 3), 9, np.uint8)
    out = proxy_blend(image, target, empty, sources, rgb)
    assert np.array_equal(out.image, image) and not out.replaced.any()


def test_bad_inputs_are_named(shot):
    joints, sources, rgb, target, _, _ = shot
    body = proxy_body(joints, np.ones(25, bool))
    with pytest.raises(ShapeError, match="image must be uint8"):
        proxy_blend(np.zeros((64, 64, 3), np.uint8), target, body, sources, rgb)
    with pytest.raises(ShapeError, match="2 source cameras for 1 source images"):
        proxy_blend(np.zeros((128, 128, 3), np.uint8), target, body, sources, rgb[:1])
    with pytest.raises(ShapeError, match="does not match its camera"):
        proxy_blend(np.zeros((128, 128, 3), np.uint8), target, body, sources, rgb[:, :64])
    with pytest.raises(ShapeError, match=r"\(N, 3, S, S\)"):
        model_input_to_rgb(np.zeros((3, 8, 8)), Normalisation())


@pytest.mark.parametrize("norm", [Normalisation(), Normalisation(channel_order="BGR", mean_std_in_graph=False),
                                  Normalisation(value_range=(-1.0, 1.0), mean_std_in_graph=False)])
def test_model_input_to_rgb_undoes_the_preprocessing(norm):
    from ghnerf_runtime.geometry.camera import Camera, intrinsics_from_fov

    rng = np.random.default_rng(3)
    frame = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    cam = Camera("c", 64, 48, intrinsics_from_fov(64, 48, 60.0))
    maps = build_undistort_crop_maps(cam, Roi(8, 4, 32), 16)
    x = preprocess_image(frame, maps, norm)
    rgb = model_input_to_rgb(x[None], norm)[0]
    crop = preprocess_image(frame, maps, Normalisation(mean_std_in_graph=True))  # RGB in [0, 1]
    assert np.allclose(rgb, crop.transpose(1, 2, 0), atol=1e-5)


def test_proxy_blend_config_is_validated():
    assert NovelViewConfig().proxy_blend is True
    with pytest.raises(ConfigError, match="proxy_blend"):
        NovelViewConfig(proxy_blend="yes")
    with pytest.raises(ConfigError, match="proxy_tolerance_m"):
        NovelViewConfig(proxy_tolerance_m=0.0)


def test_depth_given_by_the_caller_gives_the_same_blend(shot):
    joints, sources, rgb, target, _, _ = shot
    body = proxy_body(joints, np.ones(25, bool))
    image = np.full((128, 128, 3), 5, np.uint8)
    own = proxy_blend(image, target, body, sources, rgb)
    given = proxy_blend(image, target, body, sources, rgb, source_depth=[proxy_depth(body, c) for c in sources],
                        depth=proxy_depth(body, target))
    assert np.array_equal(own.image, given.image) and own.replaced.sum() > 1000
    region = np.zeros((128, 128), bool)
    region[30:90, 40:100] = True
    boxed = proxy_blend(image, target, body, sources, rgb, region=region)
    whole = proxy_blend(image, target, body, sources, rgb, region=region, depth=proxy_depth(body, target))
    assert np.array_equal(boxed.image, whole.image) and np.array_equal(boxed.replaced, whole.replaced)
    with pytest.raises(ShapeError, match="depth must be"):
        proxy_blend(image, target, body, sources, rgb, depth=np.zeros((4, 4)))
    with pytest.raises(ShapeError, match="source depth"):
        proxy_blend(image, target, body, sources, rgb, source_depth=[np.zeros((4, 4))] * 2)
    with pytest.raises(ShapeError, match="2 source cameras for 1 source depth"):
        proxy_blend(image, target, body, sources, rgb, source_depth=[np.zeros((128, 128))])


def test_sample_at_reads_any_number_of_points_as_remap_does():
    import cv2

    from ghnerf_runtime.proxy_blend import SAMPLE_ROW, sample_at

    rng = np.random.default_rng(0)
    image = rng.random((50, 70, 3)).astype(np.float32)
    n = 3 * SAMPLE_ROW + 17  # rows padded: the tail must not leak
    u, v = rng.uniform(-2, 72, n).astype(np.float32), rng.uniform(-2, 52, n).astype(np.float32)
    want = np.concatenate([cv2.remap(image, u[i:i + 1000, None], v[i:i + 1000, None], cv2.INTER_LINEAR,
                                     borderMode=cv2.BORDER_CONSTANT).reshape(-1, 3) for i in range(0, n, 1000)])
    assert np.array_equal(sample_at(image, u, v, cv2.INTER_LINEAR), want)
    assert sample_at(image[..., 0], u[:0], v[:0], cv2.INTER_NEAREST).shape == (0,)


def test_a_subject_covering_more_than_32767_pixels_is_blended(shot):
    """A large novel view: one (N, 1) remap map of the subject's pixels was past OpenCV's 32767-row limit,
    and the blend raised cv2.error out of the estimator (a model of 256 px or more, the subject filling its view, reaches it)."""
    joints, sources, rgb, target, _, truth = shot
    big = novel_target(interpolate_camera(target, target, 0.0), np.stack([joints.min(0) - 0.15,
                                                                          joints.max(0) + 0.15]), 640)
    grey = np.full((640, 640, 3), 77, np.uint8)
    out = proxy_blend(grey, big, proxy_body(joints, np.ones(25, bool)), sources, rgb)
    assert (out.depth > 0).sum() > 32767 and out.replaced.sum() > 0.5 * (out.depth > 0).sum()
    small = proxy_blend(np.full((128, 128, 3), 77, np.uint8), target, proxy_body(joints, np.ones(25, bool)),
                        sources, rgb)
    # the same subject, the same colours: the big view's mean colour over its recoloured pixels matches
    assert np.abs(out.image[out.replaced].mean(0) - small.image[small.replaced].mean(0)).max() < 6.0


def test_8_bit_source_images_are_named_not_taken_for_white(shot):
    # uint8 crops (0..255) were clipped to [0, 1] in the blend: every recoloured pixel came out white
    joints, sources, rgb, target, image, _ = shot
    body = proxy_body(joints, np.ones(25, bool))
    rgb8 = np.round(rgb * 255.0)
    for bad in (rgb8.astype(np.uint8), rgb8):
        with pytest.raises(ShapeError, match=r"source image 0 must be float RGB in \[0, 1\].*divide by 255"):
            proxy_blend(image, target, body, sources, bad)
    ok = proxy_blend(image, target, body, sources, rgb.astype(np.float64))
    assert ok.replaced.sum() > 500 and ok.image[ok.replaced].mean() < 200  # the subject's colours, not white


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_source_colours_are_named_not_blended(shot, bad):
    # NaN passed both bounds of the [0, 1] check: the pixels blended from it came out as whatever uint8 NaN
    # casts to (black here), with a RuntimeWarning at most
    joints, sources, rgb, target, image, _ = shot
    body = proxy_body(joints, np.ones(25, bool))
    broken = rgb.copy()
    broken[1, 40:90, 40:90] = bad
    with pytest.raises(ShapeError, match=r"source image 1 must be float RGB in \[0, 1\], got 7500 non-finite values"):
        proxy_blend(image, target, body, sources, broken)



def test_a_proxy_point_at_the_view_cameras_centre_has_a_direction(shot):
    """A depth of 1e-300 puts a pixel's proxy point at the view camera's centre (exactly, for this level camera:
    ``R`` the identity), which is also a third source's centre here. Its directions to the view and to that source
    were ``center - point`` normalised: 0/0, a RuntimeWarning, and NaN weights that dropped the pixel only by
    chance. Now the direction to the view is the pixel's ray reversed and a source at the point sees none of it:
    no warning; the pixel keeps the picture, every other pixel blends as it did."""
    joints, sources, rgb, target, _, _ = shot
    level = Camera("level", 128, 128, target.K, np.zeros(5), np.eye(3), -target.center)
    body = proxy_body(joints, np.ones(25, bool))
    depth = proxy_depth(body, level)
    rows, cols = np.nonzero(depth > 0)
    r, c = rows[len(rows) // 2], cols[len(cols) // 2]
    at_centre = depth.copy()
    at_centre[r, c] = 1e-300
    cams, images = [*sources, level], np.concatenate([rgb, np.full((1, 128, 128, 3), 0.5, np.float32)])
    image = np.full((128, 128, 3), 5, np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning (divide by zero, invalid value) fails the test
        out = proxy_blend(image, level, body, cams, images, depth=at_centre)
    before = proxy_blend(image, level, body, cams, images, depth=depth)
    others = np.ones(depth.shape, bool)
    others[r, c] = False
    assert before.replaced[r, c] and not out.replaced[r, c] and np.array_equal(out.image[r, c], image[r, c])
    assert np.array_equal(out.image[others], before.image[others]) and before.replaced.sum() > 1000
