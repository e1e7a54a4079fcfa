"""Shade the ray-cast body over the room and produce per-camera ground truth.

Lighting is one distant light (Lambert) plus a hemispherical ambient term
(a little brighter from above), evaluated in linear BGR radiance; the
sensor model (sensor.py) applies exposure, gamma and noise afterwards.

Joint visibility (``CameraTruth.visible``) means: in front of the camera and
inside its lens model's fold (``Camera.within_lens``; a joint behind the camera
or past the fold gets ``joints_2d`` (-1, -1)), inside the image, and not hidden by the body: the rendered depth at the
joint's pixel is no nearer than the joint's depth minus the joint's
embedding depth (how far it sits under the skin) minus ``VISIBILITY_MARGIN_M``,
and, for joints on the skin (nose, eyes, ears, toes, heels), the skin there
faces the camera.

Not modelled: shadows, inter-reflection, specular highlights, anti-aliasing
(one ray per pixel centre), depth of field.
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import cv2
import numpy as np

from drivers.frames import CameraTruth
from drivers.sim.appearance import Look
from drivers.sim.background import RoomStyle, render_room
from drivers.sim.body import BodyModel, PosedBody
from drivers.sim.errors import SimConfigError
from drivers.sim.raycast import NEAR, Raster, RayGrid, rasterize
from drivers.sim.sensor import GAMMA
from ghnerf_runtime.geometry import Camera

VISIBILITY_MARGIN_M = 0.025


@dataclass(frozen=True)
class Lighting:
    """A distant key light and ambient fill.

    Attributes:
        direction: rig-frame direction *towards* the light (normalised here); the default is
            above, slightly left of and in front of the rig.
        ambient: share of light that is ambient (0..1).
    """

    direction: tuple[float, float, float] = (-0.35, -1.0, -0.6)
    ambient: float = 0.35

    def __post_init__(self) -> None:
        d = np.asarray(self.direction, dtype=np.float64)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-6:
            raise SimConfigError("Lighting.direction", f"must be a non-zero finite 3-vector, got {self.direction!r}")
        if not isinstance(self.ambient, (int, float)) or not 0.0 <= self.ambient <= 1.0:
            raise SimConfigError("Lighting.ambient", f"must be in [0, 1], got {self.ambient!r}")

    @property
    def unit_direction(self) -> np.ndarray:
        d = np.asarray(self.direction, dtype=np.float64)
        return d / np.linalg.norm(d)


def to_display(radiance: np.ndarray) -> np.ndarray:
    """Linear radiance -> display values (gamma-encoded, 1.0 = white at nominal exposure).

    Exposure is applied later as a gain on display values, which equals a gain on radiance
    because the encoding is a pure power law (``(g L)^(1/gamma) = g^(1/gamma) L^(1/gamma)``).
    """
    clipped = np.maximum(radiance, 0.0).astype(np.float32)
    return cv2.pow(clipped.reshape(len(clipped), -1), 1.0 / GAMMA).reshape(clipped.shape)  # cv2: ~10x numpy


def _camera_key(camera: Camera) -> tuple:
    return (camera.width, camera.height, camera.K.tobytes(), camera.dist.tobytes(), camera.R.tobytes(), camera.t.tobytes())


class BodyRenderer:
    """Renders one person (body + look) in one room for any camera; caches per-camera rays and
    backgrounds (bounded LRU), so a fixed rig pays for them once.

    Args:
        body, look: the person.
        lighting: the light.
        room: room style, or ``None`` for a plain background of ``plain_bgr`` (linear 0..1).
        room_center_xz: rig-frame (x, z) the room is centred on.
        cache_size: cameras whose rays/backgrounds are kept.
    """

    def __init__(
        self,
        body: BodyModel,
        look: Look,
        lighting: Lighting,
        room: RoomStyle | None,
        room_center_xz: tuple[float, float] = (0.0, 3.0),
        plain_bgr: tuple[float, float, float] = (0.0, 0.0, 0.0),
        cache_size: int = 8,
    ) -> None:
        self.body, self.look, self.lighting, self.room = body, look, lighting, room
        self.room_center_xz = room_center_xz
        self.plain_bgr = np.asarray(plain_bgr, dtype=np.float32)
        self.cache_size = cache_size
        self._grids: OrderedDict[tuple, RayGrid] = OrderedDict()
        self._backgrounds: OrderedDict[tuple, np.ndarray] = OrderedDict()
        # Primitive id + 1 (0 = background) -> part id, as a 256-entry table for cv2.LUT.
        self._part_lut = np.zeros(256, dtype=np.uint8)
        self._part_lut[1 : body.num_primitives + 1] = body.prim_part

    # ------------------------------------------------------------------ caches
    def _cached(self, store: OrderedDict, key: tuple, make):
        if key in store:
            store.move_to_end(key)
            return store[key]
        value = make()
        store[key] = value
        while len(store) > self.cache_size:
            store.popitem(last=False)
        return value

    def grid(self, camera: Camera) -> RayGrid:
        key = _camera_key(camera)[:4]  # rays in the camera frame depend on intrinsics only
        grid = self._cached(self._grids, key, lambda: RayGrid.for_camera(camera))
        return grid if grid.camera is camera else grid.with_camera(camera)

    def background(self, camera: Camera) -> np.ndarray:
        """Display-space BGR ``(H, W, 3)`` float32 of the empty scene (shared; do not modify)."""
        if self.room is None:
            plain = to_display(self.plain_bgr).astype(np.float32)
            make = lambda: np.broadcast_to(plain, (camera.height, camera.width, 3))  # noqa: E731
        else:
            make = lambda: to_display(render_room(self.grid(camera), self.room, self.room_center_xz, self.lighting.unit_direction, self.lighting.ambient)).astype(np.float32)  # noqa: E731
        return self._cached(self._backgrounds, _camera_key(camera), make)

    # ------------------------------------------------------------------ render
    def render(self, posed: PosedBody, camera: Camera, *, with_truth: bool = True) -> tuple[np.ndarray, CameraTruth | None]:
        """Display-space image ``(H, W, 3)`` float32 (BGR, 1.0 = white before exposure) and, if
        asked, the ground truth.

        Args:
            posed: the body posed in the rig frame.
        """
        grid = self.grid(camera)
        local = posed.transformed(camera.R, camera.t)
        raster = rasterize(local, grid)
        image = np.array(self.background(camera), dtype=np.float32, copy=True)
        self._shade(local, raster, grid, camera, image)
        truth = self._truth(local, raster, grid, camera) if with_truth else None
        return image, truth

    def _shade(self, body: PosedBody, raster: Raster, grid: RayGrid, camera: Camera, out: np.ndarray) -> None:
        """Write the lit albedo of every foreground pixel into ``out``.

        Foreground entries arrive grouped by primitive, so per-primitive transforms run on
        contiguous slices (a few numpy calls each) and albedos run once per material.
        """
        pix, k, t = raster.fg_pixel, raster.fg_prim, raster.fg_depth
        if pix.size == 0:
            return
        W = camera.width
        X, Y = grid.at(pix // W, pix % W)
        p = np.stack([X * t, Y * t, t], axis=-1)
        n = np.empty_like(p)
        rest = np.empty_like(p)
        look = self.look
        material = np.empty(len(p), dtype=np.int64)
        n_ell = len(body.ell_center)
        bounds = np.searchsorted(k, np.arange(len(body.to_rest_t) + 1))
        for kk in np.unique(k):
            sl = slice(bounds[kk], bounds[kk + 1])
            ps = p[sl]
            rest[sl] = ps @ body.to_rest_R[kk].T + body.to_rest_t[kk]
            material[sl] = look.prim_base[kk]
            if kk < n_ell:
                axes = body.ell_axes[kk]
                n[sl] = (((ps - body.ell_center[kk]) @ axes) / body.ell_radii[kk] ** 2) @ axes.T
            else:
                n[sl], along = _cone_normal(ps, body, kk - n_ell)
                if look.prim_cover_until[kk] > 0.0:
                    material[sl] = np.where(along < look.prim_cover_until[kk], look.prim_cover[kk], look.prim_base[kk])
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        head = k == look.head_prim
        material[head] = -1
        albedo = np.empty_like(p)
        for m in np.unique(material):
            sel = material == m
            albedo[sel] = look.face_albedo(rest[sel]) if m < 0 else look.albedo(int(m), rest[sel])
        light = camera.R @ self.lighting.unit_direction
        up = camera.R @ np.array([0.0, -1.0, 0.0])
        amb = self.lighting.ambient
        shade = amb * (0.85 + 0.15 * (n @ up)) + (1.0 - amb) * np.clip(n @ light, 0.0, None)
        out.reshape(-1, 3)[pix] = to_display(albedo * shade[:, None])

    def _truth(self, body: PosedBody, raster: Raster, grid: RayGrid, camera: Camera) -> CameraTruth:
        mask = raster.prim >= 0
        joints_cam = body.joints  # already in the camera frame
        z = joints_cam[:, 2]
        in_front = z > NEAR
        safe_z = np.where(in_front, z, 1.0)
        xy = joints_cam[:, :2] / safe_z[:, None]
        # Past the lens model's fold the polynomial mirrors a joint onto a pixel showing another direction
        # (Camera.project gives NaN there): no pixel shows it, like a joint behind the camera.
        in_front &= camera.within_lens(xy)
        uv = camera.normalized_to_pixels(np.where(in_front[:, None], xy, 0.0))
        uv = np.where(in_front[:, None], uv, -1.0)  # behind the camera or past the fold: (-1, -1), never visible
        xmin, xmax, ymin, ymax = grid.bounds
        W, H = camera.width, camera.height
        inside = (
            in_front
            & (uv[:, 0] >= -0.5) & (uv[:, 0] < W - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < H - 0.5)
            # and within the angles the image's pixels see (with a margin)
            & (xy[:, 0] >= xmin - 0.05) & (xy[:, 0] <= xmax + 0.05) & (xy[:, 1] >= ymin - 0.05) & (xy[:, 1] <= ymax + 0.05)
        )
        cols = np.clip(np.rint(uv[:, 0]), 0, W - 1).astype(np.int64)
        rows = np.clip(np.rint(uv[:, 1]), 0, H - 1).astype(np.int64)
        surface = raster.depth[rows, cols]
        unoccluded = surface >= z - self.body.joint_radius - VISIBILITY_MARGIN_M
        # A joint on the skin (face, feet) is also hidden when its surface faces away: the depth
        # margin alone cannot tell the far side of a thin part from its near side at a silhouette.
        facing = np.einsum("ka,ka->k", body.joint_normals, -joints_cam) >= 0.0
        return CameraTruth(
            joints_2d=uv,
            visible=inside & unoccluded & facing,
            mask=mask,
            depth=raster.depth.astype(np.float32),
            part_labels=cv2.LUT((raster.prim + 1).astype(np.uint8), self._part_lut),
        )


def _cone_normal(p: np.ndarray, body: PosedBody, i: int) -> tuple[np.ndarray, np.ndarray]:
    """Outward normals ``(n, 3)`` (unnormalised) and the fraction along the axis of hit points
    ``p`` on rounded cone ``i``."""
    a, b = body.cone_a[i], body.cone_b[i]
    ra, rb = float(body.cone_ra[i]), float(body.cone_rb[i])
    axis = b - a
    length = float(np.linalg.norm(axis))
    w = axis / length
    s = (ra - rb) / length
    c = np.sqrt(1.0 - s * s)
    ap = p - a
    h = ap @ w
    radial = ap - h[:, None] * w
    q = np.linalg.norm(radial, axis=-1, keepdims=True)
    side = s * w + c * radial / np.maximum(q, 1e-12)
    n = np.where((h < ra * s)[:, None], ap, np.where((h > length + rb * s)[:, None], p - b, side))
    return n, h / length


def composite_nearest(images, depths) -> np.ndarray:
    """People rendered apart (one :class:`BodyRenderer` each, same camera), as one image: each pixel is the layer's
    whose surface is nearest there (``depths``: each layer's ``CameraTruth.depth``, ``inf`` where it shows only
    its background), so a nearer person hides a farther one; where no layer shows anyone, the first layer's pixel
    (its room). ``images``: ``(H, W, C)`` arrays of one shape and dtype; returns a new one."""
    images, depths = list(images), list(depths)
    if not images or len(images) != len(depths):
        raise SimConfigError("composite_nearest", f"needs one depth map per image and at least one image, got "
                             f"{len(images)} images and {len(depths)} depth maps")
    shape = images[0].shape
    for i, (image, depth) in enumerate(zip(images, depths)):
        if image.shape != shape or image.dtype != images[0].dtype or np.shape(depth) != shape[:2]:
            raise SimConfigError(f"composite_nearest[{i}]", f"image {image.shape} {image.dtype} and depth "
                                 f"{np.shape(depth)} do not match the first image's {shape} {images[0].dtype}")
    # argmin keeps the first layer on ties, which is every background pixel (all inf)
    nearest = np.argmin(np.stack([np.asarray(d) for d in depths]), axis=0)
    return np.take_along_axis(np.stack(images), nearest[None, :, :, None], axis=0)[0]
