"""3D joints from the model's outputs: three methods, pure functions.

* :func:`triangulate_joints` -- DLT of the two views' decoded 2D peaks (in the crop cameras,
  so no lens model is involved), weighted by peak confidence, with a per-joint reprojection
  check: a joint whose reprojection error exceeds ``max_reprojection_px`` in either view is
  missing (with two views the culprit cannot be told, so neither is trusted), and so is one
  whose rays meet at less than ``min_ray_angle_deg`` (too far for its baseline to give a depth).
* :func:`volumetric_joints` -- the ``query`` graph's joint heatmap head evaluated on a regular
  grid inside the subject box (:func:`query_grid`), averaged over the two source volumes; per
  joint the weighted centroid of the grid points near its maximum (sub-cell estimate).
* :func:`depth_centroid_joints` -- each view's rendered depth turns the heatmap rays around the
  joint's 2D peak into 3D points (the depth-guided samples' expected surface); their
  heatmap-weighted centroid, pushed ``surface_offset_m`` behind the surface, is that view's
  estimate, and the views' estimates are averaged by confidence. One view suffices, so it
  also answers for joints the other camera does not see.

Every result is finite: missing joints are 0 with confidence 0.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ghnerf_runtime.config import Joints3DConfig
from ghnerf_runtime.errors import ShapeError
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.triangulation import (TwoViewCameras, TwoViewSolution, solve_two_views,
                                                  triangulate_robust, triangulate_two_views)
from ghnerf_runtime.keypoints import heatmap_to_model_pixels

__all__ = ["Joints3D", "ViewAgreement", "gate_presence", "gate_to_box", "near_the_body", "triangulate_joints",
           "triangulate_joints_checked", "solve_two_view_peaks", "sorted_median", "lowest_height_m", "lower_foot_m",
           "grid_shape", "query_grid", "volumetric_joints", "depth_centroid_joints"]


@dataclass(frozen=True, eq=False)
class Joints3D:
    """3D joints of one pair.

    Attributes:
        points: ``(J, 3)`` rig frame, metres; 0 where not valid.
        confidence: ``(J,)`` float32 in [0, 1]; 0 where not valid.
        valid: ``(J,)`` bool.
        reprojection_px: ``(J, C)`` reprojection error per view in model-input pixels (0 where
            not computed).
    """

    points: np.ndarray
    confidence: np.ndarray
    valid: np.ndarray
    reprojection_px: np.ndarray

    @staticmethod
    def missing(num_joints: int, num_views: int = 2) -> "Joints3D":
        return Joints3D(np.zeros((num_joints, 3)), np.zeros(num_joints, np.float32), np.zeros(num_joints, bool),
                        np.zeros((num_joints, num_views)))

    def sanitised(self) -> "Joints3D":
        """Joints with any non-finite value become missing; coordinates of missing joints are 0."""
        ok = (self.valid & np.all(np.isfinite(self.points), axis=-1) & np.isfinite(self.confidence)
              & (self.confidence > 0))
        return Joints3D(np.where(ok[:, None], self.points, 0.0), np.where(ok, self.confidence, 0.0).astype(np.float32),
                        ok, np.where(np.isfinite(self.reprojection_px), self.reprojection_px, 0.0))


def gate_presence(joints: Joints3D, min_joints: int, min_confidence: float) -> Joints3D:
    """Nobody unless at least ``min_joints`` joints have ``confidence >= min_confidence``.

    A model trained only on views with a person in them answers "someone" for an empty room
    too, with weaker peaks; this turns such a pair into all-missing joints.

    Example:
        >>> j = Joints3D(np.ones((3, 3)), np.array([0.9, 0.2, 0.2], np.float32), np.ones(3, bool), np.zeros((3, 2)))
        >>> gate_presence(j, 2, 0.5).valid.tolist(), gate_presence(j, 1, 0.5).valid.tolist()
        ([False, False, False], [True, True, True])
    """
    strong = int(np.count_nonzero(joints.valid & (joints.confidence >= min_confidence)))
    if strong >= min_joints:
        return joints
    J = len(joints.valid)
    return Joints3D(np.zeros_like(joints.points), np.zeros(J, np.float32), np.zeros(J, bool),
                    np.zeros_like(joints.reprojection_px))


def gate_to_box(joints: Joints3D, box: np.ndarray, margin: float) -> Joints3D:
    """Joints further than ``margin`` metres outside a ``(2, 3)`` box become missing.

    Example:
        >>> pts = np.array([[0.0, 0, 0], [2.0, 0, 0]])
        >>> j = Joints3D(pts, np.ones(2, np.float32), np.ones(2, bool), np.zeros((2, 2)))
        >>> gate_to_box(j, np.array([[-1.0, -1, -1], [1, 1, 1]]), 0.5).valid.tolist()
        [True, False]
    """
    box = np.asarray(box, dtype=np.float64)
    inside = np.all((joints.points >= box[0] - margin) & (joints.points <= box[1] + margin), axis=-1)
    return Joints3D(joints.points, joints.confidence, joints.valid & inside, joints.reprojection_px).sanitised()


def sorted_median(values, axis: int | None = None):
    """``np.median(values, axis)`` to the bit, in its dtype, from one sort: the middle value, or the middle two's sum
    halved, summed from +0.0 as np.median's mean sums; where a NaN is among the values, the NaN np.median gives (the
    NaN itself for one median, ``np.nan`` in an array of them). np.median's partition, mean and NaN check took 26 us
    a call on session 71's host against 2 for this, and a pair's decoding asks for five or six medians. An empty
    slice or another dtype than float32 and float64 goes to np.median itself (its warning; float16's and integers'
    means)."""
    a = np.asarray(values)
    n = a.size if axis is None else a.shape[axis]
    if n == 0 or a.dtype not in (np.float32, np.float64):
        return np.median(a, axis=axis)
    s = np.sort(a, axis=axis)  # flattened for axis None; NaN sorts last
    last = -1 if axis is None else axis
    k = n // 2
    # np.median's mean sums from +0.0 (a median of -0.0 values is 0.0) and halves the middle two's sum. The 0 and 2
    # are of the values' dtype: numpy 1.x (pyproject allows >= 1.26) promotes a float32 scalar with a Python float or
    # int to float64, which sums and halves float32 values in float64 (another dtype, other bits: np.median's are
    # float32's)
    zero, two = s.dtype.type(0.0), s.dtype.type(2.0)
    middle = zero + s.take(k, last) if n % 2 else (zero + s.take(k - 1, last) + s.take(k, last)) / two
    tail = s.take(-1, last)
    nan = np.isnan(tail)
    if not nan.any():
        return middle
    return tail if np.ndim(middle) == 0 else np.where(nan, s.dtype.type(np.nan), middle)


def near_the_body(joints: Joints3D, max_m: float) -> Joints3D:
    """Joints further than ``max_m`` metres across the floor (x, z of the levelled rig frame) from the median of the
    valid joints become missing: a joint triangulated from a wrong pair of peaks lies metres off the body, while a
    body read too far or too near (a camera panned since calibration) keeps its joints together, wherever it lies.

    Example:
        >>> pts = np.array([[0.0, -1.5, 4.8], [0.1, 0.8, 4.9], [0.0, -1.0, 4.7], [0.0, 1.2, 8.5]])
        >>> j = Joints3D(pts, np.ones(4, np.float32), np.ones(4, bool), np.zeros((4, 2)))
        >>> near_the_body(j, 1.0).valid.tolist()
        [True, True, True, False]
    """
    if not joints.valid.any():
        return joints
    centre = sorted_median(joints.points[joints.valid][:, [0, 2]], axis=0)
    with np.errstate(invalid="ignore"):  # (a missing joint's point may be NaN: it stays missing)
        near = np.linalg.norm(joints.points[:, [0, 2]] - centre, axis=-1) <= max_m
    return Joints3D(joints.points, joints.confidence, joints.valid & near, joints.reprojection_px).sanitised()


def _numeric(name: str, value, dtype) -> np.ndarray:
    """``value`` as a ``dtype`` array; a ragged or non-numeric one is a :class:`ShapeError` naming ``name``
    (numpy's bare ValueError did not say which argument)."""
    try:
        return np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as e:
        raise ShapeError(f"{name} must be a numeric array, got {type(value).__name__}: {e}") from None


def _check_views(uv: np.ndarray, conf: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    uv = _numeric("uv", uv, np.float64)
    conf = _numeric("confidence", conf, np.float64)
    valid = _numeric("valid", valid, bool)
    if uv.ndim != 3 or uv.shape[-1] != 2 or conf.shape != uv.shape[:2] or valid.shape != uv.shape[:2]:
        raise ShapeError(f"uv (C, J, 2), confidence (C, J), valid (C, J) expected, got {uv.shape}, {conf.shape}, "
                         f"{valid.shape}")
    # peak values are in [0, 1] (the decoder's): one past it gave a 3D confidence past it (1.5 -> 1.1), and
    # a non-finite one no view at all, so NaN and inf count as no peak
    conf = np.where(np.isfinite(conf), np.clip(conf, 0.0, 1.0), 0.0)
    return uv, conf, valid


# ----------------------------------------------------------------- triangulation
@dataclass(frozen=True)
class ViewAgreement:
    """How well the two views' confident peaks meet in 3D, measured before the reprojection gate.

    A camera turned on its mount after calibration moves every joint off its epipolar line: the error
    grows for all joints at once, and past ``max_reprojection_px`` the gate drops them, so the reported
    joints alone would not show it (the worst are gone). This is what the daemon watches
    (``docs/calibration.md``, "When the rig no longer fits").

    Attributes:
        median_px: median over the measured joints of the larger of the views' reprojection errors
            (model-input pixels), before the gate; ``None`` when fewer than ``min_joints`` were measured
            (nobody, or too little seen in both views to tell).
        joints: joints measured: triangulated, with a peak of at least ``min_confidence`` in both views.
        gated: of those, how many the ``max_reprojection_px`` gate dropped.
        worst_px: ``(J,)`` each measured joint's larger view error (the values ``median_px`` is the median of),
            NaN for a joint not measured; ``None`` where not given. Two people's pairings are measured joint by
            joint from it (``two_people.matched_errors``).
    """

    median_px: float | None
    joints: int
    gated: int
    worst_px: np.ndarray | None = field(default=None, repr=False, compare=False)


def lowest_height_m(j3: Joints3D, joints: Sequence[int]) -> float | None:
    """The height above the floor of the lowest of ``joints`` that ``j3`` has (the rig frame is levelled: y down,
    the floor at y = 0, docs/rig-file.md), in metres; ``None`` when it has none of them.

    Example:
        >>> j3 = Joints3D(np.array([[0, -1.5, 3], [0, -0.04, 3], [0, 0.5, 3]]), np.ones(3), np.array([True, True, False]),
        ...               np.zeros((3, 2)))
        >>> round(lowest_height_m(j3, [0, 1, 2]), 3), lowest_height_m(j3, [2])
        (0.04, None)
    """
    idx = [int(j) for j in joints if j3.valid[j]]
    if not idx:
        return None
    return float(-np.max(j3.points[idx, 1]))  # y down: the lowest joint has the largest y


def lower_foot_m(j3: Joints3D, feet: Sequence[Sequence[int]], standing_m: float, min_joints: int = 2) -> float | None:
    """How far the lower of ``feet`` stands above the floor (metres; the rig frame is levelled, y down, the floor at
    y = 0): per foot with at least ``min_joints`` of its joints in ``j3``, the median height of those joints less
    ``standing_m`` (that median on a foot flat on the floor: an ankle stands higher than a heel); the lower foot's.
    ``None`` when no foot has enough joints.

    The median of a foot's joints, not the lowest joint: the lowest of several noisy joints reads below the floor
    by more where the peaks are noisier (a far or foreshortened person), an offset of its own for each placement
    that hid a camera's pan (docs/calibration.md, "The feet on the floor"); a lone joint is not a foot's height.

    Example:
        >>> P = np.zeros((4, 3)); P[:, 1] = [-0.08, -0.04, -0.03, -0.30]  # a foot flat on the floor, one lifted
        >>> j3 = Joints3D(P, np.ones(4), np.array([True, True, True, True]), np.zeros((4, 2)))
        >>> round(lower_foot_m(j3, [(0, 1, 2), (3,)], 0.04), 3), lower_foot_m(j3, [(3,)], 0.04)
        (0.0, None)
    """
    heights = [[-j3.points[j, 1] for j in foot if j3.valid[j]] for foot in feet]  # y down: a height is -y
    medians = [float(sorted_median(h)) for h in heights if len(h) >= max(1, min_joints)]
    return min(medians) - standing_m if medians else None


def triangulate_joints(uv_model, confidence, valid, cameras: Sequence[Camera], config: Joints3DConfig, *,
                       terms: TwoViewCameras | None = None, solution: TwoViewSolution | None = None) -> Joints3D:
    """Triangulate 2D peaks given in model-input pixels of the crop cameras.

    Args:
        uv_model: ``(C, J, 2)`` peaks in each view's model-input pixels.
        confidence: ``(C, J)`` peak values.
        valid: ``(C, J)`` decoded.
        cameras: the C pinhole crop cameras (``preprocess.crop_camera``).
        config: ``max_reprojection_px``, ``min_view_confidence``, ``min_ray_angle_deg`` (a joint whose rays
            meet at a smaller angle is missing: nearly parallel rays give no depth worth reporting).
        terms, solution: as :func:`triangulate_joints_checked` (the answer is the same with them or without).

    Returns:
        :class:`Joints3D`; confidence is the geometric mean of the views' peak values.

    Example:
        >>> from ghnerf_runtime.geometry import Camera, look_at
        >>> K = [[100.0, 0, 63.5], [0, 100.0, 63.5], [0, 0, 1]]
        >>> eyes = (("a", -0.5), ("b", 0.5))
        >>> cams = [Camera(n, 128, 128, K, [], *look_at((x, -1.0, 0), (0, -1.0, 3))) for n, x in eyes]
        >>> X = np.array([[0.1, -1.2, 3.0]])
        >>> uv = np.stack([c.project(X)[0] for c in cams])
        >>> r = triangulate_joints(uv, np.full((2, 1), 0.8), np.ones((2, 1), bool), cams, Joints3DConfig())
        >>> np.round(r.points, 6).tolist(), r.valid.tolist(), round(float(r.confidence[0]), 3)
        ([[0.1, -1.2, 3.0]], [True], 0.8)
    """
    return triangulate_joints_checked(uv_model, confidence, valid, cameras, config, terms=terms, solution=solution)[0]


def _triangulation_inputs(uv_model, confidence, valid, cameras: Sequence[Camera], config: Joints3DConfig):
    """The checked peak values ``(C, J)``, the observations used ``(C, J)``, the peaks ``(C, J, 2)`` and weights
    ``(C, J)`` the solvers take (0 where not used) and the ``C`` projection matrices."""
    uv, conf, ok = _check_views(uv_model, confidence, valid)
    if len(cameras) != uv.shape[0]:  # (J, C, 2) with a matching (J, C) confidence passed _check_views
        raise ShapeError(f"uv_model has {uv.shape[0]} views on axis 0 (shape {uv.shape}) but {len(cameras)} cameras "
                         "were given: the peaks are (C, J, 2), views first")
    use = ok & (conf >= config.min_view_confidence) & (conf > 0) & np.all(np.isfinite(uv), axis=-1)
    weights = np.where(use, conf, 0.0)
    mats = [np.asarray(c.P if isinstance(c, Camera) else c, dtype=np.float64) for c in cameras]  # pinhole: P suffices
    return conf, use, np.where(use[..., None], uv, 0.0), weights, mats


def solve_two_view_peaks(uv_model, confidence, valid, cameras: Sequence[Camera], config: Joints3DConfig, *,
                         terms: TwoViewCameras | None = None) -> TwoViewSolution:
    """The two-view solve (:func:`~ghnerf_runtime.geometry.triangulation.solve_two_views`) that
    :func:`triangulate_joints_checked` checks, of the same peaks and weights: the caller that also builds the
    skeleton prior's inputs from these peaks passes it to both (``solution=``), so the DLT runs once.
    ``terms``: the two crop cameras' :class:`~ghnerf_runtime.geometry.triangulation.TwoViewCameras`, where the
    caller keeps them.

    Raises:
        ShapeError: as :func:`triangulate_joints`, or other than two views.
    """
    _, _, peaks, weights, mats = _triangulation_inputs(uv_model, confidence, valid, cameras, config)
    if len(mats) != 2:
        raise ShapeError(f"the two-view solve takes two views, got {len(mats)} cameras")
    return solve_two_views(peaks, np.stack(mats), weights, cameras=terms)


def triangulate_joints_checked(uv_model, confidence, valid, cameras: Sequence[Camera], config: Joints3DConfig,
                               min_confidence: float = 0.0, min_joints: int = 1, *,
                               terms: TwoViewCameras | None = None, solution: TwoViewSolution | None = None
                               ) -> tuple[Joints3D, ViewAgreement]:
    """:func:`triangulate_joints` and the :class:`ViewAgreement` of the joints whose peaks are at least
    ``min_confidence`` in every view (at least ``min_joints`` of them for a median), from one solve.
    ``solution``: :func:`solve_two_view_peaks` of these arguments, computed earlier (used where it solved these
    peaks, weights and matrices; solved here otherwise: the answer is the same). ``terms``: the two crop cameras'
    :class:`~ghnerf_runtime.geometry.triangulation.TwoViewCameras`, where the caller keeps them (a GeometryError
    where they are other cameras'; two views only: more views take the robust solver, which reads no such terms).

    Example (the right camera's rig entry tilted by 1 degree: its peaks lie 1.7 px off where the rig puts them
    in these 128 px crops, an error the triangulation shares between the views):
        >>> from ghnerf_runtime.geometry import Camera, look_at
        >>> K = [[100.0, 0, 63.5], [0, 100.0, 63.5], [0, 0, 1]]
        >>> cams = [Camera(n, 128, 128, K, [], *look_at((x, -1.0, 0), (0, -1.0, 3))) for n, x in (("a", -0.5), ("b", 0.5))]
        >>> X = np.array([[0.1, -1.2, 3.0], [-0.2, -0.4, 3.1], [0.0, 0.3, 2.9]])
        >>> uv = np.stack([c.project(X)[0] for c in cams])
        >>> a = np.radians(1.0); Rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
        >>> b = cams[1]; bumped = [cams[0], Camera("b", 128, 128, K, [], Rx @ b.R, Rx @ b.t)]
        >>> ok, conf = np.ones((2, 3), bool), np.full((2, 3), 0.8)
        >>> triangulate_joints_checked(uv, conf, ok, cams, Joints3DConfig())[1].median_px < 1e-6
        True
        >>> round(triangulate_joints_checked(uv, conf, ok, bumped, Joints3DConfig())[1].median_px, 1)
        0.9
    """
    conf, use, peaks, weights, mats = _triangulation_inputs(uv_model, confidence, valid, cameras, config)
    both = use.all(axis=0)
    if len(mats) == 2:  # the rig: the lean two-view solver (same results, a third of the numpy calls)
        # solved without its reprojection gate, applied below: the errors of the joints it drops are what a
        # bumped camera raises
        res = triangulate_two_views(peaks, np.stack(mats), weights, min_ray_angle_deg=config.min_ray_angle_deg,
                                    cameras=terms, solution=solution)
        solved = res.valid & both
        err = np.where(solved[:, None], res.reprojection_error, 0.0)
        worst = err.max(axis=-1)
        gated = solved & (worst > config.max_reprojection_px)
        good = solved & ~gated
        reprojection = np.where(good[:, None], err, 0.0)
    else:
        # more views: the robust solver drops a disagreeing view inside its gate, so only its result is measured
        res = triangulate_robust(peaks, mats, weights, undistorted=True,
                                 max_reprojection_error=config.max_reprojection_px,
                                 min_ray_angle_deg=config.min_ray_angle_deg)
        good = solved = res.valid & both
        worst = res.reprojection_error.max(axis=-1)
        gated = np.zeros_like(good)
        reprojection = res.reprojection_error
    # the C-th root: a square root is the geometric mean of two views only (three views of 0.8 gave 0.72)
    conf3 = np.prod(np.where(use, conf, 0.0), axis=0) ** (1.0 / len(conf))
    joints = Joints3D(np.where(good[:, None], res.points, 0.0), conf3.astype(np.float32), good,
                      reprojection).sanitised()
    measured = solved & np.all(conf >= min_confidence, axis=0) & np.isfinite(worst)
    n = int(measured.sum())
    median = float(sorted_median(worst[measured])) if n >= max(min_joints, 1) else None
    return joints, ViewAgreement(median, n, int((gated & measured).sum()), np.where(measured, worst, np.nan))


# ----------------------------------------------------------------- volumetric
def grid_shape(box: np.ndarray, n: int) -> tuple[int, int, int]:
    """``(nx, ny, nz)`` of a grid of about ``n**3`` points whose cells are near cubic in ``box``.

    Example:
        >>> grid_shape(np.array([[0.0, 0, 0], [1, 2, 1]]), 8)
        (6, 13, 6)
    """
    box = np.asarray(box, dtype=np.float64)
    if box.shape != (2, 3) or np.any(box[1] <= box[0]):
        raise ShapeError(f"box must be (2, 3) (min, max) with max > min, got {box.tolist()}")
    size = box[1] - box[0]
    per_axis = n * size / np.prod(size) ** (1 / 3)
    return tuple(int(max(3, round(v))) for v in per_axis)


def query_grid(box: np.ndarray, n: int) -> tuple[np.ndarray, tuple[int, int, int]]:
    """Cell centres ``(N, 3)`` float32 of a :func:`grid_shape` grid over a ``(2, 3)`` box, x fastest,
    and the grid's ``(nx, ny, nz)``.

    Example:
        >>> pts, shape = query_grid(np.array([[0.0, 0, 0], [0.4, 0.8, 0.4]]), 4)
        >>> shape, np.round(pts[:3].astype(float), 3).tolist()
        ((3, 6, 3), [[0.067, 0.067, 0.067], [0.2, 0.067, 0.067], [0.333, 0.067, 0.067]])
    """
    box = np.asarray(box, dtype=np.float64)
    shape = grid_shape(box, n)
    axes = [box[0, k] + (np.arange(shape[k]) + 0.5) * (box[1, k] - box[0, k]) / shape[k] for k in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=-1).astype(np.float32), shape


#: The share of the query grid a volumetric joint's response may hold at half its peak or more (the 2D
#: decoder's ``max_region_frac`` default); more is a flat or flooded response, and the joint is missing.
VOLUMETRIC_MAX_REGION_FRAC = 0.25


def volumetric_joints(joint_heat: np.ndarray, points: np.ndarray, shape: tuple[int, int, int],
                      config: Joints3DConfig) -> Joints3D:
    """Joints from the ``query`` graph's responses on a :func:`query_grid`.

    Per joint: the grid point of the largest response (mean over the source volumes), refined
    per axis by a parabola through the log responses of its two neighbours (exact for a
    Gaussian response; the step is clipped to half a cell); confidence is that response. A joint
    whose response is flat or flooded (more than :data:`VOLUMETRIC_MAX_REGION_FRAC` of the grid at
    half its peak or more) is missing.

    Args:
        joint_heat: ``(B, N, J)`` sigmoid responses, one row per source volume (averaged).
        points: ``(N, 3)`` the grid (x fastest).
        shape: ``(nx, ny, nz)`` with ``nx * ny * nz == N``.
        config: ``min_volumetric_response``.
    """
    heat = np.asarray(joint_heat, dtype=np.float64)
    pts = np.asarray(points, dtype=np.float64)
    nx, ny, nz = (int(v) for v in shape)
    if heat.ndim != 3 or pts.shape != (heat.shape[1], 3) or heat.shape[1] != nx * ny * nz:
        raise ShapeError(f"joint_heat (B, N, J) and points (N, 3) with N = {nx}*{ny}*{nz} expected, got "
                         f"{heat.shape}, {pts.shape}")
    J = heat.shape[2]
    with np.errstate(over="ignore", invalid="ignore"):
        mean = heat.mean(axis=0)  # (N, J)
    # As the 2D decoder: a non-finite response anywhere makes the joint missing (zeroed, its true peak could
    # be the NaN and the argmax found the next-best cell instead), and a negative one counts as 0.
    finite = np.isfinite(mean).all(axis=0)
    resp = np.where(np.isfinite(mean), np.maximum(mean, 0.0), 0.0)
    cube = resp.T.reshape(J, nz, ny, nx)
    best = resp.argmax(axis=0)
    peak = resp[best, np.arange(J)]
    idx = np.stack(np.unravel_index(best, (nz, ny, nx)), axis=-1)  # (J, 3) z, y, x
    dims = np.array([nz, ny, nx])
    floor = np.maximum(peak, 1e-12)[:, None] * 1e-6
    offset = np.zeros((J, 3))
    for axis in range(3):
        lo_i, hi_i = idx.copy(), idx.copy()
        lo_i[:, axis] -= 1
        hi_i[:, axis] += 1
        inner = (idx[:, axis] > 0) & (idx[:, axis] < dims[axis] - 1)
        lo_i = np.clip(lo_i, 0, dims - 1)
        hi_i = np.clip(hi_i, 0, dims - 1)
        j = np.arange(J)
        f0 = np.log(np.maximum(peak, floor[:, 0]))
        fm = np.log(np.maximum(cube[j, lo_i[:, 0], lo_i[:, 1], lo_i[:, 2]], floor[:, 0]))
        fp = np.log(np.maximum(cube[j, hi_i[:, 0], hi_i[:, 1], hi_i[:, 2]], floor[:, 0]))
        curv = fm - 2 * f0 + fp
        step = np.where(inner & (curv < 0), 0.5 * (fm - fp) / np.where(curv < 0, curv, -1.0), 0.0)
        offset[:, axis] = np.clip(step, -0.5, 0.5)
    cell = np.zeros(3)
    if nx > 1:
        cell[0] = pts[1, 0] - pts[0, 0]
    if ny > 1:
        cell[1] = pts[nx, 1] - pts[0, 1]
    if nz > 1:
        cell[2] = pts[nx * ny, 2] - pts[0, 2]
    points_out = pts[best] + offset[:, ::-1] * cell  # offsets z, y, x -> x, y, z
    # A peak, not a flat or flooded response (a constant one's argmax is the grid's first cell): as the 2D
    # decoder's max_region_frac, at most that share of the grid may reach half the peak.
    region = (resp >= 0.5 * peak[None, :]).mean(axis=0)
    valid = finite & (peak >= max(config.min_volumetric_response, 1e-6)) & (region <= VOLUMETRIC_MAX_REGION_FRAC)
    # sigmoid responses are at most 1: a stray larger one is no confidence above it (1e30 reached the JSON)
    conf = np.minimum(peak, 1.0).astype(np.float32)
    return Joints3D(points_out, conf, valid, np.zeros((J, heat.shape[0]))).sanitised()


# ----------------------------------------------------------------- depth centroid
def depth_centroid_joints(heatmaps: np.ndarray, depth: np.ndarray, peaks_uv: np.ndarray, confidence: np.ndarray,
                          valid: np.ndarray, cameras: Sequence[Camera], model_size: int,
                          config: Joints3DConfig) -> Joints3D:
    """Joints from the rendered depth around each view's 2D peak.

    Args:
        heatmaps: ``(C, J, h, w)`` rendered heatmaps on the heatmap grid (0 where not rendered).
        depth: ``(C, h, w)`` rendered expected depth (camera z, metres) on the same grid.
        peaks_uv: ``(C, J, 2)`` decoded peaks in heatmap pixels.
        confidence, valid: ``(C, J)`` decoded peak values and flags.
        cameras: the C pinhole crop cameras.
        model_size: model input side (heatmap -> model pixels).
        config: ``centroid_radius_cells``, ``surface_offset_m``, ``min_view_confidence``.

    Returns:
        :class:`Joints3D`; confidence is the larger of the views' peak values.
    """
    hm = np.asarray(heatmaps, dtype=np.float64)
    dep = np.asarray(depth, dtype=np.float64)
    uv, conf, ok = _check_views(peaks_uv, confidence, valid)
    C, J, h, w = hm.shape
    if dep.shape != (C, h, w) or uv.shape[:2] != (C, J) or len(cameras) != C:
        raise ShapeError(f"heatmaps (C, J, h, w), depth (C, h, w), peaks (C, J, 2) and C cameras expected, got "
                         f"{hm.shape}, {dep.shape}, {uv.shape}, {len(cameras)}")
    r = config.centroid_radius_cells
    offs = np.arange(-r, r + 1)
    # A peak off the map (or not finite) has no rays around it: clamped to the edge, the window read the
    # edge's cells and reported their centroid as the joint.
    on_map = (np.isfinite(uv).all(axis=-1) & (uv[..., 0] >= -0.5) & (uv[..., 0] < w - 0.5)
              & (uv[..., 1] >= -0.5) & (uv[..., 1] < h - 0.5))
    uv = np.where(on_map[..., None], uv, 0.0)
    cy = np.clip(np.rint(uv[..., 1]).astype(int), 0, h - 1)  # (C, J)
    cx = np.clip(np.rint(uv[..., 0]).astype(int), 0, w - 1)
    yy = cy[..., None, None] + offs[:, None]  # (C, J, k, 1)
    xx = cx[..., None, None] + offs[None, :]  # (C, J, 1, k)
    yy, xx = np.broadcast_arrays(yy, xx)
    inside = (yy >= 0) & (yy < h) & (xx >= 0) & (xx < w)
    yc, xc = np.clip(yy, 0, h - 1), np.clip(xx, 0, w - 1)
    ci = np.arange(C)[:, None, None, None]
    ji = np.arange(J)[None, :, None, None]
    hv = hm[ci, ji, yc, xc]
    dv = dep[ci, yc, xc]
    good = inside & np.isfinite(hv) & np.isfinite(dv) & (dv > 1e-3)
    # heatmap values in [0, 1], as the decoder reads them: squared, a negative one weighed like a positive one
    # (a cell of -0.95 pulled the joint 1.6 m towards its depth) and a huge one overflowed to inf
    wgt = np.where(good, np.clip(np.nan_to_num(hv), 0.0, 1.0) ** 2, 0.0)
    cells = np.stack([xc, yc], axis=-1).astype(np.float64)  # heatmap pixels
    model_uv = heatmap_to_model_pixels(cells, (w, h), model_size)
    points = np.zeros((C, J) + yy.shape[2:] + (3,))
    for c, cam in enumerate(cameras):
        xy = cam.pixels_to_normalized(model_uv[c])  # pinhole: exact
        d_cam = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
        unit = d_cam / np.linalg.norm(d_cam, axis=-1, keepdims=True)
        z = np.where(good[c], dv[c], 0.0)
        p_cam = d_cam * z[..., None] + unit * config.surface_offset_m
        points[c] = p_cam @ cam.R + cam.center  # R^T p + centre, row vectors
    wsum = wgt.sum(axis=(-2, -1))
    per_view = (wgt[..., None] * points).sum(axis=(-3, -2)) / np.where(wsum > 0, wsum, 1.0)[..., None]  # (C, J, 3)
    use = ok & on_map & (conf >= config.min_view_confidence) & (conf > 0) & (wsum > 0)
    vw = np.where(use, conf, 0.0)
    total = vw.sum(axis=0)
    joint = (vw[..., None] * per_view).sum(axis=0) / np.where(total > 0, total, 1.0)[:, None]
    conf3 = np.where(use, conf, 0.0).max(axis=0)
    return Joints3D(joint, conf3.astype(np.float32), use.any(axis=0), np.zeros((J, C))).sanitised()
