"""``ghnerf-eval`` (``python -m training.evaluate``): held-out metrics of a checkpoint or ONNX graphs."""
from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from ghnerf_runtime.contract import ray_grid
from ghnerf_runtime.keypoints import KeypointDecoderConfig, decode_keypoints, heatmap_to_model_pixels


@torch.no_grad()
def render_heatmap_grids(model, item: dict, targets: Tensor) -> Tensor:
    """Heatmaps ``(T, J, h, w)`` rendered on the heatmap grid of the views ``targets`` of scene ``item``."""
    cfg = model.config
    H, W, s = cfg.height, cfg.width, cfg.heatmap_stride
    uv = torch.from_numpy(ray_grid(H, W, s)).to(item["images"].device)
    T = len(targets)
    enc = model.encode(item["images"])
    vols = model.volumes(enc, item["src_P"], item["tgt_K_inv"][targets], item["tgt_c2w"][targets],
                         item["near_far"][targets])
    v = vols[-1]
    out = model.render(len(vols) - 1, enc, v["volume"], v["stats"], item["src_P"], item["tgt_K_inv"][targets],
                       item["tgt_c2w"][targets], uv.expand(T, -1, -1), heat=True)
    hm = out["heatmaps"]  # (T, R, J)
    return hm.transpose(1, 2).reshape(T, -1, H // s, W // s)


def keypoints_from_heatmaps(heatmaps: np.ndarray, model_size: int,
                            config: KeypointDecoderConfig | None = None) -> np.ndarray:
    """Decoded joints ``(..., J, 2)`` in model (crop) pixels; NaN where no peak was found."""
    kp = decode_keypoints(np.asarray(heatmaps, np.float32), config)
    uv = heatmap_to_model_pixels(kp.uv, heatmaps.shape[-1], model_size)
    return np.where(kp.valid[..., None], uv, np.nan)
