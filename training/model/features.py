"""Multi-scale image feature network (a small FPN, ENeRF-sized).

Encoder stages at strides 1, 2, 4 with ``channels = (c0, c1, c2)``; top-down path
that *reduces channels before upsampling* (1x1 conv then bilinear x2, or a
sub-pixel 1x1 conv + DepthToSpace; both cheap at full resolution), merged with
the lateral stage output and smoothed by a 3x3 conv (optional at full resolution). Outputs (contract names): ``feat_s4`` (c2 @ 1/4), ``feat_s2``
(c1 @ 1/2), ``feat_s1`` (c0 @ 1/1). Input is the *normalised* image.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import torch.nn.functional as F
from torch import Tensor, nn

from training.model.config import Config
from training.model.layers import conv_bn_relu


@dataclass
class FeatureNetConfig(Config):
    """Image feature FPN."""

    channels: tuple[int, int, int] = (8, 16, 32)
    """Channels at strides 1, 2, 4 (ENeRF: 8, 16, 32)."""
    norm: Literal["batch", "scene", "none"] = "batch"
    """After each conv of the encoder stages: BatchNorm (folded into the conv at export), ``scene``
    (``layers.SceneNorm2d``: the statistics of the images of the call, one scene's sources, in training
    and inference alike), or none."""
    full_res_convs: int = 2
    """3x3 convs at full resolution in the first stage (1 or 2). Full-resolution convs with few channels
    are the least efficient int8 convs on a CPU; the edge preset uses 1."""
    upsample: Literal["bilinear", "subpixel"] = "bilinear"
    """Top-down upsampling: bilinear (ENeRF), or sub-pixel (a 1x1 conv to 4x the channels then
    DepthToSpace), which keeps the int8 encoder free of Resize ops (slow on uint8 data in onnxruntime)."""
    full_res_smooth: bool = True
    """3x3 smoothing conv on the full-resolution FPN output (False: ``feat_s1`` = stage-0 output + upsampled
    coarse features, no full-resolution conv after the merge)."""


class FeatureNet(nn.Module):
    def __init__(self, config: FeatureNetConfig):
        super().__init__()
        self.config = config
        c0, c1, c2 = config.channels
        bn = config.norm
        if config.full_res_convs not in (1, 2):
            raise ValueError(f"full_res_convs must be 1 or 2, got {config.full_res_convs}")
        self.stage0 = nn.Sequential(*[conv_bn_relu(3 if i == 0 else c0, c0, 3, 1, bn)
                                      for i in range(config.full_res_convs)])
        self.stage1 = nn.Sequential(conv_bn_relu(c0, c1, 3, 2, bn), conv_bn_relu(c1, c1, 3, 1, bn))
        self.stage2 = nn.Sequential(conv_bn_relu(c1, c2, 3, 2, bn), conv_bn_relu(c2, c2, 3, 1, bn))
        self.top = nn.Conv2d(c2, c2, 1)
        if config.upsample == "subpixel":
            self.reduce1 = nn.Sequential(nn.Conv2d(c2, 4 * c1, 1), nn.PixelShuffle(2))
            self.reduce0 = nn.Sequential(nn.Conv2d(c1, 4 * c0, 1), nn.PixelShuffle(2))
            self.up = nn.Identity()
        else:
            self.reduce1 = nn.Conv2d(c2, c1, 1)
            self.reduce0 = nn.Conv2d(c1, c0, 1)
            self.up = _Up2()
        self.smooth1 = nn.Conv2d(c1, c1, 3, padding=1)
        self.smooth0 = nn.Conv2d(c0, c0, 3, padding=1) if config.full_res_smooth else nn.Identity()

    @property
    def out_channels(self) -> dict[str, int]:
        c0, c1, c2 = self.config.channels
        return {"feat_s1": c0, "feat_s2": c1, "feat_s4": c2}

    def forward(self, x: Tensor) -> dict[str, Tensor]:
        """``x`` ``(S, 3, H, W)`` normalised images -> ``{"feat_s1", "feat_s2", "feat_s4"}``."""
        x0 = self.stage0(x)
        x1 = self.stage1(x0)
        x2 = self.stage2(x1)
        f4 = self.top(x2)
        f2 = self.smooth1(x1 + self.up(self.reduce1(f4)))
        f1 = self.smooth0(x0 + self.up(self.reduce0(f2)))
        return {"feat_s1": f1, "feat_s2": f2, "feat_s4": f4}


class _Up2(nn.Module):
    def forward(self, x: Tensor) -> Tensor:
        return F.interpolate(x, scale_factor=2.0, mode="bilinear", align_corners=False)


FeatureNetConfig._target = FeatureNet

__all__ = ["FeatureNetConfig", "FeatureNet"]
