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

What is left: the interpreter's own start-up, before this module runs (tens of milliseconds), where
only the unit's ``RestartForceExitStatus=SIGHUP`` helps.
"""
from __future__ import annotations

import os
import signal
import sys

__all__ = ["install", "uninstall", "take", "is_daemon_process"]

PROG = "ghnerf-daemon"

_requested = False
_installed = False
_previous: object = None


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
    """Record SIGHUP instead of dying of it. True if installed by this call (False: already, or not the
    main thread, where Python cannot set handlers)."""
    global _installed, _previous
    if _installed:
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
