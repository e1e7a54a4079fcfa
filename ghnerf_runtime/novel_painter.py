"""A learnt painter of the novel view's subject: repaints the rendered picture over the body proxy.

GHNeRF's colour is a blend of the two source images: it cannot show a surface neither camera sees,
and on views from round the subject that is most of it. The painter (``novel_painter.onnx`` beside
the model's graphs; trained and exported by ``python -m training.learnt_fill``) is a small U-Net
that reads what the device knows at the view, all placed by the body proxy of the pair's 3D joints
(``ghnerf_runtime.body_proxy``), and returns the picture plus a learnt residual colour:

* the two sources' colours where the proxy's surface projects into them, averaged over the sources
  that see it there (their own proxy depth within ``tolerance_m``), the plain average elsewhere;
* the proxy's silhouette, which of its pixels some source sees, its camera-frame normals and its
  depth about the median;
* the 3D joints projected into the view (the graph draws a Gaussian at each);
* the rendered picture itself (the residual's base).

:func:`painter_planes` builds the image planes here in numpy exactly as the training caches hold
them (``training.fill_features``: the same rounding to 8 bits, normals to int8, depth to float16),
so the network sees on the device what it saw in training; a test checks the two agree. Measured in
docs/novel-view.md, "The learnt painter".

onnxruntime and numpy only; never torch.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ghnerf_runtime.body25 import NUM_JOINTS
from ghnerf_runtime.body_proxy import BodyProxy, proxy_depth
from ghnerf_runtime.errors import ModelContractError, ModelLoadError, ModelRunError, ShapeError
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.surface import surface_mask, surface_normals
from ghnerf_runtime.onnx_file import onnx_metadata, open_onnx_file, ort_reason, stale_int8_reason, warn_stale_int8
from ghnerf_runtime.proxy_blend import unit_rgb

__all__ = ["FEATURE_VERSION", "FILE_NAME", "INT8_FILE_NAME", "META_PREFIX", "INPUTS", "OUTPUT", "PLANES", "PainterPlanes",
           "painter_planes", "depth_about_median", "float16_depth", "F16_MAX", "angle_from_sources_deg",
           "angle_from_centres_deg",
           "NovelPainter"]

#: Bump when a plane's meaning changes: a file trained on other planes is refused.
FEATURE_VERSION = 1
FILE_NAME = "novel_painter.onnx"
#: Its static int8 QDQ twin (the convolutions), about twice as fast on two cores (docs/novel-view.md).
INT8_FILE_NAME = "novel_painter.int8.onnx"
META_PREFIX = "ghnerf_painter."
#: ``planes`` ``(N, 12, H, W)`` in this order, and ``joints`` ``(N, 25, 3)`` (u, v, valid); ``rgb`` out.
PLANES = ("blend_r", "blend_g", "blend_b", "mask", "seen", "normal_x", "normal_y", "normal_z", "depth",
          "shown_r", "shown_g", "shown_b")
INPUTS = ("planes", "joints")
OUTPUT = "rgb"
#: The largest finite float16: the depth plane is held as float16, as the caches hold it.
F16_MAX = float(np.finfo(np.float16).max)
#: The sha256 of the fp32 painter file an int8 one was quantized from (``quantize_painter`` records it): where the
#: int8 file has it, it alone says whether the fp32 file beside it is that file (``onnx_file.stale_int8_reason``).
FP32_SHA256_KEY = META_PREFIX + "fp32_sha256"
#: What ``training.learnt_fill.quantize_painter`` adds to the fp32 file's metadata in the int8 one; the rest is carried
#: over, so an int8 file whose rest differs from the fp32 painter's was quantized from another painter.
_INT8_ONLY_KEYS = frozenset({META_PREFIX + "precision", META_PREFIX + "calibration_views", FP32_SHA256_KEY})
#: The training record ``export_painter`` writes (with the net's shape): without it the metadata link nothing.
_RECORD_KEY = META_PREFIX + "steps"


def float16_depth(rel: np.ndarray) -> np.ndarray:
    """The depth plane as float16, clipped first to float16's largest finite value: a surface over 65 km from the
    median (a wild joint's ellipsoid) became inf, and the painter's answer NaN; so is an infinite one (+-inf to
    +-65504). A NaN (no depth known there) becomes 0, the plane's value off the subject ("no depth"): clip kept
    it, and one NaN pixel spread through the convolutions into a NaN patch of the picture. Shared with the
    training caches (``training.fill_features``), so the network sees on the device what it saw in training."""
    return np.clip(np.nan_to_num(rel, nan=0.0, posinf=F16_MAX, neginf=-F16_MAX), -F16_MAX, F16_MAX).astype(np.float16)


def depth_about_median(depth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``(H, W)`` float64: camera z minus its median over the subject's (``mask``) finite depths, 0 off the subject;
    a pixel of the subject without a finite depth keeps it (NaN, +-inf: :func:`float16_depth` makes them 0 and
    +-65504). One NaN inside the mask made the median NaN, so the whole subject's plane became 0; an inf counted
    in it moved it. Shared with the training caches (``training.fill_features``), so both take the same median.

    Raises:
        ShapeError: ``depth`` and ``mask`` differ in shape.
    """
    depth, mask = np.asarray(depth, np.float64), np.asarray(mask, bool)
    if depth.shape != mask.shape:
        raise ShapeError(f"depth {depth.shape} and subject mask {mask.shape} must have the same shape")
    known = mask & np.isfinite(depth)
    if not known.any():  # nothing to measure from: no depth plane
        return np.zeros(depth.shape)
    return np.where(mask, depth - np.median(depth[known]), 0.0)


def _u8(rgb: np.ndarray) -> np.ndarray:
    """Rounded to 8 bits and back: the caches store colours as uint8."""
    return np.round(np.clip(rgb, 0.0, 1.0) * 255.0) / 255.0


@dataclass(frozen=True, eq=False)
class PainterPlanes:
    """One view's inputs: ``planes`` ``(12, H, W)`` float32 (:data:`PLANES`), ``joints`` ``(25, 3)``
    float32, and the proxy's silhouette ``mask`` ``(H, W)`` bool."""

    planes: np.ndarray
    joints: np.ndarray
    mask: np.ndarray


def angle_from_sources_deg(view: Camera, sources: Sequence[Camera], joints: np.ndarray, valid: np.ndarray) -> float:
    """The angle (degrees) at the subject's centre (the mean of its known joints) between ``view``'s centre and
    the nearest source camera's: ``ghnerf-eval``'s angle bins (:func:`angle_from_centres_deg`, the rule)."""
    return angle_from_centres_deg(view.center, [c.center for c in sources], joints, valid)


def angle_from_centres_deg(view_centre: np.ndarray, source_centres: Sequence[np.ndarray], joints: np.ndarray,
                           valid: np.ndarray) -> float:
    """The angle (degrees) at the subject's centre (the mean of its known joints) between the camera centre
    ``view_centre`` and the nearest of ``source_centres``. NaN without a known joint (a NaN joint marked
    valid is not known: its NaN would make the angle NaN, which passes every ``<`` gate).

    A camera standing exactly at the centre sees the subject from no side: a source there is left out, and a
    view there (or with no source left) is at angle 0, as near a source as can be, so the painter's
    ``painter_min_angle_deg`` gate keeps the rendered picture (it ran on such a view: the direction's
    normalisation gave NaN, which passed the gate). ``training.evaluate.source_angles_deg`` uses this rule too."""
    joints = np.asarray(joints, np.float64)
    valid = np.asarray(valid, bool) & np.isfinite(joints).all(axis=-1)
    if not valid.any():
        return float("nan")
    centre = joints[valid].mean(axis=0)
    dirs = np.array([np.asarray(c, np.float64) - centre for c in (view_centre, *source_centres)])
    # scaled by the largest coordinate first: a direction of 1e-200 m squared underflowed to a norm of 0
    scale = np.abs(dirs).max(axis=-1, keepdims=True)
    placed = scale[:, 0] > 0.0
    if not placed[0] or not placed[1:].any():
        return 0.0
    dirs = dirs[placed] / scale[placed]
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    return float(np.degrees(np.arccos(np.clip(dirs[1:] @ dirs[0], -1.0, 1.0).max())))


def painter_planes(shown_rgb: np.ndarray, camera: Camera, depth: np.ndarray, sources: Sequence[Camera],
                   source_rgb: np.ndarray, source_depth: Sequence[np.ndarray], joints: np.ndarray,
                   valid: np.ndarray, tolerance_m: float = 0.03) -> PainterPlanes:
    """The painter's inputs at one view (module docstring).

    Args:
        shown_rgb: ``(H, W, 3)`` the rendered picture, RGB in [0, 1].
        camera: the view's pinhole camera (rig frame), ``H x W``.
        depth: ``(H, W)`` the proxy's camera-z depth in ``camera`` (0 where it covers nothing).
        sources: the source crop cameras (pinhole), one per image of ``source_rgb`` ``(S, h, w, 3)`` RGB
            in [0, 1]; ``source_depth`` the proxy's depth in each.
        joints, valid: the pair's 3D joints ``(25, 3)`` (rig frame) and which are known.
        tolerance_m: a source sees a surface point when its own proxy depth there is this close.
    """
    H, W = camera.height, camera.width
    shown = unit_rgb(shown_rgb, "picture").astype(np.float64)
    depth = np.asarray(depth, np.float64)
    if shown.shape != (H, W, 3) or depth.shape != (H, W):
        raise ShapeError(f"picture {shown.shape} and depth {depth.shape} must be {(H, W, 3)} and {(H, W)}")
    if not (len(sources) == len(source_rgb) == len(source_depth)) or not len(sources):
        raise ShapeError(f"{len(sources)} source cameras, {len(source_rgb)} images, {len(source_depth)} depth maps")
    joints, valid = np.asarray(joints, np.float64), np.asarray(valid, bool)
    if joints.shape != (NUM_JOINTS, 3) or valid.shape != (NUM_JOINTS,):
        raise ShapeError(f"joints must be ({NUM_JOINTS}, 3) with ({NUM_JOINTS},) valid, got {joints.shape}, {valid.shape}")
    mask = surface_mask(depth)  # a NaN depth is no surface: off, as the training caches make it
    # Every pixel unprojected at its depth (off the proxy: the camera centre, as the caches do); a NaN or
    # infinite depth has no position (NaN: no source colour, no normal), as the caches' unproject gives it.
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    xy = camera.pixels_to_normalized(np.stack([u, v], -1).reshape(-1, 2)).reshape(H, W, 2)
    placed = np.where(np.isfinite(depth), depth, np.nan)
    points = ((np.concatenate([xy, np.ones((H, W, 1))], -1) * placed[..., None]) - camera.t) @ camera.R
    flat = points.reshape(-1, 3)
    colours, sees = [], []
    for k, (cam, rgb, own_depth) in enumerate(zip(sources, source_rgb, source_depth)):
        rgb = unit_rgb(rgb, f"source image {k}")
        if rgb.shape[:2] != (cam.height, cam.width) or np.shape(own_depth) != rgb.shape[:2]:
            raise ShapeError(f"source image {rgb.shape[:2]} / depth {np.shape(own_depth)} do not match its camera "
                             f"{(cam.height, cam.width)}")
        uv, z = cam.project(flat, distort=False)
        su = np.nan_to_num(uv[:, 0], nan=-1.0).astype(np.float32).reshape(H, W)
        sv = np.nan_to_num(uv[:, 1], nan=-1.0).astype(np.float32).reshape(H, W)
        z = z.reshape(H, W)
        colours.append(cv2.remap(rgb, su, sv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT))
        own = cv2.remap(np.asarray(own_depth, np.float32), su, sv, cv2.INTER_NEAREST,
                        borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        inside = (su >= 0) & (su <= cam.width - 1) & (sv >= 0) & (sv <= cam.height - 1) & (z > 0)
        sees.append(inside & (np.abs(own - z) < tolerance_m))
    c, w = np.stack(colours), np.stack(sees).astype(np.float32)[..., None]
    n = w.sum(0)
    blend = np.where(n > 0, (c * w).sum(0) / np.maximum(n, 1.0), c.mean(0))
    seen = mask & (n[..., 0] > 0)
    normals = surface_normals(points, mask, camera.center) @ camera.R.T  # rig frame -> camera frame
    normals = np.round(np.where(mask[..., None], normals, 0.0) * 127.0) / 127.0
    rel = depth_about_median(depth, mask)
    planes = np.concatenate([_u8(blend), mask[..., None], seen[..., None], normals,
                             float16_depth(rel)[..., None], _u8(shown)], -1)
    ju, jz = camera.project(joints, distort=False)
    ok = valid & (np.nan_to_num(jz) > 0) & np.all(np.isfinite(ju), axis=-1)  # NaN: no pixel (Camera.project)
    j = np.stack([np.where(ok, np.nan_to_num(ju[:, 0]), 0.0), np.where(ok, np.nan_to_num(ju[:, 1]), 0.0), ok], -1)
    return PainterPlanes(np.ascontiguousarray(planes.transpose(2, 0, 1), np.float32), j.astype(np.float32), mask)


def _record_differs(int8_meta: dict[str, str], fp32_meta: dict[str, str]) -> list[str] | None:
    """The metadata keys (without the prefix) in which an int8 painter's record differs from the fp32 painter's;
    None where the fp32 file records no training (a hand-made file): the metadata then link nothing."""
    if _RECORD_KEY not in fp32_meta:
        return None
    keys = sorted((set(int8_meta) | set(fp32_meta)) - _INT8_ONLY_KEYS)
    return [k.removeprefix(META_PREFIX) for k in keys if int8_meta.get(k) != fp32_meta.get(k)]


class NovelPainter:
    """A loaded ``novel_painter.onnx``: :meth:`paint` returns the repainted picture."""

    def __init__(self, session, path: Path, meta: dict[str, str]) -> None:
        self._session = session
        self.path = path
        self.meta = meta
        self.precision = meta.get(META_PREFIX + "precision", "fp32")

    @staticmethod
    def find(folder: str | Path, precision: str = "auto") -> Path | None:
        """The painter file of a model folder: the int8 one for ``precision`` ``auto`` or ``int8`` when the
        folder has it (a convolution network: int8 pays, as for the encoder), else the fp32 one; None
        without either."""
        folder = Path(folder)
        names = (INT8_FILE_NAME, FILE_NAME) if precision in ("auto", "int8") else (FILE_NAME,)
        return next((folder / n for n in names if (folder / n).is_file()), None)

    @staticmethod
    def choose(folder: str | Path, precision: str = "auto") -> Path | None:
        """The painter file to load: :meth:`find`'s, or the fp32 one where the int8 file beside it was not
        quantized from it (a folder exported before session 73 keeps the int8 file of the painter an export
        replaced), with one warning naming both and the command that quantizes it again. The fp32 file's sha256 the
        int8 file records decides where it has one; else their metadata (``quantize_painter`` carries the fp32
        file's over), their times where the files record no training."""
        folder = Path(folder)
        path, fp32 = NovelPainter.find(folder, precision), folder / FILE_NAME
        if path is None or path.name != INT8_FILE_NAME or not fp32.is_file():
            return path
        try:
            int8_meta, fp32_meta = (onnx_metadata(f, "novel-view painter") for f in (path, fp32))
        except ModelLoadError:  # not ours to judge here: the int8 file is loaded, as before, and names its error
            return path
        reason = stale_int8_reason(path, fp32, _record_differs(int8_meta, fp32_meta), int8_meta.get(FP32_SHA256_KEY))
        if reason is None:
            return path
        net = fp32_meta.get(META_PREFIX + "trained_on") or "NET.pt"
        warn_stale_int8(folder, [(path, fp32, reason)], f"python -m training.learnt_fill export --net {net} "
                        f"--out {fp32} --calib-cache TRAINING_CACHE.npz")
        return fp32

    @classmethod
    def load(cls, path: str | Path, threads: int = 1) -> "NovelPainter":
        path = Path(path)
        sess, meta = open_onnx_file(path, threads, "novel-view painter")
        key = META_PREFIX + "feature_version"
        if meta.get(key) != str(FEATURE_VERSION):
            raise ModelContractError(f"feature version {meta.get(key)!r}; this runtime builds version "
                                     f"{FEATURE_VERSION}", path=str(path), key=key)
        ins = {i.name: i.shape for i in sess.get_inputs()}
        if (set(ins) != set(INPUTS) or len(ins["planes"]) != 4 or len(ins["joints"]) != 3  # ranks before sizes
                or ins["planes"][1] != len(PLANES) or list(ins["joints"][1:]) != [NUM_JOINTS, 3]):
            raise ModelContractError(f"inputs planes (N, {len(PLANES)}, H, W) and joints (N, {NUM_JOINTS}, 3) "
                                     f"expected, the file has {ins}", path=str(path), key="planes")
        if OUTPUT not in {o.name for o in sess.get_outputs()}:
            raise ModelContractError(f"output {OUTPUT!r} expected", path=str(path), key=OUTPUT)
        return cls(sess, path, meta)

    def paint(self, inputs: PainterPlanes) -> np.ndarray:
        """``(H, W, 3)`` RGB float32 in [0, 1]: the picture (the inputs' ``shown`` planes) repainted."""
        try:
            rgb = self._session.run([OUTPUT], {"planes": inputs.planes[None], "joints": inputs.joints[None]})[0]
        except Exception as e:  # onnxruntime's own exception types
            raise ModelRunError(f"painter failed: {type(e).__name__}: {ort_reason(e, 200)}", path=str(self.path)) from e
        if not np.isfinite(rgb).all():
            raise ModelRunError("painter returned non-finite colours", path=str(self.path))
        want = (1, 3) + inputs.planes.shape[1:]
        if rgb.shape != want:  # else repaint's indexing fails with an IndexError far from the cause
            raise ModelRunError(f"painter returned {OUTPUT!r} of shape {rgb.shape}, expected {want}",
                                path=str(self.path))
        # clipped: a residual overshooting [0, 1] (a file exported without the clamp) wrapped round in uint8
        return np.ascontiguousarray(np.clip(rgb[0].transpose(1, 2, 0), 0.0, 1.0), np.float32)

    def repaint(self, image_bgr: np.ndarray, camera: Camera, body: BodyProxy, sources: Sequence[Camera],
                source_rgb: np.ndarray, joints: np.ndarray, valid: np.ndarray, tolerance_m: float = 0.03,
                region: np.ndarray | None = None, margin_px: int = 24,
                source_depth: Sequence[np.ndarray] | None = None,
                depth: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The rendered view ``image_bgr`` (uint8, at pinhole ``camera``) repainted over the pair's body proxy
        ``body``; returns the image and the ``(H, W)`` pixels it changed.

        Only the box around the proxy's silhouette and ``region`` (the pixels the picture shows as the
        subject), ``margin_px`` wider and rounded up to a multiple of 8 (the network's coarsest level),
        is painted, and only the proxy's and the region's pixels inside it change: elsewhere the
        network was never asked for a colour. ``source_depth`` and ``depth``: the proxy's depth in each
        source and in ``camera``, when the caller has them already (default: ray-cast here)."""
        image = np.asarray(image_bgr)
        H, W = camera.height, camera.width
        if image.shape != (H, W, 3) or image.dtype != np.uint8:
            raise ShapeError(f"image must be uint8 {(H, W, 3)}, got {image.dtype} {image.shape}")
        depth = proxy_depth(body, camera) if depth is None else np.asarray(depth)
        if depth.shape != (H, W):
            raise ShapeError(f"depth must be {(H, W)}, got {depth.shape}")
        if region is not None:
            region = np.asarray(region, bool)
            if region.shape != (H, W):  # a row of H flags broadcast over the view and painted all of it
                raise ShapeError(f"region must be {(H, W)}, got {region.shape}")
        keep = depth > 0 if region is None else (depth > 0) | region
        if not (depth > 0).any():
            return image, np.zeros((H, W), bool)
        rs, cs = np.nonzero(keep.any(axis=1))[0], np.nonzero(keep.any(axis=0))[0]
        box = []
        for a, b, size in ((rs[0], rs[-1] + 1, H), (cs[0], cs[-1] + 1, W)):
            lo, hi = max(a - margin_px, 0), min(b + margin_px, size)
            length = -(-(hi - lo) // 8) * 8
            if length >= size:
                lo, hi = 0, size
            else:
                lo = min(lo, size - length)
                hi = lo + length
            box.append((lo, hi))
        (r0, r1), (c0, c1) = box
        crop = camera.cropped(c0, r0, c1 - c0, r1 - r0)
        shown = image[r0:r1, c0:c1, ::-1].astype(np.float64) / 255.0
        src_depth = [proxy_depth(body, c) for c in sources] if source_depth is None else source_depth
        planes = painter_planes(shown, crop, depth[r0:r1, c0:c1], sources, source_rgb, src_depth, joints, valid,
                                tolerance_m)
        painted = self.paint(planes)
        out = image.copy()
        changed = np.zeros((H, W), bool)
        changed[r0:r1, c0:c1] = keep[r0:r1, c0:c1]
        sel = changed[r0:r1, c0:c1]
        out[r0:r1, c0:c1][sel] = np.round(painted[sel][:, ::-1] * 255.0).astype(np.uint8)
        return out, changed
