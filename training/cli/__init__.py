"""The training tools' command lines, torch-free: ``--help`` and usage errors answer before torch loads.

torch takes about 3 s to import; every tool whose module imports it at the top (``training.train``,
``training.evaluate``, ``training.pretrain_human``, ``training.convert_norm``, ``training.learnt_fill``) has its
parser here, and its console script (``ghnerf-train``, ``ghnerf-eval``) or ``python -m`` guard runs
:func:`parse_then_run`: the arguments are parsed first, then the tool's module is imported and its ``main``
runs as before (parsing them again, cheaply). ``python -m training.export`` needs none of this: its
``cli`` module loads torch inside ``main``.
"""
from __future__ import annotations

import argparse
import ast
import importlib
import importlib.util
from collections.abc import Callable
from pathlib import Path

from ghnerf_runtime.cli.counts import ascii_integer


def doc_of(module: str) -> str:
    """The docstring of ``module``, read from its source without importing it (the tool's own help text)."""
    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        raise ModuleNotFoundError(module)
    return ast.get_docstring(ast.parse(Path(spec.origin).read_text(encoding="utf-8"))) or ""


def at_least(minimum: int) -> Callable[[str], int]:
    """An argparse ``type``: an integer of at least ``minimum`` (argparse names the option with the message)."""
    def parse(text: str) -> int:
        try:
            value = ascii_integer(text)  # int() also took '\u0663' and '1_0'
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {value}")
        return value

    return parse


def parse_then_run(build_parser: Callable[[], argparse.ArgumentParser], module: str,
                   argv: list[str] | None = None) -> int:
    """Parse ``argv`` with ``build_parser()`` (``--help`` or a usage error exits here, torch never loaded), then
    run ``module``'s ``main(argv)``."""
    build_parser().parse_args(argv)
    return importlib.import_module(module).main(argv)


__all__ = ["at_least", "doc_of", "parse_then_run"]
