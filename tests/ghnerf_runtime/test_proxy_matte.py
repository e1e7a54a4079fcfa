"""The novel view's fog matted out away from the body proxy (``ghnerf_runtime.proxy_matte``), on the
simulated person."""
from __future__ import annotations

import numpy as np
import pytest

from ghnerf_runtime.body25 import JOINT_INDEX
from ghnerf_runtime.body_proxy import proxy_body, proxy_depth
from ghnerf_runtime.config import ConfigError, NovelViewConfig
from ghnerf_runtime.errors import ShapeError
from ghnerf_runtime.metrics import masked_psnr
from ghnerf_runtime.proxy_matte import proxy_matte, reach_spheres

pytest.importorskip("drivers.sim")  # the shot fixture renders with the simulator


def foggy(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The person over black, with the simulator's room at 40% around it: the model's coloured fog."""
    fog = np.round(image * 0.4).astype(np.uint8)
    return np.where(mask[..., None], image, fog)


def test_fog_away_from_the_person_goes_and_the_person_stays(shot):
    joints, _, _, target, image, truth = shot
    picture = foggy(image, truth.mask)
    want = np.where(truth.mask[..., None], image, 0)  # the person over the black background
    depth = proxy_depth(proxy_body(joints, np.ones(25, bool)), target)
    region = picture.max(axis=-1) >= 13
    out = proxy_matte(picture, target, depth, region, background=0.0)
    assert out.applied
    kept = out.weight[truth.mask]
    assert (kept == 1.0).mean() > 0.99  # the proxy of the true joints keeps the person whole
    far = out.weight == 0.0
    assert far.mean() > 0.3 and not out.image[far].any()  # the room far from the person is background
    assert np.array_equal(out.image[out.weight == 1.0], picture[out.weight == 1.0])  # the rest untouched
    everything = np.ones(truth.mask.shape, bool)
    before, after = (masked_psnr(x[..., ::-1] / 255.0, want[..., ::-1] / 255.0, everything).value
                     for x in (picture, out.image))
    assert after > before + 5.0, (before, after)
    assert masked_psnr(out.image / 255.0, want / 255.0, truth.mask).value > 40.0


def test_the_margin_is_metric_so_the_matte_follows_the_subject_not_the_resolution(shot):
    joints, _, _, target, image, truth = shot
    body = proxy_body(joints, np.ones(25, bool))
    shares = []
    for size in (128, 256):
        camera = target.resized(size, size)
        depth = proxy_depth(body, camera)
        picture = np.full((size, size, 3), 200, np.uint8)
        out = proxy_matte(picture, camera, depth, np.ones((size, size), bool), 0.0, margin_m=0.1, feather_m=0.0)
        assert set(np.unique(out.weight)) == {0.0, 1.0}  # no feather: a hard edge
        shares.append((out.weight > 0).mean())
    assert shares[1] == pytest.approx(shares[0], rel=0.05)
    wide = proxy_matte(np.full((128, 128, 3), 200, np.uint8), target, proxy_depth(body, target),
                       np.ones((128, 128), bool), 0.0, margin_m=0.2, feather_m=0.0)
    assert (wide.weight > 0).mean() > shares[0] + 0.05


def test_nothing_is_matted_where_the_picture_disagrees_with_the_proxy_or_there_is_none(shot):
    """Wrong joints put the proxy where the picture shows no one: the matte would cut the person, so it
    does not run; nor does it without a proxy in view."""
    joints, _, _, target, image, truth = shot
    picture = foggy(image, truth.mask)
    body = proxy_body(joints + np.array([0.8, 0.0, 0.0]), np.ones(25, bool))  # 80 cm off to the side
    depth = proxy_depth(body, target)
    assert (depth > 0).any()
    region = truth.mask
    out = proxy_matte(picture, target, depth, region, 0.0)
    assert not out.applied and out.image is picture and (out.weight == 1.0).all()
    none = proxy_matte(picture, target, np.zeros(truth.mask.shape), region, 0.0)
    assert not none.applied and none.image is picture
    nan = proxy_matte(picture, target, np.full(truth.mask.shape, np.nan), region, 0.0)
    assert not nan.applied


def test_the_parts_of_missing_joints_are_kept_within_their_reach(shot):
    """Without the ears the proxy has no head; given the joints, the matte keeps a sphere round the eyes
    as large as a head can reach, so the simulated head stays; without the neck nothing is matted."""
    joints, _, _, target, image, truth = shot
    valid = np.ones(25, bool)
    valid[[JOINT_INDEX["REar"], JOINT_INDEX["LEar"]]] = False
    depth = proxy_depth(proxy_body(joints, valid), target)
    picture = foggy(image, truth.mask)
    region = picture.max(axis=-1) >= 13
    blind = proxy_matte(picture, target, depth, region, 0.0, feather_m=0.0)
    aware = proxy_matte(picture, target, depth, region, 0.0, feather_m=0.0, joints=joints, valid=valid)
    assert (blind.weight[truth.mask] == 0).sum() > 20  # the head is cut by a matte blind to the missing ears
    assert (aware.weight[truth.mask] == 1).mean() > 0.995
    assert aware.applied and (aware.weight == 0).mean() > 0.2  # the fog far away still goes
    centres, radii = reach_spheres(joints, valid)
    assert len(centres) == 2 and np.allclose(centres, joints[[JOINT_INDEX["REye"], JOINT_INDEX["LEye"]]])
    assert ((radii > 0.2) & (radii < 0.5)).all()
    no_neck = valid.copy()
    no_neck[JOINT_INDEX["Neck"]] = False
    assert not proxy_matte(picture, target, depth, region, 0.0, joints=joints, valid=no_neck).applied


def test_reach_spheres_climb_to_the_nearest_found_joint():
    joints = np.random.default_rng(0).normal(size=(25, 3))
    valid = np.ones(25, bool)
    assert reach_spheres(joints, valid)[0].shape == (0, 3)
    valid[[JOINT_INDEX["RElbow"], JOINT_INDEX["RWrist"]]] = False  # the whole forearm and hand: from the shoulder
    centres, radii = reach_spheres(joints, valid)
    assert np.allclose(centres, joints[JOINT_INDEX["RShoulder"]])
    assert radii.max() > 0.8  # an arm's length
    everything = np.zeros(25, bool)
    assert reach_spheres(joints, everything)[0].shape == (0, 3)  # nothing found to hang them on


def test_the_background_value_is_the_models(shot):
    joints, _, _, target, image, truth = shot
    depth = proxy_depth(proxy_body(joints, np.ones(25, bool)), target)
    out = proxy_matte(foggy(image, truth.mask), target, depth, truth.mask | ~truth.mask, background=1.0)
    assert (out.image[out.weight == 0.0] == 255).all()


def test_bad_inputs_are_named(shot):
    joints, _, _, target, image, truth = shot
    depth = proxy_depth(proxy_body(joints, np.ones(25, bool)), target)
    with pytest.raises(ShapeError, match="uint8"):
        proxy_matte(image.astype(np.float32), target, depth, truth.mask, 0.0)
    with pytest.raises(ShapeError, match="camera"):
        proxy_matte(image[:64], target, depth, truth.mask, 0.0)
    with pytest.raises(ShapeError, match="depth"):
        proxy_matte(image, target, depth[:64], truth.mask, 0.0)
    with pytest.raises(ShapeError, match="region"):
        proxy_matte(image, target, depth, truth.mask[:, :64], 0.0)
    with pytest.raises(ValueError, match="margin_m"):
        proxy_matte(image, target, depth, truth.mask, 0.0, margin_m=-0.1)
    with pytest.raises(ConfigError, match="matte_margin_m"):
        NovelViewConfig(matte_margin_m=float("nan"))
    with pytest.raises(ConfigError, match="matte_feather_m"):
        NovelViewConfig(matte_feather_m=-1.0)
    with pytest.raises(ConfigError, match="matte"):
        NovelViewConfig(matte="yes")


def _meets_brute_force(camera, centre_rig: np.ndarray, r: float) -> np.ndarray:
    """``(H, W)`` whether each pixel's ray passes within ``r`` of the point, and how far from the edge."""
    vs, us = np.mgrid[:camera.height, :camera.width].astype(np.float64)
    d = np.stack([us, vs, np.ones_like(us)], -1) @ np.linalg.inv(camera.K).T
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    c = camera.R @ centre_rig + camera.t
    along = np.maximum(d @ c, 0.0)  # the ray's closest point to the centre (rays start at the camera)
    miss = np.linalg.norm(c - along[..., None] * d, axis=-1)
    return miss <= r, np.abs(miss - r)


@pytest.mark.parametrize("centre_cam,r,share", [
    ((0.0, 0.0, 0.8), 0.63, 1.0),  # near, on the axis: covers the frame (a disc f r / z = 157 px did not)
    ((0.5, -0.2, 0.6), 0.3, None),  # near, off the axis: an ellipse
    ((0.3, 0.05, 0.1), 0.25, None),  # across the camera plane (the disc kept the whole view)
    ((-0.2, 0.3, 3.0), 0.25, None),  # far: close to the disc
    ((0.0, 0.0, -0.5), 0.3, 0.0),  # wholly behind
    ((0.1, 0.0, 0.1), 0.3, 1.0),  # round the camera
])
def test_reach_spheres_are_drawn_with_their_exact_outline(centre_cam, r, share):
    from ghnerf_runtime.geometry.camera import Camera, look_at
    from ghnerf_runtime.proxy_matte import _discs

    R, t = look_at((0.4, -1.3, -0.5), (0.1, -0.9, 3.0))
    camera = Camera("view", 256, 256, [[200.0, 0.0, 127.5], [0.0, 200.0, 127.5], [0.0, 0.0, 1.0]], [], R, t)
    centre = R.T @ (np.asarray(centre_cam) - t)  # rig frame
    got = _discs((256, 256), camera, centre[None], np.array([r]))
    want, edge = _meets_brute_force(camera, centre, r)
    clear = edge > 1e-9  # pixels on the outline itself may round either way
    assert got.shape == (256, 256) and np.array_equal(got[clear], want[clear])
    if share is not None:
        assert got.mean() == share
    else:
        assert 0.0 < got.mean() < 1.0
    none = _discs((256, 256), camera, np.zeros((0, 3)), np.zeros(0))
    assert none.shape == (256, 256) and not none.any()


@pytest.mark.parametrize("background,want", [(-0.2, 0), (1.2, 255)])
def test_a_background_past_0_1_is_clipped_not_wrapped(shot, background, want):
    # the contract checks only that its background is finite: -0.2 faded the fog to 205 (-51 wrapped round in
    # uint8) and 1.2 to 50, where the rendered view clips it to black and white
    joints, _, _, target, image, truth = shot
    depth = proxy_depth(proxy_body(joints, np.ones(25, bool)), target)
    out = proxy_matte(foggy(image, truth.mask), target, depth, np.ones(truth.mask.shape, bool), background)
    assert out.applied and (out.weight == 0.0).mean() > 0.3
    assert (out.image[out.weight == 0.0] == want).all()


def test_a_min_support_outside_0_1_is_named(shot):
    # NaN failed the support test "share < min_support" everywhere: the matte ran on a picture that showed
    # none of the proxy (the case the test is there to leave alone)
    joints, _, _, target, image, _ = shot
    depth = proxy_depth(proxy_body(joints, np.ones(25, bool)), target)
    nowhere = np.zeros(depth.shape, bool)
    assert not proxy_matte(image, target, depth, nowhere, 0.0).applied
    for bad in (float("nan"), -0.5, 1.5):
        with pytest.raises(ValueError, match=r"min_support must be within \[0, 1\], got"):
            proxy_matte(image, target, depth, nowhere, 0.0, min_support=bad)
    with pytest.raises(ValueError, match="background must be finite"):
        proxy_matte(image, target, depth, nowhere, float("nan"))


@pytest.mark.parametrize("feather_m", [0.15, 0.0])
def test_a_denormal_proxy_depth_keeps_the_whole_picture_not_nan(feather_m):
    """A proxy at 1e-308 m: pixels per metre (f / depth) overflowed to inf, the weight came out NaN and the
    picture a NaN cast to uint8. At that depth every pixel is within the margin: nothing is matted."""
    from ghnerf_runtime.geometry.camera import Camera, intrinsics_from_fov
    camera = Camera("view", 64, 64, intrinsics_from_fov(64, 64, 40.0), np.zeros(5), np.eye(3), np.zeros(3))
    depth = np.zeros((64, 64))
    depth[24:40, 24:40] = 1e-308
    picture = np.full((64, 64, 3), 200, np.uint8)
    with np.errstate(over="raise", invalid="raise", divide="raise"):  # (underflow to 0 m is the answer)
        out = proxy_matte(picture, camera, depth, np.ones((64, 64), bool), 0.0, feather_m=feather_m)
    assert out.applied and np.isfinite(out.weight).all() and (out.weight == 1.0).all()
    assert np.array_equal(out.image, picture)
    # the other end, a proxy 1e300 m off: the silhouette's pixels stay, the rest is metres beyond any feather
    depth[24:40, 24:40] = 1e300
    with np.errstate(invalid="raise"):
        far = proxy_matte(picture, camera, depth, np.ones((64, 64), bool), 0.0, feather_m=feather_m)
    assert np.array_equal(far.weight == 1.0, depth > 0) and set(np.unique(far.weight)) == {0.0, 1.0}
