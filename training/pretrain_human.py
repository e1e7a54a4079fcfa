"""``python -m training.pretrain_human``: pretrain the ResNet18 human encoder on 2D joint heatmaps alone.

GHNeRF starts its human encoder from ImageNet weights; none can be had here. This stage gives the
encoder a start of its own: the trunk, its level projections and the auxiliary heatmap head
(``human.aux_heatmaps``) are trained on the synthetic dataset's dense 2D heatmaps of *every* view of
each scene and their mirror images (left/right channels swapped), with the joint trainer's
positive-weighted MSE. No cost volume, no rays: a step costs the encoder alone, so on a 2-core CPU
the encoder sees several times more images per minute than inside the full model (docs/training.md
has the measured figures).

The run folder holds ``human.pt`` (the encoder's state dict and the model config it belongs to),
``last.pt`` and ``prev.pt`` (resume: ``training.pretrain_checkpoint``), ``log.jsonl``, ``summary.json`` and, while
it runs, ``train.pid``. Like ``ghnerf-train``, ``--resume`` refuses another config or model config and a file that
is no pretraining checkpoint (a ``human.pt`` copied to ``last.pt``), and cuts
``log.jsonl`` back to the checkpoint's step; the dataset is opened before anything is written; checkpoints
are fsynced before their rename. ``ghnerf-train`` loads ``human.pt`` with
``human_init: "<run>/human.pt"``; the pipeline does both when the train config names a
``pretrain_human`` block.

Example::

    python -m training.pretrain_human --data data/edge128 --out runs/edge128_human --iterations 6000
    python -m training.pretrain_human --score runs/edge128_human/human.pt --split val    # PCK@0.2 only
"""
from __future__ import annotations

if __name__ == "__main__":  # python -m: the arguments are parsed before torch loads (training.cli)
    from training.cli.pretrain_human import main as _cli_main

    raise SystemExit(_cli_main())

import copy
import json
import math
import os
import random
import sys
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Literal
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from training.configs import PRESETS
from training.losses import positive_weighted_mse, window_centroid_loss
from training.run_clock import RunClock
from training.run_limits import seed_problem, threads_problem
from training.model import GHNeRF, ModelConfig
from training.model.config import Config, ConfigError
from training.augment import AugmentConfig, augment_views
from training.model_card import strict_json, write_atomic
from training import pretrain_checkpoint
from ghnerf_runtime.cli.sigterm import exit_status, sigterm_as_interrupt, stop_words
from training.train import HEATMAP_SIGMA_HM_PX, CheckpointWriteError, DistInfo, Progress, apply_overrides, \
    encoder_views_images, error_words, holds_more_than_weights, learning_rate, load_config_file, load_error_words, \
    mirrored, check_model_human_init, model_config_of, padding_config, refuse_another_config, refuse_another_model, \
    refuse_existing_run, refuse_live_lock, refuse_model_folder, require_cuda_if_asked, require_resume_keys, \
    save_atomic, scene_order, seed_everything, take_lock, truncate_log

HUMAN_CHECKPOINT_VERSION = 1


@dataclass
class PretrainConfig(Config):
    """One human-encoder pretraining run (JSON file and/or ``--set key=value``)."""

    preset: str = "edge128"
    """Model preset whose human encoder is trained (its ``human`` block must have ``aux_heatmaps``)."""
    model: dict = field(default_factory=dict)
    """Partial ``ModelConfig`` overrides, as in ``TrainConfig.model`` (must match the joint run's)."""
    data: str = "data/edge128"
    split: str = "train"
    iterations: int = 1000
    scenes_per_step: int = 2
    """Scenes per step; each gives all its views (sources and targets) and, with ``flip``, their mirrors."""
    flip: bool = True
    """Also train on the mirror images (left/right joint channels swapped)."""
    frame_padding: bool = False
    """Black out what each crop shows past its camera's frame, as the runtime pads it
    (``TargetConfig.frame_padding``); a train config's own ``frame_padding`` is the default of its block."""
    edge_cut: float = 0.0
    """The share of source views whose frame is cut at the person (``TargetConfig.edge_cut``; needs
    ``frame_padding``); a train config's own ``edge_cut`` is the default of its block."""
    augment: AugmentConfig = field(default_factory=AugmentConfig)
    """Random rotation / scale / shift of every image (``training.augment``), before the mirroring."""
    lr: float = 1e-3
    lr_decay_every: int = 0
    lr_decay_gamma: float = 0.5
    lr_min: float = 0.0
    heat_positive_weight: float = 20.0
    """``mean((1 + w t) (h - t)^2)``: the joint trainer's heatmap loss (``loss.heat_positive_weight``)."""
    centroid_weight: float = 0.0
    """Weight of a localisation term (``losses.window_centroid_loss``: distance in cells between the predicted
    and the true centroid around each visible joint); 0: the heatmap MSE alone (the shipped recipe)."""
    seed: int = 0
    checkpoint_every: int = 1000
    log_every: int = 50
    eval_every: int = 1000
    """Every this many steps, PCK@0.2 of the head on ``eval_scenes`` scenes of ``eval_split`` (0: off).
    A progress figure only: nothing is selected on it."""
    eval_split: str = "val"
    eval_scenes: int = 64
    threads: int = 0
    """torch CPU threads (0: all cores)."""
    device: Literal["auto", "cpu", "cuda"] = "auto"
    loader_workers: int = 0
    """Processes that load and transform the step batches ahead of the trainer (0: in the training process).
    On a GPU the in-process loading bounds the step rate; the batches are the same either way (each is a
    pure function of the seed and the step), so this changes how fast, not what, the run learns."""
    max_minutes: float = 0.0
    """Stop (with a checkpoint and ``human.pt``) after this wall time (0: no limit)."""
    stop_at: int = 0
    """Stop (with a checkpoint and ``human.pt``) once this step is reached (0: run to ``iterations``); a run
    resumed at or past it stops at once. The pipeline trains the first steps at one thread beside the baseline's
    joint run, then resumes at every core (``--resume`` trains on the same batches, so a split run learns what a
    straight one does at the same thread counts). With ``precision`` ``auto``, a scale that starts before the
    stop is timed there, at that part's thread count, and its pick holds after the resume."""
    precision: Literal["fp32", "bf16", "auto"] = "fp32"
    """Arithmetic of the encoder's forward pass: ``fp32``; ``bf16`` (``torch.autocast``: convolutions in bfloat16,
    the weights, optimiser and loss in float32); ``auto``: on a CUDA GPU ``bf16`` where it has bfloat16; on a
    CPU with bfloat16 instructions (:func:`cpu_has_native_bf16`) whichever of the two is faster, timed on the
    run's first batch at each trunk input scale (:func:`fastest_precision`; bf16 only if 10 % faster); else
    ``fp32``. The instructions alone do not say: on the 2-core EPYC (AVX512_BF16) a 16-image step at the
    128x128 trunk takes 0.11 s in bf16 against 0.19 s in fp32, on session 38's Intel Xeon (AVX512_BF16, no
    AMX) 0.30 s against 0.21
    (``benchmarks/time_pretrain_step.py``, docs/training.md)."""

    coarse_steps: int = 0
    """The first this many steps feed the trunk the image resized by ``coarse_input_scale`` instead of the model's
    ``human.input_scale`` (progressive resizing: early steps learn coarse shapes at a fraction of the cost; the
    weights do not depend on the input size, and the heatmaps keep their size). 0: off (the ``gpu`` recipe); the
    ``cpu`` recipe runs 17600 of its 44000 steps so (docs/training.md, "Progressive resizing")."""
    coarse_input_scale: float = 0.5
    """The trunk's input scale during ``coarse_steps`` (must give a trunk input divisible by 16)."""

    def validate(self) -> None:
        def fail(key: str, why: str) -> None:
            raise ConfigError(f"pretrain_human.{key}: {why}")

        if self.preset not in PRESETS:
            fail("preset", f"unknown preset {self.preset!r}; presets: {sorted(PRESETS)}")
        for key in ("iterations", "scenes_per_step", "checkpoint_every", "log_every", "eval_scenes"):
            if getattr(self, key) < 1:
                fail(key, f"must be >= 1, got {getattr(self, key)}")
        for key in ("lr_decay_every", "eval_every", "threads", "loader_workers", "coarse_steps", "stop_at"):
            if getattr(self, key) < 0:
                fail(key, f"must be >= 0, got {getattr(self, key)}")
        for key, problem in (("seed", seed_problem(self.seed)), ("threads", threads_problem(self.threads, 0))):
            if problem:  # torch takes both as C integers: past them the run failed after its first files
                fail(key, problem)
        for key in ("lr", "lr_min", "heat_positive_weight", "centroid_weight", "max_minutes"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0) or (key == "lr" and v == 0):
                fail(key, f"must be a finite number {'> 0' if key == 'lr' else '>= 0'}, got {v!r}")
        if not 0 < self.lr_decay_gamma <= 1:
            fail("lr_decay_gamma", f"must be in (0, 1], got {self.lr_decay_gamma}")
        self.augment.validate("pretrain_human.augment")
        try:
            padding_config(self.frame_padding, self.edge_cut)
        except ConfigError as e:
            raise ConfigError(f"pretrain_human.{e}") from e
        mcfg = self.model_config()
        if not (mcfg.use_human_encoder and mcfg.human.aux_heatmaps):
            fail("preset", f"{self.preset!r} has no human encoder with an auxiliary heatmap head")
        if self.coarse_steps:  # the model's own rule for a trunk input scale
            try:
                replace(mcfg, human=replace(mcfg.human, input_scale=self.coarse_input_scale)).validate()
            except ConfigError as e:
                fail("coarse_input_scale", f"{self.coarse_input_scale!r} is not a usable trunk input scale "
                                           f"for this {mcfg.width}x{mcfg.height} model ({e})")

    def input_scale_at(self, step: int) -> float | None:
        """The trunk's input scale for ``step`` (0-based) when it differs from the model's, else None."""
        return self.coarse_input_scale if step < self.coarse_steps else None

    def model_config(self) -> ModelConfig:
        return model_config_of(self.preset, self.model)

    @classmethod
    def from_dict(cls, data: dict, _path: str = "pretrain_human") -> "PretrainConfig":
        """Typed and validated once; an unknown key or a bad value names ``pretrain_human.<key>``."""
        cfg = super().from_dict({k: v for k, v in data.items() if k != "$comment"}, _path)
        cfg.validate()
        return cfg


def view_batch(items: list[dict], flip: bool, augment: AugmentConfig | None = None,
               generator: torch.Generator | None = None) -> tuple[Tensor, Tensor]:
    """Every view of ``items`` (randomly transformed with ``augment``; and their mirrors, ``train.mirrored``):
    images ``(N, 3, H, W)`` and heatmap grids ``(N, J, h, w)``."""
    images = torch.cat([encoder_views_images(it) for it in items])  # padded past the frame where the items say
    heat = torch.cat([it["tgt_heatmaps"] for it in items])
    if augment is not None and augment.enabled:
        stride = images.shape[-1] // heat.shape[-1]
        images, heat = augment_views(images, torch.cat([it["tgt_joints_2d"] for it in items]),
                                     torch.cat([it["tgt_visible"] for it in items]), augment,
                                     generator or torch.Generator(), stride, HEATMAP_SIGMA_HM_PX)
    if flip:
        m_images, m_heat = mirrored(images, heat)
        images, heat = torch.cat([images, m_images]), torch.cat([heat, m_heat])
    return images, heat


class StepBatches(torch.utils.data.Dataset):
    """The batch of every step, by step number: the scenes of the epoch's shuffle (``scene_order``, a pure
    function of seed and epoch) and the transforms drawn from a generator seeded by the step, so a run that
    loads them in worker processes (``loader_workers``) or resumes mid-epoch trains on the same batches."""

    def __init__(self, ds, cfg: PretrainConfig):
        self.ds, self.cfg = ds, cfg
        self.per_epoch = len(ds) // cfg.scenes_per_step
        self._epoch, self._order = -1, []  # the shuffle of the epoch last asked for (steps come in order)

    def __len__(self) -> int:
        return self.cfg.iterations

    def __getitem__(self, step: int) -> tuple[Tensor, Tensor]:
        cfg = self.cfg
        epoch, b = divmod(step, self.per_epoch)
        if epoch != self._epoch:
            self._epoch = epoch
            self._order = scene_order(len(self.ds), epoch, cfg.seed, DistInfo(rank=0, world=1, local_rank=0))
        items = [self.ds[i] for i in self._order[b * cfg.scenes_per_step:(b + 1) * cfg.scenes_per_step]]
        gen = torch.Generator().manual_seed(cfg.seed * 1_000_003 + step)
        return view_batch(items, cfg.flip, cfg.augment, gen)


def step_batches(ds, cfg: PretrainConfig, start: int):
    """``(images, heat)`` of the steps from ``start`` to ``cfg.iterations``, made ahead by ``cfg.loader_workers``
    processes (or here, one at a time, with none)."""
    from training.data.torch_dataset import load_in_workers

    batches = StepBatches(ds, cfg)
    steps = range(start, cfg.iterations)
    if not cfg.loader_workers:
        return (batches[s] for s in steps)
    # a damaged sample read in a worker is raised here as the same DatasetError as in-process (one line, exit 2)
    return load_in_workers(batches, batch_size=None, sampler=steps, num_workers=cfg.loader_workers, prefetch_factor=4,
                           pin_memory=torch.cuda.is_available(), worker_init_fn=_one_thread)


def _one_thread(_worker: int) -> None:
    torch.set_num_threads(1)  # the loaders share the cores with each other and the trainer


def heatmap_pck(model: GHNeRF, dataset, scenes: int, device: torch.device) -> float:
    """PCK@0.2 of the encoder's heatmaps in the two source views of the first ``scenes`` scenes of ``dataset``
    (decoded and scored as ``ghnerf-eval`` scores ``encoder_heatmaps``)."""
    return heatmap_scores(model, dataset, scenes, device)["pck@0.2"]


def heatmap_scores(model: GHNeRF, dataset, scenes: int, device: torch.device) -> dict:
    """:func:`heatmap_pck`'s PCK@0.2, and the median / p90 distance of the decoded visible joints from their
    truth in model-input pixels (``error_px_median``, ``error_px_p90``): the localisation PCK@0.2 hardly sees,
    and what triangulation amplifies into depth."""
    from ghnerf_runtime.metrics import pck
    from training.evaluate import PCK_ALPHA, keypoints_from_heatmaps

    was = model.training
    model.eval()
    correct = evaluated = 0
    errors = []
    with torch.no_grad():
        for i in range(min(scenes, len(dataset))):
            it = dataset[i]
            src = torch.nonzero(it["tgt_is_source"]).flatten()
            hm = model.encode_human(it["tgt_images"][src].to(device)).cpu().numpy()
            uv = keypoints_from_heatmaps(hm, model.config.height)
            truth, visible = it["tgt_joints_2d"][src].numpy(), it["tgt_visible"][src].numpy()
            found = np.isfinite(uv).all(-1)
            r = pck(np.nan_to_num(uv), truth, visible, alpha=PCK_ALPHA, pred_valid=found)
            correct, evaluated = correct + r.num_correct, evaluated + r.num_evaluated
            errors.append(np.linalg.norm(uv - truth, axis=-1)[visible & found])
    model.train(was)
    err = np.concatenate(errors) if errors else np.zeros(0)
    return {"pck@0.2": correct / evaluated if evaluated else float("nan"),
            "error_px_median": float(np.median(err)) if err.size else float("nan"),
            "error_px_p90": float(np.percentile(err, 90)) if err.size else float("nan")}


def resolve_precision(precision: str, device: torch.device) -> str:
    """``fp32`` or ``bf16``: what ``PretrainConfig.precision`` means on ``device`` (``auto`` asks the hardware)."""
    if precision != "auto":
        return precision
    if device.type == "cuda":
        return "bf16" if torch.cuda.is_bf16_supported() else "fp32"
    return "bf16" if cpu_has_native_bf16() else "fp32"


def cpu_has_native_bf16() -> bool:
    """The CPU computes bfloat16 in hardware. On x86 that takes AVX512_BF16 or AMX: oneDNN also runs bfloat16 on
    plain AVX-512 (``torch.ops.mkldnn._is_mkldnn_bf16_supported()`` is true there), but by conversion, which need
    not beat float32. Elsewhere (aarch64) oneDNN's own answer."""
    probe = lambda name: bool(getattr(torch.cpu, name, lambda: False)())  # noqa: E731 - private torch probes
    if probe("_is_avx2_supported"):  # x86
        return probe("_is_avx512_bf16_supported") or probe("_is_amx_tile_supported")
    return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())


#: bf16 must be this much faster than fp32 (seconds per step, ratio) to be picked: near a tie the timing noise
#: would pick either from run to run, and the arithmetic changes the weights.
BF16_MIN_SPEEDUP = 1.10


def fastest_precision(model: GHNeRF, images: Tensor, heat: Tensor, cfg: PretrainConfig,
                      input_scale: float | None, steps: int = 4, warmup: int = 2,
                      clock=time.perf_counter) -> tuple[str, dict[str, float]]:
    """``bf16`` where it runs :func:`pretrain_step` at least :data:`BF16_MIN_SPEEDUP` times as fast as ``fp32`` here
    on this batch, else ``fp32``; and the median seconds per step of each. The two are timed step by step in
    turn (a load that comes and goes falls on both), on copies of the encoder with optimisers of their own,
    and the random states are restored after, so the run itself is exactly what it would be without the probe."""
    times: dict[str, list[float]] = {"fp32": [], "bf16": []}
    py_state, np_state = random.getstate(), np.random.get_state()
    with torch.random.fork_rng(devices=[]):
        copies = {}
        for precision in times:
            probe = copy.deepcopy(model)
            copies[precision] = (probe, torch.optim.Adam(probe.human.parameters(), lr=cfg.lr))
        for i in range(warmup + steps):
            for precision in (("fp32", "bf16") if i % 2 else ("bf16", "fp32")):
                probe, opt = copies[precision]
                t0 = clock()
                pretrain_step(probe, opt, images, heat, cfg, precision, input_scale)
                if i >= warmup:
                    times[precision].append(clock() - t0)
        del copies
    random.setstate(py_state)
    np.random.set_state(np_state)
    seconds = {k: float(np.median(v)) for k, v in times.items()}
    return ("bf16" if seconds["fp32"] >= BF16_MIN_SPEEDUP * seconds["bf16"] else "fp32"), seconds


def scale_name(input_scale: float | None) -> str:
    """A trunk input scale as the probe's log and summary name it (None: the model's own, ``full``)."""
    return "full" if input_scale is None else str(input_scale)


def precision_label(probed: dict) -> str:
    """The summary's ``precision`` of a probed run: the one pick, or each scale's when they differ."""
    picks = {scale_name(k): v[0] for k, v in probed.items()}
    if len(set(picks.values())) == 1:
        return next(iter(picks.values()))
    return ", ".join(f"{v} at {k}" for k, v in picks.items())


def save_human(path: Path, model: GHNeRF, step: int) -> None:
    """``human.pt``: the encoder's weights (trunk, projections, heatmap head) and the model config."""
    state = {"version": HUMAN_CHECKPOINT_VERSION, "human": model.human.state_dict(), "step": step,
             "model_config": model.config.to_dict()}
    save_atomic(state, path)


def load_human(model: GHNeRF, path: str | Path, what: str = "human_init") -> int:
    """Load a ``human.pt`` into ``model.human``; returns the pretraining step. ``what``: the setting or option
    that named the file (``human_init``, ``--score``), which the errors name.

    Raises:
        ConfigError: the file is missing or unreadable, or its encoder does not fit this model's
            (another architecture: the message names the differing setting or weight).
    """
    p = Path(path)
    try:
        state = torch.load(str(p), map_location="cpu", weights_only=True)
    except FileNotFoundError as e:
        raise ConfigError(f"{what}: cannot read {p}: no such file") from e
    except Exception as e:  # noqa: BLE001 - torch raises several types (pickle, zip, runtime) for a bad file
        if holds_more_than_weights(e):
            raise ConfigError(f"{what}: {p} is not a human-encoder checkpoint (it holds more than weights: a "
                              "training run's last.pt or ckpt_*.pt?); give the pretraining's human.pt") from e
        raise ConfigError(f"{what}: cannot read {p}: {load_error_words(e)}") from e
    if not isinstance(state, dict) or "human" not in state:
        raise ConfigError(f"{what}: {p} is not a human-encoder checkpoint (no 'human' weights)")
    if model.human is None:
        raise ConfigError(f"{what}: the model has no human encoder")
    theirs = ModelConfig.from_dict(state.get("model_config", {})).human if state.get("model_config") else None
    if theirs is not None:
        ours = model.config.human
        for f in fields(ours):
            if f.name != "init" and getattr(theirs, f.name) != getattr(ours, f.name):
                raise ConfigError(f"{what}: {p} was pretrained with human.{f.name}="
                                  f"{getattr(theirs, f.name)!r}, this model has {getattr(ours, f.name)!r}")
    try:
        model.human.load_state_dict(state["human"], strict=True)
    except RuntimeError as e:
        raise ConfigError(f"{what}: {p} does not fit this model's human encoder: {e}") from e
    return int(state.get("step", 0))


@contextmanager
def trunk_input_scale(model: GHNeRF, scale: float | None):
    """The human encoder's trunk sees its input resized by ``scale`` inside the block (None: as configured).
    Only the forward pass's resize changes: no weight depends on it."""
    if scale is None:
        yield
        return
    hcfg = model.human.config
    kept = hcfg.input_scale
    hcfg.input_scale = scale
    try:
        yield
    finally:
        hcfg.input_scale = kept


def pretrain_step(model: GHNeRF, opt: torch.optim.Optimizer, images: Tensor, heat: Tensor,
                  cfg: PretrainConfig, precision: str, input_scale: float | None = None) -> float:
    """One update of the human encoder on one step's batch; returns the loss. ``input_scale``: the trunk's
    input scale for this step (``PretrainConfig.input_scale_at``; None: the model's).

    The forward pass runs under ``torch.autocast`` when ``precision`` is ``bf16`` (the resolved value, see
    ``resolve_precision``); the loss, the gradients' accumulation and Adam stay float32. Shared by
    ``pretrain`` and ``benchmarks/time_pretrain_step.py`` so the benchmark times exactly this.
    """
    device = next(model.human.parameters()).device
    images = images.to(device, memory_format=torch.channels_last)
    with torch.autocast(device.type, dtype=torch.bfloat16, enabled=precision == "bf16"), \
            trunk_input_scale(model, input_scale):
        pred = model.encode_human(images)
    pred, heat = pred.float(), heat.to(device)  # the loss in float32 whatever the forward pass
    loss = positive_weighted_mse(pred, heat, cfg.heat_positive_weight)
    if cfg.centroid_weight:
        loss = loss + cfg.centroid_weight * window_centroid_loss(pred, heat)
    opt.zero_grad(set_to_none=True)
    loss.backward()
    # Checked before the update (as train_step does): a NaN gradient of a finite loss, once applied, was saved
    # in last.pt, the pretraining's only checkpoint, and every resume diverged from it.
    lv = float(loss.detach())
    if not math.isfinite(lv):
        raise FloatingPointError(f"non-finite loss ({lv:g}); the weights were not updated")
    grads = [p.grad for p in model.parameters() if p.grad is not None]
    if grads and not all(bool(torch.isfinite(g).all()) for g in grads):
        raise FloatingPointError(f"non-finite gradient of a finite loss ({lv:.6g}); the weights were not updated")
    opt.step()
    return lv


#: Pretraining keys a resumed run may change: its length, where the data lives and how it runs.
RESUME_MAY_CHANGE = ("iterations", "data", "threads", "device", "max_minutes", "stop_at", "log_every", "eval_every",
                     "eval_scenes", "checkpoint_every", "loader_workers")


#: What ``--resume`` reads from ``last.pt`` (a ``human.pt`` put in its place lacks the optimiser).
RESUME_KEYS = ("human", "optimizer", "step")


def _check_resumable(cfg: PretrainConfig, last: Path, ck: dict) -> None:
    """Refuse to resume ``last`` (loaded: ``ck``) when it is no pretraining checkpoint (named keys missing), under
    another config (checkpoints from before the config was stored pass), or when the encoder it holds was built
    from another model config (the preset changed since: its weights would not load)."""
    require_resume_keys(ck, last, RESUME_KEYS)
    old = ck.get("config")
    if old:
        now = json.loads(json.dumps(asdict(cfg)))
        was = {**now, **json.loads(json.dumps(old))}  # keys added since read as the new run's
        # the preset and the model overrides are compared by the encoder they build (a restated preset value, or
        # another preset building the same model, is the same one)
        by_model = ("preset", "model") if "model_config" in ck else ()
        refuse_another_config(last, was, now, RESUME_MAY_CHANGE, by_model)
    if "model_config" in ck:
        refuse_another_model(last, ck["model_config"], cfg.model_config())


def _refuse_existing_pretraining(out: Path) -> None:
    """A new run must not overwrite another's checkpoints: ``last.pt`` (``refuse_existing_run``) or a ``prev.pt``
    left alone (a crash between its two renames)."""
    refuse_existing_run(out)
    if (out / pretrain_checkpoint.PREV).exists():
        raise ConfigError(f"{out}: holds a training run ({pretrain_checkpoint.PREV}); pass --resume to continue "
                          "it, or another --out for a new run")


def pretrain(cfg: PretrainConfig, out_dir: str | Path, *, resume: bool = False, quiet: bool = False,
             dataset=None, eval_dataset=None) -> dict:
    """Run (or resume) the pretraining; returns the summary (also in ``out_dir/summary.json``)."""
    from training.data.targets import TargetConfig
    from training.data.torch_dataset import MultiViewDataset

    cfg.validate()
    if cfg.coarse_steps >= cfg.iterations:  # allowed (a run stopped early to be extended), but rarely meant
        print(f"warning: pretrain_human.coarse_steps={cfg.coarse_steps} >= iterations={cfg.iterations}: every "
              f"step feeds the trunk at input scale {cfg.coarse_input_scale}, none at the model's "
              f"({cfg.model_config().human.input_scale})", file=sys.stderr)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():  # (mkdir below raised FileExistsError: a traceback)
        raise ConfigError(f"{out}: is a file; --out names the run folder")
    refuse_model_folder(out)  # its last.pt and config.json beside the graphs (the trainer's check)
    refuse_live_lock(out / "train.pid")  # a folder in use is named first, whatever else is wrong
    require_cuda_if_asked(cfg.device)
    start = pretrain_checkpoint.resume_point(out) if resume else None  # last.pt, else prev.pt
    if start is not None:
        _check_resumable(cfg, *start)  # before config.json is overwritten with the new one
    elif not resume:
        _refuse_existing_pretraining(out)  # a new run never overwrites another's config.json and last.pt
    mcfg = cfg.model_config()
    if start is None:  # read as the model is built, after config.json: named before it (a resume reads it not)
        check_model_human_init(mcfg)
    targets = TargetConfig(heatmap_stride=mcfg.heatmap_stride, **padding_config(cfg.frame_padding, cfg.edge_cut))
    # the dataset and its splits are opened (a missing one named) before anything is written
    ds = dataset or MultiViewDataset(cfg.data, cfg.split, targets)
    if len(ds) < cfg.scenes_per_step:
        raise ConfigError(f"split: {cfg.split!r} of {cfg.data} has {len(ds)} scenes, fewer than "
                          f"scenes_per_step={cfg.scenes_per_step}")
    val = eval_dataset
    if val is None and cfg.eval_every:
        val = MultiViewDataset(cfg.data, cfg.eval_split, targets)
    out.mkdir(parents=True, exist_ok=True)
    # train.pid, as the trainer's: held while the run lives and removed on the way out (Ctrl-C too), so the pipeline
    # tells a run in progress (a live pid) from one stopped a moment ago, which it may resume or set aside at once
    take_lock(out / "train.pid")
    try:
        return _pretrain(cfg, out, start, quiet, ds, val)
    finally:
        (out / "train.pid").unlink(missing_ok=True)


def _pretrain(cfg: PretrainConfig, out: Path, start: tuple[Path, dict] | None, quiet: bool, ds, val) -> dict:
    write_atomic(out / "config.json", json.dumps(asdict(cfg), indent=1))
    # summary.json describes the invocation that wrote it (as the trainer's): an interrupted resume leaves none,
    # not the previous invocation's (a stop_at part's "stopped early at step N" beside a last.pt of a later step)
    (out / "summary.json").unlink(missing_ok=True)
    mcfg = cfg.model_config()
    use_cuda = cfg.device == "cuda" or (cfg.device == "auto" and torch.cuda.is_available())
    device = torch.device("cuda" if use_cuda else "cpu")
    if device.type == "cpu":
        torch.set_num_threads(cfg.threads or os.cpu_count() or 1)
        torch.set_flush_denormal(True)

    seed_everything(cfg.seed)  # same initial weights as the joint run of the same seed
    model = GHNeRF(mcfg, read_init=start is None).to(device).train()  # a resume's last.pt holds the weights
    # Channels-last convolutions: 0.165 s per 16-image step against 0.189 (2-core EPYC, two threads, the
    # 300-step run of docs/training.md "Lanes"); the same weights and updates, another memory layout.
    model.human.to(memory_format=torch.channels_last)
    params = list(model.human.parameters())
    opt = torch.optim.Adam(params, lr=cfg.lr)
    step = 0
    ck = None
    # last.pt becomes prev.pt at the next checkpoint only when it is good: after a resume from prev.pt (last.pt
    # damaged), the damaged file is overwritten and the good prev.pt kept
    rotate = start is None or start[0].name == pretrain_checkpoint.LAST
    if start is not None:
        path, ck = start
        try:
            model.human.load_state_dict(ck["human"])
        except RuntimeError as e:  # a checkpoint from before model_config was stored, of another architecture
            raise ConfigError(f"{path}: its encoder weights do not fit the {cfg.preset!r} model of this config "
                              f"({error_words(e)}); start a new run (another --out)") from e
        opt.load_state_dict(ck["optimizer"])
        step = int(ck["step"])
    clock = RunClock.resumed(ck, step, torch.get_num_threads())
    precision = resolve_precision(cfg.precision, device)
    # A CPU's bfloat16 instructions need not make bf16 the faster (docs/training.md): time both per scale. A
    # resumed run keeps the picks its checkpoint holds, so one scale never changes arithmetic midway.
    probe = cfg.precision == "auto" and device.type == "cpu" and precision == "bf16"
    probed: dict[float | None, tuple[str, dict[str, float]]] = {}
    if probe and ck is not None:
        probed = {k: tuple(v) for k, v in (ck.get("precision_probe") or {}).items()}
    seed_everything(cfg.seed + 1)
    # The log's state, as the joint trainer keeps it: the losses since the last record and the last PCK. A
    # checkpoint holds it, so the records after a resume are those of an uninterrupted run (the first one
    # averaged only the resumed steps, and its pck, like the summary's, was NaN until the next eval_every step);
    # checkpoints made before it was kept start afresh.
    logged = (ck or {}).get("log_state") or {}
    losses: list[float] = [float(x) for x in logged.get("losses", [])]
    last_pck = float(logged.get("pck", float("nan")))

    def checkpoint(s: int) -> None:
        nonlocal rotate
        state = {"human": model.human.state_dict(), "optimizer": opt.state_dict(), "step": s,
                 "segments": clock.segments(s), "config": asdict(cfg), "precision_probe": probed,
                 "model_config": mcfg.to_dict(), "log_state": {"losses": list(losses), "pck": last_pck}}
        pretrain_checkpoint.save(state, out, rotate)
        rotate = True
        save_human(out / "human.pt", model, s)

    truncate_log(out / "log.jsonl", step)  # records past the checkpoint would appear twice after a resume
    prog = Progress(cfg.iterations, step, enabled=not quiet)
    # stop_at: a run resumed at or past it has nothing to do in this invocation
    stopped_early = bool(cfg.stop_at) and cfg.stop_at <= step < cfg.iterations
    for images, heat in ([] if stopped_early else step_batches(ds, cfg, step)):
        lr = learning_rate(cfg, step)
        for g in opt.param_groups:
            g["lr"] = lr
        scale = cfg.input_scale_at(step)
        if probe and scale not in probed:
            probed[scale] = fastest_precision(model, images, heat, cfg, scale)
            times = ", ".join(f"{k} {v:.3f}" for k, v in probed[scale][1].items())
            print(f"precision auto at trunk input scale {scale_name(scale)}: {probed[scale][0]} "
                  f"(s/step {times})", file=sys.stderr)  # a decision, not progress: printed under --quiet too
        if probe:
            precision = probed[scale][0]
        try:
            lv = pretrain_step(model, opt, images, heat, cfg, precision, scale)
        except FloatingPointError as e:
            raise FloatingPointError(f"step {step + 1}: {e}") from None
        step += 1
        losses.append(lv)
        if cfg.eval_every and step % cfg.eval_every == 0:
            with trunk_input_scale(model, cfg.input_scale_at(step - 1)):  # scored as it is being trained
                last_pck = heatmap_pck(model, val, cfg.eval_scenes, device)
        if step % cfg.log_every == 0 or step == cfg.iterations:
            rec = {"step": step, "lr": lr, "time_s": round(clock.elapsed(), 2),
                   "loss": float(np.mean(losses)), "pck": last_pck,
                   **({"input_scale": scale} if scale is not None else {})}
            losses = []
            prog.update(step, {"loss": rec["loss"], "pck": last_pck})
            with open(out / "log.jsonl", "a") as fh:
                fh.write(strict_json(rec, indent=None) + "\n")  # a pck not yet scored (NaN) as null
        if step % cfg.checkpoint_every == 0 or step == cfg.iterations:
            checkpoint(step)
        if step < cfg.iterations and ((cfg.max_minutes and clock.elapsed() > 60 * cfg.max_minutes)
                                      or (cfg.stop_at and step >= cfg.stop_at)):
            stopped_early = True
            if step % cfg.checkpoint_every:  # (else saved just above)
                checkpoint(step)
            break
    prog.close()
    summary = {"steps": step, "iterations": cfg.iterations, "stopped_early": stopped_early,
               **clock.summary(step), "device": str(device), "threads": torch.get_num_threads(),
               "precision": precision_label(probed) if probed else precision,
               **({"precision_probe": {scale_name(k): {"picked": v[0], "s_per_step": v[1]}
                                       for k, v in probed.items()}} if probed else {}),
               **({"gpu": torch.cuda.get_device_name(device)} if device.type == "cuda" else {}),
               "images_per_step": cfg.scenes_per_step * ds[0]["tgt_images"].shape[0] * (2 if cfg.flip else 1),
               "eval_pck@0.2": last_pck, "eval_split": cfg.eval_split if cfg.eval_every else None,
               "human": str(out / "human.pt")}
    write_atomic(out / "summary.json", strict_json(summary))  # eval_pck@0.2 never scored: null
    return summary


def config_from_train_config(data: dict, overrides: list[str] = ()) -> PretrainConfig:
    """The ``PretrainConfig`` of a train config's ``pretrain_human`` block (its preset, model, data,
    ``frame_padding`` and ``edge_cut`` come from the train config), or of a bare ``PretrainConfig`` dict;
    ``overrides`` are ``key=value`` strings."""
    if "pretrain_human" in data:
        data = {"preset": data.get("preset", "edge128"), "model": data.get("model", {}),
                "data": data.get("data", "data/edge128"), "frame_padding": data.get("frame_padding", False),
                "edge_cut": data.get("edge_cut", 0.0),
                **(data["pretrain_human"] or {})}
    return PretrainConfig.from_dict(apply_overrides(data, list(overrides)))


def score_human(path: str | Path, data: str | Path, split: str = "val", scenes: int = 0) -> dict:
    """PCK@0.2 of a ``human.pt``'s heatmap head in the source views of ``scenes`` scenes of ``split`` (0: all),
    scored as :func:`heatmap_pck` scores it during pretraining, and its 2D error (:func:`heatmap_scores`)."""
    from training.data.targets import TargetConfig
    from training.data.torch_dataset import MultiViewDataset

    try:
        mc = torch.load(str(path), map_location="cpu", weights_only=True).get("model_config")
    except Exception:  # noqa: BLE001 - load_human below reports the unreadable file by name
        mc = None
    # the file's weights replace every encoder weight model.human.init would give, and that file may have moved
    model = GHNeRF(ModelConfig.from_dict(mc) if mc else model_config_of("edge128", {}), read_init=False)
    step = load_human(model, path, "--score")
    ds = MultiViewDataset(data, split, TargetConfig(heatmap_stride=model.config.heatmap_stride))
    n = min(scenes, len(ds)) if scenes else len(ds)
    return {"human": str(path), "step": step, "split": split, "scenes": n,
            **heatmap_scores(model, ds, n, torch.device("cpu"))}


def main(argv: list[str] | None = None) -> int:
    from training.cli.pretrain_human import build_parser, parse_args  # noqa: PLC0415

    ap = build_parser()
    args = parse_args(argv)
    from training.data.errors import DataError

    if args.score:
        if args.threads:
            torch.set_num_threads(args.threads)
        try:
            print(strict_json(score_human(args.score, args.data or "data/edge128", args.split or "val",
                                          args.scenes or 0)))
        except (ConfigError, DataError) as e:  # the file, or a missing dataset or split (was a traceback)
            print(f"error: {e}", file=sys.stderr)
            return 2
        return 0
    if not args.out:
        ap.error("--out is required (or --score HUMAN_PT)")
    try:
        sets = list(args.set) + [f"{k}={json.dumps(getattr(args, k))}" for k in ("data", "iterations", "threads")
                                 if getattr(args, k) is not None]
        cfg = config_from_train_config(load_config_file(args.config) if args.config else {}, sets)
    except ConfigError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    try:
        with sigterm_as_interrupt():  # `timeout`, `kill`, a job scheduler: stopped as Ctrl-C stops it
            summary = pretrain(cfg, args.out, resume=args.resume, quiet=args.quiet)
    except (ConfigError, DataError) as e:  # while starting: a run folder in use, a resume under another config,
        print(f"error: {e}", file=sys.stderr)  # a file that is no checkpoint, a missing dataset or split
        return 2
    except (FloatingPointError, CheckpointWriteError) as e:  # mid-run, as ghnerf-train: one line, last.pt intact
        print(f"error: {'diverged' if isinstance(e, FloatingPointError) else 'checkpoint not written'}: {e}",
              file=sys.stderr)
        return 1
    except KeyboardInterrupt as e:  # Ctrl-C or SIGTERM: the checkpoints are whole (save_atomic): say how to go on
        print(f"stopped ({stop_words(e)}); `--resume --out {args.out}` continues from its last checkpoint",
              file=sys.stderr)
        return exit_status(e)
    print(strict_json(summary))
    return 0

