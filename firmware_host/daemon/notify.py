"""systemd's notification protocol (``Type=notify``, ``WatchdogSec=``) and the daemon's hang watchdog.

The protocol is one datagram of ``KEY=VALUE`` lines to the unix socket named by ``$NOTIFY_SOCKET``
(sd_notify(3)); it is written here in a few lines rather than taken from a library, because the
maintained binding (python-systemd) needs libsystemd's headers to build, which a small ARM board's
image often lacks. Outside systemd (no ``$NOTIFY_SOCKET``) every call is a no-op. The socket never blocks:
a full queue drops WATCHDOG= and STATUS=, while READY=, STOPPING= and RELOADING= are tried again for up to a
second (``STATE_RETRY_S``), as systemd acts on them.

:class:`HangWatchdog` turns systemd's watchdog into a hang detector for the main loop: the loop
calls :meth:`HangWatchdog.beat` on each pass (or :meth:`HangWatchdog.allow` around a call known to
block longer, such as opening an OAK); a thread pings ``WATCHDOG=1`` only while the last beat is
within its allowance. When the loop hangs (a deadlocked driver, a stuck estimate) the pings stop,
the thread writes every thread's stack to the log once, and systemd kills and restarts the service.
:meth:`HangWatchdog.wedge` stops the pings for good while the loop still beats: for what only a new
process can undo (a camera thread stuck in a device call holds the device, and every reopen fails).
"""
from __future__ import annotations

import errno
import faulthandler
import logging
import os
import socket
import sys
import threading
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import Callable, Optional, TextIO

__all__ = ["SystemdNotifier", "HangWatchdog"]

_log = logging.getLogger(__name__)

#: How long READY=1, STOPPING=1 and RELOADING=1 wait for room in a full queue: one of them lost leaves systemd
#: waiting (a lost READY: TimeoutStartSec, then a restart). WATCHDOG= and STATUS= alone are dropped at once.
STATE_RETRY_S = 1.0
#: The sleep between two tries of a message that waits for room.
_RETRY_SLEEP_S = 0.01
#: The fields that change the service's state in systemd (lower case, as :meth:`SystemdNotifier.notify` takes them).
_STATE_FIELDS = frozenset({"ready", "stopping", "reloading"})
#: sendto's errors for a queue with no room (ENOBUFS: the kernel's buffers for it), not a socket gone.
_FULL_ERRNOS = frozenset({errno.EAGAIN, errno.EWOULDBLOCK, errno.ENOBUFS})


class SystemdNotifier:
    """Send sd_notify(3) messages to ``$NOTIFY_SOCKET`` (pass ``environ`` to read another mapping).

    ``watchdog_s`` is systemd's ``WatchdogSec`` as the service sees it (``$WATCHDOG_USEC``, honoured
    only when ``$WATCHDOG_PID`` is absent or this process), or None when the watchdog is off.
    ``retry_s``: how long a state message (READY, STOPPING, RELOADING) waits for room in a full queue.
    """

    def __init__(self, environ: Optional[Mapping[str, str]] = None, *, retry_s: float = STATE_RETRY_S) -> None:
        env = os.environ if environ is None else environ
        address = env.get("NOTIFY_SOCKET", "")
        # A leading "@" names a socket in the abstract namespace (a NUL byte on the wire).
        self._address = "\0" + address[1:] if address.startswith("@") else address
        self._sock: Optional[socket.socket] = None
        self._lock = threading.Lock()
        self._warned = False
        self._retry_s = float(retry_s)
        self.dropped = 0  # messages not sent because the socket's queue was full
        self.held = 0  # state messages that found the queue full and waited for room (sent or, past retry_s, dropped)
        usec, pid = env.get("WATCHDOG_USEC", ""), env.get("WATCHDOG_PID", "")
        mine = not pid or pid == str(os.getpid())
        self.watchdog_s: Optional[float] = int(usec) / 1e6 if usec.isdigit() and int(usec) > 0 and mine else None

    @property
    def enabled(self) -> bool:
        return bool(self._address)

    def notify(self, **fields: object) -> bool:
        """Send ``KEY=value`` lines (``ready=1`` becomes ``READY=1``); False when not sent.

        A full queue drops WATCHDOG= and STATUS= at once (the next follows soon); a message with READY, STOPPING or
        RELOADING is tried again for up to ``retry_s``, blocking the caller that long at most."""
        if not self._address:
            return False
        # one line per field: a value's own line break (an error message quoting a file) would start a
        # new assignment, READY= or ERRNO= among them
        text = "\n".join(f"{key.upper()}={' '.join(str(value).splitlines())}" for key, value in fields.items())
        data = text.encode("utf-8")
        sent = self._send(data)
        if sent is not None:
            return sent
        if _STATE_FIELDS.isdisjoint(key.lower() for key in fields):
            return self._drop()
        return self._send_when_room(data)

    def _send_when_room(self, data: bytes) -> bool:
        """Try ``data`` again until it fits or ``retry_s`` has passed; the lock is let go between tries, so the
        watchdog's pings are not held up behind it."""
        with self._lock:
            self.held += 1
        deadline = time.monotonic() + self._retry_s
        while time.monotonic() < deadline:
            time.sleep(_RETRY_SLEEP_S)
            sent = self._send(data)
            if sent is not None:
                return sent
        return self._drop()

    def _drop(self) -> bool:
        with self._lock:
            self.dropped += 1
        return False

    def _send(self, data: bytes) -> Optional[bool]:
        """One try: True sent, False not (no such socket: warned once), None the queue is full."""
        with self._lock:
            try:
                if self._sock is None:
                    # Non-blocking: a manager that is not reading (its queue full) must never stall the
                    # main loop beyond a state message's retry_s.
                    self._sock = socket.socket(socket.AF_UNIX,
                                               socket.SOCK_DGRAM | socket.SOCK_CLOEXEC | socket.SOCK_NONBLOCK)
                self._sock.sendto(data, self._address)
                return True
            except OSError as e:
                if e.errno in _FULL_ERRNOS:
                    return None
                # systemd gone (a restart of the manager) or a wrong path: the service goes on.
                if not self._warned:
                    _log.warning("cannot notify systemd at %r: %s", self._address, e)
                    self._warned = True
                return False

    def close(self) -> None:
        with self._lock:
            if self._sock is not None:
                self._sock.close()
                self._sock = None


#: The watchdog thread's shortest wake interval.
MIN_WAKE_S = 0.01


class HangWatchdog:
    """Ping systemd's watchdog while the main loop makes progress (see the module docstring).

    ``allowance_s`` is how long after a beat the loop still counts as alive; ``interval_s`` how
    often the thread wakes (to run ``on_tick``; default: as often as it pings), and it pings at most
    every half of systemd's WatchdogSec. ``stacks_to``
    receives the thread stacks when a hang is first seen (stderr, i.e. the journal, by default).
    """

    def __init__(self, notifier: SystemdNotifier, allowance_s: float, *, interval_s: Optional[float] = None,
                 clock: Callable[[], float] = time.monotonic, stacks_to: Optional[TextIO] = None,
                 on_tick: Optional[Callable[[str, float], None]] = None) -> None:
        self._notifier = notifier
        self._default_allowance = float(allowance_s)
        self._allowance = float(allowance_s)
        wd = notifier.watchdog_s
        self._ping_every = wd / 2 if wd else 1.0
        self._interval = self._wake_interval(interval_s)
        self._last_ping = -float("inf")
        self._clock = clock
        self._stacks_to = stacks_to
        self._on_tick = on_tick  # (where, seconds since the last beat), from the watchdog's thread
        self._last_beat = clock()
        self._where = "start"
        self._hung_reported = False
        self._wedged: Optional[str] = None  # why the pings stopped for good (wedge)
        self._wedge_reported = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.pings = 0

    def configure(self, allowance_s: float, *, interval_s: Optional[float] = None) -> None:
        """New allowance and wake interval (a reloaded config), from the next beat and the next wake."""
        with self._lock:
            self._default_allowance = float(allowance_s)
            self._interval = self._wake_interval(interval_s)

    def _wake_interval(self, interval_s: Optional[float]) -> float:
        # at least 10 ms: a tiny slow_estimate_s woke the thread every half millisecond (8 % of a core)
        return max(MIN_WAKE_S, min(interval_s, self._ping_every)) if interval_s is not None else self._ping_every

    def beat(self, where: str = "main loop") -> None:
        with self._lock:
            self._last_beat = self._clock()
            self._allowance = self._default_allowance
            self._where = where
            self._hung_reported = False

    @contextmanager
    def allow(self, seconds: float, where: str) -> Iterator[None]:
        """Around one call that may block up to ``seconds`` (e.g. opening a camera)."""
        with self._lock:
            self._last_beat = self._clock()
            self._allowance = max(float(seconds), self._default_allowance)
            self._where = where
            self._hung_reported = False
        try:
            yield
        finally:
            self.beat(where)

    def wedge(self, why: str) -> None:
        """Stop the pings for good, however the loop beats: the service cannot recover in this process
        (``why`` says how; logged once, with the thread stacks), so systemd restarts it after WatchdogSec."""
        with self._lock:
            if self._wedged is None:
                self._wedged = why

    @property
    def wedged(self) -> Optional[str]:
        return self._wedged

    def alive(self) -> bool:
        """Whether the loop beat within its allowance and nothing wedged it (what a ping vouches for)."""
        with self._lock:
            return self._wedged is None and self._clock() - self._last_beat <= self._allowance

    def since_beat(self) -> tuple[str, float]:
        """Where the loop last beat, and how long ago."""
        with self._lock:
            return self._where, self._clock() - self._last_beat

    def check(self) -> bool:
        """One tick of the thread: ping when alive; report a hang once. Returns whether it pinged."""
        if self._on_tick is not None:
            try:
                self._on_tick(*self.since_beat())
            except Exception:  # noqa: BLE001 - the watchdog must keep ticking whatever a hook does
                _log.exception("watchdog hook failed")
        if self.alive():
            now = self._clock()
            if self._notifier.watchdog_s is not None and now - self._last_ping >= self._ping_every * 0.99 \
                    and self._notifier.notify(watchdog=1):
                self.pings += 1
                self._last_ping = now
            return True
        with self._lock:
            wedged = self._wedged
            if wedged is not None:  # once: the loop's beats reset the hang's flag, not this one
                report, self._wedge_reported = not self._wedge_reported, True
            else:
                report, self._hung_reported = not self._hung_reported, True
            where, silent_s = self._where, self._clock() - self._last_beat
        if report:
            if wedged is not None:
                _log.error("%s; watchdog pings stopped for systemd to restart the service, thread stacks follow",
                           wedged)
            else:
                _log.error("the main loop has not progressed for %.1f s (last in %s); watchdog pings stopped, "
                           "thread stacks follow", silent_s, where)
            out = self._stacks_to if self._stacks_to is not None else sys.stderr
            try:
                faulthandler.dump_traceback(file=out, all_threads=True)
            except (OSError, ValueError, AttributeError):  # a stream without a file descriptor
                _log.error("cannot dump the thread stacks to %r", out)
        return False

    def start(self) -> "HangWatchdog":
        if self._thread is None:
            # the time since construction (the model loading, tens of seconds) is not a hang
            self.beat("start")
            self._thread = threading.Thread(target=self._run, name="watchdog", daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(self._interval):
            self.check()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
