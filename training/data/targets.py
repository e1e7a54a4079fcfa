"""Model inputs and training targets of one stored sample (numpy, torch-free).

Turns a cached record (``ShardedSplit.arrays``) into the arrays the model and the
losses take, under the model contract's names (``ghnerf_runtime.contract``), with the
contract's own host-side helpers for every camera matrix. Heatmaps are made here, on
the fly, from the stored 2D joints (``ghnerf_runtime.metrics.gaussian_heatmaps``); they
are never stored. See :data:`KEYS` for shapes, dtypes and units.

With ``TargetConfig.frame_padding`` the source images (``images``, the model's inputs) show the runtime's
black padding where their crop reaches past the camera's frame (``training.data.frame_padding``), and
``frame`` (:data:`FRAME_KEY`) holds every view's share of frame, for the encoder's other inputs
(``training.train.aux_encoder_batch``, ``training.pretrain_human.view_batch``); the targets
(``tgt_images`` and the rest) keep the whole picture.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Mapping

import numpy as np

from ghnerf_runtime import contract as C
from ghnerf_runtime.keypoints import model_to_heatmap_pixels
from ghnerf_runtime.metrics import gaussian_heatmaps
from ghnerf_runtime.preprocess import Roi
from training.data.errors import DataConfigError
from training.data.frame_padding import cut_frame, frame_coverage
from training.data.sample import NUM_SOURCES

#: Output keys: shape (V views incl. the 2 sources, S resolution, h = S / heatmap_stride), dtype, meaning.
KEYS: dict[str, tuple[str, str, str]] = {
    "images": ("(2, 3, S, S)", "float32", "source images, RGB in [0, 1] (views 0 and 1)"),
    "src_P": ("(2, 3, 4)", "float32", "K [R | t] of each source crop camera"),
    "src_centers": ("(2, 3)", "float32", "source camera centres, rig frame, metres"),
    "tgt_images": ("(V, 3, S, S)", "float32", "target images, RGB in [0, 1] (targets 0, 1 are the sources)"),
    "tgt_masks": ("(V, S, S)", "bool", "subject masks"),
    "tgt_depth": ("(V, S, S)", "float32", "camera-z depth, metres; 0 = none (background or no depth)"),
    "tgt_has_depth": ("(V,)", "bool", "depth is real for this view (False for ZJU-MoCap)"),
    "tgt_joints_2d": ("(V, 25, 2)", "float32", "BODY_25 joints, crop (model-input) pixels, centres at integers"),
    "tgt_visible": ("(V, 25)", "bool", "joint inside the crop, in front and (synthetic) unoccluded"),
    "tgt_heatmaps": ("(V, 25, h, h)", "float32", "Gaussian heatmaps (peak 1) of visible joints, heatmap pixels"),
    "tgt_K": ("(V, 3, 3)", "float32", "intrinsics of each target crop camera"),
    "tgt_K_inv": ("(V, 3, 3)", "float32", "inverse intrinsics (contract.target_inputs)"),
    "tgt_c2w": ("(V, 3, 4)", "float32", "[R^T | centre], camera -> rig (contract.target_inputs)"),
    "tgt_P": ("(V, 3, 4)", "float32", "K [R | t] of each target (contract.target_projections)"),
    "near_far": ("(V, 2)", "float32", "depth range of the subject box grown by near_far_margin_m"),
    "tgt_is_source": ("(V,)", "bool", "the target is a source camera"),
    "joints_3d": ("(25, 3)", "float32", "BODY_25 joints, rig frame, metres"),
    "joints_3d_valid": ("(25,)", "bool", "3D joint known"),
    "bbox": ("(2, 3)", "float32", "subject box (min, max), rig frame, metres (synthetic: exact, no margin; "
                                  "ZJU-MoCap: the joints' box grown by bbox_margin_m)"),
}

#: With ``TargetConfig.frame_padding`` only: ``(V, S, S)`` float32, each pixel's share of its camera's frame
#: (0 in the runtime's black padding past the frame's edge, 1 inside; ``frame_padding.frame_coverage``).
FRAME_KEY = "frame"
#: Seed stream of ``TargetConfig.edge_cut``'s draws (with the sample index).
EDGE_CUT_STREAM = 55
#: Range of the share of the crop's side a cut puts past the frame: 0.25, the person's box at the edge, to 0.5,
#: through its middle (``benchmarks/measure_edge_padding.py``: the runtime's crops there are 34-38 % black).
EDGE_CUT_BAND = (0.25, 0.5)


@dataclass(frozen=True)
class TargetConfig:
    """How targets are made from a stored sample.

    Attributes:
        heatmap_stride: model pixels per heatmap pixel (the model's ``heatmap_stride``, the
            contract's ``ray_grid`` stride); ``0`` leaves ``tgt_heatmaps`` out.
        heatmap_sigma: Gaussian standard deviation **in heatmap pixels** (1.5 at stride 4 is
            6 model pixels, ~5% of a 128 crop).
        near_far_margin_m: metres added around the subject box before taking its depth range
            (ENeRF uses 0.1 on ZJU-MoCap).
        frame_padding: black out what each crop shows past its camera's frame in the model's inputs,
            as the runtime pads such a crop (module docstring). Off by default: a config that does not
            say it trains as before.
        edge_cut: with ``frame_padding``, the share of source views whose frame is cut on its left or
            right so that 25-50 % of the crop lies past it (``frame_padding.cut_frame``): the person at the
            frame's edge, which the training scenes never place there. The draw is a function of the
            sample's index (:data:`EDGE_CUT_STREAM`), the same in every epoch. 0: none.
    """

    heatmap_stride: int = 4
    heatmap_sigma: float = 1.5
    near_far_margin_m: float = 0.1
    frame_padding: bool = False
    edge_cut: float = 0.0

    def __post_init__(self) -> None:
        s = self.heatmap_stride
        if isinstance(s, bool) or not isinstance(s, int) or not 0 <= s <= 64:
            raise DataConfigError("TargetConfig.heatmap_stride", f"must be an int in [0, 64], got {s!r}")
        sig = self.heatmap_sigma
        if isinstance(sig, bool) or not isinstance(sig, (int, float)) or not (math.isfinite(sig) and 0 < sig <= 50):
            raise DataConfigError("TargetConfig.heatmap_sigma", f"must be a number in (0, 50], got {sig!r}")
        m = self.near_far_margin_m
        if isinstance(m, bool) or not isinstance(m, (int, float)) or not (math.isfinite(m) and 0 <= m <= 2):
            raise DataConfigError("TargetConfig.near_far_margin_m", f"must be a number in [0, 2], got {m!r}")
        if not isinstance(self.frame_padding, (bool, np.bool_)):
            raise DataConfigError("TargetConfig.frame_padding", f"must be true or false, got {self.frame_padding!r}")
        e = self.edge_cut
        if isinstance(e, bool) or not isinstance(e, (int, float)) or not (math.isfinite(e) and 0 <= e <= 1):
            raise DataConfigError("TargetConfig.edge_cut", f"must be a number in [0, 1], got {e!r}")
        if e and not self.frame_padding:
            raise DataConfigError("TargetConfig.edge_cut",
                                  f"{e} needs frame_padding (a cut frame is shown by its padding)")


def _box_corners(bbox: np.ndarray) -> np.ndarray:
    idx = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)])
    return np.where(idx == 1, bbox[1], bbox[0])


def view_heatmaps(joints_2d: np.ndarray, visible: np.ndarray, resolution: int, config: TargetConfig) -> np.ndarray:
    """``(V, 25, h, h)`` float32 heatmaps of crop-pixel joints ``(V, 25, 2)`` (``h = S / stride``)."""
    stride = config.heatmap_stride
    if resolution % stride:
        raise DataConfigError("TargetConfig.heatmap_stride", f"{stride} must divide the resolution {resolution}")
    h = resolution // stride
    uv = model_to_heatmap_pixels(np.asarray(joints_2d, dtype=np.float64), h, resolution)
    return gaussian_heatmaps(uv, visible, h, config.heatmap_sigma)


def model_inputs(record: Mapping[str, np.ndarray], resolution: int, config: TargetConfig | None = None, *,
                 index: int = 0) -> dict[str, np.ndarray]:
    """Every key of :data:`KEYS` for one stored record (``ShardedSplit.arrays(i)``); ``index``: the sample's,
    which seeds ``TargetConfig.edge_cut``."""
    config = config or TargetConfig()
    S = int(resolution)
    V = int(record["images"].shape[0])
    # Plain records, not validated Cameras: the contract helpers read only K, R, t, width, height.
    cams = [SimpleNamespace(name=f"v{i}", width=S, height=S, K=record["K"][i], R=record["R"][i], t=record["t"][i])
            for i in range(V)]
    bbox = np.asarray(record["bbox"], dtype=np.float64)
    corners = _box_corners(bbox)
    images = np.ascontiguousarray(np.asarray(record["images"]).transpose(0, 3, 1, 2), dtype=np.float32)
    images *= np.float32(1.0 / 255.0)
    out = {
        "images": images[:NUM_SOURCES].copy(),
        "src_P": C.source_projections(cams[:NUM_SOURCES], S, S),
        "src_centers": C.source_centers(cams[:NUM_SOURCES]),
        "tgt_images": images,
        "tgt_masks": np.unpackbits(np.asarray(record["masks"]), axis=-1).astype(bool),
        "tgt_depth": np.asarray(record["depth"], dtype=np.float32),
        "tgt_has_depth": np.asarray(record["has_depth"], dtype=bool),
        "tgt_joints_2d": np.asarray(record["joints_2d"], dtype=np.float32),
        "tgt_visible": np.asarray(record["visible"], dtype=bool),
        "tgt_K": np.asarray(record["K"], dtype=np.float32),
        **C.target_inputs(cams, S, S),
        "tgt_P": C.target_projections(cams, S, S),
        "near_far": np.stack([C.near_far_from_box(c, corners, config.near_far_margin_m) for c in cams]),
        "tgt_is_source": np.arange(V) < NUM_SOURCES,
        "joints_3d": np.asarray(record["joints_3d"], dtype=np.float32),
        "joints_3d_valid": np.asarray(record["joints_3d_valid"], dtype=bool),
        "bbox": bbox.astype(np.float32),
    }
    if config.heatmap_stride:
        out["tgt_heatmaps"] = view_heatmaps(out["tgt_joints_2d"], out["tgt_visible"], S, config)
    if config.frame_padding:
        frame = np.ones((V, S, S), np.float32)
        rng = np.random.default_rng([EDGE_CUT_STREAM, int(index)])
        for i in range(V):
            K, size, roi = record["full_K"][i], record["full_size"][i], Roi(*(int(c) for c in record["roi"][i]))
            if i < NUM_SOURCES and config.edge_cut:
                cut, side, band = rng.uniform(), rng.integers(2), rng.uniform(*EDGE_CUT_BAND)  # 3 draws a view, always
                if cut < config.edge_cut:
                    K, size, roi = cut_frame(K, size, roi, ("left", "right")[side], band)
            share = frame_coverage(K, size, roi, S)
            if share is not None:
                frame[i] = share
        out["images"] *= frame[:NUM_SOURCES, None]
        out[FRAME_KEY] = frame
    return out


__all__ = ["KEYS", "FRAME_KEY", "EDGE_CUT_STREAM", "EDGE_CUT_BAND", "TargetConfig", "model_inputs", "view_heatmaps"]
