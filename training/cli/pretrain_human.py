"""``python -m training.pretrain_human``'s command line (torch-free; ``training.pretrain_human`` runs it)."""
from __future__ import annotations

import argparse

from training.cli import at_least, doc_of, parse_then_run


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m training.pretrain_human",
                                 description=doc_of("training.pretrain_human").split("\n\n")[0])
    ap.add_argument("--config", help="JSON file: a PretrainConfig, or a train config with a 'pretrain_human' block")
    ap.add_argument("--out", help="run folder (required unless --score; not a model folder of *.onnx graphs)")
    ap.add_argument("--score", metavar="HUMAN_PT", help="only score this human.pt's heatmaps on --split "
                                                         "(--data, default data/edge128; --scenes, default all)")
    ap.add_argument("--split", help="with --score: the split scored (default val); the pretraining reads its "
                                    "config's split (--set split=NAME)")
    ap.add_argument("--scenes", type=at_least(0), help="with --score: the first N scenes (0, the default: all)")
    ap.add_argument("--resume", action="store_true",
                    help="continue from OUT/last.pt (from OUT/prev.pt when last.pt is missing or damaged); without "
                         "--resume an OUT holding checkpoints is refused")
    ap.add_argument("--data")
    ap.add_argument("--iterations", type=at_least(1))
    ap.add_argument("--threads", type=at_least(0), help="torch CPU threads (0: every core)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--quiet", action="store_true")
    return ap


#: The options of one mode each: given to the other they were ignored without a word (``--out RUN --split
#: train`` pretrained on the config's split; ``--score HUMAN_PT --iterations 10`` scored and trained nothing).
SCORE_ONLY = ("split", "scenes")
TRAINING_ONLY = ("config", "out", "resume", "iterations", "set")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The arguments, an option of the other mode (``--score`` or a pretraining) refused as a usage error."""
    ap = build_parser()
    args = ap.parse_args(argv)
    given = [name for name in (TRAINING_ONLY if args.score else SCORE_ONLY)
             if getattr(args, name) not in (None, False, [])]
    if given:
        options = ", ".join(f"--{name}" for name in given)
        ap.error(f"{options}: not read with --score HUMAN_PT, which only scores it" if args.score else
                 f"{options}: read only with --score HUMAN_PT; the pretraining's split is its config's "
                 "(--set split=NAME)")
    return args


def main(argv: list[str] | None = None) -> int:
    parse_args(argv)  # a usage error before torch loads
    return parse_then_run(build_parser, "training.pretrain_human", argv)


if __name__ == "__main__":  # `python -m training.cli.pretrain_human`, the module pyproject names: it ran nothing, exit 0
    raise SystemExit(main())
