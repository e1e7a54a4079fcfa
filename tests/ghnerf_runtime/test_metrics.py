"""Metrics: hand-computed values, masks, missing joints, and degenerate inputs without NaN surprises."""
from __future__ import annotations

import doctest
import math
import re
import warnings

import cv2
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from ghnerf_runtime import metrics
from ghnerf_runtime.body25 import JOINT_INDEX, MID_HIP, NECK, NUM_JOINTS
from ghnerf_runtime.errors import ShapeError
from ghnerf_runtime.metrics import (
    TORSO_BOX_JOINTS, acceleration_error, gaussian_heatmaps, heatmap_mse, left_right_swaps, masked_psnr, masked_ssim,
    mpjpe, mpjpe_by_visibility, pck, visibility_class,
)


def test_doctests():
    result = doctest.testmod(metrics, raise_on_error=False)
    assert result.attempted >= 23 and result.failed == 0, result  # 23 examples when written


# --------------------------------------------------------------------------- PCK
# Toy skeleton: joint 0 "neck", 1 "mid-hip", 2 "shoulder", 3 "wrist".
TRUE = np.array([[0.0, 0.0], [0.0, 10.0], [6.0, 2.0], [5.0, 5.0]])
TOY = dict(torso_joints=(0, 1), box_joints=(0, 1, 2))


def test_pck_three_joint_toy_example():
    true = TRUE[[0, 1, 3]]
    pred = true + [[1.0, 0.0], [0.0, 3.0], [0.0, 2.0]]  # 1 px, 3 px, exactly 2 px (= 0.2 x 10)
    r = pck(pred, true, [True, True, True], torso_joints=(0, 1), box_joints=(0, 1))
    assert r.reference == pytest.approx(10.0)
    assert r.correct.tolist() == [True, False, True]  # the threshold is inclusive
    assert (r.value, r.num_evaluated, r.num_correct, r.num_missing) == (pytest.approx(2 / 3), 3, 2, 0)


def test_pck_missing_joints_are_excluded_and_counted():
    pred = TRUE + [[1.0, 0.0], [0.0, 3.0], [0.0, 0.0], [9.0, 9.0]]
    r = pck(pred, TRUE, [True, True, True, False], **TOY)
    assert r.evaluated.tolist() == [True, True, True, False]
    assert (r.num_evaluated, r.num_correct, r.num_missing) == (3, 2, 1)
    assert r.value == pytest.approx(2 / 3)


def test_pck_falls_back_to_torso_box_diagonal():
    # Neck missing: box of mid-hip (0, 10) and shoulder (6, 2) -> diagonal sqrt(36 + 64) = 10.
    pred = TRUE + [[0.0, 0.0], [0.0, 1.9], [2.1, 0.0], [0.0, 0.0]]
    r = pck(pred, TRUE, [False, True, True, True], **TOY)
    assert r.reference == pytest.approx(10.0)
    assert r.correct.tolist() == [False, True, False, True]
    assert (r.num_evaluated, r.num_correct, r.num_missing) == (3, 2, 1)


def test_pck_without_reference_is_undefined_but_counted():
    r = pck(TRUE, TRUE, [False, True, False, True], **TOY)  # one box joint only: no reference
    assert math.isnan(r.value)
    assert (r.num_evaluated, r.num_unreferenced, r.num_missing) == (0, 2, 2)
    empty = pck(TRUE, TRUE, [False] * 4, **TOY)
    assert math.isnan(empty.value) and empty.num_evaluated == 0 and empty.num_missing == 4


def test_pck_missing_predictions_count_as_wrong():
    pred = TRUE.copy()
    pred[3] = np.nan
    r = pck(pred, TRUE, [True] * 4, pred_valid=[True, False, True, True], **TOY)
    assert r.correct.tolist() == [True, False, True, False]
    assert (r.num_evaluated, r.num_pred_missing, r.value) == (4, 2, 0.5)


def test_pck_pools_a_batch_with_per_sample_references():
    true = np.stack([TRUE, 3.0 * TRUE])  # references 10 and 30
    pred = true + [[5.0, 0.0]] * 4  # 5 px off: wrong at 2 px tolerance, right at 6 px
    r = pck(pred, true, np.ones((2, 4), bool), **TOY)
    np.testing.assert_allclose(r.reference, [10.0, 30.0])
    assert r.correct.tolist() == [[False] * 4, [True] * 4]
    assert r.value == 0.5


def test_pck_body25_defaults():
    rng = np.random.default_rng(0)
    true = rng.uniform(0, 100, size=(3, NUM_JOINTS, 2))
    true[:, NECK] = [50.0, 20.0]
    true[:, MID_HIP] = [50.0, 70.0]  # reference 50 -> 10 px tolerance
    pred = true + [[9.0, 0.0]]
    pred[:, JOINT_INDEX["LWrist"]] += [0.0, 5.0]  # sqrt(81 + 25) > 10
    r = pck(pred, true, np.ones((3, NUM_JOINTS), bool))
    assert r.num_evaluated == 75 and r.num_correct == 72
    assert set(TORSO_BOX_JOINTS) == {JOINT_INDEX[n] for n in ("Neck", "RShoulder", "LShoulder", "MidHip", "RHip", "LHip")}


def test_pck_shape_errors():
    with pytest.raises(ShapeError):
        pck(TRUE, TRUE[:3], [True] * 4, **TOY)
    with pytest.raises(ShapeError):
        pck(TRUE, TRUE, [True] * 3, **TOY)
    with pytest.raises(ShapeError):
        pck(TRUE, TRUE, [True] * 4)  # default BODY_25 torso indices do not fit 4 joints


# ------------------------------------------------------------------------- MPJPE
def test_mpjpe_millimetres_hand_computed():
    true = np.array([[0.0, 0.0, 2.0], [0.1, -1.0, 3.0], [0.5, 0.5, 2.5]])
    pred = true + [[0.003, 0.004, 0.0], [0.0, 0.0, 0.010], [1.0, 1.0, 1.0]]
    r = mpjpe(pred, true, [True, True, False])
    np.testing.assert_allclose(r.errors, [5.0, 10.0, 0.0], atol=1e-9)
    assert r.value == pytest.approx(7.5)
    assert (r.num_evaluated, r.num_missing, r.num_pred_missing) == (2, 1, 0)


def test_mpjpe_missing_predictions_and_empty():
    true = np.zeros((2, 3, 3))
    pred = np.full((2, 3, 3), 0.002)
    pred[0, 0] = np.nan
    r = mpjpe(pred, true, np.ones((2, 3), bool))
    assert r.num_evaluated == 5 and r.num_pred_missing == 1
    assert r.value == pytest.approx(1000 * 0.002 * math.sqrt(3))
    assert np.all(np.isfinite(r.errors))
    empty = mpjpe(pred, true, np.zeros((2, 3), bool))
    assert math.isnan(empty.value) and empty.num_evaluated == 0 and empty.num_missing == 6
    with pytest.raises(ShapeError):
        mpjpe(pred[..., :2], true[..., :2], np.ones((2, 3), bool))


def test_mpjpe_split_by_visibility_hand_computed():
    # two pairs x three joints; errors 5, 10, 20 / 30, missing, 40 mm
    true = np.zeros((2, 3, 3))
    pred = true + np.array([[[0.005, 0, 0], [0, 0.010, 0], [0, 0, 0.020]],
                            [[0.030, 0, 0], [np.nan, 0, 0], [0, 0.040, 0]]])
    r = mpjpe(pred, true, np.ones((2, 3), bool))
    # visibility (pair, view, joint): pair 0 sees joint 0 in both views, 1 in one, 2 in none;
    # pair 1 sees every joint in both views except joint 2 (none)
    vis = np.array([[[1, 1, 0], [1, 0, 0]], [[1, 1, 0], [1, 1, 0]]], bool)
    assert visibility_class(vis).tolist() == [[0, 1, 2], [0, 0, 2]]
    split = mpjpe_by_visibility(r, vis)
    assert split["all_views"] == pytest.approx((35.0, 2))  # 5 + 30; the missing joint is not evaluated
    assert split["some_views"] == pytest.approx((10.0, 1))
    assert split["no_view"] == pytest.approx((60.0, 2))
    # the classes partition exactly what mpjpe evaluated
    assert sum(n for _, n in split.values()) == r.num_evaluated
    assert sum(t for t, _ in split.values()) == pytest.approx(r.value * r.num_evaluated)
    with pytest.raises(ShapeError, match="does not match"):
        mpjpe_by_visibility(r, vis[:1])
    with pytest.raises(ShapeError):
        visibility_class([True, False])


def test_acceleration_error_hand_computed():
    # one joint over five frames, errors along x of 0, 2, 0, 0, 0 mm; the truth itself moves (a still
    # error over a moving joint scores 0), the second joint's error is a constant 50 mm
    t = np.arange(5)[:, None] * np.array([0.1, 0.0, 0.0])  # 0.1 m per frame
    true = np.stack([t, t + [0, 1.0, 0]], axis=1)  # (5, 2, 3)
    pred = true.copy()
    pred[1, 0, 0] += 0.002
    pred[:, 1, 2] += 0.050
    r = acceleration_error(pred, true, np.ones((5, 2), bool))
    # second differences of joint 0: frames 1..3 -> |0 - 4 + 0| = 4, |2 - 0 + 0| = 2, 0 mm
    np.testing.assert_allclose(r.errors, [[4.0, 0.0], [2.0, 0.0], [0.0, 0.0]], atol=1e-9)
    assert r.num_evaluated == 6 and r.value == pytest.approx(1.0)
    # a missing prediction takes out every inner frame it neighbours
    found = np.ones((5, 2), bool)
    found[2, 0] = False
    m = acceleration_error(pred, true, np.ones((5, 2), bool), pred_valid=found)
    assert m.evaluated[:, 0].tolist() == [False, False, False] and m.num_evaluated == 3
    # a break in the chain (dropped frames, a new sequence) likewise
    c = acceleration_error(pred, true, np.ones((5, 2), bool), consecutive=[True, True, True, False, True])
    assert c.evaluated[:, 0].tolist() == [True, False, False]
    assert c.value == pytest.approx(4.0 / 2)  # frame 1: joint 0 (4 mm) and joint 1 (0)


def test_acceleration_error_short_and_bad_input():
    short = acceleration_error(np.zeros((2, 3, 3)), np.zeros((2, 3, 3)), np.ones((2, 3), bool))
    assert math.isnan(short.value) and short.num_evaluated == 0
    nothing = acceleration_error(np.zeros((4, 3, 3)), np.zeros((4, 3, 3)), np.zeros((4, 3), bool))
    assert math.isnan(nothing.value) and np.all(np.isfinite(nothing.errors))
    with pytest.raises(ShapeError, match=r"\(F, J, 3\)"):
        acceleration_error(np.zeros((3, 3)), np.zeros((3, 3)), np.ones(3, bool))
    with pytest.raises(ShapeError, match="consecutive"):
        acceleration_error(np.zeros((4, 3, 3)), np.zeros((4, 3, 3)), np.ones((4, 3), bool), consecutive=[True])


def test_left_right_swaps_hand_computed():
    # torso 0-1 of length 10: PCK radius 2 px. Pairs (2, 3) and (4, 5), truth 6 px apart.
    true = np.array([[0.0, 0.0], [0.0, 10.0], [-3.0, 5.0], [3.0, 5.0], [-3.0, 9.0], [3.0, 9.0]])
    kw = {"pairs": [(2, 3), (4, 5)], "torso_joints": (0, 1), "box_joints": (0, 1)}
    vis = np.ones(6, bool)
    # sample 0: pair (2, 3) exchanged (1 px off each way round): swapped; pair (4, 5) right as labelled
    p0 = true.copy()
    p0[2], p0[3] = true[3] + [1.0, 0.0], true[2] - [1.0, 0.0]
    # sample 1: pair (2, 3) both on joint 2 (one wrong, yet not exchanged): not swapped; joint 5 missing
    p1 = true.copy()
    p1[3] = true[2]
    r = left_right_swaps(np.stack([p0, p1]), np.stack([true, true]), np.stack([vis, vis]),
                         pred_valid=np.array([[True] * 6, [True] * 5 + [False]]), **kw)
    assert r.swapped.tolist() == [[True, False], [False, False]]
    assert r.evaluated.tolist() == [[True, True], [True, False]]  # the pair with a missing joint is left out
    assert (r.num_swapped, r.num_evaluated) == (1, 3) and r.value == pytest.approx(1 / 3)
    # a hidden joint leaves its pair out; nothing evaluated is undefined, not 0
    hidden = vis.copy()
    hidden[[2, 4]] = False
    empty = left_right_swaps(p0, true, hidden, **kw)
    assert empty.num_evaluated == 0 and math.isnan(empty.value)
    # BODY_25 defaults: 11 pairs, each a joint and its mirror
    assert len(metrics.LEFT_RIGHT_PAIRS) == 11
    assert (JOINT_INDEX["RShoulder"], JOINT_INDEX["LShoulder"]) in metrics.LEFT_RIGHT_PAIRS
    with pytest.raises(ShapeError, match="out of range"):
        left_right_swaps(true, true, vis, pairs=[(2, 9)], torso_joints=(0, 1), box_joints=(0, 1))


# ------------------------------------------------------------------------- PSNR
def test_psnr_of_a_known_mse():
    target = np.random.default_rng(0).random((2, 16, 16, 3))
    pred = target + 0.1  # MSE 0.01 -> 20 dB
    r = masked_psnr(pred, target, np.ones((2, 16, 16), bool))
    np.testing.assert_allclose(r.per_image, [20.0, 20.0])
    assert r.value == pytest.approx(20.0) and r.num_images == 2
    r255 = masked_psnr(np.full((8, 8), 10.0), np.zeros((8, 8)), np.ones((8, 8), bool), data_range=255.0)
    assert r255.value == pytest.approx(10 * math.log10(255 ** 2 / 100))


def test_psnr_ignores_pixels_outside_the_mask():
    target = np.zeros((10, 10))
    pred = np.full((10, 10), 1000.0)
    mask = np.zeros((10, 10), bool)
    mask[2:5, 2:5] = True
    pred[mask] = 0.05  # MSE inside = 0.0025 -> 26.02 dB
    r = masked_psnr(pred, target, mask)
    assert r.value == pytest.approx(10 * math.log10(1 / 0.0025))
    assert r.num_pixels == 9


def test_psnr_empty_mask_and_identical_images():
    img = np.random.default_rng(1).random((2, 8, 8))
    mask = np.ones((2, 8, 8), bool)
    mask[1] = False
    r = masked_psnr(img, img, mask)
    assert r.per_image[0] == math.inf and math.isnan(r.per_image[1]) and r.num_images == 1
    none = masked_psnr(img, img, np.zeros((2, 8, 8), bool))
    assert math.isnan(none.value) and none.num_images == 0


# ------------------------------------------------------------------------- SSIM
def test_ssim_identical_images_is_one():
    img = np.random.default_rng(2).random((2, 24, 24, 3))
    r = masked_ssim(img, img, np.ones((2, 24, 24), bool))
    np.testing.assert_allclose(r.per_image, 1.0, atol=1e-9)


def test_ssim_of_constant_images_hand_computed():
    # Flat images: variances are 0, so SSIM = (2 mx my + C1) / (mx^2 + my^2 + C1).
    c1 = (0.01 * 1.0) ** 2
    r = masked_ssim(np.full((16, 16), 0.5), np.full((16, 16), 0.6), np.ones((16, 16), bool))
    assert r.value == pytest.approx((2 * 0.5 * 0.6 + c1) / (0.25 + 0.36 + c1), rel=1e-9)


def test_ssim_matches_direct_window_sum_at_an_interior_pixel():
    rng = np.random.default_rng(3)
    x, y = rng.random((32, 32)), rng.random((32, 32))
    y = 0.7 * x + 0.3 * y  # correlated
    g = cv2.getGaussianKernel(11, 1.5)
    w = g @ g.T
    r0, c0 = 16, 15
    px, py = x[r0 - 5:r0 + 6, c0 - 5:c0 + 6], y[r0 - 5:r0 + 6, c0 - 5:c0 + 6]
    mx, my = (w * px).sum(), (w * py).sum()
    vx, vy = (w * px * px).sum() - mx ** 2, (w * py * py).sum() - my ** 2
    cxy = (w * px * py).sum() - mx * my
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    expected = (2 * mx * my + c1) * (2 * cxy + c2) / ((mx ** 2 + my ** 2 + c1) * (vx + vy + c2))
    # The per-pixel map is private; the public value is its mean over the mask.
    ssim_map = metrics._ssim_map(x, y, np.ones((32, 32)), 1.0)
    assert ssim_map[r0, c0] == pytest.approx(expected, rel=1e-9)
    assert masked_ssim(x, y, np.ones((32, 32), bool)).value == pytest.approx(ssim_map.mean(), rel=1e-12)


def test_ssim_masked_ignores_outside_pixels():
    rng = np.random.default_rng(4)
    target = rng.random((40, 40, 3))
    pred = np.clip(target + rng.normal(0, 0.05, target.shape), 0, 1)
    mask = np.zeros((40, 40), bool)
    mask[10:30, 12:28] = True
    base = masked_ssim(pred, target, mask)
    wrecked = pred.copy()
    wrecked[~mask] = rng.random(((~mask).sum(), 3))
    assert masked_ssim(wrecked, target, mask).value == pytest.approx(base.value, abs=1e-12)
    assert 0.5 < base.value < 1.0
    assert math.isnan(masked_ssim(pred, target, np.zeros((40, 40), bool)).value)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_pixels_outside_the_mask_do_not_reach_the_score(bad):
    rng = np.random.default_rng(5)
    target = rng.random((2, 24, 24, 3))
    pred = np.clip(target + rng.normal(0, 0.05, target.shape), 0, 1)
    mask = np.zeros((2, 24, 24), bool)
    mask[:, 6:18, 5:20] = True
    broken = pred.copy()
    broken[~mask] = bad  # 0 * NaN (and 0 * inf) is NaN: a masked product would score NaN
    for metric in (masked_psnr, masked_ssim):
        assert metric(broken, target, mask).value == pytest.approx(metric(pred, target, mask).value, abs=1e-12)
    inside = broken.copy()
    inside[0, 10, 10] = np.nan  # inside the mask a broken pixel still propagates
    assert math.isnan(masked_psnr(inside, target, mask).per_image[0])
    assert math.isnan(masked_ssim(inside, target, mask).per_image[0])


def test_image_metric_shape_errors():
    with pytest.raises(ShapeError):
        masked_psnr(np.zeros((8, 8, 3)), np.zeros((8, 8, 3)), np.ones((8, 7), bool))
    with pytest.raises(ShapeError):
        masked_ssim(np.zeros((8, 8)), np.zeros((8, 9)), np.ones((8, 8), bool))



@pytest.mark.parametrize("metric", [masked_psnr, masked_ssim])
@pytest.mark.parametrize("bad", [-1.0, 0.0, np.nan, np.inf, "255", True])
def test_image_metrics_refuse_a_data_range_that_is_not_a_positive_number(metric, bad):
    """-1 scored as 1 (squared), 0 gave -inf dB and a NaN SSIM."""
    a, m = np.zeros((4, 4)), np.ones((4, 4), bool)
    with pytest.raises(ValueError, match="data_range"):
        metric(a, a + 0.1, m, data_range=bad)


@pytest.mark.parametrize("metric", [masked_psnr, masked_ssim])
def test_image_metrics_refuse_images_outside_the_data_range(metric):
    """An 8-bit pair at the default data_range 1.0 scored -20 dB (PSNR) and a uint8 prediction against a [0, 1]
    truth anything at all, silently; the same pair with data_range 255 is scored."""
    m = np.ones((16, 16), bool)
    a8, b8 = np.full((16, 16, 3), 200, np.uint8), np.full((16, 16, 3), 190, np.uint8)
    with pytest.raises(ValueError, match=r"target values inside the mask span \[190, 190\].*data_range=1"):
        metric(a8, b8, m)
    with pytest.raises(ValueError, match="pred is uint8 and target float64"):
        metric(a8, b8 / 255.0, m)
    with pytest.raises(ValueError, match="pred is float64 and target uint8"):
        metric(a8 / 255.0, b8, m, data_range=255)
    with pytest.raises(ValueError, match="pred is uint16 with values up to 300"):
        metric(a8.astype(np.uint16) + 100, b8.astype(np.uint16), m, data_range=255)
    assert metric(a8, b8, m, data_range=255).value == pytest.approx(metric(a8 / 255.0, b8 / 255.0, m).value)
    # only the mask counts; a float prediction may overshoot (scored as it is), the truth a hair (float noise)
    outside = np.zeros((16, 16), bool)
    outside[4:8, 4:8] = True
    wild = np.where(outside[..., None], b8 / 255.0, 7.0)
    assert math.isfinite(metric(b8 / 255.0 + 0.5, wild, outside).value)
    assert math.isfinite(metric(b8 / 255.0, b8 / 255.0 * 1.005, m).value)
    with pytest.raises(ShapeError, match="at least 1x1"):
        metric(np.zeros((0, 0)), np.zeros((0, 0)), np.ones((0, 0), bool))


@pytest.mark.parametrize("metric", [masked_psnr, masked_ssim])
@pytest.mark.parametrize("data_range", [1e-200, 1e200])
def test_image_metrics_at_a_data_range_whose_square_leaves_float64(metric, data_range):
    """The scores depend on the images over data_range alone: at 1e-200 its square underflowed (0 / 0: a NaN PSNR
    and SSIM with a RuntimeWarning), at 1e200 it overflowed (the same)."""
    rng = np.random.default_rng(7)
    a, b, m = rng.random((12, 12)), rng.random((12, 12)), np.ones((12, 12), bool)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scaled = metric(a * data_range, b * data_range, m, data_range=data_range).value
    assert scaled == pytest.approx(metric(a, b, m).value, rel=1e-12)


def test_image_metrics_on_images_smaller_than_the_ssim_window():
    """1x1 and 3x3 images: the window is renormalised over the pixels there are, never NaN."""
    one = masked_ssim(np.full((1, 1), 0.5), np.full((1, 1), 0.6), np.ones((1, 1), bool))
    c1 = 0.01 ** 2
    assert one.value == pytest.approx((2 * 0.5 * 0.6 + c1) / (0.25 + 0.36 + c1))  # flat: luminance only
    rng = np.random.default_rng(6)
    x = rng.random((3, 3, 3))
    assert masked_ssim(x, x, np.ones((3, 3), bool)).value == pytest.approx(1.0)
    assert masked_psnr(x, x, np.ones((3, 3), bool)).value == math.inf


# ---------------------------------------------------------------------- heatmaps
def test_heatmap_mse_and_valid_selection():
    target = np.zeros((2, 3, 4, 4))
    pred = np.zeros((2, 3, 4, 4))
    pred[0, 1] = 0.5
    assert heatmap_mse(pred, target).value == pytest.approx(0.25 / 6)
    sel = heatmap_mse(pred, target, valid=[[False, True, False], [False, False, False]])
    assert sel.value == pytest.approx(0.25) and sel.count == 16
    none = heatmap_mse(pred, target, valid=np.zeros((2, 3), bool))
    assert math.isnan(none.value) and none.count == 0
    with pytest.raises(ShapeError):
        heatmap_mse(pred, target[..., :3])


def test_gaussian_heatmaps():
    joints = np.array([[[3.0, 5.0], [1.5, 2.5], [np.nan, 1.0]]])
    h = gaussian_heatmaps(joints, [[True, False, True]], (8, 6), sigma=2.0)
    assert h.shape == (1, 3, 8, 6) and h.dtype == np.float32
    assert h[0, 0, 5, 3] == 1.0 and h[0, 0].max() == 1.0
    assert h[0, 0, 5, 4] == pytest.approx(math.exp(-1 / 8))  # one pixel away, sigma 2
    assert h[0, 0, 4, 2] == pytest.approx(math.exp(-2 / 8))
    assert np.all(h[0, 1] == 0) and np.all(h[0, 2] == 0)  # not visible; non-finite
    sq = gaussian_heatmaps([[2.0, 2.0]], [True], 5, sigma=1.0)
    np.testing.assert_allclose(sq[0], sq[0].T)
    with pytest.raises(ValueError):
        gaussian_heatmaps([[2.0, 2.0]], [True], 5, sigma=0.0)


def test_gaussian_heatmaps_at_the_ends_of_float64():
    """A sigma of 1e-200 squared to 0 (0 / 0 on the joint's pixel: a NaN target, with a warning); a joint 1e300
    pixels off squared to inf, a warning for its (right) all-zero map."""
    with pytest.raises(ValueError, match="sigma must be a positive number whose square float64 holds, got 1e-200"):
        gaussian_heatmaps([[2.0, 2.0]], [True], 5, sigma=1e-200)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        far = gaussian_heatmaps([[1e300, 2.0], [2.0, 2.0]], [True, True], 5, sigma=1.0)
    assert np.all(far[0] == 0) and far[1].max() == 1.0


# ------------------------------------------------------------------- properties
@settings(max_examples=60, deadline=None)
@given(data=st.data(), batch=st.integers(1, 3))
def test_pck_counts_add_up(data, batch):
    coords = st.one_of(st.floats(-50, 50), st.just(np.nan))
    true = data.draw(arrays(np.float64, (batch, 4, 2), elements=coords))
    pred = data.draw(arrays(np.float64, (batch, 4, 2), elements=coords))
    valid = data.draw(arrays(bool, (batch, 4)))
    r = pck(pred, true, valid, **TOY)
    assert r.num_evaluated + r.num_missing + r.num_unreferenced == batch * 4
    assert r.num_correct <= r.num_evaluated and r.num_pred_missing <= r.num_evaluated
    assert math.isnan(r.value) == (r.num_evaluated == 0)
    if r.num_evaluated:
        assert 0.0 <= r.value <= 1.0
    assert np.all(np.isfinite(r.reference)) and not np.any(r.correct & ~r.evaluated)


def test_a_report_with_numpy_nan_writes_strict_json():
    """finite_or_none turns numpy float NaN/inf (float32 is no Python float) into null, so the strict JSON
    dump ghnerf-bench and ghnerf-eval write never holds NaN."""
    import json

    from ghnerf_runtime.metrics import finite_or_none

    report = {"mpjpe_mm": np.float32("nan"), "rows": [np.float16("inf"), np.float64("nan"), 3], "ok": np.float32(1)}
    text = json.dumps(finite_or_none(report), default=float, allow_nan=False)
    assert json.loads(text) == {"mpjpe_mm": None, "rows": [None, None, 3], "ok": 1.0}


def test_scorable_images_marks_a_view_with_any_non_finite_pixel_and_keeps_a_float32_render_float32():
    """What ghnerf-eval and the painter's table share: a NaN or +-inf anywhere breaks the whole view (before the
    clip, which would score +inf as 1); the other views are clipped; a float32 render is not doubled in size."""
    imgs = np.full((3, 4, 4, 3), 0.5, np.float32)
    imgs[0, 0, 0, 0] = 1.7  # overshoot: clipped, scored
    imgs[1, 3, 3, 2] = -np.inf
    imgs[2, 1, 2, 0] = np.nan
    out, broken = metrics.scorable_images(imgs)
    assert out.dtype == np.float32 and broken.tolist() == [False, True, True]
    assert out[0].max() == 1.0 and np.isnan(out[1:]).all()
    assert metrics.scorable_images(np.full((1, 2, 2), 300, np.uint16), data_range=255)[0].max() == 255.0
    with pytest.raises(ShapeError, match="leading image axis"):
        metrics.scorable_images(np.float32(0.5))
    with pytest.raises(ValueError, match="data_range"):
        metrics.scorable_images(imgs, data_range=0)


# ------------------------------------------------------------- ends of float64
def _no_warnings(fn, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return fn(*args, **kwargs)


@settings(max_examples=80, deadline=None)
@given(k=st.integers(-990, 990), seed=st.integers(0, 2 ** 32 - 1))
@example(k=990, seed=0)
@example(k=-990, seed=0)
def test_joint_metrics_scale_with_their_inputs_across_float64(k, seed):
    """Joints scaled by 2**k (1e-298..1e298) score the unscaled score scaled alike (PCK: unchanged), with no
    RuntimeWarning: squares past 1e154 overflowed (inf/NaN scores), squares below 1e-154 underflowed (0 mm)."""
    rng = np.random.default_rng(seed)
    s = math.ldexp(1.0, k)
    true = rng.normal(size=(5, 4, 3))
    pred = true + rng.normal(scale=0.01, size=true.shape)
    valid = np.ones((5, 4), bool)
    for fn in (mpjpe, acceleration_error):
        plain, scaled = fn(pred, true, valid), _no_warnings(fn, pred * s, true * s, valid)
        assert scaled.value == pytest.approx(plain.value * s, rel=1e-12)
        np.testing.assert_allclose(scaled.errors, plain.errors * s, rtol=1e-12)
    true2, pred2 = true[..., :2], true[..., :2] + rng.normal(scale=0.3, size=(5, 4, 2))
    plain, scaled = pck(pred2, true2, valid, **TOY), _no_warnings(pck, pred2 * s, true2 * s, valid, **TOY)
    assert scaled.correct.tolist() == plain.correct.tolist()
    np.testing.assert_allclose(scaled.reference, plain.reference * s, rtol=1e-12)
    swaps = _no_warnings(left_right_swaps, pred2 * s, true2 * s, valid, pairs=[(2, 3)], torso_joints=(0, 1),
                         box_joints=(0, 1, 2))
    assert swaps.evaluated.tolist() == left_right_swaps(pred2, true2, valid, pairs=[(2, 3)], torso_joints=(0, 1),
                                                        box_joints=(0, 1, 2)).evaluated.tolist()


@settings(max_examples=60, deadline=None)
@given(k=st.integers(-500, 510), seed=st.integers(0, 2 ** 32 - 1))
@example(k=510, seed=0)
def test_heatmap_mse_scales_with_its_inputs_across_float64(k, seed):
    """Heatmaps scaled by 2**k score 4**k times the MSE wherever that is a float64 (to 2**1020 here): the sum of
    squares of 384 values reached inf from 2**509 on, the mean did not."""
    rng = np.random.default_rng(seed)
    s = math.ldexp(1.0, k)
    pred, target = rng.random((2, 3, 8, 8)), rng.random((2, 3, 8, 8))
    scaled = _no_warnings(heatmap_mse, pred * s, target * s).value
    assert scaled == pytest.approx(heatmap_mse(pred, target).value * s * s, rel=1e-12)


def test_joint_metrics_at_the_ends_of_float64():
    """Hand-checked: a 1e200 m error is 1e203 mm (was inf), a 1e-200 m one 1e-197 mm (was 0); two 1e305 m errors
    average 1e308 mm (their sum is past float64: was inf); an error past float64 is inf, without a warning."""
    one, zero = [True], np.zeros((1, 3))
    assert _no_warnings(mpjpe, [[0, 0, 1e200]], zero, one).value == pytest.approx(1e203, rel=1e-15)
    assert _no_warnings(mpjpe, [[3e-200, 4e-200, 0]], zero, one).value == pytest.approx(5e-197, rel=1e-15)
    assert _no_warnings(mpjpe, [[0, 0, 1e305]] * 2, np.zeros((2, 3)), [True] * 2).value == pytest.approx(1e308)
    assert _no_warnings(mpjpe, [[0, 0, 1e308]], [[0, 0, -1e308]], one).value == math.inf
    # a constant 2e308 m offset (past float64 as a difference) has no acceleration; one frame off has 4e308: inf
    pred, true = np.full((4, 1, 3), 1e308), np.full((4, 1, 3), -1e308)
    assert _no_warnings(acceleration_error, pred, true, np.ones((4, 1), bool)).value == 0.0
    pred[1] = -1e308
    assert _no_warnings(acceleration_error, pred, true, np.ones((4, 1), bool)).errors[0, 0] == math.inf
    assert _no_warnings(heatmap_mse, np.full((2, 3, 3), 1e154), np.zeros((2, 3, 3))).value == pytest.approx(1e308)


def test_pck_box_past_float64_is_no_reference():
    """A torso box from x = -1e308 to 1e308 (neck missing) has a diagonal past float64: no reference length, so
    the sample is unreferenced. nan_to_num made that extent 0, a diagonal of the y extent alone (8 px)."""
    true = np.array([[0.0, 0.0], [-1e308, 10.0], [1e308, 2.0], [5.0, 5.0]])
    r = _no_warnings(pck, true, true, [False, True, True, True], **TOY)
    assert r.reference == 0.0 and r.num_unreferenced == 3 and r.num_evaluated == 0


@pytest.mark.parametrize("spike", [1e160, 1e200, 1e300, 1.7e308, -1e300])
def test_image_metrics_of_a_prediction_past_1e154_data_ranges(spike):
    """One wild pixel (a broken render's overshoot): its squares overflowed, a NaN SSIM and a -inf dB PSNR with
    RuntimeWarnings. SSIM: the windows around it score ~0 as they do for a 1e70 spike; PSNR: the mean square is
    spike**2 / (pixels * channels), so -20 log10 |spike| + 10 log10(768)."""
    rng = np.random.default_rng(3)
    truth, m = rng.random((16, 16, 3)), np.ones((16, 16), bool)
    pred, moderate = truth.copy(), truth.copy()
    pred[8, 8, 1], moderate[8, 8, 1] = spike, 1e70
    assert _no_warnings(masked_ssim, pred, truth, m).value == pytest.approx(masked_ssim(moderate, truth, m).value,
                                                                            rel=1e-12)
    expected = -20 * math.log10(abs(spike)) + 10 * math.log10(16 * 16 * 3)
    assert _no_warnings(masked_psnr, pred, truth, m).value == pytest.approx(expected, rel=1e-12)


def test_wild_ssim_map_agrees_with_the_plain_one_where_both_hold():
    """The scaled luminance and structure ratios, run where the plain formula still holds (its bound lowered to
    1e3 for a 1e60 spike, on a half mask): the same map to 1e-12."""
    rng = np.random.default_rng(4)
    x, y = rng.random((20, 24)), rng.random((20, 24))
    x[9, 7], y[3, 20] = 1e60, -1e50
    m = (rng.random((20, 24)) < 0.5).astype(np.float64)
    m[9, 7] = m[3, 20] = 1.0
    wild, plain = metrics._wild_ssim_map(x, y, m, plain_max=1e3), metrics._ssim_map(x, y, m, 1.0)
    np.testing.assert_allclose(wild, plain, rtol=1e-12, atol=1e-15)
    assert not np.array_equal(wild, metrics._wild_ssim_map(x, y, m))  # the lowered bound took the scaled path


# ------------------------------------------------------------ scalar arguments
@pytest.mark.parametrize("bad", [True, np.True_, "2", None, 0, -1.0, math.nan, math.inf,
                                 pytest.param(10 ** 400, id="int-past-float64")])
def test_gaussian_heatmaps_refuses_a_sigma_that_is_not_a_positive_number(bad):
    """True was a sigma of 1 (a bool is an int), "2" and None raised numpy's bare TypeError."""
    with pytest.raises(ValueError, match=r"sigma must be a positive number \(heatmap pixels\), got "
                                         + re.escape(metrics._shown(bad))):
        gaussian_heatmaps([[2.0, 2.0]], [True], 5, sigma=bad)


def test_gaussian_heatmaps_takes_numpy_and_int_sigmas_and_sizes():
    ref = gaussian_heatmaps([[2.0, 1.0]], [True], (5, 4), sigma=2.0)
    for size, sigma in (((np.int64(5), 4), 2), (np.array([5, 4]), np.float32(2.0)), ([5, 4], np.float64(2.0))):
        np.testing.assert_array_equal(_no_warnings(gaussian_heatmaps, [[2.0, 1.0]], [True], size, sigma), ref)


@pytest.mark.parametrize("bad", [True, "8", 8.7, (4,), (4, 5, 6), (4, 0)])
def test_gaussian_heatmaps_refuses_a_size_that_is_not_positive_ints(bad):
    """int() took True as a 1x1 map, 8.7 as 8, "8" as 8, and (4, 5, 6) as (4, 5)."""
    with pytest.raises(ShapeError, match="heatmap size must be a positive int or"):
        gaussian_heatmaps([[2.0, 2.0]], [True], bad, sigma=1.0)


@pytest.mark.parametrize(("kw", "message"), [
    ({"alpha": True}, "alpha must be a positive number, got True"),
    ({"alpha": "0.2"}, "alpha must be a positive number, got '0.2'"),
    ({"torso_joints": (0, True)}, "torso_joints: a joint index must be an int, got True"),
    ({"box_joints": ("0", 1)}, "box_joints: a joint index must be an int, got '0'"),
    ({"box_joints": (0, 1.0)}, "box_joints: a joint index must be an int, got 1.0"),
])
def test_pck_and_swaps_refuse_bool_and_text_arguments(kw, message):
    """int() took True as joint 1 and "0" as joint 0; alpha=True was PCK@1 and "0.2" numpy's bare TypeError."""
    args = {**TOY, **kw}
    with pytest.raises(ValueError, match=re.escape(message)):
        pck(TRUE, TRUE, [True] * 4, **args)
    with pytest.raises(ValueError, match=re.escape(message)):
        left_right_swaps(TRUE, TRUE, [True] * 4, pairs=[(2, 3)], **args)
    with pytest.raises(ValueError, match=re.escape("pairs: a joint index must be an int, got True")):
        left_right_swaps(TRUE, TRUE, [True] * 4, pairs=[(2, True)], **TOY)
    with pytest.raises(ShapeError, match="torso_joints: joint index 7 out of range for 4 joints"):
        pck(TRUE, TRUE, [True] * 4, torso_joints=(0, 7), box_joints=(0, 1))
    numpy_args = {"torso_joints": (np.int64(0), 1), "box_joints": (0, 1), "alpha": np.float32(0.2)}
    assert pck(TRUE, TRUE, [True] * 4, **numpy_args).value == 1.0


@pytest.mark.parametrize(("alpha", "correct"), [(2.0, False), (6.0, True)])
def test_pck_and_swaps_compare_a_distance_and_radius_both_past_float64(alpha, correct):
    """A reference of 1e308 px with alpha 2 or 6 is a radius past float64, and a joint 4.8e308 px off a distance
    past float64: inf <= inf counted it correct for any alpha. Exactly, 4.8e308 > 2e308 and 4.8e308 < 6e308."""
    true = np.array([[-0.5e308, 0.0], [0.5e308, 0.0], [1.7e308, 1.7e308], [0.0, 0.0]])
    pred = true.copy()
    pred[2] = -1.7e308
    r = _no_warnings(pck, pred, true, [True] * 4, alpha=alpha, **TOY)
    assert r.reference == 1e308 and r.correct.tolist() == [True, True, correct, True]
    # joints 2 and 3 predicted exchanged, 4.8e308 px from their own truths: a swap unless that is within the radius
    true[3], pred[3] = [-1.7e308, -1.7e308], [1.7e308, 1.7e308]
    swaps = _no_warnings(left_right_swaps, pred, true, [True] * 4, pairs=[(2, 3)], alpha=alpha, **TOY)
    assert swaps.num_evaluated == 1 and swaps.swapped.tolist() == [not correct]


@pytest.mark.parametrize("bad", [10 ** 400, -10 ** 5000], ids=["1e400", "-1e5000"])
def test_an_int_past_float64_is_refused_by_its_size_not_its_digits(bad):
    """The message held all 400 digits; past 4300 digits repr() itself raised (Python's int-to-text limit)."""
    bits = abs(bad).bit_length()
    with pytest.raises(ValueError, match=re.escape(f"data_range must be a positive number (1.0 for [0, 1] images, "
                                                   f"255 for 8-bit), got an int of {bits} bits (past float64)")):
        masked_psnr(np.zeros((2, 2)), np.zeros((2, 2)), np.ones((2, 2), bool), data_range=bad)
    with pytest.raises(ShapeError, match=re.escape(f"box_joints: joint index an int of {bits} bits (past float64) "
                                                   f"out of range for 4 joints")):
        pck(TRUE, TRUE, [True] * 4, torso_joints=(0, 1), box_joints=(0, bad))


def test_image_metrics_of_a_prediction_past_float64_in_data_ranges():
    """A 1e300 pixel against 1e-10 data ranges is 1e310 of them, past float64: PSNR was -inf, SSIM NaN (with
    RuntimeWarnings). PSNR: -20 log10(1e310) + 10 log10(768); SSIM: its windows score ~0, as a 1e60 one's do."""
    rng = np.random.default_rng(5)
    truth, m = rng.random((16, 16, 3)) * 1e-10, np.ones((16, 16), bool)
    pred, moderate = truth.copy(), truth.copy()
    pred[8, 8, 1], moderate[8, 8, 1] = 1e300, 1e50
    r = _no_warnings(masked_psnr, pred, truth, m, data_range=1e-10)
    assert r.value == pytest.approx(-3100 * 2 + 10 * math.log10(16 * 16 * 3), rel=1e-12)
    assert _no_warnings(masked_ssim, pred, truth, m, data_range=1e-10).value == pytest.approx(
        masked_ssim(moderate, truth, m, data_range=1e-10).value, rel=1e-12)


@pytest.mark.parametrize("offset", [1e-170, 1e-300])
def test_psnr_of_differences_below_1e154_data_ranges_is_finite(offset):
    """Every pixel off by 1e-170 data ranges: the squares underflowed to 0, +inf dB (identical images), where it
    is 20 * 170 = 3400 dB. 1 / mse of a subnormal mse (1e-300: its square 1e-600 is 0 too) overflowed alike."""
    truth, m = np.zeros((4, 4)), np.ones((4, 4), bool)
    assert _no_warnings(masked_psnr, truth + offset, truth, m).value == pytest.approx(-20 * math.log10(offset),
                                                                                      rel=1e-12)
    assert masked_psnr(truth, truth, m).value == math.inf  # identical: still +inf


@pytest.mark.parametrize("sigma", [np.int64(2 ** 40), 2 ** 70, 10 ** 300], ids=["int64-2e40", "2e70", "1e300"])
def test_gaussian_heatmaps_takes_a_large_int_sigma_as_its_float(sigma):
    """An int sigma is a number like any: 2 sigma^2 wrapped in int64 (2**40: 0, refused as underflowing) or was a
    Python int past float64 (10**300: OverflowError)."""
    ref = gaussian_heatmaps([[2.0, 1.0]], [True], (5, 4), sigma=float(sigma))
    np.testing.assert_array_equal(_no_warnings(gaussian_heatmaps, [[2.0, 1.0]], [True], (5, 4), sigma), ref)


@pytest.mark.parametrize(("data_range", "spike"), [(2 ** 70, 1e200), (10 ** 300, 1.0)], ids=["2e70", "1e300"])
def test_psnr_takes_an_int_data_range_past_int64(data_range, spike):
    """A wild prediction's PSNR (1e179 data ranges: a mean square past float64; 1e-300 of them: below its normal
    numbers) took log10 of the int itself: numpy has no log10 for an int past int64 (TypeError)."""
    truth, m = np.zeros((4, 4)), np.ones((4, 4), bool)
    pred = truth.copy()
    pred[0, 0] = spike
    expected = 20 * (math.log10(data_range) - math.log10(spike)) + 10 * math.log10(16)
    assert _no_warnings(masked_psnr, pred, truth, m, data_range=data_range).value == pytest.approx(expected, rel=1e-12)
