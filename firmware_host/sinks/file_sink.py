"""file:///path/joints.jsonl - one JSON object per packet, in the canonical form of the test vectors.

The path is absolute and percent-decoded (``file:///data/my%20run/joints.jsonl``; ``Path.as_uri()``
writes such URLs); the host is empty or ``localhost``. The values are the quantised wire values (mm,
confidence 0..255), so the file is a faithful record of what robots received. Lines are flushed one
by one, not fsynced (a stopped or killed daemon leaves whole lines; a power cut loses what the kernel
had not written back); a failed write (disk full, removed medium) closes the file and reopens it in
append mode with backoff, first ending a line the failed write cut short, so the one broken line stays
on its own. A path that cannot be opened (a folder, no permission, a named pipe no program reads yet) is
retried like an absent device. A regular file removed, or renamed away, while open (its folder deleted, a USB
stick's mount point remade, logrotate's default rename) is seen at the next write: that frame is dropped and
counted, the file at the path reopened (or created) with backoff, a HELLO first, and the frame after it carries
DROPPED. (Until session 62 the sink wrote on into the removed file, ``up``, every frame counted ``sent`` and none
on any disk.)

A named pipe (or /dev/stdout on one) whose reader stops reading fills the pipe's buffer: each write then waits
for room (poll, no CPU) at most ``write_timeout_ms`` (default 100, at most 60000), and the frame is dropped
and counted, the sink ``stalled`` once that lasts ``stall_s``; a line cut short by the timeout is ended by the
next write's leading newline. (Blocking writes held the worker for as long as the reader stayed away, the sink
reading ``up``.) A regular file's write is never cut short by it.

One sink writes a regular file at a time: the sink holds an exclusive ``flock`` on it while open
(``file_claim``), and a second sink on that file, in this process or another (two daemons on a ``sim://`` rig with
their own status files), is ``down`` naming the file and the holder's pid, retried until the first lets go. (Until
session 63 both appended, their lines interleaved.) A pipe or terminal is not claimed: its reader takes the lines.

The file grows for as long as the sink runs (about 650 bytes per JOINTS line); rotate it with
logrotate's ``copytruncate``: every write is O_APPEND, so it lands at the end of the truncated file.
"""
from __future__ import annotations

import errno
import itertools
import json
import os
import stat
from typing import Any, Optional

from firmware_host.errors import SinkConfigError, SinkUnavailableError
from firmware_host.protocol.messages import Message
from firmware_host.service_unit import read_only_hint  # the sandbox's EROFS: what to do
from firmware_host.sinks.fd_write import write_within
from firmware_host.sinks.file_claim import FileTaken, claim_file
from firmware_host.sinks.options import SinkOptions, reject_unknown_kw
from firmware_host.sinks.protocol_sink import ProtocolSink, judge_cut_write
from firmware_host.sinks.url import SinkUrl, int_in, parse_url, unquote_part
from ghnerf_runtime.path_check import path_problem, shown

#: Longest wait for room in a pipe whose reader stopped reading, as for serial:// (a joint line a minute late is
#: of no use).
MAX_WRITE_TIMEOUT_MS = 60_000


def _no_reader_hint(e: OSError) -> str:
    """What ENXIO means here: a named pipe that no program has open for reading (yet)."""
    return " (a named pipe with no reader: retried until one opens it)" if e.errno == errno.ENXIO else ""


def _open_append(path: str) -> int:
    """A descriptor like ``open(path, "a")``'s, except that a named pipe with no reader fails at once (ENXIO)
    instead of blocking: the worker waited in open() for ever, the sink ``connecting`` rather than ``down`` in
    the status file, and a close() left that thread behind (it wrote a HELLO into the pipe once a reader came,
    for a closed sink). It stays non-blocking: a pipe whose reader stops reading must not hold the worker's
    writes either (``write_within``)."""
    return os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_NONBLOCK, 0o666)


class FileSink(ProtocolSink):
    scheme = "file"

    def __init__(self, url: str, path: str, options: SinkOptions, write_timeout_s: float = 0.1) -> None:
        super().__init__(url, options)
        self.path = path
        self.write_timeout_s = write_timeout_s
        self._fd: Optional[int] = None
        self._opened: Optional[tuple[int, int]] = None  # (st_dev, st_ino) of a regular file opened; None: not one
        self._cut_line = False  # a write timed out inside a line: the next write starts with a newline

    @classmethod
    def from_url(cls, url: str, **kw: Any) -> "FileSink":
        u: SinkUrl = parse_url(url)
        path = _local_path(url, u)
        timeout_ms = u.take("write_timeout_ms", int_in(1, MAX_WRITE_TIMEOUT_MS, "milliseconds"), 100, kw)
        options = SinkOptions.take(u, kw)
        u.reject_leftovers()
        reject_unknown_kw(url, kw)
        return cls(url, path, options, timeout_ms / 1000.0)

    def _connect(self) -> None:
        try:
            self._fd = _open_append(self.path)
            self._opened = _regular_file_id(self._fd)
            if self._opened is not None:  # before a byte is written, the cut line's newline included
                claim_file(self._fd, self.path)
            self._cut_line = False  # a new reader of a pipe starts at the next line; a file is checked below
            self._end_cut_line()
        except FileTaken as e:  # another writer: down, retried, as a USB interface another program holds
            self._disconnect()
            raise SinkUnavailableError(self.url, str(e)) from None
        except OSError as e:
            self._disconnect()
            raise SinkUnavailableError(self.url, f"cannot open {shown(self.path)}: {e}{read_only_hint(e)}"
                                                 f"{_no_reader_hint(e)}") from e

    def _end_cut_line(self) -> None:
        """End the last line if a write cut it short (disk full, EFBIG): the HELLO written next must start
        a line of its own, not make one unparsable line of both."""
        assert self._fd is not None
        if not stat.S_ISREG(os.fstat(self._fd).st_mode):
            return  # a FIFO or /dev/stdout: nothing to read back, and a reader there sees whole lines anyway
        with open(self.path, "rb") as f:
            if f.seek(0, os.SEEK_END) == 0:
                return
            f.seek(-1, os.SEEK_END)
            if f.read(1) == b"\n":
                return
        os.write(self._fd, b"\n")  # a regular file: never EAGAIN

    def _disconnect(self) -> None:
        fd, self._fd = self._fd, None
        self._opened = None
        if fd is not None:
            try:
                os.close(fd)
            except OSError:
                pass  # the write that failed already reported why

    def _write_messages(self, messages: list[Message]) -> bool:
        """One write of the messages' lines. False: the frame's lines went out but the HELLO + STATUS behind
        them did not (a pipe that stopped taking them); that STATUS is owed (ProtocolSink). Raises as
        :func:`~firmware_host.sinks.protocol_sink.judge_cut_write` when the frame's own lines were cut."""
        lines = [(json.dumps(m.to_json(), separators=(",", ":")) + "\n").encode("utf-8") for m in messages]
        lead = b"\n" if self._cut_line else b""
        data = lead + b"".join(lines)
        written = self._write_within(data)
        if written == len(data):
            self._cut_line = False
            return True
        if written:  # the reader holds part of a line unless the cut fell just after a newline
            self._cut_line = data[written - 1:written] != b"\n"
        reason = (f"write timed out after {self.write_timeout_s * 1000:.0f} ms ({written} of {len(data)} bytes out; "
                  "the reader is not reading)")
        # a line is out with its newline; the JOINTS line out and a JOINTS_2D line not: the frame is sent in part
        line_ends = [len(lead) + end for end in itertools.accumulate(map(len, lines))]
        return judge_cut_write(self.url, reason, messages, line_ends, written)

    def _check_still_at_path(self) -> None:
        """The open regular file must still be the one at ``path``: written past its removal, lines land in an
        inode no one can read. A pipe or /dev/stdout is left alone (its reader gets the lines either way).

        :raises SinkUnavailableError: the path names no file, or another one, now; the sink reopens it.
        """
        if self._opened is None:
            return
        try:
            st = os.stat(self.path)
            now_there: Optional[tuple[int, int]] = (st.st_dev, st.st_ino)
        except OSError:
            now_there = None
        if now_there != self._opened:
            raise SinkUnavailableError(self.url, f"{shown(self.path)} was removed or replaced while open; reopening it")

    def _write_bytes(self, data: bytes) -> None:
        raise NotImplementedError("the file sink writes JSON lines, not frames")

    def _write_within(self, data: bytes) -> int:
        """Write ``data`` as far as it goes within ``write_timeout_s`` (a regular file: all of it)."""
        if self._fd is None:
            raise SinkUnavailableError(self.url, "file not open")
        self._check_still_at_path()
        try:
            return write_within(self._fd, data, self.write_timeout_s)
        except OSError as e:
            raise SinkUnavailableError(self.url, f"write to {shown(self.path)} failed: {e}") from e


def _regular_file_id(fd: int) -> Optional[tuple[int, int]]:
    """(st_dev, st_ino) of a regular file's descriptor, to tell when its path names another file; None for a pipe."""
    st = os.fstat(fd)
    return (st.st_dev, st.st_ino) if stat.S_ISREG(st.st_mode) else None


def _local_path(url: str, u: SinkUrl) -> str:
    """The file's path: percent-decoded, absolute, on this machine (host empty or ``localhost``)."""
    if u.netloc not in ("", "localhost"):
        # file://rel/path once meant a relative path; now a host, and another machine's file is not ours to write
        raise SinkConfigError(url, "host", u.netloc, "file:// takes a local, absolute path: file:///path/to/"
                                                     "joints.jsonl (or file://localhost/path/to/joints.jsonl)")
    path = unquote_part(url, "path", u.path)
    if not path.startswith("/") or path == "/":
        raise SinkConfigError(url, "path", path, "expected file:///path/to/joints.jsonl")
    problem = path_problem(path)  # a NUL byte or a name too long: said now, not as a traceback from os.open
    if problem is not None:
        raise SinkConfigError(url, "path", path, problem)
    return path
