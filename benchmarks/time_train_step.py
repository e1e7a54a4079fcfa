"""Seconds per step of the joint run (``ghnerf-train``), by variant, thread count and arithmetic.

    .venv/bin/python benchmarks/time_train_step.py --data data/edge128 \
        [--variants ghnerf,baseline] [--threads 1,2] [--precisions fp32,bf16] [--steps 20] [--set KEY=VALUE]

One step is ``training.train.train_step``, the function the trainer itself calls (forward over the step's
rays, the losses, backward, clipping, Adam), with the config ``make model``'s ``cpu`` recipe trains:
``training/train_configs/edge128.json`` (``edge128_baseline.json`` for the baseline) with the human encoder's
trunk at 128x128, the encoder frozen as in the joint run (its weights here are the untrained ones: the
arithmetic is the same). The batches are made before the clock starts, so this times the arithmetic.

``bf16`` wraps the step in ``torch.autocast("cpu", dtype=torch.bfloat16)``. **The trainer has no such
option: it trains in float32.** The row says what bfloat16 would buy in time on this host (AMX or
AVX-512 bf16 kernels), not what it would cost in accuracy, which only a full run can tell.
Prints the median and p90 after the warm-up, and bf16's speed-up. Not a test: the figures depend on the
host.
"""
from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.counts import positive_count, positive_count_list  # noqa: E402
import torch  # noqa: E402

from training.cli.dataset_split import check_dataset_split  # noqa: E402
from training.data.targets import TargetConfig  # noqa: E402
from training.data.torch_dataset import MultiViewDataset  # noqa: E402
from training.model import GHNeRF  # noqa: E402
from training.model.config import ConfigError  # noqa: E402
from training.pipeline import RECIPES  # noqa: E402
from training.train import (TrainConfig, apply_overrides, build_config, load_config_file, make_batch,  # noqa: E402
                            seed_everything, train_step)

WARMUP = 3
CONFIGS = {"ghnerf": "training/train_configs/edge128.json", "baseline": "training/train_configs/edge128_baseline.json"}


def train_config(data: str, variant: str, sets: list[str] = ()) -> TrainConfig:
    """The ``cpu`` recipe's train config of ``variant`` on ``data``, ``sets`` (``KEY=VALUE``) applied after the
    recipe's overrides."""
    root = Path(__file__).resolve().parents[1]
    raw = apply_overrides(load_config_file(root / CONFIGS[variant]),
                          [*RECIPES["cpu"].train_overrides, f'data="{data}"', *sets])
    raw.pop("pretrain_human", None)  # the joint run's encoder comes pretrained; here its weights do not matter
    return build_config(raw)


def time_steps(data: str, variant: str, precision: str, steps: int, sets: list[str] = ()) -> list[float]:
    """Wall seconds of each of ``steps`` joint-run steps (``WARMUP`` more first, not returned); ``sets`` are
    ``KEY=VALUE`` train config overrides after the recipe's."""
    cfg = train_config(data, variant, sets)
    mcfg = cfg.model_config()
    seed_everything(cfg.seed)
    model = GHNeRF(mcfg).train()
    if cfg.freeze_human and model.human is not None:
        model.human.freeze()
    opt = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=cfg.lr)
    ds = MultiViewDataset(cfg.data, cfg.split, TargetConfig(heatmap_stride=mcfg.heatmap_stride))
    gen = torch.Generator().manual_seed(cfg.seed)
    batches = [make_batch(ds[i % len(ds)], cfg, mcfg, gen) for i in range(steps + WARMUP)]
    times = []
    for i, batch in enumerate(batches):
        t0 = time.perf_counter()
        with (torch.autocast("cpu", dtype=torch.bfloat16) if precision == "bf16" else contextlib.nullcontext()):
            train_step(model, model, opt, batch, cfg)
        if i >= WARMUP:
            times.append(time.perf_counter() - t0)
    return times


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="data/edge128")
    ap.add_argument("--variants", default="ghnerf,baseline")
    ap.add_argument("--threads", type=positive_count_list, default="1,2",
                    help="thread counts (the pipeline trains both variants side by side at one thread each on two "
                         "cores)")
    ap.add_argument("--precisions", default="fp32,bf16", help="fp32 (what the trainer runs) and/or bf16 (autocast)")
    ap.add_argument("--steps", type=positive_count, default=20)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="train config override after the recipe's (as ghnerf-train --set)")
    args = ap.parse_args(argv)
    for v in args.variants.split(","):
        if v not in CONFIGS:
            ap.error(f"--variants: unknown {v!r}; variants: {', '.join(CONFIGS)}")
    for p in args.precisions.split(","):
        if p not in ("fp32", "bf16"):
            ap.error(f"--precisions: unknown {p!r}; fp32 or bf16")
    for v in args.variants.split(","):  # the split the steps read, as the --set overrides leave it
        try:
            split = train_config(args.data, v, args.set).split
        except ConfigError as e:  # a --set the trainer refuses, named
            ap.error(f"argument --set: {e}")
        check_dataset_split(ap, args.data, split)
    torch.set_flush_denormal(True)
    print(f"torch {torch.__version__}; bf16 rows are autocast, which the trainer does not run")
    print("| variant | threads | precision | median s/step | p90 s/step | bf16 speed-up |")
    print("|---|---|---|---|---|---|")
    for variant in args.variants.split(","):
        for threads in args.threads:
            torch.set_num_threads(threads)
            medians = {}
            for precision in args.precisions.split(","):
                t = np.array(time_steps(args.data, variant, precision, args.steps, args.set))
                medians[precision] = float(np.median(t))
                ratio = (f"{medians['fp32'] / medians['bf16']:.2f}x" if precision == "bf16" and "fp32" in medians
                         else "")
                print(f"| {variant} | {threads} | {precision} | {medians[precision]:.3f} | "
                      f"{np.percentile(t, 90):.3f} | {ratio} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
