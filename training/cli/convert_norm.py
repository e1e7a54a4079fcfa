"""``python -m training.convert_norm``'s command line (torch-free; ``training.convert_norm`` runs it)."""
from __future__ import annotations

import argparse

from training.cli import doc_of, parse_then_run


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m training.convert_norm",  # not "convert_norm.py"
                                 description=doc_of("training.convert_norm").split("\n\n")[0])
    ap.add_argument("src", help="a .pt checkpoint trained with features.norm = 'batch'")
    ap.add_argument("dst", help="where to write the converted checkpoint")
    return ap


def main(argv: list[str] | None = None) -> int:
    return parse_then_run(build_parser, "training.convert_norm", argv)


if __name__ == "__main__":  # `python -m training.cli.convert_norm`, the module pyproject names: it ran nothing, exit 0
    raise SystemExit(main())
