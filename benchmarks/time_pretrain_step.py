"""Seconds per step of the human encoder's pretraining, by trunk resolution and arithmetic.

    .venv/bin/python benchmarks/time_pretrain_step.py --data data/edge128 \
        [--input-scales 0.5,1.0] [--precisions fp32,bf16] [--scenes-per-step 2,4] [--steps 25] [--threads 2] \
        [--profile 20]

One step is ``training.pretrain_human.pretrain_step``, the function the pretraining itself calls: the
encoder's forward pass (under ``torch.autocast`` for ``bf16``, as ``PretrainConfig.precision`` runs it),
the loss in float32, backward and an Adam update, on that step's batch (``StepBatches``: 2 scenes, every
view and its mirror image, 16 images at 128x128). The batch is made before the clock starts, so this
times the arithmetic, not the loading.
Prints the median and p90 over the steps after the first five (warm-up), the median per scene (what
compares batch sizes), and bf16's speed-up over fp32 at each scale. Not a test: the figures depend on the
host (AVX-512 with bfloat16 kernels or not).
"""
from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.counts import non_negative_count, positive_count, positive_count_list  # noqa: E402
from ghnerf_runtime.cli.numbers import number_list  # noqa: E402
import torch  # noqa: E402

from training.cli.dataset_split import check_dataset_split  # noqa: E402
from training.data.targets import TargetConfig  # noqa: E402
from training.data.torch_dataset import MultiViewDataset  # noqa: E402
from training.model import GHNeRF  # noqa: E402
from training.model.config import ConfigError  # noqa: E402
from training.pretrain_human import (PretrainConfig, StepBatches, cpu_has_native_bf16,  # noqa: E402
                                     fastest_precision, pretrain_step, resolve_precision)
from training.train import seed_everything  # noqa: E402

WARMUP = 5


def pretrain_config(data: str, scale: float, precision: str, steps: int, scenes_per_step: int) -> PretrainConfig:
    """The pretraining config of one setting, checked as the pretraining checks it (the trunk's input scale
    with the model's sizes too): a :class:`ConfigError` names the key."""
    cfg = PretrainConfig.from_dict({"data": data, "iterations": steps + WARMUP, "precision": precision,
                                    "scenes_per_step": scenes_per_step, "model": {"human": {"input_scale": scale}}})
    cfg.model_config().validate()
    return cfg


def time_steps(data: str, scale: float, precision: str, steps: int, scenes_per_step: int = 2,
               profile_rows: int = 0) -> list[float]:
    """Wall seconds of each of ``steps`` pretraining steps (``WARMUP`` more first, not returned). With
    ``profile_rows``, also prints torch.profiler's costliest operators over those steps, by input shape."""
    cfg = pretrain_config(data, scale, precision, steps, scenes_per_step)
    seed_everything(cfg.seed)
    model = GHNeRF(cfg.model_config()).train()
    model.human.to(memory_format=torch.channels_last)
    ds = MultiViewDataset(cfg.data, cfg.split, TargetConfig(heatmap_stride=model.config.heatmap_stride))
    batches = StepBatches(ds, cfg)
    opt = torch.optim.Adam(model.human.parameters(), lr=cfg.lr)
    resolved = resolve_precision(precision, torch.device("cpu"))
    if precision == "auto" and resolved == "bf16":  # what the pretraining does: time both, keep the faster
        resolved = fastest_precision(model, *batches[0], cfg, None)[0]
    times = []
    for step in range(WARMUP):
        pretrain_step(model, opt, *batches[step], cfg, resolved)
    with contextlib.ExitStack() as stack:
        prof = stack.enter_context(torch.profiler.profile(record_shapes=True)) if profile_rows else None
        for step in range(WARMUP, steps + WARMUP):
            images, heat = batches[step]
            t0 = time.perf_counter()
            pretrain_step(model, opt, images, heat, cfg, resolved)
            times.append(time.perf_counter() - t0)
    if prof is not None:
        print(prof.key_averages(group_by_input_shape=True).table(
            sort_by="self_cpu_time_total", row_limit=profile_rows, max_name_column_width=32,
            max_shapes_column_width=70))
    return times


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="data/edge128", help="a dataset folder (default: the one make model makes)")
    ap.add_argument("--input-scales", type=number_list, default="0.5,1.0",
                    help="human.input_scale values (1.0: a 128x128 trunk)")
    ap.add_argument("--precisions", default="fp32,bf16", help="PretrainConfig.precision values")
    ap.add_argument("--steps", type=positive_count, default=25)
    ap.add_argument("--threads", type=positive_count, default=2)
    ap.add_argument("--profile", type=non_negative_count, default=0, metavar="ROWS",
                    help="also print the ROWS costliest operators of each setting (torch.profiler; slows the steps)")
    ap.add_argument("--scenes-per-step", type=positive_count_list, default="2",
                    help="PretrainConfig.scenes_per_step values (the cpu recipe 2, the gpu recipe 4)")
    args = ap.parse_args(argv)
    check_dataset_split(ap, args.data, PretrainConfig.split)
    for option, settings in (("--input-scales", [(scale, "fp32", 2) for scale in args.input_scales]),
                             ("--precisions", [(1.0, p, 2) for p in args.precisions.split(",")]),
                             ("--scenes-per-step", [(1.0, "fp32", n) for n in args.scenes_per_step])):
        for scale, precision, per_step in settings:  # each as the pretraining checks it, before minutes of steps
            try:
                pretrain_config(args.data, scale, precision, args.steps, per_step)
            except ConfigError as e:
                ap.error(f"argument {option}: {e}")
    torch.set_num_threads(args.threads)
    torch.set_flush_denormal(True)
    auto = ("the faster of fp32 and bf16, timed at the start of each pretraining scale" if cpu_has_native_bf16()
            else resolve_precision("auto", torch.device("cpu")))
    print(f"torch {torch.__version__}, {args.threads} threads, bfloat16 in hardware: {cpu_has_native_bf16()} "
          f"(precision auto: {auto})")
    print("| trunk input | scenes per step | precision | median s/step | p90 s/step | median ms/scene | "
          "bf16 speed-up |")
    print("|---|---|---|---|---|---|---|")
    for scale in args.input_scales:
        for per_step in args.scenes_per_step:
            medians = {}
            for precision in args.precisions.split(","):
                t = np.array(time_steps(args.data, scale, precision, args.steps, per_step, args.profile))
                medians[precision] = float(np.median(t))
                ratio = (f"{medians['fp32'] / medians['bf16']:.2f}x" if precision == "bf16" and "fp32" in medians
                         else "")
                side = int(round(128 * scale))
                print(f"| {side}x{side} | {per_step} | {precision} | {medians[precision]:.3f} | "
                      f"{np.percentile(t, 90):.3f} | {1000 * medians[precision] / per_step:.1f} | {ratio} |",
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
