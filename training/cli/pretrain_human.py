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
    ap.add_argument("--split", default="val")
    ap.add_argument("--scenes", type=at_least(0), default=0, help="with --score: the first N scenes (0: all)")
    ap.add_argument("--resume", action="store_true",
                    help="continue from OUT/last.pt (from OUT/prev.pt when last.pt is missing or damaged); without "
                         "--resume an OUT holding checkpoints is refused")
    ap.add_argument("--data")
    ap.add_argument("--iterations", type=at_least(1))
    ap.add_argument("--threads", type=at_least(0), help="torch CPU threads (0: every core)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--quiet", action="store_true")
    return ap


def main(argv: list[str] | None = None) -> int:
    return parse_then_run(build_parser, "training.pretrain_human", argv)


if __name__ == "__main__":  # `python -m training.cli.pretrain_human`, the module pyproject names: it ran nothing, exit 0
    raise SystemExit(main())
