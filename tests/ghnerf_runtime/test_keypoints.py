"""Heatmap decoding: subpixel accuracy on known Gaussians, degenerate maps, mapping back to the frame."""
from __future__ import annotations

import doctest
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from ghnerf_runtime import keypoints
from ghnerf_runtime.errors import ShapeError
from ghnerf_runtime.geometry.camera import Camera, look_at
from ghnerf_runtime.geometry.rig import WorkingVolume
from ghnerf_runtime.keypoints import (
    MISSING_FILL, KeypointConfigError, KeypointDecoderConfig, decode_keypoints, heatmap_to_image_pixels,
    heatmap_to_model_pixels, model_to_heatmap_pixels, model_to_image_pixels,
)
from ghnerf_runtime.metrics import gaussian_heatmaps
from ghnerf_runtime.preprocess import Roi, crop_camera, roi_from_volume

SIZE = 64


def blobs(centres: np.ndarray, sigma: float, size: int = SIZE) -> np.ndarray:
    return gaussian_heatmaps(centres, np.ones(len(centres), bool), size, sigma)


def assert_missing_and_finite(kp, where):
    assert not kp.valid[where].any()
    assert np.all(kp.confidence[where] == 0.0)
    assert np.all(kp.uv[where] == MISSING_FILL)
    for arr in (kp.uv, kp.confidence, kp.runner_up, kp.runner_up_uv):
        assert np.all(np.isfinite(arr))


# ---------------------------------------------------------------- smoke / shape
def test_doctests():
    result = doctest.testmod(keypoints, raise_on_error=False)
    assert result.attempted >= 5 and result.failed == 0, result  # 5 examples when written


def test_shapes_and_dtypes_single_and_batched():
    hm = blobs(np.array([[10.0, 20.0], [30.0, 40.0], [50.0, 5.5]]), 2.0)
    kp = decode_keypoints(hm)
    assert kp.uv.shape == (3, 2) and kp.confidence.shape == (3,) and kp.valid.shape == (3,)
    assert kp.confidence.dtype == np.float32 and kp.valid.dtype == bool
    batched = decode_keypoints(np.stack([hm, hm[::-1]]))
    assert batched.uv.shape == (2, 3, 2)
    np.testing.assert_array_equal(batched.uv[0], kp.uv)
    np.testing.assert_array_equal(batched.uv[1], kp.uv[::-1])


@pytest.mark.parametrize("shape", [(64, 64), (1, 2, 3, 8, 8), (3, 0, 8)])
def test_bad_shapes_raise(shape):
    with pytest.raises(ShapeError):
        decode_keypoints(np.zeros(shape, np.float32))


@pytest.mark.parametrize("kwargs", [
    {"sigma": -1.0}, {"sigma": float("nan")}, {"threshold": 0.0}, {"threshold": 1.0},
    {"refine": "argmax"}, {"centroid_radius": 0}, {"max_region_frac": 0.0},
])
def test_config_validated_once(kwargs):
    with pytest.raises(KeypointConfigError) as info:
        KeypointDecoderConfig(**kwargs)
    assert next(iter(kwargs)) in str(info.value)
    assert isinstance(info.value, ValueError)


# --------------------------------------------------------------------- accuracy
@pytest.mark.parametrize("sigma", [1.5, 2.0, 2.5, 3.0])
def test_subpixel_error_on_noise_free_gaussians(sigma):
    rng = np.random.default_rng(int(sigma * 10))
    centres = rng.uniform(0.0, SIZE - 1.0, size=(50, 2))  # includes peaks near and on the border
    centres[:25] = rng.uniform(8, SIZE - 9, size=(25, 2))
    kp = decode_keypoints(blobs(centres, sigma))
    assert kp.valid.all()
    err = np.linalg.norm(kp.uv - centres, axis=-1)
    assert err.max() < 0.05, err.max()
    # Confidence is the filtered peak: a unit Gaussian filtered with sigma_f = 1 peaks at about
    # sigma^2 / (sigma^2 + 1), a little less off the pixel grid.
    expected = sigma ** 2 / (sigma ** 2 + 1.0)
    assert np.all(kp.confidence[:25] <= expected * 1.01) and np.all(kp.confidence[:25] >= expected * 0.9)


def test_quadratic_beats_centroid_and_integer_peak():
    """The comparison behind the default refine method (numbers in the module docstring)."""
    rng = np.random.default_rng(3)
    errors = {}
    for method in ("quadratic", "centroid", "none"):
        errs = []
        for sigma in (1.5, 3.0):
            centres = rng.uniform(8, SIZE - 9, size=(100, 2))
            hm = blobs(centres, sigma) + rng.normal(0, 0.02, (100, SIZE, SIZE)).astype(np.float32)
            kp = decode_keypoints(hm, KeypointDecoderConfig(refine=method))
            errs.append(np.linalg.norm(kp.uv - centres, axis=-1).mean())
        errors[method] = max(errs)
    assert errors["quadratic"] < 0.08
    assert errors["quadratic"] < 0.5 * errors["centroid"] < errors["none"]


def test_no_filter_is_exact_too():
    centres = np.array([[0.0, 31.2], [63.0, 12.7], [20.35, 44.6]])
    kp = decode_keypoints(blobs(centres, 2.0), KeypointDecoderConfig(sigma=0.0))
    np.testing.assert_allclose(kp.uv, centres, atol=1e-3)


def test_two_blobs_stronger_wins_and_runner_up_reported():
    yy, xx = np.mgrid[:SIZE, :SIZE]
    strong = np.exp(-((xx - 40.3) ** 2 + (yy - 12.8) ** 2) / (2 * 2.0 ** 2))
    weak = 0.6 * np.exp(-((xx - 15.0) ** 2 + (yy - 50.0) ** 2) / (2 * 2.0 ** 2))
    kp = decode_keypoints((strong + weak)[None].astype(np.float32))
    np.testing.assert_allclose(kp.uv[0], [40.3, 12.8], atol=0.05)
    assert kp.valid[0]
    assert 0.4 < kp.runner_up[0] < kp.confidence[0]
    single = decode_keypoints(strong[None].astype(np.float32))
    assert single.runner_up[0] == 0.0
    np.testing.assert_array_equal(single.runner_up_uv[0], [keypoints.MISSING_FILL] * 2)


@pytest.mark.parametrize("refine", ["quadratic", "centroid", "none"])
def test_runner_up_is_located_as_the_peak_is(refine):
    """Two people in view: the weaker blob (the other person's peak of that joint) comes back where the decoder
    places that blob alone as a peak, in each map of a batch, on the map edge too; none where a map has one blob.
    With the quadratic fit (the default) that is the blob's centre."""
    yy, xx = np.mgrid[:SIZE, :SIZE]

    def blob(x, y, height=1.0, sigma=2.0):
        return height * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * sigma ** 2))

    cfg = KeypointDecoderConfig(refine=refine)
    strong = [(40.3, 12.8), (10.6, 30.2), (33.0, 33.0)]
    weak = [(15.45, 50.7), (52.2, 0.0), None]  # the second one's centre on the top edge
    maps = np.stack([blob(*s) + (0 if w is None else blob(*w, 0.7)) for s, w in zip(strong, weak)])
    kp = decode_keypoints(np.stack([maps, maps[::-1]]).astype(np.float32), cfg)
    assert kp.runner_up_uv.shape == (2, 3, 2) and kp.runner_up_uv.dtype == np.float64
    for view, order in ((0, [0, 1, 2]), (1, [2, 1, 0])):
        for j, k in enumerate(order):
            if weak[k] is None:
                assert kp.runner_up[view, j] == 0 and not kp.runner_up_uv[view, j].any()
                continue
            alone = decode_keypoints(blob(*weak[k], 0.7)[None].astype(np.float32), cfg)
            assert kp.runner_up[view, j] == pytest.approx(alone.confidence[0], abs=1e-6)
            np.testing.assert_allclose(kp.runner_up_uv[view, j], alone.uv[0], atol=1e-6)
            if refine == "quadratic":
                np.testing.assert_allclose(kp.runner_up_uv[view, j], weak[k], atol=0.01)


def test_a_second_peak_in_the_best_region_is_the_runner_up():
    """Two people 0.6 m apart: their peaks of a joint lie 6-8 cells apart in one view (the oracle's sigma 1.5),
    and above the threshold the two blobs join into one region, so another region's maximum found no runner-up
    and the pair was not flagged (docs/two-people.md, "Two people in the working volume"). The second maximum past
    a valley is the runner-up, located as the peak is; a blob with a shoulder (no valley) has none."""
    yy, xx = np.mgrid[:32, :32]

    def blob(x, y, height=1.0, sigma=1.5):
        return height * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * sigma ** 2))

    for sep in (6.0, 7.0):
        pair = np.maximum(blob(12.3, 15.6), blob(12.3 + sep, 15.6, 0.9))[None].astype(np.float32)
        kp = decode_keypoints(pair)
        assert kp.valid[0]
        above = keypoints._filter(pair, 1.0)[0][0] > 0.1  # (one region: the case the old decoder missed)
        assert keypoints._regions(above[None]).max() == 1
        alone = decode_keypoints(blob(12.3 + sep, 15.6, 0.9)[None].astype(np.float32))
        assert kp.runner_up[0] == pytest.approx(alone.confidence[0], rel=0.02)
        np.testing.assert_allclose(kp.runner_up_uv[0], [12.3 + sep, 15.6], atol=0.1)
        np.testing.assert_allclose(kp.uv[0], [12.3, 15.6], atol=0.1)
    # a second maximum (0.57 filtered, 5 cells off) whose valley (0.47) is no dip: one blob's shoulder, not a peak
    shoulder = (blob(12.0, 15.0) + blob(17.0, 15.0, 0.8))[None].astype(np.float32)
    assert decode_keypoints(shoulder).runner_up[0] == 0.0
    # two bumps below the threshold: no peak, and no runner-up (a runner-up is a peak above it, the pairings' rule)
    faint = (0.1 * np.maximum(blob(10.0, 15.0), blob(20.0, 15.0, 0.9)))[None].astype(np.float32)
    kp = decode_keypoints(faint)
    assert not kp.valid[0] and kp.runner_up[0] == 0.0


def test_rendered_blocks_place_the_runner_up_in_the_grid_s_cells():
    from ghnerf_runtime.keypoints import decode_blocks

    g = 32
    yy, xx = np.mgrid[:g, :g]
    blocks = [(0, 8, 24, 20), (4, 0, 24, 20)]  # (r0, c0, rows, cols)
    rendered = []
    for r0, c0, rows, cols in blocks:
        full = (np.exp(-((xx - 12.3) ** 2 + (yy - 9.6) ** 2) / 4.5)
                + 0.6 * np.exp(-((xx - 18.0) ** 2 + (yy - 20.4) ** 2) / 4.5)).astype(np.float32)
        rendered.append(full[r0:r0 + rows, c0:c0 + cols].reshape(-1, 1))
    kp = decode_blocks(np.stack(rendered), blocks)
    np.testing.assert_allclose(kp.uv[:, 0], [[12.3, 9.6]] * 2, atol=0.02)
    np.testing.assert_allclose(kp.runner_up_uv[:, 0], [[18.0, 20.4]] * 2, atol=0.02)


def test_oblique_anisotropic_blob():
    yy, xx = np.mgrid[:SIZE, :SIZE].astype(np.float64)
    c, s = np.cos(0.6), np.sin(0.6)
    dx, dy = xx - 30.4, yy - 33.7
    a, b = c * dx + s * dy, -s * dx + c * dy
    hm = np.exp(-(a ** 2 / (2 * 3.5 ** 2) + b ** 2 / (2 * 1.5 ** 2)))[None].astype(np.float32)
    kp = decode_keypoints(hm)
    np.testing.assert_allclose(kp.uv[0], [30.4, 33.7], atol=0.05)


# ---------------------------------------------------------------- degenerate maps
def test_degenerate_maps_are_missing_with_finite_outputs():
    rng = np.random.default_rng(0)
    good = blobs(np.array([[20.2, 30.7]]), 2.0)[0]
    maps = np.stack([
        np.zeros((SIZE, SIZE)),                       # 0 all zero
        np.ones((SIZE, SIZE)),                        # 1 saturated
        rng.uniform(0, 1, (SIZE, SIZE)),              # 2 uniform noise
        rng.uniform(0, 0.05, (SIZE, SIZE)),           # 3 faint noise, below threshold
        np.where(np.arange(SIZE) == 5, np.nan, good),  # 4 a NaN row
        np.full((SIZE, SIZE), np.inf),                # 5 Inf
        np.full((SIZE, SIZE), -np.inf),               # 6 -Inf
        0.05 * good,                                  # 7 real blob, below threshold
        good,                                         # 8 the control
    ]).astype(np.float32)
    kp = decode_keypoints(maps)
    assert_missing_and_finite(kp, slice(0, 8))
    assert kp.valid[8]
    np.testing.assert_allclose(kp.uv[8], [20.2, 30.7], atol=0.05)


def test_one_bad_joint_does_not_spoil_the_batch():
    hm = blobs(np.array([[10.0, 10.0], [40.0, 40.0]]), 2.0)
    hm[0, 3, 3] = np.nan
    kp = decode_keypoints(hm)
    assert kp.valid.tolist() == [False, True]
    np.testing.assert_allclose(kp.uv[1], [40.0, 40.0], atol=0.05)


def test_threshold_and_region_fraction_are_honoured():
    hm = blobs(np.array([[30.0, 30.0]]), 2.0) * 0.5
    assert decode_keypoints(hm, KeypointDecoderConfig(threshold=0.3)).valid[0]
    assert not decode_keypoints(hm, KeypointDecoderConfig(threshold=0.6)).valid[0]
    wide = blobs(np.array([[30.0, 30.0]]), 12.0)
    assert not decode_keypoints(wide).valid[0]  # its region covers more than a quarter of the map
    assert decode_keypoints(wide, KeypointDecoderConfig(max_region_frac=1.0)).valid[0]


# ------------------------------------------------------------------ coordinates
def test_heatmap_model_pixel_conversion():
    uv = np.array([[0.0, 0.0], [31.0, 15.5]])
    model = heatmap_to_model_pixels(uv, 32, 128)
    np.testing.assert_allclose(model, [[1.5, 1.5], [125.5, 63.5]])  # block centres, stride 4
    np.testing.assert_allclose(model_to_heatmap_pixels(model, 32, 128), uv)
    np.testing.assert_allclose(heatmap_to_model_pixels(uv, (32, 16), (128, 64)), [[1.5, 1.5], [125.5, 63.5]])
    with pytest.raises(ShapeError):
        heatmap_to_model_pixels(uv, (32, 16, 4), 128)
    for size in (np.inf, (32, np.inf)):  # was accepted: every point mapped to -0.5
        with pytest.raises(ShapeError, match="heatmap_size"):
            heatmap_to_model_pixels(uv, size, 128)
        with pytest.raises(ShapeError, match="model_size"):
            model_to_heatmap_pixels(uv, 32, size)


def _rig_camera() -> Camera:
    K = np.array([[560.0, 0.0, 331.0], [0.0, 556.0, 236.5], [0.0, 0.0, 1.0]])
    R, t = look_at((0.4, -1.3, -0.5), (0.0, -0.9, 3.0))
    return Camera("left", 640, 480, K, np.array([-0.24, 0.07, 0.0009, -0.0012, -0.01]), R, t)


def test_decoded_keypoints_map_back_to_projected_joints():
    """3D joints -> crop camera -> heatmap Gaussians -> decode -> frame pixels == Camera.project."""
    cam = _rig_camera()
    volume = WorkingVolume([-1.0, -2.0, 2.0], [1.0, 0.0, 4.0])
    roi = roi_from_volume(cam, volume, margin=0.05)
    model_size, heat_size = 128, 32
    rng = np.random.default_rng(7)
    joints = rng.uniform([-0.6, -1.8, 2.5], [0.6, -0.1, 3.5], size=(25, 3))

    crop = crop_camera(cam, roi, model_size)
    uv_model, _ = crop.project(joints)
    uv_heat = model_to_heatmap_pixels(uv_model, heat_size, model_size)
    inside = np.all((uv_heat >= 0) & (uv_heat <= heat_size - 1), axis=-1)
    assert inside.sum() >= 20
    hm = gaussian_heatmaps(uv_heat, inside, heat_size, sigma=1.5)
    kp = decode_keypoints(hm)
    assert np.array_equal(kp.valid, inside)

    px_per_heat = roi.size / heat_size
    uv_img = heatmap_to_image_pixels(kp.uv, cam, roi, model_size, heat_size, valid=kp.valid)
    truth, _ = cam.project(joints)
    err = np.linalg.norm(uv_img[inside] - truth[inside], axis=-1)
    assert err.max() < 0.05 * px_per_heat, (err.max(), px_per_heat)
    assert np.all(uv_img[~inside] == MISSING_FILL)

    undist = heatmap_to_image_pixels(kp.uv, cam, roi, model_size, heat_size, distort=False)
    ideal, _ = cam.project(joints, distort=False)
    assert np.linalg.norm(undist[inside] - ideal[inside], axis=-1).max() < 0.05 * px_per_heat


def test_model_to_image_matches_roi_affine_without_distortion():
    cam = _rig_camera()
    roi = Roi(100, 40, 300)
    uv = np.array([[0.0, 0.0], [127.0, 64.0]])
    np.testing.assert_allclose(model_to_image_pixels(uv, cam, roi, 128, distort=False),
                               roi.model_to_image(uv, 128), atol=1e-9)


# ------------------------------------------------------------------- properties

_values = st.one_of(st.floats(-2.0, 2.0, width=32), st.sampled_from([np.nan, np.inf, -np.inf, 0.0, 1.0]))


@settings(max_examples=60, deadline=None)
@given(hm=arrays(np.float32, st.tuples(st.integers(1, 3), st.integers(1, 9), st.integers(1, 9)), elements=_values),
       sigma=st.sampled_from([0.0, 0.7, 1.0, 2.0]), refine=st.sampled_from(["quadratic", "centroid", "none"]))
def test_outputs_always_finite_and_consistent(hm, sigma, refine):
    cfg = KeypointDecoderConfig(sigma=sigma, refine=refine)
    kp = decode_keypoints(hm, cfg)
    for arr in (kp.uv, kp.confidence, kp.runner_up, kp.runner_up_uv):
        assert np.all(np.isfinite(arr))
    h, w = hm.shape[-2:]
    assert np.all(kp.confidence[kp.valid] > cfg.threshold) and np.all(kp.confidence[~kp.valid] == 0)
    assert np.all(kp.uv[~kp.valid] == MISSING_FILL)
    assert np.all(kp.uv[kp.valid] >= -1.0) and np.all(kp.uv[kp.valid] <= [w, h])
    assert not np.any(kp.valid & ~np.isfinite(hm).all(axis=(-2, -1)))


_extreme_values = st.sampled_from([np.nan, np.inf, -np.inf, 0.0, 1.0, 0.5, 1e-30, 6e-8, 65504.0, 1e30, -1e30, -0.5])


@settings(max_examples=80, deadline=None)
@given(dtype=st.sampled_from([np.float16, np.float64]),
       shape=st.tuples(st.integers(1, 3), st.integers(1, 9), st.integers(1, 9)),
       data=st.data(), sigma=st.sampled_from([0.0, 1.0, 20.0]), refine=st.sampled_from(["quadratic", "centroid", "none"]),
       threshold=st.sampled_from([1e-6, 0.1, 0.999]), max_region_frac=st.sampled_from([1e-3, 0.25, 1.0]))
def test_half_and_double_maps_with_extreme_values_decode_finite_in_range_and_on_the_map(
        dtype, shape, data, sigma, refine, threshold, max_region_frac):
    """Beyond the float32 sweep above: a corrupt model output in float16 (its largest finite value, denormals) or
    float64 (1e30, past float32's range) mixed with NaN, infinities and negatives, at the decoder's extreme
    settings: every output finite, both confidences in [0, 1], a decoded joint on the map, a map holding a
    non-finite value never decoded."""
    with np.errstate(over="ignore"):  # (1e30 is inf in float16: one more infinity)
        hm = np.array(data.draw(st.lists(_extreme_values | st.floats(0.0, 1.0), min_size=int(np.prod(shape)),
                                         max_size=int(np.prod(shape)))), dtype=np.float64).astype(dtype).reshape(shape)
    cfg = KeypointDecoderConfig(sigma=sigma, refine=refine, threshold=threshold, max_region_frac=max_region_frac)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        kp = decode_keypoints(hm, cfg)
    for arr in (kp.uv, kp.confidence, kp.runner_up, kp.runner_up_uv):
        assert np.all(np.isfinite(arr))
    for arr in (kp.confidence, kp.runner_up):
        assert np.all((arr >= 0) & (arr <= 1))
    h, w = shape[-2:]
    assert np.all(kp.uv[kp.valid] >= -0.5) and np.all(kp.uv[kp.valid] <= [w - 0.5, h - 0.5])
    assert not np.any(kp.valid & ~np.isfinite(hm).all(axis=(-2, -1)))


def test_a_peak_past_the_lens_fold_is_missing_not_mirrored():
    # a square crop can reach past where the lens model folds; a peak there went through the folded
    # model and came back as a confident joint on the opposite side of the frame
    cam = Camera("c", 640, 480, [[300, 0, 319.5], [0, 300, 239.5], [0, 0, 1]], [-0.4, 0, 0, 0, 0])
    roi, size = Roi(-200, -200, 1040), 128
    uv = np.array([[8.0, 8.0], [64.0, 64.0]])  # past the fold, top left; the centre
    assert np.hypot(*crop_camera(cam, roi, size).pixels_to_normalized(uv[:1])[0]) > cam.fold_radius
    mapped = model_to_image_pixels(uv, cam, roi, size)
    np.testing.assert_array_equal(mapped[0], MISSING_FILL)
    assert 0 < mapped[1][0] < 640 and 0 < mapped[1][1] < 480
    np.testing.assert_array_equal(model_to_image_pixels(uv, cam, roi, size, valid=[True, False]), MISSING_FILL)
    assert np.all(np.isfinite(model_to_image_pixels(uv, cam, roi, size, distort=False)))  # a ray still


@pytest.mark.parametrize("dist", [np.zeros(5), np.array([-0.2, 0.05, 0.001, -0.001, 0.0])], ids=["pinhole", "lens"])
@pytest.mark.parametrize("roll_deg", [0.0, 30.0])
def test_non_finite_or_far_model_pixels_map_to_the_fill_without_numpy_warnings(dist, roll_deg):
    """Model pixels no frame pixel shows (NaN, inf, 1e300 px: past the lens model's reach) come back as the
    fill, as a point past the fold does; they went through the lens model first, which overflowed with a dozen
    numpy warnings (and within_lens' square of 1e300 one more). The other pixels keep their values to the bit."""
    cam = Camera("c", 640, 480, [[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]], dist)
    roi, size = Roi(100, 50, 256), 256
    uv = np.array([[0.0, 0.0], [np.nan, 1.0], [np.inf, 0.0], [1e300, 1e300], [255.0, 255.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mapped = model_to_image_pixels(uv, cam, roi, size, roll_deg=roll_deg)
    np.testing.assert_array_equal(mapped[1:4], MISSING_FILL)
    np.testing.assert_array_equal(mapped[[0, 4]], model_to_image_pixels(uv[[0, 4]], cam, roi, size,
                                                                        roll_deg=roll_deg))


def test_values_outside_zero_one_never_give_a_confidence_outside_it():
    """A model straying outside [0, 1]: a block of 3.4e38 once overflowed the filter to an infinite confidence."""
    yy, xx = np.mgrid[:32, :32]
    blob = np.exp(-((xx - 10.3) ** 2 + (yy - 20.6) ** 2) / (2 * 2.0 ** 2)).astype(np.float32)
    huge = np.zeros((32, 32), np.float32)
    huge[14:17, 14:17] = 3.4e38
    kp = decode_keypoints(np.stack([huge, 1.5 * blob, blob]))
    assert np.isfinite(kp.confidence).all() and (kp.confidence <= 1.0).all() and (kp.confidence >= 0.0).all()
    assert kp.valid[0] and np.abs(kp.uv[0] - 15.0).max() < 0.5  # the block's centre
    assert np.abs(kp.uv[2] - [10.3, 20.6]).max() < 0.05


def test_a_blob_past_one_keeps_its_peak():
    """A map above 1 (a model without its sigmoid, a uint8 map) was clipped to 1: the blob's top became a
    plateau whose first pixel was the peak, 2.3 px off for peak 255; scaled by its maximum it stays a blob."""
    yy, xx = np.mgrid[:32, :32]
    centres = [(10.3, 20.6), (17.45, 9.8), (21.9, 14.2)]
    for scale in (1.5, 20.0, 255.0, 1e30):
        maps = np.stack([scale * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * 2.0 ** 2)) for x, y in centres])
        kp = decode_keypoints(maps.astype(np.float32))
        assert kp.valid.all() and (kp.confidence <= 1.0).all()
        np.testing.assert_allclose(kp.uv, centres, atol=0.01)
    as_uint8 = decode_keypoints((255 * maps / maps.max(axis=(1, 2), keepdims=True)).astype(np.uint8))
    np.testing.assert_allclose(as_uint8.uv, centres, atol=0.1)  # rounded to integers, but no plateau


@pytest.mark.parametrize("sigma, gain", [(2.0, 100.0), (3.0, 3.0), (1.5, 10.0), (1.5, 1.5)])
@pytest.mark.parametrize("across", [(10.0, 22.0), (0.0, 1.0), (1.0, 3.0)], ids=["inside", "on the edge", "by it"])
@pytest.mark.parametrize("noise", [0.0, 0.02])
def test_a_saturated_top_is_placed_at_its_centre(sigma, gain, across, noise):
    """A blob whose top saturates (a sigmoid at 1.0 in float32 past a logit of 17; an int8 output at its largest
    value) is a plateau: the fit took the filtered map's highest pixel, which rounding picks anywhere on it, up to
    2.0 px off for sigma 2, 100-fold, inside the map and 3.0 px on its edge (these blobs through session 64's
    decoder). Its flank is a Gaussian's samples: placed by them, within 0.001 px noise-free, 0.3 px with noise of
    0.02."""
    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[:32, :32]
    centres = np.stack([rng.uniform(*across, size=30), rng.uniform(10.0, 22.0, size=30)], axis=-1)
    maps = np.stack([gain * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * sigma ** 2)) for x, y in centres])
    maps = np.clip(maps + rng.normal(0.0, noise, maps.shape), 0.0, 1.0).astype(np.float32)
    kp = decode_keypoints(maps)
    assert kp.valid.all()
    assert np.hypot(*(kp.uv - centres).T).max() < (0.3 if noise else 0.001)


@pytest.mark.parametrize("apart", [5.27, 6.27, 7.27, 9.3])
def test_a_saturated_top_run_into_a_second_one_is_placed_on_the_stronger(apart):
    """Two people's saturated tops a few cells apart, their plateaus run into one or lying side by side: no
    paraboloid fits two blobs' flanks (its vertex fell between them, on neither person, 4.0 px off for 7.27 cells
    apart), so the joint stays where the filtered peak puts it, on the stronger blob's plateau."""
    yy, xx = np.mgrid[:32, :32]
    centres = np.array([(8.4, 15.3), (8.4 + apart, 16.1)])
    tops = [gain * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * 1.5 ** 2)) for (x, y), gain in zip(centres, (20, 8))]
    kp = decode_keypoints(np.minimum(np.maximum(*tops), 1.0)[None].astype(np.float32))
    assert kp.valid[0] and np.hypot(*(kp.uv[0] - centres[0])) < 0.7


def test_float64_values_past_the_float32_range_are_clipped_like_any_other():
    """A finite float64 value past 3.4e38 overflowed the float32 cast to inf, so its joint was dropped as
    non-finite (with a RuntimeWarning), where the same map in float32 range is clipped to 1 and decoded."""
    huge = np.zeros((1, 32, 32))
    huge[0, 14:17, 14:17] = 1e39
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        kp = decode_keypoints(huge)
    ref = decode_keypoints(np.minimum(huge, 1.0).astype(np.float32))
    assert kp.valid[0] and ref.valid[0]
    np.testing.assert_array_equal(kp.uv, ref.uv)
    np.testing.assert_array_equal(kp.confidence, ref.confidence)


def test_a_peak_by_a_rendered_blocks_border_is_not_pulled_inward():
    """Only a block of rays is rendered: decoded on the whole grid, the zeros around it bias a peak near
    its border by up to 0.7 cells; decoded as its own map, the border is an edge like the grid's."""
    from ghnerf_runtime.keypoints import decode_blocks

    g, sigma = 32, 1.5
    yy, xx = np.mgrid[:g, :g]
    blocks = [(0, 8, 28, 24), (4, 0, 28, 24)]  # (r0, c0, rows, cols), one size for both views
    truth = [(8.4, 15.0), (12.0, 4.3)]  # (x, y) in grid cells: by view 0's left border, view 1's top border
    rendered = []
    for (r0, c0, rows, cols), (x, y) in zip(blocks, truth):
        full = np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * sigma ** 2)).astype(np.float32)
        rendered.append(full[r0:r0 + rows, c0:c0 + cols].reshape(-1, 1))
    kp = decode_blocks(np.stack(rendered), blocks)
    assert kp.valid.all()
    assert np.abs(kp.uv[:, 0] - np.array(truth)).max() < 0.05, kp.uv
    # the whole-grid decode of the same rays, as before: biased inward
    grid = np.zeros((2, 1, g, g), np.float32)
    for i, ((r0, c0, rows, cols), r) in enumerate(zip(blocks, rendered)):
        grid[i, 0, r0:r0 + rows, c0:c0 + cols] = r.reshape(rows, cols)
    assert np.abs(decode_keypoints(grid).uv[:, 0] - np.array(truth)).max() > 0.3
    with pytest.raises(ShapeError, match="one block of one size per view"):
        decode_blocks(np.stack(rendered), [(0, 8, 28, 24), (4, 0, 24, 28)])


def test_rendered_blocks_past_the_float32_range_decode_as_decode_keypoints_does():
    """decode_blocks cast the rendered rays to float32 first: a float64 value past 3.4e38 became inf and its
    joint was dropped, where decode_keypoints scales the same map and decodes it."""
    from ghnerf_runtime.keypoints import decode_blocks

    rendered = np.zeros((2, 64, 1))
    rendered[:, 8 * 3 + 5, 0] = 1e39  # row 3, column 5 of an 8x8 block
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        kp = decode_blocks(rendered, [(0, 0, 8, 8), (2, 4, 8, 8)])
    assert kp.valid.all()
    np.testing.assert_allclose(kp.uv[:, 0], [[5.0, 3.0], [9.0, 5.0]], atol=1e-6)


# --------------------------------------------------- extremes (session 51's numerical review)
@pytest.mark.parametrize("sigma", [2.0, 3.0])
def test_a_peak_at_the_map_edge_is_found_with_a_wide_decoder_filter(sigma):
    """The filter's zero border pulls an edge peak of the filtered map 2 px and more inward with a decoder
    sigma of 2 or more; the raw-map fit there started from that pixel and, its step clipped to one pixel,
    left the joint up to a pixel off (0.99 px for a blob on the edge). It now starts from the raw map's own
    maximum (one pixel short of the edge), and the result never leaves the map."""
    centres = np.array([[0.0, 30.4], [0.25, 12.2], [0.75, 44.0], [1.5, 50.2], [63.0, 40.7], [20.3, 0.0],
                        [44.6, 63.0], [0.0, 0.0], [63.0, 63.0], [62.4, 0.6]])
    kp = decode_keypoints(blobs(centres, 3.0), KeypointDecoderConfig(sigma=sigma))
    assert kp.valid.all()
    err = np.linalg.norm(kp.uv - centres, axis=-1)
    assert err.max() < 0.01, err
    assert np.all((kp.uv >= 0) & (kp.uv <= SIZE - 1))


def test_a_peak_outside_the_map_stays_on_its_edge():
    """A blob centred past the edge (the joint left the crop): never placed outside the map, whatever the
    filter and method; the quadratic fit puts it on the edge pixel (sigma 3 left one a pixel inside)."""
    centres = np.array([[-2.0, 30.0], [65.5, 20.0], [30.0, -1.0], [-3.0, 66.0]])
    for sigma in (0.0, 1.0, 3.0):
        for refine in ("quadratic", "centroid", "none"):
            kp = decode_keypoints(blobs(centres, 3.0), KeypointDecoderConfig(sigma=sigma, refine=refine))
            assert kp.valid[:3].all(), (sigma, refine)  # the corner blob is too faint after a sigma 3 filter
            assert np.all((kp.uv >= 0) & (kp.uv <= SIZE - 1)), (sigma, refine, kp.uv)
            if refine == "quadratic":  # the others are biased inward (module docstring)
                np.testing.assert_allclose(kp.uv[kp.valid], np.clip(centres, 0, SIZE - 1)[kp.valid], atol=1e-6)


def test_complex_heatmaps_are_refused():
    """Complex maps are "numeric": the float32 cast dropped their imaginary part with only a warning."""
    hm = blobs(np.array([[20.0, 30.0]]), 2.0).astype(np.complex64)
    with pytest.raises(ShapeError, match="complex64"):
        decode_keypoints(hm)


@pytest.mark.parametrize("h, w", [(1, 1), (2, 3), (3, 2), (5, 7), (16, 4000), (4000, 16)])
def test_tiny_and_extreme_maps_at_every_border_pixel(h, w):
    """A single peak on each border pixel (every pixel of a small map), two equal peaks, float16 and
    read-only/negative-stride views: no exception, finite outputs, joints inside the map."""
    border = [(y, x) for y in range(h) for x in range(w) if min(y, x, h - 1 - y, w - 1 - x) == 0]
    if len(border) > 40:
        border = border[:: len(border) // 40]
    maps = np.zeros((len(border) + 1, h, w), np.float16)
    for k, (y, x) in enumerate(border):
        maps[k, y, x] = 1.0
    maps[-1, 0, 0] = maps[-1, -1, -1] = 1.0  # two equal peaks
    for flipped, view in ((False, maps), (True, maps[:, ::-1, ::-1])):
        view = view.view()
        view.flags.writeable = False
        for sigma in (0.0, 1.0, 3.0):
            kp = decode_keypoints(view, KeypointDecoderConfig(sigma=sigma, max_region_frac=1.0))
            for arr in (kp.uv, kp.confidence, kp.runner_up, kp.runner_up_uv):
                assert np.all(np.isfinite(arr))
            assert np.all((kp.uv >= 0) & (kp.uv <= [w - 1, h - 1]))
            # a one-pixel peak is decoded on its pixel (the filter cannot move a lone pixel's maximum)
            found = kp.valid[:-1]
            expect = np.array([[x, y] for y, x in border], float)
            if flipped:
                expect = [w - 1, h - 1] - expect
            np.testing.assert_allclose(kp.uv[:-1][found], expect[found], atol=1e-6)


@pytest.mark.parametrize("fraction", [0.0, 0.001, 0.05, 1.0])
def test_nonzero_of_the_maps_is_numpys(fraction):
    """The decoder's flat nonzero gives numpy's nonzero of the (N, H, W) mask: the same indices in the same order."""
    rng = np.random.default_rng(7)
    for shape in ((50, 64, 64), (3, 1, 5), (1, 7, 1)):
        mask = rng.random(shape) < fraction
        got, want = keypoints._nonzero_3d(mask), np.nonzero(mask)
        for g, w in zip(got, want):
            assert g.dtype == w.dtype and np.array_equal(g, w)


def test_decoding_takes_no_nonzero_of_a_3d_array(monkeypatch):
    """numpy's nonzero of a 3-d mask steps through every element (0.15 ms a pair for a pair's 50 maps of 32 x 32
    cells, a sixth of the decode's time): the decoder takes flat indices, with the same keypoints."""
    yy, xx = np.mgrid[:48, :48]
    blob = lambda x, y: np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * 1.5 ** 2))  # noqa: E731
    maps = np.stack([blob(10.3, 20.6) + 0.8 * blob(30.2, 22.1), blob(24.0, 8.5)]).astype(np.float32)
    want = decode_keypoints(maps)
    ndims = []
    real = np.nonzero
    monkeypatch.setattr(np, "nonzero", lambda a: ndims.append(np.ndim(a)) or real(a))
    got = decode_keypoints(maps)
    assert all(n <= 1 for n in ndims), ndims
    for name in ("uv", "confidence", "valid", "runner_up", "runner_up_uv"):
        assert np.array_equal(getattr(got, name), getattr(want, name)), name
    assert got.runner_up[0] > 0  # the second blob was looked at as a runner-up


_scaled_values = st.sampled_from([0.0, 1e-30, 6e-8, 0.3, 0.999, 1.0, 1.0000001, 1.5, 255.0, 65504.0, 1e30, 1e300])


@settings(max_examples=80, deadline=None)
@given(dtype=st.sampled_from([np.float16, np.float32, np.float64, np.uint8, np.int32]),
       shape=st.tuples(st.integers(1, 4), st.integers(1, 6), st.integers(1, 6)), data=st.data())
def test_the_maxima_the_scaling_hands_on_are_those_of_the_maps_it_returns(dtype, shape, data):
    """The flat-top check takes each map's maximum from the scaling (it took it again from the maps, since session
    66 it does not): bit for bit the maximum of the float32 maps the scaling returns, maps past 1 (1 exactly: x / x),
    under 1, of half, single, double or integer values, past float32's range."""
    values = data.draw(st.lists(_scaled_values | st.floats(0.0, 2.0), min_size=int(np.prod(shape)),
                                max_size=int(np.prod(shape))))
    with np.errstate(over="ignore"), warnings.catch_warnings():  # (past a dtype's range: its largest or inf)
        warnings.simplefilter("ignore")
        raw = np.array(values, np.float64).reshape(shape)
        maps = raw.astype(dtype) if np.issubdtype(dtype, np.floating) else np.clip(raw, 0, 255).astype(dtype)
    maps = np.where(np.isfinite(maps), maps, 0)  # (the decoder zeroes a map with a non-finite value first)
    scaled, maxima = keypoints._scaled_to_one(np.maximum(maps, 0.0))
    assert scaled.dtype == maxima.dtype == np.float32 and maxima.shape == (shape[0],)
    want = scaled.max(axis=(1, 2))
    assert np.array_equal(maxima.view(np.uint32), want.view(np.uint32)), (maxima, want)
    assert np.all(maxima <= 1.0)


def _patch3_by_loop(maps, pad, iy, ix, which):
    """The 3x3 neighbourhoods read pixel by pixel, indices clipped to the map: _patch3's reference."""
    out = np.zeros((len(iy), 3, 3))
    for k in range(len(iy)):
        for dy in range(3):
            for dx in range(3):
                r = min(max(iy[k] + pad + dy - 1, 0), maps.shape[1] - 1)
                c = min(max(ix[k] + pad + dx - 1, 0), maps.shape[2] - 1)
                out[k, dy, dx] = maps[which[k], r, c]
    return out


@pytest.mark.parametrize("pad", [0, 1, 3])
def test_patch3_reads_the_pixels_a_loop_reads(pad):
    # session 71 read the 3x3s with one take of flat indices (np.clip's checks cost more than the read): the same
    # values, edges and corners included, from a contiguous stack and a strided view alike
    rng = np.random.default_rng(71)
    stack = rng.random((6, 9 + 2 * pad, 11 + 2 * pad)).astype(np.float32)
    for maps in (stack, stack[:, :, ::-1]):
        n = 40
        iy, ix = rng.integers(0, 9, n), rng.integers(0, 11, n)
        iy[:4], ix[:4] = [0, 8, 0, 8], [0, 10, 10, 0]  # the four corners
        which = rng.integers(0, len(maps), n)
        got = keypoints._patch3(maps, pad, iy, ix, which)
        assert got.dtype == np.float64
        np.testing.assert_array_equal(got, _patch3_by_loop(maps, pad, iy, ix, which))
    np.testing.assert_array_equal(keypoints._patch3(stack, pad, iy[:6], ix[:6]),
                                  _patch3_by_loop(stack, pad, iy[:6], ix[:6], np.arange(6)))


def _climb_by_loop(maps, iy, ix, steps):
    """Each pixel moved uphill one at a time, as _climb's docstring says: its reference."""
    h, w = maps.shape[1:]
    out_y, out_x = np.array(iy), np.array(ix)
    for k in range(len(iy)):
        y, x = int(iy[k]), int(ix[k])
        lo_y, hi_y = (0 if y == 0 else min(1, h - 1)), (h - 1 if y == h - 1 else max(h - 2, 0))
        lo_x, hi_x = (0 if x == 0 else min(1, w - 1)), (w - 1 if x == w - 1 else max(w - 2, 0))
        for _ in range(steps):
            near = [maps[k, min(max(y + dy, 0), h - 1), min(max(x + dx, 0), w - 1)]
                    for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
            best = int(np.argmax(near))
            ty, tx = min(max(y + best // 3 - 1, lo_y), hi_y), min(max(x + best % 3 - 1, lo_x), hi_x)
            if not maps[k, ty, tx] > maps[k, y, x]:
                break
            y, x = ty, tx
        out_y[k], out_x[k] = y, x
    return out_y, out_x


def test_climb_moves_as_a_loop_over_pixels_does():
    rng = np.random.default_rng(171)
    maps = rng.random((60, 7, 8)).astype(np.float32)
    iy, ix = rng.integers(0, 7, 60), rng.integers(0, 8, 60)
    iy[:8], ix[:8] = [0, 6, 0, 6, 3, 3, 0, 6], [0, 7, 7, 0, 0, 7, 4, 4]  # corners and edges
    for steps in (1, 3):
        got = keypoints._climb(maps, iy, ix, steps)
        want = _climb_by_loop(maps, iy, ix, steps)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
