"""Training losses: ``l_col + 0.5 l_heat`` (+ SSIM patch loss as the perceptual substitute,
+ optional ``0.01 l_coord``, + optional ``l_mask``), summed over the cascade levels (ENeRF supervises
every level).

GHNeRF uses ``l_col + 0.01 l_perc + 0.5 l_heat`` with a VGG perceptual loss; no VGG
weights are obtainable here, so ``l_perc`` is replaced by ``1 - SSIM`` over ray
patches (needs the rays of a target to form a ``patch_shape`` patch, row-major).
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor

from training.model.config import Config


@dataclass
class LossConfig(Config):
    """Loss weights."""

    colour_weight: float = 1.0
    """l_col: MSE of the rendered colour."""
    heat_weight: float = 0.5
    """l_heat: MSE of the rendered joint heatmaps (GHNeRF: 0.5)."""
    heat_positive_weight: float = 20.0
    """Per-ray weight ``1 + w * target`` of the heatmap MSE. Positives are a few per cent of the
    rays, so plain MSE sits at the all-zero solution for thousands of steps; weighting them keeps
    the minimiser at the target but makes peaks appear early (0 gives GHNeRF's plain MSE)."""
    ssim_weight: float = 0.01
    """1 - SSIM over ray patches, the stand-in for GHNeRF's 0.01 l_perc (VGG). 0 disables."""
    coord_weight: float = 0.0
    """l_coord: MSE of g_co's regressed sample coordinates (metres); GHNeRF's optional 0.01."""
    encoder_heat_weight: float = 0.0
    """Auxiliary dense heatmap loss on the human encoder's training-only head (``aux_heatmaps``): the same
    positive-weighted MSE against the source views' ground-truth heatmap grids. 0 disables."""
    mask_weight: float = 0.0
    """l_mask: MSE of each ray's accumulated opacity against the subject mask at that ray (0 disables).
    The colour target is the subject over a black background, so the colour loss alone does not
    penalise opaque black fog around the subject, and fog in front of the subject dims it; this term
    asks for an opaque subject and empty space around it."""
    depth_weight: float = 0.0
    """l_depth: mean absolute error (metres) of each subject ray's rendered depth (``sum w z / acc``,
    camera z) against the dataset's true depth, over the rays whose four bilinear taps all lie on the
    subject, every level (0 disables). The synthetic dataset has true depth; views without it (ZJU-MoCap)
    add nothing. Tried at 0.1: the depth error at the sources fell from 45 to 36 mm and the PSNR did
    not move (docs/training.md, "Scene normalisation"), so it is off in the shipped recipe."""
    level_weights: tuple[float, ...] = ()
    """Weight of each cascade level, coarse to fine (empty: 1.0 each)."""
    ssim_window: int = 7
    """SSIM window (uniform), in rays."""


def ssim(x: Tensor, y: Tensor, window: int = 7, c1: float = 0.01 ** 2, c2: float = 0.03 ** 2) -> Tensor:
    """Mean SSIM of images ``(B, C, h, w)`` in ``[0, 1]`` with a uniform ``window`` (valid positions only)."""
    window = min(window, x.shape[-1], x.shape[-2])
    mu_x, mu_y = F.avg_pool2d(x, window, 1), F.avg_pool2d(y, window, 1)
    sxx = F.avg_pool2d(x * x, window, 1) - mu_x ** 2
    syy = F.avg_pool2d(y * y, window, 1) - mu_y ** 2
    sxy = F.avg_pool2d(x * y, window, 1) - mu_x * mu_y
    num = (2 * mu_x * mu_y + c1) * (2 * sxy + c2)
    den = (mu_x ** 2 + mu_y ** 2 + c1) * (sxx + syy + c2)
    return (num / den).mean()


def positive_weighted_mse(pred: Tensor, target: Tensor, positive_weight: float) -> Tensor:
    """``mean((1 + w * target) * (pred - target)^2)``: heatmap MSE that does not sit at all-zero maps."""
    return ((1.0 + positive_weight * target) * (pred - target) ** 2).mean()


def masked_l1(pred: Tensor, target: Tensor, valid: Tensor) -> Tensor:
    """Mean ``|pred - target|`` over ``valid``; zero (with a gradient path) when nothing is valid."""
    v = valid.to(pred.dtype)
    return ((pred - target).abs() * v).sum() / torch.clamp(v.sum(), min=1.0)


#: Mass (sum of heatmap values) that :func:`window_centroid_loss` adds at each window's centre. A Gaussian
#: peak of height 1 and sigma 1 cell holds about 6.3, so a trained peak moves by a fraction of a per cent
#: of its offset; a map with no mass in the window has its centroid at the window's centre, not at
#: the map's corner (cell 0, 0), and a slope of at most ``radius * sqrt(2) / CENTROID_PRIOR_MASS``.
CENTROID_PRIOR_MASS = 1e-2


def window_centroid_loss(pred: Tensor, target: Tensor, radius: int = 3, min_peak: float = 0.5) -> Tensor:
    """Mean distance (heatmap cells) between the centroids of ``pred`` and of ``target``, both taken over
    the same ``(2 radius + 1)^2`` cells around the true joint; a localisation term beside the heatmap MSE,
    which scores values, not where the peak's mass sits.

    The window is centred on the cell of the Gaussian ``target``'s centroid; joints whose target peaks
    below ``min_peak`` (hidden, or off the map) are left out. Each centroid carries
    :data:`CENTROID_PRIOR_MASS` at the window's centre, so a prediction with (next to) no mass there scores
    the target's distance from that cell (under a cell) with a bounded slope. ``pred`` and ``target`` are
    ``(N, J, h, w)``; returns 0 when no joint qualifies, and 0 for ``pred == target``.
    """
    n, j, h, w = target.shape
    t = target.reshape(n * j, h, w)
    keep = t.amax(dim=(1, 2)) >= min_peak
    if not bool(keep.any()):
        return pred.sum() * 0.0
    t, p = t[keep], pred.reshape(n * j, h, w)[keep].clamp(min=0.0)
    ys = torch.arange(h, dtype=t.dtype, device=t.device)
    xs = torch.arange(w, dtype=t.dtype, device=t.device)
    mass = t.sum(dim=(1, 2))
    cy = ((t.sum(dim=2) * ys).sum(dim=1) / mass).round()
    cx = ((t.sum(dim=1) * xs).sum(dim=1) / mass).round()
    # offsets from the window's centre: the prior mass sits at offset 0 (a clamped total put it at cell 0, 0)
    dy, dx = ys[None, :] - cy[:, None], xs[None, :] - cx[:, None]  # (K, h), (K, w)
    inside = (dy.abs() <= radius)[:, :, None] & (dx.abs() <= radius)[:, None, :]

    def centroid(maps: Tensor) -> tuple[Tensor, Tensor]:
        m = maps * inside
        total = m.sum(dim=(1, 2)) + CENTROID_PRIOR_MASS
        return (m.sum(dim=2) * dy).sum(dim=1) / total, (m.sum(dim=1) * dx).sum(dim=1) / total

    (ty, tx), (py, px) = centroid(t), centroid(p)
    return torch.sqrt((py - ty) ** 2 + (px - tx) ** 2 + 1e-12).mean()


def compute_losses(outputs: dict, batch: dict[str, Tensor], config: LossConfig,
                   patch_shape: tuple[int, int] | None = None) -> dict[str, Tensor]:
    """Loss terms and their weighted total (``"loss"``).

    Args:
        outputs: :meth:`GHNeRF.forward` output (``{"levels": [...]}``).
        batch: ``rgb`` ``(B, R, 3)`` target colour (subject over the model's background), ``heatmaps``
            ``(B, R, J)`` Gaussian ground-truth heatmaps of the same rays; optional ``mask`` ``(B, R)`` subject
            mask at the rays in [0, 1] (for ``mask_weight``); optional ``depth`` and ``depth_valid`` ``(B, R)``
            true depth at the rays and where it counts (for ``depth_weight``); optional ``source_heatmaps``
            ``(S, J, h, w)`` ground-truth grids of the source views (for ``encoder_heat_weight``).
        patch_shape: ``(h, w)`` with ``h * w == R`` when the rays of each target form a row-major patch
            (enables the SSIM term).

    Returns:
        ``loss`` plus per level ``l{i}_col``, ``l{i}_heat`` [, ``l{i}_ssim``, ``l{i}_coord``, ``l{i}_mask``].
    """
    levels = outputs["levels"]
    weights = config.level_weights or (1.0,) * len(levels)
    if len(weights) != len(levels):
        raise ValueError(f"level_weights has {len(weights)} entries for {len(levels)} levels")
    terms: dict[str, Tensor] = {}
    total = torch.zeros((), device=batch["rgb"].device)
    for i, (out, lw) in enumerate(zip(levels, weights)):
        level_total = torch.zeros_like(total)
        if "rgb" in out and config.colour_weight:
            terms[f"l{i}_col"] = F.mse_loss(out["rgb"], batch["rgb"])
            level_total = level_total + config.colour_weight * terms[f"l{i}_col"]
        if "heatmaps" in out and config.heat_weight:
            terms[f"l{i}_heat"] = positive_weighted_mse(out["heatmaps"], batch["heatmaps"], config.heat_positive_weight)
            level_total = level_total + config.heat_weight * terms[f"l{i}_heat"]
        if "rgb" in out and config.ssim_weight and patch_shape is not None:
            h, w = patch_shape
            B, R, _ = out["rgb"].shape
            if h * w != R:
                raise ValueError(f"patch_shape {patch_shape} does not match {R} rays")
            pred = out["rgb"].transpose(1, 2).reshape(B, 3, h, w)
            gt = batch["rgb"].transpose(1, 2).reshape(B, 3, h, w)
            terms[f"l{i}_ssim"] = 1.0 - ssim(pred, gt, config.ssim_window)
            level_total = level_total + config.ssim_weight * terms[f"l{i}_ssim"]
        if config.mask_weight and "acc" in out:
            if "mask" not in batch:
                raise ValueError("mask_weight is set but the batch has no 'mask' (subject mask at the rays)")
            terms[f"l{i}_mask"] = F.mse_loss(out["acc"], batch["mask"])
            level_total = level_total + config.mask_weight * terms[f"l{i}_mask"]
        if config.depth_weight and "depth" in out:
            if "depth" not in batch or "depth_valid" not in batch:
                raise ValueError("depth_weight is set but the batch has no 'depth' / 'depth_valid'")
            terms[f"l{i}_depth"] = masked_l1(out["depth"], batch["depth"], batch["depth_valid"])
            level_total = level_total + config.depth_weight * terms[f"l{i}_depth"]
        if config.coord_weight and "coord" in out:
            terms[f"l{i}_coord"] = F.mse_loss(out["coord"], out["points"].detach())
            level_total = level_total + config.coord_weight * terms[f"l{i}_coord"]
        total = total + lw * level_total
    if config.encoder_heat_weight and "encoder_heatmaps" in outputs and "source_heatmaps" in batch:
        pred, target = outputs["encoder_heatmaps"], batch["source_heatmaps"]
        if pred.shape != target.shape:
            raise ValueError(f"encoder heatmaps {tuple(pred.shape)} do not match the targets {tuple(target.shape)}")
        terms["enc_heat"] = positive_weighted_mse(pred, target, config.heat_positive_weight)
        total = total + config.encoder_heat_weight * terms["enc_heat"]
        if "aux_encoder_heatmaps" in outputs and "aux_heatmaps" in batch:  # more views / mirrored images
            pred, target = outputs["aux_encoder_heatmaps"], batch["aux_heatmaps"]
            if pred.shape != target.shape:
                raise ValueError(f"auxiliary encoder heatmaps {tuple(pred.shape)} do not match the targets "
                                 f"{tuple(target.shape)}")
            terms["enc_heat_aux"] = positive_weighted_mse(pred, target, config.heat_positive_weight)
            total = total + config.encoder_heat_weight * terms["enc_heat_aux"]
    terms["loss"] = total
    return terms


__all__ = ["LossConfig", "ssim", "positive_weighted_mse", "masked_l1", "compute_losses"]
