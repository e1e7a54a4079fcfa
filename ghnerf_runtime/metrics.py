"""Evaluation metrics, defined once for training evaluation and the runtime alike.

Every definition here is restated in ``docs/metrics.md``; change both together.

* :func:`pck` -- PCK@alpha of 2D joints against a per-sample torso reference length.
* :func:`mpjpe` -- mean per-joint 3D position error, millimetres (inputs in metres).
* :func:`mpjpe_by_visibility` -- that error split by how many views see each joint.
* :func:`acceleration_error` -- jitter: the second difference of the 3D error from frame to frame.
* :func:`left_right_swaps` -- how often a left/right pair of 2D joints comes out exchanged.
* :func:`masked_psnr`, :func:`masked_ssim` -- image quality inside a mask; :func:`scorable_images` and
  :func:`capped_psnr` -- how a pooled score takes renders (a broken one counted, an identical one capped).
* :func:`heatmap_mse` -- mean squared error between heatmaps.
* :func:`gaussian_heatmaps` -- the ground-truth heatmap generator (training targets, tests).

Conventions: numpy only, batch dimensions first, shapes checked on entry
(:class:`~ghnerf_runtime.errors.ShapeError`). Metrics return small result objects
holding the value *and* the counts behind it. The value is ``nan`` only where
the metric is undefined (nothing to evaluate); each function says when.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from ghnerf_runtime.body25 import FLIP_INDEX, JOINT_INDEX, MID_HIP, NECK
from ghnerf_runtime.errors import ShapeError
from ghnerf_runtime.plain_values import numpy_for_json

#: BODY_25 joints whose bounding box gives the fallback PCK reference length:
#: Neck, RShoulder, LShoulder, MidHip, RHip, LHip.
TORSO_BOX_JOINTS: tuple[int, ...] = tuple(
    JOINT_INDEX[n] for n in ("Neck", "RShoulder", "LShoulder", "MidHip", "RHip", "LHip")
)

#: The BODY_25 left/right joint pairs ``(a, b)``, ``a < b`` (RShoulder/LShoulder, ..., LHeel/RHeel): 11.
LEFT_RIGHT_PAIRS: tuple[tuple[int, int], ...] = tuple((j, m) for j, m in enumerate(FLIP_INDEX) if m > j)

# SSIM constants of Wang et al. 2004 ("Image quality assessment: from error
# visibility to structural similarity", IEEE TIP 13(4)): 11x11 Gaussian window,
# sigma 1.5, K1 = 0.01, K2 = 0.03.
SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
SSIM_K1 = 0.01
SSIM_K2 = 0.03

__all__ = [
    "TORSO_BOX_JOINTS", "LEFT_RIGHT_PAIRS", "PckResult", "SwapResult", "MpjpeResult", "ImageMetricResult",
    "MseResult", "VISIBILITY_CLASSES", "visibility_class", "mpjpe_by_visibility", "left_right_swaps",
    "AccelerationResult", "acceleration_error", "pck", "mpjpe", "masked_psnr", "masked_ssim", "heatmap_mse",
    "gaussian_heatmaps", "finite_or_none", "strict_json", "PSNR_CAP_DB", "capped_psnr", "scorable_images",
]


def finite_or_none(value):
    """A metrics report with every non-finite float (a metric with nothing to score, a broken model's
    NaN) as ``None``: strict JSON, which refuses NaN and infinity. numpy floats too (a float32 is no Python
    float, and ``json.dump(default=float)`` wrote its NaN).

    Example:
        >>> finite_or_none({"a": [1.5, float("nan")], "b": np.float32("inf"), "c": np.float32(2.0)})
        {'a': [1.5, None], 'b': None, 'c': np.float32(2.0)}
    """
    if isinstance(value, dict):
        return {k: finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_none(v) for v in value]
    if isinstance(value, (float, np.floating)) and not np.isfinite(value):
        return None
    return value


def _json_default(value):
    """A value ``json`` cannot write: numpy scalars as Python numbers (``default=str`` wrote a float32 2.5 as the
    string ``"2.5"``, ``default=float`` an int64 count as 3.0), arrays as lists (non-finite entries ``None``),
    anything else (a path) as text."""
    try:
        return finite_or_none(numpy_for_json(value))
    except TypeError:  # not NumPy (a path): the reports are read by people, so as text
        return str(value)


def strict_json(report, indent: int | None = 1) -> str:
    """``report`` as strict JSON: every NaN or infinity (a metric with nothing to score, a PSNR of identical
    images) as ``null``. ``json.dumps`` writes them as bare ``NaN`` / ``Infinity``, which is not JSON: other
    readers (``jq``, browsers, most languages) refuse the whole file. The one writer of the bench's, the
    benchmarks' and the training side's reports (``training.model_card`` takes it from here: the runtime imports
    nothing of training)."""
    return json.dumps(finite_or_none(report), indent=indent, default=_json_default, allow_nan=False)


# ------------------------------------------------------------------ results
@dataclass(frozen=True, eq=False)
class PckResult:
    """PCK over a batch, pooled over every evaluated joint of every sample.

    Attributes:
        value: ``num_correct / num_evaluated``; ``nan`` when ``num_evaluated == 0``.
        correct: ``(..., J)`` bool, True where the joint was evaluated and correct.
        evaluated: ``(..., J)`` bool, True where the truth is valid and the sample has a
            reference length.
        reference: ``(...)`` reference length per sample (pixels); ``0.0`` where none.
        num_evaluated: joints that entered the score.
        num_correct: evaluated joints within ``alpha * reference`` of the truth.
        num_missing: joints excluded because their truth is not valid.
        num_unreferenced: joints with valid truth excluded because their sample had
            no usable reference length.
        num_pred_missing: evaluated joints with no prediction (scored as wrong).
    """

    value: float
    correct: np.ndarray
    evaluated: np.ndarray
    reference: np.ndarray
    num_evaluated: int
    num_correct: int
    num_missing: int
    num_unreferenced: int
    num_pred_missing: int


@dataclass(frozen=True, eq=False)
class SwapResult:
    """Left/right swaps over a batch (:func:`left_right_swaps`).

    Attributes:
        value: ``num_swapped / num_evaluated``; ``nan`` when ``num_evaluated == 0``.
        swapped: ``(..., P)`` bool per sample and pair of ``pairs``.
        evaluated: ``(..., P)`` bool: both joints' truth valid, both predicted, a reference length.
        num_evaluated: pairs that entered the rate.
        num_swapped: evaluated pairs found exchanged.
    """

    value: float
    swapped: np.ndarray
    evaluated: np.ndarray
    num_evaluated: int
    num_swapped: int


@dataclass(frozen=True, eq=False)
class MpjpeResult:
    """MPJPE over a batch, pooled over every evaluated joint.

    Attributes:
        value: mean error in millimetres; ``nan`` when ``num_evaluated == 0``.
        errors: ``(..., J)`` per-joint error in millimetres; ``0.0`` where not evaluated.
        evaluated: ``(..., J)`` bool.
        num_evaluated: joints that entered the mean.
        num_missing: joints excluded because the truth is not valid.
        num_pred_missing: joints with valid truth excluded because the prediction is
            missing (``pred_valid`` False or non-finite). Report it next to the value:
            a method that drops hard joints looks better otherwise.
    """

    value: float
    errors: np.ndarray
    evaluated: np.ndarray
    num_evaluated: int
    num_missing: int
    num_pred_missing: int


@dataclass(frozen=True, eq=False)
class AccelerationResult:
    """The acceleration error of a joint sequence (:func:`acceleration_error`).

    Attributes:
        value: mean error in millimetres per frame squared; ``nan`` when ``num_evaluated == 0``.
        errors: ``(F - 2, J)`` per inner frame and joint, mm per frame squared; ``0.0`` where not evaluated.
        evaluated: ``(F - 2, J)`` bool: the joint is evaluated in the frame and both its neighbours.
        num_evaluated: (inner frame, joint) entries that entered the mean.
    """
    value: float
    errors: np.ndarray
    evaluated: np.ndarray
    num_evaluated: int


@dataclass(frozen=True, eq=False)
class ImageMetricResult:
    """A per-image metric (PSNR, SSIM) and its mean over the batch.

    Attributes:
        value: mean of ``per_image`` over images with a non-empty mask; ``nan`` when
            every mask is empty.
        per_image: ``(...)`` value per image; ``nan`` where that image's mask is empty.
        num_pixels: ``(...)`` int, mask pixels per image.
        num_images: images that entered ``value``.
    """

    value: float
    per_image: np.ndarray
    num_pixels: np.ndarray
    num_images: int


@dataclass(frozen=True, eq=False)
class MseResult:
    """A mean squared error and how many values it averages (``nan`` when none)."""

    value: float
    count: int


# ------------------------------------------------------------------ helpers
def _points(name: str, array, dim: int) -> np.ndarray:
    a = np.asarray(array, dtype=np.float64)
    if a.ndim < 2 or a.shape[-1] != dim:
        raise ShapeError(f"{name} must have shape (..., J, {dim}), got {a.shape}")
    return a


def _mask(name: str, array, shape: tuple[int, ...]) -> np.ndarray:
    a = np.asarray(array)
    if a.shape != shape:
        raise ShapeError(f"{name} must have shape {shape}, got {a.shape}")
    return a.astype(bool)


def _joints_pair(pred, true, valid, pred_valid, dim: int, kind: str):
    """Checked ``(pred, true, valid, pred_ok)`` of a prediction against its truth (``..., J, dim``):
    non-finite truth is not valid, a non-finite prediction is not predicted."""
    pred = _points(f"pred_{kind}", pred, dim)
    true = _points(f"true_{kind}", true, dim)
    if pred.shape != true.shape:
        raise ShapeError(f"pred_{kind} {pred.shape} and true_{kind} {true.shape} must match")
    valid_b = _mask("valid", valid, true.shape[:-1]) & np.all(np.isfinite(true), axis=-1)
    pred_ok = np.ones(valid_b.shape, bool) if pred_valid is None else _mask("pred_valid", pred_valid, valid_b.shape)
    return pred, true, valid_b, pred_ok & np.all(np.isfinite(pred), axis=-1)


def _is_int(value) -> bool:
    """An int or NumPy integer, not a bool (an int to Python: True was taken as 1)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


_FLOAT64_MAX = float(np.finfo(np.float64).max)


def _positive_number(name: str, value, hint: str = ""):
    """``value`` if it is a finite number > 0, else ValueError naming ``name`` and ``value``: a bool is an int to
    Python (True was taken as 1), text reached numpy's bare TypeError, an int past float64 overflowed later."""
    # an int is compared with float64's largest, a float with inf (a float32 against 1.8e308 warned of a cast)
    whole = _is_int(value) and 0 < value <= _FLOAT64_MAX
    if not (whole or isinstance(value, (float, np.floating)) and 0 < value < np.inf):
        raise ValueError(f"{name} must be a positive number{hint}, got {_shown(value)}")
    return value


def _shown(value) -> str:
    """``repr(value)``, but an int past float64 by its size: its hundreds of digits said nothing, and past 4300
    of them ``repr`` raises ValueError itself."""
    if _is_int(value) and abs(value) > _FLOAT64_MAX:
        return f"an int of {int(value).bit_length()} bits (past float64)"
    return repr(value)


def _check_joint_indices(name: str, joints, num_joints: int) -> None:
    """Each of ``joints`` an int in ``[0, num_joints)``: ``int()`` took True as joint 1 and "3" as joint 3."""
    for j in joints:
        if not _is_int(j):
            raise ValueError(f"{name}: a joint index must be an int, got {j!r}")
        if not 0 <= j < num_joints:
            raise ShapeError(f"{name}: joint index {_shown(j)} out of range for {num_joints} joints")


def _check_pck_args(num_joints: int, torso_joints, box_joints, alpha: float) -> None:
    _check_joint_indices("torso_joints", torso_joints, num_joints)
    _check_joint_indices("box_joints", box_joints, num_joints)
    _positive_number("alpha", alpha)


def _mean_or_nan(total: float, count: int) -> float:
    return float(total / count) if count > 0 else float("nan")


#: Below this a Euclidean norm's squares may have lost bits to underflow (float64's least normal number is 2.2e-308)
#: and it is recomputed scaled; above about 1.3e154 they overflowed (an infinite norm), recomputed likewise.
_NORM_PLAIN_MIN = 1e-145


def _scaled_norms(v: np.ndarray) -> np.ndarray:
    """Norms over the last axis of ``(N, D)`` vectors, each divided by its largest component before squaring: no
    square over- or underflows. A norm past float64 is ``inf`` (no warning); NaN stays NaN."""
    top = np.abs(v).max(axis=-1)
    scalable = (top > 0) & np.isfinite(top)
    unit = v / np.where(scalable, top, 1.0)[:, None]
    with np.errstate(over="ignore"):  # top * sqrt(3) past float64: the norm is, too
        return np.where(scalable, top * np.sqrt((unit * unit).sum(axis=-1)), top)


def _norms(v: np.ndarray) -> np.ndarray:
    """Euclidean norms over the last axis: ``np.linalg.norm``'s (bit for bit) where its squares stay inside float64,
    else :func:`_scaled_norms`' (squares of components past 1e154 overflowed to inf with a RuntimeWarning, squares
    below 1e-154 underflowed to 0)."""
    with np.errstate(over="ignore"):
        plain = np.sqrt(np.add.reduce(v * v, axis=-1))  # np.linalg.norm's sum, without its argument checks
    if _NORM_PLAIN_MIN <= plain.min(initial=np.inf) and plain.max(initial=0.0) < np.inf:  # the usual case, quickly
        return plain
    # a zero vector (a masked-out joint) is plainly 0; NaN stays NaN
    redo = (~(plain >= _NORM_PLAIN_MIN) & np.any(v != 0, axis=-1) | np.isinf(plain)) & ~np.isnan(plain)
    if not redo.any():
        return plain
    out = np.array(plain, dtype=np.float64)
    out[redo] = _scaled_norms(v[redo])
    return out


def _differences(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a - b``; one past float64 (finite values of opposite signs near 1e308) is +-inf without a warning: its
    norm is past float64 too. inf - inf (a non-finite joint, masked out by the caller) is NaN without one."""
    with np.errstate(over="ignore", invalid="ignore"):
        return a - b


def _pooled_mean(values: np.ndarray, count: int) -> float:
    """Sum of the non-negative ``values`` over ``count`` (``nan`` for none) without the sum overflowing where the
    mean does not: divided by the largest value first where the plain sum reached inf."""
    with np.errstate(over="ignore"):
        total = float(values.sum())
    if count == 0 or np.isfinite(total):
        return _mean_or_nan(total, count)
    top = float(values.max())
    if not np.isfinite(top):  # a value past float64 (or NaN): so is the mean
        return _mean_or_nan(total, count)
    with np.errstate(over="ignore"):
        return float(top * ((values / top).sum() / count))


def _within(pred: np.ndarray, true: np.ndarray, dist: np.ndarray, alpha: float, ref: np.ndarray) -> np.ndarray:
    """``dist <= alpha * ref`` (``dist`` the norms of ``pred - true``, ``ref`` broadcast to it), exact where both
    sides passed float64: inf <= inf counted a prediction past float64 as correct. Those are compared at a quarter
    (powers of two: no rounding), in range for a distance between finite points (under 4 times float64's largest)."""
    with np.errstate(over="ignore"):  # alpha * ref past float64: every finite distance is within it
        radius = alpha * ref
        near = dist <= radius
        redo = np.isinf(dist) & np.isinf(radius)
        if redo.any():
            quarter = np.broadcast_to(ref, dist.shape)[redo] / 4
            near[redo] = _norms(pred[redo] / 4 - true[redo] / 4) <= alpha * quarter
    return near


# ---------------------------------------------------------------------- PCK
def _reference_lengths(true_2d: np.ndarray, valid: np.ndarray, torso_joints: tuple[int, int],
                       box_joints: Sequence[int]) -> np.ndarray:
    """Per-sample reference length ``(...)``: neck--mid-hip, else torso-box diagonal, else 0."""
    a, b = torso_joints
    both = valid[..., a] & valid[..., b]
    direct = _norms(_differences(true_2d[..., a, :], true_2d[..., b, :]))

    box = list(box_joints)
    pts, ok = true_2d[..., box, :], valid[..., box]
    lo = np.where(ok[..., None], pts, np.inf).min(axis=-2)
    hi = np.where(ok[..., None], pts, -np.inf).max(axis=-2)
    # A box needs two valid joints; fewer gives -inf/inf extents, zeroed here. An extent past float64 (joints
    # near +-1e308) stays inf, a reference length of none below (nan_to_num made it 0: a diagonal of the rest).
    enough = ok.sum(axis=-1) >= 2
    diag = np.where(enough, _norms(np.where(enough[..., None], _differences(hi, lo), 0.0)), 0.0)

    ref = np.where(both, direct, diag)
    return np.where(np.isfinite(ref) & (ref > 0), ref, 0.0)


def pck(pred_2d, true_2d, valid, torso_joints: tuple[int, int] = (NECK, MID_HIP), alpha: float = 0.2, *,
        pred_valid=None, box_joints: Sequence[int] = TORSO_BOX_JOINTS) -> PckResult:
    """Percentage of correct keypoints, PCK@alpha.

    A joint is *correct* when its prediction lies within ``alpha * reference`` (inclusive)
    of the truth. The reference length is per sample, from the **true** joints:

    1. the distance between ``torso_joints`` (neck and mid-hip) when both are valid;
    2. otherwise the diagonal of the bounding box of the valid ``box_joints`` (neck,
       shoulders, hips; at least two valid);
    3. otherwise none: the sample's joints are excluded and counted in
       ``num_unreferenced``. A zero-length reference counts as none.

    The fallback diagonal only applies when a torso joint is missing. With the shoulders and
    hips visible it is about 1.2x the neck--mid-hip distance of an upright adult seen from the
    front, so slightly more lenient; with only two close torso joints it can be much shorter,
    so stricter (docs/metrics.md).

    Joints whose truth is not valid are excluded and counted (``num_missing``). Joints with
    valid truth but no prediction (``pred_valid`` False, or a non-finite prediction) are
    evaluated and scored wrong. The score pools every evaluated joint of the batch.

    Args:
        pred_2d: ``(..., J, 2)`` predicted pixels.
        true_2d: ``(..., J, 2)`` true pixels (same image space as ``pred_2d``).
        valid: ``(..., J)`` bool, truth is visible and labelled.
        torso_joints: the two joints whose distance is the reference length (int indices, as ``box_joints``).
        alpha: threshold as a fraction of the reference length (a number > 0, else ValueError).
        pred_valid: optional ``(..., J)`` bool, the predictor produced the joint.
        box_joints: joints whose bounding-box diagonal is the fallback reference.

    Returns:
        :class:`PckResult`; ``value`` is ``nan`` (undefined) when no joint was evaluated.

    Example:
        >>> true = np.array([[0.0, 0.0], [0.0, 10.0], [5.0, 5.0]])
        >>> pred = true + [[1.0, 0.0], [3.0, 0.0], [0.0, 0.0]]
        >>> r = pck(pred, true, [True, True, True], torso_joints=(0, 1), box_joints=(0, 1))
        >>> r.value, r.correct.tolist()
        (0.6666666666666666, [True, False, True])
    """
    pred, true, valid_b, pred_ok = _joints_pair(pred_2d, true_2d, valid, pred_valid, 2, "2d")
    _check_pck_args(true.shape[-2], torso_joints, box_joints, alpha)
    ref = _reference_lengths(true, valid_b, tuple(torso_joints), box_joints)
    evaluated = valid_b & (ref > 0)[..., None]
    dist = _norms(np.where(pred_ok[..., None], _differences(pred, true), 0.0))
    correct = evaluated & pred_ok & _within(pred, true, dist, alpha, ref[..., None])

    n_eval = int(evaluated.sum())
    n_ok = int(correct.sum())
    return PckResult(
        value=_mean_or_nan(n_ok, n_eval), correct=correct, evaluated=evaluated, reference=ref,
        num_evaluated=n_eval, num_correct=n_ok, num_missing=int((~valid_b).sum()),
        num_unreferenced=int((valid_b & ~evaluated).sum()), num_pred_missing=int((evaluated & ~pred_ok).sum()),
    )


def left_right_swaps(pred_2d, true_2d, valid, *, pred_valid=None,
                     pairs: Sequence[tuple[int, int]] = LEFT_RIGHT_PAIRS, alpha: float = 0.2,
                     torso_joints: tuple[int, int] = (NECK, MID_HIP),
                     box_joints: Sequence[int] = TORSO_BOX_JOINTS) -> SwapResult:
    """How often a left/right pair of 2D joints is predicted the wrong way round.

    A pair ``(a, b)`` of a sample is *swapped* when, as labelled, at least one of its two
    predictions is wrong by PCK@alpha (:func:`pck`'s per-sample reference length) and,
    exchanged (``a``'s prediction read as ``b``'s and the reverse), both are right. It is
    *evaluated* when both truths are valid, both joints are predicted (finite) and the sample
    has a reference length. A swapped pair costs PCK twice and, swapped in one view only,
    breaks the triangulation of both joints; swapped in both views alike it places both on the
    wrong side of the body in 3D.

    Args:
        pred_2d, true_2d: ``(..., J, 2)`` pixels of one image per sample.
        valid: ``(..., J)`` bool, the truth is visible and labelled.
        pred_valid: optional ``(..., J)`` bool, the predictor produced the joint.
        pairs: the joint pairs to test (default: BODY_25's 11 left/right pairs).
        alpha, torso_joints, box_joints: as for :func:`pck`.

    Returns:
        :class:`SwapResult`; ``value`` is ``nan`` when no pair was evaluated.

    Example:
        >>> true = np.array([[0.0, 0.0], [0.0, 10.0], [-3.0, 5.0], [3.0, 5.0]])
        >>> pred = true[[0, 1, 3, 2]]  # joints 2 and 3 exchanged
        >>> r = left_right_swaps(pred, true, np.ones(4, bool), pairs=[(2, 3)], torso_joints=(0, 1), box_joints=(0, 1))
        >>> r.value, r.num_swapped
        (1.0, 1)
    """
    pred, true, valid_b, pred_ok = _joints_pair(pred_2d, true_2d, valid, pred_valid, 2, "2d")
    pairs = [tuple(p) for p in pairs]
    _check_joint_indices("pairs", [j for p in pairs for j in p], true.shape[-2])
    _check_pck_args(true.shape[-2], torso_joints, box_joints, alpha)
    ref = _reference_lengths(true, valid_b, tuple(torso_joints), box_joints)
    with np.errstate(over="ignore"):  # past float64: _within compares it exactly
        radius = alpha * ref
    shape = true.shape[:-2] + (len(pairs),)
    swapped, evaluated = np.zeros(shape, bool), np.zeros(shape, bool)
    for k, (a, b) in enumerate(pairs):
        ev = valid_b[..., a] & valid_b[..., b] & pred_ok[..., a] & pred_ok[..., b] & (radius > 0)
        pa, pb = np.where(ev[..., None], pred[..., a, :], 0.0), np.where(ev[..., None], pred[..., b, :], 0.0)
        ta, tb = true[..., a, :], true[..., b, :]
        # a-a, a-b, b-a, b-b in one call: _norms' checks cost more than its sums on 4 x 2 values
        p, t = np.stack([pa, pa, pb, pb]), np.stack([ta, tb, ta, tb])
        near = _within(p, t, _norms(_differences(p, t)), alpha, ref)
        as_labelled = near[0] & near[3]
        exchanged = near[1] & near[2]
        evaluated[..., k] = ev
        swapped[..., k] = ev & ~as_labelled & exchanged
    n_eval, n_swap = int(evaluated.sum()), int(swapped.sum())
    return SwapResult(_mean_or_nan(n_swap, n_eval), swapped, evaluated, n_eval, n_swap)


# -------------------------------------------------------------------- MPJPE
def mpjpe(pred_3d, true_3d, valid, *, pred_valid=None) -> MpjpeResult:
    """Mean per-joint position error in millimetres (inputs in metres, rig frame).

    The mean of the Euclidean distances between predicted and true joints, pooled over
    every evaluated joint of the batch. No alignment (no root or Procrustes alignment).
    Joints with invalid truth are excluded and counted (``num_missing``); joints with no
    prediction are excluded and counted separately (``num_pred_missing``).

    Args:
        pred_3d: ``(..., J, 3)`` metres.
        true_3d: ``(..., J, 3)`` metres.
        valid: ``(..., J)`` bool, truth is available.
        pred_valid: optional ``(..., J)`` bool, the predictor produced the joint.

    Returns:
        :class:`MpjpeResult`; ``value`` is ``nan`` (undefined) when no joint was evaluated.

    Example:
        >>> r = mpjpe([[0.0, 0.0, 1.0], [0.0, 0.0, 2.0]], [[0.003, 0.004, 1.0], [0.0, 0.0, 2.0]], [True, True])
        >>> round(r.value, 6), r.num_evaluated
        (2.5, 2)
    """
    pred, true, valid_b, pred_ok = _joints_pair(pred_3d, true_3d, valid, pred_valid, 3, "3d")
    evaluated = valid_b & pred_ok
    errors = np.where(evaluated, _norms(np.where(evaluated[..., None], _differences(pred, true), 0.0)), 0.0)
    with np.errstate(over="ignore"):  # an error past 1.8e305 m is past float64 in mm: inf
        errors_mm = 1000.0 * errors
    n = int(evaluated.sum())
    return MpjpeResult(value=_pooled_mean(errors_mm, n), errors=errors_mm, evaluated=evaluated,
                       num_evaluated=n, num_missing=int((~valid_b).sum()),
                       num_pred_missing=int((valid_b & ~pred_ok).sum()))


def acceleration_error(pred_3d, true_3d, valid, *, pred_valid=None, consecutive=None) -> AccelerationResult:
    """Jitter: the mean size of the second difference, frame to frame, of the 3D error, mm per frame².

    ``|a_pred - a_true|`` with ``a = x[f+1] - 2 x[f] + x[f-1]`` per joint, the "acceleration error" of
    the video pose literature (Kanazawa et al., CVPR 2019), pooled over every inner frame whose joint is
    evaluated (valid truth and a prediction) in that frame and both its neighbours. An error that stays
    put scores 0, however large (that is MPJPE's business); noise from frame to frame scores its size.
    Per frame, not per second: it compares runs at the same frame rate.

    Args:
        pred_3d: ``(F, J, 3)`` metres, frames in order.
        true_3d: ``(F, J, 3)`` metres.
        valid: ``(F, J)`` bool, truth is available.
        pred_valid: optional ``(F, J)`` bool, the predictor produced the joint.
        consecutive: optional ``(F,)`` bool, frame ``f`` directly follows frame ``f - 1`` (False where a
            sequence starts or frames were dropped; ``consecutive[0]`` is ignored). Default: all do.

    Returns:
        :class:`AccelerationResult`; ``value`` is ``nan`` when fewer than three frames chain.

    Example:
        >>> pred = [[[0, 0, 1.0]], [[0, 0, 1.003]], [[0, 0, 1.0]]]  # 3 mm out in the middle frame
        >>> r = acceleration_error(pred, [[[0, 0, 1.0]]] * 3, [[True]] * 3)
        >>> round(r.value, 6), r.num_evaluated
        (6.0, 1)
    """
    pred, true, valid_b, pred_ok = _joints_pair(pred_3d, true_3d, valid, pred_valid, 3, "3d")
    if pred.ndim != 3:
        raise ShapeError(f"pred_3d must have shape (F, J, 3), got {pred.shape}")
    frames = pred.shape[0]
    chained = np.ones(frames, bool) if consecutive is None else _mask("consecutive", consecutive, (frames,)).copy()
    if frames < 3:
        empty = np.zeros((0, pred.shape[1]), bool)
        return AccelerationResult(float("nan"), empty.astype(np.float64), empty, 0)
    ok = valid_b & pred_ok
    evaluated = ok[:-2] & ok[1:-1] & ok[2:] & (chained[1:-1] & chained[2:])[:, None]
    accel = _second_difference_norms(pred, true, ok)
    with np.errstate(over="ignore"):  # past float64 in mm: inf
        errors = np.where(evaluated, 1000.0 * accel, 0.0)
    n = int(evaluated.sum())
    return AccelerationResult(_pooled_mean(errors, n), errors, evaluated, n)


#: The fallback scale of :func:`_second_difference_norms`: with ``pred`` and ``true`` divided by it neither their
#: difference nor its second difference (at most 8 times the largest value) leaves float64.
_SECOND_DIFFERENCE_SCALE = 16.0


def _second_difference_norms(pred: np.ndarray, true: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """``(F - 2, J)`` norms of the second difference of the error ``pred - true`` (``(F, J, 3)``; 0 where not
    ``ok``). Where that overflowed (values near 1e308: a difference or ``2 e`` past float64 although the result
    need not be) it is recomputed from the values divided by :data:`_SECOND_DIFFERENCE_SCALE`, a power of two."""
    def second(p: np.ndarray, t: np.ndarray) -> np.ndarray:
        e = np.where(ok[..., None], _differences(p, t), 0.0)
        with np.errstate(over="ignore", invalid="ignore"):
            return e[2:] - 2.0 * e[1:-1] + e[:-2]

    plain = _norms(second(pred, true))
    redo = ~np.isfinite(plain)
    if not redo.any():
        return plain
    k = _SECOND_DIFFERENCE_SCALE
    scaled = second(np.where(ok[..., None], pred / k, 0.0), np.where(ok[..., None], true / k, 0.0))
    with np.errstate(over="ignore"):  # a norm past float64 is inf
        return np.where(redo, k * _norms(scaled), plain)


#: A 3D joint's visibility class: seen (in the image, unoccluded) by every source view, by some, by none.
VISIBILITY_CLASSES: tuple[str, ...] = ("all_views", "some_views", "no_view")


def visibility_class(visible) -> np.ndarray:
    """Index into :data:`VISIBILITY_CLASSES` of each joint from its per-view visibility.

    Args:
        visible: ``(..., C, J)`` bool, joint ``j`` visible in view ``c``.

    Returns:
        ``(..., J)`` int: 0 all views, 1 some, 2 none.

    Example:
        >>> visibility_class([[True, True, False], [True, False, False]]).tolist()
        [0, 1, 2]
    """
    v = np.asarray(visible, bool)
    if v.ndim < 2:
        raise ShapeError(f"visible must have shape (..., C, J), got {v.shape}")
    seen = v.sum(axis=-2)
    return np.where(seen == v.shape[-2], 0, np.where(seen > 0, 1, 2))


def mpjpe_by_visibility(result: MpjpeResult, visible) -> dict[str, tuple[float, int]]:
    """``result``'s evaluated errors split by :func:`visibility_class`: ``{class: (sum_mm, joints)}``.

    Sums, not means, so batches pool exactly; the mean is ``sum_mm / joints``. Why: the synthetic
    truth knows every 3D joint, visible or not, and the MPJPE pools them all; this says how much of
    the error comes from joints that some or every camera cannot see (docs/metrics.md).

    Args:
        result: :func:`mpjpe` of ``(..., J)`` joints.
        visible: ``(..., C, J)`` bool per-view visibility of the same joints.

    Example:
        >>> r = mpjpe([[0, 0, 1.0], [0, 0, 1.0]], [[0, 0, 1.002], [0, 0, 1.01]], [True, True])
        >>> {k: (round(s, 6), n) for k, (s, n) in mpjpe_by_visibility(r, [[True, True], [True, False]]).items()}
        {'all_views': (2.0, 1), 'some_views': (10.0, 1), 'no_view': (0.0, 0)}
    """
    cls = visibility_class(visible)
    if cls.shape != result.evaluated.shape:
        raise ShapeError(f"visible {np.shape(visible)} does not match the MPJPE's joints {result.evaluated.shape}")
    out = {}
    for k, name in enumerate(VISIBILITY_CLASSES):
        sel = result.evaluated & (cls == k)
        out[name] = (float(result.errors[sel].sum()), int(sel.sum()))
    return out


# ------------------------------------------------------------- image metrics
def _image_args(pred, target, mask) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Images as ``(N, H, W, C)`` float64 and the mask as ``(N, H, W)`` bool.

    The mask decides the layout: ``mask.shape == pred.shape[:-1]`` means channel-last
    images ``(..., H, W, C)``; ``mask.shape == pred.shape`` means single-channel images
    ``(..., H, W)``.
    """
    p = np.asarray(pred, dtype=np.float64)
    t = np.asarray(target, dtype=np.float64)
    m = np.asarray(mask)
    if p.shape != t.shape:
        raise ShapeError(f"pred {p.shape} and target {t.shape} must have the same shape")
    if m.shape == p.shape and p.ndim >= 2:
        p, t = p[..., None], t[..., None]
    elif not (p.ndim >= 3 and m.shape == p.shape[:-1]):
        raise ShapeError(f"mask must have shape (..., H, W) matching pred (..., H, W[, C]); got mask {m.shape}, "
                         f"pred {p.shape}")
    h, w, c = p.shape[-3:]
    if h == 0 or w == 0:  # reshape(-1, 0, 0, c) failed with numpy's own message
        raise ShapeError(f"images must be at least 1x1 pixels, got pred {p.shape}")
    return p.reshape(-1, h, w, c), t.reshape(-1, h, w, c), m.astype(bool).reshape(-1, h, w)


#: Slack of the truth's range check, as a share of ``data_range``: float noise and resampling overshoot, not
#: the factor of 255 between an 8-bit image and a [0, 1] one.
RANGE_SLACK = 0.01


def _check_image_range(pred, target, p: np.ndarray, t: np.ndarray, m: np.ndarray, data_range: float) -> None:
    """Images that do not live in ``[0, data_range]`` scored silently wrong (a uint8 pair at the default 1.0:
    20 log10 255 = 48 dB too low; uint8 against [0, 1] floats: anything): refuse them by name.

    * an integer-typed image beside a float one: two ranges, say which;
    * the truth inside the mask outside ``[0, data_range]`` (give or take :data:`RANGE_SLACK`);
    * an integer-typed prediction inside the mask beyond ``data_range`` (a float one may overshoot: it is
      scored as it is).

    ``pred``, ``target``: the arrays as given (their dtypes); ``p``, ``t``, ``m``: :func:`_image_args`'s.
    """
    dtypes = {name: np.asarray(a).dtype for name, a in (("pred", pred), ("target", target))}
    ints = {name: np.issubdtype(d, np.integer) for name, d in dtypes.items()}
    if ints["pred"] != ints["target"]:
        raise ValueError(f"pred is {dtypes['pred']} and target {dtypes['target']}: give both images in one type and "
                         f"range (e.g. uint8 with data_range=255, or both float in [0, 1] with data_range=1.0)")
    slack = RANGE_SLACK * data_range
    inside = t[m]
    inside = inside[np.isfinite(inside)]  # a non-finite truth propagates as NaN, as a non-finite prediction does
    if inside.size and (inside.min() < -slack or inside.max() > data_range + slack):
        raise ValueError(f"target values inside the mask span [{inside.min():g}, {inside.max():g}], outside "
                         f"[0, data_range={data_range:g}]: pass the images' peak as data_range (255 for 8-bit)")
    top = p[m].max(initial=0.0) if ints["pred"] else 0.0
    if top > data_range:
        raise ValueError(f"pred is {dtypes['pred']} with values up to {top:g} inside the mask, beyond "
                         f"data_range={data_range:g}: pass the images' peak as data_range (255 for 8-bit)")


def _check_data_range(data_range) -> None:
    """A peak value of -1 scored as 1 (it is squared) and 0 gave -inf dB and a NaN SSIM: refuse them by name."""
    _positive_number("data_range", data_range, " (1.0 for [0, 1] images, 255 for 8-bit)")


def _per_image_result(values: np.ndarray, counts: np.ndarray, batch_shape: tuple[int, ...]) -> ImageMetricResult:
    has = counts > 0
    values = np.where(has, values, np.nan)
    n = int(has.sum())
    mean = float(values[has].mean()) if n else float("nan")
    return ImageMetricResult(value=mean, per_image=values.reshape(batch_shape),
                             num_pixels=counts.reshape(batch_shape), num_images=n)


def masked_psnr(pred, target, mask, data_range: float = 1.0) -> ImageMetricResult:
    """Peak signal-to-noise ratio inside a mask, per image, in dB.

    ``PSNR = 10 log10(data_range^2 / MSE)`` where MSE averages the squared error over every
    channel of the mask pixels of one image. Identical images give ``+inf``. The batch
    value is the mean of the per-image PSNRs (as NeRF papers report it), not the PSNR of
    the pooled MSE.

    Args:
        pred: ``(..., H, W, C)`` or ``(..., H, W)`` images (the mask shape decides which).
        target: same shape as ``pred``.
        mask: ``(..., H, W)`` bool, pixels to score.
        data_range: peak value (1.0 for [0, 1] images, 255 for 8-bit); a positive number, else ValueError.
            The truth inside the mask must lie in ``[0, data_range]`` (1 % slack), an integer-typed prediction
            too, and an integer image is not scored against a float one: ValueError (:func:`_check_image_range`).

    Returns:
        :class:`ImageMetricResult`; ``nan`` (undefined) for images with an empty mask.

    Example:
        >>> a = np.zeros((4, 4)); b = a + 0.1
        >>> round(masked_psnr(a, b, np.ones((4, 4), bool)).value, 6)
        20.0
    """
    _check_data_range(data_range)
    p, t, m = _image_args(pred, target, mask)
    _check_image_range(pred, target, p, t, m, data_range)
    batch_shape = np.asarray(mask).shape[:-2]
    counts = m.sum(axis=(1, 2))
    # in units of data_range: data_range ** 2 under- or overflowed (1e-200: 0 / 0, a NaN and a warning; 1e200: inf)
    with np.errstate(over="ignore"):  # a difference past 1e154 data ranges: redone below
        sq = (((p - t) / data_range) ** 2).sum(axis=-1)  # (N, H, W), summed over channels
        sq = np.where(m, sq, 0.0)  # not sq * m: a NaN outside the mask would poison the sum (0 * NaN is NaN)
        mse = np.where(counts > 0, sq.sum(axis=(1, 2)) / np.maximum(counts * p.shape[-1], 1), np.nan)
    with np.errstate(divide="ignore"):
        values = 10.0 * np.log10(1.0 / mse)
    # past float64 (a wild prediction, or a tiny data_range) or below its normal numbers (1 / mse: inf dB)
    for i in np.flatnonzero(np.isinf(mse) | (mse < _FLOAT64_TINY)):
        values[i] = _wild_psnr(p[i][m[i]], t[i][m[i]], data_range, values[i])
    return _per_image_result(values, counts, batch_shape)


_FLOAT64_TINY = float(np.finfo(np.float64).tiny)


def _wild_psnr(p: np.ndarray, t: np.ndarray, data_range: float, plain: float) -> float:
    """PSNR (dB) of the values ``p`` against ``t`` whose mean square in data ranges left float64's normal numbers:
    ``20 log10(data_range / top) - 10 log10(mean((d / top)**2))``, ``d = p - t`` (both halved first where that
    passes float64) and ``top`` its largest magnitude. ``plain`` (+-inf, or NaN) where ``d`` is all 0 or not finite."""
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(t))):
        return plain
    with np.errstate(over="ignore"):
        d, halved = p - t, 1.0
    if np.any(np.isinf(d)):  # opposite signs near 1e308
        d, halved = p / 2 - t / 2, 2.0
    top = float(np.abs(d).max())
    if top == 0:
        return plain
    unit = d / top
    peak = np.log10(float(data_range)) - np.log10(top) - np.log10(halved)  # an int past int64: no ufunc loop
    return float(20.0 * peak - 10.0 * np.log10((unit * unit).mean()))


#: A per-image PSNR of identical images (+inf) counts as this in a pooled mean (``ghnerf-eval``, the painter's
#: held-out table, ``bench_runtime_vs_eval``), so one such image cannot make the mean infinite.
PSNR_CAP_DB = 100.0


def capped_psnr(values) -> np.ndarray:
    """Per-image PSNRs (dB) with ``+inf`` (identical images) as :data:`PSNR_CAP_DB`; ``nan`` stays ``nan``.

    Example:
        >>> capped_psnr([20.0, float("inf"), float("nan")]).tolist()
        [20.0, 100.0, nan]
    """
    return np.minimum(np.asarray(values, np.float64), PSNR_CAP_DB)


def scorable_images(images, data_range: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Rendered images ``(N, ...)`` as a pooled score takes them, and the ``(N,)`` bool of the broken ones.

    An image with any non-finite value (NaN or +-inf, anywhere, inside its mask or not) is a broken render:
    ``nan`` throughout, so its PSNR and SSIM are ``nan`` and the caller leaves it out of its means and counts it
    (``ghnerf-eval``'s ``nonfinite_views``). The others are clipped to ``[0, data_range]``. Finiteness is tested
    before the clip, which would turn +-inf into ``data_range`` or 0 and score it.

    Example:
        >>> img, broken = scorable_images(np.array([[0.5, 1.5], [0.2, np.inf]]))
        >>> img.tolist(), broken.tolist()
        ([[0.5, 1.0], [nan, nan]], [False, True])
    """
    _check_data_range(data_range)
    x = np.asarray(images)
    if not np.issubdtype(x.dtype, np.floating):  # a float image keeps its precision (a float32 cache: half the bytes)
        x = x.astype(np.float64)
    if x.ndim < 1:
        raise ShapeError(f"images must have a leading image axis (N, ...), got shape {x.shape}")
    broken = ~np.isfinite(x.reshape(len(x), -1)).all(axis=1)
    keep = broken.reshape((-1,) + (1,) * (x.ndim - 1))
    return np.where(keep, np.nan, np.clip(x, 0.0, data_range)), broken


def _window_sum(a: np.ndarray) -> np.ndarray:
    # Constant (zero) border: pixels outside the image weigh like pixels outside the mask.
    return cv2.GaussianBlur(a, (SSIM_WINDOW, SSIM_WINDOW), SSIM_SIGMA, borderType=cv2.BORDER_CONSTANT)


def _ssim_stats(x: np.ndarray, y: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, ...]:
    """Mask-normalised window means ``mx, my``, variances ``vx, vy`` and covariance ``cxy`` of one channel."""
    inside = m > 0  # a NaN or inf outside the mask must not reach the sums: 0 * NaN is NaN
    x, y = np.where(inside, x, 0.0), np.where(inside, y, 0.0)
    w = _window_sum(m)
    inv_w = np.where(w > 1e-12, 1.0 / np.maximum(w, 1e-12), 0.0)
    mx, my = _window_sum(m * x) * inv_w, _window_sum(m * y) * inv_w
    # Variances can come out a hair negative from cancellation; clamp.
    vx = np.maximum(_window_sum(m * x * x) * inv_w - mx * mx, 0.0)
    vy = np.maximum(_window_sum(m * y * y) * inv_w - my * my, 0.0)
    cxy = _window_sum(m * x * y) * inv_w - mx * my
    return mx, my, vx, vy, cxy


def _ssim_map(x: np.ndarray, y: np.ndarray, m: np.ndarray, data_range: float) -> np.ndarray:
    """SSIM map ``(H, W)`` of one channel with a mask-normalised Gaussian window."""
    mx, my, vx, vy, cxy = _ssim_stats(x, y, m)
    c1, c2 = (SSIM_K1 * data_range) ** 2, (SSIM_K2 * data_range) ** 2
    return ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))


#: Images (in units of ``data_range``) within +-2**250 take :func:`_ssim_map`: its product of two sums of squares
#: stays inside float64 (2**1000). A window holding a larger value (a wild prediction) takes :func:`_wild_ssim_map`.
SSIM_PLAIN_MAX = 2.0 ** 250


def _ssim_ratio(num: np.ndarray, den: np.ndarray, c: float, s: np.ndarray) -> np.ndarray:
    """``(num + c) / (den + c)`` with all three divided by the per-pixel scale ``s`` first (> 0)."""
    return (num / s + c / s) / (den / s + c / s)


def _wild_ssim_map(x: np.ndarray, y: np.ndarray, m: np.ndarray, plain_max: float = SSIM_PLAIN_MAX) -> np.ndarray:
    """SSIM map (``data_range`` 1) of a channel holding values past :data:`SSIM_PLAIN_MAX`, where
    :func:`_ssim_map`'s squares and products overflowed (inf - inf: NaN, with RuntimeWarnings).

    A pixel whose window holds no such value keeps :func:`_ssim_map`'s value, bit for bit. The others take the
    statistics of the images divided by a power of two that puts their largest value at 2**500 (so squares of
    values past 2**250 stay normal numbers), and the luminance and structure terms as separate ratios, each
    divided by its largest term first: SSIM is homogeneous in the images and ``c1``, ``c2`` together.
    ``plain_max``: the bound, lower in tests (to compare both maps where the plain one holds)."""
    inside = m > 0
    big = inside & ((np.abs(x) > plain_max) | (np.abs(y) > plain_max))
    near = cv2.dilate(big.astype(np.uint8), np.ones((SSIM_WINDOW, SSIM_WINDOW), np.uint8),
                      borderType=cv2.BORDER_CONSTANT, borderValue=0) > 0
    plain = _ssim_map(np.where(big, 0.0, x), np.where(big, 0.0, y), m, 1.0)  # right where no window holds one
    top = max(float(np.abs(x[big & np.isfinite(x)]).max(initial=0.0)),
              float(np.abs(y[big & np.isfinite(y)]).max(initial=0.0)))
    k = np.ldexp(1.0, max(0, int(np.frexp(top)[1]) - 500))
    mx, my, vx, vy, cxy = _ssim_stats(x / k, y / k, m)
    k1, k2 = SSIM_K1 / k, SSIM_K2 / k  # at least 0.01 * 2**-524: c1 and c2 stay above 0 (no 0 / 0)
    luminance = _ssim_ratio(2 * mx * my, mx * mx + my * my, k1 * k1,
                            np.maximum(np.maximum(np.abs(mx), np.abs(my)), k1) ** 2)
    structure = _ssim_ratio(2 * cxy, vx + vy, k2 * k2, np.maximum(np.maximum(vx, vy), k2 * k2))
    return np.where(near, luminance * structure, plain)


def _ssim_channel(x: np.ndarray, y: np.ndarray, m: np.ndarray) -> np.ndarray:
    """SSIM map of one channel in units of ``data_range``: :func:`_ssim_map`, or :func:`_wild_ssim_map` where a
    finite value inside the mask passes :data:`SSIM_PLAIN_MAX`."""
    if _within_plain_ssim(x) and _within_plain_ssim(y):  # the usual images: no per-pixel masks (a fifth of the time)
        return _ssim_map(x, y, m, 1.0)
    wild = (np.abs(x) > SSIM_PLAIN_MAX) & np.isfinite(x) | (np.abs(y) > SSIM_PLAIN_MAX) & np.isfinite(y)
    if np.any(wild & (m > 0)):  # (an infinite value gives a NaN map either way)
        return _wild_ssim_map(x, y, m)
    return _ssim_map(x, y, m, 1.0)


def _within_plain_ssim(a: np.ndarray) -> bool:
    """Every value of ``a`` within +-:data:`SSIM_PLAIN_MAX`, by its extremes (False where it holds a NaN: the
    caller's per-pixel check decides)."""
    return bool(-SSIM_PLAIN_MAX <= a.min() and a.max() <= SSIM_PLAIN_MAX) if a.size else True


def _in_data_ranges(a: np.ndarray, data_range: float) -> np.ndarray:
    """``a / data_range``, a finite value of ``a`` whose quotient passes float64 (a wild prediction, a tiny
    ``data_range``: an inf, a NaN SSIM map) held at float64's largest. Its windows score under 1e-300 either way."""
    with np.errstate(over="ignore"):
        x = a / data_range
    if x.size == 0 or np.isfinite(x.min()) and np.isfinite(x.max()):  # no inf (nor NaN) made: the usual images
        return x
    return np.where(np.isinf(x) & np.isfinite(a), np.copysign(_FLOAT64_MAX, x), x)


def masked_ssim(pred, target, mask, data_range: float = 1.0) -> ImageMetricResult:
    """Structural similarity (Wang et al. 2004) averaged over the mask pixels, per image.

    Local statistics use an 11x11 Gaussian window (sigma 1.5) **restricted to the mask**:
    each weighted mean, variance and covariance is a window sum over mask pixels divided by
    the window weight of mask pixels, so pixels outside the mask (and outside the image)
    never influence the score. ``K1 = 0.01``, ``K2 = 0.03``, ``L = data_range``. The SSIM
    map is averaged over mask pixels and then over channels. With a full mask this is
    standard Gaussian-window SSIM except within 5 pixels of the image border, where the
    window is renormalised instead of cropped.

    Args:
        pred: ``(..., H, W, C)`` or ``(..., H, W)`` images (the mask shape decides which).
        target: same shape as ``pred``.
        mask: ``(..., H, W)`` bool.
        data_range: peak value (1.0 for [0, 1] images); a positive number, else ValueError; the images'
            range is checked as for :func:`masked_psnr`.

    Returns:
        :class:`ImageMetricResult`; ``nan`` (undefined) for images with an empty mask.

    Example:
        >>> img = np.random.default_rng(0).random((16, 16))
        >>> round(masked_ssim(img, img, np.ones((16, 16), bool)).value, 9)
        1.0
    """
    _check_data_range(data_range)
    p, t, m = _image_args(pred, target, mask)
    _check_image_range(pred, target, p, t, m, data_range)
    batch_shape = np.asarray(mask).shape[:-2]
    counts = m.sum(axis=(1, 2))
    values = np.full(len(p), np.nan)
    for i in range(len(p)):
        if counts[i] == 0:
            continue
        mi = m[i].astype(np.float64)
        # in units of data_range (L = 1), as masked_psnr: squares of 1e-200 images underflowed (0 / 0, a NaN)
        per_channel = [(_ssim_channel(_in_data_ranges(p[i, ..., c], data_range), t[i, ..., c] / data_range,
                                      mi)[m[i]]).mean() for c in range(p.shape[-1])]
        values[i] = float(np.mean(per_channel))
    return _per_image_result(values, counts, batch_shape)


# ------------------------------------------------------------------ heatmaps
def heatmap_mse(pred, target, valid=None) -> MseResult:
    """Mean squared error between heatmaps, over every pixel of every included joint.

    Args:
        pred: ``(..., J, H, W)``.
        target: same shape (usually :func:`gaussian_heatmaps`).
        valid: optional ``(..., J)`` bool: joints to include (default all: a joint with no
            visible truth has an all-zero target, so a spurious peak for it is penalised).

    Returns:
        :class:`MseResult`; ``nan`` (undefined) when no joint is included. Non-finite
        predictions propagate into the value on purpose: a broken model must not look good.

    Example:
        >>> heatmap_mse(np.full((2, 3, 3), 0.5), np.zeros((2, 3, 3))).value
        0.25
    """
    p = np.asarray(pred, dtype=np.float64)
    t = np.asarray(target, dtype=np.float64)
    if p.shape != t.shape or p.ndim < 3:
        raise ShapeError(f"pred {p.shape} and target {t.shape} must have the same shape (..., J, H, W)")
    keep = np.ones(p.shape[:-2], bool) if valid is None else _mask("valid", valid, p.shape[:-2])
    count = int(keep.sum()) * p.shape[-2] * p.shape[-1]
    return MseResult(value=_mean_square(p, t, keep, count), count=count)


def _mean_square(p: np.ndarray, t: np.ndarray, keep: np.ndarray, count: int) -> float:
    """Mean of ``(p - t) ** 2`` over the ``(H, W)`` maps (``..., J, H, W``) where ``keep`` (``..., J``), over
    ``count`` values: the plain sum of squares, or where that reached inf (differences past 1e154, with a
    RuntimeWarning) the squares of the differences divided by the largest one. Differences below 1e-154 stay
    plain: their squares' rounding is within the last place of a mean that small. A non-finite difference (a
    broken prediction) propagates."""
    with np.errstate(over="ignore"):  # one expression, as before: numpy squares p - t in place (no second buffer)
        plain = _mean_or_nan(float(((p - t) ** 2).sum(axis=(-2, -1))[keep].sum()), count)
    if not np.isinf(plain):
        return plain
    kept = _differences(p[keep], t[keep])
    top = float(np.abs(kept).max())
    if not top < np.inf:  # a difference past float64 or NaN (a broken prediction): so is the mean
        return plain
    unit = kept / top
    with np.errstate(over="ignore"):  # past float64: inf
        return float(top * (top * ((unit * unit).sum() / count)))


def _heatmap_size(size) -> tuple[int, int]:
    """``(H, W)`` from one int or two: ``int()`` took True as 1, 8.7 as 8 and "8" as 8."""
    dims = (size, size) if np.ndim(size) == 0 else tuple(size)
    if len(dims) != 2 or not all(_is_int(d) and d >= 1 for d in dims):
        raise ShapeError(f"heatmap size must be a positive int or (H, W) of them, got {size!r}")
    return int(dims[0]), int(dims[1])


def gaussian_heatmaps(joints_2d, visible, size: int | tuple[int, int], sigma: float) -> np.ndarray:
    """Ground-truth joint heatmaps: one unnormalised Gaussian (peak 1) per visible joint.

    ``h(u, v) = exp(-((u - x)^2 + (v - y)^2) / (2 sigma^2))`` evaluated at pixel centres
    (integer coordinates, OpenCV convention), no truncation. Joints not visible, or with
    non-finite coordinates, get an all-zero map. The value is exactly 1 only when the joint
    sits on a pixel centre.

    Args:
        joints_2d: ``(..., J, 2)`` joint positions **in heatmap pixels** (convert image or
            model-input pixels first, e.g. ``keypoints.model_to_heatmap_pixels``).
        visible: ``(..., J)`` bool.
        size: heatmap ``(H, W)``, or one int for a square map (positive ints; else ShapeError).
        sigma: Gaussian standard deviation in heatmap pixels: a number > 0, at least about 1e-162 (else, and for a
            bool or text, ValueError naming it).

    Returns:
        ``(..., J, H, W)`` float32.

    Example:
        >>> h = gaussian_heatmaps([[1.0, 2.0]], [True], (4, 3), sigma=1.0)
        >>> h.shape, float(h[0, 2, 1])
        ((1, 4, 3), 1.0)
    """
    joints = _points("joints_2d", joints_2d, 2)
    vis = _mask("visible", visible, joints.shape[:-1]) & np.all(np.isfinite(joints), axis=-1)
    h, w = _heatmap_size(size)
    if _is_int(_positive_number("sigma", sigma, " (heatmap pixels)")):
        sigma = float(sigma)  # an int's 2 sigma^2 wrapped in int64 (2**40: 0) or left float64 (10**300: OverflowError)
    # below 1e-162 the 2 sigma^2 of the exponent underflows to 0: 0 / 0 on a joint's own pixel, a NaN target
    if not 2 * sigma * sigma > 0:
        raise ValueError(f"sigma must be a positive number whose square float64 holds, got {sigma}")
    x = np.where(vis, joints[..., 0], 0.0)[..., None]
    y = np.where(vis, joints[..., 1], 0.0)[..., None]
    # Separable: exp(-dx^2) * exp(-dy^2) as an outer product, cheap for any batch size. A joint 1e154 pixels
    # off squares to inf (its map is 0, as it should be): no overflow warning for it.
    with np.errstate(over="ignore"):
        gx = np.exp(-((np.arange(w) - x) ** 2) / (2 * sigma * sigma))
        gy = np.exp(-((np.arange(h) - y) ** 2) / (2 * sigma * sigma))
    maps = gy[..., :, None] * gx[..., None, :]
    return (maps * vis[..., None, None]).astype(np.float32)
