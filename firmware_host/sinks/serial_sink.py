"""serial:///dev/ttyACM0?baud=921600 - the protocol over a UART or USB CDC port (pyserial).

Query: ``baud`` (default 115200; 50 to 2**31 - 1), ``write_timeout_ms`` (default
100, at most 60000), plus the common options. The device path is percent-decoded
(a ``#`` in it is written ``%23``), as in file:// and rig URLs. The rate is capped
at what the baud rate carries (8N1, with headroom); a faster producer is
decimated with a warning, never backed up.
Unplug shows up as a failed write (EIO on Linux); the port is then reopened by
path with backoff, so use a stable path such as /dev/serial/by-id/....

A peer that stops reading fills the tty's buffer: each write then waits for
room (poll, no CPU) at most ``write_timeout_ms`` and the rest of the frame is
dropped and counted. The next write starts with a 0x00 delimiter, so the
receiver discards the cut frame (one decode error) and decodes the next one.
pyserial's own ``write()`` is not used: on a full buffer it retries without
waiting (a busy loop), and it reports a timeout for a write that did go out.

Closing gives the bytes the tty still holds ``CLOSE_DRAIN_S`` to go out and
discards the rest (TCOFLUSH) before the close: the kernel's close of a USB CDC
port whose receiver stopped reading would otherwise wait for them up to the
tty's ``closing_wait`` (30 s), past the unit's ``TimeoutStopSec``.
"""
from __future__ import annotations

import errno
import itertools
import logging
import os
import termios
import time
from typing import Any, Optional

import serial

from firmware_host.errors import SinkConfigError, SinkUnavailableError, SinkWriteError
from firmware_host.protocol.encoder import encode
from firmware_host.protocol.messages import Message
from firmware_host.sinks.file_claim import holder_pid, holder_text
from firmware_host.sinks.fd_write import write_within
from firmware_host.sinks.options import SinkOptions, reject_unknown_kw
from firmware_host.sinks.protocol_sink import ProtocolSink, judge_cut_write
from firmware_host.sinks.rate import serial_capacity_fps
from firmware_host.sinks.url import SinkUrl, int_in, parse_url, unquote_part
from ghnerf_runtime.path_check import path_problem

_log = logging.getLogger(__name__)

#: The rates a port may be asked for: B50 is the lowest POSIX rate, and pyserial hands any other rate to
#: termios as a signed 32-bit int (a larger one failed every open with an OverflowError, retried forever).
MIN_BAUD, MAX_BAUD = 50, 2**31 - 1
#: Longest wait for room in a stalled port: a joint frame a minute late is of no use (and a value past
#: select()'s range, once accepted, failed every frame of a stalled port with a traceback in the journal).
MAX_WRITE_TIMEOUT_MS = 60_000
#: How long a closing port may take to send what its tty still holds (TIOCOUTQ) before the rest is
#: discarded: a few frames at 115200 baud; a stop or reload must not wait on a receiver that stopped reading.
CLOSE_DRAIN_S = 0.25
#: What pyserial's ``exclusive=True`` open raises (its ``flock(LOCK_EX | LOCK_NB)``) when another open file holds the
#: port's lock (it keeps the errno); its O_NONBLOCK open of the tty, which waits for no carrier, does not say it.
_LOCK_HELD = (errno.EAGAIN, errno.EWOULDBLOCK)


class SerialSink(ProtocolSink):
    scheme = "serial"

    def __init__(self, url: str, port: str, baud: int, write_timeout_s: float, options: SinkOptions) -> None:
        self.port = port
        self.baud = baud
        self.write_timeout_s = write_timeout_s
        super().__init__(url, options)
        self._ser: Optional[serial.Serial] = None

    @classmethod
    def from_url(cls, url: str, **kw: Any) -> "SerialSink":
        u: SinkUrl = parse_url(url)
        port = u.netloc + u.path
        if not port:
            raise SinkConfigError(url, "port", port, "expected serial:///dev/ttyACM0")
        if u.netloc or not u.path.startswith("/"):
            # serial://dev/ttyACM0 would be the relative path dev/ttyACM0 (its "dev" a URL's host), opened
            # from the daemon's working directory and retried forever: the path is absolute (as for file://)
            raise SinkConfigError(url, "port", port, f"expected an absolute path: serial:///{port.lstrip('/')}")
        # percent-decoded as file:// and rig URLs are: a '#' in a by-id name can only be written %23
        port = unquote_part(url, "port", port)
        problem = path_problem(port)  # a NUL byte or a name too long: said now, not "cannot open" retried for ever
        if problem is not None:
            raise SinkConfigError(url, "port", port, problem)
        baud = u.take("baud", int_in(MIN_BAUD, MAX_BAUD, "bits per second"), 115200, kw)
        timeout_ms = u.take("write_timeout_ms", int_in(1, MAX_WRITE_TIMEOUT_MS, "milliseconds"), 100, kw)
        options = SinkOptions.take(u, kw)
        u.reject_leftovers()
        reject_unknown_kw(url, kw)
        return cls(url, port, baud, timeout_ms / 1000.0, options)

    def link_capacity_fps(self) -> float:
        return serial_capacity_fps(self.baud, self.frame_bytes())

    def _connect(self) -> None:
        try:
            # exclusive: a second process writing the same port would interleave frames.
            # write_timeout=0: the sink writes the fd itself (_write_within), never through pyserial.
            self._ser = serial.Serial(self.port, self.baud, write_timeout=0, exclusive=True)
            os.set_blocking(self._ser.fileno(), False)  # a full buffer must return EAGAIN, not block
        except (serial.SerialException, OSError, ValueError) as e:
            self._disconnect()
            if getattr(e, "errno", None) in _LOCK_HELD:
                raise SinkUnavailableError(self.url, _lock_held_reason(self.port)) from e
            raise SinkUnavailableError(self.url, f"cannot open {self.port}: {e}") from e

    def _disconnect(self) -> None:
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                if not _drain_then_discard(ser, CLOSE_DRAIN_S):
                    _log.info("%s: discarded what the port had not sent within %.2f s of closing "
                              "(the receiver is not reading)", self.shown, CLOSE_DRAIN_S)
            finally:
                try:
                    ser.close()
                except (serial.SerialException, OSError):
                    pass  # already gone; nothing left to release

    def _write_messages(self, messages: list[Message]) -> bool:
        packets = [encode(m) for m in messages]
        return self._write_framed(b"".join(packets), messages, list(itertools.accumulate(map(len, packets))))

    def _write_bytes(self, data: bytes) -> None:
        # ProtocolSink's hook (framed packets, bounds unknown): the whole of ``data`` is the frame.
        self._write_framed(data, None, [len(data)])

    def _write_framed(self, data: bytes, messages: Optional[list[Message]], packet_ends: list[int]) -> bool:
        """Write the framed packets of ``messages`` (None: one frame whose bounds are unknown), ``packet_ends``
        where each ends in ``data``. A write cut short sets ``_resync``: the next write's leading 0x00 ends the cut
        frame. Returns whether all of ``data`` went out (False: a trailing HELLO + STATUS was cut, the STATUS owed).

        :raises SinkPartialWriteError: a frame's JOINTS went out, a JOINTS_2D behind it did not.
        :raises SinkWriteError: the frame (or a write without one) did not go out.
        """
        lead = b"\x00" if self._resync else b""  # ends a frame a timeout cut short
        data = lead + data
        written = self._write_within(data, self.write_timeout_s)
        if written == len(data):
            self._resync = False
            return True
        if written:
            self._resync = True  # the receiver holds part of a frame: the next write's 0x00 ends it
        reason = (f"write timed out after {self.write_timeout_s * 1000:.0f} ms ({written} of {len(data)} bytes out; "
                  "the peer is not reading)")
        # a packet is out once all but its 0x00 is: the next write's leading delimiter supplies that
        ends = [len(lead) + end - 1 for end in packet_ends]
        if messages is None:
            if written < ends[-1]:
                raise SinkWriteError(self.url, reason)
            return False
        return judge_cut_write(self.url, reason, messages, ends, written)

    def _write_within(self, data: bytes, timeout_s: float) -> int:
        """Write ``data`` as far as the port takes it within ``timeout_s``; returns the bytes written.

        Waits for room with poll(), so a peer that stops reading costs no CPU.
        :raises SinkUnavailableError: the port is gone (EIO after an unplug).
        """
        if self._ser is None:
            raise SinkUnavailableError(self.url, "port not open")
        try:
            return write_within(self._ser.fileno(), data, timeout_s)
        except OSError as e:
            raise SinkUnavailableError(self.url, f"write to {self.port} failed: {e}") from e


def _lock_held_reason(port: str) -> str:
    """Why ``port`` did not open when its exclusive ``flock`` is held: by whom (``/proc/locks``) and, when ``port``
    is a link (``/dev/serial/by-id/...``), the node it leads to. pyserial said only "Could not exclusively lock
    port ...: Resource temporarily unavailable", which read as a fault of the port rather than another writer."""
    where = port
    holder = "another program"
    try:
        node = os.path.realpath(port)
        st = os.stat(node)
    except (OSError, ValueError):  # gone since the open: the retry will say so
        pass
    else:
        where = port if node == port else f"{port} (which is {node})"
        holder = holder_text(holder_pid(st.st_dev, st.st_ino))
    return (f"cannot open {where}: {holder} holds its exclusive lock: one writer per port, as two would interleave "
            "their frames; stop that one, or give this sink another port (retried until that one lets go)")


def _drain_then_discard(ser: serial.Serial, drain_s: float) -> bool:
    """Wait up to ``drain_s`` for the port's output queue to empty, then discard what is left.

    Returns whether it emptied in time. Without the discard, close() on a USB CDC port (cdc-acm's flush
    unlinks the pending URBs) or on a UART held off by flow control blocks in the kernel until the queue
    drains or the tty's ``closing_wait`` (30 s by default) runs out. An unplugged port's ioctls fail:
    nothing is left to send then.
    """
    deadline = time.monotonic() + drain_s
    try:
        while ser.out_waiting:
            if time.monotonic() >= deadline:
                ser.reset_output_buffer()  # TCOFLUSH: stale joints, of no use to anyone now
                return False
            time.sleep(0.01)
    except (serial.SerialException, OSError, termios.error):
        pass  # the port is gone (EIO): the kernel has already dropped its queue
    return True
