"""A learnt painter of the surfaces no source camera sees, and what it reaches held out.

The analytic fills (``training.unseen_fill``) give the novel views 22.65 dB with the true geometry
(``fill:relit``), 2.4 dB short of issue #3's 25 dB. This trains a small U-Net on
``training.fill_features`` caches to repaint a view from the same information (the two-camera blend,
the relit fill, visibility, normals, depth, the fitted light and the projected 3D joints), never the
view's own image, and scores it on the held-out split beside the fills. It starts as the relit fill
(its last layer is zero: the output is the relit fill plus a learnt residual) and is trained on the
masked MSE, which is what the masked PSNR scores. With the true geometry it bounds what a learnt
appearance model of this size and data adds once the geometry is right; it is a measurement, not a
runtime stage (the runtime has no true geometry); docs/training.md, "A learnt painter of the unseen
side", has the figures.

    python -m training.learnt_fill cache --data out/s26/data --split val --limit 256 --out fill_val.npz
    python -m training.learnt_fill cache --data out/s26/data --split train --limit 2048 --out fill_train.npz
    python -m training.learnt_fill train --train-cache fill_train.npz --val-cache fill_val.npz --out runs/fill
    python -m training.learnt_fill score --val-cache fill_val.npz --net runs/fill/fill_net.pt

The same on a model's geometry and picture (``cache --model models/ghnerf/ghnerf.pt`` for both
caches, ``train --set net.shown_input=true``): what the painter would give on a device today. With
``cache --model ... --joints <training.device_joints cache>`` the geometry is the body proxy built from
the device's joints instead (``training.body_proxy``; the model's picture is still the one repainted).

Such a net trained without the relit fill (``--set net.relit_input=false --set net.shown_input=true``:
the light fit is too slow for a device) is the runtime's painter: ``export`` writes it as
``novel_painter.onnx`` (and, with ``--calib-cache``, its int8 twin) for ``ghnerf_runtime.novel_painter``;
``make painter`` runs the whole recipe (docs/training.md, "The painter in the runtime"). The runtime
repaints the proxy's pixels and every pixel its picture shows, the model's fog around the subject
included; the masked MSE never asks for a colour there, so since session 31 the recipe adds
``--set around_weight=0.03``, a second term whose target there is the background (``repainted``), and
the caches skip the light fit such a net does not read (``cache --no-relit``). ``train`` and ``score``
print the whole view as the runtime shows it beside the masked columns (``shown:whole``,
``learnt:whole``).

``train`` takes the GPU when torch sees one (``--device``) and prints the held-out table at the end
(also written to ``<out>/score.md``).

Every file ``train`` and ``export`` write (``fill_net.pt``, ``score.md``, ``score.json``, the ONNX files and
their ``.json``) goes through a temporary file and a rename (``training.model_card.write_atomic``): a crash
or a full disk leaves the previous file or none, never a cut one that ``export`` would then read.
"""
from __future__ import annotations

if __name__ == "__main__":  # python -m: the arguments are parsed before torch loads (training.cli)
    from training.cli.learnt_fill import main as _cli_main

    raise SystemExit(_cli_main())

import io
import json
import math
import pickle
import sys
import tempfile
import time
import warnings
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from ghnerf_runtime.body25 import FLIP_INDEX, NUM_JOINTS
from ghnerf_runtime.cli.output_path import ready_output_arg
from ghnerf_runtime.config import NovelViewConfig
from ghnerf_runtime.metrics import capped_psnr, masked_psnr, scorable_images
from training.evaluate import angle_bins
from training.fill_features import (MASK_BIT, SEEN_BIT, TRUTH_BIT, FillCacheError, check_held_out, load_cache,
                                    relit_in)
from training.model_card import sha256, strict_json, write_atomic
from training.run_limits import seed_problem
from training.step_guard import TrainingDiverged, finite_step

#: blend 3, relit 3, mask 1, seen 1, normals 3, depth 1, light 4 (constant planes), 25 joint maps;
#: with ``FillNetConfig.shown_input``, the model's picture 3 more.
IN_CHANNELS = 41
#: The models' background (the contract's, black): the caches' target is the view over it.
BACKGROUND = 0.0


@dataclass(frozen=True)
class FillNetConfig:
    width: int = 32
    """Channels at full resolution; doubled per level, at most 8x."""
    levels: int = 4
    """Resolutions (128, 64, 32, 16 at 128x128): the coarsest sees the whole body."""
    joint_sigma_px: float = 2.0
    """Std of the Gaussian drawn at each projected joint (pixels)."""
    relit_input: bool = True
    """Read the relit fill and its fitted light. Without them (7 planes fewer) the net starts from the
    blend, or from the model's picture with ``shown_input``: the light fit costs about 0.4 s a scene
    on one core, more than a runtime stage could spend."""
    shown_input: bool = False
    """Read the model's picture (the cache's ``shown``) too, and start from it instead of the relit fill:
    for caches made with a model's geometry, whose picture is better than its repainting."""


@dataclass(frozen=True)
class FillTrainConfig:
    steps: int = 6000
    batch: int = 32
    lr: float = 2e-3
    """Peak AdamW rate; cosine decay after a 200-step warm-up."""
    weight_decay: float = 1e-4
    flip: bool = True
    """Mirror half the batches left-right (joints swapped, normals and light mirrored)."""
    seed: int = 0
    device: str = "auto"
    log_every: int = 500
    max_seconds: float = 0.0
    """Wall-time budget (0: none): the cosine decay follows whichever of steps and time runs out first,
    so a run cut by a lent machine's lease still ends at a low rate."""
    around_weight: float = 0.0
    """Weight of a second masked MSE, over the pixels the runtime's painter changes that are not the
    subject (:func:`repainted`: the proxy's and those the model's picture shows, less the true
    subject; mostly the model's fog), whose target is the background. 0: the subject's pixels alone
    (sessions 28-30: such a painter paints that fog brighter, which the masked PSNR does not see)."""
    net: FillNetConfig = field(default_factory=FillNetConfig)


def _block(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, padding=1), nn.GroupNorm(8, cout), nn.SiLU(),
                         nn.Conv2d(cout, cout, 3, padding=1), nn.GroupNorm(8, cout), nn.SiLU())


class FillNet(nn.Module):
    """A U-Net that returns ``base`` (the relit fill, or the model's picture) plus a residual colour,
    zero at initialisation."""

    def __init__(self, cfg: FillNetConfig = FillNetConfig()) -> None:
        super().__init__()
        self.cfg = cfg
        self.steps_trained = 0  # set by train_fill
        self.trained: dict = {}  # the checkpoint's config and training record (load_net)
        widths = [cfg.width * min(2 ** i, 8) for i in range(cfg.levels)]
        self.stem = _block(IN_CHANNELS - 7 * (not cfg.relit_input) + 3 * cfg.shown_input, widths[0])
        self.down = nn.ModuleList(nn.Sequential(nn.Conv2d(a, b, 3, stride=2, padding=1), _block(b, b))
                                  for a, b in zip(widths[:-1], widths[1:]))
        self.up = nn.ModuleList(_block(b + a, a) for a, b in zip(widths[:-1], widths[1:]))
        self.head = nn.Conv2d(widths[0], 3, 1)
        nn.init.zeros_(self.head.weight)
        nn.init.zeros_(self.head.bias)

    def forward(self, x: torch.Tensor, base: torch.Tensor) -> torch.Tensor:
        skips = [self.stem(x)]
        for down in self.down:
            skips.append(down(skips[-1]))
        h = skips.pop()
        for up in reversed(self.up):
            skip = skips.pop()
            h = F.interpolate(h, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            h = up(torch.cat([h, skip], 1))
        return base + self.head(h).float()


def to_device(arrays: dict[str, np.ndarray], device: torch.device) -> dict[str, torch.Tensor]:
    """The cache's image fields as tensors on ``device`` (still uint8 / int8 / float16: converted per batch)."""
    keep = ("blend", "relit", "shown", "truth", "flags", "normals", "depth", "joints", "light")
    return {k: torch.from_numpy(np.ascontiguousarray(arrays[k])).to(device) for k in keep}


def joint_maps(joints: torch.Tensor, H: int, W: int, sigma: float) -> torch.Tensor:
    """``(N, 25, H, W)`` Gaussians at the projected joints ``(N, 25, 3)`` (u, v, valid)."""
    ys = torch.arange(H, device=joints.device, dtype=torch.float32).view(1, 1, H, 1)
    xs = torch.arange(W, device=joints.device, dtype=torch.float32).view(1, 1, 1, W)
    u, v, valid = (joints[..., i, None, None] for i in range(3))
    return torch.exp(-((xs - u) ** 2 + (ys - v) ** 2) / (2.0 * sigma * sigma)) * valid


def flip_views(b: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The views mirrored left-right: images along W, normals' and light's x negated, joints mirrored and
    their left and right swapped (a mirrored person is a person)."""
    W = b["flags"].shape[-1]
    out = {k: b[k].flip(2) for k in ("blend", "relit", "shown", "truth", "normals")}  # (N, H, W, C)
    out["flags"], out["depth"] = b["flags"].flip(-1), b["depth"].flip(-1)
    out["normals"] = out["normals"] * torch.tensor([-1, 1, 1], dtype=torch.int8, device=b["normals"].device)
    j = b["joints"][:, list(FLIP_INDEX)].clone()
    j[..., 0] = torch.where(j[..., 2] > 0, (W - 1) - j[..., 0], j[..., 0])
    out["joints"] = j
    out["light"] = b["light"] * torch.tensor([-1.0, 1.0, 1.0, 1.0], device=b["light"].device)
    return out


def decoded(b: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """A cache batch's planes as the network reads them, ``(N, C, H, W)`` float: the colours in [0, 1]
    (``blend``, ``relit``, ``shown``, ``truth``), the flags' ``mask``, ``seen`` and ``subject`` (the true
    subject: the loss's and the score's), unit ``normals`` and ``depth``."""
    flags = b["flags"].long()
    out = {k: b[k].permute(0, 3, 1, 2).float() / 255.0 for k in ("blend", "relit", "shown", "truth")}
    for name, bit in (("mask", MASK_BIT), ("seen", SEEN_BIT), ("subject", TRUTH_BIT)):
        out[name] = ((flags & bit) > 0).float()[:, None]
    out["normals"] = b["normals"].permute(0, 3, 1, 2).float() / 127.0
    out["depth"] = b["depth"].float()[:, None]
    return out


def net_inputs(b: dict[str, torch.Tensor],
               cfg: FillNetConfig) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Network input ``(N, C, H, W)``, base and truth ``(N, 3, H, W)`` in [0, 1], and the true subject's
    mask ``(N, 1, H, W)`` (the loss's and the score's)."""
    d = decoded(b)
    N, H, W = b["flags"].shape
    light = b["light"][:, :, None, None].expand(N, 4, H, W)
    maps = joint_maps(b["joints"], H, W, cfg.joint_sigma_px)
    geometry = [d["mask"], d["seen"], d["normals"], d["depth"]]
    if cfg.relit_input:
        base, planes = d["relit"], [d["blend"], d["relit"], *geometry, light, maps]
    else:
        base, planes = d["blend"], [d["blend"], *geometry, maps]
    if cfg.shown_input:
        base = d["shown"]
        planes.append(base)
    return torch.cat(planes, 1), base, d["truth"], d["subject"]


def repainted(b: dict[str, torch.Tensor]) -> torch.Tensor:
    """``(N, 1, H, W)``: the pixels the runtime's painter changes (``NovelPainter.repaint``): the proxy's
    (the geometry's mask) and those the model's picture shows as the subject (its colour test,
    ``novel_view.silhouette_min_diff`` from the background)."""
    from ghnerf_runtime.proxy_blend import subject_region  # noqa: PLC0415 - the runtime's own test

    cfg = NovelViewConfig()
    shown = b["shown"].cpu().numpy()[..., ::-1]  # RGB -> BGR, as the runtime's picture
    region = np.stack([subject_region(v, BACKGROUND, cfg.silhouette_min_diff) for v in shown])
    mask = (b["flags"] & MASK_BIT) > 0
    return (mask | torch.from_numpy(region).to(mask.device)).float()[:, None]


def masked_mse(pred: torch.Tensor, truth: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Per image, the mean squared error over the mask's pixels and the channels; the batch's mean."""
    sq = ((pred - truth) ** 2 * mask).sum((1, 2, 3))
    return (sq / (mask.sum((1, 2, 3)) * pred.shape[1]).clamp_min(1.0)).mean()


def pick_device(kind: str) -> torch.device:
    if kind == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if kind == "cuda" and not torch.cuda.is_available():
        raise RuntimeError("--device cuda: torch sees no GPU")
    return torch.device(kind)


def _subset(b: dict[str, torch.Tensor], idx: torch.Tensor) -> dict[str, torch.Tensor]:
    return {k: v[idx] for k, v in b.items()}


def _predict(net: FillNet, b: dict[str, torch.Tensor], flip_test: bool) -> torch.Tensor:
    """The net's picture of a batch ``(N, 3, H, W)`` in [0, 1]; ``flip_test``: averaged with its picture
    of the mirrored views, mirrored back."""
    device = b["flags"].device
    pred = []
    for views in (b, flip_views(b)) if flip_test else (b,):
        x, base, _, _ = net_inputs(views, net.cfg)
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=device.type == "cuda"):
            pred.append(net(x, base).clamp(0, 1).float())
    return pred[0] if len(pred) == 1 else 0.5 * (pred[0] + pred[1].flip(-1))


@torch.no_grad()
def paintings(net: FillNet | Sequence[FillNet], arrays: dict[str, np.ndarray], device: torch.device | None = None,
              batch: int = 64, flip_test: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """One pass of the network over every cached view: its picture ``(N, H, W, 3)`` in [0, 1] black off
    the subject (the masked scores'), and the whole view as the runtime shows it, the network's colours
    on the pixels it repaints (:func:`repainted`) and the model's picture on the others. Several nets:
    the mean of their pictures (an ensemble); ``flip_test``: each net's picture averaged with that of the
    mirrored views (docs/training.md, "The painter and the fog", has what both buy)."""
    nets = [net] if isinstance(net, FillNet) else list(net)
    device = device or next(nets[0].parameters()).device
    for member in nets:
        member.eval()
    data = to_device(arrays, device)
    n, subject, whole = len(arrays["flags"]), [], []
    for s in range(0, n, batch):
        b = _subset(data, torch.arange(s, min(s + batch, n), device=device))
        pred = torch.stack([_predict(member, b, flip_test) for member in nets]).mean(0)
        planes = decoded(b)
        for out, img in ((subject, pred * planes["subject"]),
                         (whole, torch.where(repainted(b) > 0, pred, planes["shown"]))):
            out.append(img.permute(0, 2, 3, 1).cpu().numpy())
    return np.concatenate(subject), np.concatenate(whole)


def paint(net: FillNet, arrays: dict[str, np.ndarray], device: torch.device | None = None,
          batch: int = 64, as_runtime: bool = False) -> np.ndarray:
    """One of :func:`paintings`: the picture black off the subject, or (``as_runtime``) the whole view."""
    return paintings(net, arrays, device, batch)[int(as_runtime)]


def train_fill(train: dict[str, np.ndarray], cfg: FillTrainConfig, val: dict[str, np.ndarray] | None = None,
               log=print) -> FillNet:
    """Train a :class:`FillNet` on a feature cache; logs the loss (and, with ``val``, its held-out PSNR)."""
    if cfg.net.relit_input and not relit_in(train):
        raise ValueError("the training cache was made without the light fit (cache --no-relit): it holds no relit "
                         "fill; train with --set net.relit_input=false")
    torch.manual_seed(cfg.seed)
    device = pick_device(cfg.device)
    net = FillNet(cfg.net).to(device)
    torch.backends.cudnn.benchmark = device.type == "cuda"  # fixed shapes: let cuDNN pick its kernels once
    opt = torch.optim.AdamW(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    warm = min(200, max(cfg.steps // 10, 1))
    data = to_device(train, device)
    n = len(train["flags"])
    gen = torch.Generator(device="cpu").manual_seed(cfg.seed)
    t0, running = time.monotonic(), []
    log(f"fill net: {sum(p.numel() for p in net.parameters()) / 1e6:.2f} M parameters, {n} training views, "
        f"{cfg.steps} steps of {cfg.batch} on {device}")
    step = 0
    while True:
        progress = step / max(cfg.steps, 1)
        if cfg.max_seconds > 0:
            progress = max(progress, (time.monotonic() - t0) / cfg.max_seconds)
        if progress >= 1.0:
            break
        for g in opt.param_groups:
            g["lr"] = cfg.lr * min((step + 1) / warm, 0.5 * (1 + math.cos(math.pi * progress)))
        net.train()
        idx = torch.randint(0, n, (cfg.batch,), generator=gen).to(device)
        b = _subset(data, idx)
        if cfg.flip and step % 2 == 1:
            b = flip_views(b)
        x, base, truth, mask = net_inputs(b, cfg.net)
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=device.type == "cuda"):
            pred = net(x, base)
        loss = masked_mse(pred, truth, mask)
        if cfg.around_weight > 0:  # the truth is the background off the subject
            loss = loss + cfg.around_weight * masked_mse(pred, truth, repainted(b) * (1.0 - mask))
        opt.zero_grad(set_to_none=True)
        loss.backward()
        running.append(finite_step(loss, net, step + 1))
        opt.step()
        step += 1
        if step % cfg.log_every == 0:
            msg = f"  step {step}: loss {np.mean(running):.5f}"
            if val is not None:
                few = {k: v[:128] for k, v in val.items()}
                held_out = score_rows(few, *paintings(net, few))["novel, all"]
                msg += (f", held-out PSNR (128 views) {held_out['fill:learnt']:.2f} dB "
                        f"(whole view {held_out['learnt:whole']:.2f})")
            log(msg + f", {(time.monotonic() - t0) / step * 1000:.0f} ms/step")
            running = []
    net.steps_trained = step
    log(f"  {step} steps in {time.monotonic() - t0:.0f} s")
    return net


def _psnr(pred: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Per-view masked PSNR as ``ghnerf-eval`` scores a novel view: NaN where the mask is empty or the picture
    has a non-finite pixel (:func:`~ghnerf_runtime.metrics.scorable_images`; :func:`score_rows` counts those),
    an identical view at :data:`~ghnerf_runtime.metrics.PSNR_CAP_DB`."""
    return capped_psnr(np.ravel(masked_psnr(scorable_images(pred)[0], truth, mask).per_image))


def score_rows(arrays: dict[str, np.ndarray], learnt: np.ndarray,
               whole: np.ndarray | None = None) -> dict[str, dict[str, float]]:
    """Mean PSNR per angle bin (and over all novel views) of the blend (with the true geometry: the
    ceiling), the relit fill, the model's picture (caches made with a model) and the learnt fill, over
    the true subject's mask and over the pixels the geometry calls unseen or seen; ``n`` views.
    ``whole``: the learnt fill as the runtime shows it (:func:`paintings`), scored with the
    model's picture over every pixel of the view (``shown:whole``, ``learnt:whole``: the fog counts).

    Scored as ``ghnerf-eval`` scores its novel views: an identical view counts as
    :data:`~ghnerf_runtime.metrics.PSNR_CAP_DB`, the bins are :func:`training.evaluate.angle_bins` (the last
    includes 180 degrees), and a view whose painting (``learnt`` or ``whole``) has a NaN or infinite pixel is
    left out of the painter's columns and counted in ``nonfinite`` (its ``nonfinite_views``); before, such a
    view vanished from the means as if its mask were empty."""
    truth = arrays["truth"].astype(np.float64) / 255.0
    flags = arrays["flags"]
    mask, seen = (flags & TRUTH_BIT) > 0, (flags & SEEN_BIT) > 0
    unseen = mask & ~seen
    true_geometry = bool((arrays["geometry"] == "truth").all())
    blend, relit = arrays["blend"] / 255.0, arrays["relit"] / 255.0
    cols = {"ceiling" if true_geometry else "blend": _psnr(blend, truth, mask)}
    relit_fill = relit_in(arrays)  # a cache made without the light fit has no relit fill to score
    if relit_fill:
        cols["fill:relit"] = _psnr(relit, truth, mask)
    if not true_geometry:
        cols["shown"] = _psnr(arrays["shown"] / 255.0, truth, mask)
    cols["fill:learnt"] = _psnr(learnt, truth, mask)
    if relit_fill:
        cols["relit:unseen"] = _psnr(relit, truth, unseen)
    cols["learnt:unseen"] = _psnr(learnt, truth, unseen)
    cols["learnt:seen"] = _psnr(learnt, truth, mask & seen)
    if whole is not None:
        everywhere = np.ones_like(mask)
        cols["shown:whole"] = _psnr(arrays["shown"] / 255.0, truth, everywhere)
        cols["learnt:whole"] = _psnr(whole, truth, everywhere)
    if true_geometry:
        cols["ceil:seen"] = _psnr(blend, truth, mask & seen)
    broken = scorable_images(learnt)[1]
    if whole is not None:
        broken |= scorable_images(whole)[1]
    angle = arrays["angle"]
    groups = [(f"novel {lo:g}-{hi:g} deg", inside) for lo, hi, inside in angle_bins(angle)]
    groups.append(("novel, all", np.ones(len(angle), bool)))
    rows = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a bin whose views have no unseen pixel: NaN
        for label, keep in groups:
            if keep.any():
                rows[label] = {"n": int(keep.sum()), "nonfinite": int((keep & broken).sum()),
                               **{k: float(np.nanmean(v[keep])) for k, v in cols.items()}}
    return rows


def table(rows: dict[str, dict[str, float]]) -> str:
    """:func:`score_rows` as a markdown table; a ``nonfinite`` column (views the painter's columns leave out)
    only when some view's painting was non-finite, so a sound run's table reads as before."""
    first = next(iter(rows.values()))
    cols = [c for c in ("ceiling", "blend", "fill:relit", "shown", "fill:learnt", "relit:unseen", "learnt:unseen",
                        "ceil:seen", "learnt:seen", "shown:whole", "learnt:whole") if c in first]
    counts = ["n"] + (["nonfinite"] if any(r.get("nonfinite", 0) for r in rows.values()) else [])
    lines = ["| views | " + " | ".join(counts + cols) + " |", "|---" * (len(cols) + len(counts) + 1) + "|"]
    for label, r in rows.items():
        lines.append(f"| {label} | " + " | ".join([str(r.get(c, 0)) for c in counts] + [f"{r[c]:.2f}" for c in cols])
                     + " |")
    return "\n".join(lines)


def save_net(net: FillNet, cfg: FillTrainConfig, path: Path, **info) -> None:
    # whole or not at all: a cut fill_net.pt under its name is what export would read next
    buf = io.BytesIO()
    torch.save({"config": asdict(cfg), "state_dict": net.state_dict(), "info": info}, buf)
    write_atomic(path, buf.getvalue())


def load_net(path: str | Path, device: torch.device | str = "cpu") -> FillNet:
    path = Path(path)
    try:
        ckpt = torch.load(path, map_location=device, weights_only=True)
        net = FillNet(FillNetConfig(**ckpt["config"]["net"]))
        net.load_state_dict(ckpt["state_dict"])
        net.steps_trained = int(ckpt.get("info", {}).get("steps", 0))
        # What the checkpoint says of its own training, for an export made without its score.json beside
        # it (a net brought back alone from a GPU machine).
        net.trained = {"config": ckpt["config"], **ckpt.get("info", {})}
    except (OSError, RuntimeError, KeyError, TypeError, EOFError, pickle.UnpicklingError) as e:
        raise ValueError(f"{path}: not a fill-net checkpoint ({e})") from e
    return net.to(device)


# ---------------------------------------------------------------------------------------------- the runtime's painter
class PainterGraph(nn.Module):
    """A :class:`FillNet` that reads the runtime's inputs (``ghnerf_runtime.novel_painter``): the image
    planes ``(N, 12, H, W)`` and the projected joints ``(N, 25, 3)``, whose Gaussians it draws itself;
    returns the repainted picture in [0, 1]. Only a net without the relit fill and with the model's
    picture (``net.relit_input=false``, ``net.shown_input=true``) runs on the device: the light fit is
    too slow there."""

    def __init__(self, net: FillNet) -> None:
        super().__init__()
        if net.cfg.relit_input or not net.cfg.shown_input:
            raise ValueError("the runtime's painter is trained with net.relit_input=false and net.shown_input=true; "
                             f"this net has {net.cfg}")
        self.net = net

    def forward(self, planes: torch.Tensor, joints: torch.Tensor) -> torch.Tensor:
        H, W = planes.shape[-2:]
        maps = joint_maps(joints, H, W, self.net.cfg.joint_sigma_px)
        x = torch.cat([planes[:, :9], maps, planes[:, 9:]], 1)  # net_inputs' order: ..., depth, maps, shown
        return self.net(x, planes[:, 9:]).clamp(0.0, 1.0)


def painter_planes_of(b: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """A cache batch's runtime inputs (``ghnerf_runtime.novel_painter.PLANES`` and the joints)."""
    d = decoded(b)
    return torch.cat([d[k] for k in ("blend", "mask", "seen", "normals", "depth", "shown")], 1), b["joints"].float()


def export_painter(net: FillNet, path: str | Path, metadata: dict[str, str], size: int = 128) -> Path:
    """``net`` as the runtime's ``novel_painter.onnx`` (dynamic batch and image size), with the
    ``ghnerf_painter.*`` metadata."""
    import onnx  # noqa: PLC0415

    from ghnerf_runtime import novel_painter as rt  # noqa: PLC0415

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    graph = PainterGraph(net.cpu().eval())
    planes, joints = torch.zeros(1, len(rt.PLANES), size, size), torch.zeros(1, NUM_JOINTS, 3)
    axes = {"planes": {0: "N", 2: "H", 3: "W"}, "joints": {0: "N"}, rt.OUTPUT: {0: "N", 2: "H", 3: "W"}}
    with tempfile.TemporaryDirectory() as tmp:  # the graph without its metadata never sits under path
        raw = Path(tmp) / "painter.onnx"
        torch.onnx.export(graph, (planes, joints), str(raw), input_names=list(rt.INPUTS),
                          output_names=[rt.OUTPUT], opset_version=17, dynamo=False, dynamic_axes=axes)
        model = onnx.load(str(raw))
    meta = {"feature_version": str(rt.FEATURE_VERSION), "joint_sigma_px": str(net.cfg.joint_sigma_px),
            "width": str(net.cfg.width), "levels": str(net.cfg.levels), "steps": str(net.steps_trained), **metadata}
    for k, v in meta.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = rt.META_PREFIX + k, str(v)
    write_atomic(path, model.SerializeToString())
    return path


def quantize_painter(fp32_path: str | Path, out_path: str | Path, arrays: dict[str, np.ndarray],
                     views: int = 64) -> Path:
    """Static int8 QDQ of the painter's convolutions (``training.export.quantize``'s default policy, as the
    encoder's), calibrated on a cache's first ``views`` (a training cache: the held-out one scores it); its
    metadata is the fp32 file's, with the precision and the fp32 file's sha256."""
    import onnx  # noqa: PLC0415

    from ghnerf_runtime import novel_painter as rt  # noqa: PLC0415
    from training.export.quantize import QuantPolicy, quantize_qdq  # noqa: PLC0415

    fp32_path, out_path = Path(fp32_path), Path(out_path)
    few = {k: v[:views] for k, v in arrays.items()}
    planes, joints = painter_planes_of(to_device(few, torch.device("cpu")))
    feeds = [{"planes": planes[i:i + 1].numpy(), "joints": joints[i:i + 1].numpy()} for i in range(len(planes))]
    meta = {p.key: p.value for p in onnx.load(str(fp32_path)).metadata_props}
    meta[rt.META_PREFIX + "precision"] = "int8"
    meta[rt.META_PREFIX + "calibration_views"] = str(len(feeds))
    meta[rt.FP32_SHA256_KEY] = sha256(fp32_path)  # what the runtime's stale-int8 check compares first
    with tempfile.TemporaryDirectory() as tmp:  # quantized, then stamped: only the stamped file takes the name
        raw = quantize_qdq(fp32_path, Path(tmp) / "painter.int8.onnx", feeds, QuantPolicy(), "novel_painter")
        model = onnx.load(str(raw))
    del model.metadata_props[:]
    for k, v in meta.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = k, v
    write_atomic(out_path, model.SerializeToString())
    return out_path


def onnx_rows(path: Path, arrays: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """:func:`score_rows` of an exported painter run through onnxruntime over a whole cache."""
    from ghnerf_runtime.novel_painter import NovelPainter, PainterPlanes  # noqa: PLC0415

    painter, out, whole = NovelPainter.load(path), [], []
    for s in range(0, len(arrays["flags"]), 64):
        b = to_device({k: v[s:s + 64] for k, v in arrays.items()}, torch.device("cpu"))
        planes, joints = painter_planes_of(b)
        subject = ((b["flags"].long() & TRUTH_BIT) > 0).numpy()[..., None]
        changed = repainted(b).numpy().transpose(0, 2, 3, 1) > 0
        shown = decoded(b)["shown"].numpy().transpose(0, 2, 3, 1)
        for p, j, m, c, v in zip(planes.numpy(), joints.numpy(), subject, changed, shown):
            painted = painter.paint(PainterPlanes(p, j, p[3] > 0))
            out.append(painted * m)
            whole.append(np.where(c, painted, v))
    return score_rows(arrays, np.stack(out), np.stack(whole))


def _parse_sets(cfg: FillTrainConfig, sets: list[str]) -> FillTrainConfig:
    """``key=value`` overrides; ``net.width=16`` reaches the network's config."""
    net = asdict(cfg.net)
    top = {k: v for k, v in asdict(cfg).items() if k != "net"}
    for s in sets:
        key, sep, value = s.partition("=")
        target, name = (net, key[4:]) if key.startswith("net.") else (top, key)
        if not sep or name not in target:
            raise ValueError(f"--set {s}: expected key=value with key one of {sorted(top)} or net.{sorted(net)}")
        kind = type(target[name])
        try:
            target[name] = _bool_of(value) if kind is bool else kind(value)
        except ValueError:
            what = "true or false (1/0, yes/no)" if kind is bool else f"a {kind.__name__}"
            raise ValueError(f"--set {s}: {key} takes {what}, got {value!r}") from None
    cfg = replace(FillTrainConfig(**top), net=FillNetConfig(**net))
    if problem := _config_problem(cfg):
        raise ValueError(f"--set {problem}")
    return cfg


def _bool_of(text: str) -> bool:
    """A ``--set`` truth value; a ValueError for any other word (``flip=on``, ``flip=ture`` were False)."""
    word = text.strip().lower()
    if word in ("1", "true", "yes"):
        return True
    if word in ("0", "false", "no"):
        return False
    raise ValueError(text)


def _config_problem(cfg: FillTrainConfig) -> str | None:
    """What is wrong with ``cfg`` (``key: why, got value``), or None: values that trained nothing (lr 0),
    divided by zero (log_every 0) or failed inside torch (a width GroupNorm's 8 groups do not divide)."""
    checks = (
        ("steps", cfg.steps >= 1, "must be at least 1"), ("batch", cfg.batch >= 1, "must be at least 1"),
        ("lr", cfg.lr > 0 and math.isfinite(cfg.lr), "must be a positive number"),
        ("weight_decay", cfg.weight_decay >= 0 and math.isfinite(cfg.weight_decay), "must be a finite number >= 0"),
        ("log_every", cfg.log_every >= 1, "must be at least 1"),
        ("max_seconds", cfg.max_seconds >= 0 and math.isfinite(cfg.max_seconds),
         "must be a finite number >= 0 (0: none)"),
        ("around_weight", cfg.around_weight >= 0 and math.isfinite(cfg.around_weight), "must be a finite number >= 0"),
        ("net.width", cfg.net.width >= 8 and cfg.net.width % 8 == 0, "must be a multiple of 8 (GroupNorm's groups)"),
        ("net.levels", cfg.net.levels >= 1, "must be at least 1"),
        ("device", cfg.device in ("auto", "cpu", "cuda"), "must be auto, cpu or cuda"),  # (torch's RuntimeError)
        ("net.joint_sigma_px", cfg.net.joint_sigma_px > 0 and math.isfinite(cfg.net.joint_sigma_px),
         "must be a positive number"),
    )
    for key, ok, why in checks:
        if not ok:
            value = getattr(cfg.net, key[4:]) if key.startswith("net.") else getattr(cfg, key)
            return f"{key}: {why}, got {value}"
    if problem := seed_problem(cfg.seed):  # past 2**64 was torch's 'Overflow when unpacking long long' traceback
        return f"seed: {problem}"  # (after the caches loaded); the trainers' bound
    return None


def drop_stale_int8(out: Path, remade: bool) -> list[Path]:
    """Remove the int8 twin of the painter ``out`` an export replaces (returned, to be dropped from the card
    too): the runtime takes the int8 file first (precision auto or int8), and ran the previous painter in place
    of the new one where the export made no int8 file, or stopped before it (a Ctrl-C in the calibration).
    Removed before the new fp32 file is written: a stop between the two leaves the previous fp32 painter alone,
    not two painters. ``remade``: the export writes a new one (no word then)."""
    stale = Path(out).with_suffix(".int8.onnx")
    if not stale.is_file():
        return []
    stale.unlink()
    if not remade:
        print(f"{stale}: removed, the int8 file of the painter this export replaces (--calib-cache makes this "
              "one's)", file=sys.stderr)
    return [stale]


def _export_cli(args) -> int:
    import hashlib  # noqa: PLC0415

    try:  # every input read before anything is written: a bad --net or cache was a traceback (the caches' after
        # the painter was written)
        net = _exportable(load_net(args.net), args.net)
        calib = load_cache(args.calib_cache) if args.calib_cache is not None else None
        val = load_cache(args.val_cache) if args.val_cache is not None else None
    except ValueError as e:  # load_net's or a FillCacheError: the message names the file
        print(f"error: {e}", file=sys.stderr)
        return 2
    # The checkpoint's own record; the score.json beside it lends its held-out rows only if it is this
    # net's (another run's may sit in the folder a net was copied into).
    trained = dict(net.trained)
    score_json = args.net.parent / "score.json"
    if score_json.is_file() and (scored := _score_record(score_json)) is not None:  # (an unreadable one is named)
        if scored.get("steps") == net.steps_trained and scored.get("config") == net.trained.get("config"):
            trained["rows"] = scored.get("rows")
        else:
            print(f"{score_json}: another run's (steps or config differ from {args.net}): its figures are not "
                  "used", file=sys.stderr)
    meta = {"trained_on": str(args.net), "hardware": str(trained.get("hardware", "")),
            "seconds": str(trained.get("seconds", ""))}
    dropped = drop_stale_int8(args.out, remade=calib is not None)
    out = export_painter(net, args.out, meta)
    report = {"command": "python -m training.learnt_fill export " + " ".join(
                  f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items() if k != "cmd" and v is not None),
              "net": str(args.net), "steps": net.steps_trained, "config": trained.get("config"),
              "train_views": trained.get("train_views"), "train_s": trained.get("seconds"),
              "hardware": trained.get("hardware"), "held_out": trained.get("rows")}
    outs = [out]
    if calib is not None:
        outs.append(quantize_painter(out, out.with_suffix(".int8.onnx"), calib))
    if val is not None:
        if not report["held_out"]:  # no score.json of this net: the torch net's own figures on this cache
            report["held_out"] = score_rows(val, *paintings(net, val))
            report["held_out_cache"] = str(args.val_cache)
            report["held_out_scored_on"] = "cpu, float32"  # train scores on its own device (bf16 on a GPU)
        report["parity"] = painter_parity(net, out, val)
        print(f"onnxruntime vs torch on {report['parity']['views']} views: max |diff| "
              f"{report['parity']['max_abs']:.2e}, PSNR {report['parity']['psnr_db']:.1f} dB")
        report["onnx_held_out"] = {}
        for path in outs:
            precision = "int8" if path.name.endswith(".int8.onnx") else "fp32"
            report["onnx_held_out"][precision] = rows = onnx_rows(path, val)
            print(f"{path.name} (onnxruntime, {precision}) held out:\n{table(rows)}")
    # strict JSON: a held-out bin with no views scores NaN, identical pictures inf; bare NaN is not JSON
    write_atomic(out.with_suffix(".json"), strict_json(report))
    for path in outs:
        print(f"{path}: {path.stat().st_size / 1e6:.2f} MB, sha256 {hashlib.sha256(path.read_bytes()).hexdigest()[:16]}")
    if args.card_dir is not None:
        from training.model_card import add_painter_to_card  # noqa: PLC0415

        print(add_painter_to_card(args.card_dir, out, outs[1:], dropped))
    return 0


def _exportable(net: FillNet, path: Path) -> FillNet:
    """``net`` when the runtime can run it as its painter (:class:`PainterGraph`), else a ValueError naming ``path``:
    refused before anything is written (the refusal was a traceback after the previous int8 painter was removed)."""
    try:
        PainterGraph(net)
    except ValueError as e:
        raise ValueError(f"--net {path}: {e}") from None
    return net


def _score_record(path: Path) -> dict | None:
    """The ``score.json`` beside a net as an object, or None with a line saying why it is not used: a cut or
    hand-edited file was a JSONDecodeError or AttributeError traceback before the export began."""
    try:
        scored = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        print(f"{path}: cannot be read as JSON ({type(e).__name__}: {e}): its figures are not used", file=sys.stderr)
        return None
    if not isinstance(scored, dict):
        print(f"{path}: holds a JSON {type(scored).__name__}, not the train command's record: its figures are not "
              "used", file=sys.stderr)
        return None
    return scored


def painter_parity(net: FillNet, path: Path, arrays: dict[str, np.ndarray], views: int = 8) -> dict:
    """The exported painter through onnxruntime against the torch net on a cache's first ``views``."""
    from ghnerf_runtime.novel_painter import NovelPainter, PainterPlanes  # noqa: PLC0415

    few = {k: v[:views] for k, v in arrays.items()}
    b = to_device(few, torch.device("cpu"))
    planes, joints = painter_planes_of(b)
    with torch.no_grad():
        want = PainterGraph(net.cpu().eval())(planes, joints).permute(0, 2, 3, 1).numpy()
    painter = NovelPainter.load(path)
    got = np.stack([painter.paint(PainterPlanes(p, j, p[3] > 0)) for p, j in zip(planes.numpy(), joints.numpy())])
    mse = float(np.mean((got - want) ** 2))
    return {"views": len(got), "max_abs": float(np.abs(got - want).max()),
            "psnr_db": float(10 * np.log10(1.0 / max(mse, 1e-20)))}


def _cache_cli(args) -> int:
    """``cache``: a joints cache, dataset or checkpoint that is missing or wrong is one line naming it, exit 2."""
    from training.data.errors import DataError  # noqa: PLC0415
    from training.device_joints import JointsCacheError  # noqa: PLC0415
    from training.fill_features import cache_split  # noqa: PLC0415
    from training.model.config import ConfigError  # noqa: PLC0415

    try:
        cache_split(args.data, args.split, args.out, args.limit, args.workers, model=args.model, joints=args.joints,
                    relight=not args.no_relit)
    except (JointsCacheError, DataError, ConfigError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


def _held_out_pair(train_path: Path, val_path: Path,
                   cfg: FillTrainConfig) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The training and validation caches, checked to be a held-out pair (``fill_features.check_held_out``) that
    holds what the net reads; a :class:`FillCacheError` names the file otherwise."""
    check_held_out(train_path, val_path)
    train, val = load_cache(train_path), load_cache(val_path)
    if cfg.net.relit_input:  # a cache without the light fit: the net would read the picture as the relit fill
        for flag, path, arrays in (("--train-cache", train_path, train), ("--val-cache", val_path, val)):
            if not relit_in(arrays):
                raise FillCacheError(f"{flag} {path}: made without the light fit (cache --no-relit): it holds no "
                                     "relit fill; train with --set net.relit_input=false")
    return train, val


def main(argv: list[str] | None = None) -> int:
    from training.cli.learnt_fill import build_parser  # noqa: PLC0415

    ap = build_parser()
    args = ap.parse_args(argv)
    if args.cmd == "cache" and args.joints and not args.model:  # cache_split's ValueError, a traceback
        ap.error("--joints: takes --model too (the model's picture is the one repainted)")
    if getattr(args, "device", None) == "cuda" and not torch.cuda.is_available():  # pick_device's RuntimeError
        ap.error("--device cuda: torch sees no GPU")
    # the cache, the training and the export take minutes to hours: where they go is settled first
    if args.cmd == "train":
        args.out = ready_output_arg(ap, args.out, "--out", kind="folder")
    elif args.cmd == "cache":
        args.out = ready_output_arg(ap, args.out, "--out", suffix=".npz")
    elif args.cmd == "export":
        args.out = ready_output_arg(ap, args.out, "--out")
    if args.cmd == "export" and args.card_dir is not None:
        from training.model_card import CardError, check_card_dir  # noqa: PLC0415

        try:
            check_card_dir(args.card_dir, args.out, "--card-dir")
        except CardError as e:
            ap.error(str(e))

    if args.cmd == "export":
        return _export_cli(args)
    if args.cmd == "cache":
        return _cache_cli(args)
    if args.cmd == "score":
        try:
            nets = [load_net(path, pick_device(args.device)) for path in args.net]
            val = load_cache(args.val_cache)
        except ValueError as e:  # a FillCacheError, or load_net's: the message names the file
            print(f"error: {e}", file=sys.stderr)
            return 2
        print(table(score_rows(val, *paintings(nets, val, flip_test=args.flip_test))))
        return 0
    try:
        cfg = _parse_sets(FillTrainConfig(), args.set)
    except ValueError as e:
        ap.error(str(e))
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.device:
        cfg = replace(cfg, device=args.device)
    if cfg.device == "cuda" and not torch.cuda.is_available():  # (--set device=cuda: pick_device's RuntimeError)
        ap.error("device cuda: torch sees no GPU")
    try:
        train, val = _held_out_pair(args.train_cache, args.val_cache, cfg)
    except FillCacheError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.train_views:
        held = len(train["flags"])
        if args.train_views > held:  # was trained on every view and reported as --train-views' share
            print(f"error: --train-views {args.train_views}: {args.train_cache} holds {held} training views",
                  file=sys.stderr)
            return 2
        train = {k: v[:args.train_views] for k, v in train.items()}
    t0 = time.monotonic()
    try:
        net = train_fill(train, cfg, val=val)
    except TrainingDiverged as e:  # one line, and no fill_net.pt / score of NaN weights
        print(f"error: training diverged: {e}", file=sys.stderr)
        return 1
    seconds = time.monotonic() - t0
    rows = score_rows(val, *paintings(net, val))
    args.out.mkdir(parents=True, exist_ok=True)
    device = next(net.parameters()).device
    hardware = (torch.cuda.get_device_name(device) if device.type == "cuda"
                else f"cpu, {torch.get_num_threads()} threads")
    info = {"train_views": len(train["flags"]), "steps": net.steps_trained, "seconds": round(seconds, 1),
            "hardware": hardware}
    save_net(net, cfg, args.out / "fill_net.pt", **info)
    report = (f"{len(val['flags'])} held-out views ({args.val_cache}), fill net trained on {len(train['flags'])} "
              f"views ({args.train_cache}), {net.steps_trained} steps of {cfg.batch} in {seconds:.0f} s on "
              f"{hardware}; masked PSNR, dB\n\n{table(rows)}\n")
    write_atomic(args.out / "score.md", report)
    write_atomic(args.out / "score.json", strict_json({"config": asdict(cfg), "rows": rows, **info}))
    print(report)
    return 0

