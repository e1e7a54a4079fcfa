"""Small 3D U-Net that regularises a cost volume into depth logits and voxel features (f_voxel)."""
from __future__ import annotations

from dataclasses import dataclass

from torch import Tensor, nn

from training.model.config import Config
from training.model.layers import conv_bn_relu_3d


@dataclass
class RegularizerConfig(Config):
    """3D regularisation network of one cascade level."""

    channels: int = 8
    """Channels at full volume resolution (= f_voxel channels); doubled at each down stage."""
    stages: int = 2
    """Down/up stages; the plane count and the volume's h, w must be divisible by 2**stages."""
    head_kernel: int = 3
    """Kernel of the depth-logit conv (3 as ENeRF; 1 is ~8x cheaper on a CPU)."""


class Regularizer(nn.Module):
    def __init__(self, config: RegularizerConfig, in_channels: int, with_logits: bool = True):
        super().__init__()
        self.config = config
        c = config.channels
        self.inp = conv_bn_relu_3d(in_channels, c)
        self.down = nn.ModuleList()
        self.up = nn.ModuleList()
        ch = c
        for _ in range(config.stages):
            self.down.append(nn.Sequential(conv_bn_relu_3d(ch, 2 * ch, stride=2), conv_bn_relu_3d(2 * ch, 2 * ch)))
            self.up.insert(0, nn.Sequential(
                nn.ConvTranspose3d(2 * ch, ch, 3, stride=2, padding=1, output_padding=1, bias=False),
                nn.BatchNorm3d(ch), nn.ReLU(inplace=True)))
            ch *= 2
        k = config.head_kernel
        self.logits = nn.Conv3d(c, 1, k, padding=k // 2) if with_logits else None

    @property
    def multiple(self) -> int:
        return 2 ** self.config.stages

    def forward(self, cost: Tensor) -> tuple[Tensor, Tensor | None]:
        """``(B, G, D, h, w)`` -> features ``(B, channels, D, h, w)`` and logits ``(B, D, h, w)`` (or None)."""
        x = self.inp(cost)
        skips = [x]
        for down in self.down:
            x = down(x)
            skips.append(x)
        skips.pop()
        for up in self.up:
            x = up(x) + skips.pop()
        return x, (self.logits(x).squeeze(1) if self.logits is not None else None)


RegularizerConfig._target = Regularizer

__all__ = ["RegularizerConfig", "Regularizer"]
