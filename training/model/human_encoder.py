"""ResNet18 human encoder (GHNeRF's second encoder), pixelNeRF-style multi-level features.

The trunk's module names follow torchvision's ``resnet18`` exactly (``conv1``,
``bn1``, ``layer1``..``layer4``, each a list of ``BasicBlock`` with ``conv1``,
``bn1``, ``conv2``, ``bn2`` and ``downsample.0`` / ``downsample.1``), so a
torchvision state dict loads with strict key matching for the layers in use
(:func:`load_torchvision_resnet18`). Only the layers up to ``num_layers`` are
built; torchvision's ``fc`` (and ``layer4`` when ``num_layers == 3``) are
dropped on load. From scratch by default (no ImageNet weights on these
machines); ``init`` takes the path of a torchvision-format ``resnet18.pth``.

Head (``decoder``): the stem (after max-pool, 64 ch @ 1/4) and every layer
output go through their own 1x1 conv to ``out_channels``. Then either

* ``"sum"``: bilinearly resized to ``out_stride`` and summed. Because the 1x1
  conv and bilinear resize are both linear, this equals pixelNeRF's "upsample,
  concatenate, project" but runs the projection at each level's low resolution.
  The result is linear in the levels: the deep level that knows *which* joint
  is where only reaches the output through a bilinear upsample of its coarse
  grid (4x4 cells for a 64x64 trunk input at layer3).
* ``"fpn"``: a top-down pathway (feature pyramid): from the deepest level down,
  upsample, add the next level's projection, 3x3 conv + ReLU. The fine levels
  now localise the deep ones non-linearly, which is what sharp joint heatmaps
  need; it costs four small 3x3 convs.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Mapping

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from training.model.config import Config

#: Channels and strides of the trunk outputs used by the head.
TRUNK_LEVELS = {"stem": (64, 4), "layer1": (64, 4), "layer2": (128, 8), "layer3": (256, 16), "layer4": (512, 32)}


@dataclass
class HumanEncoderConfig(Config):
    """ResNet18 human encoder."""

    num_layers: int = 3
    """Residual layers used (2, 3 or 4). MODEL.md: to layer3 int8 1.5 ms, to layer4 1.9 ms at 128^2."""
    out_channels: int = 32
    """Channels of ``human_feat`` (pixel-aligned human features)."""
    out_stride: int = 4
    """Stride of ``human_feat`` w.r.t. the input image."""
    input_scale: float = 1.0
    """The trunk sees the image resized by this factor (0.5: a quarter of the MACs; the features are coarse
    anyway). ``out_stride`` stays relative to the model input."""
    decoder: Literal["sum", "fpn"] = "sum"
    """How the trunk levels become ``human_feat``: linear resize-and-sum, or a top-down FPN (see the module doc).
    "sum" is the default so that models trained before "fpn" existed load unchanged."""
    init: str | None = None
    """Path of a torchvision-format resnet18 state dict (ImageNet weights), or None for scratch."""
    aux_heatmaps: bool = False
    """Build a training-only 1x1 head ``human_feat -> 25`` joint heatmaps in the source image itself,
    supervised densely (every cell of both source views, every step) by ``LossConfig.encoder_heat_weight``.
    The rendered heatmaps reach the encoder through a few hundred rays per step; this dense signal teaches
    it "where is joint j in this image" far sooner (deep supervision). Exported as the encoder graph's
    ``encoder_heatmaps`` output (contract 1.1.0), a heatmap source the runtime can use instead of rendering."""


class BasicBlock(nn.Module):
    """torchvision's ``BasicBlock`` layout (same attribute names, same keys)."""

    expansion = 1

    def __init__(self, inplanes: int, planes: int, stride: int = 1):
        super().__init__()
        self.conv1 = nn.Conv2d(inplanes, planes, 3, stride, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(planes)
        self.relu = nn.ReLU(inplace=True)
        self.conv2 = nn.Conv2d(planes, planes, 3, 1, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(planes)
        self.downsample: nn.Module | None = None
        if stride != 1 or inplanes != planes:
            self.downsample = nn.Sequential(nn.Conv2d(inplanes, planes, 1, stride, bias=False), nn.BatchNorm2d(planes))

    def forward(self, x: Tensor) -> Tensor:
        identity = x if self.downsample is None else self.downsample(x)
        out = self.relu(self.bn1(self.conv1(x)))
        out = self.bn2(self.conv2(out))
        return self.relu(out + identity)


class ResNet18Trunk(nn.Module):
    """torchvision ``resnet18`` without ``avgpool``/``fc``, cut after ``num_layers`` layers."""

    def __init__(self, num_layers: int = 4):
        super().__init__()
        if num_layers not in (1, 2, 3, 4):
            raise ValueError(f"num_layers must be 1..4, got {num_layers}")
        self.num_layers = num_layers
        self.conv1 = nn.Conv2d(3, 64, 7, 2, 3, bias=False)
        self.bn1 = nn.BatchNorm2d(64)
        self.relu = nn.ReLU(inplace=True)
        self.maxpool = nn.MaxPool2d(3, 2, 1)
        inplanes = 64
        for i, planes in enumerate((64, 128, 256, 512)[:num_layers]):
            stride = 1 if i == 0 else 2
            self.add_module(f"layer{i + 1}", nn.Sequential(BasicBlock(inplanes, planes, stride),
                                                           BasicBlock(planes, planes, 1)))
            inplanes = planes
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
        # Zero-init the last BN of each block (torchvision's zero_init_residual): stabler from scratch.
        for m in self.modules():
            if isinstance(m, BasicBlock):
                nn.init.zeros_(m.bn2.weight)

    @property
    def level_names(self) -> list[str]:
        return ["stem"] + [f"layer{i + 1}" for i in range(self.num_layers)]

    def forward(self, x: Tensor) -> dict[str, Tensor]:
        out = {"stem": self.maxpool(self.relu(self.bn1(self.conv1(x))))}
        h = out["stem"]
        for i in range(self.num_layers):
            h = getattr(self, f"layer{i + 1}")(h)
            out[f"layer{i + 1}"] = h
        return out


def used_keys_filter(state_dict: Mapping[str, Tensor], num_layers: int) -> dict[str, Tensor]:
    """Keep the keys of a torchvision resnet18 state dict that a ``num_layers`` trunk uses."""
    dropped = ("fc.",) + tuple(f"layer{i}." for i in range(num_layers + 1, 5))
    return {k: v for k, v in state_dict.items() if not k.startswith(dropped)}


class ResNet18WeightsError(RuntimeError):
    """A state dict that is not torchvision's resnet18 as the trunk takes it; the message names the first
    missing, unexpected or mis-shaped key (torch's strict-load message lists them all and was cut short
    before the key's shapes or the missing key's name)."""


def _first_and_count(keys: list[str]) -> str:
    """``'conv1.weight'`` or ``'conv1.weight' and 41 more``."""
    more = f" and {len(keys) - 1} more" if len(keys) > 1 else ""
    return f"{keys[0]!r}{more}"


def weights_mismatch(expected: Mapping[str, Tensor], given: Mapping[str, Tensor]) -> str | None:
    """Why ``given`` does not load strictly where ``expected`` (a ``state_dict()``) is (None: it does): the
    missing keys, then the unexpected ones (with the first of ``given``'s, to show a prefix), then the first
    shape that differs."""
    problems = []
    missing = [k for k in expected if k not in given]
    unexpected = [k for k in given if k not in expected]
    if missing:
        problems.append(f"no key {_first_and_count(missing)}")
    if unexpected:
        problems.append(f"unexpected key {_first_and_count(unexpected)}")
    shapes = [(k, tuple(given[k].shape), tuple(v.shape)) for k, v in expected.items()
              if k in given and hasattr(given[k], "shape") and tuple(given[k].shape) != tuple(v.shape)]
    if shapes:
        key, got, want = shapes[0]
        more = f" (and {len(shapes) - 1} more keys)" if len(shapes) > 1 else ""
        problems.append(f"{key!r} has shape {list(got)}, resnet18 {list(want)}{more}")
    return "; ".join(problems) or None


def load_torchvision_resnet18(trunk: ResNet18Trunk, source: str | Path | Mapping[str, Tensor]) -> list[str]:
    """Load torchvision resnet18 weights into ``trunk`` with strict key matching for the used layers.

    Args:
        trunk: the trunk to fill.
        source: a path to a ``torch.save``'d state dict (``resnet18-f37072fd.pth``) or the dict itself;
            a checkpoint wrapping it under ``"state_dict"`` or ``"model"`` is unwrapped.

    Returns:
        The keys that were dropped because the trunk does not use them (``fc.*``, deeper layers).

    Raises:
        ResNet18WeightsError: not a mapping, or a used key is missing, unexpected or mis-shaped (named).
    """
    if isinstance(source, (str, Path)):
        state = torch.load(str(source), map_location="cpu", weights_only=True)
    else:
        state = source
    if not isinstance(state, Mapping):
        raise ResNet18WeightsError(f"holds a {type(state).__name__}, not a state dict")
    for wrapper in ("state_dict", "model"):
        if wrapper in state and isinstance(state[wrapper], Mapping):
            state = state[wrapper]
    state = {str(k).removeprefix("module."): v for k, v in state.items()}
    used = used_keys_filter(state, trunk.num_layers)
    if problem := weights_mismatch(trunk.state_dict(), used):
        raise ResNet18WeightsError(problem)
    trunk.load_state_dict(used, strict=True)
    return sorted(set(state) - set(used))


class HumanEncoder(nn.Module):
    """ResNet18 trunk + per-level 1x1 projections summed at ``out_stride``."""

    def __init__(self, config: HumanEncoderConfig, read_init: bool = True):
        """``read_init`` False leaves ``config.init`` unread: for a model whose weights come from a checkpoint
        next (a resume), where the file may have moved since the run began."""
        super().__init__()
        self.config = config
        self.trunk = ResNet18Trunk(config.num_layers)
        self.proj = nn.ModuleDict({
            name: nn.Conv2d(TRUNK_LEVELS[name][0], config.out_channels, 1) for name in self.trunk.level_names
        })
        # Top-down smoothing convs, one per level below the deepest (FPN's "merge, then 3x3").
        self.smooth = nn.ModuleDict({
            name: nn.Conv2d(config.out_channels, config.out_channels, 3, padding=1)
            for name in self.trunk.level_names[:-1]
        }) if config.decoder == "fpn" else None
        self.heat_head = nn.Conv2d(config.out_channels, 25, 1) if config.aux_heatmaps else None
        self.frozen = False
        if config.init and read_init:
            load_torchvision_resnet18(self.trunk, config.init)

    def freeze(self) -> "HumanEncoder":
        """Fix every weight and the BatchNorm statistics (a pretrained encoder kept as it is): no
        gradients, and evaluation mode whatever ``train()`` asks (batch statistics of the two source
        images of one scene would otherwise replace the pretraining's)."""
        self.frozen = True
        for p in self.parameters():
            p.requires_grad_(False)
        return super().train(False)

    def train(self, mode: bool = True) -> "HumanEncoder":
        return super().train(mode and not self.frozen)

    @property
    def out_channels(self) -> int:
        return self.config.out_channels

    def forward(self, x: Tensor) -> Tensor:
        """``x`` ``(S, 3, H, W)`` normalised images -> ``(S, out_channels, H / out_stride, W / out_stride)``."""
        H, W = x.shape[-2:]
        size = (H // self.config.out_stride, W // self.config.out_stride)
        if self.config.input_scale != 1.0:
            x = F.interpolate(x, scale_factor=self.config.input_scale, mode="bilinear", align_corners=False,
                              antialias=False)
        feats = self.trunk(x)
        if self.smooth is not None:
            return self._top_down(feats, size)
        out = None
        for name, f in feats.items():
            p = self.proj[name](f)
            if p.shape[-2:] != size:
                p = F.interpolate(p, size=size, mode="bilinear", align_corners=False)
            out = p if out is None else out + p
        return out

    def _top_down(self, feats: dict[str, Tensor], size: tuple[int, int]) -> Tensor:
        top = None
        for name in reversed(self.trunk.level_names):
            p = self.proj[name](feats[name])
            if top is not None:
                if top.shape[-2:] != p.shape[-2:]:
                    top = F.interpolate(top, size=p.shape[-2:], mode="bilinear", align_corners=False)
                p = F.relu(self.smooth[name](p + top))
            top = p
        if top.shape[-2:] != size:
            top = F.interpolate(top, size=size, mode="bilinear", align_corners=False)
        return top

    def heatmaps(self, human_feat: Tensor) -> Tensor:
        """The auxiliary head's joint heatmaps ``(S, 25, H / out_stride, W / out_stride)`` in [0, 1]."""
        if self.heat_head is None:
            raise RuntimeError("the auxiliary heatmap head is off (HumanEncoderConfig.aux_heatmaps=False)")
        return torch.sigmoid(self.heat_head(human_feat))


HumanEncoderConfig._target = HumanEncoder

__all__ = ["HumanEncoderConfig", "HumanEncoder", "ResNet18Trunk", "BasicBlock", "load_torchvision_resnet18",
           "ResNet18WeightsError",
           "used_keys_filter", "TRUNK_LEVELS"]
