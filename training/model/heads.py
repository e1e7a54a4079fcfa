"""Per-sample heads: g_NeRF (intermediate feature), g_sigma, g_c, g_h, g_co.

Layout: per-point tensors are *channels first*, ``(S or 1, C, P, N)`` for ``P``
rays/points and ``N`` samples per ray, which is what ``grid_sample`` returns,
so the heads are stacks of 1x1 ``Conv2d`` (exported as Conv, the op the int8
quantizer handles best) and no transpose runs per sample.

* ``g_nerf``: ``[mean_S f_img, var_S f_img, f_voxel] -> V_NeRF`` (2 layers), where
  ``f_img`` is the pixel-aligned image feature concatenated with the source RGB.
* ``g_sigma``: ``V -> sigma`` through softplus (ENeRF).
* ``g_c``: per source, ``[V, f_img_s, d_t - d_s, <d_t, d_s>, visible_s] -> logit``;
  softmax over sources; colour = blend of the source colours (ENeRF style).
* ``g_h``: ``[V, mean_S f_h, var_S f_h] -> 25`` joint heatmap values through a
  sigmoid (GHNeRF); in the baseline (no human encoder) ``g_h`` reads ``V`` only.
  ``f_h`` may be sampled once per ray (at the ray's expected depth) and shared by
  its samples: the samples of a ray lie within a few centimetres, less than a
  pixel of the stride-4 human feature map apart in the sources.
* ``g_co``: ``V -> xyz`` (optional coordinate regression, training only).
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from training.model.config import Config


@dataclass
class HeadsConfig(Config):
    """Sizes of the per-sample heads."""

    feature_dim: int = 32
    """V_NeRF width."""
    nerf_hidden: int = 32
    """Hidden width of g_NeRF."""
    colour_hidden: int = 16
    """Hidden width of the per-view blending net g_c."""
    heat_hidden: int = 32
    """Hidden width of g_h."""
    coord_head: bool = False
    """Build g_co (coordinate regression of the query point)."""
    num_joints: int = 25
    """Joint heatmap channels (BODY_25)."""


def pointwise_mlp(dims: list[int], last_activation: bool = False) -> nn.Sequential:
    """1x1 convolutions with ReLU between them, over channels-first ``(S, C, P, N)`` tensors."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(dims[:-1], dims[1:])):
        layers.append(nn.Conv2d(a, b, 1))
        if i < len(dims) - 2 or last_activation:
            layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


def pool_views(views: list[Tensor]) -> Tensor:
    """Per-view ``(1, C, P, N)`` tensors -> ``(1, 2C, P, N)``: mean and (biased) variance across the views.

    Views are kept as separate tensors (sampled one by one) because slicing a stacked view axis copies
    in onnxruntime; two views (the product) take an exact shortcut without reductions.
    """
    if len(views) == 2:
        a, b = views
        half = 0.5 * (a - b)
        return torch.cat([0.5 * (a + b), half * half], dim=1)
    x = torch.cat(views, dim=0)
    mean = x.mean(dim=0, keepdim=True)
    d = x - mean
    return torch.cat([mean, (d * d).mean(dim=0, keepdim=True)], dim=1)


def unit(x: Tensor, dim: int = -1, eps: float = 1e-8) -> Tensor:
    return x / torch.sqrt((x * x).sum(dim=dim, keepdim=True) + eps)


class Heads(nn.Module):
    """The per-sample heads of one cascade level.

    Shapes: ``Q = B * N`` rows of ``M`` rays (targets x samples, rays innermost).
    """

    def __init__(self, config: HeadsConfig, img_channels: int, voxel_channels: int, human_channels: int | None):
        super().__init__()
        self.config = config
        self.img_channels = img_channels  # per view, features + RGB
        V = config.feature_dim
        self.g_nerf = pointwise_mlp([2 * img_channels + voxel_channels, config.nerf_hidden, V], last_activation=True)
        self.g_sigma = nn.Conv2d(V, 1, 1)
        # g_c = Linear([V, f_img_s, d_t - d_s, <d_t, d_s>, visible_s]) -> ReLU -> Linear, per source view; the
        # first layer is split so its V part runs once for all views (no per-view copy of V).
        self.g_c_v = nn.Conv2d(V, config.colour_hidden, 1)
        self.g_c_f = nn.Conv2d(img_channels + 5, config.colour_hidden, 1, bias=False)
        self.g_c_out = nn.Conv2d(config.colour_hidden, 1, 1)
        # g_h = Linear([V, pooled f_h]) -> ReLU -> Linear -> sigmoid. The first layer is split into the V part
        # and the f_h part (same function) so f_h may be given once per ray and broadcast over its samples.
        self.g_h_v = nn.Conv2d(V, config.heat_hidden, 1)
        self.g_h_h = nn.Conv2d(2 * human_channels, config.heat_hidden, 1, bias=False) if human_channels else None
        self.g_h_out = nn.Conv2d(config.heat_hidden, config.num_joints, 1)
        self.g_co = pointwise_mlp([V, config.feature_dim, 3]) if config.coord_head else None

    def nerf_feature(self, f_img: list[Tensor], f_voxel: Tensor) -> Tensor:
        """``f_img`` per view ``(1, Ci, Q, M)``, ``f_voxel`` ``(1, Cv, Q, M)`` -> ``V`` ``(1, feature_dim, Q, M)``."""
        return self.g_nerf(torch.cat([pool_views(f_img), f_voxel], dim=1))

    def density(self, V: Tensor) -> Tensor:
        """``(1, Vd, Q, M)`` -> ``(Q, M)``."""
        return F.softplus(self.g_sigma(V))[0, 0]

    def heat(self, V: Tensor, f_h: list[Tensor] | None, batch: int) -> Tensor:
        """Joint heatmap values in ``[0, 1]``.

        Args:
            V: ``(1, Vd, Q, M)`` with ``Q = batch * N``.
            f_h: per view ``(1, Ch, batch * n, M)`` human features with ``n = N`` (per sample) or ``n = 1``
                (per ray, broadcast over the samples), or None (baseline).

        Returns:
            ``(J, Q, M)``.
        """
        h = self.g_h_v(V)
        if f_h is not None and self.g_h_h is not None:
            hh = self.g_h_h(pool_views(f_h))  # (1, hidden, batch*n, M)
            hidden, M = h.shape[1], h.shape[3]
            h = (h.reshape(1, hidden, batch, -1, M) + hh.reshape(1, hidden, batch, -1, M)).reshape(h.shape)
        return torch.sigmoid(self.g_h_out(torch.relu(h)))[0]

    def colour(self, V: Tensor, f_img: list[Tensor], d_target: Tensor, d_source: list[Tensor],
               visible: list[Tensor]) -> Tensor:
        """Blend source colours (the last 3 channels of each view's ``f_img``).

        Args:
            V: ``(1, Vd, Q, M)``; f_img: per view ``(1, Ci, Q, M)``;
            d_target: ``(1, 3, B, 1, M)`` unit target ray directions; d_source: per view ``(1, 3, B, N, M)``
            unit directions source centre -> point (``Q = B * N``); visible: per view ``(1, 1, Q, M)``,
            1.0 inside the source image.

        Returns:
            ``(3, Q, M)`` colour.
        """
        _, _, Q, M = f_img[0].shape
        v_part = self.g_c_v(V)
        logits = []
        for f, d_s, vis in zip(f_img, d_source, visible):
            diff = (d_target - d_s).reshape(1, 3, Q, M)
            dot = (d_target * d_s).sum(dim=1, keepdim=True).reshape(1, 1, Q, M)
            hidden = torch.relu(self.g_c_f(torch.cat([f, diff, dot, vis], dim=1)) + v_part)
            logits.append(self.g_c_out(hidden) - 30.0 * (1.0 - vis))  # (1, 1, Q, M)
        rgb = [f[0, -3:] for f in f_img]
        if len(f_img) == 2:  # softmax over two views is a sigmoid of the difference
            w0 = torch.sigmoid(logits[0] - logits[1])[0]
            return rgb[1] + w0 * (rgb[0] - rgb[1])
        w = torch.softmax(torch.cat(logits, dim=0), dim=0)
        return (w * torch.stack(rgb)).sum(dim=0)

    def coord(self, V: Tensor) -> Tensor:
        """``(1, Vd, Q, M)`` -> ``(3, Q, M)``."""
        if self.g_co is None:
            raise RuntimeError("g_co is disabled (HeadsConfig.coord_head=False)")
        return self.g_co(V)[0]


__all__ = ["HeadsConfig", "Heads", "pool_views", "pointwise_mlp", "unit"]
