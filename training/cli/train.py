"""``ghnerf-train``'s command line (torch-free; ``training.train`` runs it)."""
from __future__ import annotations

import argparse

from training.cli import doc_of, parse_then_run
from training.configs import PRESETS
from ghnerf_runtime.path_check import user_path


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="ghnerf-train", description=doc_of("training.train").split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", type=user_path, help="JSON or TOML train config (training/train_configs/*.json)")
    p.add_argument("--out", type=user_path, required=True, help="run folder: checkpoints, log.jsonl, config.json "
                   "(not a model folder of *.onnx graphs: refused)")
    p.add_argument("--resume", action="store_true",
                   help="continue from OUT/last.pt (without it, the newest OUT/ckpt_*.pt) when it exists; "
                        "without --resume an OUT holding checkpoints is refused")
    p.add_argument("--init", type=user_path, help="torchvision resnet18 state dict for the human encoder")
    p.add_argument("--preset", choices=sorted(PRESETS))
    p.add_argument("--data", type=user_path)
    p.add_argument("--iterations", type=int)
    p.add_argument("--threads", type=int)
    p.add_argument("--seed", type=int)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override any config key (dotted for nested, JSON value), e.g. --set loss.heat_weight=0.5")
    p.add_argument("--validate-config", action="store_true", help="check the config and exit")
    p.add_argument("--quiet", action="store_true")
    return p


def main(argv: list[str] | None = None) -> int:
    """The ``ghnerf-train`` console script."""
    return parse_then_run(build_parser, "training.train", argv)


if __name__ == "__main__":  # `python -m training.cli.train`, the module pyproject names: it ran nothing, exit 0
    raise SystemExit(main())
