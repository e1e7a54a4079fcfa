"""``--seconds``-like options: one argparse type, so that ``ghnerf-demo`` and ``ghnerf-listen`` take and refuse the
same values in the same words (each had its own copy, worded apart)."""
from __future__ import annotations

import argparse

from ghnerf_runtime.cli.numbers import finite_number

__all__ = ["positive_seconds"]


def positive_seconds(text: str) -> float:
    """An argparse ``type=`` for a duration in seconds: a finite number > 0. ``-1`` or ``nan`` read no pair (the
    demo) or ended the listening before it began (the listener), and said all was well; ``inf`` never ends. The
    function's own name stays out of the message: argparse's default said "invalid positive_seconds value". Read as
    :func:`~ghnerf_runtime.cli.numbers.finite_number` reads a number: float() took other scripts' digits and '1_0'."""
    try:
        value = finite_number(text)
    except argparse.ArgumentTypeError:
        value = 0.0
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds > 0, got {text!r}")
    return value
