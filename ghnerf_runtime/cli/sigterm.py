"""SIGTERM stops a command-line tool as Ctrl-C does: one helper for ``ghnerf-run``, ``ghnerf-listen``, ``ghcal``,
``ghnerf-demo``, ``ghnerf-train``, the human-encoder pretraining, ``ghnerf-eval``, the dataset generator and the
ZJU-MoCap conversion.

SIGTERM's default action (``timeout``, ``kill``, a wrapper's stop button, systemd) kills the process outright:
no ``finally`` runs, so a tool's outputs are left half-written (a ``record+`` take stays ``complete: false``)
and nothing is said. Inside :func:`sigterm_as_interrupt` the signal raises :class:`Terminated`, a
:class:`KeyboardInterrupt`, in the main thread, where Ctrl-C raises its own: every ``except KeyboardInterrupt``
and ``finally`` a tool has for Ctrl-C handles SIGTERM too, and :func:`stop_signal` tells the two apart for the
exit status (128 + the signal's number: 130, 143, the shell's figures) and the message (:func:`stop_words`).
:func:`stop_signals_deferred`, the one helper for work that must finish, holds both back over it (a second Ctrl-C
pressed while a stopped run writes its outputs: ``ghnerf-run``'s files, ``ghnerf-demo``'s sink and take, ``ghcal
capture``'s cameras; with ``only_raising``, a training checkpoint and a ZJU split's swap).
:func:`stop_signals_noted` holds them over the stretch from ``ghnerf-demo``'s or ``ghcal capture``'s reading to its
take's close, handing each stop to the caller to raise once the take is closed and checked.

The daemon does not use it: a handler that raises can land anywhere in its loop, inside a lock its threads share
(``firmware_host.daemon.cli._StopOnSignal`` says why), and it must close its sinks in order and tell systemd it
is stopping; its handler only wakes a thread that sets a stop event.
"""
from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator


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
def stop_signals_deferred(*, then_raise: bool = True, only_raising: bool = False) -> Iterator[None]:
    """Within the block Ctrl-C (SIGINT) and SIGTERM are noted, not raised, so that what must finish is written
    whole: the outputs a stopped run closes when the user presses Ctrl-C again (a second Ctrl-C landing in
    ``ghnerf-run``'s write of its ``.json`` list lost every pair of it), a recorder's close rewriting its manifest
    ``complete: true``. The handlers before it are put back as it ends, however it ends. A signal ignored before
    the block (``SIG_IGN``) is not noted: it stays ignored.

    ``then_raise``: the first signal noted is raised once the block has ended normally (:class:`KeyboardInterrupt`
    or :class:`Terminated`); pass False where the block runs while a stop or an error is already on its way, which
    is then the one reported. ``only_raising``: for a library's step (a checkpoint write, a dataset split's two
    renames), hold only the signals that would raise now, Ctrl-C under Python's own handler and SIGTERM inside
    :func:`sigterm_as_interrupt`, leaving a caller's own handling of either (SIGTERM's default kill) alone.
    Outside the main thread nothing is installed, as for :func:`sigterm_as_interrupt`.
    """
    signums = (signal.SIGINT, signal.SIGTERM)
    if only_raising:
        signums = tuple(signum for signum in signums if _raises_now(signum))
    with _signals_held(signums, then_raise=then_raise):
        yield


@contextlib.contextmanager
def stop_signals_noted(stops: list[KeyboardInterrupt]) -> Iterator[None]:
    """Within the block Ctrl-C and SIGTERM are noted, never raised: each is added to ``stops`` as the
    :class:`KeyboardInterrupt` (or :class:`Terminated`) it would have raised, once the block has ended, however it
    ends. For the stretch between a run's reading and its close (``ghnerf-demo``, ``ghcal capture``): a first stop
    landing there, before the close's own deferral, was raised past the close (a ``record+`` take left
    ``complete: false``); noted, it is the caller's to raise once the take is closed and checked. One ignored before
    the block is not noted (:func:`stop_signals_deferred`). Outside the main thread nothing is installed, as for
    :func:`sigterm_as_interrupt`."""
    noted: list[int] = []
    try:
        with _signals_held((signal.SIGINT, signal.SIGTERM), then_raise=False, noted=noted):
            yield
    finally:
        stops.extend(_stop_raised_by(signum) for signum in noted)


def closed_with_stops_deferred(close: Callable[[], None], *, then_raise: bool) -> KeyboardInterrupt | None:
    """``close()`` inside :func:`stop_signals_deferred`; the stop it raises once the close is done (``then_raise``)
    is returned, not raised, so that the caller checks what the close left first (a ``record+`` take that failed
    as it closed is said, exit 2, rather than the stop's 130 or 143: ``ghnerf-demo``, ``ghcal capture``).

    A stop landing before the handlers that hold it are in place (as the block is entered) is taken as one in the
    close: the close is still run, its stops held, and that stop returned when ``then_raise``; returned at once, it
    skipped the close (a ``record+`` take left ``complete: false``)."""
    closing = False
    try:
        with stop_signals_deferred(then_raise=then_raise):
            closing = True
            close()
    except KeyboardInterrupt as e:
        if closing:  # raised once the close was done
            return e
        early = e
    else:
        return None
    with stop_signals_deferred(then_raise=False):
        close()
    return early if then_raise else None


def _raises_now(signum: signal.Signals) -> bool:
    """Whether ``signum`` would raise a :class:`KeyboardInterrupt` now (Python's own Ctrl-C handler, ours for
    SIGTERM)."""
    if signum == signal.SIGINT:
        return signal.getsignal(signal.SIGINT) is signal.default_int_handler
    return sigterm_raises()


@contextlib.contextmanager
def _signals_held(signums: tuple[signal.Signals, ...], *, then_raise: bool,
                  noted: list[int] | None = None) -> Iterator[None]:
    """``signums`` noted (into ``noted`` where given), not raised, within the block; their handlers before it put
    back as it ends, however it ends; the first noted raised after a block that ended normally when ``then_raise``.
    Nothing is installed outside the main thread (:func:`sigterm_as_interrupt`)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    noted = [] if noted is None else noted
    previous = {signum: signal.getsignal(signum) for signum in signums}
    _install_noting(signums, noted, previous)
    try:
        yield
    finally:
        _put_back(previous)
    if noted and then_raise:  # after the block, not in its finally: an error the block raised is the one reported
        raise _stop_raised_by(noted[0])


def _stop_raised_by(signum: int) -> KeyboardInterrupt:
    """What ``signum`` raises in a tool: :class:`Terminated` for SIGTERM, :class:`KeyboardInterrupt` for Ctrl-C."""
    name = signal.Signals(signum).name
    return Terminated(name) if signum == signal.SIGTERM else KeyboardInterrupt(name)


def _install_noting(signums: tuple[signal.Signals, ...], noted: list[int],
                    previous: dict[signal.Signals, object]) -> None:
    """Each of ``signums`` noted into ``noted`` from now on. A stop that lands while the handlers go in (SIGTERM
    after SIGINT's is set, run by its handler before ours) is noted as if it came a moment later and the
    installing goes on: raised out of here it would skip the block (``closed_with_stops_deferred``'s close) and
    leave the handlers already set in place. Any other error puts ``previous`` back and is raised."""
    def note(got: int, _frame: object) -> None:
        # one ignored before (a script's background job: ``ghnerf-demo ... &``) stays ignored: noted, it was raised
        # after the block, the Ctrl-C meant for the script ending the tool (130)
        if previous.get(got) is not signal.SIG_IGN:
            noted.append(got)

    waiting = list(signums)
    try:
        while waiting:
            try:
                signal.signal(waiting[0], note)
            except KeyboardInterrupt as e:
                noted.append(stop_signal(e))
                continue  # setting a handler twice is harmless: the raise may have come before or after it was set
            waiting.pop(0)
    except BaseException:
        _put_back(previous)
        raise


def _put_back(previous: dict[signal.Signals, object]) -> None:
    """The handlers in ``previous`` set again; None (a handler not set from Python) as the default."""
    for signum, handler in previous.items():
        signal.signal(signum, signal.SIG_DFL if handler is None else handler)
