"""Counts on a command line (``--sequences``, ``--frames``, ``--repeats``, ghcal's ``--count``...): argparse types
that refuse what no run can use with the option's name and the value, before anything is loaded or rendered, in
one wording for every program (``must be a whole number >= 1, got '0'``). An unchecked ``type=int`` let ``--frames
-5`` or ``--repeats 0`` through to a traceback (numpy's "negative dimensions", an empty median, an index out of
range) after the model and the sequences were loaded, or to a run of nothing.

A count is ASCII digits (a sign and spaces around them allowed): ``int()`` also takes other scripts' digits
(``'٣'``, full-width ``'３'``) and ``'1_000'``, which ran as a count the command line does not show to most readers,
an input method's slip taken for a number."""
from __future__ import annotations

import argparse
import re
from collections.abc import Callable

__all__ = ["ascii_integer", "bounded_count", "image_size", "non_negative_count", "positive_count",
           "positive_count_list", "seed_list", "whole_number"]

_SIGNED_DIGITS = re.compile(r"[+-]?[0-9]+")


def whole_number(text: str, least: int, most: int | None = None) -> int:
    """``text`` as a whole number from ``least`` (to ``most``, where given), or argparse's usage error naming the
    value: ``must be a whole number >= 1, got '0'``, ``must be a whole number from 1 to 100, got '101'``."""
    value = _ascii_digits(text)
    if value is None or value < least or (most is not None and value > most):
        bounds = f">= {least}" if most is None else f"from {least} to {most}"
        raise argparse.ArgumentTypeError(f"must be a whole number {bounds}, got {text!r}")
    return value


def ascii_integer(text: str) -> int:
    """A whole number of any sign and size in ASCII digits (:func:`whole_number`'s reading, for a caller with its
    own bounds and words: ``config_field``, ``training.cli.at_least``), or ValueError (argparse's kind) naming the
    value."""
    value = _ascii_digits(text)
    if value is None:
        raise ValueError(f"not a whole number, got {text!r}")
    return value


def _ascii_digits(text: str) -> int | None:
    """``text`` (a sign and spaces around allowed) as an int where it is ASCII digits, else None."""
    stripped = text.strip()
    if not _SIGNED_DIGITS.fullmatch(stripped):
        return None
    try:
        return int(stripped)
    except ValueError:  # past int()'s 4300 digits
        return None


def positive_count(text: str) -> int:
    """An argparse ``type=`` for a count of which one at least is needed (sequences, pairs, rounds)."""
    return whole_number(text, 1)


def non_negative_count(text: str) -> int:
    """An argparse ``type=`` for a count where 0 means none (warm-up pairs, ``--limit 0``: all)."""
    return whole_number(text, 0)


def bounded_count(least: int, most: int) -> Callable[[str], int]:
    """An argparse ``type=`` for a count from ``least`` to ``most`` (ghcal's views: a mistyped ``--count
    100000000`` rendered until the disk was full)."""
    def count(text: str) -> int:
        return whole_number(text, least, most)
    return count


def seed_list(text: str) -> list[int]:
    """An argparse ``type=`` for ``--seeds 0,1,2``: one seed at least, each a whole number >= 0 (``--seeds x`` was
    int()'s "invalid literal" traceback)."""
    return _count_list(text, 0)


def positive_count_list(text: str) -> list[int]:
    """An argparse ``type=`` for ``--threads 1,2``: one count at least, each a whole number >= 1 (``--threads x``
    was int()'s "invalid literal" traceback, ``--threads 0`` torch's once the dataset was read)."""
    return _count_list(text, 1)


def _count_list(text: str, least: int) -> list[int]:
    """``text``'s comma-separated whole numbers, each from ``least``, or one usage error naming the whole list."""
    try:
        return [whole_number(part, least) for part in text.split(",")]
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"must be comma-separated whole numbers >= {least}, got {text!r}") from None


def image_size(text: str) -> tuple[int, int]:
    """An argparse ``type=`` for ``--size 640x480``: (width, height), each a whole number >= 1 (``--size
    not-a-size`` was a ValueError traceback from unpacking ``split("x")``, ``--size 0x0`` OpenCV's)."""
    parts = text.lower().split("x")
    try:
        if len(parts) != 2:
            raise argparse.ArgumentTypeError(text)
        width, height = (whole_number(part, 1) for part in parts)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"must be WIDTHxHEIGHT in pixels, each >= 1 (as 640x480), got {text!r}") \
            from None
    return width, height
