"""The sink base class: owns the public behaviour, backends fill four small hooks.

Behaviour written once here:

- ``send()`` never blocks: it admits the frame through the rate limiter and
  appends it to a bounded queue, dropping (and counting) the oldest when full;
- a worker thread connects, delivers queued frames and, when the link goes
  away, disconnects and reconnects with exponential backoff;
- every frame submitted ends up in exactly one counter: ``sent``,
  ``decimated``, ``dropped_queue``, ``dropped_error``, ``dropped_close``, or
  is still ``queued`` / ``in_flight``; ``partial`` counts those of ``sent`` only part of which went out
  (``SinkPartialWriteError``).

A link that cannot be (re)opened is retried forever; the journal hears of it
once per outage (a WARNING, again only when the error changes, repeats at
DEBUG) and ``stats().state`` says ``down`` with the error in ``last_error``. So is a link that opens but is lost
again before a frame gets through (its HELLO went out, every transfer after it fails): after one "link lost", one
"connected again" and one "lost again ...: it flaps" (the journal's last word must not say it is up) the rest are DEBUG,
it is reopened at the backoff's pace, and an INFO says when frames get through.
An outage ends when a write gets through, not when the link opens: a board that resets at every transfer (opens,
takes HELLO, is lost, is absent while it boots) logs its failed open once. A link whose stall was logged is no flap:
its loss is a WARNING, and so is its failed open.

A link that is open but whose receiver stopped reading (every write times out,
a buffer stays full) is ``stalled`` rather than ``up`` once no frame has got
through whole for ``options.stall_s`` since a write first failed (in whole or in part: a vmc:// sink whose every
second bundle met a full buffer read ``up`` while half the avatar's bones never moved), or once one write
has been in progress that long; ``stalled_s`` says for how long. The first frame
that gets through whole makes it ``up`` again, and so does an idle write that does
(``_on_idle`` says it wrote: a STATUS while no frame comes, the rig down). The
journal hears of a stall once (a WARNING) and of its end once (INFO). So is a
link whose writes go out but whose receiver's side says nothing takes them (a
UDP port no program has open: ``_receiver_refusing``), counted from the first
refusal of the stretch; the backend logs those.

Backend hooks: ``_connect``, ``_disconnect``, ``_deliver`` and optionally
``_on_connected`` and ``link_capacity_fps``.
"""
from __future__ import annotations

import logging
import threading
import time
from abc import ABC, abstractmethod
from collections import deque
from dataclasses import dataclass
from typing import Optional

from drivers.url import shown_url
from firmware_host.errors import SinkClosedError, SinkPartialWriteError, SinkUnavailableError, SinkWriteError
from firmware_host.protocol.constants import Flags
from firmware_host.protocol.messages import JointFrame
from firmware_host.sinks.backoff import Backoff
from firmware_host.sinks.options import SinkOptions
from firmware_host.sinks.rate import RateLimiter

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SinkStats:
    submitted: int
    sent: int
    decimated: int  # skipped on purpose to fit the link
    dropped_queue: int  # oldest frame pushed out of a full queue
    dropped_error: int  # write failed (stall, timeout, unplug)
    dropped_close: int  # still queued when close() gave up
    queued: int
    in_flight: int
    connected: bool
    connects: int
    connect_failures: int
    disconnects: int
    last_error: Optional[str]
    state: str = "connecting"
    """``connecting`` (not tried yet), ``up``, ``stalled`` (up, but no frame got through whole for ``stall_s``:
    the receiver stopped reading; ``connected`` stays true), ``down`` (the link was lost or the last connect
    failed; ``last_error`` says why) or ``closed``."""
    stalled_s: Optional[float] = None
    """While ``stalled``: seconds since the first write that failed (or the write still in progress) with
    no frame through since; None otherwise."""
    partial: int = 0
    """Of ``sent``: frames only part of which went out (a vmc:// frame whose second bundle met a full send
    buffer: the receiver applied the first one's root and bones, the rest held their last pose)."""

    @property
    def dropped(self) -> int:
        return self.dropped_queue + self.dropped_error + self.dropped_close

    @property
    def accounted(self) -> int:
        """Equals ``submitted`` at every instant: no frame is lost silently."""
        return self.sent + self.decimated + self.dropped + self.queued + self.in_flight


class Sink(ABC):
    """A joint-stream output. Create with ``open_sink(url)`` (which also starts it)."""

    scheme: str = ""
    #: Longest close() waits, once it gave up, for a new link's HELLO + STATUS being written (its links' writes time
    #: out well within it by default; ``write_timeout_ms`` and ``timeout_ms`` go to 60 s, past a service's stop).
    announcement_wait_s: float = 2.0

    def __init__(self, url: str, options: SinkOptions) -> None:
        self.url = url
        #: How logs, the thread name and repr show the URL: without its passwords (they reach the journal), on one
        #: line (a control character escaped).
        self.shown = shown_url(url)
        self.options = options
        self._cond = threading.Condition()
        self._stop = threading.Event()
        # Queued items are [frame, flags]: flags describe the gap just before that frame.
        self._queue: deque[list] = deque()
        self._thread: Optional[threading.Thread] = None
        self._held = False  # started held (start(held=True)): the worker opens nothing until release(); _cond guards
        self._closed = False
        self._given_up = False  # close() waited its timeout and gave up: a link opening after that is let go
        # The worker is writing a new link's announcement (HELLO + STATUS): close() giving up waits for it to end,
        # so none goes out after close() returned. _cond guards both.
        self._announcing = False
        self._limiter: Optional[RateLimiter] = None
        self._warned_decimation = False
        # Counters, guarded by _cond.
        self._submitted = self._sent = self._decimated = self._partial = 0
        self._dropped_queue = self._dropped_error = self._dropped_close = 0
        self._in_flight = 0
        self._connected = False
        self._connects = self._connect_failures = self._disconnects = 0
        self._last_error: Optional[str] = None
        # The error of the current outage logged last: a repeat of it is not logged again. Kept through a link that
        # opens but carries nothing (a board that resets at every transfer), None once a write gets through.
        self._down = False
        self._down_error: Optional[str] = None
        # Gap reasons not yet attached to a frame (see protocol Flags): decimation
        # since the last admitted frame, and failed deliveries since the last pop.
        self._gap_flags = 0
        self._error_flags = 0
        # Stall watch, guarded by _cond (monotonic seconds): when the first write failed since a frame last got
        # through, and when the write in progress (frame, or idle STATUS) began; None: no such write.
        self._failing_since: Optional[float] = None
        self._writing_since: Optional[float] = None
        self._stall_logged = False  # the WARNING for this stall was written: its end gets an INFO
        # A link that opens (its HELLO goes out) but is lost again before a frame or idle write gets through is one
        # outage: a "link lost" WARNING, a "connected again" INFO and an "it flaps" WARNING once, then DEBUG until a
        # write gets through (an INFO says so). Before, such a link logged both lines, and was reopened, for every
        # frame. Guarded by _cond.
        self._carried = False  # a frame or idle write got through since the last connect
        self._said_again = False  # "connected again" was logged, and no write got through since
        self._flapping = False  # lost again before a write got through: the journal waits for one that does
        # The worker's own (no lock): a flapping link was just lost, its reopen waits the backoff first (a failed
        # open waits its own: both, and a board back from its boot was looked for every 2 * max_s).
        self._reopen_waits = False

    # ---- hooks -------------------------------------------------------------

    @abstractmethod
    def _connect(self) -> None:
        """Open the link. :raises SinkUnavailableError: when it cannot be opened now."""

    @abstractmethod
    def _disconnect(self) -> None:
        """Release the link; must not raise."""

    @abstractmethod
    def _deliver(self, frame: JointFrame, flags: int) -> None:
        """Write one frame.

        :raises SinkPartialWriteError: part of the frame went out, the rest is lost; the link is still up.
        :raises SinkWriteError: the frame is lost but the link is still up.
        :raises SinkUnavailableError: the link went away; the sink reconnects.
        """

    def _on_connected(self) -> None:
        """Called after each successful connect (e.g. to announce HELLO); may raise like _deliver."""

    def _idle_timeout_s(self) -> Optional[float]:
        """How long the connected worker may wait for a frame before :meth:`_on_idle` (None: forever)."""
        return None

    def _on_idle(self) -> bool:
        """Called when no frame came within :meth:`_idle_timeout_s` (e.g. a periodic STATUS while the
        estimator stalls); may raise like _deliver. Returns whether it wrote to the link, whole: the receiver
        reads, so a stall ends as at a frame that gets through (False: nothing was due, or a part was cut)."""
        return False

    def _receiver_refusing(self, now: float) -> Optional[tuple[float, str]]:
        """``(since, why)`` while the writes go out but the receiver's side refuses them (udp://, vmc://: an ICMP
        port unreachable), None otherwise: the link is as good as stalled. Called with _cond held, from any
        thread: must not block."""
        return None

    def link_capacity_fps(self) -> Optional[float]:
        """Highest frame rate the link carries, or None when it is not the bottleneck."""
        return None

    # ---- public API ------------------------------------------------------------

    def effective_max_fps(self) -> Optional[float]:
        caps = [c for c in (self.options.max_fps, self.link_capacity_fps()) if c is not None]
        return min(caps) if caps else None

    def start(self, *, held: bool = False) -> "Sink":
        """Start the worker, which opens the link and delivers.

        :param held: the worker waits for :meth:`release` (or ``close()``) before it opens anything: a daemon's reload
            starts the sinks it adds (the worker thread, which can fail to start) before it commits, and lets them
            open only once the sinks it removes have let go of their ports, so a refused reload opened nothing.
        """
        if self._thread is not None:
            return self
        self._held = held
        cap = self.effective_max_fps()
        self._limiter = RateLimiter(cap)
        if cap is not None and self.options.fps is not None and self.options.fps > cap:
            self._warned_decimation = True
            _log.warning(
                "%s: %.1f fps requested but this link carries at most %.1f joint frames/s; "
                "decimating to fit (gaps are flagged DECIMATED and counted)",
                self.shown, self.options.fps, cap,
            )
        self._thread = threading.Thread(target=self._run, name=f"sink {self.shown}", daemon=True)
        try:
            self._thread.start()
        except BaseException:  # no thread to be had (a task limit): close() must not join one never started
            self._thread = None
            raise
        return self

    def release(self) -> None:
        """Let a worker started held (``start(held=True)``) open the link; nothing for one that is not held."""
        with self._cond:
            self._held = False
            self._cond.notify_all()

    def send(self, frame: JointFrame) -> None:
        """Queue a frame for sending; never blocks, never raises for link problems.

        :raises SinkClosedError: after ``close()``.
        """
        warn_fps: Optional[float] = None
        with self._cond:
            if self._closed:
                raise SinkClosedError(f"{self.shown}: send() after close()")
            self._submitted += 1
            limiter = self._limiter
            if limiter is not None and not limiter.admit(frame.capture_time_us):
                self._decimated += 1
                self._gap_flags |= Flags.DECIMATED
                if not self._warned_decimation:
                    warn_fps = limiter.max_fps
                self._warned_decimation = True
            else:
                item = [frame, self._gap_flags]
                self._gap_flags = 0
                if len(self._queue) >= self.options.queue:
                    _, lost_flags = self._queue.popleft()
                    self._dropped_queue += 1
                    # The gap now sits before the new oldest frame.
                    heir = self._queue[0] if self._queue else item
                    heir[1] |= lost_flags | Flags.DROPPED
                self._queue.append(item)
                self._cond.notify_all()
        if warn_fps is not None:  # logged outside the lock: handlers may be slow
            _log.warning("%s: frames arrive faster than %.1f fps; decimating", self.shown, warn_fps)

    def stats(self) -> SinkStats:
        now = time.monotonic()
        with self._cond:
            stalled_s = self._stalled_s(now)
            return SinkStats(
                submitted=self._submitted,
                sent=self._sent,
                decimated=self._decimated,
                dropped_queue=self._dropped_queue,
                dropped_error=self._dropped_error,
                dropped_close=self._dropped_close,
                queued=len(self._queue),
                in_flight=self._in_flight,
                connected=self._connected,
                connects=self._connects,
                connect_failures=self._connect_failures,
                disconnects=self._disconnects,
                last_error=self._last_error,
                state=self._state(stalled_s),
                stalled_s=None if stalled_s is None else round(stalled_s, 3),
                partial=self._partial,
            )

    def _state(self, stalled_s: Optional[float]) -> str:
        if self._closed and not self._connected:
            return "closed"
        if self._connected:
            return "up" if stalled_s is None else "stalled"
        return "down" if self._down else "connecting"

    def _stalled_s(self, now: float) -> Optional[float]:
        """How long the open link has delivered nothing, once that is ``stall_s`` or more; else None. Counted
        from the first failed write since a frame got through, from the start of a write still in progress
        (a blocking write that never returns fails nothing), or from the first refusal of the receiver's side
        still going on: the earliest. Call with _cond held."""
        if not self._connected:
            return None
        refusing = self._receiver_refusing(now)
        starts = [t for t in (self._failing_since, self._writing_since, refusing and refusing[0]) if t is not None]
        if not starts:
            return None
        stalled = now - min(starts)
        return stalled if stalled >= self.options.stall_s else None

    def pending_gap_flags(self) -> int:
        """The gap flags (DROPPED, DECIMATED) the next frame would have carried: after ``close()``, what
        this sink lost that no frame of it reported (frames still queued or in flight, failed writes,
        decimation). A sink replacing this one on the same link passes them on with :meth:`carry_gap`."""
        with self._cond:
            flags = self._gap_flags | self._error_flags
            if self._queue or self._in_flight:
                flags |= Flags.DROPPED
            return flags

    def carry_gap(self, flags: int) -> None:
        """Mark the next frame with ``flags`` (DROPPED, DECIMATED): a gap made before this sink existed,
        e.g. frames a sink it replaces dropped when closed (docs/protocol.md section 3)."""
        with self._cond:
            self._gap_flags |= int(flags) & (Flags.DROPPED | Flags.DECIMATED)

    def wait_drained(self, timeout: float) -> bool:
        """Block until nothing is queued or in flight (for shutdown and tests)."""
        with self._cond:
            return self._cond.wait_for(lambda: not self._queue and not self._in_flight, timeout)

    def wait_connected(self, timeout: float) -> bool:
        with self._cond:
            return self._cond.wait_for(lambda: self._connected, timeout)

    def close(self, timeout: float = 1.0) -> SinkStats:
        """Stop accepting frames, deliver what is queued if the link is up, release it.

        Frames still queued after ``timeout`` are counted as ``dropped_close``. A link still opening then (a slow
        name lookup) is let go once open, unannounced: no HELLO from a closed sink; an open that fails then is neither
        logged nor counted. A link's HELLO + STATUS being written then is waited for, at most
        :attr:`announcement_wait_s` (a WARNING where it runs past that, as it may go out after close() returned).
        """
        with self._cond:
            if self._closed:
                return self.stats()
            self._closed = True
            self._cond.notify_all()
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
        with self._cond:
            self._dropped_close += len(self._queue)
            for _, flags in self._queue:  # a gap no frame of this sink will report now
                self._error_flags |= Flags.DROPPED | (flags & Flags.DECIMATED)
            self._queue.clear()
            self._given_up = True
            self._wait_for_announcement()
        if self._thread is None or not self._thread.is_alive():
            self._release()
        return self.stats()

    def __enter__(self) -> "Sink":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.shown}>"

    # ---- worker ------------------------------------------------------------------

    def _release(self) -> None:
        with self._cond:
            was = self._connected
            self._connected = False
            self._failing_since = None  # a link lost is down, not stalled; a new one starts afresh
            self._stall_logged = False  # "link lost" says the rest
        if was:
            self._disconnect()

    def _try_connect(self, backoff: Backoff) -> None:
        """Connect and announce; the link counts as up (state, ``connects``, "connected again") only once
        ``_on_connected`` went through: a port that opens but fails its first write (EIO, a udp:// route
        that is gone) is still the same outage, logged once, not an up/down flicker on every retry."""
        reopen_waits, self._reopen_waits = self._reopen_waits, False
        if reopen_waits and self._stop.wait(backoff.next_delay()):
            return  # a link lost again before a write got through is reopened at the backoff's pace, not per frame
        opened = False
        write_error: Optional[str] = None
        started = time.monotonic()
        try:
            self._connect()
            opened = True
            if not self._announce():  # close() gave up while it opened (a slow lookup): a closed sink says nothing
                self._disconnect()
                return
        except SinkWriteError as e:  # e.g. HELLO hit a stalled endpoint: the link itself is up
            write_error = str(e)
        except Exception as e:  # SinkUnavailableError, or a backend bug: retry later either way
            if opened:
                self._disconnect()  # never marked connected, so _release() would not
            if self._given_up:  # close() returned meanwhile: a closed sink retries nothing, and says so nowhere
                return
            self._connect_failed(e, backoff.policy.max_s)
            self._stop.wait(backoff.next_delay())
            return
        with self._cond:
            self._connected = True
            self._connects += 1
            was_down, self._down = self._down, False  # _down_error is kept until a write gets through
            quiet, self._carried = self._flapping, False
            self._said_again = self._said_again or (was_down and not quiet)
            # HELLO met a receiver that does not read: the new link counts toward a stall from the start
            self._failing_since = None if write_error is None else started
            if write_error is not None:
                self._last_error = write_error
            self._cond.notify_all()
        if was_down:  # the backoff is reset once a write gets through (_got_through): a link that flaps backs off
            _log.log(logging.DEBUG if quiet else logging.INFO, "%s: connected again", self.shown)

    def _announce(self) -> bool:
        """``_on_connected`` on a link just opened, unless close() gave up on the sink: False then, nothing written.
        The check and the announcement are one step to close(): it waits for one under way, and none starts after it
        gave up (checked without the lock, a HELLO could go out just after close() returned)."""
        with self._cond:
            if self._given_up:
                return False
            self._announcing = True
        try:
            self._on_connected()
        finally:
            with self._cond:
                self._announcing = False
                self._cond.notify_all()
        return True

    def _wait_for_announcement(self) -> None:
        """close(), giving up: a new link's HELLO + STATUS being written goes out whole before close() returns; a
        HELLO after close() read as a restart beside the sink replacing this one. Waited for at most
        :attr:`announcement_wait_s`: a write held longer (a serial or file write timeout of up to 60 s, a backend
        whose write hangs) held close(), and a daemon's stop, with no limit. Call with _cond held."""
        if not self._cond.wait_for(lambda: not self._announcing, self.announcement_wait_s):
            _log.warning("%s: closed while its HELLO + STATUS was still being written after %.1f s: it may go out "
                         "after the close", self.shown, self.announcement_wait_s)

    def _connect_failed(self, e: Exception, retry_s: float) -> None:
        """Count a failed connect; log it once per outage and per new error, not on every retry
        (a sink that is never plugged in would otherwise write a line every ``retry_s``, forever)."""
        expected = isinstance(e, SinkUnavailableError)
        error = str(e) if expected else f"{type(e).__name__}: {e}"
        with self._cond:
            repeat = error == self._down_error
            self._down, self._down_error = True, error
            if not repeat:  # the journal hears of this outage anew: its end is worth a "connected again" INFO
                self._flapping = self._said_again = False
            self._connect_failures += 1
            self._last_error = error
            self._cond.notify_all()
        if repeat:
            _log.debug("%s: %s; retrying", self.shown, error)
        elif expected:
            _log.warning("%s; retrying at least every %g s (repeats of this error logged at DEBUG)",
                         error, retry_s)
        else:  # a backend bug: its traceback once, not on every retry
            _log.error("%s: connect failed unexpectedly; retrying at least every %g s (repeats of this error "
                       "logged at DEBUG)", self.shown, retry_s, exc_info=e)

    def _next_frame(self) -> Optional[tuple[JointFrame, int]]:
        """The next queued frame; None when closed with nothing queued, or when the idle timeout passed."""
        with self._cond:
            self._cond.wait_for(lambda: self._queue or self._closed, self._idle_timeout_s())
            if not self._queue:
                return None
            frame, flags = self._queue.popleft()
            self._in_flight = 1
            flags |= self._error_flags
            self._error_flags = 0
            return frame, flags

    def _write_started(self) -> float:
        """Mark a write (frame or idle STATUS) in progress, for the stall watch; returns its start."""
        started = time.monotonic()
        with self._cond:
            self._writing_since = started
        return started

    def _write_failed(self, started: float) -> None:
        """A write that began at ``started`` failed on a link still open: a stall counts from the first.
        Call with _cond held."""
        if self._connected and self._failing_since is None:
            self._failing_since = started

    def _log_stall(self, failed: bool, what_got_through: str = "frames") -> None:
        """WARNING once when a stall is seen, INFO once when a frame (or an idle write) gets through after it
        (outside _cond)."""
        with self._cond:
            stalled_s = self._stalled_s(time.monotonic())
            if failed and stalled_s is not None and not self._stall_logged:
                self._stall_logged, what, error = True, "warn", self._last_error
            elif not failed and self._stall_logged:
                self._stall_logged, what, error = False, "info", None
            else:
                return
        if what == "warn":
            _log.warning("%s: stalled: no frame got through whole for %.1f s, the receiver is not reading (%s); "
                         "frames are dropped, or sent in part, and counted until a write gets through", self.shown,
                         stalled_s, error)
        else:
            _log.info("%s: %s get through again after a stall", self.shown, what_got_through)

    def _keep_refusal_as_last_error(self) -> None:
        """After a write: a refusal the receiver's side gave meanwhile is the last error (why the sink reads
        stalled, and what was last wrong once it no longer does). Call with _cond held."""
        refusing = self._receiver_refusing(time.monotonic())
        if refusing is not None:
            self._last_error = refusing[1]

    def _log_link_lost(self, e: SinkUnavailableError) -> None:
        """A WARNING; when the link was lost again before a write got through since it was said to be connected
        again (it flaps: the journal heard of this outage), a WARNING that it flaps the first time, then DEBUG. A link
        whose stall was logged meanwhile is no flap: the journal's last word was the stall, so its loss, and its
        failed opens, are a new outage's."""
        with self._cond:
            quiet = not self._carried and self._said_again and not self._stall_logged
            # the journal's last word was "connected again": the first loss after it is told, or the link read as up
            first_flap = quiet and not self._flapping
            self._flapping = quiet  # (a flapping link is quiet, unless it stalled: then it is told anew)
            if not quiet:  # told anew: a failed open after it is too, even with the error of the outage before
                self._down_error = None
        self._reopen_waits = quiet
        if first_flap:
            _log.warning("%s: link lost again before a frame got through (%s): it flaps; reopened at the backoff's "
                         "pace, its losses, failed opens of the same error and reopens logged at DEBUG until frames "
                         "get through", self.shown, e.reason)
        elif quiet:
            _log.debug("%s: link lost again before a frame got through (%s); reconnecting", self.shown, e.reason)
        else:  # the error's own text starts with the URL too: the line named it twice
            _log.warning("%s: link lost (%s); reconnecting", self.shown, e.reason)

    def _got_through(self, backoff: Backoff) -> None:
        """A frame or idle write got through: the link is proven, its backoff starts afresh, and a link that flapped
        is said to be back (INFO)."""
        with self._cond:
            recovered, self._flapping = self._flapping, False
            self._carried, self._said_again, self._down_error = True, False, None
        backoff.reset()
        if recovered:
            _log.info("%s: frames get through again after the link was lost and reopened repeatedly", self.shown)

    def _idle(self) -> bool:
        """The idle hook's write; returns whether it got through whole."""
        started = self._write_started()
        wrote = failed = False
        try:
            wrote = bool(self._on_idle())
        except SinkWriteError as e:
            failed = True
            with self._cond:
                self._last_error = str(e)
                self._write_failed(started)
        except SinkUnavailableError as e:
            self._log_link_lost(e)
            self._release()
            with self._cond:
                self._disconnects += 1
                self._last_error = str(e)
                self._down = True
        except Exception as e:  # a bug in a backend must not kill the worker silently
            _log.exception("%s: idle hook failed", self.shown)
            with self._cond:
                self._last_error = f"{type(e).__name__}: {e}"
        finally:
            with self._cond:
                self._writing_since = None
                self._keep_refusal_as_last_error()
                if wrote:  # the receiver reads again: with no frame to send (the rig down) nothing else ends it
                    self._failing_since = None
        if wrote or failed:  # with no frame to send the idle writes are what tells of a stall, and of its end
            self._log_stall(failed=failed, what_got_through="idle writes (STATUS)")
        return wrote

    def _run(self) -> None:
        with self._cond:  # started held: nothing is opened before release() (closed meanwhile: nothing ever is)
            self._cond.wait_for(lambda: not self._held or self._closed)
        backoff = Backoff(self.options.backoff)
        while not (self._closed and not self._queue):
            if not self._connected:
                if self._closed:
                    break  # nothing to flush into
                self._try_connect(backoff)
                continue
            item = self._next_frame()
            if item is None:
                if not self._closed and self._idle():
                    self._got_through(backoff)
                continue  # the loop's condition ends the worker once closed and drained
            frame, flags = item
            error: Optional[str] = None
            partial: Optional[str] = None  # part of the frame went out: sent, and what cut the rest
            started = self._write_started()
            try:
                self._deliver(frame, flags)
            except SinkPartialWriteError as e:  # the receiver has part of it: no gap, and the link carries
                partial = str(e)
            except SinkWriteError as e:
                error = str(e)
            except SinkUnavailableError as e:
                error = str(e)
                self._log_link_lost(e)
                self._release()
                with self._cond:
                    self._disconnects += 1
                    self._down = True
            except Exception as e:  # a bug in a backend must not kill the worker silently
                error = f"{type(e).__name__}: {e}"
                _log.exception("%s: frame %d could not be delivered", self.shown, frame.sequence)
            with self._cond:
                self._writing_since = None
                self._keep_refusal_as_last_error()
                if error is None:
                    self._sent += 1
                    if partial is None:
                        self._failing_since = None  # the receiver reads: no longer stalled
                    else:  # the rest met a full buffer: until a frame goes out whole, a stall counts on
                        self._partial += 1
                        self._last_error = partial
                        self._write_failed(started)
                else:
                    self._dropped_error += 1
                    self._last_error = error
                    self._write_failed(started)
                    # The next frame that gets through tells the receiver about this gap.
                    self._error_flags |= Flags.DROPPED | (flags & Flags.DECIMATED)
                self._in_flight = 0
                self._cond.notify_all()
            if error is None:  # in part too: the link carries, it does not flap
                self._got_through(backoff)
            self._log_stall(failed=error is not None or partial is not None)
        self._release()
