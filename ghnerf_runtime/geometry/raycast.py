"""Exact ray casting of ellipsoids and rounded cones for one pinhole/distorted camera.

The simulator's bodies (``drivers.sim.body.PosedBody``) and the body proxy built from estimated
joints (``ghnerf_runtime.body_proxy``) are both sets of these primitives; anything with the
:class:`Primitives` fields can be rasterised.

Everything happens in the camera frame: the ray through a pixel is
``t * (x, y, 1)`` where ``(x, y)`` are the pixel's undistorted normalised
coordinates, so the hit parameter ``t`` *is* the depth (camera z).

Speed: each primitive is tested only against the pixels of its projected
bounding box (a rounded cone: the union of its two spheres' exact projected
boxes; an ellipsoid: the projection of its oriented bounding box). All
(primitive, pixel) pairs of all primitives are then intersected in vectorised
passes of at most :data:`RASTER_CHUNK` pairs (one pass at the runtime's view
sizes; bounded memory at any) and the nearest hit per pixel is kept with
``np.minimum.at``, so the cost is a few dozen numpy calls per pass, not
per primitive.

Intersections are closed-form: an ellipsoid is a unit sphere after an affine
map; a rounded cone (convex hull of two spheres) is entered through one of
its spheres or through the tangent cone between them, and the smallest valid
root of the three quadrics is the entry point. Degenerate primitives (a cone
of zero length, an ellipsoid with a zero radius or a lost axis) never divide
by zero: the first is its larger sphere, the second hits nothing.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ghnerf_runtime.geometry.camera import Camera

NEAR = 1e-3  # metres: hits closer than this to the camera are ignored
#: (primitive, pixel) pairs intersected per pass of :func:`rasterize`: about 350 bytes each in flight, so
#: about 90 MB at most whatever the image size (a camera inside the body puts most primitives' windows on
#: the whole image: 14 pairs per pixel, 56 M at 2000x2000).
RASTER_CHUNK = 1 << 18
_BOX_SIGNS = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)], dtype=np.float64) * 2.0 - 1.0


class Primitives(Protocol):
    """Ellipsoids and rounded cones in one camera's frame (primitive ids: ellipsoids first).

    ``ell_center`` ``(E, 3)``, ``ell_axes`` ``(E, 3, 3)`` (columns are the local axes), ``ell_radii``
    ``(E, 3)``; ``cone_a``, ``cone_b`` ``(C, 3)`` sphere centres, ``cone_ra``, ``cone_rb`` ``(C,)`` radii
    (a rounded cone is the convex hull of its two spheres)."""

    ell_center: np.ndarray
    ell_axes: np.ndarray
    ell_radii: np.ndarray
    cone_a: np.ndarray
    cone_b: np.ndarray
    cone_ra: np.ndarray
    cone_rb: np.ndarray


@dataclass(frozen=True, eq=False)
class RayGrid:
    """Undistorted normalised coordinates of every pixel centre of one camera model.

    ``xs (W,)`` / ``ys (H,)`` when the mapping is separable (no distortion, no skew), else
    ``gx, gy (H, W)``. ``bounds`` is ``(xmin, xmax, ymin, ymax)`` over the image.
    """

    camera: Camera
    xs: np.ndarray | None
    ys: np.ndarray | None
    gx: np.ndarray | None
    gy: np.ndarray | None
    bounds: tuple[float, float, float, float]

    @classmethod
    def for_camera(cls, camera: Camera) -> "RayGrid":
        K = camera.K
        if not camera.has_distortion and K[0, 1] == 0.0:
            xs = (np.arange(camera.width) - K[0, 2]) / K[0, 0]
            ys = (np.arange(camera.height) - K[1, 2]) / K[1, 1]
            return cls(camera, xs, ys, None, None, (xs[0], xs[-1], ys[0], ys[-1]))
        xy = camera.pixels_to_normalized(camera.pixel_grid())
        gx, gy = np.ascontiguousarray(xy[..., 0]), np.ascontiguousarray(xy[..., 1])
        # NaN: pixels past the lens model's fold (Camera.undistort_normalized), which no ray reaches.
        return cls(camera, None, None, gx, gy,
                   (float(np.nanmin(gx)), float(np.nanmax(gx)), float(np.nanmin(gy)), float(np.nanmax(gy))))

    def with_camera(self, camera: Camera) -> "RayGrid":
        """The same rays for another camera with identical intrinsics (pose does not matter)."""
        return RayGrid(camera, self.xs, self.ys, self.gx, self.gy, self.bounds)

    @property
    def separable(self) -> bool:
        return self.xs is not None

    def at(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normalised ``(x, y)`` of pixel centres at integer ``rows``, ``cols``."""
        if self.separable:
            return self.xs[cols], self.ys[rows]
        return self.gx[rows, cols], self.gy[rows, cols]

    # --------------------------------------------------------------- culling
    def windows(self, body: Primitives) -> np.ndarray:
        """``(P, 4)`` int pixel windows ``r0, r1, c0, c1`` per primitive (empty when culled)."""
        # Normalised-coordinate boxes: rounded cones = union of their two spheres.
        sa = _sphere_boxes(body.cone_a, body.cone_ra)
        sb = _sphere_boxes(body.cone_b, body.cone_rb)
        cone = np.stack([np.minimum(sa[:, 0], sb[:, 0]), np.maximum(sa[:, 1], sb[:, 1]),
                         np.minimum(sa[:, 2], sb[:, 2]), np.maximum(sa[:, 3], sb[:, 3])], axis=-1)
        # Ellipsoids: project the corners of the oriented bounding box (a convex set stays convex
        # under perspective, so the corners bound it) unless a corner is behind the near plane.
        half = body.ell_axes[:, None, :, :] * (body.ell_radii[:, None, None, :] * _BOX_SIGNS[None, :, None, :])
        corners = body.ell_center[:, None, :] + half.sum(axis=-1)
        z = corners[..., 2]
        front = np.all(z > NEAR, axis=-1)
        safe = np.where(z > NEAR, z, 1.0)
        nx, ny = corners[..., 0] / safe, corners[..., 1] / safe
        ell = np.stack([nx.min(-1), nx.max(-1), ny.min(-1), ny.max(-1)], axis=-1)
        fallback = _sphere_boxes(body.ell_center, body.ell_radii.max(axis=-1))
        ell = np.where(front[:, None], ell, fallback)
        ell = np.where(solid_ellipsoids(body)[:, None], ell, np.array([1e6, -1e6, 1e6, -1e6]))  # flat: no pixel
        return self._pixel_windows(np.concatenate([ell, cone]))

    def _pixel_windows(self, boxes: np.ndarray) -> np.ndarray:
        cam = self.camera
        xmin, xmax, ymin, ymax = self.bounds
        m = 0.02 * max(xmax - xmin, ymax - ymin)  # a little beyond the image, where the lens model is sane
        x0 = np.maximum(boxes[:, 0], xmin - m)
        x1 = np.minimum(boxes[:, 1], xmax + m)
        y0 = np.maximum(boxes[:, 2], ymin - m)
        y1 = np.minimum(boxes[:, 3], ymax + m)
        seen = (x0 <= x1) & (y0 <= y1)
        if self.separable:
            K = cam.K
            u0, u1 = K[0, 0] * x0 + K[0, 2], K[0, 0] * x1 + K[0, 2]
            v0, v1 = K[1, 1] * y0 + K[1, 2], K[1, 1] * y1 + K[1, 2]
        else:
            # Distortion bends box edges: sample each border, map through the lens, pad 2 px.
            s = np.linspace(0.0, 1.0, 7)
            bx = np.concatenate([x0[:, None] + (x1 - x0)[:, None] * s, np.repeat(x1[:, None], 7, 1),
                                 x0[:, None] + (x1 - x0)[:, None] * s, np.repeat(x0[:, None], 7, 1)], axis=1)
            by = np.concatenate([np.repeat(y0[:, None], 7, 1), y0[:, None] + (y1 - y0)[:, None] * s,
                                 np.repeat(y1[:, None], 7, 1), y0[:, None] + (y1 - y0)[:, None] * s], axis=1)
            uv = cam.normalized_to_pixels(np.stack([bx, by], -1))
            u0, u1 = uv[..., 0].min(-1) - 2, uv[..., 0].max(-1) + 2
            v0, v1 = uv[..., 1].min(-1) - 2, uv[..., 1].max(-1) + 2
        c0 = np.clip(np.floor(u0), 0, cam.width).astype(np.int64)
        c1 = np.clip(np.ceil(u1) + 1, 0, cam.width).astype(np.int64)
        r0 = np.clip(np.floor(v0), 0, cam.height).astype(np.int64)
        r1 = np.clip(np.ceil(v1) + 1, 0, cam.height).astype(np.int64)
        win = np.stack([r0, r1, c0, c1], axis=-1)
        win[~seen] = 0
        return win


def _sphere_boxes(centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Exact normalised-coordinate boxes ``(n, 4)`` of camera-frame spheres (tangent planes through
    the camera centre); spheres crossing the near plane get an unbounded box, ones behind it an
    empty box."""
    X, Y, Z = centers[:, 0], centers[:, 1], centers[:, 2]
    r = radii
    big = 1e6
    rx, ry = np.hypot(X, Z), np.hypot(Y, Z)
    ok = (Z - r > NEAR) & (rx > r) & (ry > r)
    lim = np.pi / 2 - 1e-6
    bx = np.arcsin(np.where(ok, r / np.where(ok, rx, 1.0), 0.0))
    by = np.arcsin(np.where(ok, r / np.where(ok, ry, 1.0), 0.0))
    ax, ay = np.arctan2(X, Z), np.arctan2(Y, Z)
    box = np.stack([np.tan(np.maximum(ax - bx, -lim)), np.tan(np.minimum(ax + bx, lim)),
                    np.tan(np.maximum(ay - by, -lim)), np.tan(np.minimum(ay + by, lim))], axis=-1)
    box = np.where(ok[:, None], box, np.array([-big, big, -big, big]))
    behind = Z + r <= NEAR
    return np.where(behind[:, None], np.array([big, -big, big, -big]), box)


# ---------------------------------------------------------------- intersections
def solid_ellipsoids(body: Primitives) -> np.ndarray:
    """``(E,)`` bool: the ellipsoids with three positive finite radii and independent axes. The others (a
    body proxy's head from two ears at one point, a torso whose neck is on its mid-hip) are flat or
    unbounded: a radius of 0 divides by zero, and a zero axis turns the ellipsoid into an endless slab."""
    radii, axes = np.asarray(body.ell_radii, np.float64), np.asarray(body.ell_axes, np.float64)
    ok = np.all((radii > 0) & (radii < np.inf), axis=-1) & np.isfinite(axes).all(axis=(-2, -1))
    if len(axes):  # the axes' volume: 1 for orthonormal columns, 0 for a lost one
        ok &= np.abs(np.linalg.det(np.where(ok[:, None, None], axes, np.eye(3)))) > 1e-6
    return ok


def ellipsoid_coefficients(body: Primitives) -> np.ndarray:
    """``(E, 10)`` per-ellipsoid constants of the hit quadratic ``a t^2 + 2 b t + c`` in (x, y); an ellipsoid
    that is not solid (:func:`solid_ellipsoids`) gets ``a = c = 1, b = 0``: every ray misses it."""
    radii, axes, centre = body.ell_radii, body.ell_axes, body.ell_center
    solid = solid_ellipsoids(body)
    if not solid.all():  # stand-ins where it is not, so that nothing divides by zero
        radii = np.where(solid[:, None], radii, 1.0)
        axes = np.where(solid[:, None, None], axes, np.eye(3))
        centre = np.where(solid[:, None], centre, 0.0)
    Q = np.swapaxes(axes, -1, -2) / radii[:, :, None]  # camera -> unit sphere
    o = -np.einsum("kab,kb->ka", Q, centre)
    A = np.swapaxes(Q, -1, -2) @ Q
    bq = np.einsum("kba,kb->ka", Q, o)
    cq = np.einsum("ka,ka->k", o, o) - 1.0
    coef = np.stack([A[:, 0, 0], 2 * A[:, 0, 2], A[:, 1, 1], 2 * A[:, 1, 2], 2 * A[:, 0, 1], A[:, 2, 2],
                     bq[:, 0], bq[:, 1], bq[:, 2], cq], axis=-1)
    return coef if solid.all() else np.where(solid[:, None], coef, np.array([0, 0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]))


def ellipsoid_depth(X: np.ndarray, Y: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """Depth of the first hit of rays ``t * (X, Y, 1)``; ``coef (n, 10)`` per ray; inf on a miss."""
    a = (coef[:, 0] * X + coef[:, 1]) * X + (coef[:, 2] * Y + coef[:, 3]) * Y + coef[:, 4] * (X * Y) + coef[:, 5]
    b = coef[:, 6] * X + coef[:, 7] * Y + coef[:, 8]
    disc = b * b - a * coef[:, 9]
    hit = disc >= 0.0
    t = (-b - np.sqrt(np.where(hit, disc, 0.0))) / a
    return np.where(hit & (t > NEAR), t, np.inf)


def cone_coefficients(body: Primitives) -> tuple[np.ndarray, np.ndarray]:
    """Per-cone constants ``(C, 15)`` and valid axial range ``(C, 2)`` for :func:`round_cone_depth`."""
    a, b, ra, rb = body.cone_a, body.cone_b, body.cone_ra, body.cone_rb
    axis = b - a
    length = np.linalg.norm(axis, axis=-1)
    # Where one sphere holds the other (a zero-length limb among them) the hull is that sphere: no tangent
    # cone (an empty axial range below), and no division by a length of 0.
    sheathed = length > np.abs(ra - rb)
    safe = np.where(sheathed, length, 1.0)
    w = np.where(sheathed[:, None], axis / safe[:, None], np.array([0.0, 0.0, 1.0]))
    s = np.where(sheathed, (ra - rb) / safe, 0.0)  # sine of the cone's half-angle
    c2 = 1.0 - s * s
    mw = -np.einsum("ka,ka->k", a, w)  # camera centre relative to sphere a, along the axis
    mm = np.einsum("ka,ka->k", a, a)
    k = ra - mw * s
    return np.stack([
        a[:, 0], a[:, 1], a[:, 2], mm - ra * ra,
        b[:, 0], b[:, 1], b[:, 2], np.einsum("ka,ka->k", b, b) - rb * rb,
        w[:, 0], w[:, 1], w[:, 2],
        c2, k * s - c2 * mw, c2 * (mm - mw * mw) - k * k, mw,
    ], axis=-1), np.where(sheathed[:, None], np.stack([ra * s, length + rb * s], axis=-1), [np.inf, -np.inf])


def round_cone_depth(X: np.ndarray, Y: np.ndarray, coef: np.ndarray, h_range: np.ndarray) -> np.ndarray:
    """Depth of the first hit of rays ``t * (X, Y, 1)`` with a convex hull of two spheres.

    ``coef (n, 15)`` and ``h_range (n, 2)`` per ray from :func:`cone_coefficients`; inf on a miss.
    """
    dd = X * X + Y * Y + 1.0
    t = np.full(X.shape, np.inf)
    for off in (0, 4):  # the two spheres
        cd = coef[:, off] * X + coef[:, off + 1] * Y + coef[:, off + 2]
        disc = cd * cd - dd * coef[:, off + 3]
        hit = disc >= 0.0
        ts = (cd - np.sqrt(np.where(hit, disc, 0.0))) / dd
        t = np.where(hit & (ts > NEAR) & (ts < t), ts, t)
    # Tangent cone: points at axial height h and radial distance q with q*cos + h*sin = ra.
    dw = coef[:, 8] * X + coef[:, 9] * Y + coef[:, 10]
    md = -(coef[:, 0] * X + coef[:, 1] * Y + coef[:, 2])
    qa = coef[:, 11] * dd - dw * dw
    qb = coef[:, 11] * md + coef[:, 12] * dw
    disc = qb * qb - qa * coef[:, 13]
    ok = (disc >= 0.0) & (np.abs(qa) > 1e-12)
    sq = np.sqrt(np.where(ok, disc, 0.0))
    safe = np.where(ok, qa, 1.0)
    for root in ((-qb - sq) / safe, (-qb + sq) / safe):
        h = coef[:, 14] + root * dw
        valid = ok & (root > NEAR) & (h >= h_range[:, 0]) & (h <= h_range[:, 1]) & (root < t)
        t = np.where(valid, root, t)
    return t


# ---------------------------------------------------------------- rasterising
@dataclass(frozen=True, eq=False)
class Raster:
    """Nearest hit per pixel.

    Attributes:
        depth: ``(H, W)`` float64 camera z, inf on background.
        prim: ``(H, W)`` int16 primitive id, -1 on background.
        fg_pixel, fg_prim, fg_depth: flat pixel index, primitive id and depth of every
            foreground pixel (one entry per pixel).
    """

    depth: np.ndarray
    prim: np.ndarray
    fg_pixel: np.ndarray
    fg_prim: np.ndarray
    fg_depth: np.ndarray


def rasterize(body: Primitives, grid: RayGrid, chunk: int = RASTER_CHUNK) -> Raster:
    """Ray-cast every primitive of ``body`` (already in this camera's frame) into a z-buffer.

    The (primitive, pixel) pairs are intersected ``chunk`` at a time (:data:`RASTER_CHUNK`), so memory
    stays bounded when the windows cover many pixels (a large image, a camera inside the body)."""
    cam = grid.camera
    H, W = cam.height, cam.width
    win = grid.windows(body)
    heights = win[:, 1] - win[:, 0]
    widths = win[:, 3] - win[:, 2]
    sizes = heights * widths
    ends = np.cumsum(sizes)
    total = int(ends[-1]) if len(ends) else 0
    depth = np.full(H * W, np.inf)
    prim = np.full(H * W, -1, dtype=np.int16)
    n_ell = len(body.ell_center)
    ell_coef = ellipsoid_coefficients(body) if n_ell and total else None
    cone_coef, h_range = cone_coefficients(body) if len(body.cone_a) and total else (None, None)
    starts, step = ends - sizes, max(int(chunk), 1)
    for lo in range(0, total, step):
        # The pairs lo..hi of all primitives' windows (grouped by primitive, ellipsoids first), without a
        # Python loop over primitives.
        hi = min(lo + step, total)
        if hi - lo == total:  # one pass, the usual case
            k = np.repeat(np.arange(len(win)), sizes)
            j = np.arange(total) - np.repeat(starts, sizes)
        else:
            pair = np.arange(lo, hi)
            k = np.searchsorted(ends, pair, side="right")
            j = pair - starts[k]
        w_k = widths[k]
        rows = win[k, 0] + j // w_k
        cols = win[k, 2] + j % w_k
        X, Y = grid.at(rows, cols)
        t = np.empty(hi - lo)
        is_ell = k < n_ell
        if np.any(is_ell):
            e = np.nonzero(is_ell)[0]
            t[e] = ellipsoid_depth(X[e], Y[e], ell_coef[k[e]])
        if not np.all(is_ell):
            c = np.nonzero(~is_ell)[0]
            kc = k[c] - n_ell
            t[c] = round_cone_depth(X[c], Y[c], cone_coef[kc], h_range[kc])
        hit = np.isfinite(t)
        pix, k, t = (rows * W + cols)[hit], k[hit], t[hit]
        before = depth[pix] if lo else None
        np.minimum.at(depth, pix, t)
        if lo:  # a nearer hit in this pass: the earlier passes' primitive there is void
            prim[pix[depth[pix] < before]] = -1
        win_mask = t == depth[pix]
        # Exact ties (two primitives at the same depth) go to the higher id, deterministically.
        np.maximum.at(prim, pix[win_mask], k[win_mask].astype(np.int16))
    # One entry per foreground pixel, grouped by primitive (ascending) and row-major within each: in one pass
    # the winning pairs are in that order already.
    if 0 < total <= step:
        keep = win_mask & (prim[pix] == k)
        return Raster(depth.reshape(H, W), prim.reshape(H, W), pix[keep], k[keep], t[keep])
    fg = np.flatnonzero(prim >= 0)
    fg = fg[np.argsort(prim[fg], kind="stable")]
    return Raster(depth.reshape(H, W), prim.reshape(H, W), fg, prim[fg].astype(np.int64), depth[fg])
