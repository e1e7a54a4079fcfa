"""Multi-view triangulation of many joints at once: DLT, ray midpoint, view dropping.

The general solvers (:func:`triangulate_dlt`, :func:`triangulate_midpoint`,
:func:`triangulate_robust`) take the observations of ``J`` joints in ``C`` cameras as
one array ``uv`` of shape ``(..., C, J, 2)`` (leading batch dimensions, e.g. frames,
are allowed) and return a :class:`TriangulationResult` whose arrays have the joint
axis before the camera axis: points ``(..., J, 3)``, reprojection errors
``(..., J, C)``. The estimator's case, two views of one frame
(:func:`triangulate_two_views`, ``uv`` ``(2, J, 2)``), comes in two halves too:
:func:`solve_two_views` gives a :class:`TwoViewSolution`, which
:func:`check_two_views` turns into the :class:`TriangulationResult`.

Degenerate joints never raise and never produce NaN: they come back with
``valid == False`` and documented fill values (see :class:`TriangulationResult`).
Only malformed arguments (wrong shapes, non-finite or singular projection
matrices) raise :class:`~ghnerf_runtime.errors.ShapeError` /
:class:`~ghnerf_runtime.errors.GeometryError`.

Conditioning figure
    Each joint reports ``ray_angle_deg``: the largest angle between the *lines*
    of any two rays used for it, folded into [0, 90] degrees. It is geometric
    (independent of units, normalisation and noise level), it is available for
    every joint with two rays, and it is the quantity depth precision depends
    on: for pixel noise ``sigma`` and focal length ``f`` the depth error grows
    like ``sigma / (f * sin(angle))``. The algebraic alternative (ratio of the
    two smallest singular values of the DLT system) measures how *consistent*
    the observations are rather than how well the geometry constrains depth:
    noise-free rays that are nearly parallel give a tiny ratio and look
    "perfect". A 7.5 cm stereo baseline gives about 1 degree at 4 m; the
    default ``min_ray_angle_deg`` of 0.1 only rejects the numerically
    degenerate, so gate on the reported angle for application decisions.

Pure numpy; no I/O. See docs/geometry.md.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence, Union

import numpy as np

from ghnerf_runtime.errors import GeometryError, ShapeError
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.kept_terms import read_only, same_bits, terms_of

CameraLike = Union[Camera, np.ndarray]

#: Smallest camera depth (rig units) a triangulated point may have in any used view.
MIN_DEPTH = 1e-9
#: Smallest ray angle (degrees) any joint is valid at, whatever ``min_ray_angle_deg`` says (0 included): below
#: it the two rays are one line to rounding (a point on the line through two centres, or one pixel seen twice
#: through one camera), the DLT's null space is two-dimensional and its point anywhere on that line. A real
#: angle this small is a point 10^11 baselines away.
MIN_RAY_ANGLE_FLOOR_DEG = 1e-9
#: Camera centres closer than this share of their distance from the origin are one centre: views from one
#: point give no depth, and the solvers' point for their (diverging) rays is that centre, a hair in front.
CENTRE_TOLERANCE = 1e-9
#: Smallest volume the rows of a projection matrix's left 3x3 block span, once conditioned as the solvers
#: condition it and each row scaled to unit length (:func:`block_volume`), for the matrix to be solved in. It is
#: 1 for any pinhole camera without skew, whatever its focal lengths (fx and fy apart too), principal point or
#: units, and ``fx / hypot(fx, skew)`` with one; below this the block is singular to rounding (camera at infinity).
MIN_BLOCK_VOLUME = 1e-12
#: Smallest share of a left-block row's terms that its conditioned row may keep (:func:`block_volume`): less is
#: rounding (a third row that is the first over a focal length, rows 1e10 focal lengths off centre: the
#: conditioned row's digits are gone, yet scaled to unit length it spanned a volume).
MIN_ROW_SHARE = 1e-10

__all__ = [
    "TriangulationResult",
    "TwoViewCameras",
    "TwoViewSolution",
    "check_two_views",
    "solve_two_views",
    "triangulate_dlt",
    "triangulate_midpoint",
    "triangulate_robust",
    "triangulate_two_views",
    "MIN_DEPTH",
    "MIN_RAY_ANGLE_FLOOR_DEG",
    "CENTRE_TOLERANCE",
    "MIN_BLOCK_VOLUME",
    "MIN_ROW_SHARE",
    "block_volume",
]


@dataclass(frozen=True, eq=False)
class TriangulationResult:
    """Triangulated joints plus per-joint quality figures. All arrays are finite.

    Attributes:
        points: ``(..., J, 3)`` rig-frame points. ``0.0`` where ``valid`` is False.
        reprojection_error: ``(..., J, C)`` distance in pixels between the observation and
            the reprojected point, in the pixel space of the input (distorted pixels unless
            the input was undistorted). Given for every finite observation of a valid joint,
            including ones that were ignored (weight 0) or dropped, as long as that camera can
            see the point (in front of it and, for distorted pixels, inside its lens model's fold:
            :meth:`Camera.project`); ``0.0`` everywhere else. Use ``used`` to tell them apart.
        ray_angle_deg: ``(..., J)`` conditioning figure: the largest angle, in degrees within
            [0, 90], between the lines of any two used rays. ``0.0`` with fewer than two
            used views. Reported for invalid joints too (as a diagnostic).
        num_views: ``(..., J)`` number of used observations (int).
        valid: ``(..., J)`` True where the point is trustworthy: at least two used views, two of
            them from distinct centres, ``ray_angle_deg >= min_ray_angle_deg`` and
            ``>= MIN_RAY_ANGLE_FLOOR_DEG``, a finite solution that is not at infinity, and seen by
            every used camera (in front of it, inside its lens fold).
        used: ``(..., J, C)`` which observations took part in the solution.
    """

    points: np.ndarray
    reprojection_error: np.ndarray
    ray_angle_deg: np.ndarray
    num_views: np.ndarray
    valid: np.ndarray
    used: np.ndarray

    @property
    def conditioning(self) -> np.ndarray:
        """Alias of :attr:`ray_angle_deg` ``(..., J)``, the conditioning figure."""
        return self.ray_angle_deg

    def mean_reprojection_error(self) -> np.ndarray:
        """Mean reprojection error over the used views ``(..., J)``; 0 for invalid joints."""
        mask = self.used & self.valid[..., None]
        total = np.where(mask, self.reprojection_error, 0.0).sum(axis=-1)
        return total / np.maximum(mask.sum(axis=-1), 1)

    def max_reprojection_error(self) -> np.ndarray:
        """Largest reprojection error over the used views ``(..., J)``; 0 for invalid joints."""
        mask = self.used & self.valid[..., None]
        return np.where(mask, self.reprojection_error, 0.0).max(axis=-1, initial=0.0)


# --------------------------------------------------------------------------- input handling
@dataclass(frozen=True)
class _Views:
    """Observations brought to a common form: undistorted pixels and 3x4 matrices."""

    uv: np.ndarray          # (N, C, J, 2) the input pixels, float64, as given
    x: np.ndarray           # (N, C, J, 2) undistorted pixels (0 where not used)
    w: np.ndarray           # (N, C, J) weights, 0 where the observation is ignored
    used: np.ndarray        # (N, C, J) bool
    P: np.ndarray           # (C, 3, 4)
    cameras: tuple          # (C,) Camera or None
    lens: np.ndarray        # (C,) bool: the input pixels of camera c are distorted
    T: np.ndarray           # (C, 3, 3) the conditioning similarities (_conditioning_similarity of P)
    batch_shape: tuple


def _check_thresholds(min_ray_angle_deg, max_reprojection_error=None) -> None:
    """Refuse thresholds that would silently pass or fail every joint: a NaN angle made every joint invalid, a
    NaN reprojection limit of :func:`triangulate_two_views` gated nothing."""
    if not (isinstance(min_ray_angle_deg, (int, float, np.number)) and 0 <= min_ray_angle_deg <= 90):
        raise GeometryError(f"min_ray_angle_deg must be a number of degrees in [0, 90], got {min_ray_angle_deg!r}")
    if max_reprojection_error is not None and not (
            isinstance(max_reprojection_error, (int, float, np.number)) and 0 < max_reprojection_error < np.inf):
        raise GeometryError(f"max_reprojection_error must be a positive number of pixels, got {max_reprojection_error!r}")


def _as_cameras(cameras) -> tuple[np.ndarray, tuple, np.ndarray]:
    """Projection matrices ``(C, 3, 4)``, the Camera objects (or None) they came from and the matrices'
    conditioning similarities ``(C, 3, 3)`` (:func:`_conditioning_similarity`, which their check needs too)."""
    if isinstance(cameras, Camera):
        raise ShapeError("cameras must be a sequence of Camera objects or projection matrices, got one Camera")
    if isinstance(cameras, np.ndarray) and cameras.dtype != object:
        if cameras.ndim != 3 or cameras.shape[1:] != (3, 4):
            raise ShapeError(f"projection matrices must have shape (C, 3, 4), got {cameras.shape}")
        items: Sequence = list(cameras)
    else:
        try:
            items = list(cameras)
        except TypeError:
            raise ShapeError(
                f"cameras must be a sequence of Camera objects or (3, 4) projection matrices, got {type(cameras).__name__}"
            ) from None
    if not items:
        raise ShapeError("cameras must not be empty")
    matrices, objects, names = [], [], []
    for i, item in enumerate(items):
        if isinstance(item, Camera):
            matrices.append(item.P)
            objects.append(item)
            names.append(f"cameras[{i}] (camera {item.name!r})")
            continue
        try:
            P = np.asarray(item, dtype=np.float64)
        except (TypeError, ValueError):
            raise ShapeError(f"cameras[{i}] must be a Camera or a (3, 4) projection matrix, got {type(item).__name__}") from None
        if P.shape != (3, 4):
            raise ShapeError(f"cameras[{i}] projection matrix must have shape (3, 4), got {P.shape}")
        matrices.append(P)
        objects.append(None)
        names.append(f"cameras[{i}]")
    P = np.stack(matrices)
    return P, tuple(objects), _check_regular(P, names)


def _check_regular(P: np.ndarray, names: Sequence[str]) -> np.ndarray:
    """The conditioning similarities ``(C, 3, 3)`` of the ``(C, 3, 4)`` matrices ``P``; GeometryError naming the
    first that is not finite or whose left block is singular (:func:`block_volume`), by ``names[c]``, and its
    matrix. The one check of the general solvers and :meth:`TwoViewCameras.from_P`, so that both refuse the same
    matrices in the same words.

    :class:`Camera` objects are checked too: a finite K can lose its focal length to rounding in ``P``
    (fx = 1e-20 px beside a principal point at 320 px), which np.linalg.inv refused with a bare LinAlgError."""
    # (all() first, the first False by argmin only on a refusal: the two-view solver's terms are built per crop)
    finite = np.isfinite(P).all(axis=(1, 2))
    if not finite.all():
        c = int(np.argmin(finite))
        raise GeometryError(f"{names[c]} projection matrix must be finite, got {P[c].tolist()}")
    with np.errstate(all="ignore"):
        T = _conditioning_similarity(P)
    volume = block_volume(P, T)
    regular = volume > MIN_BLOCK_VOLUME
    if not regular.all():
        c = int(np.argmin(regular))
        raise GeometryError(f"{names[c]} projection matrix has a singular left 3x3 block (camera at infinity): its "
                            f"conditioned rows span a volume of {volume[c]:.3g}, at least {MIN_BLOCK_VOLUME:g} "
                            f"needed, got {P[c].tolist()}")
    return T


def _prepare(uv, cameras, weights, undistorted: bool | None) -> _Views:
    P, objects, T = _as_cameras(cameras)
    C = len(objects)
    uv = np.asarray(uv, dtype=np.float64)
    if uv.ndim < 3 or uv.shape[-1] != 2:
        raise ShapeError(f"uv must have shape (..., C, J, 2), got {uv.shape}")
    if uv.shape[-3] != C:
        raise ShapeError(f"uv has {uv.shape[-3]} cameras on axis -3 but {C} cameras were given (uv shape {uv.shape})")
    batch_shape = uv.shape[:-3]
    J = uv.shape[-2]
    if weights is None:
        w = np.ones(uv.shape[:-1])
    else:
        w = np.asarray(weights, dtype=np.float64)
        try:
            w = np.broadcast_to(w, uv.shape[:-1])
        except ValueError:
            raise ShapeError(f"weights must broadcast to (..., C, J) = {uv.shape[:-1]}, got {w.shape}") from None
    N = int(np.prod(batch_shape, dtype=np.int64))
    uv = uv.reshape((N, C, J, 2))
    w = w.reshape((N, C, J))

    if undistorted is None:
        lens = np.array([cam is not None for cam in objects])
    elif undistorted:
        lens = np.zeros(C, dtype=bool)
    else:
        for i, cam in enumerate(objects):
            if cam is None:
                raise GeometryError(
                    f"cameras[{i}] is a projection matrix, which has no lens model, so it cannot take distorted "
                    "pixels; pass undistorted=True (or None) or give Camera objects"
                )
        lens = np.ones(C, dtype=bool)

    with np.errstate(all="ignore"):
        x = uv.copy()
        for c, cam in enumerate(objects):
            if lens[c] and cam.has_distortion:
                x[:, c] = cam.undistort_pixels(uv[:, c])
        used = (
            np.all(np.isfinite(uv), axis=-1)
            & np.all(np.isfinite(x), axis=-1)
            & np.isfinite(w)
            & (w > 0)
        )
    w, used = _relative_weights(np.where(used, w, 0.0), used, axis=1)
    x = np.where(used[..., None], x, 0.0)
    return _Views(uv=uv, x=x, w=w, used=used, P=P, cameras=objects, lens=lens, T=T, batch_shape=batch_shape)


def _relative_weights(w: np.ndarray, used: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's weights over their largest (along the camera ``axis``), and ``used`` without the
    observations whose share underflows to 0.

    The solutions do not change, but huge weights cannot overflow the solvers' sums (the midpoint's
    system went inf, a valid joint invalid) nor tiny ones underflow them (all-denormal weights made it
    exactly singular: LinAlgError); an observation whose share is 0 takes no part, so it is not used
    (a joint with weights 1e300 and 1e-300 was reported valid from one view's ray, at an arbitrary depth).
    """
    top = w.max(axis=axis, keepdims=True)
    with np.errstate(all="ignore"):
        w = np.where(top > 0, w / np.where(top > 0, top, 1.0), 0.0)
    used = used & (w > 0)
    return np.where(used, w, 0.0), used


# --------------------------------------------------------------------------- shared geometry
def _rays(views: _Views) -> tuple[np.ndarray, np.ndarray]:
    """Camera centres ``(C, 3)`` and unit ray directions ``(N, C, J, 3)`` (towards the scene)."""
    M = views.P[:, :, :3]
    Minv = np.linalg.inv(M)
    centres = -np.einsum("cij,cj->ci", Minv, views.P[:, :, 3])
    sign = np.sign(np.linalg.det(M))
    xh = np.concatenate([views.x, np.ones(views.x.shape[:-1] + (1,))], axis=-1)
    d = np.einsum("cij,ncmj->ncmi", Minv, xh) * sign[None, :, None, None]
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return centres, d


def _max_ray_angle(d: np.ndarray, used: np.ndarray) -> np.ndarray:
    """Largest angle (degrees, in [0, 90]) between the lines of two used rays ``(N, J)``."""
    # atan2(|a x b|, |a . b|) is accurate for tiny angles, where arccos(a . b) is not.
    dn = np.moveaxis(d, 1, 2)  # (N, J, C, 3)
    un = np.moveaxis(used, 1, 2)  # (N, J, C)
    cross = np.linalg.norm(np.cross(dn[..., :, None, :], dn[..., None, :, :]), axis=-1)
    dot = np.abs(np.einsum("njak,njbk->njab", dn, dn))
    angle = np.degrees(np.arctan2(cross, dot))
    pair = un[..., :, None] & un[..., None, :]
    return np.where(pair, angle, 0.0).max(axis=(-1, -2), initial=0.0)


def _distinct_centres(P: np.ndarray, Minv: np.ndarray | None = None) -> np.ndarray:
    """``(C, C)`` bool: which pairs of cameras have distinct centres (:data:`CENTRE_TOLERANCE`); ``Minv``, the
    inverses of the left 3x3 blocks, where the caller has them."""
    if Minv is None:
        Minv = np.linalg.inv(P[:, :, :3])
    centres = -(Minv @ P[:, :, 3:])[..., 0]  # (C, 3)
    gap2 = np.square(centres[:, None] - centres[None]).sum(axis=-1)
    size2 = np.square(centres).sum(axis=-1)
    return gap2 > CENTRE_TOLERANCE**2 * np.maximum(size2[:, None], size2[None])


def _two_centres(P: np.ndarray, used: np.ndarray, axis: int) -> np.ndarray | bool:
    """Per joint: whether two of its used views (camera ``axis`` of ``used``) have distinct centres; True
    (every joint) where all the cameras' centres are distinct, as in any real rig."""
    distinct = _distinct_centres(P)
    if distinct.sum() == distinct.size - len(distinct):  # all but the diagonal
        return True
    u = np.moveaxis(used, axis, -1).astype(np.float64)  # (..., C)
    # u D u^T counts the used pairs of distinct centres (D's diagonal is False)
    return np.einsum("...a,ab,...b->...", u, distinct.astype(np.float64), u) > 0


def _depths(P: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Signed depth of ``points`` ``(N, J, 3)`` in every camera ``(N, C, J)`` (H&Z 6.2.3)."""
    M = P[:, :, :3]
    sign = np.sign(np.linalg.det(M))
    scale = np.linalg.norm(M[:, 2, :], axis=-1)
    w3 = np.einsum("ck,njk->ncj", P[:, 2, :3], points) + P[None, :, 2, 3, None]
    return w3 * (sign / scale)[None, :, None]


def _finish(views: _Views, points: np.ndarray, ok: np.ndarray, angle: np.ndarray,
            min_ray_angle_deg: float) -> TriangulationResult:
    """Validity checks, reprojection and fill values shared by every solver."""
    N, C, J = views.used.shape
    num_views = views.used.sum(axis=1)
    with np.errstate(all="ignore"):
        ok = ok & np.all(np.isfinite(points), axis=-1) & (num_views >= 2) & (angle >= min_ray_angle_deg)
        # With min_ray_angle_deg 0 these were valid: a point anywhere on one line, or at a shared centre.
        ok &= (angle >= MIN_RAY_ANGLE_FLOOR_DEG) & _two_centres(views.P, views.used, axis=1)
        safe = np.where(ok[..., None], points, 0.0)
        depth = _depths(views.P, safe)  # (N, C, J)
        ok &= ~np.any(views.used & ~(depth > MIN_DEPTH), axis=1)

        err = np.zeros((N, C, J))
        for c in range(C):
            cam = views.cameras[c]
            if views.lens[c]:
                uv_hat, _ = cam.project(safe, distort=True)
            else:
                ph = safe @ views.P[c, :, :3].T + views.P[c, :, 3]
                uv_hat = ph[..., :2] / ph[..., 2:3]
            uv_hat = np.where((depth[:, c] > MIN_DEPTH)[..., None], uv_hat, np.nan)
            err[:, c] = np.linalg.norm(uv_hat - views.uv[:, c], axis=-1)
        # A used view whose error is not finite makes the joint untrustworthy: the point is past that
        # camera's lens fold (Camera.project: NaN, the view cannot have seen it) or overflowed.
        ok &= ~np.any(views.used & ~np.isfinite(err), axis=1)
        err = np.where(np.isfinite(err) & ok[:, None, :], err, 0.0)

    points = np.where(ok[..., None], points, 0.0)
    angle = np.where(np.isfinite(angle), angle, 0.0)
    shape = views.batch_shape
    return TriangulationResult(
        points=points.reshape(shape + (J, 3)),
        reprojection_error=np.moveaxis(err, 1, 2).reshape(shape + (J, C)),
        ray_angle_deg=angle.reshape(shape + (J,)),
        num_views=num_views.astype(np.int64).reshape(shape + (J,)),
        valid=ok.reshape(shape + (J,)),
        used=np.moveaxis(views.used, 1, 2).reshape(shape + (J, C)),
    )


# --------------------------------------------------------------------------- solvers
def _conditioning_similarity(P: np.ndarray) -> np.ndarray:
    """Per-camera Hartley similarity ``T_c`` ``(C, 3, 3)``: translate and scale pixels isotropically.

    Hartley & Zisserman (4.4.4) centre the points on their centroid and scale them to a
    mean distance of sqrt(2). For a calibrated camera the observations fill (at most) its
    field of view, so we take the centre and scale from the camera itself: the principal
    point and the mean focal length, read off ``M = P[:, :3]`` (``K K^T ~ M M^T``). That
    maps the image to about [-1, 1]^2 (tangent of the view angle) like Hartley's
    normalisation does, but is deterministic and cannot be wrecked by one wild detection
    in a batch, which a data centroid can.
    """
    M = P[:, :, :3]
    m3 = np.einsum("cij,cij->ci", M[:, 2:3], M[:, 2:3])[:, 0]  # |m3|^2
    cx = np.einsum("ck,ck->c", M[:, 0], M[:, 2]) / m3
    cy = np.einsum("ck,ck->c", M[:, 1], M[:, 2]) / m3
    fx2 = np.einsum("ck,ck->c", M[:, 0], M[:, 0]) / m3 - cx**2
    fy2 = np.einsum("ck,ck->c", M[:, 1], M[:, 1]) / m3 - cy**2
    f = 0.5 * (np.sqrt(np.maximum(fx2, 0.0)) + np.sqrt(np.maximum(fy2, 0.0)))
    f = np.where(f > 0, f, 1.0)
    s = 1.0 / f
    T = np.zeros((P.shape[0], 3, 3))
    T[:, 0, 0] = T[:, 1, 1] = s
    T[:, 0, 2] = -s * cx
    T[:, 1, 2] = -s * cy
    T[:, 2, 2] = 1.0
    return T


def block_volume(P: np.ndarray, T: np.ndarray | None = None) -> np.ndarray:
    """``(C,)`` how far from singular each projection matrix's left 3x3 block is, in a measure that does not
    depend on scale: ``|det|`` of the block conditioned by the solvers' similarity ``T``
    (:func:`_conditioning_similarity`, computed here where not given) with each row scaled to unit length.

    It is the volume the three unit rows span, in [0, 1]. Conditioning takes out the principal point and the
    focal length (a block ``K R`` becomes about ``R``), and unit rows take out any row's scale, so a camera 10 px
    or 1e6 px long, with pixels 1e5 times taller than wide, or with its principal point 1e7 px outside the image,
    gives 1 (to rounding); a skew ``s`` gives ``fx / hypot(fx, s)``. The raw ``|det M| / |M|^3`` this
    replaces fell with the principal point's distance and the focal length's scale, and refused cameras that
    :class:`~ghnerf_runtime.geometry.camera.Camera` accepts and the solvers solve. 0 for a block with a zero row
    (a zero third row: a camera at infinity), one whose conditioning overflowed (focal lengths of 1e300 px), and
    one with a conditioned row that rounding made (:data:`MIN_ROW_SHARE`).
    """
    with np.errstate(all="ignore"):
        if T is None:
            T = _conditioning_similarity(P)
        M = P[:, :, :3]
        block = T @ M
        rows = np.sqrt(np.square(block).sum(axis=-1))  # (C, 3)
        # What the conditioning subtracted: |T_i| |m_i| bounds each conditioned row's terms, and so its rounding.
        terms = np.abs(T) @ np.sqrt(np.square(M).sum(axis=-1))[:, :, None]  # (C, 3, 1)
        significant = np.all(rows > MIN_ROW_SHARE * terms[..., 0], axis=-1)
        volume = np.abs(np.linalg.det(block / rows[..., None]))
        return np.where(significant & np.isfinite(volume), volume, 0.0)


def _dlt_solve(views: _Views) -> tuple[np.ndarray, np.ndarray]:
    """Batched homogeneous DLT. Returns points ``(N, J, 3)`` and a "finite" mask ``(N, J)``."""
    T = views.T
    xn = views.x * T[None, :, None, [0, 1], [0, 1]] + T[None, :, None, [0, 1], 2]
    Pn = T @ views.P  # (C, 3, 4)
    Pn = Pn / np.linalg.norm(Pn, axis=(-2, -1), keepdims=True)
    # Two rows per observation (H&Z 12.2): u * p3 - p1 and v * p3 - p2, scaled by the weight.
    rows_u = xn[..., 0:1] * Pn[None, :, None, 2, :] - Pn[None, :, None, 0, :]  # (N, C, J, 4)
    rows_v = xn[..., 1:2] * Pn[None, :, None, 2, :] - Pn[None, :, None, 1, :]
    # Each joint's weights over their largest (the solution does not change): huge weights cannot overflow A.
    top = views.w.max(axis=1, keepdims=True)
    with np.errstate(all="ignore"):
        weights = np.where(top > 0, views.w / np.where(top > 0, top, 1.0), 0.0)
    A = np.stack([rows_u, rows_v], axis=2) * weights[:, :, None, :, None]  # (N, C, 2, J, 4)
    N, C, _, J, _ = A.shape
    A = np.moveaxis(A, 3, 1).reshape(N, J, 2 * C, 4)
    # A row that overflowed (absurd pixels) has no answer; LAPACK's SVD can loop forever on an inf.
    solvable = np.isfinite(A).all(axis=(-2, -1))
    A = np.where(solvable[..., None, None], A, 0.0)
    # The solution is the right singular vector of the smallest singular value.
    _, _, vh = np.linalg.svd(A, full_matrices=False if 2 * C >= 4 else True)
    X = vh[..., -1, :]
    w = X[..., 3]
    # A (near-)zero homogeneous coordinate is a point at infinity: (near-)parallel rays.
    finite = solvable & (np.abs(w) > 1e-12 * np.linalg.norm(X[..., :3], axis=-1))
    with np.errstate(all="ignore"):
        points = X[..., :3] / np.where(finite, w, 1.0)[..., None]
    return points, finite


def triangulate_dlt(
    uv,
    cameras: Sequence[CameraLike] | np.ndarray,
    weights=None,
    *,
    undistorted: bool | None = None,
    min_ray_angle_deg: float = 0.1,
) -> TriangulationResult:
    r"""Triangulate many joints from many views with the linear (DLT) method.

    Implements the homogeneous method of Hartley & Zisserman, *Multiple View Geometry*,
    2nd ed., section 12.2: each observation :math:`(u, v)` of camera :math:`P` gives
    the rows :math:`u\,p^{3T} - p^{1T}` and :math:`v\,p^{3T} - p^{2T}` of
    :math:`A X = 0`, solved by the smallest right singular vector of :math:`A`. The
    system is normalised first: image coordinates per camera by a Hartley similarity
    (section 4.4.4; centre and scale from the camera's principal point and focal length,
    see :func:`_conditioning_similarity`) and each normalised :math:`P` to unit Frobenius
    norm, so that cameras weigh alike. Weights multiply an observation's two rows (confidence-weighted
    DLT). All joints and batch elements are solved by one batched SVD.

    Args:
        uv: ``(..., C, J, 2)`` pixel observations of J joints in C cameras. Distorted
            pixels unless ``undistorted``. NaN/inf observations are ignored.
        cameras: C :class:`Camera` objects, or C ``(3, 4)`` projection matrices (a
            ``(C, 3, 4)`` array or a sequence; mixing is allowed). Matrices act on
            undistorted pixels.
        weights: optional ``(..., C, J)`` confidences (broadcastable), relative per joint.
            Observations with weight ``<= 0``, NaN or inf are ignored, and so are those
            whose weight over the joint's largest underflows to 0.
        undistorted: True: ``uv`` are ideal (undistorted) pixels for every camera.
            False: ``uv`` are distorted pixels; every camera must be a :class:`Camera`.
            None (default): distorted for :class:`Camera` entries, undistorted for matrices.
        min_ray_angle_deg: joints whose largest ray angle (the conditioning figure, see
            module docstring) is below this are marked invalid.

    Returns:
        A :class:`TriangulationResult` with ``points`` ``(..., J, 3)``,
        ``reprojection_error`` ``(..., J, C)`` and ``(..., J)`` ``ray_angle_deg``,
        ``num_views``, ``valid``. Invalid joints have ``points == 0``.

    Raises:
        ShapeError: ``uv``, ``weights`` or ``cameras`` have the wrong shape.
        GeometryError: a projection matrix is non-finite or singular, distorted pixels
            were requested for a projection matrix, or ``min_ray_angle_deg`` is not in [0, 90].

    Example:
        >>> import numpy as np
        >>> from ghnerf_runtime.geometry.camera import Camera
        >>> K = [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]
        >>> left = Camera("left", 640, 480, K, t=[0.1, 1.5, 0.0])    # centre (-0.1, -1.5, 0)
        >>> right = Camera("right", 640, 480, K, t=[-0.1, 1.5, 0.0])  # centre (0.1, -1.5, 0)
        >>> joints = np.array([[0.2, -1.2, 3.0], [-0.3, -0.5, 2.5]])  # (J, 3)
        >>> uv = np.stack([cam.project(joints)[0] for cam in (left, right)])  # (C, J, 2)
        >>> res = triangulate_dlt(uv, [left, right])
        >>> np.round(res.points, 9).tolist(), res.valid.tolist(), res.num_views.tolist()
        ([[0.2, -1.2, 3.0], [-0.3, -0.5, 2.5]], [True, True], [2, 2])
        >>> bool(res.reprojection_error.max() < 1e-9), np.round(res.ray_angle_deg, 2).tolist()
        (True, [3.78, 4.2])
    """
    _check_thresholds(min_ray_angle_deg)
    return _dlt(_prepare(uv, cameras, weights, undistorted), min_ray_angle_deg)


def _dlt(views: _Views, min_ray_angle_deg: float) -> TriangulationResult:
    with np.errstate(all="ignore"):
        points, finite = _dlt_solve(views)
        _, d = _rays(views)
        angle = _max_ray_angle(d, views.used)
    return _finish(views, points, finite, angle, min_ray_angle_deg)


def triangulate_midpoint(
    uv,
    cameras: Sequence[CameraLike] | np.ndarray,
    weights=None,
    *,
    undistorted: bool | None = None,
    min_ray_angle_deg: float = 0.1,
) -> TriangulationResult:
    r"""Triangulate as the point closest to the viewing rays (midpoint method).

    With two views this is the classic midpoint of the common perpendicular of the two
    rays (Hartley & Zisserman 12.2 discusses why it is not projectively invariant; in a
    calibrated metric rig it is a good, cheap estimate). With weights it is the weighted
    point on that perpendicular, and with more views the weighted least-squares point
    :math:`\arg\min_X \sum_i w_i\, d(X, \mathrm{ray}_i)^2`, found in closed form from
    :math:`\sum_i w_i (I - d_i d_i^T) X = \sum_i w_i (I - d_i d_i^T) o_i`, solved in a frame along the mean ray
    (:func:`_midpoint_system`): exact as the DLT for near-parallel rays (a far point, a short baseline).

    Unlike the DLT this minimises a distance in the rig frame (metres), not in the image,
    so the two agree exactly on noise-free data and closely on noisy data.

    Args, returns and raises: as :func:`triangulate_dlt`.

    Example:
        >>> import numpy as np
        >>> from ghnerf_runtime.geometry.camera import Camera
        >>> K = [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]
        >>> cams = [Camera("l", 640, 480, K, t=[0.1, 1.5, 0.0]), Camera("r", 640, 480, K, t=[-0.1, 1.5, 0.0])]
        >>> uv = np.stack([c.project([[0.2, -1.2, 3.0]])[0] for c in cams])  # (2, 1, 2)
        >>> np.round(triangulate_midpoint(uv, cams).points, 9).tolist()
        [[0.2, -1.2, 3.0]]
    """
    _check_thresholds(min_ray_angle_deg)
    views = _prepare(uv, cameras, weights, undistorted)
    with np.errstate(all="ignore"):
        centres, d = _rays(views)  # (C, 3), (N, C, J, 3)
        angle = _max_ray_angle(d, views.used)
        origin = centres.mean(axis=0)
        frame = _mean_ray_frame(d, views.w)  # (N, J, 3, 3)
        A, b = _midpoint_system(np.einsum("njab,ncjb->ncja", frame, d), views.w,
                                np.einsum("njab,cb->ncja", frame, centres - origin))
        # Rays that are (near-)parallel make A singular; those joints are marked invalid by
        # the angle test, so solve a harmless identity system for them instead.
        solvable = (views.used.sum(axis=1) >= 2) & (angle >= min_ray_angle_deg) & np.all(np.isfinite(A), axis=(-2, -1))
        # So do weights that leave one ray all the say (1 and 1e-300): np.linalg.solve raised LinAlgError on those.
        trace = np.trace(A, axis1=-2, axis2=-1)
        solvable &= np.abs(np.linalg.det(np.where(solvable[..., None, None], A, np.eye(3)))) > 1e-14 * trace**3
        A = np.where(solvable[..., None, None], A, np.eye(3))
        b = np.where(solvable[..., None], b, 0.0)
        points = origin + np.einsum("njab,njb->nja", frame, np.linalg.solve(A, b[..., None])[..., 0])
    return _finish(views, points, solvable, angle, min_ray_angle_deg)


def _mean_ray_frame(d: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``(N, J, 3, 3)`` reflections (symmetric, their own inverse) taking each joint's weighted mean ray line
    (rays turned to agree with its most weighted one) to the z axis. In that frame the near-parallel rays of a far
    point have small x and y, whose squares :func:`_midpoint_system` sums without cancellation."""
    ref = np.take_along_axis(d, np.argmax(w, axis=1)[:, None, :, None], axis=1)  # (N, 1, J, 3)
    agree = np.where(np.sum(d * ref, axis=-1) >= 0, w, -w)  # (N, C, J)
    m = np.sum(d * agree[..., None], axis=1)  # (N, J, 3)
    m /= np.linalg.norm(m, axis=-1, keepdims=True)
    # Householder u = m + sign(m_z) e_z: |u|^2 >= 2, never the cancelling m - e_z of a ray near the axis
    u = m + np.where(m[..., 2:] >= 0, 1.0, -1.0) * np.array([0.0, 0.0, 1.0])
    return np.eye(3) - 2.0 * u[..., :, None] * u[..., None, :] / np.sum(u * u, axis=-1)[..., None, None]


def _midpoint_system(d: np.ndarray, w: np.ndarray, o: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``A`` ``(N, J, 3, 3)`` and ``b`` ``(N, J, 3)`` of ``sum_i w_i Q_i X = sum_i w_i Q_i o_i``, rays ``d``
    ``(N, C, J, 3)`` from ``o``. ``Q = |d|^2 I - d d^T`` projects off the ray whatever float64 left of its unit
    length (``I - d d^T`` kept a ``1 - |d|^2`` of 1e-16 along it: 38 um at 50 m, 1 mm baseline), and its diagonal
    sums the other two squares rather than taking one from 1 (the cancellation of near-parallel rays)."""
    sq = d * d
    q = -d[..., :, None] * d[..., None, :]
    for k in range(3):
        q[..., k, k] = sq[..., (k + 1) % 3] + sq[..., (k + 2) % 3]
    wq = q * w[..., None, None]
    return wq.sum(axis=1), np.einsum("ncjab,ncjb->nja", wq, o)


def _select(mask: np.ndarray, new: TriangulationResult, old: TriangulationResult) -> TriangulationResult:
    """Per joint: ``new`` where ``mask`` ``(..., J)``, else ``old``."""
    def pick(a, b):
        m = mask.reshape(mask.shape + (1,) * (a.ndim - mask.ndim))
        return np.where(m, a, b)

    return TriangulationResult(
        points=pick(new.points, old.points),
        reprojection_error=pick(new.reprojection_error, old.reprojection_error),
        ray_angle_deg=pick(new.ray_angle_deg, old.ray_angle_deg),
        num_views=pick(new.num_views, old.num_views),
        valid=pick(new.valid, old.valid),
        used=pick(new.used, old.used),
    )


def triangulate_robust(
    uv,
    cameras: Sequence[CameraLike] | np.ndarray,
    weights=None,
    *,
    undistorted: bool | None = None,
    max_reprojection_error: float = 10.0,
    min_ray_angle_deg: float = 0.1,
) -> TriangulationResult:
    """DLT that checks reprojection and drops bad views while more than two remain.

    For every joint whose largest reprojection error over its used views exceeds
    ``max_reprojection_error``, each used view is left out in turn (leave-one-out DLT);
    the view whose removal gives the smallest remaining largest error is dropped, if that
    improves the joint. This repeats while the joint still exceeds the threshold and has
    more than two views. A joint the DLT found invalid with more than two views (a wrong view
    put it behind a camera or past a lens model's fold) is tried the same way, and kept if
    leaving a view out makes it valid. Joints that still exceed the threshold afterwards
    (including two-view joints, where the culprit cannot be told) are marked invalid.

    Dropped views show up as ``used == False`` with their reprojection error against the
    final point still reported.

    Args:
        uv, cameras, weights, undistorted, min_ray_angle_deg: as :func:`triangulate_dlt`.
        max_reprojection_error: threshold in pixels of the input image. It depends on the
            resolution the joints were detected at; 10 px suits heatmaps at 640x480.

    Returns:
        A :class:`TriangulationResult`, as :func:`triangulate_dlt`.

    Example:
        >>> import numpy as np
        >>> from ghnerf_runtime.geometry.camera import Camera, look_at
        >>> K = [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]
        >>> eyes = [(-1.0, -1.5, 0.0), (0.0, -1.6, 0.0), (1.0, -1.5, 0.0)]
        >>> cams = [Camera(f"c{i}", 640, 480, K, np.zeros(5), *look_at(e, (0.0, -1.0, 3.0))) for i, e in enumerate(eyes)]
        >>> uv = np.stack([c.project([[0.1, -1.0, 3.0]])[0] for c in cams])  # (3, 1, 2)
        >>> uv[1, 0] += 40.0  # a wrong detection in the middle camera
        >>> res = triangulate_robust(uv, cams, max_reprojection_error=2.0)
        >>> np.round(res.points, 6).tolist(), res.used.tolist()
        ([[0.1, -1.0, 3.0]], [[True, False, True]])
    """
    _check_thresholds(min_ray_angle_deg, max_reprojection_error)
    views = _prepare(uv, cameras, weights, undistorted)
    N, C, J = views.w.shape
    result = _dlt(views, min_ray_angle_deg)
    for _ in range(max(C - 2, 0)):
        # An invalid joint is a candidate too: a wrong view can put the point behind a camera or past
        # its lens model's fold, where no reprojection error exists to compare (inf: any valid trial is better).
        worst = np.where(result.valid, result.max_reprojection_error(), np.inf)
        bad = (worst > max_reprojection_error) & (result.num_views > 2)
        if not np.any(bad):
            break
        bad_flat = bad.reshape(N, J)
        best, best_err, best_c = result, worst, np.full(bad.shape, -1)
        for c in range(C):
            w = views.w.copy()
            w[:, c] = np.where(bad_flat, 0.0, w[:, c])
            trial = _dlt(replace(views, w=w, used=views.used & (w > 0)), min_ray_angle_deg)
            trial_err = trial.max_reprojection_error()
            better = bad & result.used[..., c] & trial.valid & (trial_err < best_err)
            best = _select(better, trial, best)
            best_err = np.where(better, trial_err, best_err)
            best_c = np.where(better, c, best_c)
        if not np.any(best_c >= 0):
            break
        best_c = best_c.reshape(N, J)
        new_w = views.w.copy()
        for c in range(C):
            new_w[:, c] = np.where(best_c == c, 0.0, new_w[:, c])
        views = replace(views, w=new_w, used=views.used & (new_w > 0))
        result = best
    # Whatever still disagrees beyond the threshold is not trustworthy.
    reject = result.valid & (result.max_reprojection_error() > max_reprojection_error)
    if np.any(reject):
        keep = ~reject
        result = TriangulationResult(
            points=np.where(keep[..., None], result.points, 0.0),
            reprojection_error=np.where(keep[..., None], result.reprojection_error, 0.0),
            ray_angle_deg=result.ray_angle_deg,
            num_views=result.num_views,
            valid=result.valid & keep,
            used=result.used,
        )
    return result


#: How :func:`_check_regular` names the two-view solver's matrices: the argument ``P``'s index, and the view.
_TWO_VIEW_NAMES = ("P[0] (view 0)", "P[1] (view 1)")


@dataclass(frozen=True, eq=False)
class TwoViewCameras:
    """What the two-view solver derives from its two ``(2, 3, 4)`` projection matrices alone (read-only arrays):
    the matrices ``P`` (a copy), their left blocks ``M`` and inverses, the conditioning
    similarities ``T``, the conditioned unit-norm matrices ``Pn``, whether the centres are distinct and each
    view's depth scale.

    Build them with :meth:`from_P` and pass them (``cameras=``) to :func:`solve_two_views` or
    :func:`triangulate_two_views` to skip recomputing them: the estimator keeps its crop cameras' terms for as
    long as the crop keeps its cameras (many pairs of a tracked subject). The answers are the same to the bit
    with them or without.
    """

    P: np.ndarray
    M: np.ndarray
    Minv: np.ndarray
    T: np.ndarray
    Pn: np.ndarray
    distinct: bool
    depth_scale: np.ndarray  # (2, 1): sign(det) / |m3|, a homogeneous third coordinate -> depth

    @classmethod
    def from_P(cls, P) -> "TwoViewCameras":
        """The terms of ``P`` (the operations :func:`triangulate_two_views` ran on every call before).

        Raises:
            ShapeError: ``P`` is not ``(2, 3, 4)``. GeometryError: a non-finite matrix or a singular left 3x3 block
            (:func:`_check_regular`, as the general solvers: the view and its matrix named).
        """
        P = np.array(P, dtype=np.float64)  # (a copy: the caller's array may change later; these terms may not)
        if P.shape != (2, 3, 4):
            raise ShapeError(f"P (2, 3, 4) expected for two views' terms, got {P.shape}")
        M = P[:, :, :3]  # (a view, as the solver always took it: the same memory layout, the same matmul results)
        T = _check_regular(P, _TWO_VIEW_NAMES)
        det = np.linalg.det(M)
        with np.errstate(all="ignore"):
            Pn = T @ P
            Pn /= np.sqrt(np.square(Pn).sum(axis=(1, 2)))[:, None, None]
            Minv = np.linalg.inv(M)
            distinct = bool(_distinct_centres(P, Minv)[0, 1])
            depth_scale = (np.sign(det) / np.sqrt(np.square(M[:, 2, :]).sum(axis=-1)))[:, None]
        read_only(P, M, Minv, T, Pn, depth_scale)
        return cls(P, M, Minv, T, Pn, distinct, depth_scale)

    def is_for(self, P) -> bool:
        """Whether these are the terms of the matrices ``P`` (the same values to the bit, whatever the array)."""
        return same_bits(self.P, P)


@dataclass(frozen=True, eq=False)
class TwoViewSolution:
    """One DLT solve of two views' peaks, before any threshold (read-only arrays): the camera terms and the
    inputs it solved (``uv`` ``(2, J, 2)``, ``weights`` ``(2, J)``, copies), the DLT points ``(J, 3)``, whether
    each is finite ``(J,)``, the ray angles ``(J,)`` (0 where a view is not used) and the views used ``(2, J)``.

    :func:`check_two_views` applies the thresholds to it: the estimator solves a pair's peaks once and checks
    the solve for the joints and again for the skeleton prior's inputs, which differ only in their ray-angle
    threshold (when their weights are the same: :meth:`solves` tells).
    """

    cameras: TwoViewCameras
    uv: np.ndarray
    weights: np.ndarray
    points: np.ndarray
    finite: np.ndarray
    ray_angle_deg: np.ndarray
    used: np.ndarray

    def solves(self, uv, P, weights) -> bool:
        """Whether this is the solve of ``uv``, ``P`` and ``weights`` (the same values to the bit)."""
        return same_bits(self.uv, uv) and same_bits(self.weights, weights) and self.cameras.is_for(P)


def _two_view_inputs(uv, P, weights) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``uv``, ``P`` and ``weights`` as float64 arrays of the two-view solver's shapes (else ShapeError)."""
    uv = np.asarray(uv, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    P = np.asarray(P, dtype=np.float64)
    if uv.ndim != 3 or uv.shape[0] != 2 or uv.shape[2] != 2 or w.shape != uv.shape[:2] or P.shape != (2, 3, 4):
        raise ShapeError(f"uv (2, J, 2), P (2, 3, 4) and weights (2, J) expected, got {uv.shape}, {P.shape}, "
                         f"{w.shape}")
    return uv, P, w


def solve_two_views(uv, P, weights, *, cameras: TwoViewCameras | None = None) -> TwoViewSolution:
    """The DLT of :func:`triangulate_two_views` before its thresholds and checks (:func:`check_two_views`).

    Args:
        uv, P, weights: as :func:`triangulate_two_views`.
        cameras: ``TwoViewCameras.from_P(P)`` computed earlier (computed here when not given).

    Raises:
        ShapeError: wrong shapes. GeometryError: a non-finite or singular matrix, or ``cameras`` of other
        matrices.
    """
    uv, P, w = _two_view_inputs(uv, P, weights)
    cams = terms_of(P, cameras, TwoViewCameras.from_P, "two-view camera terms")
    with np.errstate(all="ignore"):
        points, finite, angle, used = _solve_two_views(uv, w, cams)
    uv, w = uv.copy(), w.copy()  # (the caller's arrays may change later)
    read_only(uv, w, points, finite, angle, used)
    return TwoViewSolution(cams, uv, w, points, finite, angle, used)


def _solve_two_views(uv: np.ndarray, w: np.ndarray, cams: TwoViewCameras
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`solve_two_views`' points, finite, ray angles and views used. Call under ``np.errstate(all="ignore")``."""
    T, Pn, Minv = cams.T, cams.Pn, cams.Minv
    J = uv.shape[1]
    used = np.isfinite(uv).all(axis=-1) & np.isfinite(w) & (w > 0)  # (2, J)
    w, used = _relative_weights(np.where(used, w, 0.0), used, axis=0)  # as _prepare
    x = np.where(used[..., None], uv, 0.0)
    # DLT rows of H&Z 12.2 on conditioned pixels and unit-norm matrices (as _dlt_solve).
    xn = x * T[:, 0, 0, None, None] + T[:, None, :2, 2]
    rows = xn[..., :, None] * Pn[:, None, None, 2, :] - Pn[:, None, :2, :]  # (2, J, 2, 4)
    top = w.max(axis=0)  # each joint's weights over their largest, as _dlt_solve
    A = (rows * np.where(top > 0, w / np.where(top > 0, top, 1.0), 0.0)[..., None, None]).transpose(
        1, 0, 2, 3).reshape(J, 4, 4)
    solvable = np.isfinite(A).all(axis=(-2, -1))  # (LAPACK's SVD can loop forever on an inf)
    A = np.where(solvable[:, None, None], A, 0.0)
    X = np.linalg.svd(A)[2][:, -1, :]
    finite = solvable & (np.abs(X[:, 3]) > 1e-12 * np.sqrt(np.square(X[:, :3]).sum(axis=-1)))
    points = X[:, :3] / np.where(finite, X[:, 3], 1.0)[:, None]

    # Ray angle (the conditioning figure) between the two viewing rays' lines: atan2(|a x b|, |a . b|)
    # of unit directions (unit, so that absurd pixels overflow to 0 degrees as in _rays).
    d = (x @ Minv[:, :, :2].transpose(0, 2, 1)) + Minv[:, None, :, 2]  # (2, J, 3)
    d /= np.sqrt(np.square(d).sum(axis=-1, keepdims=True))
    a, b = d[0], d[1]
    cross = np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                      a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=-1)
    angle = np.degrees(np.arctan2(np.sqrt(np.square(cross).sum(axis=-1)), np.abs((a * b).sum(axis=-1))))
    both = used[0] & used[1]
    angle = np.where(both & np.isfinite(angle), angle, 0.0)
    return points, finite, angle, used


def check_two_views(solution: TwoViewSolution, *, max_reprojection_error: float | None = None,
                    min_ray_angle_deg: float = 0.1) -> TriangulationResult:
    """:func:`triangulate_two_views`' answer from its solve (thresholds as there); the result's arrays are its
    own (writable), whatever the solve shares with other checks.

    Raises:
        GeometryError: a threshold that is not a number in range.
    """
    _check_thresholds(min_ray_angle_deg, max_reprojection_error)
    cams, uv, used = solution.cameras, solution.uv, solution.used
    points, angle = solution.points, solution.ray_angle_deg
    P, M = cams.P, cams.M
    with np.errstate(all="ignore"):
        both = used[0] & used[1]
        # as _finish: rays on one line to rounding, or from one centre, give no depth (valid with an angle of 0)
        ok = (solution.finite & np.isfinite(points).all(axis=-1) & both & (angle >= min_ray_angle_deg)
              & (angle >= MIN_RAY_ANGLE_FLOOR_DEG) & cams.distinct)
        safe = np.where(ok[:, None], points, 0.0)
        ph = safe @ M.transpose(0, 2, 1) + P[:, None, :, 3]  # (2, J, 3)
        depth = ph[..., 2] * cams.depth_scale
        ahead = depth > MIN_DEPTH
        ok &= ~np.any(used & ~ahead, axis=0)
        err = np.sqrt(np.square(ph[..., :2] / ph[..., 2:3] - uv).sum(axis=-1))
        err = np.where(ahead, err, np.nan)
        ok &= ~np.any(used & ~np.isfinite(err), axis=0)
        if max_reprojection_error is not None:
            ok &= ~np.any(used & (err > max_reprojection_error), axis=0)
        err = np.where(np.isfinite(err) & ok[None], err, 0.0)
    return TriangulationResult(
        points=np.where(ok[:, None], points, 0.0),
        reprojection_error=err.T,
        ray_angle_deg=angle.copy(),
        num_views=used.sum(axis=0).astype(np.int64),
        valid=ok,
        used=used.copy().T,
    )


def triangulate_two_views(uv, P, weights, *, max_reprojection_error: float | None = None,
                          min_ray_angle_deg: float = 0.1, cameras: TwoViewCameras | None = None,
                          solution: TwoViewSolution | None = None) -> TriangulationResult:
    """:func:`triangulate_dlt` (and the final check of :func:`triangulate_robust`) for the common
    case of two pinhole views and one frame, in about a third of the numpy calls.

    The estimator triangulates 25 joints in two crop cameras every pair, where the general
    functions' batch and camera-count handling costs more than the arithmetic. The system,
    its conditioning, the validity rules and the fill values are the same, so the results
    equal :func:`triangulate_dlt`'s (``tests/ghnerf_runtime/test_triangulation.py`` checks it).
    It is :func:`check_two_views` of :func:`solve_two_views`.

    Args:
        uv: ``(2, J, 2)`` undistorted pixels of each view.
        P: ``(2, 3, 4)`` projection matrices (pinhole: they act on undistorted pixels).
        weights: ``(2, J)`` confidences; ``<= 0`` or non-finite ignores the observation.
        max_reprojection_error: if given, a joint whose error exceeds it in a used view is
            invalid (with two views the culprit cannot be told).
        min_ray_angle_deg: as :func:`triangulate_dlt`.
        cameras: ``TwoViewCameras.from_P(P)`` computed earlier (computed here when not given).
        solution: an earlier :func:`solve_two_views`, used where it :meth:`~TwoViewSolution.solves` these
            ``uv``, ``P`` and ``weights`` (solved here otherwise). The answer is the same with or without either.

    Raises:
        ShapeError: wrong shapes. GeometryError: a non-finite or singular matrix, ``cameras`` of other
        matrices, or a threshold that is not a number in range.
    """
    _check_thresholds(min_ray_angle_deg, max_reprojection_error)  # (before the solve, as it always was)
    if solution is None or not solution.solves(uv, P, weights):
        solution = solve_two_views(uv, P, weights, cameras=cameras)
    return check_two_views(solution, max_reprojection_error=max_reprojection_error,
                           min_ray_angle_deg=min_ray_angle_deg)
