"""Numbers on a command line (``--scale 1.2``, ``--margins 0.04,0.06``, ``--input-scales 0.5,1.0``): argparse
types that refuse what is not a finite number with the value, in the counts' words (``must be a number, got 'x'``,
:mod:`ghnerf_runtime.cli.counts`). A ``type=`` lambda or a bare list of ``float()`` was argparse's generic
``invalid <lambda> value: 'x'`` or a ValueError traceback.

A number is ASCII (a sign, digits with one point, an exponent: ``-0.2``, ``1e-3``): ``float()`` also takes other
scripts' digits (``'٣'``, full-width ``'３'``), ``'1_0'``, ``'nan'`` and ``'inf'``, which ran as a value the command
line does not show to most readers, or as a NaN through every figure."""
from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable

__all__ = ["finite_number", "number_list", "number_or", "optional_number_list"]

_DECIMAL = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")


def finite_number(text: str) -> float:
    """An argparse ``type=`` for a finite number in ASCII digits (``1e999``, which float() reads as inf, refused)."""
    stripped = text.strip()
    value = float(stripped) if _DECIMAL.fullmatch(stripped) else math.nan
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}")
    return value


def number_list(text: str) -> list[float]:
    """An argparse ``type=`` for ``--margins 0.04,0.06``: one number at least, each :func:`finite_number`'s."""
    try:
        return [finite_number(part) for part in text.split(",")]
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"must be comma-separated numbers, got {text!r}") from None


def optional_number_list(text: str) -> list[float]:
    """:func:`number_list`, where an empty value (``--angles ''``, the default of an option that is off) is none."""
    return [] if not text.strip() else number_list(text)


def number_or(word: str) -> Callable[[str], float | None]:
    """An argparse ``type=`` for a number or ``word``, which reads as None (``--scale fit``)."""
    def parse(text: str) -> float | None:
        if text.strip() == word:
            return None
        try:
            return finite_number(text)
        except argparse.ArgumentTypeError:
            raise argparse.ArgumentTypeError(f"must be a number or {word!r}, got {text!r}") from None

    return parse
