"""Small building blocks shared by the 2D and 3D networks."""
from __future__ import annotations

from torch import nn


def conv_bn_relu(cin: int, cout: int, kernel: int = 3, stride: int = 1, norm: bool = True) -> nn.Sequential:
    """``Conv2d -> BatchNorm2d -> ReLU`` (BatchNorm folds into the conv at export)."""
    layers: list[nn.Module] = [nn.Conv2d(cin, cout, kernel, stride, kernel // 2, bias=not norm)]
    if norm:
        layers.append(nn.BatchNorm2d(cout))
    layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


def conv_bn_relu_3d(cin: int, cout: int, kernel: int = 3, stride: int = 1, norm: bool = True) -> nn.Sequential:
    """``Conv3d -> BatchNorm3d -> ReLU``."""
    layers: list[nn.Module] = [nn.Conv3d(cin, cout, kernel, stride, kernel // 2, bias=not norm)]
    if norm:
        layers.append(nn.BatchNorm3d(cout))
    layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)

