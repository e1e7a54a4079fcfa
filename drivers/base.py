"""The rig source base class: public behaviour written once, backends fill small hooks.

A backend implements :meth:`RigSource._open`, :meth:`RigSource._read_frame` and
:meth:`RigSource._close` (and, for live sources, :meth:`RigSource._frame_available`).
The base class owns pairing (:mod:`drivers.pairing`), timeouts, counters,
iteration and the context manager.

A :meth:`RigSource.close` from another thread while :meth:`RigSource.open` runs cancels that open, whatever the
backend: once ``_open`` returns, ``open()`` finds the close, releases what ``_open`` made with ``_close`` and raises
:class:`~drivers.errors.RigInitializationError`. Before, the close skipped ``_close`` for a source not yet open, and
``open()`` returned a closed source still holding camera threads or a device. Backends whose ``_open`` takes long
(``sim://``'s pre-render and disk cache, ``replay://``'s checks, ``opencv://``'s wait for the cameras' first
frames, ``depthai://``'s device start) also stop it early, in :meth:`RigSource._cancel_open`. Whatever else ends
``open()`` once ``_open`` has returned (a Ctrl-C before the source is marked open, a failed rig warning) releases
what ``_open`` made the same way, the caller having no source to close; and a second ``open()`` while one runs
raises :class:`~drivers.errors.OpenInProgressError`, not a second ``_open``.
"""
from __future__ import annotations

import abc
import logging
import math
import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import ClassVar

from drivers.clock import Clock, MonotonicClock
from drivers.errors import (
    EndOfStream,
    OpenInProgressError,
    RigConfigError,
    RigDisconnectedError,
    RigInitializationError,
    RigOperationError,
    RigTimeoutError,
)
from drivers.frames import Frame, FramePair
from drivers.pairing import DropPolicy, FramePairer, PairingConfig, PairingStats
from drivers.url import RigUrl
from ghnerf_runtime.errors import RigFileError
from ghnerf_runtime.geometry import Rig
from ghnerf_runtime.rig_file import load_rig, rig_warnings_and_notes

log = logging.getLogger(__name__)


def load_rig_option(url: RigUrl, path: str) -> Rig:
    """The rig file a URL's ``rig=`` option names, read without its warnings: the source logs them at open, once
    per daemon run (:meth:`RigSource._rig_read_from`). A file that cannot be read is a :class:`RigConfigError`
    naming the URL and the option (:func:`naming_rig_option`)."""
    with naming_rig_option(url, path):
        return load_rig(path, warn=False)


@contextmanager
def naming_rig_option(url: RigUrl, path: str) -> Iterator[None]:
    """A rig file that cannot be read, or a rig the stream does not fit, raised inside as a :class:`RigConfigError`
    that names the URL and its ``rig=`` option: the file's own error names only the file."""
    try:
        yield
    except (RigFileError, RigConfigError) as e:
        raise RigConfigError(f"rig URL {url.url!r}: option rig={path}: {e}") from e


class RigSource(abc.ABC):
    """A calibrated two-camera source of synchronised frame pairs.

    Use through :func:`drivers.open_rig`::

        with drivers.open_rig("sim://?fps=30") as source:
            pair = source.read(timeout_s=1.0)

    Args:
        rig: the calibration the frames belong to (first two cameras are the pair).
            ``None`` for hardware backends that learn it from the device: they call
            :meth:`_set_rig` in :meth:`_open` (a constructor must not open hardware).
        pairing: timestamp tolerance and drop policy.
        clock: time source for timeouts (and, in simulated backends, for timing).
        rig_built: the backend built ``rig`` in memory (``sim://``'s placement); ``False`` for one read from a rig
            file (read with ``load_rig(path, warn=False)`` and named with :meth:`_rig_read_from`, it is warned of
            at open) or handed in by the caller, which ``load_rig`` has already warned about.
    """

    #: URL scheme this backend answers to.
    scheme: ClassVar[str] = ""
    #: Most frames one ``read()`` takes in without waiting under ``DropPolicy.LATEST``: at least
    #: what the backend can hold for the reader (both cameras together), so every frame already
    #: waiting is taken and the pair handed out is the newest, and bounded, so a source delivering
    #: faster than frames can be drained cannot hold ``read()`` forever. Backends that hold more
    #: (a deeper queue) raise it.
    drain_limit: int = 32
    #: Whether a frame's timestamp is the time it was captured on this host's monotonic clock, so that
    #: ``now - timestamp`` is the latency since capture (a replay re-stamped and played at the recorded
    #: pace: yes; one keeping the recorded stamps, or played faster or slower: no).
    live_timestamps: bool = True

    def __init__(
        self, rig: Rig | None, *, pairing: PairingConfig | None = None, clock: Clock | None = None,
        rig_built: bool = False,
    ) -> None:
        self._rig: Rig | None = None
        self._rig_built = False  # see _set_rig
        self.clock: Clock = clock or MonotonicClock()
        self.pairing = pairing or PairingConfig()
        self._pairer: FramePairer | None = None  # built with the rig: it pairs the rig's camera names
        self._is_open = False
        self._closed = False
        self._opening = False  # an open() is between its checks and marking the source open (see open())
        self._close_claimed = False  # a close() or a failed open() has taken on running _close (once)
        # Held only to change or test these four flags together in open() and close(), never around a hook: a
        # close landing as open() finishes is then seen by exactly one of them, which calls _close (once).
        self._open_state = threading.Lock()
        self._held_error: RigDisconnectedError | EndOfStream | None = None  # see _take_frame
        self._rig_warnings_logged: set[str] | None = None  # see log_rig_warnings_once
        self._rig_file: str | None = None  # see _rig_read_from
        if rig is not None:
            self._set_rig(rig, built=rig_built)

    def _set_rig(self, rig: Rig, *, built: bool = False) -> None:
        """Adopt the rig (at construction, or in :meth:`_open` once the device told us its calibration).
        ``built``: the backend made it in memory (a placement, a device's calibration, a nominal rig), not
        ``load_rig``: :meth:`open` then logs ``rig_file.rig_warnings`` once, as loading a rig file does."""
        self._rig = rig
        self._rig_built = built
        self._pairer = FramePairer((rig.pair[0].name, rig.pair[1].name), self.pairing)

    # ------------------------------------------------------------------ hooks
    @classmethod
    @abc.abstractmethod
    def from_url(cls, url: RigUrl, **kwargs) -> "RigSource":
        """Build an (unopened) source from a parsed URL; consume options, then ``url.finish()``."""

    @abc.abstractmethod
    def _open(self) -> None:
        """Start the cameras. Raise :class:`RigInitializationError` on failure, having released what was started:
        :meth:`_close` follows only an ``_open`` that returned."""

    @abc.abstractmethod
    def _read_frame(self, timeout_s: float) -> Frame | None:
        """The next frame from either camera, in capture order per camera.

        Return ``None`` when nothing arrived within ``timeout_s``; raise
        :class:`RigDisconnectedError` when a camera has gone (or
        :class:`EndOfStream` when a recording is exhausted).
        """

    @abc.abstractmethod
    def _close(self) -> None:
        """Release the cameras. Called at most once, by :meth:`close` or by an :meth:`open` that failed or was
        cancelled after ``_open`` returned."""

    def _frame_available(self) -> bool:
        """Whether :meth:`_read_frame` can return a frame now, without waiting.

        Under ``DropPolicy.LATEST`` :meth:`read` takes in every such frame before
        returning, so it hands out the newest pair (older ones are dropped and
        counted) instead of the oldest one still queued in the backend. Return
        ``False`` for a pending error or the end of a recording: those are raised
        by the next read, after the pairs already captured. Default: ``False``
        (no draining; frames are read one at a time).
        """
        return False

    def _catch_up(self, pairer: FramePairer) -> None:
        """Under ``DropPolicy.LATEST``, before :meth:`read` drains: push what is waiting more cheaply.

        A backend that can tell what is due without producing it (a recording's journal) pushes
        the waiting frames into ``pairer`` here, each image left unloaded, then loads the images
        of the frames the pairer still holds (:meth:`FramePairer.replace_held`): the others went
        into dropped pairs or were unpaired, and nobody sees them. Default: nothing.
        """

    def _pairs_lost(self) -> int:
        """Whole pairs the backend lost just before the frame :meth:`_read_frame` returned last.

        A backend that sees both cameras skip together (depthai's Sync groups discarded from the
        host queue) reports them here: :meth:`read` counts them in ``stats.pairs_dropped`` and as
        sequence gaps, not as camera gaps. Called once for each frame :meth:`_read_frame` returned, just
        before it is pushed into the pairer. Default: 0.
        """
        return 0

    # ---------------------------------------------------------- public API
    @property
    def rig(self) -> Rig:
        if self._rig is None:
            raise RigOperationError(f"{type(self).__name__} learns its rig from the device; open() it first")
        return self._rig

    @property
    def is_open(self) -> bool:
        return self._is_open

    @property
    def stats(self) -> PairingStats:
        """A snapshot of the pairing counters (frames in, pairs out, unpaired, dropped, gaps)."""
        if self._pairer is None:
            return PairingStats()
        return self._pairer.stats.snapshot()

    def open(self) -> "RigSource":
        """Start the cameras (``_open``); a call once the source is open does nothing (one while another thread's
        open runs raises, below).

        Raises:
            RigOperationError: the source was closed before.
            OpenInProgressError: another thread's open() of this source has not finished (a second ``_open``
                would start a second set of cameras).
            RigInitializationError: the backend could not start, or a :meth:`close` from another thread landed
                while it started: what ``_open`` made is released (``_close``, once) and the source stays closed.
        """
        with self._open_state:
            if self._closed:
                raise RigOperationError(f"{type(self).__name__} was closed; open a new source")
            if self._is_open:
                return self
            if self._opening:
                raise OpenInProgressError(f"{type(self).__name__} is already being opened by another call to "
                                          "open(); wait for that one (a second would start a second set of "
                                          "cameras)")
            self._opening = True
        try:
            self._open()  # not under the lock: a close() meanwhile must not wait for a pre-render or a device
        except BaseException:
            with self._open_state:
                self._opening = False
            raise
        try:
            self._mark_open()
            if self._rig_built or self._rig_file is not None:
                self._warn_of_rig()
        except BaseException as failure:
            # Whatever ended the open after _open returned (a close from another thread, a Ctrl-C, a failed
            # warning): the caller gets no source to close, so what _open started is released here. The
            # failure is what the caller sees, a failing _close its cause.
            try:
                self._release_failed_open()
            except Exception as e:
                raise failure from e
            raise
        return self

    def _mark_open(self) -> None:
        """After ``_open`` returned: the source is open, unless a close landed meanwhile or ``_open`` set no rig
        (raised, and :meth:`open` releases what ``_open`` made)."""
        with self._open_state:
            cancelled = self._closed  # close() saw the source not open and left _close to us
            if not cancelled and self._rig is not None:
                self._is_open = True
                self._opening = False  # a second open() now finds it open; a failed one's release clears it
        if cancelled:
            raise RigInitializationError(f"{type(self).__name__} closed while it opened (a close() from another "
                                         "thread): the open was cancelled")
        if self._rig is None:
            raise RigOperationError(f"{type(self).__name__}._open() did not set the rig")

    def _release_failed_open(self) -> None:
        """:meth:`open` failed after ``_open`` returned: ``_close`` (once), unless a close from another thread
        found the source marked open meanwhile and runs ``_close`` itself. The source is closed after it."""
        with self._open_state:
            self._opening = False
            owed = not self._close_claimed
            self._close_claimed = True
            self._is_open = False
            self._closed = True
        if owed:
            self._close()

    def _rig_read_from(self, path: str | os.PathLike) -> None:
        """The rig handed in was read from ``path`` with ``load_rig(path, warn=False)``: :meth:`open` logs the
        file's warnings instead, naming the file as ``load_rig`` does, so that sources sharing
        :meth:`log_rig_warnings_once`'s set log them once (a daemon creates a source at each reopen, and
        ``load_rig`` warned at each)."""
        self._rig_file = str(path)

    def log_rig_warnings_once(self, logged: set[str]) -> None:
        """Log each warning about the rig at most once over every source handed the same ``logged`` set, which
        this source adds to. A daemon reopens its rig after each lost camera, and each open repeated the same
        warnings in the journal; a source given no set (a one-shot tool's) warns at each open, once."""
        self._rig_warnings_logged = logged

    def _log_about_rig_once(self, logger: logging.Logger, level: int, fmt: str, *args: object) -> None:
        """``logger.log(level, fmt, *args)``, unless a source sharing :meth:`log_rig_warnings_once`'s set logged
        the same text already."""
        logged = self._rig_warnings_logged
        if logged is not None:
            text = fmt % args
            if text in logged:
                return
            logged.add(text)
        logger.log(level, fmt, *args)

    def warn_of_built_rig(self) -> None:
        """Log now what :meth:`open` will warn and note of the rig this source built in memory before any open
        (``sim://``'s placement), for a check that opens nothing (``ghnerf-daemon --validate-config``). Nothing for a
        rig read from a file (its loader warns of it) or known only at the open (a device's calibration,
        ``opencv://``'s nominal rig, sized by the cameras' first frames)."""
        if self._rig_built and self._rig is not None:
            self._warn_of_rig()

    def _warn_of_rig(self) -> None:
        """What ``load_rig`` would warn of in the rig this backend built (a narrow ``sim://?baseline=``, a
        camera's height), and note at INFO (``rig_file.rig_notes``): the one check for every backend's in-memory
        rig, and for a rig file read without its warnings (:meth:`_rig_read_from`)."""
        warnings, notes = rig_warnings_and_notes(self._rig)
        said = [(logging.WARNING, m) for m in warnings] + [(logging.INFO, m) for m in notes]
        for level, message in said:
            if self._rig_built:
                self._log_about_rig_once(log, level, "%s:// rig %r: %s", self.scheme, self._rig.rig_id, message)
            else:  # read from a file: worded as load_rig words it
                self._log_about_rig_once(log, level, "%s: %s", self._rig_file, message)

    def read(self, timeout_s: float = 1.0) -> FramePair:
        """Block until the next synchronised pair, at most ``timeout_s`` seconds.

        With ``DropPolicy.LATEST`` that is the newest pair: every frame the backend already
        holds is taken in first (up to :attr:`drain_limit`, what the backend can hold), and
        older complete pairs are dropped, counted in ``stats.pairs_dropped`` and seen as
        sequence gaps. With ``DropPolicy.ALL`` it is the oldest pair not yet read. A pair whose
        frames were not captured together is formed once the pairer knows no later frame is
        closer (:class:`~drivers.pairing.FramePairer`): at most one frame later.

        Raises:
            RigTimeoutError: no pair within the timeout (frames may still be flowing
                but none pair within tolerance: see :attr:`stats`).
            RigDisconnectedError: a camera vanished; the source stays usable for
                backends that reconnect, otherwise close it.
            EndOfStream: a finite source (a recording) is exhausted.
        """
        if self._closed:  # "call open()" sent the reader to an open() that refuses a closed source
            raise RigOperationError(f"{type(self).__name__} was closed; open a new source")
        if not self._is_open:
            raise RigOperationError(f"{type(self).__name__} is not open; call open() or use open_rig()")
        try:
            seconds = float(timeout_s)
        except (TypeError, ValueError):
            seconds = math.nan
        # In nanoseconds too: the deadline is an integer of them, and int(inf) is an OverflowError (1e300 s).
        if not (0 <= seconds < math.inf and seconds * 1e9 < math.inf):
            raise ValueError(f"read(timeout_s={timeout_s!r}): give a finite number of seconds >= 0 "
                             "(to wait without limit, read again after each RigTimeoutError)")
        pairer = self._pairer
        assert pairer is not None  # open() guarantees the rig, hence the pairer
        deadline = self.clock.now_ns() + int(seconds * 1e9)
        drain = 0
        if self.pairing.policy is DropPolicy.LATEST:
            self._catch_up(pairer)
            drain = self.drain_limit  # read once, here: a backend may size it by what is waiting now
        # Past the deadline (at once for a poll, timeout 0), frames the backend holds are still taken,
        # without waiting: a poll must see the pair that is already there. Bounded, for a source that
        # always has a frame but never a pair.
        late_reads = max(2, drain or RigSource.drain_limit)
        while True:
            drain -= self._drain(pairer, drain)
            ready = pairer.pop()
            if ready is not None:
                return self._frame_pair(ready)
            if self._held_error is not None:  # raised once the pairs of the frames before it are read
                error, self._held_error = self._held_error, None
                raise error
            remaining = (deadline - self.clock.now_ns()) / 1e9
            if remaining <= 0:
                late_reads -= 1
                if late_reads < 0:
                    raise RigTimeoutError(
                        f"no frame pair within {seconds:.3f} s from {type(self).__name__} (stats: {self.stats})"
                    )
            frame = self._take_frame(pairer, max(remaining, 0.0))
            if frame is not None:
                self._push(pairer, frame)
            elif remaining <= 0 and self._held_error is None:
                late_reads = -1  # nothing held: time out now

    def _frame_pair(self, ready: tuple[int, Frame, Frame]) -> FramePair:
        sequence, first, second = ready
        return FramePair(frames=(first, second), sequence=sequence, rig=self.rig)

    def _take_frame(self, pairer: FramePairer, timeout_s: float) -> Frame | None:
        """:meth:`_read_frame`; a disconnect or the end of the stream is held for :meth:`read` to raise
        after the pairs still owed: the pairer decides the frames it holds now, as no later frame of
        theirs will come (one waiting to see whether a closer frame follows pairs now)."""
        try:
            return self._read_frame(timeout_s)
        except RigDisconnectedError as e:
            # EndOfStream is a RigDisconnectedError: one clause for both (a second one for it, after this, was
            # never reached). reset() decides the held frames as flush() would, then forgets the cameras'
            # timelines, which a reconnect restarts and which nothing follows at the end of a recording.
            pairer.reset()
            self._held_error = e
        return None

    def _drain(self, pairer: FramePairer, limit: int) -> int:
        """Push up to ``limit`` frames the backend holds already; returns how many were read."""
        n = 0
        while n < limit and self._held_error is None and self._frame_available():
            frame = self._take_frame(pairer, 0.0)  # zero timeout: never wait, even if availability was wrong
            if frame is None:
                break
            self._push(pairer, frame)
            n += 1
        return n

    def _push(self, pairer: FramePairer, frame: Frame) -> None:
        lost = self._pairs_lost()
        if lost > 0:
            pairer.skip_pairs(lost)
        pairer.push(frame)

    def __iter__(self) -> Iterator[FramePair]:
        """Pairs until the source ends (a recording's end stops iteration; other errors propagate)."""
        while True:
            try:
                yield self.read()
            except EndOfStream:
                return

    def close(self) -> None:
        """Release the cameras; a second call does nothing. From another thread while :meth:`open` runs, that open
        is cancelled: it releases what it made and raises :class:`RigInitializationError`."""
        with self._open_state:
            # closed first, even where closing fails: never opened again (a second device link); and an open()
            # finishing now sees it and releases what it made, this close finding nothing open to release
            must_close = self._is_open and not self._close_claimed
            self._close_claimed = self._close_claimed or must_close
            self._closed = True
        try:
            if must_close:
                self._close()
            else:
                self._cancel_open()
        finally:
            self._is_open = False

    def _cancel_open(self) -> None:
        """:meth:`close` of a source not open: an :meth:`open` another thread may be running is to stop early (a
        pre-render at its next frame) rather than run on to its end, then release what it made (it does, as
        :meth:`open` says). Runs on the closing thread, so it must not wait for that open. Default: nothing."""

    def lingering(self) -> tuple[str, ...]:
        """After :meth:`close`: what of this source is still inside a device call that the close could not
        end (a camera thread in a grab that hangs; after a close that cancelled an open, a device the opening thread
        has not released yet), by name; empty once all is released. Such a call holds
        the device, so no new source can open it, and only a new process frees it (the daemon stops its
        watchdog pings for that: ``docs/daemon.md``). Default: nothing (a backend without threads of its
        own blocks in ``close`` instead)."""
        return ()

    def __enter__(self) -> "RigSource":
        return self.open()

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
            return
        try:  # the error that ended the block (a camera unplugged) is the one to report, not the close's
            self.close()
        except Exception:
            log.warning("closing %s after %s failed too", type(self).__name__, exc_type.__name__, exc_info=True)
