"""A checkpoint whose image feature network used BatchNorm -> the same weights with scene normalisation.

    python -m training.convert_norm runs/old/edge128/last.pt runs/old/edge128/last_scene.pt

The trainer runs one scene per step, so every BatchNorm of the image feature network normalised
with the statistics of that scene's two source images: a network trained that way *is* a
``norm = "scene"`` network (``training.model.layers.SceneNorm2d``), and BatchNorm's running
averages, which inference used, are a different function that cost a run of the seventh model's
recipe 5.3 dB of PSNR at its source cameras (docs/training.md, "Scene normalisation"). This
rewrites the stored model config and drops the running statistics; the learnt weights are
untouched. The output is loadable
wherever a checkpoint is (``ghnerf-eval``, ``python -m training.export``) and evaluates the model
as it was trained. Other BatchNorms (the human encoder's, the 3D regulariser's) are left as they are:
the human encoder is pretrained on batches that mix scenes, and the 3D ones measured no difference.
"""
from __future__ import annotations

if __name__ == "__main__":  # python -m: the arguments are parsed before torch loads (training.cli)
    from training.cli.convert_norm import main as _cli_main

    raise SystemExit(_cli_main())

import io
import pickle
import sys
from pathlib import Path

import torch

from training.model import ModelConfig
from training.model_card import write_atomic

RUNNING_KEYS = ("running_mean", "running_var", "num_batches_tracked")


def to_scene_norm(checkpoint: dict) -> dict:
    """A copy of a trainer or weights-only checkpoint dict with ``features.norm = "scene"``.

    Raises:
        ValueError: the checkpoint carries no model config, or its feature network has no BatchNorm.
    """
    if "model_config" not in checkpoint:
        raise ValueError("the checkpoint has no 'model_config' (not made by the trainer or the pipeline)")
    mcfg = ModelConfig.from_dict(checkpoint["model_config"])
    if mcfg.features.norm != "batch":
        raise ValueError(f"the image feature network's norm is {mcfg.features.norm!r}, not 'batch'")
    mcfg.features.norm = "scene"
    out = dict(checkpoint)
    out["model_config"] = mcfg.to_dict()
    state = checkpoint.get("model", checkpoint)
    kept = {k: v for k, v in state.items()
            if not (k.startswith("feature_net.") and k.rsplit(".", 1)[-1] in RUNNING_KEYS)}
    if "model" in checkpoint:
        out["model"] = kept
    else:
        out = {**kept, "model_config": out["model_config"]}
    return out


def write_checkpoint(checkpoint: dict, dst: Path) -> None:
    """``checkpoint`` saved to ``dst`` whole or not at all (``write_atomic``): a full disk or Ctrl-C halfway
    through left a cut file under the name, replacing what was there (``dst`` may be an earlier conversion)."""
    buf = io.BytesIO()
    torch.save(checkpoint, buf)
    dst.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(dst, buf.getvalue())


def main(argv: list[str] | None = None) -> int:
    from training.cli.convert_norm import build_parser  # noqa: PLC0415

    ap = build_parser()
    args = ap.parse_args(argv)
    src, dst = Path(args.src), Path(args.dst)
    if src.resolve() == dst.resolve():
        print(f"convert_norm: {dst} is the input; write the converted checkpoint elsewhere", file=sys.stderr)
        return 2
    try:
        ck = torch.load(str(src), map_location="cpu", weights_only=False)
    # a file that is no torch checkpoint: pickle's and EOFError were tracebacks
    except (OSError, RuntimeError, ValueError, EOFError, pickle.UnpicklingError) as e:
        print(f"convert_norm: {src}: not a readable checkpoint ({type(e).__name__}: {e})", file=sys.stderr)
        return 2
    try:
        if not isinstance(ck, dict):
            raise ValueError(f"holds a {type(ck).__name__}, not a checkpoint dict")
        converted = to_scene_norm(ck)
    except ValueError as e:
        print(f"convert_norm: {src}: {e}", file=sys.stderr)
        return 2
    try:
        write_checkpoint(converted, dst)
    except OSError as e:
        print(f"convert_norm: {dst}: cannot write the converted checkpoint ({e.strerror or e}); "
              f"{'the file there is as it was' if dst.exists() else 'nothing was written'}", file=sys.stderr)
        return 1
    print(f"{src} -> {dst}: image feature network normalised by scene statistics")
    return 0

