"""``make model`` (``python -m training.pipeline --out models/``): everything from nothing, restartable.

Stages (each skipped when its outputs exist and its stamp's inputs still match; ``--force STAGE`` redoes one):

1. ``data``: the synthetic dataset (``training.data.generate``); reused when ``dataset.json`` matches (each split
   of exactly the requested count: :func:`dataset_matches`).
2. ``pretrain_ghnerf``: when the variant's train config has a ``pretrain_human`` block, the human encoder is
   first pretrained on 2D heatmaps alone (``training.pretrain_human``, into ``runs/<preset>_human``) and the
   joint training starts from it (``human_init``).
3. ``train_ghnerf`` / ``train_baseline``: ``training.train`` with ``training/train_configs/<preset>.json``
   (``--resume``: an interrupted run continues from its last checkpoint).
4. ``export_<variant>``: fp32 ONNX graphs (``training.export``) + a weights-only torch file.
5. ``quantize_<variant>``: static int8 QDQ graphs, calibrated on training-split scenes (real frames and
   cameras), and the int8-vs-fp32 parity on a held-out scene.
   Both write into ``<variant>.staging`` beside the model folder and move their files in only once the parity
   checks pass: a failure leaves the folder as it was and the rejected files in the staging folder
   (``training.export.staging``). When new files move in, a ``model_card.json`` recording other versions of them
   is set aside as ``model_card.stale.json`` (with ``MODEL_CARD.md`` and ``metrics.json``): until the card stage
   writes a new one, no card describes the replaced model with the new files' names.
6. ``prior_ghnerf``: the skeleton prior, trained on the exported int8 encoder's 2D errors over the training
   split (``training.skeleton_prior``; the recipe sets its steps, extra scenes, networks and the share of
   scenes added with the body turned to any angle, ``--prior-set`` overrides them: the ``cpu`` recipe's, about
   27 min on the fast two-core host with its 20000 extra scenes, as ``--recipe``'s help says) into
   ``ghnerf/skeleton_prior.onnx``,
   with its held-out figures (``skeleton_prior.json``). On CPU with the ``cpu`` recipe's lanes it was trained
   already, beside the joint run, from the pretrained encoder (``training.early_prior``): the stage takes
   that prior when it learnt from the same keypoint graphs (sha256) for the same request.
7. ``eval_<variant>``: held-out metrics of ghnerf (torch, onnx fp32, onnx int8; the ONNX rows with the
   folder's skeleton prior) and the baseline (onnx fp32, int8) into ``metrics_<variant>.json``; a new prior
   re-evaluates.
8. ``card``: ``metrics.json``, ``model_card.json`` + ``MODEL_CARD.md`` (metrics, parity, hashes, hardware,
   wall times), once every variant is evaluated; the painter's section (``training.learnt_fill export
   --card-dir``) is kept while its files are unchanged.

Stamps, cards and the JSON files the pipeline writes are replaced whole (a temporary file and ``os.replace``);
a stamp that cannot be read counts as not done. A stamp's inputs hold the output digests of the stages the
stage reads from (the joint run: the pretraining's ``human.pt``; quantize, prior and eval: the dataset's), so a
changed output reruns what reads it; a joint run folder records the ``human.pt`` it started from
(:data:`HUMAN_MARKER`), so a finished run from another encoder is not taken as it is.

``--variants baseline`` takes one variant through its stages now (e.g. while the other still trains).

``--recipe cpu|gpu`` (default ``auto``: ``gpu`` where torch sees one) picks the presets' overrides sized for
the machine (``RECIPES``); ``--set`` / ``--pretrain-set`` come after them and win.

``--quick``: a smoke test (a few scenes, a few iterations, a few eval scenes) into the same layout.

``--status``: run nothing and write nothing; list each stage the same command would run or skip, and why (the
input that changed, named where the stamp records its inputs; an output gone or changed; a stage before it
that runs).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import hashlib
import json
import logging
import os
import shlex
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, NamedTuple

# write_atomic: stamps and requests whole, as half a one would stop every later run
from training.model_card import strict_json, write_atomic
from training.run_lock import lock_holder

log = logging.getLogger("training.pipeline")

REPO = Path(__file__).resolve().parents[1]
CONFIG_DIR = REPO / "training" / "train_configs"
VARIANTS = {"ghnerf": "edge128", "baseline": "edge128_baseline"}
#: Train-config keys that do not change the result (where and how fast it runs); ignored when matching runs.
RUNTIME_KEYS = ("threads", "device", "max_minutes", "log_every", "pck_every", "checkpoint_every")
STAGE_KINDS = ("data", "pretrain", "train", "export", "quantize", "eval", "prior", "card")
"""Stage kinds; pretrain/train/export/quantize/eval run per variant (``train_ghnerf``, ``eval_baseline``, ...)."""
STAGES = ("data", "pretrain_ghnerf", *(f"{k}_{v}" for k in ("train", "export", "quantize") for v in VARIANTS),
          "prior_ghnerf", *(f"eval_{v}" for v in VARIANTS), "card")
#: Variants that get a skeleton prior (it learns from the human encoder's heatmaps).
PRIOR_VARIANTS = ("ghnerf",)
#: ``--prior-set`` keys: the ``PipelineConfig`` field each sets, and its smallest value (a whole number), or for
#: ``tilt_share`` ``"share"`` (a number from 0 to 1) and for ``tilt_mode`` ``"mode"`` (one of
#: ``training.skeleton_prior.TILT_MODES``).
PRIOR_SET_KEYS = {"steps": ("prior_steps", 1), "extra_train": ("prior_extra_train", 0),
                  "members": ("prior_members", 1), "tilt_share": ("prior_tilt_share", "share"),
                  "tilt_mode": ("prior_tilt_mode", "mode")}
#: Pretraining keys that do not change the result; ignored when matching a finished pretraining run.
PRETRAIN_RUNTIME_KEYS = ("threads", "device", "max_minutes", "stop_at", "log_every", "eval_every", "eval_scenes",
                         "checkpoint_every", "loader_workers")
EVAL_RUNTIMES = {"ghnerf": ("torch", "fp32", "int8"), "baseline": ("fp32", "int8")}


@dataclass(frozen=True)
class Recipe:
    """A named training recipe: overrides of the presets sized for one kind of machine."""

    about: str
    train_overrides: tuple[str, ...] = ()
    pretrain_overrides: tuple[str, ...] = ()
    loader_workers: int = 0
    """Pretraining batch-making processes (speed only), at most the machine's cores less four."""
    workers: int = 0
    """Dataset generation processes (speed only; 0: the pipeline's default), at most the machine's cores."""
    prior_steps: int = 15000
    """Skeleton prior training steps (``PipelineConfig.prior_steps``)."""
    prior_extra_train: int = 0
    """Scenes of the skeleton prior's second training set (``PipelineConfig.prior_extra_train``)."""
    prior_members: int = 1
    """Networks averaged in the skeleton prior (``PipelineConfig.prior_members``)."""
    prior_tilt_share: float = 0.0
    """Share of the prior's training scenes added turned to another angle (``PipelineConfig.prior_tilt_share``)."""
    prior_tilt_mode: str = "body"
    """What those copies turn (``PipelineConfig.prior_tilt_mode``)."""
    shared_pretrain_steps: int = 0
    """Pretraining steps at half the cores beside the baseline (``PipelineConfig.shared_pretrain_steps``)."""


#: ``--recipe``. ``cpu`` is sized for two cores (under two hours only on the fastest 2-core host measured, about
#: 2 h 44 min to 3 h on the others: docs/training.md, "`make model` on an AMX Xeon"; since session 40 its lanes
#: share the cores, about 2 h 23 min on the AMX Xeon by estimate: "Lanes that share the cores"): since session 20
#: the encoder's trunk at 128x128, pretrained in bfloat16 where the CPU has it; since session 24 for 44000 steps,
#: the first 17600 with the trunk's input at 64x64 (progressive resizing: about the time of 36000 steps at 128x128
#: on the EPYC by estimate, 3-14 % more on the Intel Xeon over two runs): 39.5 mm held out with a one-network prior
#: (39.7 with a second pretraining seed), against 41.8 for those 36000 steps on the same host, 43.9 for 20000
#: steps and 58.9 for the 64x64 trunk's 24000 float32 steps (docs/training.md, "Progressive resizing in the
#: two-core pretraining", "The same-host baseline" and "A second pretraining seed"); since session 27 a prior of
#: two networks: 38.8 and 39.2 mm over the two seeds, for about 10.5 more minutes on the EPYC, 14.6 on the Intel
#: host (docs/training.md, "Two prior networks in the cpu recipe");
#: ``gpu`` is the shipped (tenth) model's, about 25 minutes on one H100: the same trunk with 27000 float32
#: pretraining steps of 4 scenes and a prior of two networks (docs/training.md, "The tenth model").
RECIPES = {
    "cpu": Recipe("two CPU cores, about 1 h 56 min from nothing on a fast AVX-512 host (by its stages' measured "
                  "times), about 2 h 44 min on session 39's AMX Xeon, about 2 h 45 min on session 35's EPYC and about "
                  "3 h on session 38's Intel Xeon (each timed into its first stages; docs/training.md), before "
                  "session 40's lanes (the baseline beside the pretraining's 64x64 steps, the prior beside the "
                  "joint run and its two networks side by side; benchmarks/time_lanes.py): encoder "
                  "trunk at 128x128, 44000 pretraining "
                  "steps of 2 scenes, "
                  "the first 17600 with the trunk's input at 64x64 (progressive resizing), the rate halved "
                  "every 8800, with the forward pass in bfloat16 where the CPU computes it faster (precision "
                  "auto times both at the start of each scale: 0.11 s per step in bfloat16 against 0.19 in "
                  "float32 on that host, 0.30 against 0.21 on session 38's Intel Xeon, which then runs "
                  "float32, 0.11 against 0.25 on session 39's AMX Xeon); skeleton prior: two networks of "
                  "30000 steps on 25000 scenes (about 27 min on the fast host, about 4.5 of them making its "
                  "20000 extra scenes), a share of 0.3 of its training scenes added with the body turned to "
                  "any angle (--tilt-share 0.3 --tilt-mode body, the shipped prior's)",
                  train_overrides=("model.human.input_scale=1.0",),
                  pretrain_overrides=("iterations=44000", "lr_decay_every=8800", "coarse_steps=17600",
                                      'precision="auto"'),
                  prior_steps=30000, prior_extra_train=20000, prior_members=2, prior_tilt_share=0.3,
                  prior_tilt_mode="body", shared_pretrain_steps=17600),
    "gpu": Recipe("one GPU, ~25 min on an H100: encoder trunk at 128x128, 27000 pretraining steps of 4 scenes; "
                  "skeleton prior: two networks of 30000 steps on 25000 scenes, a share of 0.3 of them added "
                  "with the body turned to any angle (--tilt-share 0.3 --tilt-mode body; ~30 min on two cores "
                  "before the turned copies, where the export runs)",
                  train_overrides=("model.human.input_scale=1.0",),
                  pretrain_overrides=("iterations=27000", "lr_decay_every=4500", "scenes_per_step=4"),
                  loader_workers=12, workers=16, prior_steps=30000, prior_extra_train=20000, prior_members=2,
                  prior_tilt_share=0.3, prior_tilt_mode="body"),
}


def resolve_recipe(name: str) -> str:
    """``auto``: ``gpu`` where torch sees a CUDA device, else ``cpu``."""
    if name != "auto":
        if name not in RECIPES:
            raise ValueError(f"--recipe: unknown {name!r}; recipes: auto, {', '.join(RECIPES)}")
        return name
    import torch

    return "gpu" if torch.cuda.is_available() else "cpu"


@dataclass
class PipelineConfig:
    out: Path
    data: Path = Path("data/edge128")
    runs: Path = Path("runs")
    train: int = 5000
    val: int = 256
    val_seen_motions: int = 128
    freestyle_share: float = 0.5
    """Share of ``train`` scenes moving ``freestyle`` (``SyntheticConfig.freestyle_share``): a half (of 5000)
    is the recipe of the shipped (sixth) model, a third (of 2500) the fifth's; 0 makes the routines-only
    set of the models before it."""
    res: int = 128
    workers: int = 2
    eval_split: str = "val"
    eval_limit: int = 0
    calib_scenes: int = 16
    prior_steps: int = 15000
    """Training steps of the skeleton prior (``training.skeleton_prior``; 15000: ~5 min on two cores)."""
    prior_scenes: int = 0
    """Scenes per split the prior collects (0: all)."""
    prior_extra_train: int = 0
    """Scenes of a second training set the prior also learns from (``<data>_prior_extra``: dataset seed 1, no
    novel views; about 6 min per 20000 scenes on two cores); 0: the model's training split only."""
    prior_members: int = 1
    """Networks averaged in the skeleton prior (``training.skeleton_prior --members``; side by side as far as
    ``threads`` goes, each one after that takes the training time again)."""
    prior_tilt_share: float = 0.0
    """Share (0-1) of the prior's training scenes added again turned to a random angle (``training.skeleton_prior
    --tilt-share``), so it learns bodies lying or upside down; 0: upright bodies only, the priors before session 54."""
    prior_tilt_mode: str = "body"
    """What a turned copy turns (``--tilt-mode``, one of ``training.skeleton_prior.TILT_MODES``): ``body``, the
    shipped prior's, before the same cameras; ``scene``, cameras too. No effect while ``prior_tilt_share`` is 0."""
    quick: bool = False
    accept_stopped: bool = False
    parity_check: bool = True
    """Stop when an exported graph differs from torch, or int8 from fp32, beyond ``training.export.parity``'s
    bounds (the figures go to the card either way)."""
    until: str | None = None
    """Stop after this stage kind (``data``, ``pretrain``, ``train``): train where a GPU is, finish elsewhere."""
    variants: tuple[str, ...] = tuple(VARIANTS)
    threads: int = 2
    parallel_train: bool = True
    """On CPU, train in lanes that share the cores (:func:`side_by_side_plan`): by default the encoder's
    pretraining with every core, then the variants side by side at one thread each (the joint run and the
    baseline take 45-61 min each at one thread, against ~45 min each one after the other at two, 2-core EPYC);
    with ``shared_pretrain_steps`` the baseline beside the pretraining's start and the prior beside the joint
    run."""
    shared_pretrain_steps: int = 0
    """On CPU, when the baseline trains too: the pretraining's first this many steps run at half the cores beside
    the baseline's joint run, the rest with every core, and the prior then trains beside the joint run
    (:func:`side_by_side_plan`; 0: the pretraining alone first, the prior after the joint run). The ``cpu`` recipe
    shares its 17600 steps at 64x64, so ``precision`` ``auto`` times the 128x128 trunk after the resume, at every
    core. The same batches; the thread counts differ, so the rounding does."""
    force: tuple[str, ...] = ()
    train_overrides: list[str] = field(default_factory=list)
    pretrain_overrides: list[str] = field(default_factory=list)
    command: str = ""
    recipe: str = "cpu"
    """The ``RECIPES`` entry whose overrides ``apply_recipe`` put before the command line's."""

    def apply_recipe(self, name: str, cores: int | None = None) -> None:
        """Put recipe ``name``'s overrides before the ``--set`` / ``--pretrain-set`` ones (which win) and
        take its worker counts, capped by ``cores`` (default: this machine's)."""
        r = RECIPES[name]
        cores = cores or os.cpu_count() or 1
        self.recipe = name
        loaders = min(r.loader_workers, max(0, cores - 4))
        self.train_overrides = [*r.train_overrides, *self.train_overrides]
        self.pretrain_overrides = [*r.pretrain_overrides, *([f"loader_workers={loaders}"] if loaders else []),
                                   *self.pretrain_overrides]
        if r.workers:
            self.workers = max(1, min(r.workers, cores))
        self.prior_steps, self.prior_extra_train, self.prior_members = (r.prior_steps, r.prior_extra_train,
                                                                        r.prior_members)
        self.prior_tilt_share, self.prior_tilt_mode = r.prior_tilt_share, r.prior_tilt_mode
        self.shared_pretrain_steps = r.shared_pretrain_steps

    def apply_prior_overrides(self, items: list[str]) -> None:
        """``KEY=VALUE`` overrides of the skeleton prior's recipe (``PRIOR_SET_KEYS``), after the recipe's.

        Raises:
            ValueError: an unknown key, a value that is not a whole number, or one below the key's minimum; a
                ``tilt_share`` that is not a number from 0 to 1, a ``tilt_mode`` that is not one of ``TILT_MODES``.
        """
        from training.skeleton_prior import TILT_MODES

        for item in items:
            key, sep, value = item.partition("=")
            if not sep or key not in PRIOR_SET_KEYS:
                raise ValueError(f"--prior-set {item!r}: expected KEY=VALUE with KEY one of {sorted(PRIOR_SET_KEYS)}")
            field_name, minimum = PRIOR_SET_KEYS[key]
            if minimum == "share":
                try:
                    share = float(value)
                except ValueError:
                    share = float("nan")
                if not 0.0 <= share <= 1.0:  # (nan too) refused here, not after hours of the stages before the prior
                    raise ValueError(f"--prior-set {item!r}: {key} must be a number from 0 to 1, got {value!r}")
                setattr(self, field_name, share)
                continue
            if minimum == "mode":
                if value not in TILT_MODES:
                    raise ValueError(f"--prior-set {item!r}: {key} must be one of {', '.join(TILT_MODES)}, "
                                     f"got {value!r}")
                setattr(self, field_name, value)
                continue
            try:
                number = int(value)
            except ValueError:
                raise ValueError(f"--prior-set {item!r}: {key} must be a whole number, got {value!r}") from None
            if number < minimum:
                raise ValueError(f"--prior-set {item!r}: {key} must be at least {minimum}, got {number}")
            setattr(self, field_name, number)

    @classmethod
    def quick_defaults(cls, out: Path) -> "PipelineConfig":
        return cls(out=out, data=out / "data", runs=out / "runs", train=12, val=4, val_seen_motions=0,
                   eval_limit=2, calib_scenes=2, quick=True, prior_steps=4, prior_scenes=4,
                   prior_extra_train=4, prior_members=2,
                   train_overrides=["iterations=6", "log_every=3", "checkpoint_every=3", "pck_every=3",
                                    "targets_per_iter=2", "heat_rays=64", "patch_size=8", "max_minutes=0"],
                   pretrain_overrides=["iterations=2", "log_every=1", "checkpoint_every=1", "eval_every=0",
                                       "scenes_per_step=1", "max_minutes=0"],
                   shared_pretrain_steps=1)  # the cpu recipe's lanes, in miniature


# ----------------------------------------------------------------------------------------- stamps
def _digest(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


_ABSENT = "<absent>"


def _flat(obj: Any, prefix: str = "") -> dict[str, Any]:
    """A JSON value's leaves by dotted path (list items by index), to name the stamp inputs that changed."""
    if isinstance(obj, dict) and obj:
        return {k: v for key, value in obj.items() for k, v in _flat(value, f"{prefix}{key}.").items()}
    if isinstance(obj, list) and obj:
        return {k: v for i, value in enumerate(obj) for k, v in _flat(value, f"{prefix}{i}.").items()}
    return {prefix[:-1] or "(all)": obj}


def _short(value: Any) -> str:
    text = value if value == _ABSENT else json.dumps(value, default=str)
    return text if len(text) <= 40 else text[:37] + "..."


class Stages:
    """Stamp files ``<out>/.stages/<stage>.json``: the inputs' digest and the inputs (``request``), outputs with
    sha256, wall time."""

    def __init__(self, out: Path, force: tuple[str, ...], create: bool = True):
        self.dir = out / ".stages"
        if create:  # (not for ``--status``, which writes nothing)
            self.dir.mkdir(parents=True, exist_ok=True)
        self.force = {s for f in force for s in STAGES if s == f or s.startswith(f + "_")}
        self._warned: set[Path] = set()

    def stamp(self, name: str) -> dict | None:
        """The stage's stamp; None when it has none, or an unreadable one (the stage runs again)."""
        p = self.dir / f"{name}.json"
        if not p.exists():
            return None
        try:
            s = json.loads(p.read_text())
            if not isinstance(s, dict):
                raise ValueError(f"a JSON {type(s).__name__}, not an object")
        except (OSError, ValueError) as e:  # (stamps made before they were written atomically, or damaged since)
            if p not in self._warned:
                self._warned.add(p)
                log.warning("stage %s: its stamp %s is unreadable (%s); the stage counts as not done", name, p, e)
            return None
        return s

    def done(self, name: str, inputs: Any) -> dict | None:
        """The stamp when the stage is finished for these inputs and its outputs are intact."""
        return None if self.why_not_done(name, inputs) else self.stamp(name)

    def why_not_done(self, name: str, inputs: Any) -> str | None:
        """Why the stage would run for these inputs (None: it is done): forced, no stamp, which inputs changed
        (named where the stamp records them, since session 57), or which output went or changed."""
        from training.model_card import sha256

        if name in self.force:
            return "forced (--force)"
        s = self.stamp(name)
        if not s:
            return "no stamp"
        if s.get("inputs") != _digest(inputs):
            if not isinstance(s.get("request"), (dict, list)):
                return "inputs changed (the stamp predates recorded inputs: the digest alone differs)"
            now = _flat(json.loads(json.dumps(inputs, sort_keys=True, default=str)))
            then = _flat(s["request"])
            keys = sorted(k for k in now.keys() | then.keys() if now.get(k, _ABSENT) != then.get(k, _ABSENT))
            return "inputs changed: " + ", ".join(
                f"{k} ({_short(then.get(k, _ABSENT))} -> {_short(now.get(k, _ABSENT))})" for k in keys[:6]) + (
                f" and {len(keys) - 6} more" if len(keys) > 6 else "")
        for path, digest in s.get("outputs", {}).items():
            if not Path(path).exists():
                return f"output {path} is missing"
            if digest and sha256(path) != digest:
                return f"output {path} changed since the stamp (sha256 {sha256(path)[:12]}, stamped {digest[:12]})"
        return None

    def run(self, name: str, inputs: Any, fn: Callable[[], tuple[list[Path], dict]]) -> dict:
        from training.model_card import sha256

        s = self.done(name, inputs)
        if s is not None:
            log.info("stage %s: up to date (%.0f s when it ran)", name, s.get("wall_s", 0))
            return s
        log.info("stage %s: running", name)
        t0 = time.monotonic()
        outputs, info = fn()
        # the inputs themselves too (small JSON), so --status can name the one that changed
        s = {"inputs": _digest(inputs), "request": json.loads(json.dumps(inputs, sort_keys=True, default=str)),
             "outputs": {str(p): sha256(p) for p in outputs},
             "wall_s": round(time.monotonic() - t0, 1), "info": info,
             "finished": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
        write_atomic(self.dir / f"{name}.json", json.dumps(s, indent=1, default=str))
        self._warned.discard(self.dir / f"{name}.json")
        log.info("stage %s: done in %.0f s", name, s["wall_s"])
        return s


#: Written into each run folder the pipeline starts: the sha256 of the ``dataset.json`` it trains on.
DATA_MARKER = "dataset.sha256"


def _dataset_sha(cfg: PipelineConfig) -> str:
    from training.model_card import sha256

    return sha256(cfg.data / "dataset.json")


def _data_marker_ok(cfg: PipelineConfig, run: Path) -> bool:
    """The run trained on this dataset (runs made before the marker existed are taken on trust)."""
    marker = run / DATA_MARKER
    return not marker.exists() or marker.read_text().strip() == _dataset_sha(cfg)


def _mark_data(cfg: PipelineConfig, run: Path) -> None:
    run.mkdir(parents=True, exist_ok=True)
    write_atomic(run / DATA_MARKER, _dataset_sha(cfg) + "\n")


#: Written into a joint run folder the pipeline starts with a ``human_init``: the sha256 of the ``human.pt`` the
#: run started from. The config names only the path, which a pretraining done again overwrites.
HUMAN_MARKER = "human_init.sha256"


def _human_init_mismatch(run: Path, tc: dict) -> str | None:
    """Why the run in ``run`` did not start from the ``human_init`` file that ``tc`` names now (None: it did, or
    the run has no marker: runs made before it existed are taken on trust, as for the dataset)."""
    from training.model_card import sha256

    marker, init = run / HUMAN_MARKER, tc.get("human_init")
    if not init or not marker.exists():
        return None
    started = marker.read_text().strip()
    now = sha256(init) if Path(init).is_file() else None
    if now == started:
        return None
    return (f"it started from another {init} ({HUMAN_MARKER} {started[:12]}, the file now "
            f"{now[:12] if now else 'missing'})")


def _mark_human_init(run: Path, tc: dict) -> None:
    """Record the ``human_init`` a fresh run starts from; a resumed run keeps its marker (its checkpoint holds
    the weights it started from, whatever the file holds now)."""
    from training.model_card import sha256

    init = tc.get("human_init")
    if not init or not Path(init).is_file() or (run / "last.pt").exists() or (run / "prev.pt").exists():
        return  # (a missing file: the trainer names it)
    run.mkdir(parents=True, exist_ok=True)
    write_atomic(run / HUMAN_MARKER, sha256(init) + "\n")


def _train_cmd(cfg: PipelineConfig, preset: str, run: Path, extra: list[str] = ()) -> list[str]:
    cmd = [sys.executable, "-m", "training.train", "--config", str(CONFIG_DIR / f"{preset}.json"),
           "--out", str(run), "--resume", "--data", str(cfg.data)]
    tc = train_inputs(cfg, preset)
    human_init, block = tc.get("human_init"), _joint_pretrain_overrides(cfg) if tc.get("pretrain_human") else []
    for o in [*cfg.train_overrides, *block, *([f"human_init={json.dumps(human_init)}"] if human_init else []), *extra]:
        cmd += ["--set", o]
    return cmd


def _pretrain_cmd(cfg: PipelineConfig, variant: str, extra: list[str] = ()) -> list[str]:
    """The pretraining command; its config (the train config's block, every override applied) is written
    to ``<run>/requested.json`` first."""
    run = pretrain_dir(cfg, variant)
    run.mkdir(parents=True, exist_ok=True)
    write_atomic(run / "requested.json", json.dumps(pretrain_inputs(cfg, variant), indent=1))
    cmd = [sys.executable, "-m", "training.pretrain_human", "--config", str(run / "requested.json"),
           "--out", str(run), "--resume", "--quiet"]
    for o in extra:
        cmd += ["--set", o]
    return cmd


class LaneStep(NamedTuple):
    """One command of a lane and its log; ``run_folder``: it trains in the log's folder, which is marked with the
    dataset's hash first (:func:`_mark_data`); ``optional``: a failure is reported and the lane goes on (what the
    step saves time on is done by a later stage anyway); ``train_config``: a joint run's config, whose
    ``human_init`` is marked when the step starts (:func:`_mark_human_init`: the pretraining may run in an
    earlier phase)."""

    cmd: list[str]
    log: Path
    run_folder: bool = True
    optional: bool = False
    train_config: dict | None = None


def side_by_side_plan(cfg: PipelineConfig, variants: list[str], cores: int,
                      data: Any = None) -> list[list[list[LaneStep]]]:
    """Phases of lanes of steps: the lanes of a phase run at once, the phases in order, never with more threads
    in all than ``cores``.

    By default the pretraining comes first with every core (the long pole), then the joint runs side by side
    at ``cores // n`` threads each. Two things in ``make model`` need no pretrained encoder (the baseline's joint
    run, the prior's extra scenes) and one needs only that encoder (the skeleton prior: the joint run keeps it
    frozen), and a second thread buys little on several of them (docs/training.md, "Lanes"). So with
    ``cfg.shared_pretrain_steps`` (the ``cpu`` recipe), on two cores or more, when the baseline trains too:

    1. the pretraining's first ``shared_pretrain_steps`` (``stop_at``) at half the cores, beside the baseline's
       joint run (the ``cpu`` recipe shares the 64x64 steps, whose second thread buys the least); then the
       prior's extra scenes with every core;
    2. the rest of the pretraining with every core (``--resume``: the same batches);
    3. the joint run at half the cores beside the skeleton prior learnt from the pretrained encoder
       (:mod:`training.early_prior`, which the prior stage then takes), when ``data`` (the dataset's stamp) is
       given, the pipeline goes on to the prior (no ``--until``) and the run keeps its encoder frozen; else
       the joint run alone with every core. (Also when only the joint run is left to train, as after a stop.)
    """
    half = max(1, cores // 2)
    pre = [v for v in variants if pretrain_block(cfg, v) and not _pretrain_finished(cfg, v)]
    free = [v for v in variants if not pretrain_block(cfg, v)]
    wants_prior = cfg.until is None and any(v in PRIOR_VARIANTS for v in variants)

    def extras(workers: int) -> list[LaneStep]:
        if not (wants_prior and cfg.prior_extra_train):
            return []
        return [LaneStep([sys.executable, "-m", "training.data.generate", *prior_extra_args(cfg, workers)],
                         cfg.runs / "prior_extra.log", run_folder=False)]

    def joint(v: str, threads: int) -> LaneStep:
        run = cfg.runs / VARIANTS[v]
        return LaneStep(_train_cmd(cfg, VARIANTS[v], run, [f"threads={threads}"]), run / "train.log",
                        train_config=train_inputs(cfg, VARIANTS[v]))

    def pretrain(v: str, extra: list[str]) -> LaneStep:
        return LaneStep(_pretrain_cmd(cfg, v, extra), pretrain_dir(cfg, v) / "train.log")

    phases: list[list[list[LaneStep]]] = []
    steps = cfg.shared_pretrain_steps
    if pre and free and cores >= 2 and steps and all(steps < pretrain_inputs(cfg, v)["iterations"] for v in pre):
        if all(_pretrain_progress(cfg, v) < steps for v in pre):
            threads = max(1, cores // (len(pre) + 1))
            phases.append([[pretrain(v, [f"threads={threads}", f"stop_at={steps}"])] for v in pre]
                          + [[joint(v, threads) for v in free]])
        else:  # resumed with the pretraining's shared part done: what was beside it finishes with every core
            phases.append([[joint(v, cores) for v in free]])
        # the extra scenes with every core: the generator at one worker beside the pretraining makes a scene in
        # 0.053 s, against 0.016-0.019 s at two alone (benchmarks/time_lanes.py at 66cf209), too dear a lane
        if made := extras(cores):
            phases.append([made])
        variants, later_extras = [v for v in variants if v not in free], []
    else:
        later_extras = extras(half)
    phases += [[[pretrain(v, [f"threads={cores}"])]] for v in pre]
    # the early prior at the threads the prior stage would give each network (the same weights): see _early_prior_step
    early = _early_prior_step(cfg, variants, min(half, cfg.threads), data) if wants_prior and cores >= 2 else None
    if early is not None:
        phases.append([[joint(variants[0], half)], [*later_extras, early]])
    elif variants:
        phases.append([[joint(v, max(1, cores // len(variants)))] for v in variants])
    return phases


def _pretrain_progress(cfg: PipelineConfig, variant: str) -> int:
    """The last step the pretraining run logged (0 when none): where a resumed run starts, or a little past it."""
    log_file = pretrain_dir(cfg, variant) / "log.jsonl"
    lines = log_file.read_text().splitlines() if log_file.is_file() else []
    for line in reversed(lines):
        try:
            return int(json.loads(line)["step"])
        except (ValueError, KeyError, TypeError):
            continue  # a line cut short by a stop
    return 0


def early_prior_current(folder: Path, request: dict, human: Path) -> bool:
    """The early prior in ``folder`` learnt from this ``human.pt`` for this request (keypoint graphs aside, which
    follow from the encoder: its export is the same graph, the weights id aside) and is intact. The pipeline asks before it
    plans the lane, :mod:`training.early_prior` before it exports."""
    from training.early_prior import REQUEST_FILE
    from training.model_card import sha256

    try:
        record = json.loads((folder / REQUEST_FILE).read_text())
        return (record["human_sha256"] == sha256(human) and sha256(record["prior"]) == record["prior_sha256"]
                and _digest({**record["request"], "keypoints": {}}) == _digest(request))
    except (OSError, ValueError, KeyError, TypeError):
        return False


def _early_prior_step(cfg: PipelineConfig, variants: list[str], threads: int, data: Any) -> LaneStep | None:
    """The :mod:`training.early_prior` step for the one variant left to train, with its job file written; None
    when it does not apply (no dataset stamp, other variants, no pretraining, an encoder that trains on) or its
    prior is already done for the finished pretraining.

    ``threads``: the plan gives it ``min(half the cores, cfg.threads)``, so each of its networks trains at the
    thread count the prior stage would give it (``skeleton_prior.member_lanes``), as the adoption assumes."""
    from training.early_prior import JOB_FILE
    from training.skeleton_prior import FILE_NAME, member_lanes

    if data is None or not cfg.shared_pretrain_steps or len(variants) != 1 or variants[0] not in PRIOR_VARIANTS:
        return None
    v = variants[0]
    tc = train_inputs(cfg, VARIANTS[v])
    if not (pretrain_block(cfg, v) and tc.get("freeze_human") and tc.get("human_init")):
        return None
    if member_lanes(cfg.prior_members, threads)[1] != member_lanes(cfg.prior_members, cfg.threads)[1]:
        return None  # (one network at two threads, say: the lane cannot train what the stage would)
    folder = early_prior_dir(cfg, v)
    request = early_prior_request(cfg, {}, data, threads)
    if _pretrain_finished(cfg, v) and early_prior_current(folder, request, Path(tc["human_init"])):
        log.info("early prior: %s is up to date for this encoder; the joint run gets every core", folder)
        return None
    folder.mkdir(parents=True, exist_ok=True)
    job = {"train_config": tc, "data": str(cfg.data), "calib_scenes": cfg.calib_scenes, "threads": threads,
           "prior_argv": prior_argv(cfg, folder, folder / FILE_NAME, threads), "request": request}
    write_atomic(folder / JOB_FILE, json.dumps(job, indent=1, default=str) + "\n")
    return LaneStep([sys.executable, "-m", "training.early_prior", str(folder / JOB_FILE)],
                    folder / "early_prior.log", run_folder=False, optional=True)


def train_side_by_side(cfg: PipelineConfig, variants: list[str], data: Any = None) -> None:
    """Run the trainings of ``variants`` by :func:`side_by_side_plan` (CPU only)."""
    from concurrent.futures import ThreadPoolExecutor

    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    for v in variants:
        if pretrain_block(cfg, v) and not _pretrain_finished(cfg, v):
            _check_pretrain_folder(cfg, v)
        _check_run_folder(cfg, v)

    def lane(steps: list[LaneStep]) -> Path | None:
        """None when every step succeeded, else the failed step's log."""
        for step in steps:
            step.log.parent.mkdir(parents=True, exist_ok=True)
            if step.run_folder:
                _mark_data(cfg, step.log.parent)
            if step.train_config is not None:
                _mark_human_init(step.log.parent, step.train_config)
            log.info("$ %s &", shlex.join(step.cmd))
            with open(step.log, "a") as fh:
                if subprocess.run(step.cmd, cwd=REPO, env=env, stdout=fh, stderr=subprocess.STDOUT).returncode != 0:
                    if not step.optional:
                        log.error("%s failed (see %s); the other lanes of this phase finish first, their work kept "
                                  "for the next run", step.cmd[2], step.log)
                        return step.log
                    log.warning("%s failed (see %s); its stage will do that work later", step.cmd[2], step.log)
        return None

    for phase in side_by_side_plan(cfg, variants, os.cpu_count() or 1, data):
        with ThreadPoolExecutor(len(phase)) as pool:
            failed = [str(p) for p in pool.map(lane, phase) if p is not None]
        if failed:
            raise RuntimeError(f"training failed; see {', '.join(failed)}")


def _sh(cmd: list[str], log_path: Path | None = None) -> None:
    log.info("$ %s", shlex.join(cmd))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    if log_path is None:
        subprocess.run(cmd, check=True, cwd=REPO, env=env)
        return
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with open(log_path, "a") as fh:
        subprocess.run(cmd, check=True, cwd=REPO, env=env, stdout=fh, stderr=subprocess.STDOUT)


# ------------------------------------------------------------------------------------------ stages
def dataset_matches(cfg: PipelineConfig) -> bool:
    """``dataset.json`` has the resolution, the generator settings ``stage_data`` asks for, and the requested,
    complete splits, each of exactly the requested count.

    Not "at least": the trainer, the pretraining, the calibration and the evaluation read every scene of a split
    that ``dataset.json`` counts, so a folder generated with more would be trained on with more than the stamp
    and the model card say. ``stage_data`` then asks ``generate`` for the requested count, which shrinks the
    manifest's count without rendering or deleting anything (the shards past it stay for a later larger count)."""
    from training.data.cache import ShardedSplit
    from training.data.splits import split_spec

    meta = cfg.data / "dataset.json"
    if not meta.exists():
        return False
    d = json.loads(meta.read_text())
    if d.get("resolution") != cfg.res:
        return False
    from training.data.cache import generator_version
    from training.data.generate import GENERATOR_VERSION

    if generator_version(d) != GENERATOR_VERSION:
        return False  # rendered by another generator: generate names the difference
    from training.data.generate import source_config
    from training.data.synthetic import SyntheticConfig

    # stage_data asks generate for its defaults (views, supersampling, cold starts, ROI margins, dataset seed 0):
    # a folder made by hand with other ones must not be trained on silently; generate names the differing key
    want_source = source_config(SyntheticConfig(resolution=cfg.res, freestyle_share=cfg.freestyle_share), 0)
    if d.get("source") != "synthetic" or d.get("source_config") != want_source:
        return False
    want = {"train": cfg.train, "val": cfg.val, "val_seen_motions": cfg.val_seen_motions}
    splits = d.get("splits", {})
    for name, n in want.items():
        if n and splits.get(name, {}).get("count", 0) != n:  # more is refused too: readers read every scene
            return False
        if n and splits[name].get("spec") != split_spec(name, cfg.freestyle_share).to_json():
            return False  # made by another recipe; generate names the difference
        if n:
            try:
                if len(ShardedSplit(cfg.data, name)) < n:
                    return False
            except Exception:  # noqa: BLE001 - an unreadable split means regenerate (generate resumes)
                return False
    return True




def _set_aside_forced(cfg: PipelineConfig, forced: set[str]) -> None:
    """``--force`` of a stage that reuses what it finds (the dataset, a finished run) and that this invocation
    will run: move that aside (``<name>.replaced-<time>``, nothing deleted), so the stage makes it again."""
    folders = {"data": cfg.data}
    if cfg.until != "data":
        folders.update({f"pretrain_{v}": pretrain_dir(cfg, v) for v in cfg.variants if pretrain_block(cfg, v)})
    if cfg.until not in ("data", "pretrain"):
        folders.update({f"train_{v}": cfg.runs / VARIANTS[v] for v in cfg.variants})
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    for stage, folder in folders.items():
        if stage not in forced or not folder.exists():
            continue
        # The trainer and the pretraining hold train.pid while they run and remove it on the way out (Ctrl-C);
        # after a kill it names a dead process. A fresh log.jsonl without summary.json also counted as in use,
        # so --force right after a Ctrl-C was refused for three minutes.
        if (pid := lock_holder(folder / "train.pid")) is not None:
            raise RuntimeError(f"--force {stage}: {folder} is in use by a training run (process {pid} holds its "
                               "train.pid); wait for it or stop it first")
        aside = folder.with_name(f"{folder.name}.replaced-{stamp}")
        n = 1
        while aside.exists():
            aside, n = folder.with_name(f"{folder.name}.replaced-{stamp}-{n}"), n + 1
        folder.rename(aside)
        log.info("--force %s: moved %s aside to %s", stage, folder, aside)


def data_request(cfg: PipelineConfig) -> dict:
    """The data stage's stamp input. Keys join only when they leave their old value, so the stamps of datasets
    made before them keep matching: ``freestyle`` when not 0, ``generator`` when not version 1."""
    from training.data.generate import GENERATOR_VERSION

    return {"data": str(cfg.data), "res": cfg.res, "train": cfg.train, "val": cfg.val, "vsm": cfg.val_seen_motions,
            **({"freestyle": cfg.freestyle_share} if cfg.freestyle_share else {}),
            **({"generator": GENERATOR_VERSION} if GENERATOR_VERSION != 1 else {})}


def stage_data(cfg: PipelineConfig) -> tuple[list[Path], dict]:
    if not dataset_matches(cfg):
        _sh([sys.executable, "-m", "training.data.generate", "--out", str(cfg.data), "--train", str(cfg.train),
             "--val", str(cfg.val), "--val-seen-motions", str(cfg.val_seen_motions), "--res", str(cfg.res),
             "--workers", str(cfg.workers), "--freestyle-share", str(cfg.freestyle_share)])
        if not dataset_matches(cfg):
            raise RuntimeError(f"{cfg.data}: the generated dataset does not match the request")
    return [cfg.data / "dataset.json"], json.loads((cfg.data / "dataset.json").read_text()).get("splits", {})


def train_inputs(cfg: PipelineConfig, preset: str) -> dict:
    """The train config a run of ``preset`` gets (as its ``config.json`` holds it); with a ``pretrain_human``
    block, ``human_init`` names the pretraining run's ``human.pt``."""
    from training.train import apply_overrides, build_config, load_config_file

    data = apply_overrides(load_config_file(CONFIG_DIR / f"{preset}.json"),
                           [f"data={json.dumps(str(cfg.data))}", *cfg.train_overrides])
    if data.get("pretrain_human"):  # the block as the pretraining ran it: a changed one is another joint run
        data = apply_overrides(data, _joint_pretrain_overrides(cfg))
    if data.get("pretrain_human") and not data.get("human_init"):
        data["human_init"] = str(cfg.runs / f"{preset}_human" / "human.pt")
    tc = build_config(data)
    return json.loads(json.dumps(asdict(tc)))  # as config.json holds it (lists, not tuples)


def _joint_pretrain_overrides(cfg: PipelineConfig) -> list[str]:
    """``--pretrain-set`` overrides as train-config overrides of the ``pretrain_human`` block (runtime keys
    such as threads aside), so the joint run's ``config.json`` records the pretraining it started from."""
    return [f"pretrain_human.{o.strip()}" for o in cfg.pretrain_overrides
            if o.split("=", 1)[0].strip().split(".")[0] not in PRETRAIN_RUNTIME_KEYS]


def pretrain_block(cfg: PipelineConfig, variant: str) -> dict:
    """The variant's ``pretrain_human`` block, overrides applied ({} when it has none)."""
    return train_inputs(cfg, VARIANTS[variant]).get("pretrain_human") or {}


def pretrain_dir(cfg: PipelineConfig, variant: str) -> Path:
    return cfg.runs / f"{VARIANTS[variant]}_human"


def pretrain_inputs(cfg: PipelineConfig, variant: str) -> dict:
    """The ``PretrainConfig`` the pretraining run of ``variant`` gets (as its ``config.json`` holds it)."""
    from training.pretrain_human import config_from_train_config

    pc = config_from_train_config(train_inputs(cfg, VARIANTS[variant]), cfg.pretrain_overrides)
    return json.loads(json.dumps(asdict(pc)))


def pretrain_scene_problem(cfg: PipelineConfig, pretrain: Mapping) -> str | None:
    """Why the pretraining ``pretrain`` (:func:`pretrain_inputs`) cannot run on the train split ``cfg`` makes
    (None: it can): each step reads ``scenes_per_step`` scenes of it. ``--train 3`` under the cpu recipe's 4 was
    refused by the pretrain stage, after the data stage. A pretraining on another dataset (``--pretrain-set
    data=...``) or split is not the data stage's: its own stage checks it."""
    if pretrain.get("split") != "train" or Path(pretrain.get("data", "")) != Path(cfg.data) \
            or cfg.train >= pretrain["scenes_per_step"]:
        return None
    return (f"--train {cfg.train}: fewer scenes than the pretraining's scenes_per_step {pretrain['scenes_per_step']} "
            "(each of its steps reads that many train scenes); give more, or --pretrain-set scenes_per_step=N")


def _pretrain_config_matches(cfg: PipelineConfig, variant: str) -> bool:
    """The pretraining folder's ``config.json`` has this pipeline's settings (runtime keys aside)."""
    from training.pretrain_human import PretrainConfig

    def result(c: dict) -> dict:
        # through PretrainConfig: a run made before a setting existed reads it as its default
        full = json.loads(json.dumps(asdict(PretrainConfig.from_dict(c))))
        return {k: v for k, v in full.items() if k not in PRETRAIN_RUNTIME_KEYS}

    cfg_p = pretrain_dir(cfg, variant) / "config.json"
    return cfg_p.exists() and result(json.loads(cfg_p.read_text())) == result(pretrain_inputs(cfg, variant))


def _pretrain_finished(cfg: PipelineConfig, variant: str) -> bool:
    run = pretrain_dir(cfg, variant)
    if not ((run / "summary.json").exists() and (run / "human.pt").exists()
            and _pretrain_config_matches(cfg, variant) and _data_marker_ok(cfg, run)):
        return False
    steps = json.loads((run / "summary.json").read_text()).get("steps", 0)
    return steps >= pretrain_inputs(cfg, variant)["iterations"]


def _check_pretrain_folder(cfg: PipelineConfig, variant: str) -> None:
    """Refuse to resume a pretraining run of another config or on another dataset (``--resume`` would
    carry on from its checkpoint)."""
    run = pretrain_dir(cfg, variant)
    if (pid := lock_holder(run / "train.pid")) is not None:  # (the pretraining holds it as the trainer does)
        raise RuntimeError(f"{run}: a pretraining run is in progress (process {pid} holds its train.pid); wait for "
                           "it or stop it")
    held = (run / "last.pt").exists() or (run / "prev.pt").exists()  # prev.pt alone: resumed from it
    if held and (run / "config.json").exists() and not _pretrain_config_matches(cfg, variant):
        raise RuntimeError(f"{run} holds a pretraining run with another config; move it away or pass --runs")
    if held and not _data_marker_ok(cfg, run):
        raise RuntimeError(f"{run} holds a pretraining run on another dataset ({DATA_MARKER} differs from "
                           f"{cfg.data}/dataset.json); move it away or pass --runs")
    if joint := _joint_run_before(cfg, variant):
        raise RuntimeError(f"{joint} holds a joint run started from an earlier pretraining: the pretraining about "
                           f"to run replaces its human.pt; --force train_{variant} sets that run aside, or move it "
                           "away or pass --runs")


def _joint_run_before(cfg: PipelineConfig, variant: str) -> Path | None:
    """The variant's joint run folder when it holds a checkpoint while its pretraining is yet to finish: that run
    started from an earlier encoder (the joint run starts only from a finished one). Refused before the
    pretraining, since runs made before :data:`HUMAN_MARKER` carry no record of which encoder they began from."""
    joint = cfg.runs / VARIANTS[variant]
    return joint if (joint / "last.pt").exists() or (joint / "prev.pt").exists() else None


def stage_pretrain(cfg: PipelineConfig, variant: str) -> tuple[list[Path], dict]:
    run = pretrain_dir(cfg, variant)
    if not _pretrain_finished(cfg, variant):
        _check_pretrain_folder(cfg, variant)
        _mark_data(cfg, run)
        _sh(_pretrain_cmd(cfg, variant), run / "train.log")
    return [run / "human.pt"], {"summary": json.loads((run / "summary.json").read_text()),
                                "config": json.loads((run / "config.json").read_text())}


def _result_keys(tc: dict) -> dict:
    """The parts of a train config that shape the trained weights. A baseline has no human encoder, so its
    ``model.human`` overrides are dropped: a recipe that changes only the encoder reuses the baseline run."""
    out = {k: v for k, v in tc.items() if k not in RUNTIME_KEYS}
    if "human" in (out.get("model") or {}) and not _uses_human_encoder(tc):
        out["model"] = {k: v for k, v in out["model"].items() if k != "human"}
    return out


def _uses_human_encoder(tc: dict) -> bool:
    from training.train import build_config

    return bool(build_config(json.loads(json.dumps(tc))).model_config().use_human_encoder)


def _run_config(path: Path) -> dict:
    """A run's ``config.json`` through ``TrainConfig``: keys added since the run read as their defaults."""
    from dataclasses import asdict

    from training.train import build_config

    return json.loads(json.dumps(asdict(build_config(json.loads(path.read_text())))))


def _model_key(model_config: dict) -> dict:
    """The parts of a model config that shape the trained weights (a baseline's unused human encoder aside)."""
    out = json.loads(json.dumps(model_config))
    if not out.get("use_human_encoder", True):
        out.pop("human", None)
    return out


def expected_model(cfg: PipelineConfig, variant: str) -> dict:
    """The model config a run of ``variant`` trains: the preset with the train config's overrides."""
    from training.train import build_config

    return _model_key(build_config(train_inputs(cfg, VARIANTS[variant])).model_config().to_dict())


def _run_model(run: Path) -> dict | None:
    """The model config a run folder's last checkpoint was trained with (None: no checkpoint)."""
    last = run / "last.pt"
    if not last.exists():
        return None
    from training.model import ModelConfig
    from training.train import load_checkpoint

    ck = load_checkpoint(last)  # a damaged file: an error naming it
    # Through the dataclass: keys added since the run was saved read as their defaults.
    return _model_key(ModelConfig.from_dict(ck.get("model_config", {})).to_dict())


def _run_finished(cfg: PipelineConfig, variant: str) -> bool:
    """``runs/<preset>`` holds a finished run (all steps, or a capped one with ``accept_stopped``) of this config."""
    run = cfg.runs / VARIANTS[variant]
    cfg_p, summary_p = run / "config.json", run / "summary.json"
    if not (cfg_p.exists() and summary_p.exists()):
        return False
    tc = train_inputs(cfg, VARIANTS[variant])
    if _result_keys(_run_config(cfg_p)) != _result_keys(tc):
        return False
    if _run_model(run) != expected_model(cfg, variant):  # the preset changed since (architecture)
        return False
    if not _data_marker_ok(cfg, run):
        return False
    if _human_init_mismatch(run, tc):  # a pretraining done again since: the run learnt from the old encoder
        return False
    sm = json.loads(summary_p.read_text())
    return sm.get("steps", 0) >= tc["iterations"] or bool(cfg.accept_stopped and sm.get("stopped_early"))


def _check_run_folder(cfg: PipelineConfig, variant: str) -> None:
    """Refuse to (re)start a run over one in progress or one of another config."""
    run = cfg.runs / VARIANTS[variant]
    cfg_p = run / "config.json"
    # The trainer holds train.pid while it runs and removes it on the way out (Ctrl-C too); after a kill -9 it
    # names a dead process. A fresh log.jsonl alone used to count as a run in progress, so running the command
    # again just after a Ctrl-C was refused for three minutes.
    if (pid := lock_holder(run / "train.pid")) is not None:
        raise RuntimeError(f"{run}: a training run is in progress (process {pid} holds its train.pid); wait for it "
                           "or stop it")
    tc = train_inputs(cfg, VARIANTS[variant])
    if (run / "last.pt").exists() and cfg_p.exists() and \
            _result_keys(_run_config(cfg_p)) != _result_keys(tc):
        raise RuntimeError(f"{run} holds a run with another config; move it away or pass --runs")
    if (run / "last.pt").exists() and _run_model(run) != expected_model(cfg, variant):
        raise RuntimeError(f"{run} holds a run of another model config (the preset changed since); "
                           "move it away or pass --runs")
    if (run / "last.pt").exists() and not _data_marker_ok(cfg, run):
        raise RuntimeError(f"{run} holds a run on another dataset ({DATA_MARKER} differs from "
                           f"{cfg.data}/dataset.json); move it away or pass --runs")
    if ((run / "last.pt").exists() or (run / "prev.pt").exists()) and (why := _human_init_mismatch(run, tc)):
        raise RuntimeError(f"{run} holds a run of another pretraining: {why}; --force train_{variant} sets it "
                           "aside, or move it away or pass --runs")


def stage_train(cfg: PipelineConfig, variant: str) -> tuple[list[Path], dict]:
    preset = VARIANTS[variant]
    run = cfg.runs / preset
    summary_p = run / "summary.json"
    cfg_p = run / "config.json"
    # A finished run with the same config (e.g. started by hand) is reused as is.
    if not _run_finished(cfg, variant):
        _check_run_folder(cfg, variant)
        _mark_data(cfg, run)
        _mark_human_init(run, train_inputs(cfg, preset))
        _sh(_train_cmd(cfg, preset, run), run / "train.log")
    summary = json.loads(summary_p.read_text())
    if summary.get("stopped_early"):
        if not cfg.accept_stopped:  # no stamp: the next run of the pipeline resumes it
            raise RuntimeError(f"{run} stopped at its max_minutes cap after {summary.get('steps')} of "
                               f"{summary.get('iterations', '?')} steps: run the same command again to resume it, "
                               "or pass --accept-stopped to use it as it is")
        log.warning("%s stopped early at step %s (max_minutes); used as it is (--accept-stopped)", preset,
                    summary.get("steps"))
    return [run / "last.pt"], {"summary": summary, "config": json.loads(cfg_p.read_text())}


def _scene_inputs(model, item: dict, ray_stride: int, targets=None, points_per_target: int = 256, seed: int = 0):
    """``ExampleInputs`` of one dataset scene (real images and cameras) for every graph."""
    import torch

    from ghnerf_runtime.contract import ray_grid
    from training.export.export import ExampleInputs

    t = torch.arange(len(item["tgt_is_source"])) if targets is None else torch.as_tensor(targets)
    cfg = model.config
    uv = torch.from_numpy(ray_grid(cfg.height, cfg.width, ray_stride))
    d = {"images": item["images"], "src_P": item["src_P"], "src_centers": item["src_centers"],
         "tgt_K_inv": item["tgt_K_inv"][t], "tgt_c2w": item["tgt_c2w"][t], "tgt_P": item["tgt_P"][t],
         "near_far": item["near_far"][t], "ray_uv": uv.unsqueeze(0).expand(len(t), -1, -1).contiguous()}
    g = torch.Generator().manual_seed(seed)
    lo, hi = item["bbox"][0] - 0.1, item["bbox"][1] + 0.1
    d["points"] = lo + (hi - lo) * torch.rand(len(t), points_per_target, 3, generator=g)
    with torch.no_grad():
        enc = model.encode(d["images"])
        d.update(enc)
        last = model.volumes(enc, d["src_P"], d["tgt_K_inv"], d["tgt_c2w"], d["near_far"])[-1]
        d["volume"], d["depth_stats"] = last["volume"], last["stats"]
    return ExampleInputs(d)


def calibration_items(dataset, scenes: int) -> list[tuple[int, dict]]:
    """``(index, scene)`` of the int8 calibration: ``scenes`` evenly spaced over the training split (the quantize
    stage's, and ``training.early_prior``'s for the same keypoint graph). A split of fewer scenes than asked
    gives all of its scenes, with a warning naming both counts: indexing past its end was an IndexError
    traceback at the quantize stage, after the training (``--train 8`` with the 16 ``calib_scenes``)."""
    if len(dataset) < scenes:
        log.warning("int8 calibration: %s holds %d scene(s), fewer than the %d asked (calib_scenes): "
                    "calibrating on all %d", _split_name(dataset), len(dataset), scenes, len(dataset))
        scenes = len(dataset)
    step = max(1, len(dataset) // scenes) if scenes else 1
    return [(i, dataset[i]) for i in range(0, step * scenes, step)[:scenes]]


def _split_name(dataset) -> str:
    """``<root>/<split>`` of a ``MultiViewDataset`` (its ``ShardedSplit``) for messages."""
    shards = getattr(dataset, "split", None)
    root, split = getattr(shards, "root", None), getattr(shards, "split", None)
    return f"{root}/{split}" if root is not None and split is not None else "the calibration split"


#: The quantize stage's calibration inputs (``training.early_prior`` calibrates its keypoint graph alike).
CALIB_RAY_STRIDE = 2
CALIB_RAYS_PER_TARGET = 2048


def export_settings() -> dict:
    """What the export stage's files follow besides the checkpoint (a stamp input): another opset or contract
    (its version, its graphs) exports again."""
    from ghnerf_runtime.contract import CONTRACT_VERSION, GRAPH_NAMES
    from training.export.export import DEFAULT_OPSET

    return {"opset": DEFAULT_OPSET, "contract": CONTRACT_VERSION, "graphs": list(GRAPH_NAMES)}


def quantize_settings() -> dict:
    """What the quantize stage's files follow besides the fp32 graphs and the calibration scenes (a stamp input):
    the per-graph policies (``HEAD_OUTPUT_LAYERS``, ``ENCODER_FLOAT_LAYERS`` and the rest, as ``POLICIES``
    holds them) and the calibration rays."""
    from training.export.quantize import POLICIES, QUANTIZER_VERSION

    return {"version": QUANTIZER_VERSION,
            "policies": {g: None if p is None else asdict(p) for g, p in sorted(POLICIES.items())},
            "ray_stride": CALIB_RAY_STRIDE, "rays_per_target": CALIB_RAYS_PER_TARGET}


def _staging(folder: Path) -> Path:
    from training.export.staging import staging_dir

    return staging_dir(folder)


def _rejected(folder: Path, staging: Path, e: BaseException) -> None:
    from training.export.staging import rejected

    rejected(folder, staging, e)


def _move_into(staging: Path, folder: Path, files: list[Path], removed: list[Path] = ()) -> list[Path]:
    """``training.export.staging.move_into``: the card (``cfg.out/model_card.json``, the folder's parent) is set
    aside as the first new file moves in, when it records other versions of them (the card stage writes it again)."""
    from training.export.staging import move_into

    return move_into(staging, folder, files, removed)


def _drop_stale_int8(folder: Path, fresh: dict[str, Path]) -> list[Path]:
    from training.export.staging import drop_stale_int8

    return drop_stale_int8(folder, fresh)


def stage_export(cfg: PipelineConfig, trained: dict[str, Path]) -> tuple[list[Path], dict]:
    """fp32 graphs and weights, written and checked in ``<variant>.staging``, then moved over the folder's: a
    failed check or a crash leaves the model folder's files as they were."""
    import torch

    from training.export.export import example_inputs, export_all, trained_frame_padding
    from training.export.parity import check_fp32_parity, torch_vs_ort
    from training.train import load_model

    outputs, info = [], {}
    for variant, ckpt in trained.items():
        model, ck = load_model(ckpt)
        # the contract says what the crops showed past the frame in training: the runtime pads to match
        padding = trained_frame_padding(ck)
        folder = cfg.out / variant
        staging = _staging(folder)
        try:
            weights = staging / f"{variant}.pt"
            torch.save({"model": model.state_dict(), "model_config": model.config.to_dict(), "step": ck["step"],
                        "frame_padding": padding},
                       weights)  # weights only: loads with torch.load(weights_only=True); a re-export reads padding
            paths = export_all(model, staging, inputs=example_inputs(model), frame_padding=padding)
            info[variant] = {"fp32_parity_torch_vs_ort": torch_vs_ort(
                model, paths, example_inputs(model, targets=3, ray_stride=4, seed=1))}
            if cfg.parity_check:
                check_fp32_parity(info[variant]["fp32_parity_torch_vs_ort"], f"{staging}/")
        except BaseException as e:
            _rejected(folder, staging, e)
            raise
        removed = _drop_stale_int8(folder, paths)
        outputs += _move_into(staging, folder, [weights, *paths.values()], removed)
    return outputs, info


def stage_quantize(cfg: PipelineConfig, trained: dict[str, Path]) -> tuple[list[Path], dict]:
    """int8 graphs of the folder's fp32 ones, written and checked in ``<variant>.staging``, then moved over the
    folder's (as :func:`stage_export`)."""
    from training.data.targets import TargetConfig
    from training.data.torch_dataset import MultiViewDataset
    from training.export.parity import check_int8_parity, int8_vs_fp32
    from training.export.quantize import calibration_feeds, quantize_all
    from training.train import load_model

    outputs, info = [], {}
    calib_ds = MultiViewDataset(cfg.data, "train", TargetConfig())
    val_ds = MultiViewDataset(cfg.data, cfg.eval_split, TargetConfig())
    for variant, ckpt in trained.items():
        model, _ = load_model(ckpt)
        folder = cfg.out / variant
        graphs = model.contract().graph_names
        fp32 = {g: folder / f"{g}.onnx" for g in graphs}
        calib = [_scene_inputs(model, item, ray_stride=CALIB_RAY_STRIDE, seed=i)
                 for i, item in calibration_items(calib_ds, cfg.calib_scenes)]
        staging = _staging(folder)
        try:
            int8 = quantize_all(fp32, staging, calibration_feeds(model, calib, graphs,
                                                                 rays_per_target=CALIB_RAYS_PER_TARGET))
            parity_in = _scene_inputs(model, val_ds[0], ray_stride=model.config.heatmap_stride, targets=[0, 1])
            info[variant] = {"int8_vs_fp32": int8_vs_fp32(fp32, int8, model.contract(), parity_in),
                             "calibration_scenes": len(calib)}
            if cfg.parity_check:
                check_int8_parity(info[variant]["int8_vs_fp32"], f"{staging}: ")
        except BaseException as e:
            _rejected(folder, staging, e)
            raise
        outputs += _move_into(staging, folder, list(int8.values()))
    return outputs, info


def stage_eval(cfg: PipelineConfig, variant: str, ckpt: Path) -> tuple[list[Path], dict]:
    from training import evaluate as ev

    folder = cfg.out / variant
    specs = {"torch": str(ckpt), "fp32": str(folder), "int8": f"{folder}#int8"}
    out = cfg.out / f"metrics_{variant}.json"
    argv = ["--data", str(cfg.data), "--split", cfg.eval_split, "--out", str(out), "--threads", str(cfg.threads)]
    if cfg.eval_limit:
        argv += ["--limit", str(cfg.eval_limit)]
    for runtime in EVAL_RUNTIMES[variant]:
        argv += ["--model", f"{variant}_{runtime}={specs[runtime]}"]
    rc = ev.main(argv)
    if rc == 130:  # Ctrl-C: ghnerf-eval said so and what it kept; the pipeline stops as a Ctrl-C stops it
        raise KeyboardInterrupt
    if rc != 0:  # a bad input: ghnerf-eval has said which, in one line
        raise RuntimeError(f"eval_{variant}: ghnerf-eval refused its inputs (the line above names them)")
    return [out], {}


def prior_extra_dir(cfg: PipelineConfig) -> Path:
    """The prior's second training set: other scenes of the same recipe (dataset seed 1, no novel views)."""
    return cfg.data.parent / f"{cfg.data.name}_prior_extra"


def prior_extra_args(cfg: PipelineConfig, workers: int) -> list[str]:
    """``training.data.generate``'s arguments for :func:`prior_extra_dir` (the files do not depend on ``workers``)."""
    return ["--out", str(prior_extra_dir(cfg)), "--train", str(cfg.prior_extra_train), "--val", "0",
            "--val-seen-motions", "0", "--novel-views", "0", "--seed", "1", "--res", str(cfg.res),
            "--freestyle-share", str(cfg.freestyle_share), "--workers", str(workers)]


def prior_extra_data(cfg: PipelineConfig) -> Path:
    """The prior's second training set (made, resumed or extended here; nothing to do once complete)."""
    from training.data.generate import main as generate

    generate(prior_extra_args(cfg, cfg.workers))
    return prior_extra_dir(cfg)


def prior_argv(cfg: PipelineConfig, model_dir: Path, out: Path, threads: int) -> list[str]:
    """``training.skeleton_prior``'s arguments for the recipe's prior of ``model_dir``'s keypoint graph."""
    argv = ["--model-dir", str(model_dir), "--data", str(cfg.data), "--val-split", cfg.eval_split,
            "--steps", str(cfg.prior_steps), "--threads", str(threads), "--out", str(out)]
    if cfg.prior_members > 1:
        argv += ["--members", str(cfg.prior_members)]
    if cfg.prior_tilt_share:  # (none: the upright-only prior, whatever the mode)
        argv += ["--tilt-share", str(cfg.prior_tilt_share), "--tilt-mode", cfg.prior_tilt_mode]
    if cfg.prior_scenes:
        argv += ["--limit", str(cfg.prior_scenes)]
    if cfg.prior_extra_train:
        argv += ["--extra-data", str(prior_extra_dir(cfg))]
    return argv


def early_prior_dir(cfg: PipelineConfig, variant: str) -> Path:
    """Where :mod:`training.early_prior` exports the pretrained encoder and trains its prior."""
    return cfg.runs / f"{VARIANTS[variant]}_prior"


def early_prior_request(cfg: PipelineConfig, keypoints: dict[str, str], data: Any, threads: int) -> dict:
    """What an early prior must have been trained for to stand for the prior stage's: the keypoint graphs' hashes
    by file name, the dataset (its stamp and folder), the prior's recipe and the threads each network trains at
    when trained with ``threads`` in all (the stage's ``cfg.threads``; arithmetic may round by thread count)."""
    from training.skeleton_prior import member_lanes

    return {**prior_stage_inputs(cfg, {}, data), "keypoints": keypoints, "data_folder": str(cfg.data),
            "threads_per_network": member_lanes(cfg.prior_members, threads)[1]}


def adopt_early_prior(cfg: PipelineConfig, variant: str, data: Any) -> bool:
    """Copy the early prior into the model folder when it was trained on this folder's keypoint graphs (same
    :func:`~training.model_card.graph_sha256`: the weights id aside) for the same request, and intact; False
    (nothing copied) otherwise."""
    from training.early_prior import REQUEST_FILE
    from training.model_card import graph_sha256, sha256
    from training.skeleton_prior import FILE_NAME

    folder, staged = cfg.out / variant, early_prior_dir(cfg, variant)
    try:
        record = json.loads((staged / REQUEST_FILE).read_text())
        prior = Path(record["prior"])
        graphs = keypoint_graphs({str(p): None for p in folder.glob("*.onnx")})
        wanted = early_prior_request(cfg, {Path(p).name: graph_sha256(p) for p in graphs}, data, cfg.threads)
        if not graphs or _digest(record["request"]) != _digest(wanted) or sha256(prior) != record["prior_sha256"]:
            log.info("prior: the early prior in %s does not match %s; training it here", staged, folder)
            return False
        report = json.loads(prior.with_suffix(".json").read_text())
    except (OSError, ValueError, KeyError, TypeError) as e:
        if (staged / REQUEST_FILE).exists():
            log.info("prior: the early prior in %s is unreadable (%s); training it here", staged, e)
        return False
    out = folder / FILE_NAME
    write_atomic(out, prior_for_folder(prior, folder))  # (a small MLP) never half a prior beside the graphs
    report.update({"file": str(out), "trained_in": str(prior),
                   "trained_beside": "the joint run (training.early_prior, from the pretrained encoder)"})
    write_atomic(out.with_suffix(".json"), strict_json(report) + "\n")  # an older report's NaN read back: null
    log.info("prior: taken from %s (trained beside the joint run on the same keypoint graphs)", staged)
    return True


def prior_for_folder(prior: Path, folder: Path) -> bytes:
    """The early prior's file with its encoder's sha256 (``ghnerf_skeleton.encoder_sha256``, which the runtime
    checks against the file beside it) set to that of ``folder``'s encoder file: the same graph as the one it
    learnt from (:func:`adopt_early_prior` checked it), under another weights id, so another file hash."""
    import onnx  # noqa: PLC0415
    from google.protobuf.message import DecodeError  # noqa: PLC0415

    from ghnerf_runtime.skeleton_prior import META_PREFIX  # noqa: PLC0415
    from training.model_card import sha256  # noqa: PLC0415

    try:
        m = onnx.load(str(prior))
    except (DecodeError, ValueError):  # not a graph (the runtime refuses it, naming it): copied as it is
        return prior.read_bytes()
    props = {p.key: p.value for p in m.metadata_props}
    name = props.get(META_PREFIX + "encoder_file")
    if not name:  # a prior that records no encoder is taken as it is (SkeletonPrior.check_encoder)
        return prior.read_bytes()
    props[META_PREFIX + "encoder_sha256"] = sha256(folder / name)
    del m.metadata_props[:]
    onnx.helper.set_model_props(m, props)
    return m.SerializeToString()


def stage_prior(cfg: PipelineConfig, variant: str, data: Any = None, adopt: bool = True) -> tuple[list[Path], dict]:
    """The skeleton prior of the exported model (``training.skeleton_prior``), beside its graphs: the early
    prior's when it learnt from the same graphs (:func:`adopt_early_prior`; not when ``adopt`` is False, as
    under ``--force prior``), else trained here."""
    from training import skeleton_prior as sp

    out = cfg.out / variant / sp.FILE_NAME
    if adopt and adopt_early_prior(cfg, variant, data):
        return [out, out.with_suffix(".json")], {"early": True}
    if cfg.prior_extra_train:
        prior_extra_data(cfg)
    sp.main(prior_argv(cfg, cfg.out / variant, out, cfg.threads))
    return [out, out.with_suffix(".json")], {}


def keypoint_graphs(graphs: dict) -> dict:
    """Of a variant's graph files (path: hash), those the runtime decodes 2D joints from: ``human.*``, else
    ``encoder.*`` (``training.skeleton_prior`` loads the same one)."""
    from training.skeleton_prior import KEYPOINT_GRAPHS

    for stem in KEYPOINT_GRAPHS:
        picked = {k: v for k, v in graphs.items() if Path(k).name.split(".")[0] == stem and k.endswith(".onnx")}
        if picked:
            return picked
    return {}


def prior_stage_inputs(cfg: PipelineConfig, graphs: dict, data: Any = None) -> dict:
    """What the prior stage reads: the keypoint graph (the encoder it learns the errors of; fp32 and int8),
    the dataset and its recipe. Not the rendering graphs: the joint run keeps the pretrained encoder frozen,
    so training the NeRF branch again (longer, on another machine) leaves the prior as it is."""
    from ghnerf_runtime.skeleton_prior import FEATURE_VERSION  # a new feature set retrains the prior

    inputs = {"keypoints": keypoint_graphs(graphs), "data": data, "steps": cfg.prior_steps,
              "scenes": cfg.prior_scenes, "split": cfg.eval_split, "extra": cfg.prior_extra_train,
              "members": cfg.prior_members, "features": FEATURE_VERSION}
    # only when there are turned copies: the stamps and early-prior requests of the upright priors before these
    # keys (tilt share 0, any mode) still match, and a tilted recipe never matches one of them
    if cfg.prior_tilt_share:
        inputs["tilt"] = {"share": cfg.prior_tilt_share, "mode": cfg.prior_tilt_mode}
    return inputs


def motion_mix(spec: dict) -> str:
    """A split spec's motions as the card prints them: ``"stand, walk"`` or, weighted, ``"stand 11 %, ..."``."""
    motions, weights = spec.get("motions") or [], spec.get("motion_weights")
    if not weights:
        return ", ".join(motions)
    total = sum(weights)
    return ", ".join(f"{m} {100 * w / total:.0f} %" for m, w in zip(motions, weights))


def kept_painter_sections(cfg: PipelineConfig) -> dict:
    """The ``novel_painter`` sections of the folder's card (``training.model_card.add_painter_to_card``, not made
    by the pipeline) whose files are still the ones the card recorded (same sha256), to carry into the new card;
    a section whose files changed or went is dropped with a warning naming them."""
    from training.model_card import sha256

    from training.export.staging import STALE_CARD

    card = cfg.out / "model_card.json"
    if not card.exists():  # set aside when new graphs moved in (training.export.staging): its painter still counts
        card = cfg.out / STALE_CARD
    try:
        old = json.loads(card.read_text())
        sections, files = old.get("novel_painter") or {}, old.get("files") or {}
    except (OSError, ValueError, AttributeError):
        return {}  # no card yet (or an unreadable one: nothing of it to keep)
    kept = {}
    for variant, section in sections.items():
        recorded = {k: v for k, v in files.items()
                    if Path(k).parent.name == variant and Path(k).name.startswith("novel_painter")
                    and k.endswith(".onnx")}
        changed = sorted(str(cfg.out / k) for k, v in recorded.items() if not (cfg.out / k).is_file()
                         or sha256(cfg.out / k) != (v.get("sha256") if isinstance(v, dict) else None))
        if recorded and not changed:
            kept[variant] = section
        else:
            log.warning("card: the novel_painter section of %s is dropped: %s", variant,
                        f"{', '.join(changed)} changed or went since the card recorded them" if changed else
                        f"the card records none of its files ({variant}/novel_painter*.onnx)")
    return kept


def stage_card(cfg: PipelineConfig, st: Stages) -> tuple[list[Path], dict]:
    from training.model_card import hardware, sha256, write_card
    from training.skeleton_prior import card_summary

    data_s = st.stamp("data")
    metrics: dict = {"models": {}}
    for v in VARIANTS:
        m = json.loads((cfg.out / f"metrics_{v}.json").read_text())
        metrics["models"].update(m["models"])
        metrics.update({k: m[k] for k in ("data", "split", "pck_alpha", "pck_reference")})
    write_atomic(cfg.out / "metrics.json", strict_json(metrics))  # a NaN read back from a variant's file: null
    files = {}
    for variant in VARIANTS:
        for p in sorted((cfg.out / variant).glob("*")):
            if p.suffix in (".onnx", ".pt"):
                files[str(p.relative_to(cfg.out))] = {"bytes": p.stat().st_size, "sha256": sha256(p)}
    training = {}
    for variant in VARIANTS:
        pre = (st.stamp(f"pretrain_{variant}") or {}).get("info")
        if pre:
            training[f"{variant}_human_pretraining"] = {
                "config": pre.get("config", {}), "steps": pre.get("summary", {}).get("steps"),
                "stopped_early": pre.get("summary", {}).get("stopped_early"),
                "wall_s": pre.get("summary", {}).get("wall_s"), "checkpoint": pre.get("summary", {}).get("human"),
                "images_per_step": pre.get("summary", {}).get("images_per_step"),
                "eval_pck@0.2": pre.get("summary", {}).get("eval_pck@0.2"),
                **{k: pre["summary"][k]
                   for k in ("threads", "segments", "device", "gpu", "precision", "precision_probe")
                   if k in pre.get("summary", {})}}
        s = st.stamp(f"train_{variant}") or {}
        info = s.get("info", {})
        training[variant] = {"config": info.get("config", {}), "steps": info.get("summary", {}).get("steps"),
                             "stopped_early": info.get("summary", {}).get("stopped_early"),
                             "wall_s": info.get("summary", {}).get("wall_s"),
                             "checkpoint": info.get("summary", {}).get("checkpoint"),
                             **{k: info["summary"][k] for k in ("threads", "segments", "device", "gpu")
                                if k in info.get("summary", {})}}
    q = {v: (st.stamp(f"quantize_{v}") or {}).get("info", {}).get(v, {}) for v in VARIANTS}
    ds_meta = json.loads((cfg.data / "dataset.json").read_text())
    card = {
        "name": "GHNeRF edge128 (ResNet18 human encoder, BODY_25 heatmaps)",
        "summary": ("Generalizable human NeRF (ENeRF backbone + GHNeRF joint-heatmap head) at 128x128 for a 2-core "
                    "CPU through onnxruntime; `ghnerf/` is the model, `baseline/` the same network without the "
                    "human encoder (ENeRF + heatmap). Trained from scratch on synthetic data."),
        "quick": cfg.quick,
        "command": cfg.command,
        "recipe": None if cfg.quick else cfg.recipe,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "hardware": hardware(),
        "wall_time_s": {name: (st.stamp(name) or {}).get("wall_s") for name in STAGES if name != "card"},
        "data": {"path": str(cfg.data), "source": ds_meta.get("source"), "resolution": ds_meta.get("resolution"),
                 "splits": {k: v.get("count") for k, v in ds_meta.get("splits", {}).items()},
                 "motions": {k: motion_mix(v.get("spec") or {}) for k, v in ds_meta.get("splits", {}).items()},
                 "eval_split": cfg.eval_split, "eval_scenes": next(iter(metrics["models"].values()))["scenes"]},
        "training": training,
        "metrics": metrics["models"],
        "parity": {v: q[v].get("int8_vs_fp32", {}) for v in VARIANTS},
        # which data fixed the int8 ranges: training scenes, never the held-out split the metrics score
        "calibration": {v: {"split": "train", "scenes": q[v].get("calibration_scenes"),
                            "quantizer_version": card_quantizer_version(cfg.out / v)} for v in VARIANTS},
        "fp32_parity_torch_vs_ort": {v: (st.stamp(f"export_{v}") or {}).get("info", {}).get(v, {})
                                     .get("fp32_parity_torch_vs_ort") for v in VARIANTS},
        "files": files,
        "skeleton_prior": {v: card_summary(cfg.out / v) for v in PRIOR_VARIANTS},
        "notes": [
            "Synthetic training and evaluation data only; no real-camera or ZJU-MoCap numbers.",
            "The ResNet18 human encoder is trained from scratch (no ImageNet weights available here): when the "
            "train config has a pretrain_human block it is first pretrained alone on the synthetic 2D heatmaps "
            "(and, with freeze_human, kept fixed in the joint run).",
            "The perceptual loss is replaced by a 1 - SSIM patch loss (no VGG weights).",
            "The human encoder carries a training-time 2D heatmap head (dense auxiliary loss on both source "
            "views); it is exported as the encoder's `encoder_heatmaps` output, scored above, and usable by the "
            "runtime instead of the rendered heatmaps (faster: no volume or rendering for keypoints).",
            _budget_note(cfg),
        ],
        "stage_inputs": {"data": (data_s or {}).get("inputs")},
    }
    for v in VARIANTS:  # a reused run's stamp took ~0 s: its own summary has the real wall time
        card["wall_time_s"][f"train_{v}"] = max(card["wall_time_s"].get(f"train_{v}") or 0,
                                                training[v].get("wall_s") or 0)
        if f"{v}_human_pretraining" in training:
            card["wall_time_s"][f"pretrain_{v}"] = max(card["wall_time_s"].get(f"pretrain_{v}") or 0,
                                                       training[f"{v}_human_pretraining"].get("wall_s") or 0)
    if painter := kept_painter_sections(cfg):  # the painter's figures, while its files are the ones they describe
        card["novel_painter"] = painter
    j, m = write_card(cfg.out, card)
    from training.export.staging import drop_stale_leftovers

    drop_stale_leftovers(cfg.out)  # the card set aside by the export stage is replaced now
    return [j, m], {}


def _budget_note(cfg: PipelineConfig) -> str:
    where = "a smoke test's few steps" if cfg.quick else f"the `{cfg.recipe}` recipe: {RECIPES[cfg.recipe].about}"
    return (f"A small training budget ({where}; not GHNeRF's 200k GPU iterations): expect lower accuracy than "
            "the paper.")


def _warn_if_replacing_another_recipe(cfg: PipelineConfig) -> str | None:
    """A folder whose card names another recipe (``make model`` on two cores over the shipped ``gpu`` model)
    is about to be replaced by a model of this one: say so before hours of training, not after."""
    card = cfg.out / "model_card.json"
    if cfg.quick or not card.exists():
        return None
    try:
        old = json.loads(card.read_text()).get("recipe")
    except (OSError, ValueError):
        return None
    if not old or old == cfg.recipe:
        return None
    msg = (f"{cfg.out} holds a model of the {old!r} recipe; this run makes the {cfg.recipe!r} recipe "
           f"({RECIPES[cfg.recipe].about}) and replaces it at the export stage. Pass --recipe {old} to remake "
           "that one, or another --out to keep it (docs/training.md, `make model`)")
    log.warning("%s", msg)
    return msg


def run(cfg: PipelineConfig) -> dict | None:
    """Run the stages of ``cfg.variants``; the card when every variant is evaluated (else None)."""
    import torch

    torch.set_num_threads(cfg.threads)
    _warn_if_replacing_another_recipe(cfg)
    cfg.out.mkdir(parents=True, exist_ok=True)
    st = Stages(cfg.out, cfg.force)
    _set_aside_forced(cfg, st.force)
    data_in = data_request(cfg)
    d = st.run("data", data_in, lambda: stage_data(cfg))
    if cfg.until == "data":
        return None
    data_key = data_stage_key(d)

    def train_in(variant: str, pretrained: dict | None) -> dict:
        return train_stage_inputs(cfg, variant, data_key, (pretrained or {}).get("outputs"))

    for v in cfg.variants:  # a run stopped at its max_minutes cap is resumed, whatever its stamp says
        if cfg.until != "pretrain" and not _run_finished(cfg, v):
            st.force.add(f"train_{v}")
    todo = [v for v in cfg.variants if st.done(f"train_{v}", train_in(v, st.stamp(f"pretrain_{v}"))) is None
            and not _run_finished(cfg, v)]
    # lanes: two trainings to share the cores, or (the shared plan) one beside the early prior
    lanes = len(todo) > 1 or (todo and cfg.shared_pretrain_steps and (os.cpu_count() or 1) >= 2)
    if cfg.until != "pretrain" and cfg.parallel_train and lanes and not torch.cuda.is_available():
        train_side_by_side(cfg, todo, data_key)  # (it trains too: not when only the pretraining is asked for)
    for variant in cfg.variants:
        pre = None
        if pretrain_block(cfg, variant):
            pre = st.run(f"pretrain_{variant}", pretrain_stage_inputs(cfg, variant, data_key),
                         lambda v=variant: stage_pretrain(cfg, v))
        if cfg.until == "pretrain":
            continue
        t = st.run(f"train_{variant}", train_in(variant, pre), lambda v=variant: stage_train(cfg, v))
        if cfg.until == "train":
            continue
        ckpt = {variant: Path(next(iter(t["outputs"])))}
        # the exporter's and quantizer's own settings too: another policy or opset remakes the files
        e = st.run(f"export_{variant}", export_stage_inputs(t),
                   lambda c=ckpt: stage_export(cfg, c))
        q = st.run(f"quantize_{variant}", quantize_stage_inputs(cfg, e, data_key),
                   lambda c=ckpt: stage_quantize(cfg, c))
        p = None
        if variant in PRIOR_VARIANTS:  # before the eval, which scores it: a new prior re-evaluates
            p = st.run(f"prior_{variant}", prior_stage_inputs(cfg, {**e["outputs"], **q["outputs"]}, data_key),
                       lambda v=variant: stage_prior(cfg, v, data_key, adopt=f"prior_{v}" not in st.force))
        st.run(f"eval_{variant}", eval_stage_inputs(cfg, variant, e, q, p, data_key),
               lambda v=variant, c=ckpt[variant]: stage_eval(cfg, v, c))
    if cfg.until:
        log.info("stopped after the %s stages (--until)", cfg.until)
        return None
    if any(st.stamp(f"eval_{v}") is None for v in VARIANTS):
        log.info("card: waiting for %s", [v for v in VARIANTS if st.stamp(f"eval_{v}") is None])
        return None
    st.force.add("card")  # always rewritten: cheap, and it records the command and the stamps
    st.run("card", card_stage_inputs(st), lambda: stage_card(cfg, st))
    return json.loads((cfg.out / "model_card.json").read_text())


# ------------------------------------------------------------------------------ stage inputs (stamps)
def data_stage_key(d: dict) -> dict:
    """What the training stages read of the data stage's stamp: the request *and* the manifest's hash, so a
    dataset regenerated under another recipe (same folder and counts, say a new training motion) retrains."""
    return {"request": d["inputs"], "manifest": d["outputs"]}


def _pretrain_result_keys(cfg: PipelineConfig, variant: str) -> dict:
    """The pretraining config without ``PRETRAIN_RUNTIME_KEYS``: the ``gpu`` recipe sizes ``loader_workers`` by
    the machine's cores, which stamped the pretraining and the joint run again on every other machine."""
    return {k: v for k, v in pretrain_inputs(cfg, variant).items() if k not in PRETRAIN_RUNTIME_KEYS}


def pretrain_stage_inputs(cfg: PipelineConfig, variant: str, data_key: dict) -> dict:
    return {"data": data_key, "config": _pretrain_result_keys(cfg, variant)}


def train_stage_inputs(cfg: PipelineConfig, variant: str, data_key: dict, pretrain_outputs: dict | None) -> dict:
    """``pretrain_outputs``: the pretrain stage's stamped outputs (``human.pt`` and its sha256; None before it has
    a stamp): a pretraining done again with the same config is another encoder to start from."""
    block = pretrain_block(cfg, variant)
    return {"data": data_key, "config": _result_keys(train_inputs(cfg, VARIANTS[variant])),
            "model": expected_model(cfg, variant), "runs": str(cfg.runs), "accept_stopped": cfg.accept_stopped,
            "pretrain": _pretrain_result_keys(cfg, variant) if block else None,
            # (a variant without a pretraining gets no key: its stamps made before the key keep matching)
            **({"pretrain_outputs": pretrain_outputs} if block else {})}


def export_stage_inputs(train_stamp: dict) -> dict:
    # the exporter's own settings too: another opset or contract remakes the files
    return {"checkpoint": train_stamp["outputs"], "settings": export_settings()}


def card_quantizer_version(variant_dir: Path) -> int | dict[str, int] | None:
    """Which ``QUANTIZER_VERSION`` made the int8 graphs in ``variant_dir``, read from the files themselves (not the
    quantize stamp: a file replaced since, as session 60's render graphs, keeps the stamp's word stale): the
    version when every graph that shows one agrees, ``{graph: version}`` when they differ, None when none shows
    one (``training.export.quantize.quantizer_version_of_file``). A file it cannot read shows none, with a warning
    naming it: the card still records its hash, and the runtime refuses it by name."""
    from ghnerf_runtime.contract import GRAPH_NAMES
    from training.export.quantize import quantizer_version_of_file

    found = {}
    for graph in GRAPH_NAMES:
        path = variant_dir / f"{graph}.int8.onnx"
        try:
            version = quantizer_version_of_file(path) if path.is_file() else None
        except ValueError as e:
            log.warning("the card names no quantizer version for it: %s", e)
            continue
        if version is not None:
            found[graph] = version
    if len(set(found.values())) > 1:
        return found
    return next(iter(found.values()), None)


def quantize_stage_inputs(cfg: PipelineConfig, export_stamp: dict, data_key: dict) -> dict:
    # the dataset too: it calibrates on the training split's scenes and checks parity on a held-out one
    return {"export": export_stamp["outputs"], "calib": cfg.calib_scenes, "settings": quantize_settings(),
            "data": data_key}


def eval_stage_inputs(cfg: PipelineConfig, variant: str, export_stamp: dict, quantize_stamp: dict,
                      prior_stamp: dict | None, data_key: dict) -> dict:
    # the dataset too: the held-out scenes it scores are the data stage's
    inputs = {"q": quantize_stamp["outputs"], "e": export_stamp["outputs"], "split": cfg.eval_split,
              "limit": cfg.eval_limit, "runtimes": EVAL_RUNTIMES[variant], "data": data_key}
    if prior_stamp is not None:  # the graph, not its report
        inputs["prior"] = {k: v for k, v in prior_stamp["outputs"].items() if k.endswith(".onnx")}
    return inputs


def card_stage_inputs(st: Stages) -> list:
    return ([st.stamp(f"eval_{v}")["outputs"] for v in VARIANTS]
            + [st.stamp(f"prior_{v}")["outputs"] for v in PRIOR_VARIANTS])


class StageStatus(NamedTuple):
    """One row of ``--status``: the stage, whether ``make model`` would run it now, and why."""

    stage: str
    runs: bool
    why: str


def status(cfg: PipelineConfig) -> list[StageStatus]:
    """What :func:`run` would do now, stage by stage, without running or writing anything.

    Each stage is judged on its own stamp against inputs made from the stamps before it (what :func:`run`
    reads when those stages are skipped). A stage after one that runs is listed as running after it even when
    its own stamp matches: the files that one writes are its inputs. A train stage is also judged as
    :func:`run` judges it: a run folder without a finished run of this config trains (or resumes) there."""
    from training.model_card import sha256

    st = Stages(cfg.out, cfg.force, create=False)
    rows: list[StageStatus] = []

    def judge(name: str, inputs: Any, after: list[str], why: str | None = None) -> bool:
        """Add the stage's row; whether it runs."""
        why = why or st.why_not_done(name, inputs)
        note = f"after {', '.join(after)}, whose files are its inputs" if after else ""
        if why is None and not after:
            rows.append(StageStatus(name, False, "up to date"))
            return False
        rows.append(StageStatus(name, True, "; ".join(filter(None, [why, note]))))
        return True

    def waiting(names: list[str], on: str) -> None:
        rows.extend(StageStatus(n, True, f"waits for {on} (no stamp: its inputs are not known yet)") for n in names)

    d = st.stamp("data")
    data_runs = judge("data", data_request(cfg), [])
    if cfg.until == "data":
        return rows
    if d is None:
        waiting([n for n in STAGES[1:] if n != "card"], "data")
        return rows
    data_key = data_stage_key(d)
    data_after = ["data"] if data_runs else []  # (the stages that read the dataset itself)
    for variant in cfg.variants:
        # the training stages reuse a finished run of the same config: then only the stamp is written again,
        # with the same checkpoint, and the stages after them keep theirs (their inputs are its files)
        after = list(data_after)
        # what run() gives the train stage: the pretraining's stamped outputs, as that stage leaves them
        pretrained = (st.stamp(f"pretrain_{variant}") or {}).get("outputs")
        train_after = after
        # what run() sets aside before any stage (_set_aside_forced): a forced stage's folder is made again, not
        # reused, and a forced joint run's folder no longer stops a pretraining
        joint_set_aside = f"train_{variant}" in st.force and cfg.until not in ("data", "pretrain")
        if pretrain_block(cfg, variant):
            finished = _pretrain_finished(cfg, variant) and f"pretrain_{variant}" not in st.force
            if judge(f"pretrain_{variant}", pretrain_stage_inputs(cfg, variant, data_key), after):
                if finished:  # the same human.pt, stamped again
                    human = pretrain_dir(cfg, variant) / "human.pt"
                    pretrained = {str(human): sha256(human)}
                    rows[-1] = rows[-1]._replace(why=rows[-1].why + "; the finished pretraining there is reused: "
                                                                    "only its stamp is written again")
                else:  # a new human.pt: the joint run starts from it
                    train_after = [*after, f"pretrain_{variant}"]
                    if not joint_set_aside and (joint := _joint_run_before(cfg, variant)):
                        rows[-1] = rows[-1]._replace(why=rows[-1].why + f"; make model stops first: {joint} holds "
                                                     f"a joint run of an earlier pretraining (--force train_{variant}"
                                                     " sets it aside)")
        if cfg.until == "pretrain":
            continue
        joint = cfg.runs / VARIANTS[variant]
        if train_after != after:
            unfinished = f"it trains in {joint} from the new pretraining's human.pt"
        elif joint_set_aside:
            unfinished = None  # forced: "forced (--force)", in a folder made again (the old one moved aside)
        elif why := _human_init_mismatch(joint, train_inputs(cfg, VARIANTS[variant])):
            unfinished = (f"{joint} holds a run of another pretraining ({why}): make model stops there "
                          f"(--force train_{variant} sets it aside)")
        elif not _run_finished(cfg, variant):
            unfinished = f"{joint} holds no finished run of this config: it trains (or resumes) there"
        else:
            unfinished = None
        if judge(f"train_{variant}", train_stage_inputs(cfg, variant, data_key, pretrained), train_after,
                 unfinished) and not unfinished and not joint_set_aside:
            rows[-1] = rows[-1]._replace(why=rows[-1].why + f"; the finished run in {cfg.runs / VARIANTS[variant]} "
                                                              "is reused: only its stamp is written again")
        if cfg.until == "train":
            continue
        after = [f"train_{variant}"] if unfinished or joint_set_aside else []  # (a new checkpoint)
        later = [f"export_{variant}", f"quantize_{variant}",
                 *([f"prior_{variant}"] if variant in PRIOR_VARIANTS else []), f"eval_{variant}"]
        t, e, q = (st.stamp(f"{k}_{variant}") for k in ("train", "export", "quantize"))
        if t is None:
            waiting(later, f"train_{variant}")
            continue
        if judge(f"export_{variant}", export_stage_inputs(t), after):
            after = [f"export_{variant}"]
        if e is None:
            waiting(later[1:], f"export_{variant}")
            continue
        if judge(f"quantize_{variant}", quantize_stage_inputs(cfg, e, data_key), [*data_after, *after]):
            after = [*after, f"quantize_{variant}"]
        if q is None:
            waiting(later[2:], f"quantize_{variant}")
            continue
        p = None
        if variant in PRIOR_VARIANTS:
            p = st.stamp(f"prior_{variant}")
            if judge(f"prior_{variant}", prior_stage_inputs(cfg, {**e["outputs"], **q["outputs"]}, data_key),
                     [*data_after, *after]):
                after = [*after, f"prior_{variant}"]
            if p is None:
                waiting([f"eval_{variant}"], f"prior_{variant}")
                continue
        judge(f"eval_{variant}", eval_stage_inputs(cfg, variant, e, q, p, data_key), [*data_after, *after])
    if not cfg.until:
        rows.append(StageStatus("card", True, "always rewritten once every variant is evaluated (it records the "
                                              "command and the stamps)"))
    return rows


def print_status(rows: list[StageStatus]) -> None:
    width = max(len(r.stage) for r in rows)
    for r in rows:
        print(f"{r.stage:<{width}}  {'runs' if r.runs else 'skip'}  {r.why}")


def _recipe_args(argv: list[str]) -> list[str]:
    """``argv`` without ``--force STAGE`` and ``--variants LIST``: redoing a stage, or taking only some
    variants through now, changes no result, so the card's command (the recipe) leaves them out."""
    out, skip = [], False
    for a in argv:
        if skip:
            skip = False
        elif a in ("--force", "--variants", "--until", "--workers", "--recipe"):
            skip = True
        elif not a.startswith(("--force=", "--variants=", "--until=", "--workers=", "--recipe=")):
            out.append(a)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m training.pipeline", description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--out", default="models", help="model folder (ONNX graphs, metrics, card)")
    ap.add_argument("--data", help="dataset folder (default data/edge128; --quick: OUT/data)")
    ap.add_argument("--runs", help="training runs folder (default runs/; --quick: OUT/runs)")
    ap.add_argument("--quick", action="store_true", help="smoke test: tiny data, a few iterations")
    ap.add_argument("--eval-limit", type=int, help="evaluate the first N held-out scenes only (0: all)")
    ap.add_argument("--accept-stopped", action="store_true",
                    help="use a training run that stopped at its max_minutes cap as it is (default: resume it)")
    ap.add_argument("--force", action="append", default=[], choices=[*STAGES, *STAGE_KINDS],
                    help="redo a stage (repeatable); a kind (export) means every variant's")
    ap.add_argument("--variants", default=",".join(VARIANTS),
                    help="variants to take through train/export/quantize/eval now (the card needs all)")
    ap.add_argument("--threads", type=int, default=2, help="torch / onnxruntime threads for export and eval")
    ap.add_argument("--no-parity-check", action="store_true",
                    help="export and quantize even when onnxruntime strays from torch (fp32) or int8 from fp32 "
                         "beyond training.export.parity's bounds (default: stop there)")
    ap.add_argument("--sequential-train", action="store_true",
                    help="train the variants one after the other with every core (default on CPU: side by side)")
    ap.add_argument("--shared-pretrain-steps", type=int, default=None, metavar="N",
                    help="on CPU, the pretraining's first N steps run at half the cores beside the baseline's joint "
                         "run, and the skeleton prior then trains beside the joint run (default: the recipe's, "
                         "17600 for cpu; 0: the pretraining alone first, with every core, and the prior after the "
                         "joint run). The same batches; the thread counts, hence the rounding, change with it")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="train config override")
    ap.add_argument("--pretrain-set", action="append", default=[], metavar="KEY=VALUE",
                    help="override of the human-encoder pretraining (a PretrainConfig key, e.g. iterations=12000)")
    ap.add_argument("--prior-set", action="append", default=[], metavar="KEY=VALUE",
                    help="override of the skeleton prior's recipe: steps, extra_train (scenes of the second "
                         "training set), members (networks averaged), tilt_share (0-1: training scenes added "
                         "turned to any angle; 0: upright only) and tilt_mode (body or scene: what turns), e.g. "
                         "--recipe cpu --prior-set extra_train=0 --prior-set steps=15000 --prior-set members=1: "
                         "session 17's smaller prior, about 23 min sooner (docs/training.md, `make model`)")
    ap.add_argument("--workers", type=int, default=None,
                    help=f"dataset generation processes (default {PipelineConfig.workers}; "
                         + "".join(f"the {k} recipe's {r.workers}, at most the cores; " for k, r in RECIPES.items()
                                   if r.workers)
                         + "the files do not depend on it)")
    ap.add_argument("--until", choices=("data", "pretrain", "train"),
                    help="stop after this stage kind, e.g. train on a GPU machine and export, quantize and "
                         "evaluate elsewhere: the same command there reuses the finished runs")
    ap.add_argument("--train", type=int, default=None,
                    help="scenes in the train split (default: PipelineConfig's, 5000; another count makes another "
                         "dataset request: pass a new --data folder)")
    ap.add_argument("--freestyle-share", type=float, default=None,
                    help="share of train scenes moving 'freestyle' (default: PipelineConfig's, a half; another "
                         "value makes another dataset: pass a new --data folder)")
    ap.add_argument("--status", action="store_true",
                    help="run nothing, write nothing: list each stage this command would run or skip, and why (a "
                         "changed input, named where its stamp records it; an output gone or changed; a stage "
                         "before it that runs)")
    ap.add_argument("--recipe", default="auto", choices=("auto", *RECIPES),
                    help="training recipe: " + "; ".join(f"{k}: {r.about}" for k, r in RECIPES.items())
                         + "; auto (default): gpu where torch sees one, else cpu. Ignored with --quick")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    out = Path(args.out)
    cfg = PipelineConfig.quick_defaults(out) if args.quick else PipelineConfig(out=out)
    if args.data:
        cfg.data = Path(args.data)
    if args.runs:
        cfg.runs = Path(args.runs)
    # out-of-range numbers named now: they were used hours in (the eval stage's limit, the export's threads) or
    # raised a traceback from the dataset's config (the freestyle share)
    if args.eval_limit is not None and args.eval_limit < 0:
        ap.error(f"--eval-limit: must be at least 0 (0: every held-out scene), got {args.eval_limit}")
    if args.threads < 1:
        ap.error(f"--threads: must be at least 1, got {args.threads}")
    if args.freestyle_share is not None and not 0.0 <= args.freestyle_share <= 1.0:
        ap.error(f"--freestyle-share: must be a share from 0 to 1, got {args.freestyle_share!r}")
    if args.eval_limit is not None:
        cfg.eval_limit = args.eval_limit
    cfg.force = tuple(args.force)
    if args.freestyle_share is not None:
        cfg.freestyle_share = args.freestyle_share
    if args.train is not None:
        if args.train < 1:
            ap.error(f"--train: must be at least 1 scene, got {args.train}")
        cfg.train = args.train
    if args.workers is not None:
        if args.workers < 1:
            ap.error(f"--workers: must be at least 1, got {args.workers}")
        cfg.workers = args.workers
    cfg.until = args.until
    cfg.accept_stopped = args.accept_stopped
    cfg.parity_check = not args.no_parity_check
    cfg.threads = args.threads
    cfg.parallel_train = not args.sequential_train
    cfg.variants = tuple(v for v in args.variants.split(",") if v)
    bad = [v for v in cfg.variants if v not in VARIANTS]
    if bad:
        ap.error(f"--variants: unknown {bad}; variants: {list(VARIANTS)}")
    cfg.train_overrides = [*cfg.train_overrides, *args.set]
    cfg.pretrain_overrides = [*cfg.pretrain_overrides, *args.pretrain_set]
    recipe_flag: list[str] = []
    if not args.quick:
        cfg.apply_recipe(resolve_recipe(args.recipe))
        if args.workers is not None:  # --workers wins over the recipe's
            cfg.workers = args.workers
        recipe_flag = ["--recipe", cfg.recipe]  # resolved: the card names what was trained, not "auto"
        log.info("recipe %s: %s", cfg.recipe, RECIPES[cfg.recipe].about)
    if args.shared_pretrain_steps is not None:
        if args.shared_pretrain_steps < 0:
            ap.error(f"--shared-pretrain-steps: must be at least 0, got {args.shared_pretrain_steps}")
        cfg.shared_pretrain_steps = args.shared_pretrain_steps
    try:
        cfg.apply_prior_overrides(args.prior_set)
    except ValueError as e:
        ap.error(str(e))
    from training.model.config import ConfigError  # (lazy: it imports torch)

    try:  # each variant's train config and pretraining config, --set / --pretrain-set applied: a mistyped key or a
        # bad value was found by the train or pretrain stage, after the dataset (an hour on two cores) was made
        for variant in cfg.variants:
            train_inputs(cfg, VARIANTS[variant])
            if pretrain_block(cfg, variant) and (problem := pretrain_scene_problem(cfg, pretrain_inputs(cfg, variant))):
                ap.error(problem)
    except ConfigError as e:
        ap.error(str(e))

    cfg.command = shlex.join(["python", "-m", "training.pipeline",
                              *_recipe_args(argv if argv is not None else sys.argv[1:]), *recipe_flag])
    try:
        if args.status:
            print_status(status(cfg))
            return 0
        card = run(cfg)
    except (RuntimeError, subprocess.CalledProcessError, ConfigError) as e:
        # the stage that failed has said why (a refused run folder, a damaged checkpoint named with what to do,
        # or the step's own log / stderr)
        print(f"python -m training.pipeline: error: {e}", file=sys.stderr)
        return 2
    if card is not None:
        print(strict_json(card["metrics"]))  # as model_card.json holds them: a NaN as null
    return 0


if __name__ == "__main__":
    sys.exit(main())
