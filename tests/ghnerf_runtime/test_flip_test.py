import numpy as np
import pytest

from ghnerf_runtime.body25 import JOINT_INDEX, NUM_JOINTS
from ghnerf_runtime.flip_test import flip_averaged, mirror_images, unmirror_heatmaps
from ghnerf_runtime.keypoints import decode_keypoints, heatmap_to_model_pixels


def _gaussian(g: int, x: float, y: float, sigma: float = 1.2) -> np.ndarray:
    yy, xx = np.mgrid[0:g, 0:g]
    return np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * sigma ** 2)).astype(np.float32)


def test_a_left_joint_of_the_mirror_image_comes_back_as_the_right_joint_at_the_mirrored_place():
    g, S = 32, 128
    mirrored = np.zeros((2, NUM_JOINTS, g, g), np.float32)
    # in the mirror image the person's right wrist shows as a left wrist, at x = 10.3 cells
    mirrored[0, JOINT_INDEX["LWrist"]] = _gaussian(g, 10.3, 7.6)
    back = unmirror_heatmaps(mirrored)
    kp = decode_keypoints(back)
    r, l = JOINT_INDEX["RWrist"], JOINT_INDEX["LWrist"]
    assert kp.valid[0, r] and not kp.valid[0, l]
    np.testing.assert_allclose(kp.uv[0, r], [g - 1 - 10.3, 7.6], atol=0.05)  # cell x -> w - 1 - x
    # and in model pixels: pixel column i of the mirror image is column S - 1 - i of the original
    uv_m = heatmap_to_model_pixels(decode_keypoints(mirrored).uv, g, S)[0, l]
    uv_b = heatmap_to_model_pixels(kp.uv, g, S)[0, r]
    np.testing.assert_allclose([uv_b[0] + uv_m[0], uv_b[1]], [S - 1, uv_m[1]], atol=1e-3)
    np.testing.assert_array_equal(unmirror_heatmaps(unmirror_heatmaps(mirrored)), mirrored)  # an involution


def test_an_equivariant_encoder_is_left_unchanged_and_errors_partly_cancel():
    g = 16
    rng = np.random.default_rng(0)
    h = rng.random((2, NUM_JOINTS, g, g), dtype=np.float32)
    # a model that sees the mirror image exactly mirrored: the average is its own heatmaps
    np.testing.assert_allclose(flip_averaged(h, unmirror_heatmaps(h)), h, atol=1e-7)
    # two estimates off by +e and -e (in the original frame) average to the truth
    truth = np.zeros((1, NUM_JOINTS, g, g), np.float32)
    truth[0, 4] = _gaussian(g, 8.0, 8.0)
    a = np.zeros_like(truth)
    a[0, 4] = _gaussian(g, 8.6, 8.0)
    b = np.zeros_like(truth)
    b[0, 4] = _gaussian(g, 7.4, 8.0)
    avg = flip_averaged(a, unmirror_heatmaps(b))
    assert abs(decode_keypoints(avg).uv[0, 4, 0] - 8.0) < 0.1 < abs(decode_keypoints(a).uv[0, 4, 0] - 8.0)


def test_images_mirror_along_their_width_and_shapes_are_checked():
    images = np.arange(2 * 3 * 4 * 5, dtype=np.float32).reshape(2, 3, 4, 5)
    m = mirror_images(images)
    assert m.flags.c_contiguous and np.array_equal(m[..., 0], images[..., -1])
    with pytest.raises(ValueError, match="expected"):
        unmirror_heatmaps(np.zeros((2, 3, 4, 4), np.float32))
    with pytest.raises(ValueError, match="differ"):
        flip_averaged(np.zeros((2, NUM_JOINTS, 4, 4)), np.zeros((1, NUM_JOINTS, 4, 4)))


def test_averaging_maps_past_half_the_float32_range_does_not_overflow():
    """Two out-of-contract maps of peak 3e38 (a model without its sigmoid) summed to inf before halving, and
    the decoder drops a joint with an inf where it scales any other map past 1 back to its peak."""
    import warnings

    g = 32
    heat = np.zeros((1, NUM_JOINTS, g, g), np.float32)
    heat[0, 0] = 3e38 * _gaussian(g, 12.3, 20.6)
    mirrored = mirror_images(heat)  # an equivariant encoder: the nose mirrored is the nose
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        avg = flip_averaged(heat, mirrored)
    assert np.all(np.isfinite(avg)) and avg.dtype == np.float32
    kp = decode_keypoints(avg[:, :1])
    assert kp.valid[0, 0] and np.abs(kp.uv[0, 0] - [12.3, 20.6]).max() < 0.05


@pytest.mark.parametrize("heat, views, rank", [
    (np.zeros((2, NUM_JOINTS, 4, 4), np.float32), (), 3),             # numpy's "cannot reshape"
    (np.zeros((2, NUM_JOINTS, 0, 4), np.float32), (0, 1), 3),         # numpy's "zero-size array"
    (np.zeros((2, NUM_JOINTS, 4, 4), np.float32), (0, 1), 0),
])
def test_presence_peak_names_what_it_cannot_take(heat, views, rank):
    from ghnerf_runtime.errors import ShapeError
    from ghnerf_runtime.flip_test import presence_peak

    with pytest.raises(ShapeError, match="at least one view"):
        presence_peak(heat, views, rank)


@pytest.mark.parametrize("bad", [np.inf, -np.inf, np.nan])
def test_presence_peak_counts_no_peak_where_the_decoder_drops_the_joint(bad):
    """A map with a non-finite value anywhere is a missing joint to the 2D decoder; presence_peak counted an inf
    map as a full-strength peak (1.0) and a map with -inf beside a real blob as that blob, so the flip test's skip
    saw joints that the pair then did not report. (NaN already gave none: np.max passes it on.) No peak is the
    floor of the geometric mean, 1e-30."""
    from ghnerf_runtime.flip_test import presence_peak

    g = 16
    heat = np.zeros((2, NUM_JOINTS, g, g), np.float32)
    heat[:, :3] = 0.9 * _gaussian(g, 7.0, 7.0)  # three good joints in both views
    heat[:, 3] = 0.8 * _gaussian(g, 4.0, 9.0)   # a fourth, spoilt below by one bad cell per view
    heat[:, 3, 0, 0] = bad
    kp = decode_keypoints(heat)
    assert kp.valid[:, :3].all() and not kp.valid[:, 3].any()
    assert presence_peak(heat, (0, 1), 3) == pytest.approx(0.9)
    assert presence_peak(heat, (0, 1), 4) < 1e-20  # the fourth strongest: no peak (was 1.0 or 0.8)
    assert presence_peak(heat, (0,), 4) < 1e-20
