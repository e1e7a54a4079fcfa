"""SIGTERM stops a command-line tool as Ctrl-C does: one helper for ``ghnerf-run``, ``ghnerf-listen``, ``ghcal``,
``ghnerf-demo``, ``ghnerf-train``, the human-encoder pretraining, ``ghnerf-eval`` and the dataset generator.

SIGTERM's default action (``timeout``, ``kill``, a wrapper's stop button, systemd) kills the process outright:
no ``finally`` runs, so a tool's outputs are left half-written (a ``record+`` take stays ``complete: false``)
and nothing is said. Inside :func:`sigterm_as_interrupt` the signal raises :class:`Terminated`, a
:class:`KeyboardInterrupt`, in the main thread, where Ctrl-C raises its own: every ``except KeyboardInterrupt``
and ``finally`` a tool has for Ctrl-C handles SIGTERM too, and :func:`stop_signal` tells the two apart for the
exit status (128 + the signal's number: 130, 143, the shell's figures) and the message (:func:`stop_words`). :func:`sigterm_deferred`
holds one back over a close that must finish (a recorder rewriting its manifest ``complete: true``).

The daemon does not use it: a handler that raises can land anywhere in its loop, inside a lock its threads share
(``firmware_host.daemon.cli._StopOnSignal`` says why), and it must close its sinks in order and tell systemd it
is stopping; its handler only wakes a thread that sets a stop event.
"""
from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Ctrl-C raises KeyboardInterrupt; its own type tells the two apart."""


def _raise_terminated(signum: int, _frame: object) -> None:
    raise Terminated(signal.Signals(signum).name)


def stop_signal(e: KeyboardInterrupt) -> signal.Signals:
    """The signal that stopped a command: SIGTERM where :func:`sigterm_as_interrupt` raised ``e``, else Ctrl-C's."""
    return signal.SIGTERM if isinstance(e, Terminated) else signal.SIGINT


def stop_words(e: KeyboardInterrupt) -> str:
    """How a tool's message names the stop: ``Ctrl-C`` for a user's, the signal's name (``SIGTERM``) for one from
    outside, which the user did not type."""
    return "Ctrl-C" if stop_signal(e) == signal.SIGINT else stop_signal(e).name


def exit_status(e: KeyboardInterrupt) -> int:
    """The shell's figure for a death by the signal that raised ``e``: 130 (Ctrl-C), 143 (SIGTERM)."""
    return 128 + stop_signal(e).value


def sigterm_raises() -> bool:
    """Whether a SIGTERM would raise :class:`Terminated` now (inside :func:`sigterm_as_interrupt`): a write that
    must finish (a training checkpoint) holds it back only then, and leaves a library caller's handling alone."""
    return signal.getsignal(signal.SIGTERM) is _raise_terminated


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Within the block SIGTERM raises :class:`Terminated` in the main thread; the handler before it is put back
    on the way out, however the block ends.

    Outside the main thread nothing is installed (Python runs signal handlers in the main thread only and
    refuses to set one from another; a tool's ``main`` called from a test's thread or a caller's worker leaves
    the process's handling as it was).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        # None: the handler before was not set from Python (it cannot be put back); the default is the safe one,
        # ours left in place would raise outside any block meant to catch it
        signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)


@contextlib.contextmanager
def sigterm_deferred() -> Iterator[None]:
    """Within the block a SIGTERM is noted, not raised: a close that must finish (a recorder fsyncing its take
    and rewriting the manifest ``complete: true``) is not torn by one that lands in it, as ``timeout``'s does
    when a run's own end comes at about its time. :class:`Terminated` is raised once the block has ended, the
    handler before it put back first. Outside the main thread nothing is installed, as for
    :func:`sigterm_as_interrupt`.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    noted: list[int] = []
    previous = signal.signal(signal.SIGTERM, lambda signum, _frame: noted.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)
    if noted:  # after the block, not in its finally: an error the block raised is the one reported
        raise Terminated(signal.Signals(noted[0]).name)
