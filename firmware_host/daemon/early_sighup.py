"""SIGHUP recorded from the start of ``ghnerf-daemon``, before the heavy imports and the config read.

SIGHUP's default action kills the process, and systemd (``Restart=on-failure``) counts a death by
SIGHUP as clean: a ``systemctl reload`` (or any stray SIGHUP) landing while the daemon still imports
onnxruntime and OpenCV, reads its config or loads its model would leave the service dead. So the
package installs :func:`_record` as the handler first thing when the process is ``ghnerf-daemon``
(imports only the standard library's ``os``, ``signal`` and ``sys``), and :func:`cli.main` installs
it too, for any other caller. It only sets a flag. :func:`cli.main` clears the flag (:func:`take`)
just before it reads the config file (a request before that read is met by the read itself) and,
once the daemon's own handler is in place, turns a request recorded since into a reload
(:meth:`Daemon.request_reload`): the file may have changed after it was read.

SIGTERM and SIGINT, likewise, from the package's first import in ``ghnerf-daemon`` (:func:`install_stop`): a
``systemctl stop`` landing while Python imported the runtime killed the process (status 143, no log line), and
Ctrl-C there printed a KeyboardInterrupt traceback. The first one is recorded; the daemon's own stop handlers
(``cli._StopOnSignal``) take it (:func:`take_stop`) as they are installed, after the config read, and stop as for
a signal of their own. ``--validate-config``, which installs none, puts back what was there (:func:`release_stop`)
and meets a recorded one as it would have been met; so does any run that ends without them (``cli.main``'s exit:
``--print-example-config``, a usage error, a config the start refused).

What is left: the interpreter's own start-up, before this module runs (tens of milliseconds), where
only the unit's ``RestartForceExitStatus=SIGHUP`` helps (and a stop there kills as before).
"""
from __future__ import annotations

import os
import signal
import sys

__all__ = ["install", "uninstall", "take", "is_daemon_process", "install_stop", "take_stop", "release_stop"]

PROG = "ghnerf-daemon"

_requested = False
_installed = False
_previous: object = None
#: the stop signal recorded first (None: none), and the handlers :func:`install_stop` replaced
_stop_signal: int | None = None
_previous_stop: dict[int, object] = {}

#: the signals that stop the daemon (cli._StopOnSignal's)
STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT)


def _record(_signum: int, _frame: object) -> None:
    global _requested
    _requested = True


def is_daemon_process() -> bool:
    """This process is ``ghnerf-daemon``: its console script, or ``python -m firmware_host.daemon.cli``."""
    argv = getattr(sys, "argv", None) or [""]
    if os.path.basename(argv[0]) == PROG:
        return True
    orig = list(getattr(sys, "orig_argv", ()))
    return any(a == "-m" and b == "firmware_host.daemon.cli" for a, b in zip(orig, orig[1:]))


def install() -> bool:
    """Record SIGHUP instead of dying of it. True if installed by this call (False: already in place, or not
    the main thread, where Python cannot set handlers)."""
    global _installed, _previous
    # installed and still in place (one replaced since, as by the daemon's SIG_IGN at exit, is installed again:
    # a later main() in the same process, ghnerf-daemon's by name, met a SIGHUP with no recording handler)
    if _installed and signal.getsignal(signal.SIGHUP) is _record:
        return False
    try:
        _previous = signal.signal(signal.SIGHUP, _record)
    except ValueError:  # not the main thread
        return False
    _installed = True
    return True


def uninstall() -> None:
    """Put back the handler :func:`install` replaced (if its own is still the one in place)."""
    global _installed
    if _installed and signal.getsignal(signal.SIGHUP) is _record:
        signal.signal(signal.SIGHUP, _previous)  # type: ignore[arg-type]
    _installed = False


def take() -> bool:
    """Whether a SIGHUP was recorded since the last call; clears it."""
    global _requested
    requested, _requested = _requested, False
    return requested


def _record_stop(signum: int, _frame: object) -> None:
    global _stop_signal
    if _stop_signal is None:
        _stop_signal = signum


def install_stop() -> bool:
    """Record SIGTERM and SIGINT instead of dying of them (or raising KeyboardInterrupt), until the daemon's own stop
    handlers replace these. True if installed by this call (False: already, or not the main thread)."""
    if _previous_stop:
        return False
    try:
        for signum in STOP_SIGNALS:
            _previous_stop[signum] = signal.signal(signum, _record_stop)
    except ValueError:  # not the main thread (nothing was installed: the first call fails)
        return False
    return True


def take_stop() -> int | None:
    """The stop signal recorded since the last call (None: none); clears it."""
    global _stop_signal
    signum, _stop_signal = _stop_signal, None
    return signum


def release_stop() -> None:
    """Put back the handlers :func:`install_stop` replaced (where its own is still in place), then deliver a stop
    recorded meanwhile to them: for a mode that installs no stop handlers of its own (``--validate-config``), a
    stop during its imports acts as it did before they were recorded. Off the main thread, where Python sets no
    handler, nothing is put back nor delivered: the recording, and a stop it holds, stay as they are."""
    try:
        for signum, previous in _previous_stop.items():
            if signal.getsignal(signum) is _record_stop:
                signal.signal(signum, previous)  # type: ignore[arg-type]
    except ValueError:  # not the main thread (the first one set fails: nothing was put back)
        return
    _previous_stop.clear()
    signum = take_stop()
    if signum is not None:
        signal.raise_signal(signum)
