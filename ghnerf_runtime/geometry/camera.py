"""Pinhole camera with OpenCV lens distortion: projection, undistortion, rays.

Conventions (documented in docs/rig-file.md):

* Rig frame: metres, right-handed, x to the right of the rig, y down (gravity),
  z forward (horizontal, towards the subject), origin on the floor below the
  midpoint of the camera centres. A standing person has negative y.
* Extrinsics map rig (world) points into the camera: ``X_cam = R @ X + t``.
* Camera frame: OpenCV (x right, y down, z along the optical axis).
* Distortion: OpenCV's rational + thin-prism model with 4, 5, 8, 12 or 14
  coefficients ``k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tx ty]]]]``. The tilt
  terms (tx, ty) must be zero: no supported sensor uses them.

Pure numpy, arrays in and arrays out, batch dimensions first, shapes checked
on entry.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from ghnerf_runtime.errors import GeometryError, ShapeError
from ghnerf_runtime.plain_values import whole_valued_or_none

#: Distortion coefficient counts OpenCV's models take (and :class:`Camera` accepts).
DIST_LENGTHS = (0, 4, 5, 8, 12, 14)
#: Names of OpenCV's distortion coefficients, in their order (messages name the coefficient at fault).
DISTORTION_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4", "tx", "ty")


def check_last_dim(name: str, array: np.ndarray, size: int) -> np.ndarray:
    """Return ``array`` as float64, raising :class:`ShapeError` unless its last axis is ``size``."""
    array = np.asarray(array, dtype=np.float64)
    if array.ndim < 1 or array.shape[-1] != size:
        raise ShapeError(f"{name} must have shape (..., {size}), got {array.shape}")
    return array


def _as_dist(coefficients) -> np.ndarray:
    dist = np.asarray(coefficients, dtype=np.float64).reshape(-1)
    if dist.size not in DIST_LENGTHS:
        raise GeometryError(f"dist must have 0, 4, 5, 8, 12 or 14 coefficients, got {dist.size}")
    if dist.size == 14 and np.any(dist[12:] != 0.0):
        raise GeometryError(f"dist tilt terms tx, ty must be 0, got {dist[12:].tolist()}")
    full = np.zeros(12)
    full[: min(dist.size, 12)] = dist[:12]
    return full


#: Largest width or height a :class:`Camera` takes: OpenCV's image sizes are C ints. A model's camera may be larger
#: than a rig file holds (``rig_file.MAX_IMAGE_SIDE``: an imported calibration is refused when saved, by name); this
#: bound keeps absurd sizes (10**400, which ``int`` takes) out of the float arithmetic.
MAX_CAMERA_SIDE = 2**31 - 1


def _image_side(value) -> bool:
    """Whether ``value`` is a whole number of pixels in [1, :data:`MAX_CAMERA_SIDE`] (``640``, ``640.0``,
    ``np.int64(640)``; not ``True``, ``np.True_``, ``"640"`` or ``10**400``): 640.0 is taken, as a size read from a
    file or scaled in floating point."""
    whole = whole_valued_or_none(value)
    return whole is not None and 1 <= whole <= MAX_CAMERA_SIDE


def image_rotation(degrees: float) -> np.ndarray:
    """``(2, 2)``: pixel offsets (x right, y down) turned ``degrees`` counterclockwise on the screen.

    Raises:
        GeometryError: ``degrees`` is not finite (NaN made a NaN crop camera, inf a bare math domain error).
    """
    if not math.isfinite(degrees):
        raise GeometryError(f"rotation degrees must be finite, got {degrees!r}")
    a = math.radians(degrees)
    return np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])


def _distorted_radius(dist: np.ndarray, r):
    """``r * radial(r)``: where the radial lens model puts a point ``r`` from the axis (normalised)."""
    k1, k2, _, _, k3, k4, k5, k6 = _as_dist(dist)[:8]
    r2 = r * r
    return r * (1 + k1 * r2 + k2 * r2**2 + k3 * r2**3) / (1 + k4 * r2 + k5 * r2**2 + k6 * r2**3)


#: Residual (normalised) below which an undistorted point is taken as it is; one between this and the
#: ``tolerance`` of :meth:`Camera.undistort_normalized` (1e-6) is solved again by Newton steps. 1e-9 is a
#: ten-thousandth of a pixel at a focal length of 1e5 px.
UNDISTORT_POLISH = 1e-9

#: Normalised radius the lens model is checked (:func:`fold_radius`) and inverted out to: 89.9999 degrees off
#: the axis. Real lenses stay far inside it (a 120-degree lens reaches about 1.7, a fisheye-like fit about 10).
LENS_REACH = 10.0 * 4**8


@functools.lru_cache(maxsize=64)
def fold_radius(coefficients: tuple[float, ...], r_max: float = LENS_REACH) -> float:
    """Normalised radius where the radial lens model stops growing (``inf``: not within ``r_max``).

    Past it, ``r * radial(r)`` falls again, so those points land on pixels nearer the centre
    that other points already map to: the model is only valid inside this radius. Wide lenses
    fitted with a few polynomial terms often fold inside the image corners; weak terms fold far
    out (``k1 = -0.002``: at 12.9), which matters for points projected from wide angles.
    """
    # steps of 0.0005 to 10 (84 degrees), where real lenses live; steps of 0.05 % beyond (42k in all, 3 ms)
    r = np.linspace(0.0, min(r_max, 10.0), 20001)
    if r_max > 10.0:
        far = np.geomspace(10.0, r_max, int(math.ceil(math.log(r_max / 10.0) / math.log1p(5e-4))) + 1)
        r = np.concatenate([r, far[1:]])
    with np.errstate(all="ignore"):
        rd = _distorted_radius(np.asarray(coefficients), r)
    falling = ~(np.diff(rd) > 0)
    return float(r[int(np.argmax(falling))]) if falling.any() else math.inf


def lens_jacobian_det(coefficients, xy: np.ndarray) -> np.ndarray:
    """``(...)`` determinant of the lens model's Jacobian (d distorted / d undistorted) at normalised points
    ``(..., 2)``: positive where :meth:`Camera.distort` keeps the orientation of a small patch, 0 on a fold."""
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = _as_dist(coefficients)[:12]
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    g = num / den
    dg = ((k1 + r2 * (2 * k2 + 3 * k3 * r2)) * den - num * (k4 + r2 * (2 * k5 + 3 * k6 * r2))) / (den * den)  # dg/dr2
    prism_x, prism_y = s1 + 2 * s2 * r2, s3 + 2 * s4 * r2  # d(s r2 + s' r2^2)/dr2
    shared = 2 * x * y * dg + 2 * p1 * x + 2 * p2 * y
    dxd_dx = g + 2 * x * x * dg + 2 * p1 * y + 6 * p2 * x + 2 * x * prism_x
    dxd_dy = shared + 2 * y * prism_x
    dyd_dx = shared + 2 * x * prism_y
    dyd_dy = g + 2 * y * y * dg + 6 * p1 * y + 2 * p2 * x + 2 * y * prism_y
    return dxd_dx * dyd_dy - dxd_dy * dyd_dx


#: Directions :func:`unfolded_radius` samples the lens model along (every 2.8 degrees).
UNFOLD_DIRECTIONS = 128


@functools.lru_cache(maxsize=64)
def unfolded_radius(coefficients: tuple[float, ...], r_max: float) -> float:
    """Normalised radius of the nearest point (within ``r_max``) where the whole lens model folds over: its
    Jacobian's determinant (:func:`lens_jacobian_det`) is not positive; ``inf`` where none is.

    :func:`fold_radius` finds where the radial part stops growing, which is the whole model's fold only without
    tangential (p1, p2) or thin-prism (s1..s4) terms. Strong ones fold the model nearer the centre, in some
    directions only: from p1 = 0.3 (90-degree lens) pixels there are reached from two points, and undistortion
    returned the one on the unfolded side while projection sent the other, on the folded side, to the same pixel
    (a ray off by tens of degrees). Real lenses' terms (about 1e-3) fold it only far outside any image.
    Sampled on 4000 circles out to ``r_max`` or 10 (steps of 0.0025 at most), 1 % apart beyond, along
    :data:`UNFOLD_DIRECTIONS` directions.
    """
    r = np.linspace(0.0, min(r_max, 10.0), 4001)[1:]
    if r_max > 10.0:
        r = np.concatenate([r, np.geomspace(10.0, r_max, int(math.ceil(math.log(r_max / 10.0) / math.log(1.01))) + 1)[1:]])
    angle = np.linspace(0.0, 2 * math.pi, UNFOLD_DIRECTIONS, endpoint=False)
    unit = np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    dist = np.asarray(coefficients)
    for start in range(0, len(r), 1024):  # nearest circles first: most models fold near or not at all
        rings = r[start:start + 1024]
        with np.errstate(all="ignore"):
            det = lens_jacobian_det(dist, rings[:, None, None] * unit[None])
        folded = ~(det > 0).all(axis=-1)
        if folded.any():
            return float(rings[int(np.argmax(folded))])
    return math.inf


def fold_terms_text(terms: tuple[tuple[str, float], ...]) -> str:
    """:meth:`Camera.fold_terms` as a message says them: ``p1 = 0.3, p2 = 0.0001; a real lens's are about 0.001``."""
    named = ", ".join(f"{name} = {value:g}" for name, value in terms)
    return f"{named}; a real lens's are about 0.001"


def folded_by_tangential(terms: tuple[tuple[str, float], ...]) -> bool:
    """Whether p1 or p2 are among :meth:`Camera.fold_terms`: a calibration can hold them at 0 (``ghcal solve
    --no-tangential``); the thin-prism terms no ghcal lens model fits have no such remedy."""
    return any(name in ("p1", "p2") for name, _ in terms)


#: Distortion coefficients (indices into the 14) that make the lens model other than radial.
_ASYMMETRIC_TERMS = (2, 3, 8, 9, 10, 11)

#: Points :meth:`Camera.fold_inside_image` traces the rim of the lens model's reach with (every 0.09 degrees).
REACH_RIM_POINTS = 4096


def _segments_meet_box(start: np.ndarray, end: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Whether any segment ``start[i] -> end[i]`` (``(N, 2)`` each) touches the box ``[lo, hi]`` (clipped
    against its two slabs: the segment's parameter range inside both is not empty)."""
    step = end - start
    moving = step != 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        t_lo, t_hi = (lo - start) / step, (hi - start) / step
    within = (start >= lo) & (start <= hi)  # a segment parallel to a slab: inside it throughout, or never
    enter = np.where(moving, np.minimum(t_lo, t_hi), np.where(within, -np.inf, np.inf))
    leave = np.where(moving, np.maximum(t_lo, t_hi), np.where(within, np.inf, -np.inf))
    first, last = np.maximum(enter.max(axis=-1), 0.0), np.minimum(leave.min(axis=-1), 1.0)
    return bool(np.any(first <= last))


def _winding_number(polygon: np.ndarray, point: np.ndarray) -> int:
    """How many times the closed polygon ``(N, 2)`` winds around ``point`` (which it must not pass through), in
    the sense its angle (``arctan2``) grows: each straight edge turns by less than half a turn."""
    offset = polygon - point
    angle = np.arctan2(offset[:, 1], offset[:, 0])
    turn = np.diff(np.append(angle, angle[0]))
    turn = (turn + math.pi) % (2 * math.pi) - math.pi
    return int(round(float(turn.sum()) / (2 * math.pi)))


@dataclass(frozen=True, eq=False)
class Camera:
    """One calibrated camera of the rig.

    Attributes:
        name: unique name within the rig (``"left"``, ``"cam0"``...).
        width, height: image size in pixels.
        K: 3x3 intrinsic matrix (pixels).
        dist: OpenCV distortion coefficients (0, 4, 5, 8, 12 or 14 values).
        R: 3x3 rotation, rig -> camera.
        t: 3-vector translation, rig -> camera, metres.
    """

    name: str
    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        where = f"camera {self.name!r}"
        if not isinstance(self.name, str) or not self.name:
            raise GeometryError(f"camera name must be a non-empty string, got {self.name!r}")
        if not all(_image_side(v) for v in (self.width, self.height)):  # int() cut 640.7 to 640, failed on NaN
            raise GeometryError(f"{where}: image size must be whole pixels in [1, {MAX_CAMERA_SIDE}], "
                                f"got {self.width!r}x{self.height!r}")
        K = np.asarray(self.K, dtype=np.float64)
        R = np.asarray(self.R, dtype=np.float64)
        t = np.asarray(self.t, dtype=np.float64).reshape(-1)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise GeometryError(f"{where}: K must be a finite 3x3 matrix, got {K.tolist()}")
        if not (K[0, 0] > 0 and K[1, 1] > 0) or K[2, 2] != 1.0 or np.any(K[2, :2] != 0) or K[1, 0] != 0:
            raise GeometryError(
                f"{where}: K must be upper-triangular with fx, fy > 0 and K[2,2] == 1 (singular or "
                f"non-pinhole K), got {K.tolist()}"
            )
        if R.shape != (3, 3) or not np.all(np.isfinite(R)):
            raise GeometryError(f"{where}: R must be a finite 3x3 matrix, got shape {R.shape}")
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise GeometryError(f"{where}: R must be a proper rotation (orthonormal, det +1)")
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise GeometryError(f"{where}: t must be a finite 3-vector, got {t.tolist()}")
        dist = np.asarray(self.dist, dtype=np.float64).reshape(-1)
        try:
            _as_dist(dist)
        except GeometryError as e:
            raise GeometryError(f"{where}: {e}") from None
        if not np.all(np.isfinite(dist)):
            raise GeometryError(f"{where}: dist must be finite, got {dist.tolist()}")
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        for name, value in (("K", K), ("R", R), ("t", t), ("dist", dist)):
            value = value.copy()
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    # ------------------------------------------------------------------ derived
    @property
    def center(self) -> np.ndarray:
        """Camera centre in the rig frame (metres)."""
        return -self.R.T @ self.t

    @property
    def P(self) -> np.ndarray:
        """3x4 projection matrix ``K [R | t]`` for *undistorted* pixel coordinates."""
        return self.K @ np.hstack([self.R, self.t[:, None]])

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.dist != 0.0))

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.width, self.height

    # --------------------------------------------------------------- transforms
    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """Rig-frame points ``(..., 3)`` to camera-frame points ``(..., 3)``."""
        points = check_last_dim("points", points, 3)
        return points @ self.R.T + self.t

    def distort(self, xy: np.ndarray) -> np.ndarray:
        """Apply the lens model to normalised coordinates ``(..., 2)``."""
        xy = check_last_dim("xy", xy, 2)
        k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = _as_dist(self.dist)
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        r4, r6 = r2 * r2, r2 * r2 * r2
        radial = (1 + k1 * r2 + k2 * r4 + k3 * r6) / (1 + k4 * r2 + k5 * r4 + k6 * r6)
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + s1 * r2 + s2 * r4
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y + s3 * r2 + s4 * r4
        return np.stack([xd, yd], axis=-1)

    def undistort_normalized(
        self, xy_distorted: np.ndarray, iterations: int = 100, tolerance: float = 1e-6
    ) -> np.ndarray:
        """Invert :meth:`distort` by residual iteration (as ``cv2.undistortPoints`` does, checked).

        Points the lens model cannot reach come back NaN: a wide lens fitted with a few
        polynomial terms folds over (its distorted radius stops growing, :attr:`fold_radius`)
        before the image corners, so no undistorted point maps to them; so do points where
        neither the iteration nor Newton steps after it reached ``tolerance`` (normalised
        units: a thousandth of a pixel at a focal length of 1000 px) or that reached a root
        past the fold. ``cv2.undistortPoints`` returns finite, wrong coordinates there
        instead. Points the iteration left between :data:`UNDISTORT_POLISH` and
        ``tolerance`` are solved again, so the points returned agree with the lens model to
        ``UNDISTORT_POLISH`` wherever Newton steps reach it, at any focal length.
        """
        xy_d = check_last_dim("xy_distorted", xy_distorted, 2)
        if not self.has_distortion:
            return xy_d.copy()
        xy = xy_d.copy()
        limit2 = 4 * self.fold_radius**2  # a point this far out has run away: stop waiting for it
        with np.errstate(all="ignore"):  # runaway points overflow; they are flagged below
            for _ in range(iterations):
                # Residual form converges for the moderate distortion of real lenses
                # and, unlike a pure fixed point, corrects the tangential terms too.
                step = self.distort(xy) - xy_d
                xy = xy - step
                settled = np.all(np.abs(step) < 1e-10, axis=-1) | ~(np.sum(xy * xy, axis=-1) < limit2)
                if np.all(settled):  # most calls need few steps
                    break

            def residual(xy: np.ndarray, xy_d: np.ndarray = xy_d) -> np.ndarray:
                return np.max(np.abs(self.distort(xy) - xy_d), axis=-1)

            left = residual(xy)
            bad = ~(left <= tolerance) | ~self.within_lens(xy)
            # The residual step overshoots where the lens model's slope passes 2 (strong pincushion,
            # mixed signs) and diverges on points it can reach: solve those again. So are points it
            # left converging slowly, short of its own 1e-10 steps: within ``tolerance`` they were
            # kept as they were, up to 1e-6 off (0.1 px with a focal length of 1e5 px). Points well
            # past what the fold reaches stay out (a folding wide lens has many, every frame).
            retry = bad | ~(left <= UNDISTORT_POLISH)
            if math.isfinite(self.fold_radius):
                reach = _distorted_radius(self.dist, self.fold_radius)
                retry &= np.hypot(xy_d[..., 0], xy_d[..., 1]) < 1.05 * reach
            if np.any(retry):
                again = self._undistort_newton(xy_d[retry])
                before = left[retry]
                better = self.within_lens(again) & ((residual(again, xy_d[retry]) < before) | ~np.isfinite(before))
                kept = xy[retry]
                kept[better] = again[better]
                xy[retry] = kept
                bad = ~(residual(xy) <= tolerance) | ~self.within_lens(xy)
        if np.any(bad):
            xy[bad] = np.nan
        return xy

    def _undistort_newton(self, xy_d: np.ndarray, iterations: int = 30) -> np.ndarray:
        """Points ``(N, 2)`` the residual iteration missed: the radial model inverted by bisection
        inside the fold, then Newton steps on the whole model (tangential and prism terms too)."""
        dist = self.dist
        rd = np.hypot(xy_d[:, 0], xy_d[:, 1])
        # inside the fold r * radial(r) grows: bisection holds; past it a root would be a mirrored point
        folds = math.isfinite(self.fold_radius)
        hi = np.full(rd.shape, self.fold_radius if folds else 10.0)
        for _ in range(8):  # a model that never folds: widen the bracket until it holds the point
            short = _distorted_radius(dist, hi) < rd
            if not short.any() or folds:
                break
            hi[short] = np.minimum(4 * hi[short], LENS_REACH)  # no further than fold_radius checked
        lo = np.zeros_like(rd)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            below = _distorted_radius(dist, mid) < rd
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        scale = np.divide(0.5 * (lo + hi), rd, out=np.ones_like(rd), where=rd > 0)
        xy = xy_d * scale[:, None]
        h = 1e-7
        for _ in range(iterations):
            f = self.distort(xy) - xy_d
            jx = (self.distort(xy + [h, 0.0]) - self.distort(xy - [h, 0.0])) / (2 * h)
            jy = (self.distort(xy + [0.0, h]) - self.distort(xy - [0.0, h])) / (2 * h)
            det = jx[:, 0] * jy[:, 1] - jy[:, 0] * jx[:, 1]
            safe = np.where(np.abs(det) > 1e-12, det, np.nan)
            step = np.stack([jy[:, 1] * f[:, 0] - jy[:, 0] * f[:, 1],
                             -jx[:, 1] * f[:, 0] + jx[:, 0] * f[:, 1]], axis=-1) / safe[:, None]
            xy = xy - step
            if np.all(~(np.abs(step) >= 1e-12)):
                break
        return xy

    def fold_inside_image(self) -> bool:
        """Whether some pixel of the image is not reached exactly once from inside the lens model's unfolded
        disc (:attr:`lens_limit`, where it folds: radially, or nearer by its tangential or thin-prism terms).

        Such a pixel is beyond the fold's reach (undistortion has no solution there: NaN, outside the image) or
        reached twice (ambiguous). The disc's rim, traced through the lens (:data:`REACH_RIM_POINTS` points),
        bounds what it reaches; each pixel is reached as many times as the rim winds around it (the model keeps
        orientation inside the disc). So every pixel is reached once exactly when the rim stays off the image
        (the box out to its pixels' outer edges) and winds once around its centre. With radial terms only the
        rim is a circle and this is the old test: the farthest corner beyond the fold's distorted radius. With
        asymmetric terms it is not a circle, and the nearest fold need not be seen in the image at all.
        A model that does not fold within :data:`LENS_REACH` reaches every pixel once."""
        limit = self.lens_limit
        if not limit < LENS_REACH:
            return False
        angle = np.linspace(0.0, 2 * math.pi, REACH_RIM_POINTS, endpoint=False)
        with np.errstate(all="ignore"):
            rim = self.normalized_to_pixels(limit * np.stack([np.cos(angle), np.sin(angle)], axis=-1))
        if not np.all(np.isfinite(rim)):  # a rational model's pole on the rim: its reach cannot be traced
            return True
        lo, hi = np.array([-0.5, -0.5]), np.array([self.width - 0.5, self.height - 0.5])
        if _segments_meet_box(rim, np.roll(rim, -1, axis=0), lo, hi):
            return True
        return _winding_number(rim, 0.5 * (lo + hi)) != 1

    def fold_terms(self) -> tuple[tuple[str, float], ...]:
        """The tangential and thin-prism coefficients ``(name, value)``, largest first, when they are why the
        lens model folds inside the image (:meth:`fold_inside_image`, while its radial terms alone would not
        fold there); ``()`` otherwise. Real lenses' are about 1e-3: ones that fold the model inside its own
        image are a calibration that went wrong, which a message should name."""
        dist = _as_dist(self.dist)
        terms = [(DISTORTION_NAMES[i], float(dist[i])) for i in _ASYMMETRIC_TERMS if dist[i] != 0.0]
        if not terms or not self.fold_inside_image():
            return ()
        radial = dist.copy()
        radial[list(_ASYMMETRIC_TERMS)] = 0.0
        if self._derived(dist=radial).fold_inside_image():
            return ()
        return tuple(sorted(terms, key=lambda term: -abs(term[1])))

    def within_lens(self, xy: np.ndarray) -> np.ndarray:
        """``(...)`` bool: normalised coordinates ``(..., 2)`` inside :attr:`lens_limit` (:attr:`fold_radius`), where
        :meth:`distort` is one to one. Past it the model mirrors a point to a pixel that shows
        another direction (its radial factor turns negative), so no pixel of the frame shows it.
        A lens model that does not fold is checked out to :data:`LENS_REACH` only: beyond it
        (within 0.0001 degrees of the camera plane) points count as outside too. Tangential or
        thin-prism terms that fold the model nearer (:func:`unfolded_radius`) bring the limit in to there."""
        xy = check_last_dim("xy", xy, 2)
        with np.errstate(over="ignore", invalid="ignore"):  # NaN, inf and overflowing points are outside
            return np.sum(xy * xy, axis=-1) < self.lens_limit ** 2

    @property
    def lens_limit(self) -> float:
        """The normalised radius the lens model is trusted to (:meth:`within_lens`, :meth:`project`, undistortion,
        the crop warp's mask): its radial fold, or nearer where tangential or thin-prism terms fold it
        (:func:`unfolded_radius`); :data:`LENS_REACH` for a model that does not fold that far; ``inf`` without
        distortion."""
        if not self.has_distortion:
            return math.inf
        fold = self.fold_radius
        limit = fold if math.isfinite(fold) else LENS_REACH
        if np.any(_as_dist(self.dist)[list(_ASYMMETRIC_TERMS)] != 0.0):  # (radial only: positive inside its fold)
            limit = min(limit, unfolded_radius(tuple(self.dist.tolist()), limit))
        return limit

    @property
    def fold_radius(self) -> float:
        """Normalised radius the lens model is valid within (:func:`fold_radius`; ``inf`` without distortion)."""
        return fold_radius(tuple(self.dist.tolist())) if self.has_distortion else math.inf

    def pixels_to_normalized(self, uv: np.ndarray) -> np.ndarray:
        """Distorted pixel coordinates ``(..., 2)`` -> undistorted normalised coordinates.

        A pixel with a NaN or infinite coordinate, or one whose normalised coordinates overflow float64, gives
        ``(NaN, NaN)``, as one the lens model cannot reach does (:meth:`undistort_normalized`): a pinhole camera
        returned ``inf`` (or NaN, with a numpy warning, for an infinite pixel times a skew of 0)."""
        uv = check_last_dim("uv", uv, 2)
        fx, fy, cx, cy, skew = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2], self.K[0, 1]
        with np.errstate(all="ignore"):  # non-finite results are flagged below
            y = (uv[..., 1] - cy) / fy
            x = (uv[..., 0] - cx - skew * y) / fx
            xy = np.stack([x, y], axis=-1)
        lost = ~np.isfinite(xy).all(axis=-1)
        if lost.any():
            xy[lost] = np.nan
        return self.undistort_normalized(xy)

    def normalized_to_pixels(self, xy: np.ndarray, distort: bool = True) -> np.ndarray:
        """Normalised coordinates ``(..., 2)`` -> pixel coordinates, optionally through the lens."""
        xy = check_last_dim("xy", xy, 2)
        if distort and self.has_distortion:
            xy = self.distort(xy)
        u = self.K[0, 0] * xy[..., 0] + self.K[0, 1] * xy[..., 1] + self.K[0, 2]
        v = self.K[1, 1] * xy[..., 1] + self.K[1, 2]
        return np.stack([u, v], axis=-1)

    def undistort_pixels(self, uv: np.ndarray) -> np.ndarray:
        """Distorted pixels -> the pixels an ideal (distortion-free) camera with the same K sees."""
        return self.normalized_to_pixels(self.pixels_to_normalized(uv), distort=False)

    def project(self, points: np.ndarray, distort: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Project rig-frame points.

        Args:
            points: ``(..., 3)`` rig-frame points, metres.
            distort: apply the lens model (``False`` gives ideal pinhole pixels).

        Returns:
            ``uv`` ``(..., 2)`` pixels and ``depth`` ``(...)`` (camera z, metres). ``uv`` is NaN
            for every point no pixel shows, so callers need one test (``np.isfinite``):

            * at or behind the camera plane (depth <= 1e-9; the depth is returned as is);
            * with ``distort``, past the lens model's fold (:meth:`within_lens`): the polynomial
              would mirror it onto a pixel nearer the centre that shows another direction;
            * NaN or inf coordinates, or a pixel too large for float64: never ``inf``.

            Every other point gets a finite pixel (it may lie outside the image).

        Example:
            >>> cam = Camera("c", 640, 480, [[500, 0, 320], [0, 500, 240], [0, 0, 1]])
            >>> uv, z = cam.project([0.0, 0.0, 2.0])
            >>> uv.tolist(), float(z)
            ([320.0, 240.0], 2.0)
        """
        with np.errstate(over="ignore", invalid="ignore"):  # huge or NaN points: flagged below
            pc = self.to_camera(points)
            z = pc[..., 2]
            seen = z > 1e-9
            xy = pc[..., :2] / np.where(seen, z, 1.0)[..., None]
            if distort and self.has_distortion:
                seen &= np.sum(xy * xy, axis=-1) < self.lens_limit ** 2  # within_lens; False for NaN, inf
            everywhere = bool(seen.all())
            if not everywhere:  # flagged points go through the lens model at the axis: no overflow from them
                xy = np.where(seen[..., None], xy, 0.0)
            uv = self.normalized_to_pixels(xy, distort=distort)
            finite = np.isfinite(uv)  # not: inf coordinates, or a pixel past float64's range
            if not finite.all():
                seen &= np.all(finite, axis=-1)
                everywhere = False
        return (uv if everywhere else np.where(seen[..., None], uv, np.nan)), z

    def rays(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rays through distorted pixel coordinates ``(..., 2)``.

        Returns ``origins`` ``(..., 3)`` (the camera centre) and unit ``directions`` ``(..., 3)``,
        both in the rig frame. The direction is NaN where :meth:`pixels_to_normalized` is (a non-finite pixel, or
        one the lens model cannot reach); a pixel far off the image (1e300 px) has its direction, nearly square
        to the optical axis (its length overflowed: NaN, with numpy warnings).
        """
        xy = self.pixels_to_normalized(uv)
        d_cam = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
        with np.errstate(invalid="ignore"):  # NaN rows stay NaN
            # a huge one over its largest component first, so that its length cannot overflow
            big = np.abs(d_cam).max(axis=-1, keepdims=True)
            d_cam = np.where(big > 1e150, d_cam / np.where(big > 1e150, big, 1.0), d_cam)
            d = d_cam @ self.R  # R^T d for row vectors
            d /= np.linalg.norm(d, axis=-1, keepdims=True)
        return np.broadcast_to(self.center, d.shape).copy(), d

    def pixel_grid(self, stride: int = 1) -> np.ndarray:
        """Pixel-centre coordinates ``(H', W', 2)`` of the image, every ``stride`` pixels."""
        us = np.arange(0, self.width, stride, dtype=np.float64)
        vs = np.arange(0, self.height, stride, dtype=np.float64)
        u, v = np.meshgrid(us, vs)
        return np.stack([u, v], axis=-1)

    # ---------------------------------------------------------- derived cameras
    def with_pose(self, R: np.ndarray, t: np.ndarray) -> "Camera":
        return replace(self, R=np.asarray(R, float), t=np.asarray(t, float))

    def _derived(self, **changes) -> "Camera":
        """A copy with ``changes`` that are valid by construction (crop, resize, no distortion).

        Skips ``__post_init__``'s checks (a third of the runtime's per-pair geometry cost): the
        derived cameras below keep K upper-triangular with fx, fy > 0 and R a rotation.
        """
        cam = object.__new__(Camera)
        for name in ("name", "width", "height", "K", "dist", "R", "t"):
            value = changes.get(name, getattr(self, name))
            if isinstance(value, np.ndarray) and value.flags.writeable:
                value = value.astype(np.float64)  # own copy, frozen like __post_init__'s
                value.setflags(write=False)
            object.__setattr__(cam, name, value)
        return cam

    def cropped(self, x0: float, y0: float, width: int, height: int) -> "Camera":
        """The camera seen through a crop window whose top-left pixel is ``(x0, y0)``."""
        width, height = int(width), int(height)
        if width <= 0 or height <= 0:
            raise GeometryError(f"camera {self.name!r}: crop size must be positive, got {width}x{height}")
        K = self.K.copy()
        K[0, 2] -= x0
        K[1, 2] -= y0
        if not np.all(np.isfinite(K)):
            raise GeometryError(f"camera {self.name!r}: crop origin must be finite, got ({x0}, {y0})")
        return self._derived(K=K, width=width, height=height)

    def resized(self, width: int, height: int) -> "Camera":
        """The camera after resizing its image to ``width`` x ``height`` (pixel-centre convention)."""
        width, height = int(width), int(height)
        if width <= 0 or height <= 0:
            raise GeometryError(f"camera {self.name!r}: image size must be positive, got {width}x{height}")
        sx, sy = width / self.width, height / self.height
        S = np.array([[sx, 0, 0.5 * sx - 0.5], [0, sy, 0.5 * sy - 0.5], [0, 0, 1.0]])
        return self._derived(K=S @ self.K, width=width, height=height)

    def without_distortion(self) -> "Camera":
        return self._derived(dist=np.zeros(5))

    def rotated(self, degrees: float) -> "Camera":
        """The camera whose image is this one's rotated ``degrees`` counterclockwise about the image
        centre, size kept (the corners turn out of the frame, others come in): the same centre,
        rolled about the optical axis, with the principal point moved to match. For a square image
        and a multiple of 90 degrees it is :meth:`quarter_turned`. Pinhole cameras only.
        """
        if degrees % 360.0 == 0.0:
            return self
        if self.has_distortion:
            raise GeometryError(f"camera {self.name!r}: only a pinhole camera can be rotated")
        rot = image_rotation(degrees)
        centre = np.array([(self.width - 1) / 2, (self.height - 1) / 2])
        M = rot @ self.K[:2, :2]
        # RQ of M = K2 @ Q: K2 upper triangular with a positive diagonal, Q a rotation (det M > 0).
        r = math.hypot(M[1, 0], M[1, 1])
        q_row = M[1] / r  # (-sin phi, cos phi)
        q = np.array([[q_row[1], -q_row[0]], [q_row[0], q_row[1]]])
        K = np.eye(3)
        K[0, 0], K[0, 1], K[1, 1] = M[0] @ q[0], M[0] @ q[1], r
        K[:2, 2] = rot @ (self.K[:2, 2] - centre) + centre
        Rz = np.eye(3)
        Rz[:2, :2] = q
        return self._derived(K=K, R=Rz @ self.R, t=Rz @ self.t)

    def quarter_turned(self, turns: int) -> "Camera":
        """The camera whose image is this one's turned ``turns`` quarter turns counterclockwise, as
        ``np.rot90(image, turns)``: the same centre and optical axis, rolled about the axis.

        Pinhole cameras only (a lens model's tangential terms would turn too); a skewed ``K`` only
        by half turns (a quarter turn would move the skew below the diagonal).
        """
        turns = int(turns) % 4
        if turns == 0:
            return self
        if self.has_distortion:
            raise GeometryError(f"camera {self.name!r}: only a pinhole camera can be quarter-turned")
        if turns % 2 and self.K[0, 1] != 0.0:
            raise GeometryError(f"camera {self.name!r}: a skewed camera turns by half turns only")
        W, H = self.width, self.height
        # A: pixel (u, v) -> its place in the turned image; Rz: the camera frame rolled to match.
        if turns == 1:  # u' = v, v' = W-1-u
            A, Rz, size = [[0, 1, 0], [-1, 0, W - 1], [0, 0, 1]], [[0, 1, 0], [-1, 0, 0], [0, 0, 1]], (H, W)
        elif turns == 2:  # u' = W-1-u, v' = H-1-v
            A, Rz, size = [[-1, 0, W - 1], [0, -1, H - 1], [0, 0, 1]], [[-1, 0, 0], [0, -1, 0], [0, 0, 1]], (W, H)
        else:  # u' = H-1-v, v' = u
            A, Rz, size = [[0, -1, H - 1], [1, 0, 0], [0, 0, 1]], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], (H, W)
        A, Rz = np.asarray(A, np.float64), np.asarray(Rz, np.float64)
        K = A @ self.K @ Rz.T
        K[1, 0] = 0.0  # exactly 0 by the checks above; drop the -0.0
        return self._derived(K=K, R=Rz @ self.R, t=Rz @ self.t, width=size[0], height=size[1])


def nearest_rotation(R) -> np.ndarray:
    """The rotation closest to a nearly orthonormal ``(3, 3)`` matrix (SVD): what a file printed with a few
    digits, or a device stored in float32, meant."""
    u, _, vt = np.linalg.svd(np.asarray(R, dtype=np.float64))
    return u @ vt


def _look_at_vector(name: str, value) -> np.ndarray:
    """``value`` as a finite float64 3-vector; else a GeometryError naming ``name`` (a NaN gave a NaN rotation)."""
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):  # OverflowError: an int past float64 (10 ** 400)
        v = None
    if v is None or v.shape != (3,) or not np.isfinite(v).all():
        raise GeometryError(f"look_at: {name} must be a finite 3-vector, got {value!r}")
    return v


def look_at(eye, target, up=(0.0, -1.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Extrinsics ``(R, t)`` of a camera at ``eye`` looking at ``target``.

    ``up`` is the rig-frame direction that should appear up in the image (the rig
    frame is y-down, so the default is ``-y``).
    """
    eye, target, up = (_look_at_vector(name, v) for name, v in (("eye", eye), ("target", target), ("up", up)))
    with np.errstate(over="ignore", invalid="ignore"):  # eye and target 2e308 apart: refused below
        forward = target - eye
    if not np.isfinite(forward).all():
        raise GeometryError(f"look_at: eye {eye.tolist()} and target {target.tolist()} are too far apart for float64")
    with np.errstate(over="ignore"):
        norm = np.linalg.norm(forward)
    if norm == np.inf:  # an offset past 1e154 m: its length overflowed (a warning, then a zero direction)
        scale = np.abs(forward).max()
        forward, norm = forward / scale, np.linalg.norm(forward / scale)
    if norm < 1e-12:
        raise GeometryError("look_at: eye and target coincide")
    z = forward / norm
    if not np.any(up):
        raise GeometryError("look_at: up must be a direction, got (0, 0, 0)")
    x = np.cross(-up, z)
    if np.linalg.norm(x) < 1e-9:
        raise GeometryError("look_at: viewing direction is parallel to up")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])  # rows: camera axes in rig coordinates
    return R, -R @ eye


def intrinsics_from_fov(width: int, height: int, hfov_deg: float) -> np.ndarray:
    """A square-pixel K with the principal point at the image centre."""
    if not 1.0 < hfov_deg < 179.0:
        raise GeometryError(f"horizontal field of view must be in (1, 179) degrees, got {hfov_deg}")
    f = 0.5 * width / np.tan(np.radians(hfov_deg) / 2)
    return np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])
