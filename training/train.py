"""``ghnerf-train`` (``python -m training.train``): train GHNeRF (or the baseline) on a cached dataset.

Example::

    python -m training.train --config training/train_configs/edge128.json --out runs/edge128
    python -m training.train --config training/train_configs/edge128.json --out runs/edge128 --resume
    torchrun --nproc_per_node 2 -m training.train --config ... --out ...     # DDP (nccl on GPU, gloo on CPU)

One step = one scene (2 source images) per process and ``targets_per_iter`` target cameras of it
(half sources, half novel views). Per target, rays are drawn (see :func:`sample_rays`):

* ``heat_rays`` rays on the heatmap grid (``contract.ray_grid`` at ``heatmap_stride``: 32x32 at 128),
  ``mask_fraction`` (0.75, as in ENeRF/GHNeRF) of them on grid cells touching the subject mask;
  they carry colour and heatmap supervision;
* one ``patch_size`` x ``patch_size`` block of full-resolution rays centred on a random subject pixel;
  it carries colour, heatmap and the SSIM patch loss (the perceptual-loss substitute).

Targets: colour is the subject over the model's background (black), bilinearly sampled at the ray;
heatmaps are the dataset's Gaussians (``metrics.gaussian_heatmaps``, sigma 1.5 heatmap pixels)
evaluated at the ray in model pixels (sigma ``1.5 * stride``), identical to ``tgt_heatmaps`` on the grid.

Checkpoints (``ckpt_XXXXXXX.pt`` and ``last.pt``) hold the model, the optimiser, the step, the config,
the process count and every RNG state, so ``--resume`` continues bit-identically to an uninterrupted run
(on CPU): from ``last.pt``, else from the newest readable ``ckpt_*.pt``; in an empty folder it starts fresh.
It refuses another config, another model config (the one the checkpoint stores), another process count, and a
file that is no training checkpoint (a weights-only ``ghnerf.pt`` placed as ``last.pt``), before anything is written;
``log.jsonl`` keeps the records up to the checkpoint's step, and the later ones are an uninterrupted run's (the
checkpoint keeps the log's running window and last PCK). Without ``--resume`` a folder that holds checkpoints is
refused (exit 2), so a new run never overwrites another. The dataset and split are opened (and checked against
the model's resolution) before ``config.json`` is written; a missing one exits 2 with one line. A NaN or infinite
loss term or gradient stops the run before that update, and a checkpoint that cannot be written (a full disk)
stops it with the previous one intact: each in one line naming the step and term, or the file (exit 1).
"""
from __future__ import annotations

if __name__ == "__main__":  # python -m: the arguments are parsed before torch loads (training.cli)
    from training.cli.train import main as _cli_main

    raise SystemExit(_cli_main())

import argparse
import json
import math
import os
import pickle
import random
import sys
import time
import tomllib
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Callable, Literal, Mapping

import numpy as np
import torch
import torch.distributed as dist
import torch.nn.functional as F
from torch import Tensor

from ghnerf_runtime.cli.sigterm import exit_status, sigterm_as_interrupt, stop_signals_deferred, stop_words
from ghnerf_runtime.config import read_json_file
from ghnerf_runtime.contract import ray_grid
from training.configs import PRESETS, preset
from training.losses import LossConfig, compute_losses
from training.model import GHNeRF, ModelConfig
from training.model.config import Config, ConfigError
from training.model_card import strict_json, write_atomic
from training.run_clock import RunClock
from training.run_limits import seed_problem, threads_problem
from training.run_lock import lock_holder, lock_text
from training.step_guard import TrainingDiverged

CHECKPOINT_VERSION = 1
HEATMAP_SIGMA_HM_PX = 1.5
"""Gaussian sigma of the ground-truth heatmaps in heatmap pixels (``TargetConfig.heatmap_sigma``)."""


# ---------------------------------------------------------------------------------------------- config
@dataclass
class TrainConfig(Config):
    """Everything a training run needs; validated once by :meth:`from_dict` / :meth:`validate`."""

    preset: str = "edge128"
    """Model preset of ``training.configs`` (``tiny``, ``edge128``, ``edge128_baseline``)."""
    model: dict = field(default_factory=dict)
    """Partial ``ModelConfig`` overriding the preset (``{"human": {"decoder": "fpn"}}``; ``--set model.x.y=v``):
    an architecture experiment without a new preset. The checkpoint stores the resulting model config."""
    data: str = "data/edge128"
    """Dataset folder (``dataset.json``), made by ``python -m training.data.generate``."""
    split: str = "train"
    """Training split."""
    iterations: int = 1000
    """Optimiser steps (one scene per process per step)."""
    targets_per_iter: int = 2
    """Target cameras per scene and step: ceil(n/2) source views (heatmaps in the sources) + the rest novel."""
    heat_rays: int = 256
    """Rays per target on the heatmap grid (``heatmap_stride``), colour + heatmap supervision."""
    patch_size: int = 12
    """Side of the full-resolution ray patch per target (colour + heatmap + SSIM); 0 disables it."""
    mask_fraction: float = 0.75
    """Fraction of grid rays (and patch centres) drawn inside the subject mask."""
    lr: float = 5e-4
    """Adam learning rate."""
    lr_decay_every: int = 0
    """Multiply the learning rate by ``lr_decay_gamma`` every this many steps (0: constant)."""
    lr_decay_gamma: float = 0.5
    """Step decay factor."""
    lr_min: float = 0.0
    """Floor of the decayed learning rate (a longer schedule then extends a shorter one unchanged)."""
    grad_clip: float = 0.0
    """Clip the global gradient norm (0: off)."""
    encoder_views: Literal["sources", "all"] = "sources"
    """Images the human encoder's auxiliary heatmap head is supervised on each step: the two sources, or
    every view of the scene (the novel target views too: the encoder sees them only for this loss)."""
    encoder_flip: bool = False
    """Also supervise the auxiliary head on the mirrored images (left/right joints swapped): twice the
    images per step, and the left/right distinction taught by contrast."""
    frame_padding: bool = False
    """Show the model's inputs the runtime's black padding where a crop reaches past its camera's frame
    (``training.data.frame_padding``; the targets keep the whole picture). Also the ``pretrain_human``
    stage's, unless its block says otherwise. Off when a config does not say it: configs made before it
    keep training as they did."""
    edge_cut: float = 0.0
    """With ``frame_padding``: the share of source views shown as if the person stood at the frame's edge, the
    frame cut so that 25-50 % of the crop is black (``TargetConfig.edge_cut``). Also the ``pretrain_human``
    stage's, unless its block says otherwise. 0: none."""
    loss: LossConfig = field(default_factory=LossConfig)
    """Loss weights (``l_col + 0.5 l_heat + ssim_weight * (1 - SSIM) [+ coord_weight * l_coord]
    [+ mask_weight * l_mask] [+ depth_weight * l_depth]``)."""
    seed: int = 0
    """Seed of the weights, data order, ray sampling and stratified samples."""
    checkpoint_every: int = 500
    """Save a checkpoint every this many steps (and at the end)."""
    log_every: int = 25
    """Progress line / log record every this many steps."""
    pck_every: int = 100
    """Render the source heatmap grids of the current scene every this many steps for the PCK in the log (0: off)."""
    threads: int = 0
    """torch CPU threads per process (0: ``os.cpu_count()`` / processes on this machine)."""
    device: Literal["auto", "cpu", "cuda"] = "auto"
    """``auto``: cuda when present, else CPU."""
    init: str = ""
    """torchvision-format resnet18 state dict for the human encoder ('' = from scratch)."""
    human_init: str = ""
    """A ``human.pt`` from ``python -m training.pretrain_human`` (trunk, projections and heatmap head of the
    human encoder, pretrained on 2D heatmaps alone); loaded after ``init``. '' = none."""
    freeze_human: bool = False
    """Keep the human encoder (trunk, projections, heatmap head, BatchNorm statistics) as ``human_init`` or
    ``init`` left it: no gradients, no auxiliary-head images or loss. The joint run then only teaches the
    NeRF to read its features, and its steps skip the encoder's backward pass (docs/training.md)."""
    pretrain_human: dict = field(default_factory=dict)
    """The ``PretrainConfig`` (``training.pretrain_human``) of the stage that makes ``human_init``; read by
    the pipeline (which runs it first and sets ``human_init``), ignored by the trainer itself."""
    max_minutes: float = 0.0
    """Stop (with a checkpoint) after this wall time (0: no limit). The run then counts as finished early."""

    def validate(self) -> None:
        def fail(key: str, why: str) -> None:
            raise ConfigError(f"{key}: {why}")

        if self.preset not in PRESETS:
            fail("preset", f"unknown preset {self.preset!r}; presets: {sorted(PRESETS)}")
        for key in ("iterations", "targets_per_iter", "heat_rays", "checkpoint_every", "log_every"):
            if getattr(self, key) < 1:
                fail(key, f"must be >= 1, got {getattr(self, key)}")
        for key in ("patch_size", "lr_decay_every", "threads", "pck_every"):
            if getattr(self, key) < 0:
                fail(key, f"must be >= 0, got {getattr(self, key)}")
        for key, problem in (("seed", seed_problem(self.seed)), ("threads", threads_problem(self.threads, 0))):
            if problem:  # torch takes both as C integers: past them the run failed after config.json was written
                fail(key, problem)
        if self.patch_size == 1:
            fail("patch_size", "must be 0 (off) or >= 2")
        if not 0.0 <= self.mask_fraction <= 1.0:
            fail("mask_fraction", f"must be in [0, 1], got {self.mask_fraction}")
        if not (self.lr > 0 and math.isfinite(self.lr)):
            fail("lr", f"must be a positive number, got {self.lr}")
        if not 0 < self.lr_decay_gamma <= 1:
            fail("lr_decay_gamma", f"must be in (0, 1], got {self.lr_decay_gamma}")
        for key in ("grad_clip", "max_minutes"):  # NaN compares False with everything: test for it
            v = getattr(self, key)
            if not (math.isfinite(v) and v >= 0):
                fail(key, f"must be a finite number >= 0 (0: off), got {v}")
        if not (self.lr_min >= 0 and math.isfinite(self.lr_min)):
            fail("lr_min", f"must be a finite number >= 0, got {self.lr_min}")
        for f in fields(LossConfig):
            v = getattr(self.loss, f.name)
            if isinstance(v, float) and (v < 0 or not math.isfinite(v)):
                fail(f"loss.{f.name}", f"must be a finite number >= 0, got {v}")
        if self.loss.ssim_window < 1:
            fail("loss.ssim_window", "must be >= 1")
        if not self.data:
            fail("data", "must name the dataset folder")
        padding_config(self.frame_padding, self.edge_cut)  # named here, before a dataset is opened
        if not isinstance(self.model, Mapping):
            fail("model", f"must be a mapping of ModelConfig overrides, got {self.model!r}")
        if not isinstance(self.pretrain_human, Mapping):
            fail("pretrain_human", f"must be a mapping (a PretrainConfig), got {self.pretrain_human!r}")
        if self.pretrain_human:
            from training.pretrain_human import config_from_train_config  # lazy: it imports this module
            config_from_train_config(asdict(self))  # a bad block fails here, named pretrain_human.<key>
        mcfg = self.model_config()  # unknown or mistyped model keys fail here, named by their path
        try:  # sizes that do not fit (a zero stride) fail here, not as a ZeroDivisionError after config.json
            mcfg.validate()
        except ConfigError as e:
            raise ConfigError(f"model.{e}") from e
        for key in ("init", "freeze_human"):  # named here, before a dataset is opened or a file written
            if getattr(self, key) and not mcfg.use_human_encoder:
                fail(key, "the preset has no human encoder")
        if self.patch_size > min(mcfg.height, mcfg.width):  # sample_rays would place the patch off the image
            fail("patch_size", f"must be at most the model's {mcfg.width}x{mcfg.height} input, got {self.patch_size}")
        lw = self.loss.level_weights
        if any(not (math.isfinite(w) and w >= 0) for w in lw):
            fail("loss.level_weights", f"must be finite numbers >= 0, got {list(lw)}")
        if lw and len(lw) != len(mcfg.levels):
            fail("loss.level_weights", f"has {len(lw)} entries for the model's {len(mcfg.levels)} cascade levels")

    def model_config(self) -> ModelConfig:
        """The preset with ``model`` merged on top, validated (unknown keys name their path)."""
        return model_config_of(self.preset, self.model)


def model_config_of(preset_name: str, overrides: Mapping[str, Any]) -> ModelConfig:
    """A preset with partial ``ModelConfig`` overrides merged on top (``TrainConfig.model``)."""
    base = preset(preset_name)
    if not overrides:
        return base
    return ModelConfig.from_dict(_deep_merge(base.to_dict(), overrides), "model")


def _deep_merge(base: dict, over: Mapping[str, Any], path: str = "model") -> dict:
    """``over`` on top of ``base``: sections merge key by key, lists of sections entry by entry
    (:func:`_merge_list`), anything else is replaced."""
    out = dict(base)
    for key, value in over.items():
        here, old = f"{path}.{key}", out.get(key)
        if isinstance(value, Mapping) and isinstance(old, dict):
            out[key] = _deep_merge(old, value, here)
        elif isinstance(old, (list, tuple)) and old and all(isinstance(e, dict) for e in old):
            out[key] = _merge_list(list(old), value, here)
        else:
            out[key] = value
    return out


def _merge_list(base: list[dict], over: Any, path: str) -> Any:
    """A list of sections (``levels``) with an override on top. A list of the preset's length, or a mapping of
    indices (``--set model.levels.0.planes=16``), merges entry by entry onto the preset's entries; a list of
    another length replaces the preset's list, so each of its entries must give every key (else the rest would
    silently take the class defaults, not the preset's)."""
    if isinstance(over, Mapping) and all(str(k).isdigit() for k in over):
        over = {int(k): v for k, v in over.items()}
        bad = sorted(k for k in over if k >= len(base))
        if bad:
            raise ConfigError(f"{path}: no entry {bad[0]}; the preset has {len(base)} (0..{len(base) - 1})")
        return [_merge_entry(e, over[i], f"{path}[{i}]") if i in over else e for i, e in enumerate(base)]
    if not isinstance(over, (list, tuple)):
        return over  # ModelConfig.from_dict names the wrong type
    if len(over) == len(base):
        return [_merge_entry(e, o, f"{path}[{i}]") for i, (e, o) in enumerate(zip(base, over))]
    for i, entry in enumerate(over):
        missing = _missing_keys(base[0], entry) if isinstance(entry, Mapping) else []
        if missing:
            raise ConfigError(f"{path}[{i}]: the override has {len(over)} entries for the preset's {len(base)}, so "
                              f"it replaces the list and each entry must be whole; missing {', '.join(missing)} "
                              f"(or give {len(base)} entries, merged onto the preset's one by one)")
    return list(over)


def _merge_entry(base: dict, over: Any, path: str) -> Any:
    return _deep_merge(base, over, path) if isinstance(over, Mapping) else over


def _missing_keys(template: Mapping[str, Any], entry: Mapping[str, Any], prefix: str = "") -> list[str]:
    """Keys of ``template`` (nested sections too) that ``entry`` lacks, as dotted paths."""
    missing = []
    for key, value in template.items():
        if key not in entry:
            missing.append(prefix + key)
        elif isinstance(value, dict) and isinstance(entry[key], Mapping):
            missing += _missing_keys(value, entry[key], f"{prefix}{key}.")
    return missing


def load_config_file(path: str | Path) -> dict:
    """A JSON or TOML (``.toml``) file as a dict. JSON is read as the runtime reads its configs
    (:func:`ghnerf_runtime.config.read_json_file`): a key given twice is refused by name (JSON kept the last,
    silently undoing the first), as are an empty file and one nested too deeply (a RecursionError traceback)."""
    path = Path(path)

    def fail(message: str) -> ConfigError:
        return ConfigError(f"config file {path}: {message}")

    data = _read_toml(path, fail) if path.suffix == ".toml" else read_json_file(path, fail, what="file")
    if not isinstance(data, dict):
        raise ConfigError(f"config file {path}: must hold a JSON object of settings, got a {type(data).__name__}")
    return data


def _read_toml(path: Path, fail: Callable[[str], ConfigError]) -> dict:
    """A TOML file as a dict (tomllib refuses a key given twice itself)."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except (OSError, ValueError) as e:
        raise fail(str(e)) from e
    except RecursionError as e:  # arrays or tables nested thousands deep
        raise fail("not valid TOML (nested too deeply)") from e


def _parse_value(key: str, text: str) -> Any:
    try:
        return json.loads(text)
    except ValueError:
        return text
    except RecursionError:  # brackets thousands deep: a traceback before this
        raise ConfigError(f"{key}: the value is nested too deeply to be a setting") from None


def apply_overrides(data: dict, overrides: list[str]) -> dict:
    """``key=value`` (dotted keys for nested configs, JSON values) on top of ``data``."""
    out = json.loads(json.dumps(data))
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"{item}: override must be key=value")
        key, value = item.split("=", 1)
        node = out
        parts = key.strip().split(".")
        if not all(parts):  # '=1', 'loss..heat_weight': said as an unknown key named '' before
            raise ConfigError(f"{item}: override key {key.strip()!r} has an empty part; keys are dotted names such "
                              f"as loss.heat_weight")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise ConfigError(f"{key}: {p} is not a section")
        node[parts[-1]] = _parse_value(key.strip(), value)
    return out


def build_config(data: Mapping[str, Any]) -> TrainConfig:
    """Validate a config dict once; unknown keys and bad values raise :class:`ConfigError` naming the key."""
    data = dict(data)
    data.pop("$comment", None)
    cfg = TrainConfig.from_dict(data)
    cfg.validate()
    return cfg


# ------------------------------------------------------------------------------------------ runtime
@dataclass
class DistInfo:
    rank: int = 0
    world: int = 1
    local_rank: int = 0

    @property
    def main(self) -> bool:
        return self.rank == 0


def setup_distributed(device_kind: str) -> DistInfo:
    """Join the process group torchrun (or a test) describes in the environment; no-op for one process."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return DistInfo()
    if not dist.is_initialized():
        dist.init_process_group(backend="nccl" if device_kind == "cuda" else "gloo")
    return DistInfo(dist.get_rank(), dist.get_world_size(), int(os.environ.get("LOCAL_RANK", "0")))


def require_cuda_if_asked(kind: str) -> None:
    """``device: "cuda"`` on a host where torch sees no GPU is a config error (the pretraining's too): it was torch's
    RuntimeError traceback from ``torch.cuda.set_device`` (exit 1), the pretraining's after ``config.json``."""
    if kind == "cuda" and not torch.cuda.is_available():
        raise ConfigError("device: 'cuda', but torch sees no CUDA GPU here (torch.cuda.is_available() is False); "
                          "use 'auto' or 'cpu'")


def pick_device(kind: str, info: DistInfo) -> torch.device:
    if kind == "cuda" or (kind == "auto" and torch.cuda.is_available()):
        torch.cuda.set_device(info.local_rank)
        return torch.device("cuda", info.local_rank)
    return torch.device("cpu")


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % 2 ** 32)
    torch.manual_seed(seed)


def rng_state(gen: torch.Generator) -> dict:
    state = {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "python": random.getstate(),
             "rays": gen.get_state()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: dict, gen: torch.Generator) -> None:
    # RNG states are CPU byte tensors; a checkpoint loaded with map_location="cuda" has moved them to the GPU
    torch.set_rng_state(state["torch"].cpu())
    np.random.set_state(state["numpy"])
    random.setstate(state["python"])
    gen.set_state(state["rays"].cpu())
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all([s.cpu() for s in state["cuda"]])


# ----------------------------------------------------------------------------------------- sampling
def pick_targets(item: dict, n: int, gen: torch.Generator) -> Tensor:
    """Indices of ``n`` target views: ceil(n/2) sources, the rest novel views (sources if none)."""
    is_src = item["tgt_is_source"]
    src = torch.nonzero(is_src).flatten()
    nov = torch.nonzero(~is_src).flatten()
    n_src = n if len(nov) == 0 else min(len(src), (n + 1) // 2)
    n_nov = n - n_src
    pick_s = src[torch.randperm(len(src), generator=gen)[:n_src]] if n_src <= len(src) else \
        src[torch.randint(len(src), (n_src,), generator=gen)]
    if n_nov == 0:
        return pick_s
    pick_n = nov[torch.randint(len(nov), (n_nov,), generator=gen)] if n_nov > len(nov) else \
        nov[torch.randperm(len(nov), generator=gen)[:n_nov]]
    return torch.cat([pick_s, pick_n])


def _choose(weights_inside: Tensor, count: int, fraction: float, gen: torch.Generator) -> Tensor:
    """``count`` indices of a flat boolean map: ``round(fraction * count)`` inside (if any), rest anywhere."""
    n = weights_inside.numel()
    inside = torch.nonzero(weights_inside.flatten()).flatten()
    n_in = int(round(fraction * count)) if len(inside) else 0
    idx_in = inside[torch.randint(len(inside), (n_in,), generator=gen)] if n_in else inside[:0]
    idx_any = torch.randint(n, (count - n_in,), generator=gen)
    return torch.cat([idx_in, idx_any])


def sample_rays(masks: Tensor, heat_rays: int, patch: int, stride: int, fraction: float,
                gen: torch.Generator) -> Tensor:
    """Ray pixels ``(B, heat_rays + patch**2, 2)`` (model pixels, centres at integers) for masks ``(B, H, W)``.

    The first ``heat_rays`` lie on the ``stride`` grid (``contract.ray_grid``), ``fraction`` of them in
    cells touching the mask; the last ``patch**2`` form a row-major ``patch x patch`` block of pixels.
    """
    B, H, W = masks.shape
    grid = torch.from_numpy(ray_grid(H, W, stride))  # (h*w, 2)
    cells = F.max_pool2d(masks[:, None].float(), stride)[:, 0] > 0  # (B, h, w)
    out = []
    for b in range(B):
        uv = grid[_choose(cells[b], heat_rays, fraction, gen)]
        if patch:
            inside = torch.nonzero(masks[b].flatten()).flatten()
            if len(inside) and float(torch.rand((), generator=gen)) < fraction:
                centre = inside[torch.randint(len(inside), (), generator=gen)]
            else:
                centre = torch.randint(H * W, (), generator=gen)
            cy, cx = int(centre) // W, int(centre) % W
            top = min(max(cy - patch // 2, 0), H - patch)
            left = min(max(cx - patch // 2, 0), W - patch)
            ys, xs = torch.meshgrid(torch.arange(top, top + patch), torch.arange(left, left + patch), indexing="ij")
            uv = torch.cat([uv, torch.stack([xs.flatten(), ys.flatten()], -1).float()])
        out.append(uv)
    return torch.stack(out)


def bilinear_at(images: Tensor, uv: Tensor) -> Tensor:
    """``images`` ``(B, C, H, W)`` at pixels ``uv`` ``(B, M, 2)`` (centres at integers) -> ``(B, M, C)``."""
    H, W = images.shape[-2:]
    g = torch.stack([(uv[..., 0] + 0.5) / W * 2 - 1, (uv[..., 1] + 0.5) / H * 2 - 1], -1)
    out = F.grid_sample(images, g[:, None], mode="bilinear", padding_mode="border", align_corners=False)
    return out[:, :, 0].transpose(1, 2)


def heatmaps_at(joints_2d: Tensor, visible: Tensor, uv: Tensor, sigma_px: float) -> Tensor:
    """Gaussian heatmaps (peak 1, zero for invisible joints) at rays ``uv`` ``(B, M, 2)`` -> ``(B, M, J)``.

    ``joints_2d`` ``(B, J, 2)`` and ``uv`` in model pixels, ``sigma_px`` in model pixels.
    """
    d2 = ((uv[:, :, None, :] - joints_2d[:, None, :, :]) ** 2).sum(-1)  # (B, M, J)
    vis = visible & torch.isfinite(joints_2d).all(-1)
    return torch.exp(-d2 / (2 * sigma_px ** 2)) * vis[:, None, :].float()


def make_batch(item: dict, cfg: TrainConfig, mcfg: ModelConfig, gen: torch.Generator) -> dict[str, Tensor]:
    """Model inputs and ray targets of one scene: the step's targets and rays."""
    t = pick_targets(item, cfg.targets_per_iter, gen)
    masks = item["tgt_masks"][t]
    stride = mcfg.heatmap_stride
    uv = sample_rays(masks, cfg.heat_rays, cfg.patch_size, stride, cfg.mask_fraction, gen)
    bg = mcfg.background
    img = item["tgt_images"][t]
    m = masks[:, None].float()
    comp = img * m + bg * (1 - m)
    H = img.shape[-1]
    scale = H / mcfg.height  # dataset at model resolution; guard anyway
    if scale != 1:
        raise ValueError(f"dataset resolution {H} does not match the model's {mcfg.height}")
    batch = {
        "images": item["images"], "src_P": item["src_P"], "src_centers": item["src_centers"],
        "tgt_K_inv": item["tgt_K_inv"][t], "tgt_c2w": item["tgt_c2w"][t], "near_far": item["near_far"][t],
        "ray_uv": uv, "rgb": bilinear_at(comp, uv), "mask": bilinear_at(m, uv)[..., 0],
        "heatmaps": heatmaps_at(item["tgt_joints_2d"][t], item["tgt_visible"][t], uv, HEATMAP_SIGMA_HM_PX * stride),
        "targets": t,
    }
    if cfg.loss.depth_weight and "tgt_depth" in item:
        # every bilinear tap on the subject: the interpolated depth is the surface's, not a blend with 0
        on_subject = bilinear_at(m, uv)[..., 0] > 0.999
        batch["depth"] = bilinear_at(item["tgt_depth"][t][:, None], uv)[..., 0]
        batch["depth_valid"] = on_subject & item["tgt_has_depth"][t][:, None] & (batch["depth"] > 0)
    if "tgt_heatmaps" in item and not cfg.freeze_human:  # dense grids of the source views: auxiliary head
        batch["source_heatmaps"] = item["tgt_heatmaps"][item["tgt_is_source"]]
        if cfg.encoder_views == "all" or cfg.encoder_flip:
            batch.update(aux_encoder_batch(item, cfg))
    return batch


def aux_encoder_batch(item: dict, cfg: TrainConfig) -> dict[str, Tensor]:
    """Extra images for the encoder's auxiliary head (``encoder_views``, ``encoder_flip``) and their grids.

    Mirroring is exact on the heatmap grid (cell centres map onto cell centres) once the joint channels
    are swapped left for right (``FLIP_INDEX``).
    """
    src = item["tgt_is_source"]
    seen = encoder_views_images(item)
    images, heat = [], []
    if cfg.encoder_views == "all" and (~src).any():
        images.append(seen[~src])
        heat.append(item["tgt_heatmaps"][~src])
    if cfg.encoder_flip:
        views = slice(None) if cfg.encoder_views == "all" else src
        m_images, m_heat = mirrored(seen[views], item["tgt_heatmaps"][views])
        images.append(m_images)
        heat.append(m_heat)
    if not images:
        return {}
    return {"aux_images": torch.cat(images), "aux_heatmaps": torch.cat(heat)}


def padding_config(frame_padding: bool, edge_cut: float) -> dict:
    """``TargetConfig``'s frame padding keywords, checked (a bad value raises :class:`ConfigError` naming it)."""
    from training.data.errors import DataConfigError
    from training.data.targets import TargetConfig

    try:
        TargetConfig(frame_padding=frame_padding, edge_cut=edge_cut)
    except DataConfigError as e:
        raise ConfigError(str(e).replace("TargetConfig.", "")) from e
    return {"frame_padding": frame_padding, "edge_cut": edge_cut}


def encoder_views_images(item: dict) -> Tensor:
    """Every view's image ``(V, 3, S, S)`` as the encoder is shown it: ``tgt_images`` with the runtime's black
    padding past each camera's frame where the item has it (``TargetConfig.frame_padding``)."""
    from training.data.targets import FRAME_KEY

    if FRAME_KEY not in item:
        return item["tgt_images"]
    return item["tgt_images"] * item[FRAME_KEY][:, None]


def mirrored(images: Tensor, heatmaps: Tensor) -> tuple[Tensor, Tensor]:
    """Mirror images ``(N, 3, H, W)`` and their heatmap grids ``(N, J, h, w)`` left to right: exact on the
    grid (cell centres map onto cell centres) once the joint channels are swapped (``FLIP_INDEX``)."""
    from ghnerf_runtime.body25 import FLIP_INDEX

    return torch.flip(images, dims=(-1,)), torch.flip(heatmaps, dims=(-1,))[:, list(FLIP_INDEX)]


def learning_rate(cfg: TrainConfig, step: int) -> float:
    """Step decay by ``lr_decay_gamma`` every ``lr_decay_every`` steps, floored at ``lr_min`` (reads only
    ``lr``, ``lr_decay_every``, ``lr_decay_gamma``, ``lr_min``: the pretraining's config too)."""
    lr = cfg.lr * (cfg.lr_decay_gamma ** (step // cfg.lr_decay_every) if cfg.lr_decay_every else 1.0)
    return max(lr, min(cfg.lr_min, cfg.lr))


# -------------------------------------------------------------------------------------------- losses
def step_losses(out: dict, batch: dict, cfg: TrainConfig) -> dict[str, Tensor]:
    """All rays: colour + heatmap (+ coord, + mask); the patch rays also SSIM (``training.losses``)."""
    lc = cfg.loss
    terms = compute_losses(out, batch, replace(lc, ssim_weight=0.0))
    P = cfg.patch_size
    if P and lc.ssim_weight:
        only_ssim = replace(lc, colour_weight=0.0, heat_weight=0.0, coord_weight=0.0, mask_weight=0.0,
                            depth_weight=0.0)
        sliced = {"levels": [{"rgb": lv["rgb"][:, -P * P:]} for lv in out["levels"]]}
        extra = compute_losses(sliced, {"rgb": batch["rgb"][:, -P * P:]}, only_ssim, patch_shape=(P, P))
        terms.update({k: v for k, v in extra.items() if k != "loss"})
        terms["loss"] = terms["loss"] + extra["loss"]
    return terms


def train_step(ddp_model: torch.nn.Module, model: GHNeRF, opt: torch.optim.Optimizer, batch: dict[str, Tensor],
               cfg: TrainConfig) -> tuple[dict, dict[str, Tensor]]:
    """One update of the joint run (``ddp_model`` is ``model`` or its DDP wrapper): forward over the batch's
    rays, the losses, backward, gradient clipping, Adam. Returns the outputs and the loss terms.
    ``benchmarks/time_train_step.py`` times this very function."""
    out = ddp_model(batch["images"], batch["src_P"], batch["src_centers"], batch["tgt_K_inv"],
                    batch["tgt_c2w"], batch["near_far"], batch["ray_uv"], perturb=True,
                    aux_images=batch.get("aux_images"))
    terms = step_losses(out, batch, cfg)
    opt.zero_grad(set_to_none=True)
    terms["loss"].backward()
    # Checked before the update, so the weights (and the next checkpoint) never take a non-finite step. After the
    # backward pass: under DDP a NaN on one rank reaches every rank's gradients, so every rank stops here alike.
    values = {k: float(v.detach()) for k, v in terms.items()}
    bad = [f"{k}={v:g}" for k, v in values.items() if k != "loss" and not math.isfinite(v)]
    if bad or not math.isfinite(values["loss"]):
        raise NonFiniteLoss(f"non-finite loss ({', '.join(bad) or 'loss={:g}'.format(values['loss'])})")
    if cfg.grad_clip:
        norm = torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
    else:  # the same norm, read only: the gradients stay bit for bit as they were
        grads = [p.grad for p in model.parameters() if p.grad is not None]
        norm = torch.linalg.vector_norm(torch.stack([torch.linalg.vector_norm(g) for g in grads])) if grads \
            else torch.zeros(())
    if not torch.isfinite(norm):  # a finite loss can still have one (sqrt at 0, an overflow in the backward pass)
        raise NonFiniteLoss(f"non-finite gradient norm ({float(norm):g}) of a finite loss "
                            f"({values['loss']:.6g})")
    opt.step()
    return out, terms


class NonFiniteLoss(TrainingDiverged):
    """A step's loss terms or gradients are NaN or infinite; raised before the update (the message names them).
    Checked here, not by ``step_guard.finite_step``: it names the terms, and reads the norm the clipping takes."""


def _saved_step(path: Path) -> Any:
    try:
        return int(load_checkpoint(path)["step"])
    except (ConfigError, KeyError, TypeError, ValueError):
        return "?"


def psnr_of(pred: Tensor, target: Tensor) -> float:
    mse = float(F.mse_loss(pred.detach(), target))
    return 10 * math.log10(1.0 / max(mse, 1e-10))


@torch.no_grad()
def source_pck(model: GHNeRF, item: dict, device: torch.device) -> float:
    """PCK@0.2 of the keypoints decoded from the rendered heatmap grids of both source views of ``item``."""
    from training.evaluate import render_heatmap_grids, keypoints_from_heatmaps  # lazy: avoids a cycle
    from ghnerf_runtime.metrics import pck

    was = model.training
    model.eval()
    src = torch.nonzero(item["tgt_is_source"]).flatten()
    hm = render_heatmap_grids(model, {k: v.to(device) for k, v in item.items()}, src.to(device))  # (S, J, h, w)
    model.train(was)
    uv = keypoints_from_heatmaps(hm.cpu().numpy(), model.config.height)
    res = pck(uv, item["tgt_joints_2d"][src].numpy(), item["tgt_visible"][src].numpy())
    return float(res.value)


# --------------------------------------------------------------------------------------- checkpoints
def unwrap(model: torch.nn.Module) -> GHNeRF:
    return model.module if hasattr(model, "module") else model  # type: ignore[return-value]


def save_checkpoint(path: Path, model, opt, step: int, cfg: TrainConfig, gen: torch.Generator,
                    extra: dict | None = None) -> None:
    state = {"version": CHECKPOINT_VERSION, "model": unwrap(model).state_dict(), "optimizer": opt.state_dict(),
             "step": step, "config": asdict(cfg), "model_config": unwrap(model).config.to_dict(),
             "rng": rng_state(gen), "extra": extra or {}}
    save_atomic(state, path)


class CheckpointWriteError(OSError):
    """A checkpoint could not be written (a full disk, say); the message names the file. The previous one is
    left as it was."""


def save_atomic(state: Any, path: Path, keep_previous: Path | None = None) -> None:
    """``torch.save`` through ``<path>.tmp``, fsynced, then renamed: a crash or power cut leaves the old file or
    the new one, never a renamed empty or half-written ``last.pt``. A failed write (a full disk, Ctrl-C) removes
    the half-written ``.tmp``, which would otherwise keep the disk full, and is a :class:`CheckpointWriteError`
    naming ``path`` (torch's own error names neither the file nor the cause).

    ``keep_previous``: the file ``path`` held is renamed to it, once the new one is written whole (a crash
    between the two renames leaves it and no ``path``: a reader falls back to it)."""
    tmp = path.with_suffix(".tmp")
    try:
        # a Ctrl-C or SIGTERM raised inside torch's writer came out as a RuntimeError ("unexpected pos"), reported
        # as a failed write, and the step's checkpoint was lost: held over the write and renames, raised after
        with stop_signals_deferred(only_raising=True):
            with open(tmp, "wb") as fh:
                torch.save(state, fh)
                fh.flush()
                os.fsync(fh.fileno())
            if keep_previous is not None and path.exists():
                os.replace(path, keep_previous)
            os.replace(tmp, path)
    except BaseException as e:
        tmp.unlink(missing_ok=True)
        if not isinstance(e, Exception):  # Ctrl-C: stop as asked
            raise
        kept = f"the previous {path.name} is as it was" if path.exists() else f"no {path.name} was written"
        raise CheckpointWriteError(f"{path}: cannot write the checkpoint ({type(e).__name__}: "
                                   f"{error_words(e)}); {kept}. Free space and run again with "
                                   "--resume") from e


def load_model(path: str | Path, map_location: str | torch.device = "cpu",
               default_config: ModelConfig | None = None) -> tuple[GHNeRF, dict]:
    """A trained model (eval mode) and its checkpoint dict from a ``.pt`` file.

    Reads trainer checkpoints (which hold numpy RNG state, hence ``weights_only=False``: load only
    files you made), the weights-only files ``make model`` ships, and bare state dicts; the model
    config stored in the file wins, ``default_config`` serves files that carry none.
    """
    ck = load_checkpoint(path, map_location, hint=READ_HINT)
    if not isinstance(ck, Mapping):
        raise ConfigError(f"{path}: not a model checkpoint (a {type(ck).__name__}); {READ_HINT}")
    if "human" in ck and "model" not in ck:  # was "its weights do not fit", listing the missing tensors
        raise ConfigError(f"{path}: a human-encoder pretraining checkpoint (the encoder's weights alone, the start "
                          f"of a joint run's human_init), not a model; {READ_HINT}")
    if "model_config" in ck:
        mcfg = ModelConfig.from_dict(ck["model_config"], "model_config")
    elif default_config is not None:
        mcfg = default_config
    else:
        raise ConfigError(f"{path}: no 'model_config' in the checkpoint; {READ_HINT}")
    model = GHNeRF(mcfg, read_init=False)  # the file's weights replace model.human.init's, which may have moved
    try:
        model.load_state_dict(ck.get("model", ck))
    except RuntimeError as e:  # missing or mis-shaped tensors
        raise ConfigError(f"{path}: its weights do not fit its model config ({error_words(e)})") from e
    refuse_non_finite(path, model)
    return model.eval(), ck


def refuse_non_finite(path: str | Path, model: torch.nn.Module) -> None:
    """:class:`ConfigError` naming ``path`` and its first tensor holding NaN or infinite values: such weights
    exported (a parity check of NaN against NaN is no check) and quantized into a traceback deep in onnxruntime
    ("scale issue"), or evaluated as a model that finds no one."""
    for name, t in model.state_dict().items():
        if t.is_floating_point() and not bool(torch.isfinite(t).all()):
            bad = int((~torch.isfinite(t)).sum())
            raise ConfigError(f"{path}: tensor {name!r} holds {bad} NaN or infinite value(s) of {t.numel()}: weights "
                              f"of a run that diverged; {READ_HINT}")


# ------------------------------------------------------------------------------------------ progress
class Progress:
    """One status line: ``\\r``-updated on a terminal, one line per update otherwise (log files)."""

    def __init__(self, total: int, start: int, stream=None, enabled: bool = True):
        # sys.stderr as it is now, not as it was when this module was imported (a redirected or closed stream)
        stream = sys.stderr if stream is None else stream
        self.total, self.start, self.stream, self.enabled = total, start, stream, enabled
        self.t0 = time.monotonic()
        self.tty = hasattr(stream, "isatty") and stream.isatty()

    def update(self, step: int, fields_: dict[str, float]) -> str:
        done = step - self.start
        el = time.monotonic() - self.t0
        rate = el / max(done, 1)
        eta = rate * (self.total - step)
        w = 24
        fill = int(w * step / max(self.total, 1))
        bar = "#" * fill + "-" * (w - fill)
        vals = " ".join(f"{k} {v:.4g}" for k, v in fields_.items())
        line = (f"[{bar}] {step}/{self.total} {vals} | {rate:.2f} s/it elapsed {el / 60:.1f} min "
                f"eta {eta / 60:.1f} min")
        if self.enabled:
            self.stream.write(("\r" + line) if self.tty else line + "\n")
            self.stream.flush()
        return line

    def close(self) -> None:
        if self.enabled and self.tty:
            self.stream.write("\n")


# ------------------------------------------------------------------------------------------- training
def scene_order(n: int, epoch: int, seed: int, info: DistInfo) -> list[int]:
    """This rank's scene indices of ``epoch`` (``DistributedSampler``: same shuffle on every rank)."""
    from torch.utils.data.distributed import DistributedSampler

    sampler = DistributedSampler(range(n), num_replicas=info.world, rank=info.rank, shuffle=True, seed=seed,
                                 drop_last=True)
    sampler.set_epoch(epoch)
    return list(sampler)


def train(cfg: TrainConfig, out_dir: str | Path, *, resume: bool = False, quiet: bool = False,
          dataset=None) -> tuple[dict, GHNeRF]:
    """Run (or resume) training.

    Returns the summary (also written to ``out_dir/summary.json`` by rank 0) and the trained model
    (this rank's copy). ``dataset`` replaces the ``MultiViewDataset`` of ``cfg.data`` (tests).
    """
    out_dir = Path(out_dir)
    # named before the dataset opens or a file is written: these were tracebacks (exit 1), an --init one after
    # config.json was written into the new run folder
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError(f"{out_dir}: is a file; --out names the run folder")
    refuse_model_folder(out_dir)  # resumed or not: nothing of a run belongs beside the graphs
    if not resume:
        refuse_existing_run(out_dir)  # before config.json is overwritten with the new one
    require_cuda_if_asked(cfg.device)
    device_kind = "cuda" if cfg.device == "cuda" or (cfg.device == "auto" and torch.cuda.is_available()) else "cpu"
    info = setup_distributed(device_kind)
    device = pick_device(cfg.device, info)
    if device.type == "cpu":
        # never oversubscribe: OpenMP threads spin-wait, a 2-thread run beside another busy process ran >10x slower
        local_world = int(os.environ.get("LOCAL_WORLD_SIZE", info.world))
        torch.set_num_threads(cfg.threads or max(1, (os.cpu_count() or 1) // local_world))
        torch.set_flush_denormal(True)
    start = resume_checkpoint(out_dir, verbose=info.main) if resume else None
    if start is not None:
        check_resumable(cfg, start, world=info.world)  # before config.json is overwritten with the new one
    else:  # a resume takes the checkpoint's weights, not these files: they may have moved since the run began
        for key in ("init", "human_init"):
            if getattr(cfg, key) and not Path(getattr(cfg, key)).is_file():
                raise ConfigError(f"{key}: {getattr(cfg, key)}: no such file")
        check_start_weights(cfg)
        check_model_human_init(cfg.model_config())
    if info.main:
        refuse_live_lock(out_dir / "train.pid")  # a folder in use is named first, whatever else is wrong
    # a missing dataset or split, or one of another resolution: named before anything is written
    dataset = dataset if dataset is not None else open_dataset(cfg, info.world)
    if info.main:
        try:
            out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise ConfigError(f"{out_dir}: cannot make the run folder ({e.strerror or e})") from e
        take_lock(out_dir / "train.pid")
        write_atomic(out_dir / "config.json", json.dumps(asdict(cfg), indent=1))
        # summary.json describes the invocation that wrote it: one stopped at max_minutes, then resumed and
        # interrupted, would still read "stopped early at step N" beside a last.pt of a later step
        # (`make model --accept-stopped` then used the run as its stale summary described it)
        (out_dir / "summary.json").unlink(missing_ok=True)
    try:
        return _train(cfg, out_dir, info, device, start=start, resume=resume, quiet=quiet, dataset=dataset)
    finally:
        if info.main:
            (out_dir / "train.pid").unlink(missing_ok=True)


#: Train-config keys a resumed run may change: its length, where the data lives and how it runs.
RESUME_MAY_CHANGE = ("iterations", "data", "threads", "device", "max_minutes", "log_every", "pck_every",
                     "checkpoint_every")


#: What to do about a damaged checkpoint of a run folder (``--resume``'s advice).
RESUME_HINT = ("delete it (--resume then continues from the newest ckpt_*.pt), or restore one of the run's "
               "ckpt_*.pt as last.pt")
#: ... and about a damaged ckpt_*.pt that --resume passes over (last.pt's advice, "delete it", misled there).
SKIP_HINT = "passed over: --resume tries the next older ckpt_*.pt"
#: ... and about a damaged model file given to be read (evaluation, export): no run to resume.
READ_HINT = "give another checkpoint (a run's last.pt or ckpt_*.pt, or a model folder's <variant>.pt)"


#: ... and about a damaged last.pt of a run with no ckpt_*.pt (a short run, or one whose checkpoint_every its
#: steps never reached): RESUME_HINT's "the newest ckpt_*.pt" named files that were not there.
RESUME_FROM_NOTHING_HINT = ("the run has no ckpt_*.pt to go back to: restore last.pt from a copy, or delete it "
                            "and --resume starts the run again from step 0")


def load_checkpoint(path: str | Path, map_location="cpu", hint: str = RESUME_HINT) -> dict:
    """``torch.load`` of a checkpoint; a damaged file is a ``ConfigError`` naming it, with ``hint`` (the
    default, :data:`RESUME_HINT`, only where the folder holds a ``ckpt_*.pt`` to go back to)."""
    try:
        return torch.load(str(path), map_location=map_location, weights_only=False)
    except Exception as e:  # torch's zip reader, pickle, EOF...
        if hint is RESUME_HINT and not _step_checkpoints(Path(path).parent):
            hint = RESUME_FROM_NOTHING_HINT
        raise ConfigError(f"{path}: unreadable checkpoint ({type(e).__name__}: {error_words(e)}); {hint}") from e


#: About where :func:`error_words` shortens an error's text (torch's run to a page of advice).
ERROR_WORDS_LIMIT = 200


def error_words(e: BaseException, limit: int = ERROR_WORDS_LIMIT) -> str:
    """The first line of ``e``'s text, kept whole up to ``limit`` characters; a longer one is cut after its last
    sentence (else clause) that ends within ``limit``: a cut mid-sentence read "...your checkpoint file is)".
    A first line with no such boundary is kept whole (complete beats short). A first line that heads the rest
    (ends in ":", as torch's "Error(s) in loading state_dict for GHNeRF:") is read with the lines after it:
    alone it names no key."""
    lines = str(e).strip().splitlines()
    heading = bool(lines) and lines[0].rstrip().endswith(":")
    first = " ".join((" ".join(lines) if heading else lines[0] if lines else "").split())
    if len(first) <= limit:
        return first
    for mark in (". ", "; ", ", "):
        end = first.rfind(mark, 0, limit + 1)
        if end > 0:
            return first[:end + (mark == ". ")]  # a sentence keeps its full stop, a clause drops its comma
    return first


def _step_checkpoints(out_dir: Path) -> list[Path]:
    """The run's ``ckpt_<step>.pt``, newest first (by step: the zero padding runs out past 9999999)."""
    found = [(int(p.stem[5:]), p) for p in out_dir.glob("ckpt_*.pt") if p.stem[5:].isdigit()]
    return [p for _, p in sorted(found, reverse=True)]


#: Files only a model folder holds: the graphs ``python -m training.export`` writes (what ``ghnerf-run --model-dir``
#: loads), and the card of the folder ``make model`` writes (``models/``, its variants in subfolders).
MODEL_FOLDER_MARKS = ("*.onnx", "model_card.json")


def model_folder_marks(folder: Path) -> list[str]:
    """The names of ``folder``'s files that mark it as a model folder (:data:`MODEL_FOLDER_MARKS`), sorted; empty
    for a run folder, a new one or none at all."""
    if not folder.is_dir():
        return []
    return sorted({p.name for pattern in MODEL_FOLDER_MARKS for p in folder.glob(pattern)})


def refuse_model_folder(out_dir: Path) -> None:
    """A model folder is no run folder: ``--out models/ghnerf`` (a path copied from a ``ghnerf-run`` command) put
    ``last.pt``, ``config.json`` and ``log.jsonl`` beside the ONNX graphs. Refused for the trainer and the
    pretraining, resumed or not, before anything is read or written."""
    marks = model_folder_marks(out_dir)
    if marks:
        held = ", ".join(marks[:3]) + (", ..." if len(marks) > 3 else "")
        raise ConfigError(f"{out_dir}: is a model folder (it holds {held}), not a run folder: --out names the "
                          "folder of the run's checkpoints, config.json and log.jsonl; give a new one (runs/<name>, "
                          "say)")


def refuse_existing_run(out_dir: Path) -> None:
    """A new run must not overwrite another run's ``config.json`` and checkpoints: refuse a folder holding them."""
    ckpts = [p.name for p in _step_checkpoints(out_dir)]
    held = ["last.pt"] * (out_dir / "last.pt").exists() + ckpts[:2] + ["..."] * (len(ckpts) > 2)
    if held:
        raise ConfigError(f"{out_dir}: holds a training run ({', '.join(held)}); pass --resume to continue it, "
                          "or another --out for a new run")


def resume_checkpoint(out_dir: Path, verbose: bool = True) -> Path | None:
    """The checkpoint ``--resume`` continues from: ``last.pt``, else (deleted or lost) the newest readable
    ``ckpt_*.pt``; None for a folder with neither, where the run starts fresh (``--resume`` is then a no-op,
    which the pipeline relies on)."""
    last = out_dir / "last.pt"
    if last.exists():
        return last  # a damaged one is refused by name (load_checkpoint), never skipped silently
    ckpts = _step_checkpoints(out_dir)
    for ck in ckpts:
        try:
            load_checkpoint(ck, hint=SKIP_HINT)
        except ConfigError as e:
            if verbose:
                print(f"ghnerf-train: skipping {e}", file=sys.stderr)
            continue
        if verbose:
            print(f"ghnerf-train: {last} is missing: resuming from {ck.name}", file=sys.stderr)
        return ck
    if ckpts:
        raise ConfigError(f"{out_dir}: no last.pt and none of its {len(ckpts)} ckpt_*.pt loads; "
                          "start a new run (another --out)")
    return None


def checkpoint_world_size(ck: dict) -> int:
    """Processes of the run that saved ``ck`` (checkpoints made before it was stored: its per-rank RNG states)."""
    extra = ck.get("extra") or {}
    if "world_size" in extra:
        return int(extra["world_size"])
    return len(extra["rng_ranks"]) if "rng_ranks" in extra else 1


def refuse_another_config(last: Path, was: dict, now: dict, may_change: tuple[str, ...],
                          compared_elsewhere: tuple[str, ...] = ()) -> None:
    """Refuse to resume ``last`` (whose run had config ``was``) under ``now``: the rest of the run would
    silently mix two. Only the keys in ``may_change`` may differ; those in ``compared_elsewhere`` are left to
    another check (``model``: by the model it builds, :func:`refuse_another_model`)."""
    skip = (*may_change, *compared_elsewhere)
    differ = [f"{p} {a!r} in the run, {b!r} now" for k in sorted(set(was) | set(now)) if k not in skip
              for p, a, b in _differences(was.get(k, _UNSET), now.get(k, _UNSET), k)]
    if differ:
        raise ConfigError(f"{last}: resuming under another config ({'; '.join(differ)}); "
                          "resume changes only " + ", ".join(may_change) + ": start a new run (--out) "
                          "for another config")


#: What ``--resume`` reads from a checkpoint; a weights-only file (``make model``'s ``ghnerf.pt``) lacks most.
RESUME_KEYS = ("model", "optimizer", "step", "config", "rng")


def other_tools_checkpoint(ck: Mapping, keys: tuple[str, ...]) -> str | None:
    """What ``ck`` is when it is the other trainer's resumable checkpoint (``keys``: the resuming tool's
    :data:`RESUME_KEYS`): the two tools' run folders both hold a ``last.pt``, and one given to the other was called
    "a weights-only file", with the advice to restore a ``ckpt_*.pt`` the pretraining never writes."""
    if "model" in keys and "human" in ck and "optimizer" in ck and "model" not in ck:
        return "a human-encoder pretraining checkpoint (python -m training.pretrain_human's)"
    if "human" in keys and all(k in ck for k in RESUME_KEYS):
        return "a training checkpoint of the whole model (ghnerf-train's)"
    return None


def require_resume_keys(ck: Any, path: Path, keys: tuple[str, ...] = RESUME_KEYS) -> None:
    """Refuse a checkpoint ``--resume`` cannot continue from, naming the ``keys`` it lacks."""
    if not isinstance(ck, Mapping):
        raise ConfigError(f"{path}: not a training checkpoint (a {type(ck).__name__}, not a mapping); "
                          "start a new run (another --out)")
    missing = [k for k in keys if k not in ck]
    if missing and (kind := other_tools_checkpoint(ck, keys)):  # a run folder of the other trainer: say which
        raise ConfigError(f"{path}: {kind}, which this tool's --resume cannot continue; resume it with the tool that "
                          "made it, or give this run another --out")
    if missing:
        raise ConfigError(f"{path}: not a training checkpoint --resume can continue from: no "
                          f"{', '.join(missing)} (a weights-only file?); restore one of the run's ckpt_*.pt as "
                          "last.pt, or start a new run (another --out)")


class _Unset:
    """A key one of two configs does not give: shown as ``unset``, not as ``None`` (a value it could hold)."""

    def __repr__(self) -> str:
        return "unset"


_UNSET = _Unset()


def _differences(was: Any, now: Any, path: str = "") -> list[tuple[str, Any, Any]]:
    """``(dotted path, was, now)`` where two JSON-like trees differ (``levels[0].samples``); a key only one of
    them has is ``_UNSET`` in the other."""
    if isinstance(was, dict) and isinstance(now, dict):
        return [d for k in sorted(set(was) | set(now), key=str)
                for d in _differences(was.get(k, _UNSET), now.get(k, _UNSET), f"{path}.{k}" if path else str(k))]
    if isinstance(was, list) and isinstance(now, list) and len(was) == len(now):
        return [d for i, (a, b) in enumerate(zip(was, now)) for d in _differences(a, b, f"{path}[{i}]")]
    return [] if was == now else [(path or "(root)", was, now)]


def refuse_another_model(last: Path, stored: Any, now: ModelConfig) -> None:
    """Refuse to resume ``last`` when the model it holds was built from another model config (a preset changed
    since, or other ``model`` overrides): the weights would load into another architecture, or silently not."""
    try:
        was = ModelConfig.from_dict(stored, "model_config").to_dict()  # keys added since read as their defaults
    except ConfigError as e:
        raise ConfigError(f"{last}: its stored model config does not read: {e}") from e
    differ = _differences(json.loads(json.dumps(was)), json.loads(json.dumps(now.to_dict())))
    if differ:
        named = "; ".join(f"{p} {a!r} in the checkpoint, {b!r} now" for p, a, b in differ)
        raise ConfigError(f"{last}: resuming under another model config ({named}: the preset and the model "
                          "overrides build another model than the checkpoint holds); start a new run (another --out) "
                          "for another model")


def check_resumable(cfg: TrainConfig, last: Path, world: int | None = None) -> None:
    """:func:`refuse_another_config` for a training run (only :data:`RESUME_MAY_CHANGE` may differ) and
    :func:`refuse_another_model`; with ``world``, also refuse another process count (each rank's scenes and RNG
    state depend on it). A file without :data:`RESUME_KEYS` is refused first."""
    ck = load_checkpoint(last)
    require_resume_keys(ck, last)
    if world is not None and checkpoint_world_size(ck) != world:
        n = checkpoint_world_size(ck)
        raise ConfigError(f"{last}: saved by a run of {n} process(es), resumed with {world}: the scene split and "
                          f"the per-process random states depend on the count; resume with {n} "
                          f"(torchrun --nproc_per_node {n}) or start a new run (another --out)")
    try:
        was = json.loads(json.dumps(asdict(build_config(ck["config"]))))  # keys added since read as their defaults
    except ConfigError as e:
        raise ConfigError(f"{last}: its stored train config does not read: {e}") from e
    # the preset and the model overrides are compared by the model they build: restating a preset's own value, or
    # naming another preset that builds the same model (edge128 without its encoder: edge128_baseline), is the same
    by_model = ("preset", "model") if "model_config" in ck else ()
    refuse_another_config(last, was, json.loads(json.dumps(asdict(cfg))), RESUME_MAY_CHANGE, by_model)
    if by_model:
        refuse_another_model(last, ck["model_config"], cfg.model_config())


class RunFolderInUse(ConfigError, RuntimeError):
    """Another live process holds the run folder's ``train.pid``. A ConfigError (of ``--out``), so the command
    lines report it in one line with exit 2 (it was a bare RuntimeError: a traceback); still a RuntimeError for
    the callers that caught it as one."""


def refuse_live_lock(path: Path) -> None:
    """One training process per run folder: refuse (:class:`RunFolderInUse`) when ``path`` names another live
    process that holds it (a stale file, whose number another process has since been given, is not one:
    ``training.run_lock``)."""
    pid = lock_holder(path)
    if pid is not None and pid != os.getpid():
        raise RunFolderInUse(f"{path.parent}: another training process ({pid}) is using this run folder; wait for "
                             "it or stop it, or give another --out")


def take_lock(path: Path) -> None:
    refuse_live_lock(path)
    path.write_text(lock_text(os.getpid()))


def open_dataset(cfg: TrainConfig, world: int = 1):
    """The ``MultiViewDataset`` of ``cfg.data`` / ``cfg.split``, checked against the model and the process count
    (a :class:`~training.data.errors.DataError` or :class:`ConfigError` names what does not fit)."""
    from training.data.targets import TargetConfig
    from training.data.torch_dataset import MultiViewDataset

    mcfg = cfg.model_config()
    ds = MultiViewDataset(cfg.data, cfg.split, TargetConfig(heatmap_stride=mcfg.heatmap_stride,
                                                          **padding_config(cfg.frame_padding, cfg.edge_cut)))
    if ds.resolution != mcfg.height or ds.resolution != mcfg.width:
        raise ConfigError(f"data: {cfg.data} holds {ds.resolution} px scenes, the {cfg.preset!r} model takes "
                          f"{mcfg.width}x{mcfg.height}: use a dataset of its resolution or another preset")
    if len(ds) < world:
        raise ConfigError(f"split: {cfg.split!r} of {cfg.data} has {len(ds)} scenes for {world} processes")
    return ds


def ddp_find_unused(cfg: TrainConfig, mcfg: ModelConfig) -> bool:
    """Whether some parameters can go without a gradient in a step, which DDP must be told of: a head (or a cascade
    level) whose loss weight is zero, or the encoder's auxiliary head without its loss."""
    lc = cfg.loss
    return bool((mcfg.heads.coord_head and not lc.coord_weight)
                or (mcfg.use_human_encoder and mcfg.human.aux_heatmaps and not lc.encoder_heat_weight
                    and not cfg.freeze_human)
                or not lc.heat_weight  # g_h (and the human encoder's features it reads)
                or not (lc.colour_weight or (lc.ssim_weight and cfg.patch_size))  # g_c
                or any(w == 0 for w in lc.level_weights))  # that level's heads and 3D network


def truncate_log(path: Path, step: int) -> None:
    """Keep the records of ``path`` (``log.jsonl``) up to ``step``: a resumed run logs the later steps again
    (a line cut short by a crash goes too)."""
    if not path.exists():
        return
    kept = []
    for line in path.read_text().splitlines():
        try:
            rec = json.loads(line)
        except ValueError:
            continue
        if isinstance(rec, dict) and isinstance(rec.get("step"), int) and rec["step"] <= step:
            kept.append(line + "\n")
    write_atomic(path, "".join(kept))


def holds_more_than_weights(e: BaseException) -> bool:
    """Whether ``torch.load(..., weights_only=True)`` refused a whole pickle for holding other objects (a training
    checkpoint's numpy RNG state), not a damaged file: torch words both as a page of advice, the first naming the
    ``Unsupported global``."""
    return isinstance(e, pickle.UnpicklingError) and "Unsupported global" in str(e)


def load_error_words(e: BaseException) -> str:
    """Why ``torch.load`` could not read a file, in a few words: a file that is no pickle at all is a page of
    advice on ``weights_only`` to torch, which says nothing of the file."""
    if isinstance(e, pickle.UnpicklingError):
        return "UnpicklingError: not a file torch.save wrote, or a damaged one"
    words = error_words(e) or ("the file ends before its first record (empty?)"
                                               if isinstance(e, EOFError) else "no message")
    return f"{type(e).__name__}: {words}"


def load_init_weights(model: GHNeRF, path: str) -> None:
    """``init``: torchvision's resnet18 weights into the human encoder's trunk; a file that is not such weights is a
    ConfigError naming it (torch's errors came out as a traceback)."""
    if model.human is None:
        raise ConfigError("init: the preset has no human encoder")
    load_resnet18_into(model.human.trunk, path, "init")


def load_resnet18_into(trunk: torch.nn.Module, path: str, key: str) -> None:
    """torchvision's resnet18 weights at ``path`` into ``trunk``; a file that is not such weights is a ConfigError
    naming ``key`` (the setting that gave the file) and the file."""
    from training.model.human_encoder import ResNet18WeightsError, load_torchvision_resnet18

    try:
        load_torchvision_resnet18(trunk, path)
    except ResNet18WeightsError as e:  # named by key and shape, whole: torch's message was cut before them
        raise ConfigError(f"{key}: {path}: not torchvision resnet18 weights this encoder takes ({e}); give "
                          "torchvision's resnet18 state dict (resnet18-f37072fd.pth)") from e
    except Exception as e:  # noqa: BLE001 - torch raises several types (zip, EOF, a key or shape mismatch)
        if holds_more_than_weights(e):
            raise ConfigError(f"{key}: {path}: holds more than weights (a training run's last.pt or ckpt_*.pt?); "
                              f"{key} takes torchvision's resnet18 state dict (resnet18-f37072fd.pth)") from e
        raise ConfigError(f"{key}: {path}: not torchvision resnet18 weights this encoder takes "
                          f"({load_error_words(e)})") from e


def check_model_human_init(mcfg: ModelConfig) -> None:
    """``model.human.init`` (torchvision's resnet18 weights, read as a new run's model is built; a resume takes
    the checkpoint's) loaded into a throwaway trunk: a missing or foreign file was a traceback after
    ``config.json`` was written."""
    if not (mcfg.use_human_encoder and mcfg.human.init):
        return
    from training.model.human_encoder import ResNet18Trunk

    path = mcfg.human.init
    if not Path(path).is_file():
        raise ConfigError(f"model.human.init: {path}: no such file")
    load_resnet18_into(ResNet18Trunk(mcfg.human.num_layers), path, "model.human.init")


def load_start_weights(model: GHNeRF, cfg: TrainConfig) -> None:
    """The weights a new run starts from: ``init`` (torchvision), then ``human_init`` (the pretraining's
    ``human.pt``); each file that does not fit is a ConfigError naming the setting and the file."""
    if cfg.init:
        load_init_weights(model, cfg.init)
    if cfg.human_init:
        from training.pretrain_human import load_human

        load_human(model, cfg.human_init)


def check_start_weights(cfg: TrainConfig) -> None:
    """Load ``init`` / ``human_init`` into a throwaway model before the run folder is written: a file that is no
    such weights, or of another encoder, was found after ``config.json`` was (``init``'s as a traceback). The run
    reseeds before it builds its own model, so this changes none of its numbers."""
    if cfg.init or cfg.human_init:
        load_start_weights(GHNeRF(cfg.model_config()), cfg)


def _train(cfg: TrainConfig, out_dir: Path, info: DistInfo, device: torch.device, *, start: Path | None,
           resume: bool, quiet: bool, dataset) -> tuple[dict, GHNeRF]:
    mcfg = cfg.model_config()
    ds = dataset

    seed_everything(cfg.seed)  # same initial weights on every rank
    # a resume's checkpoint holds the weights model.human.init, init and human_init gave its start
    model = GHNeRF(mcfg, read_init=start is None).to(device).train()
    if start is None:
        load_start_weights(model, cfg)
    if not cfg.human_init and cfg.pretrain_human and info.main and not resume:
        print("warning: the config has a pretrain_human block but no human_init: the human encoder starts from "
              "scratch (run `python -m training.pretrain_human` first and pass its human.pt, or `make model`)",
              file=sys.stderr)
    if cfg.freeze_human:
        if model.human is None:
            raise ConfigError("freeze_human: the preset has no human encoder")
        model.human.freeze()
    opt = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=cfg.lr)
    gen = torch.Generator().manual_seed(cfg.seed * 1000 + info.rank + 1)
    seed_everything(cfg.seed + 7919 * info.rank + 1)  # per-rank stratified-sample noise
    step = 0
    last = out_dir / "last.pt"
    ck = None
    if start is not None:
        ck = load_checkpoint(start, map_location=device)
        model.load_state_dict(ck["model"])
        opt.load_state_dict(ck["optimizer"])
        step = int(ck["step"])
        extra = ck.get("extra") or {}
        if info.world == 1 or "rng_ranks" not in extra:
            set_rng_state(ck["rng"], gen)
        else:
            set_rng_state(extra["rng_ranks"][info.rank], gen)
    ddp_model: torch.nn.Module = model
    if info.world > 1:
        from torch.nn.parallel import DistributedDataParallel as DDP
        ddp_model = DDP(model, device_ids=[device.index] if device.type == "cuda" else None,
                        find_unused_parameters=ddp_find_unused(cfg, mcfg))

    log_path = out_dir / "log.jsonl"
    if info.main:
        truncate_log(log_path, step)  # records past the checkpoint would appear twice
    prog = Progress(cfg.iterations, step, enabled=info.main and not quiet)
    per_epoch = len(ds) // info.world
    clock = RunClock.resumed(ck and ck.get("extra"), step, torch.get_num_threads())
    stopped_early = False
    # The log's state: the steps since the last record and the last PCK. A checkpoint keeps it, so the records
    # after a resume are those of an uninterrupted run (the first one averaged only the resumed steps, and its
    # pck was NaN until the next pck_every step); checkpoints made before it was kept start afresh.
    logged = ((ck and ck.get("extra")) or {}).get("log_state") or {}
    window: dict[str, list[float]] = {k: [float(x) for x in v] for k, v in logged.get("window", {}).items()}
    last_pck = float(logged.get("pck", float("nan")))
    item = None

    def checkpoint(s: int) -> None:
        extra = {"segments": clock.segments(s), "world_size": info.world,
                 "log_state": {"window": {k: list(v) for k, v in window.items()}, "pck": last_pck}}
        if info.world > 1:
            states = [None] * info.world
            dist.all_gather_object(states, rng_state(gen))
            extra["rng_ranks"] = states
        if info.main:
            save_checkpoint(last, model, opt, s, cfg, gen, extra)
            if s % cfg.checkpoint_every == 0:
                save_checkpoint(out_dir / f"ckpt_{s:07d}.pt", model, opt, s, cfg, gen, extra)

    while step < cfg.iterations:
        epoch, offset = divmod(step, per_epoch)
        order = scene_order(len(ds), epoch, cfg.seed, info)
        for idx in order[offset:]:
            if step >= cfg.iterations:
                break
            item = ds[idx]
            batch = make_batch(item, cfg, mcfg, gen)
            batch = {k: v.to(device) for k, v in batch.items()}
            lr = learning_rate(cfg, step)
            for g in opt.param_groups:
                g["lr"] = lr
            try:
                out, terms = train_step(ddp_model, model, opt, batch, cfg)
            except NonFiniteLoss as e:
                saved = f"{last} holds step {_saved_step(last)}" if last.exists() else "no checkpoint was saved"
                raise NonFiniteLoss(f"step {step + 1} (scene {idx}): {e}; the weights were not updated and {saved}: "
                                    "start a new run with a lower lr or a grad_clip") from None
            step += 1
            loss_v = float(terms["loss"].detach())
            window.setdefault("loss", []).append(loss_v)
            window.setdefault("psnr", []).append(psnr_of(out["levels"][-1]["rgb"], batch["rgb"]))
            last_heat = terms.get(f"l{len(out['levels']) - 1}_heat")  # absent with loss.heat_weight 0
            if last_heat is not None:
                window.setdefault("heat", []).append(float(last_heat.detach()))
            last_depth = f"l{len(out['levels']) - 1}_depth"
            if last_depth in terms:  # metres, mean absolute error on the subject
                window.setdefault("depth_err_m", []).append(float(terms[last_depth].detach()))
            if cfg.pck_every and step % cfg.pck_every == 0 and info.main:
                last_pck = source_pck(model, item, device)
            if step % cfg.log_every == 0 or step == cfg.iterations:
                rec = {k: float(np.mean(v)) for k, v in window.items()}
                rec["pck"] = last_pck
                window = {}
                if info.main:
                    prog.update(step, {"loss": rec["loss"], "psnr": rec["psnr"], "pck": rec["pck"]})
                    with open(log_path, "a") as fh:
                        # strict JSON: the pck before the first pck_every step is NaN, written as null
                        fh.write(strict_json({"step": step, "lr": lr, "time_s": round(clock.elapsed(), 2),
                                              **rec}, indent=None) + "\n")
            if step % cfg.checkpoint_every == 0 or step == cfg.iterations:
                checkpoint(step)
            if cfg.max_minutes and step % cfg.log_every == 0 and step < cfg.iterations:
                over = torch.tensor([float(clock.elapsed() > 60 * cfg.max_minutes)], device=device)
                if info.world > 1:  # every rank must take the same decision (rank 0's clock)
                    dist.broadcast(over, 0)
                if over.item():
                    stopped_early = True
                    checkpoint(step)
                    break
        if stopped_early:
            break
    prog.close()
    summary = {"steps": step, "iterations": cfg.iterations, "stopped_early": stopped_early,
               **clock.summary(step), "world_size": info.world, "device": str(device),
               **({"gpu": torch.cuda.get_device_name(device)} if device.type == "cuda" else {}),
               "threads": torch.get_num_threads(), "checkpoint": str(last)}
    if info.main:
        write_atomic(out_dir / "summary.json", strict_json(summary))
    return summary, model


# ------------------------------------------------------------------------------------------------ CLI
def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    from training.cli.train import build_parser  # noqa: PLC0415

    return build_parser().parse_args(argv)


def config_from_args(args: argparse.Namespace) -> TrainConfig:
    data = load_config_file(args.config) if args.config else {}
    sets = list(args.set)
    for key in ("preset", "data", "iterations", "threads", "seed", "init"):
        v = getattr(args, key)
        if v is not None:
            sets.append(f"{key}={json.dumps(v)}")
    return build_config(apply_overrides(data, sets))


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        cfg = config_from_args(args)
    except ConfigError as e:
        print(f"ghnerf-train: config error: {e}", file=sys.stderr)
        return 2
    if args.validate_config:
        print(json.dumps(asdict(cfg), indent=1))
        return 0
    out = Path(args.out)
    from training.data.errors import DataError

    try:
        with sigterm_as_interrupt():  # `timeout`, `kill`, a job scheduler: stopped as Ctrl-C stops it
            summary, _ = train(cfg, out, resume=args.resume, quiet=args.quiet)
    except (ConfigError, DataError) as e:  # of the run itself: its folder, a checkpoint, the dataset or split
        kind = "config error" if isinstance(e, ConfigError) else "data error"
        print(f"ghnerf-train: {kind}: {e}", file=sys.stderr)
        if dist.is_initialized():
            dist.destroy_process_group()
        return 2
    except (NonFiniteLoss, CheckpointWriteError) as e:  # mid-run: named in one line, the last checkpoint intact
        kind = "diverged" if isinstance(e, NonFiniteLoss) else "checkpoint not written"
        print(f"ghnerf-train: {kind}: {e}", file=sys.stderr)
        if dist.is_initialized():
            dist.destroy_process_group()
        return 1
    except KeyboardInterrupt as e:  # Ctrl-C or SIGTERM: the checkpoints are whole (save_checkpoint): say how to go on
        print(f"ghnerf-train: stopped ({stop_words(e)}); `--resume --out {out}` continues from its last checkpoint",
              file=sys.stderr)
        return exit_status(e)
    if int(os.environ.get("RANK", "0")) == 0:
        print(strict_json(summary, indent=None))
    if dist.is_initialized():
        dist.destroy_process_group()
    return 0

