"""Counts on a command line (``--sequences``, ``--frames``, ``--repeats``...): argparse types that refuse what
no run can use with the option's name and the value, before anything is loaded or rendered. An unchecked
``type=int`` let ``--frames -5`` or ``--repeats 0`` through to a traceback (numpy's "negative dimensions", an
empty median, an index out of range) after the model and the sequences were loaded, or to a run of nothing."""
from __future__ import annotations

import argparse

__all__ = ["image_size", "non_negative_count", "positive_count", "positive_count_list", "seed_list"]


def _whole_number(text: str, least: int) -> int:
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or value < least:
        raise argparse.ArgumentTypeError(f"must be a whole number >= {least}, got {text!r}")
    return value


def positive_count(text: str) -> int:
    """An argparse ``type=`` for a count of which one at least is needed (sequences, pairs, rounds)."""
    return _whole_number(text, 1)


def non_negative_count(text: str) -> int:
    """An argparse ``type=`` for a count where 0 means none (warm-up pairs, ``--limit 0``: all)."""
    return _whole_number(text, 0)


def seed_list(text: str) -> list[int]:
    """An argparse ``type=`` for ``--seeds 0,1,2``: one seed at least, each a whole number >= 0 (``--seeds x`` was
    int()'s "invalid literal" traceback)."""
    parts = [part.strip() for part in text.split(",")]
    if not all(part.isdecimal() for part in parts):  # isdigit() passes "²", which int() refuses
        raise argparse.ArgumentTypeError(f"must be comma-separated whole numbers >= 0, got {text!r}")
    return [int(part) for part in parts]


def positive_count_list(text: str) -> list[int]:
    """An argparse ``type=`` for ``--threads 1,2``: one count at least, each a whole number >= 1 (``--threads x``
    was int()'s "invalid literal" traceback, ``--threads 0`` torch's once the dataset was read)."""
    parts = [part.strip() for part in text.split(",")]
    if not all(part.isdecimal() and int(part) >= 1 for part in parts):
        raise argparse.ArgumentTypeError(f"must be comma-separated whole numbers >= 1, got {text!r}")
    return [int(part) for part in parts]


def image_size(text: str) -> tuple[int, int]:
    """An argparse ``type=`` for ``--size 640x480``: (width, height), each a whole number >= 1 (``--size
    not-a-size`` was a ValueError traceback from unpacking ``split("x")``, ``--size 0x0`` OpenCV's)."""
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(part.strip().isdecimal() and int(part) >= 1 for part in parts):
        raise argparse.ArgumentTypeError(f"must be WIDTHxHEIGHT in pixels, each >= 1 (as 640x480), got {text!r}")
    return int(parts[0]), int(parts[1])
