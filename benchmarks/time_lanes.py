"""Step rates of ``make model``'s jobs alone and side by side, and what each lane plan costs on this host.

    .venv/bin/python benchmarks/time_lanes.py --data data/edge128 [--seconds 60] [--rounds 3] [--json out.json]

The jobs are the real commands the pipeline runs (``training.pretrain_human`` at the trunk's 64x64 and
128x128 inputs, ``training.train`` for each variant, ``training.data.generate`` for the prior's extra scenes)
with the ``cpu`` recipe's settings, each stopped after ``--seconds``, plus the skeleton prior's two parts in
this script's own worker processes: collecting the shipped model's flip-tested peaks (``--model-dir``, default
``models/ghnerf``) and training one prior network on inputs of the recipe's size (random values: the
arithmetic is the same). Each measurement runs its jobs at once, as a lane plan would, and reads their rates
from their own logs after the first records (warm-up). The pairs are those of the two plans
(``training.pipeline.side_by_side_plan``):

- **alone first** (``--shared-pretrain-steps 0``): the pretraining at every core; the joint run beside the
  baseline at one thread each; then the prior's extra scenes, collection and networks at every core;
- **shared** (the ``cpu`` recipe): the pretraining's first ``shared_pretrain_steps`` at one thread beside the
  baseline; the extra scenes at every core; the rest of the pretraining at every core; the joint run beside
  the early prior (collection, then the networks one after the other) at one thread each.

The estimate multiplies each lane's steps (the recipe's counts) by its measured rate; where a lane ends before
the other, the phase lasts as long as the longer. The extra scenes' rate is the generator's wall time over its
scenes, start-up included, so it errs high; the others are read after the warm-up. Data, export, quantization,
evaluation and card are the same in both plans and left out. Needs two cores or more; the figures depend on the
host and on what else runs.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from ghnerf_runtime.cli.seconds import positive_seconds  # noqa: E402
from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.output_path import ready_output_arg  # noqa: E402

SKIP_RECORDS = 2
"""Log records left out of a rate (the warm-up and, for the pretraining, its precision probe)."""
WARMUP_STEPS = 50
"""Prior-network steps before the clock starts."""


# ------------------------------------------------------------------------------------------------ workers
def worker_prior(threads: int, steps: int, scenes: int) -> dict:
    """Seconds per step of one prior network (``training.skeleton_prior._train_one``) on ``scenes`` inputs."""
    import torch

    from ghnerf_runtime.body25 import NUM_JOINTS
    from ghnerf_runtime.skeleton_prior import CONTEXT_FEATURES, JOINT_FEATURES
    from training.skeleton_prior import PriorTrainConfig, _train_one

    torch.set_num_threads(threads)
    rng = np.random.default_rng(0)
    features = rng.normal(size=(scenes, NUM_JOINTS, JOINT_FEATURES)).astype(np.float32)
    context = rng.normal(size=(scenes, CONTEXT_FEATURES)).astype(np.float32)
    truth = rng.normal(size=(scenes, NUM_JOINTS, 3)).astype(np.float32)
    valid = np.ones((scenes, NUM_JOINTS), bool)
    _train_one(features, context, truth, valid, PriorTrainConfig(steps=WARMUP_STEPS), 0, False)
    t0 = time.monotonic()
    _train_one(features, context, truth, valid, PriorTrainConfig(steps=steps), 0, False)
    return {"s_per_step": (time.monotonic() - t0) / steps}


def worker_collect(threads: int, scenes: int, model_dir: str, data: str) -> dict:
    """Seconds per scene of the prior's collection (``training.skeleton_prior.collect``, flip test on)."""
    from training.skeleton_prior import collect

    collect(model_dir, data, "train", 8, True, threads, progress=False)  # warm-up
    t0 = time.monotonic()
    collect(model_dir, data, "train", scenes, True, threads, progress=False)
    return {"s_per_scene": (time.monotonic() - t0) / scenes}


# --------------------------------------------------------------------------------------------------- jobs
class Job:
    """One process of a measurement and how its rate is read."""

    def __init__(self, name: str, cmd: list[str], rate, folder: Path):
        self.name, self.cmd, self.rate, self.folder = name, cmd, rate, folder


def log_rate(folder: Path) -> float:
    """Seconds per step from a run's ``log.jsonl`` (``step``, ``time_s``), the first records left out."""
    log = folder / "log.jsonl"
    # a job stopped by --seconds before its first log_every steps writes no log at all (the pretraining logs
    # every 10 steps of seconds each on two cores): the advice of a short log, not a FileNotFoundError
    lines = log.read_text().splitlines() if log.is_file() else []
    records = [json.loads(line) for line in lines if line.strip()]
    records = [r for r in records if "time_s" in r][SKIP_RECORDS:]
    if len(records) < 2:
        raise RuntimeError(f"{folder}: too few log records for a rate ({len(records)}); give more --seconds")
    return (records[-1]["time_s"] - records[0]["time_s"]) / (records[-1]["step"] - records[0]["step"])


class Jobs:
    """The jobs of one host's measurement, in a scratch folder."""

    def __init__(self, data: Path, model_dir: Path, scratch: Path, seconds: float):
        from training.pipeline import PipelineConfig, pretrain_inputs

        self.data, self.model_dir, self.scratch, self.seconds = data, model_dir, scratch, seconds
        self.cfg = PipelineConfig(out=scratch / "models", data=data, runs=scratch / "runs")
        self.cfg.apply_recipe("cpu", cores=2)
        self.pretrain_config = scratch / "pretrain.json"
        self.pretrain_config.write_text(json.dumps({**pretrain_inputs(self.cfg, "ghnerf"), "data": str(data)}))
        self.count = 0

    def _folder(self, name: str) -> Path:
        self.count += 1
        return self.scratch / f"{self.count:02d}_{name}"

    def pretrain(self, scale: str, threads: int) -> Job:
        folder = self._folder(f"pretrain{scale}_{threads}t")
        coarse = "1000000" if scale == "64" else "0"
        cmd = [sys.executable, "-m", "training.pretrain_human", "--config", str(self.pretrain_config), "--out",
               str(folder), "--quiet", "--threads", str(threads), "--iterations", "1000000",
               "--set", f"coarse_steps={coarse}", "--set", "eval_every=0", "--set", "log_every=10",
               "--set", "checkpoint_every=1000000", "--set", f"max_minutes={self.seconds / 60}"]
        return Job(f"pretrain {scale}x{scale}, {threads} thread(s)", cmd, lambda: log_rate(folder), folder)

    def joint(self, variant: str, threads: int) -> Job:
        from training.pipeline import CONFIG_DIR, VARIANTS

        folder = self._folder(f"{variant}_{threads}t")
        cmd = [sys.executable, "-m", "training.train", "--config", str(CONFIG_DIR / f"{VARIANTS[variant]}.json"),
               "--out", str(folder), "--data", str(self.data), "--quiet"]
        for o in [*self.cfg.train_overrides, f"threads={threads}", "log_every=10", "pck_every=0",
                  "checkpoint_every=1000000", "iterations=1000000", f"max_minutes={self.seconds / 60}"]:
            cmd += ["--set", o]
        return Job(f"joint run {variant}, {threads} thread(s)", cmd, lambda: log_rate(folder), folder)

    def extras(self, workers: int, scenes: int) -> Job:
        from training.pipeline import prior_extra_args

        folder = self._folder(f"extras_{workers}w")
        args = prior_extra_args(self.cfg, workers)
        args[args.index("--out") + 1], args[args.index("--train") + 1] = str(folder / "data"), str(scenes)
        cmd = [sys.executable, "-m", "training.data.generate", *args]
        return Job(f"prior's extra scenes, {workers} worker(s)", cmd, lambda: self._timed(folder) / scenes, folder)

    def prior(self, threads: int, steps: int) -> Job:
        folder = self._folder(f"prior_{threads}t")
        cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", "prior", "--threads", str(threads),
               "--steps", str(steps), "--scenes", str(self.cfg.train + self.cfg.prior_extra_train)]
        return Job(f"prior network, {threads} thread(s)", cmd, lambda: self._reported(folder, "s_per_step"), folder)

    def collect(self, threads: int, scenes: int) -> Job:
        folder = self._folder(f"collect_{threads}t")
        cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", "collect", "--threads", str(threads),
               "--scenes", str(scenes), "--model-dir", str(self.model_dir), "--data", str(self.data)]
        return Job(f"prior's collection, {threads} thread(s)", cmd, lambda: self._reported(folder, "s_per_scene"),
                   folder)

    @staticmethod
    def _timed(folder: Path) -> float:
        return json.loads((folder / "wall.json").read_text())["wall_s"]

    @staticmethod
    def _reported(folder: Path, key: str) -> float:
        return json.loads((folder / "stdout.log").read_text().strip().splitlines()[-1])[key]


def measure(jobs: dict[str, Job], limit_s: float) -> dict[str, float]:
    """Run ``jobs`` at once; each one's rate, by its key. A job that fails or runs past ``limit_s`` stops the
    others and raises with its output's tail."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    procs = {}
    for key, job in jobs.items():
        job.folder.mkdir(parents=True, exist_ok=True)
        out = open(job.folder / "stdout.log", "w")
        procs[key] = (out, time.monotonic(), subprocess.Popen(job.cmd, cwd=ROOT, env=env, stdout=out,
                                                              stderr=subprocess.STDOUT))
    try:
        for key, (out, t0, p) in procs.items():
            try:
                code = p.wait(timeout=max(1.0, limit_s - (time.monotonic() - t0)))
            except subprocess.TimeoutExpired:
                code = f"still running after {limit_s:.0f} s"
            out.close()
            (jobs[key].folder / "wall.json").write_text(json.dumps({"wall_s": time.monotonic() - t0}))
            if code != 0:
                tail = (jobs[key].folder / "stdout.log").read_text()[-2000:]
                raise RuntimeError(f"{jobs[key].name}: exit {code}\n{tail}")
    finally:
        for _, _, p in procs.values():
            if p.poll() is None:
                p.kill()
                p.wait()
    return {key: job.rate() for key, job in jobs.items()}


# ------------------------------------------------------------------------------------------------ estimate
def plans(cfg, r: dict[str, float]) -> dict[str, dict[str, float]]:
    """Seconds of each phase of the two plans from the measured rates ``r`` (keys as :func:`main` names them)."""
    from training.pipeline import VARIANTS, pretrain_inputs, train_inputs

    pc = pretrain_inputs(cfg, "ghnerf")  # the recipe's counts
    iters, coarse = pc["iterations"], pc["coarse_steps"]
    fine, shared = iters - coarse, cfg.shared_pretrain_steps
    joint, base = (train_inputs(cfg, VARIANTS[v])["iterations"] for v in ("ghnerf", "baseline"))
    collect_scenes = cfg.train + cfg.prior_extra_train + cfg.val
    members, steps = cfg.prior_members, cfg.prior_steps
    alone = {
        "pretraining, every core": coarse * r["pre64_2"] + fine * r["pre128_2"],
        "joint run beside the baseline": max(joint * r["ghnerf_1_b"], base * r["baseline_1_g"]),
        "prior's extra scenes, every core": cfg.prior_extra_train * r["extras_2"],
        "prior's collection, every core": collect_scenes * r["collect_2"],
        "prior's networks side by side": steps * r["prior_1_1"] * -(-members // 2),
    }
    lane_a = min(shared, coarse) * r["pre64_1_b"] + max(0, shared - coarse) * r["pre128_1_b"]
    # the baseline's steps beside the 64x64 ones at that pair's rate, the rest beside the 128x128 ones
    beside64 = min(base, min(shared, coarse) * r["pre64_1_b"] / r["baseline_1_p"])
    lane_b = beside64 * r["baseline_1_p"] + (base - beside64) * r["baseline_1_p2"]
    collecting = collect_scenes * r["collect_1_g"]
    early = collecting + members * steps * r["prior_1_g"]
    # the joint run goes at its rate beside the collection while that lasts, then beside the networks
    joint_lane = collecting + max(0.0, joint - collecting / r["ghnerf_1_c"]) * r["ghnerf_1_q"]
    shared_plan = {
        "phase 1: pretraining beside the baseline": max(lane_a, lane_b),
        "prior's extra scenes, every core": cfg.prior_extra_train * r["extras_2"],
        "phase 2: the rest of the pretraining, every core": (iters - max(shared, coarse)) * r["pre128_2"]
        + max(0, coarse - shared) * r["pre64_2"],
        "phase 3: joint run beside the early prior": max(joint_lane, early),
    }
    return {"alone first": alone, "shared": shared_plan,
            "lanes": {"phase 1 pretraining lane": lane_a, "phase 1 baseline lane": lane_b,
                      "phase 3 joint run lane": joint_lane, "phase 3 early prior lane": early}}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="data/edge128", help="the make model dataset (its train split)")
    ap.add_argument("--model-dir", default=str(ROOT / "models" / "ghnerf"),
                    type=lambda p: str(Path(model_folder_option(p)).resolve()),
                    help="a model folder for the collection")
    ap.add_argument("--seconds", type=positive_seconds, default=60.0, help="length of each measurement")
    ap.add_argument("--rounds", type=positive_count, default=3,
                    help="times every measurement runs (every other round in reverse order); the rates are the "
                         "medians (a shared host's speed drifts by a fifth over minutes)")
    ap.add_argument("--json", help="also write the rates and estimates here")
    ap.add_argument("--worker", choices=("prior", "collect"), help=argparse.SUPPRESS)
    ap.add_argument("--threads", type=positive_count, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--steps", type=non_negative_count, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--scenes", type=non_negative_count, default=0, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker == "prior":
        print(json.dumps(worker_prior(args.threads, args.steps, args.scenes)))
        return 0
    if args.worker == "collect":
        print(json.dumps(worker_collect(args.threads, args.scenes, args.model_dir, args.data)))
        return 0
    out = ready_output_arg(ap, args.json, "--json") if args.json else None
    data = Path(args.data).resolve()  # (the jobs run in the repository)
    if not (data / "dataset.json").is_file():
        ap.error(f"--data {data}: no dataset.json (make it with `python -m training.pipeline --until data`)")
    if (os.cpu_count() or 1) < 2:
        ap.error("the lanes need two cores or more")
    # rough counts that run about --seconds at the rates of a 2-core host (the rates do not depend on them)
    s = args.seconds
    prior_steps, collect_scenes, extra_scenes = int(s / 0.03), int(s / 0.02), int(s / 0.05)
    with tempfile.TemporaryDirectory(prefix="time_lanes_") as tmp:
        j = Jobs(data, Path(args.model_dir), Path(tmp), s)
        def measurements() -> list[dict[str, Job]]:  # new folders each round
            return [
                {"pre64_2": j.pretrain("64", 2)},
                {"pre128_2": j.pretrain("128", 2)},
                {"ghnerf_1_b": j.joint("ghnerf", 1), "baseline_1_g": j.joint("baseline", 1)},
                {"extras_2": j.extras(2, 2 * extra_scenes)},
                {"collect_2": j.collect(2, 2 * collect_scenes)},
                {"prior_1_1": j.prior(1, prior_steps), "prior_1_1b": j.prior(1, prior_steps)},
                {"pre64_1_b": j.pretrain("64", 1), "baseline_1_p": j.joint("baseline", 1)},
                {"pre128_1_b": j.pretrain("128", 1), "baseline_1_p2": j.joint("baseline", 1)},
                {"ghnerf_1_q": j.joint("ghnerf", 1), "prior_1_g": j.prior(1, int(1.5 * prior_steps))},
                {"ghnerf_1_c": j.joint("ghnerf", 1), "collect_1_g": j.collect(1, collect_scenes)},
            ]

        samples: dict[str, list[float]] = {}
        names: dict[str, str] = {}
        savings = []
        for round_ in range(args.rounds):
            # every other round in reverse order, so a host that speeds up or slows down over the run weighs
            # on both plans' jobs alike
            order = measurements() if round_ % 2 == 0 else measurements()[::-1]
            this: dict[str, float] = {}
            for measurement in order:
                got = measure(measurement, limit_s=5 * s + 300)
                for key, job in measurement.items():
                    this[key], names[key] = got[key], job.name + (
                        f" beside {', '.join(o.name for o in measurement.values() if o is not job)}"
                        if len(measurement) > 1 else ", alone")
                    samples.setdefault(key, []).append(got[key])
                print(f"round {round_ + 1}: " + "; ".join(f"{names[k]}: {this[k]:.4f}" for k in measurement),
                      flush=True)
            e = plans(j.cfg, this)
            savings.append((sum(e["alone first"].values()) - sum(e["shared"].values())) / 60)
            print(f"round {round_ + 1}: shared saves {savings[-1]:.1f} min", flush=True)
        rates = {k: float(np.median(v)) for k, v in samples.items()}
        cfg = j.cfg
    est = plans(cfg, rates)
    print(f"\n| job | s per step, scene or network step (median of {args.rounds} rounds) |\n|---|---|")
    for k, v in rates.items():
        print(f"| {names[k]} | {v:.4f} |")
    for plan in ("alone first", "shared"):
        total = sum(est[plan].values())
        print(f"\n**{plan}**: {total / 60:.1f} min in the stages that differ")
        for phase, sec in est[plan].items():
            print(f"- {phase}: {sec / 60:.1f} min")
    print("\nlanes of the shared plan: " + "; ".join(f"{k} {v / 60:.1f} min" for k, v in est["lanes"].items()))
    a, b = sum(est["alone first"].values()), sum(est["shared"].values())
    print(f"\nshared saves {(a - b) / 60:.1f} min ({1 - b / a:.0%} of those stages) at the median rates; by round "
          + ", ".join(f"{x:.1f}" for x in savings) + " min")
    if out:
        out.write_text(json.dumps({"rates": rates, "samples": samples, "jobs": names, "estimates_s": est,
                                   "savings_by_round_min": savings, "seconds": args.seconds}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
