"""The 3D joints a device estimates for dataset scenes, cached per split.

What the runtime's 3D path gives for a pair of source images: the model folder's human encoder
heatmaps, flip-tested (averaged with those of the mirrored images), decoded, and lifted to 3D by the
folder's skeleton prior (``ghnerf_runtime.skeleton_prior``), exactly as ``ghnerf-eval`` scores it
(``training.evaluate.scene_metrics``: the model card's "MPJPE mm, skeleton prior" column). The
geometry built from joints (``training.body_proxy``) reads these, never the dataset's true joints,
when it stands for what a device could do.

    python -m training.device_joints --data out/s26/data --split val --limit 256 \
        --model models/ghnerf --out out/s34/joints_val.npz

``--truth`` writes the dataset's true joints in the same format instead (an oracle, for measuring
what better joints would give).

Cached fields: ``joints`` ``(N, 25, 3)`` float32 (rig frame, metres), ``expected_error_m`` ``(N, 25)``
(the prior's own estimate), ``index`` ``(N,)`` the dataset items, and where they came from: ``split`` and
``dataset_sha256`` (of its ``dataset.json``), which :func:`check_source` compares before a cache's joints
are paired with a split's scenes by index.
"""
from __future__ import annotations

import argparse
import io
import sys
import time
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ghnerf_runtime.cli.output_path import ready_output_arg
from training.cli import at_least
from training.model_card import sha256, write_atomic


class JointsCacheError(ValueError):
    """A joints cache that is missing, broken or does not cover the scenes asked for."""


def estimate_joints(renderer, scene: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """``(25, 3)`` joints and ``(25,)`` expected errors (m) of one scene from a
    ``training.evaluate.OnnxRenderer`` whose folder has a skeleton prior."""
    from training.evaluate import flip_tested, prior_estimate  # noqa: PLC0415 - torch-side module, loaded late

    if renderer.skeleton_prior is None:
        raise JointsCacheError("the model folder has no skeleton prior the runtime accepts")
    enc = renderer.encoder_heatmaps(scene)
    if enc is None:
        raise JointsCacheError("the model's encoder graph has no encoder_heatmaps output")
    est = prior_estimate(renderer.skeleton_prior, flip_tested(renderer, scene, enc), scene["src_P"], renderer.height)
    return np.asarray(est.points, np.float32), np.asarray(est.expected_error_m, np.float32)


def cache_joints(data: str | Path, split: str, model: str | Path, out: str | Path, limit: int = 0,
                 precision: str = "int8", threads: int = 1, log=print) -> Path:
    """Estimate the joints of a split's first ``limit`` scenes (0: all) and write them to ``out`` (.npz)."""
    from training.data.torch_dataset import MultiViewDataset  # noqa: PLC0415
    from training.evaluate import OnnxRenderer  # noqa: PLC0415

    renderer = OnnxRenderer(model, precision, threads)
    ds = MultiViewDataset(data, split=split)
    n = _scenes(limit, len(ds))
    t0 = time.monotonic()
    joints, errors = [], []
    for i in range(n):
        scene = {k: v.numpy() for k, v in ds[i].items()}
        p, e = estimate_joints(renderer, scene)
        joints.append(p)
        errors.append(e)
        if (i + 1) % 256 == 0:
            log(f"  {split}: {i + 1}/{n} scenes, {time.monotonic() - t0:.0f} s")
    out = _write_cache(out, data, split, joints=np.stack(joints), expected_error_m=np.stack(errors),
                       index=np.arange(n, dtype=np.int32))
    log(f"{out}: joints of {n} {split} scenes in {time.monotonic() - t0:.0f} s")
    return out


def cache_true_joints(data: str | Path, split: str, out: str | Path, limit: int = 0, log=print) -> Path:
    """The dataset's own 3D joints of a split's first ``limit`` scenes, cached as :func:`cache_joints`
    caches a device's (invalid joints, which the dataset marks, are written as they are)."""
    from training.data.torch_dataset import MultiViewDataset  # noqa: PLC0415

    ds = MultiViewDataset(data, split=split)
    n = _scenes(limit, len(ds))
    joints = np.stack([ds[i]["joints_3d"].numpy() for i in range(n)]).astype(np.float32)
    out = _write_cache(out, data, split, joints=joints, expected_error_m=np.zeros(joints.shape[:2], np.float32),
                       index=np.arange(n, dtype=np.int32))
    log(f"{out}: true joints of {n} {split} scenes")
    return out


def _scenes(limit: int, available: int) -> int:
    """How many scenes ``limit`` asks for (0: all)."""
    if limit < 0:
        raise ValueError(f"limit must be 0 (all scenes) or more, not {limit}")
    return min(limit, available) if limit else available


def _write_cache(out: str | Path, data: str | Path, split: str, **arrays: np.ndarray) -> Path:
    """``arrays`` and their source (``split``, ``data``'s manifest hash) as the ``.npz`` file ``out`` (that very
    name), written whole: a temporary file in the same folder, then ``os.replace`` (an interrupted write leaves
    the old cache or the new one, never a cut one)."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    np.savez(buf, **arrays, split=np.str_(split), dataset_sha256=np.str_(sha256(Path(data) / "dataset.json")))
    return write_atomic(out, buf.getvalue())


def check_source(path: str | Path, data: str | Path, split: str) -> None:
    """Refuse a joints cache made from another split or dataset than ``data``'s ``split``: its joints are taken
    by scene index, so another split's would be paired with the wrong scenes without a word. A cache from
    before the fields (or made by hand without them) is taken as it is."""
    path = Path(path)
    try:
        with np.load(path) as z:
            made = {k: str(z[k]) for k in ("split", "dataset_sha256") if k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise JointsCacheError(f"{path}: not a joints cache ({e})") from e
    if made.get("split", split) != split:
        raise JointsCacheError(f"{path}: holds the joints of split {made['split']!r}, not {split!r}")
    want = sha256(Path(data) / "dataset.json")
    if made.get("dataset_sha256", want) != want:
        raise JointsCacheError(f"{path}: was made from another dataset than {data} (its dataset.json differs: "
                               "regenerated or another folder); make it again")


def _read(path: Path, key: str, what: str) -> np.ndarray:
    """One float64 array of a joints cache; a missing or damaged file (a cut one: ``BadZipFile``) or key is a
    :class:`JointsCacheError` naming the file."""
    try:
        with np.load(path) as z:
            return np.asarray(z[key], np.float64)
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as e:
        raise JointsCacheError(f"{path}: {what} ({e})") from e


def load_joints(path: str | Path, n: int = 0) -> np.ndarray:
    """The cached ``(N, 25, 3)`` joints; ``n``: how many scenes they must cover at least."""
    path = Path(path)
    joints = _read(path, "joints", "not a joints cache")
    if joints.ndim != 3 or joints.shape[1:] != (25, 3):
        raise JointsCacheError(f"{path}: joints have shape {joints.shape}, expected (N, 25, 3)")
    if len(joints) < n:
        raise JointsCacheError(f"{path}: holds {len(joints)} scenes, {n} asked for")
    return joints


def load_found(path: str | Path, n: int = 0, max_error_m: float | None = None) -> np.ndarray:
    """``(N, 25)`` bool: the cached joints the runtime reports (their expected error within ``max_error_m``,
    default the runtime's ``joints3d.max_prior_error_m``); the others it leaves out, as missing."""
    from ghnerf_runtime.config import Joints3DConfig  # noqa: PLC0415

    limit = Joints3DConfig().max_prior_error_m if max_error_m is None else max_error_m
    path = Path(path)
    errors = _read(path, "expected_error_m", "not a joints cache with expected errors")
    if errors.ndim != 2 or errors.shape[1] != 25 or len(errors) < n:
        raise JointsCacheError(f"{path}: expected_error_m has shape {errors.shape}, expected (N >= {n}, 25)")
    return errors <= limit


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--split", default="val")
    ap.add_argument("--limit", type=int, default=0, help="first N scenes (0: all)")
    ap.add_argument("--model", default="models/ghnerf", help="a model folder with a skeleton prior")
    ap.add_argument("--precision", choices=["fp32", "int8"], default="int8")
    ap.add_argument("--threads", type=at_least(1), default=1)
    ap.add_argument("--truth", action="store_true", help="cache the dataset's true joints instead (an oracle)")
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    if args.limit < 0:
        ap.error(f"--limit must be 0 (all scenes) or more, not {args.limit}")
    # a pass over every scene comes first: where its file goes (with the name savez writes) is settled now
    args.out = ready_output_arg(ap, args.out, "--out", suffix=".npz")
    from ghnerf_runtime.errors import RuntimeErrorBase  # noqa: PLC0415
    from training.data.errors import DataError  # noqa: PLC0415
    from training.evaluate import EvalInputError  # noqa: PLC0415

    try:  # a missing dataset or split, a model folder without its graphs or prior: one line naming it (were tracebacks)
        if args.truth:
            cache_true_joints(args.data, args.split, args.out, args.limit)
        else:
            cache_joints(args.data, args.split, args.model, args.out, args.limit, args.precision, args.threads)
    except (JointsCacheError, FileNotFoundError, DataError, EvalInputError, RuntimeErrorBase) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
