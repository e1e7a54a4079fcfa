"""The novel view's subject recoloured from the source crops at the body proxy's depth.

GHNeRF's colour is a learnt blend of the two source images where each sample projects, placed by
its own depth, which is about 5 cm off (median) on views off the rig's cameras. The body proxy built
from the pair's 3D joints (``ghnerf_runtime.body_proxy``) is about 2 cm off. This replaces the
rendered colour of the pixels that

* the rendered picture shows as the subject (``region``; where the proxy is wider than the person,
  the sources show the room behind, which would draw a halo),
* the proxy covers, and
* some source sees at the proxy's depth (the proxy's own depth in that source within
  ``tolerance_m``), within ``max_angle_deg`` of the view's own ray (a view from far round the
  subject is better left to the network),

by those sources' pixels, averaged with weights that favour the source whose ray to the point is
nearest the view's own (``1 / (angle + 1 degree)``, as unstructured lumigraph rendering weighs its
cameras). At a rig camera's own viewpoint its pixels are copied whatever the proxy's depth error;
halfway between the cameras both count alike. Every other pixel keeps the rendered picture.
Measured in docs/novel-view.md, "Recolouring from the body proxy".

numpy, OpenCV.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from ghnerf_runtime.body_proxy import BodyProxy, proxy_depth
from ghnerf_runtime.contract import Normalisation
from ghnerf_runtime.errors import ShapeError
from ghnerf_runtime.geometry.camera import Camera

__all__ = ["ProxyBlend", "model_input_to_rgb", "proxy_blend", "subject_region"]

#: Angular weights ``1 / (angle + this)``: keeps the weight of a source on the view's own ray finite.
ANGLE_FLOOR_RAD = np.deg2rad(1.0)


@dataclass(frozen=True, eq=False)
class ProxyBlend:
    """The recoloured view.

    Attributes:
        image: ``(H, W, 3)`` uint8 BGR.
        replaced: ``(H, W)`` bool, the pixels recoloured from the sources.
        depth: ``(H, W)`` the proxy's camera-z depth (0 where it covers nothing, and outside the box
            of ``region`` when one was given).
    """

    image: np.ndarray
    replaced: np.ndarray
    depth: np.ndarray


def model_input_to_rgb(batch: np.ndarray, normalisation: Normalisation) -> np.ndarray:
    """The model's input ``(N, 3, S, S)`` (``preprocess.preprocess_image``'s) back to ``(N, S, S, 3)``
    RGB float32 in [0, 1]: the inverse of its affine map per channel."""
    x = np.asarray(batch, np.float32)
    if x.ndim != 4 or x.shape[1] != 3:
        raise ShapeError(f"model input must be (N, 3, S, S), got {x.shape}")
    lo, hi = (float(v) for v in normalisation.value_range)
    a, b = np.full(3, (hi - lo)), np.full(3, lo)  # x = a * pixel / 255 + b before mean/std
    if not normalisation.mean_std_in_graph:
        mean, std = np.asarray(normalisation.mean, float), np.asarray(normalisation.std, float)
        a, b = a / std, (b - mean) / std
    rgb = (x.transpose(0, 2, 3, 1) - b) / a
    if normalisation.channel_order == "BGR":
        rgb = rgb[..., ::-1]
    return np.ascontiguousarray(np.clip(rgb, 0.0, 1.0), dtype=np.float32)


def subject_region(image_bgr: np.ndarray, background: float, min_diff: float) -> np.ndarray:
    """``(H, W)`` bool: where a rendered uint8 view shows the subject, the colour test of the novel view's
    coarse pass (``novel_view.silhouette_min_diff``): some channel differs from ``background`` ([0, 1])
    by at least ``min_diff``."""
    return np.abs(np.asarray(image_bgr, np.float32) / 255.0 - background).max(axis=-1) >= min_diff


def unit_rgb(rgb: np.ndarray, name: str) -> np.ndarray:
    """``rgb`` as float32, refused (:class:`ShapeError` naming ``name``) unless it is a float array within
    [0, 1]: 8-bit colours (0..255) taken for [0, 1] clip to white everywhere, silently, and a NaN would
    pass every bound and end as an arbitrary uint8 pixel (or a painter's NaN answer)."""
    a = np.asarray(rgb)
    if np.issubdtype(a.dtype, np.floating) and not np.isfinite(a).all():
        raise ShapeError(f"{name} must be float RGB in [0, 1], got {int(np.count_nonzero(~np.isfinite(a)))} "
                         f"non-finite values (NaN or inf)")
    if not np.issubdtype(a.dtype, np.floating) or np.any(a > 1.0 + 1e-3) or np.any(a < -1e-3):
        top = float(np.nanmax(a)) if a.size else float("nan")
        raise ShapeError(f"{name} must be float RGB in [0, 1], got {a.dtype} up to {top:g}"
                         f"{' (8-bit? divide by 255)' if top > 2.0 else ''}")
    return np.ascontiguousarray(a, np.float32)


#: Points per row of :func:`sample_at`'s maps: ``cv2.remap`` refuses maps of 32767 rows or more (SHRT_MAX), which
#: one ``(N, 1)`` column reaches once the subject covers a third of a 320x320 view.
SAMPLE_ROW = 1024


def sample_at(image: np.ndarray, u: np.ndarray, v: np.ndarray, interpolation: int) -> np.ndarray:
    """``image`` (H, W[, C]) at the ``N`` pixel positions ``(u, v)``: ``(N[, C])``, 0 outside the image."""
    n = len(u)
    rows = max(-(-n // SAMPLE_ROW), 1)
    pad = rows * SAMPLE_ROW - n

    def as_map(a: np.ndarray) -> np.ndarray:
        return np.pad(np.asarray(a, np.float32), (0, pad), constant_values=-1.0).reshape(rows, SAMPLE_ROW)

    out = cv2.remap(image, as_map(u), as_map(v), interpolation, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    return out.reshape((rows * SAMPLE_ROW,) + image.shape[2:])[:n]


def proxy_blend(image_bgr: np.ndarray, camera: Camera, body: BodyProxy, sources: Sequence[Camera],
                source_rgb: np.ndarray, tolerance_m: float = 0.03, region: np.ndarray | None = None,
                max_angle_deg: float = 180.0, source_depth: Sequence[np.ndarray] | None = None,
                depth: np.ndarray | None = None) -> ProxyBlend:
    """Recolour ``image_bgr`` (the rendered view at pinhole ``camera``) from the sources at the proxy's
    depth (module docstring).

    Args:
        image_bgr: ``(H, W, 3)`` uint8, the size of ``camera``.
        body: the pair's body proxy (rig frame).
        sources: the source crop cameras (pinhole, rig frame), one per image of ``source_rgb``.
        source_rgb: ``(N, h, w, 3)`` float RGB in [0, 1], the crops the cameras describe.
        tolerance_m: a source sees a surface point when its own proxy depth there is this close.
        region: ``(H, W)`` bool, the only pixels that may be recoloured (default: all).
        max_angle_deg: recolour a pixel only when a source that sees its point looks at it within this
            angle of the view's ray (default: any).
        source_depth: the proxy's depth in each source camera, when the caller has it already
            (``proxy_depth(body, camera)``); default: ray-cast here.
        depth: the proxy's depth in ``camera``, when the caller has it already; default: ray-cast here
            (only the box of ``region`` when one is given).
    """
    image = np.asarray(image_bgr)
    if image.shape != (camera.height, camera.width, 3) or image.dtype != np.uint8:
        raise ShapeError(f"image must be uint8 {(camera.height, camera.width, 3)}, got {image.dtype} {image.shape}")
    if len(sources) != len(source_rgb):
        raise ShapeError(f"{len(sources)} source cameras for {len(source_rgb)} source images")
    if source_depth is not None and len(source_depth) != len(sources):
        raise ShapeError(f"{len(sources)} source cameras for {len(source_depth)} source depth maps")
    if region is not None:
        region = np.asarray(region, bool)
        if region.shape != image.shape[:2]:
            raise ShapeError(f"region must be {image.shape[:2]}, got {region.shape}")
    if depth is not None:
        depth = np.asarray(depth)
        if depth.shape != image.shape[:2]:
            raise ShapeError(f"depth must be {image.shape[:2]}, got {depth.shape}")
        covered = (depth > 0) if region is None else (depth > 0) & region
    elif region is None:
        depth = proxy_depth(body, camera)
        covered = depth > 0
    else:  # ray-cast only the region's box
        depth = np.zeros(region.shape)
        if region.any():
            rs, cs = np.nonzero(region.any(axis=1))[0], np.nonzero(region.any(axis=0))[0]
            r0, r1, c0, c1 = rs[0], rs[-1] + 1, cs[0], cs[-1] + 1
            depth[r0:r1, c0:c1] = proxy_depth(body, camera.cropped(c0, r0, c1 - c0, r1 - r0))
        covered = (depth > 0) & region
    if not covered.any():
        return ProxyBlend(image, covered, depth)
    rows, cols = np.nonzero(covered)
    z = depth[rows, cols]
    xy = camera.pixels_to_normalized(np.stack([cols, rows], -1).astype(np.float64))
    in_cam = np.concatenate([xy * z[:, None], z[:, None]], -1)
    points = (in_cam - camera.t) @ camera.R  # camera frame -> rig frame
    total = np.zeros((len(z), 3), np.float64)
    weight = np.zeros(len(z), np.float64)
    nearest = np.full(len(z), np.inf)  # the smallest angle of a source that sees the point
    # From each point to the view's centre is its pixel's ray reversed, whatever the depth: ``camera.center -
    # points`` was a zero vector for a point at the centre (a depth of 1e-300), and its 0/0 a NaN and a warning.
    ray = np.concatenate([xy, np.ones((len(z), 1))], -1) @ camera.R  # camera frame -> rig frame; |ray| >= 1
    to_view = -ray / np.linalg.norm(ray, axis=-1, keepdims=True)
    for k, (cam, rgb) in enumerate(zip(sources, source_rgb)):
        rgb = unit_rgb(rgb, f"source image {k}")
        if rgb.shape[:2] != (cam.height, cam.width):
            raise ShapeError(f"source image {rgb.shape[:2]} does not match its camera {(cam.height, cam.width)}")
        uv, zs = cam.project(points, distort=False)
        u = np.nan_to_num(uv[:, 0], nan=-1.0).astype(np.float32)
        v = np.nan_to_num(uv[:, 1], nan=-1.0).astype(np.float32)
        colour = sample_at(rgb, u, v, cv2.INTER_LINEAR)
        # full resolution: at half, visibility along the silhouettes' edges goes wrong
        own_depth = proxy_depth(body, cam) if source_depth is None else np.asarray(source_depth[k])
        if own_depth.shape != rgb.shape[:2]:
            raise ShapeError(f"source depth {own_depth.shape} does not match its camera {(cam.height, cam.width)}")
        own = sample_at(own_depth.astype(np.float32), u, v, cv2.INTER_NEAREST)
        inside = (u >= 0) & (u <= cam.width - 1) & (v >= 0) & (v <= cam.height - 1)
        sees = inside & (zs > 0) & (np.abs(own - zs) < tolerance_m)
        to_source = cam.center - points
        length = np.linalg.norm(to_source, axis=-1)
        # a point at the source's centre (length 0) has no direction to it, and the source does not see it (zs 0)
        cos = np.divide(np.sum(to_view * to_source, axis=-1), length, out=np.zeros_like(length), where=length > 0)
        angle = np.arccos(np.clip(cos, -1.0, 1.0))
        w = np.where(sees, 1.0 / (angle + ANGLE_FLOOR_RAD), 0.0)
        nearest = np.where(sees, np.minimum(nearest, angle), nearest)
        total += w[:, None] * colour
        weight += w
    seen = (weight > 0) & (nearest <= np.deg2rad(max_angle_deg))
    out = image.copy()
    blended = total[seen] / weight[seen, None]  # RGB
    out[rows[seen], cols[seen]] = np.round(np.clip(blended[:, ::-1], 0.0, 1.0) * 255.0).astype(np.uint8)
    replaced = np.zeros_like(covered)
    replaced[rows[seen], cols[seen]] = True
    return ProxyBlend(out, replaced, depth)
