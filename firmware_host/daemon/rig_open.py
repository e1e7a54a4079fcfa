"""Opening the rig in a thread of its own, so that a stop does not wait for it.

An OAK's open may block for tens of seconds (``health.open_allowance_s``, 60 by default), longer than systemd's
``TimeoutStopSec=20``: a stop that waited for it was SIGKILLed with the sinks unflushed. :func:`open_unless_stopped`
waits for the open or the stop, whichever comes first. A stopped wait abandons the open to its thread and closes
the source at once: a :meth:`drivers.RigSource.close` landing during ``open()`` cancels that open (a backend's
``_cancel_open`` stops it at its next step) and the open releases what it made as it returns, so the cameras go
with the stop rather than with the open's end (the process's exit, which does not wait for the thread, releases
whatever an open blocked inside a device call still holds).
"""
from __future__ import annotations

import logging
import threading
from typing import Optional

import drivers

__all__ = ["open_unless_stopped"]

_log = logging.getLogger("ghnerf.daemon")

#: How often the wait looks at the stop: a stop during an open ends the wait within this.
POLL_S = 0.05


class _Opening:
    """One ``source.open()`` on a daemon thread, which the waiting thread may :meth:`abandon`: the open's end
    is then only logged, the abandoning thread having closed the source."""

    def __init__(self, source: drivers.RigSource) -> None:
        self._source = source
        self._lock = threading.Lock()
        self._done = threading.Event()
        self._abandoned = False
        self._error: Optional[BaseException] = None
        self._thread = threading.Thread(target=self._run, name="rig-open", daemon=True)

    def start(self) -> "_Opening":
        self._thread.start()
        return self

    def _run(self) -> None:
        try:
            self._source.open()
        except BaseException as e:  # noqa: BLE001 - handed to the waiting thread, which raises it
            self._error = e
        with self._lock:
            self._done.set()
            abandoned = self._abandoned
        if abandoned:  # closed at the stop already; a second close would only cancel an open once more
            outcome = f"failed ({self._error})" if self._error is not None else "completed"
            _log.info("the rig's open abandoned at the stop has returned: %s", outcome)

    def wait(self, timeout: float) -> bool:
        return self._done.wait(timeout)

    def abandon(self) -> bool:
        """Leave the open to its thread; the caller then closes the source (:func:`_close_abandoned`). False: it
        has returned already, and the caller keeps the source (and the open's outcome, :meth:`result`)."""
        with self._lock:
            if self._done.is_set():
                return False
            self._abandoned = True
            return True

    def result(self) -> None:
        """:raises BaseException: what the open raised."""
        if self._error is not None:
            raise self._error


def _close_abandoned(source: drivers.RigSource) -> None:
    """Close the source of an open the daemon stopped waiting for, while that open still runs: the close cancels
    it (it releases what it made as it returns), or, where the open finished meanwhile, releases the cameras."""
    _log.info("the rig's open abandoned at the stop: closing the rig, which cancels the open")
    try:
        source.close()
    except Exception as e:  # noqa: BLE001 - a device half opened may fail its close; the stop goes on
        _log.warning("closing the abandoned rig: %s", e)


def open_unless_stopped(source: drivers.RigSource, stop: threading.Event, *, poll_s: float = POLL_S) -> bool:
    """Open ``source`` unless ``stop`` is set first. True: open. False: stopped; the source is closed, which
    cancels the open still running in its thread (the caller must not touch the source).

    :raises BaseException: what the open raised (a :class:`drivers.DriverError`...), when it returned first.
    """
    opening = _Opening(source).start()
    while not opening.wait(poll_s):
        if stop.is_set() and opening.abandon():
            _close_abandoned(source)
            return False
    opening.result()
    return True
