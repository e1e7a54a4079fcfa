"""Small building blocks shared by the 2D and 3D networks."""
from __future__ import annotations

import torch
from torch import Tensor, nn

#: 2D normalisations of ``conv_bn_relu``: BatchNorm, scene statistics (``SceneNorm2d``), none.
NORMS_2D = ("batch", "scene", "none")


class SceneNorm2d(nn.Module):
    """Normalise each channel with the mean and variance of the whole input batch, always.

    This is what ``BatchNorm2d`` computes *in training*. Where a batch is one scene's source images
    (the image feature network: a step trains on one scene), a network trained with BatchNorm
    learns to rely on those per-scene statistics (exposure, contrast, background), and BatchNorm's
    running averages at inference are a different function: a run of the seventh model's recipe lost
    5.3 dB of novel-view PSNR at its own source cameras that way, 3.7 dB within 15 degrees of them
    (docs/training.md, "Scene normalisation"). This layer
    uses the batch's statistics at inference too (the device's pair of crops), so training and
    inference compute the same thing. It keeps BatchNorm's affine parameter names (``weight``,
    ``bias``), has no running statistics, and exports to plain ONNX reductions (it does not fold into
    the convolution).
    """

    def __init__(self, channels: int, eps: float = 1e-5):
        super().__init__()
        self.eps = eps
        self.weight = nn.Parameter(torch.ones(channels))
        self.bias = nn.Parameter(torch.zeros(channels))

    def forward(self, x: Tensor) -> Tensor:
        mean = x.mean(dim=(0, 2, 3), keepdim=True)
        centred = x - mean
        var = (centred * centred).mean(dim=(0, 2, 3), keepdim=True)  # biased, as BatchNorm normalises
        scale = self.weight.reshape(1, -1, 1, 1) / torch.sqrt(var + self.eps)
        return centred * scale + self.bias.reshape(1, -1, 1, 1)


def conv_bn_relu(cin: int, cout: int, kernel: int = 3, stride: int = 1, norm: str = "batch") -> nn.Sequential:
    """``Conv2d -> norm -> ReLU``; ``norm`` one of ``NORMS_2D`` (BatchNorm folds into the conv at export)."""
    if norm not in NORMS_2D:
        raise ValueError(f"norm must be one of {NORMS_2D}, got {norm!r}")
    layers: list[nn.Module] = [nn.Conv2d(cin, cout, kernel, stride, kernel // 2, bias=norm == "none")]
    if norm == "batch":
        layers.append(nn.BatchNorm2d(cout))
    elif norm == "scene":
        layers.append(SceneNorm2d(cout))
    layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


def conv_bn_relu_3d(cin: int, cout: int, kernel: int = 3, stride: int = 1, norm: bool = True) -> nn.Sequential:
    """``Conv3d -> BatchNorm3d -> ReLU``."""
    layers: list[nn.Module] = [nn.Conv3d(cin, cout, kernel, stride, kernel // 2, bias=not norm)]
    if norm:
        layers.append(nn.BatchNorm3d(cout))
    layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)

