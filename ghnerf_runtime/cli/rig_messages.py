"""The rig file's notes shown where a tool reads or writes a rig, as its warnings are.

Loading a rig logs its warnings at WARNING and its notes at INFO (``rig_file.rig_notes``: a standing person partly
out of the pair's views, which the shipped ``ghcal synth`` rig must load without a warning for; since session 69 one
cut at the working volume's near or far edge, ``rig_file.volume_edge_notes``). Python shows
WARNING and over where no logging is set up, and ``ghnerf-run`` sets it up so: the notes were dropped by ``ghcal``,
by ``ghnerf-run`` without ``--verbose`` and by ``ghnerf-daemon --validate-config``, the places a user mounting a rig
looks. The daemon itself logs at INFO by default (``log_level``), so its rig source's note is shown at its start.

The helpers, by the way a tool shows its log:

- :func:`rig_messages_on_stderr`: a tool that sets no logging up (``ghcal``, ``ghnerf-daemon --validate-config``):
  each warning and note on stderr as its bare message, as Python's last-resort handler prints the warnings.
  :func:`log_on_stderr` does the same for another logger: a rig source's (``drivers.base``), which logs at its open
  what it warns and notes of its rig (``ghcal capture``; ``--validate-config`` of a ``sim://`` rig, built in memory).
- :func:`rig_notes_let_through`: a tool whose logging is set up to show WARNING and over (``ghnerf-run``): the notes
  go out through that set-up's handler, in its format, beside the warnings.
"""
from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Iterator

from ghnerf_runtime.rig_file import log as rig_file_log

__all__ = ["log_on_stderr", "rig_messages_on_stderr", "rig_notes_let_through"]


@contextlib.contextmanager
def rig_notes_let_through(logger: logging.Logger = rig_file_log) -> Iterator[None]:
    """``logger`` (the rig file's: load_rig's and read_manifest's, a take's rig) passes INFO (its notes) while
    inside, its own level put back after: the notes then reach the handlers the tool set up, however high the root
    logger's level."""
    level = logger.level
    logger.setLevel(logging.INFO)
    try:
        yield
    finally:
        logger.setLevel(level)


@contextlib.contextmanager
def log_on_stderr(logger: logging.Logger) -> Iterator[None]:
    """``logger``'s records of INFO and over on stderr while inside, each once as its bare message."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))  # as Python's last-resort handler prints the warnings
    propagate = logger.propagate
    logger.addHandler(handler)
    # not passed on as well: a handler above (the root logger's, from a caller's logging set-up or pytest's caplog)
    # printed each line a second time, in its own format
    logger.propagate = False
    try:
        with rig_notes_let_through(logger):
            yield
    finally:
        logger.propagate = propagate
        logger.removeHandler(handler)


def rig_messages_on_stderr() -> contextlib.AbstractContextManager[None]:
    """The rig file's warnings and notes on stderr while inside, each once as its bare message."""
    return log_on_stderr(rig_file_log)
