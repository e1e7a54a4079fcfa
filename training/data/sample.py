"""One multi-view training sample: the in-memory structure shared by every data source.

A :class:`Sample` is one instant of one subject seen by ``V`` views. Views ``0`` and ``1``
are the two **source** cameras (what the device's rig sees); views ``2 .. V-1`` are
**novel** target cameras. Every view is a square **crop camera** of ``S x S`` pixels
(``ghnerf_runtime.preprocess.crop_camera``: undistorted pinhole, cropped to a ROI of
the full camera image, resized), exactly what the runtime feeds the model.

Conventions (restated in ``docs/dataset.md``):

* rig frame: metres; extrinsics map rig points into the camera, ``X_cam = R X + t``;
* pixels: centres at integer coordinates (OpenCV), in crop (model-input) pixels;
* images: **RGB** uint8 (the model contract wants RGB; OpenCV frames are BGR);
* depth: camera-z metres; ``0`` where there is no depth (background, or a source
  without depth: ``has_depth`` False);
* joints: 25 BODY_25 joints (``ghnerf_runtime.body25``).

:func:`sample_to_arrays` / :func:`arrays_to_sample` convert to and from the flat array
record that the cache stores (:data:`FIELDS` is its schema). Pure numpy.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from ghnerf_runtime.body25 import NUM_JOINTS
from ghnerf_runtime.geometry import Camera
from ghnerf_runtime.preprocess import Roi
from training.data.errors import DataError

#: Number of source views; they come first in :attr:`Sample.views`.
NUM_SOURCES = 2
J = NUM_JOINTS


@dataclass(frozen=True, eq=False)
class ViewData:
    """One view of a sample, at the crop resolution ``S``.

    Attributes:
        name: view name (``"src0"``, ``"src1"``, ``"novel0"``...; for recorded data the camera).
        image: ``(S, S, 3)`` uint8, **RGB**.
        mask: ``(S, S)`` bool subject mask.
        depth: ``(S, S)`` float16 camera-z depth in metres, ``0`` outside the mask or when
            ``has_depth`` is False.
        has_depth: whether ``depth`` holds real values (synthetic: yes; ZJU-MoCap: no).
        joints_2d: ``(25, 2)`` float32 BODY_25 joints in crop pixels (``0`` where the joint is
            behind the camera or unknown).
        visible: ``(25,)`` bool: inside the crop, in front of the camera and, where the source
            knows it, not occluded by the body.
        K, R, t: the crop camera (``(3, 3)``, ``(3, 3)``, ``(3,)`` float64; no distortion).
        roi: the crop window in the full camera's undistorted pixels.
        roi_from_volume: the ROI came from the working volume (cold start), not from joints.
        full_K: ``(3, 3)`` intrinsics of the full camera the crop was taken from.
        full_size: ``(width, height)`` of that full camera image.
    """

    name: str
    image: np.ndarray
    mask: np.ndarray
    depth: np.ndarray
    has_depth: bool
    joints_2d: np.ndarray
    visible: np.ndarray
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    roi: Roi
    roi_from_volume: bool
    full_K: np.ndarray
    full_size: tuple[int, int]

    @property
    def resolution(self) -> int:
        return int(self.image.shape[0])

    def camera(self) -> Camera:
        """The crop camera as a :class:`Camera` (``S x S``, no distortion)."""
        S = self.resolution
        return Camera(self.name, S, S, self.K, np.zeros(5), self.R, self.t)


@dataclass(frozen=True, eq=False)
class Sample:
    """One instant of one subject in ``V`` views (sources first).

    Attributes:
        views: the views; ``views[:NUM_SOURCES]`` are the source cameras.
        joints_3d: ``(25, 3)`` float64 BODY_25 joints in the rig frame (metres).
        joints_3d_valid: ``(25,)`` bool (all True for synthetic data).
        bbox: ``(2, 3)`` float64 axis-aligned box ``(min, max)`` of the subject in the rig frame,
            synthetic: the exact body surface, no margin; ZJU-MoCap: the joints' box grown by
            ``bbox_margin_m`` (``docs/dataset.md``).
        metadata: JSON-serialisable facts about where the sample came from.
    """

    views: tuple[ViewData, ...]
    joints_3d: np.ndarray
    joints_3d_valid: np.ndarray
    bbox: np.ndarray
    metadata: dict = field(default_factory=dict)

    @property
    def num_views(self) -> int:
        return len(self.views)

    @property
    def resolution(self) -> int:
        return self.views[0].resolution


# ------------------------------------------------------------------ array record
#: Stored arrays of one sample: name -> (shape as a function of (V, S), dtype). The cache
#: stacks them over samples (leading axis). Masks are bit-packed along the last axis
#: (``np.packbits``), so ``S`` must be a multiple of 8.
FIELDS: dict[str, tuple[Callable[[int, int], tuple[int, ...]], np.dtype]] = {
    "images": (lambda V, S: (V, S, S, 3), np.dtype(np.uint8)),
    "masks": (lambda V, S: (V, S, S // 8), np.dtype(np.uint8)),
    "depth": (lambda V, S: (V, S, S), np.dtype(np.float16)),
    "has_depth": (lambda V, S: (V,), np.dtype(np.bool_)),
    "joints_2d": (lambda V, S: (V, J, 2), np.dtype(np.float32)),
    "visible": (lambda V, S: (V, J), np.dtype(np.bool_)),
    "K": (lambda V, S: (V, 3, 3), np.dtype(np.float64)),
    "R": (lambda V, S: (V, 3, 3), np.dtype(np.float64)),
    "t": (lambda V, S: (V, 3), np.dtype(np.float64)),
    "roi": (lambda V, S: (V, 3), np.dtype(np.int32)),
    "roi_from_volume": (lambda V, S: (V,), np.dtype(np.bool_)),
    "full_K": (lambda V, S: (V, 3, 3), np.dtype(np.float64)),
    "full_size": (lambda V, S: (V, 2), np.dtype(np.int32)),
    "joints_3d": (lambda V, S: (J, 3), np.dtype(np.float64)),
    "joints_3d_valid": (lambda V, S: (J,), np.dtype(np.bool_)),
    "bbox": (lambda V, S: (2, 3), np.dtype(np.float64)),
}


def field_shape(name: str, num_views: int, resolution: int) -> tuple[int, ...]:
    return FIELDS[name][0](num_views, resolution)


def sample_to_arrays(sample: Sample) -> dict[str, np.ndarray]:
    """The flat array record of ``sample`` (shapes and dtypes of :data:`FIELDS`)."""
    check_sample(sample)
    v = sample.views
    out = {
        "images": np.stack([x.image for x in v]),
        "masks": np.packbits(np.stack([x.mask for x in v]), axis=-1),
        "depth": np.stack([x.depth for x in v]).astype(np.float16),
        "has_depth": np.array([x.has_depth for x in v], dtype=bool),
        "joints_2d": np.stack([x.joints_2d for x in v]).astype(np.float32),
        "visible": np.stack([x.visible for x in v]).astype(bool),
        "K": np.stack([x.K for x in v]),
        "R": np.stack([x.R for x in v]),
        "t": np.stack([x.t for x in v]),
        "roi": np.array([[x.roi.x0, x.roi.y0, x.roi.size] for x in v], dtype=np.int32),
        "roi_from_volume": np.array([x.roi_from_volume for x in v], dtype=bool),
        "full_K": np.stack([x.full_K for x in v]),
        "full_size": np.array([x.full_size for x in v], dtype=np.int32),
        "joints_3d": np.asarray(sample.joints_3d, dtype=np.float64),
        "joints_3d_valid": np.asarray(sample.joints_3d_valid, dtype=bool),
        "bbox": np.asarray(sample.bbox, dtype=np.float64),
    }
    return {k: np.ascontiguousarray(a, dtype=FIELDS[k][1]) for k, a in out.items()}


def arrays_to_sample(arrays: Mapping[str, np.ndarray], view_names: tuple[str, ...], metadata: dict | None = None) -> Sample:
    """Inverse of :func:`sample_to_arrays` (masks are unpacked)."""
    masks = np.unpackbits(np.asarray(arrays["masks"]), axis=-1).astype(bool)
    views = []
    for i, name in enumerate(view_names):
        x0, y0, size = (int(c) for c in arrays["roi"][i])
        views.append(ViewData(
            name=name, image=np.asarray(arrays["images"][i]), mask=masks[i], depth=np.asarray(arrays["depth"][i]),
            has_depth=bool(arrays["has_depth"][i]), joints_2d=np.asarray(arrays["joints_2d"][i]),
            visible=np.asarray(arrays["visible"][i]), K=np.asarray(arrays["K"][i]), R=np.asarray(arrays["R"][i]),
            t=np.asarray(arrays["t"][i]), roi=Roi(x0, y0, size), roi_from_volume=bool(arrays["roi_from_volume"][i]),
            full_K=np.asarray(arrays["full_K"][i]), full_size=tuple(int(c) for c in arrays["full_size"][i]),
        ))
    return Sample(tuple(views), np.asarray(arrays["joints_3d"]), np.asarray(arrays["joints_3d_valid"]),
                  np.asarray(arrays["bbox"]), dict(metadata or {}))


def check_sample(sample: Sample) -> None:
    """Raise :class:`DataError` unless every array of ``sample`` has its documented shape."""
    if len(sample.views) < NUM_SOURCES:
        raise DataError(f"a sample needs at least {NUM_SOURCES} views, got {len(sample.views)}")
    S = sample.views[0].image.shape[0]
    if S % 8:
        raise DataError(f"resolution must be a multiple of 8 (masks are bit-packed), got {S}")
    expect: dict[str, tuple[Any, ...]] = {
        "image": (S, S, 3), "mask": (S, S), "depth": (S, S), "joints_2d": (J, 2), "visible": (J,),
        "K": (3, 3), "R": (3, 3), "t": (3,), "full_K": (3, 3),
    }
    for view in sample.views:
        for name, shape in expect.items():
            got = np.shape(getattr(view, name))
            if got != shape:
                raise DataError(f"view {view.name!r}: {name} must have shape {shape}, got {got}")
        if view.image.dtype != np.uint8 or view.mask.dtype != np.bool_:
            raise DataError(f"view {view.name!r}: image must be uint8 and mask bool, got {view.image.dtype}, {view.mask.dtype}")
    for name, shape in (("joints_3d", (J, 3)), ("joints_3d_valid", (J,)), ("bbox", (2, 3))):
        if np.shape(getattr(sample, name)) != shape:
            raise DataError(f"sample {name} must have shape {shape}, got {np.shape(getattr(sample, name))}")


__all__ = ["NUM_SOURCES", "FIELDS", "ViewData", "Sample", "field_shape", "sample_to_arrays", "arrays_to_sample",
           "check_sample"]
