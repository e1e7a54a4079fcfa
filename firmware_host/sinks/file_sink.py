"""file:///path/joints.jsonl - one JSON object per packet, in the canonical form of the test vectors.

The path is absolute and percent-decoded (``file:///data/my%20run/joints.jsonl``; ``Path.as_uri()``
writes such URLs); the host is empty or ``localhost``. The values are the quantised wire values (mm,
confidence 0..255), so the file is a faithful record of what robots received. Lines are flushed one
by one, not fsynced (a stopped or killed daemon leaves whole lines; a power cut loses what the kernel
had not written back); a failed write (disk full, removed medium) closes the file and reopens it in
append mode with backoff, first ending a line the failed write cut short, so the one broken line stays
on its own. A path that cannot be opened (a folder, no permission, a named pipe no program reads yet) is
retried like an absent device.

The file grows for as long as the sink runs (about 650 bytes per JOINTS line); rotate it with
logrotate's ``copytruncate``: every write is O_APPEND, so it lands at the end of the truncated file.
"""
from __future__ import annotations

import errno
import json
import os
import stat
from typing import IO, Any, Optional
from urllib.parse import unquote

from firmware_host.errors import SinkConfigError, SinkUnavailableError
from firmware_host.protocol.messages import Message
from firmware_host.service_unit import read_only_hint  # the sandbox's EROFS: what to do
from firmware_host.sinks.options import SinkOptions, reject_unknown_kw
from firmware_host.sinks.protocol_sink import ProtocolSink
from firmware_host.sinks.url import SinkUrl, parse_url


def _no_reader_hint(e: OSError) -> str:
    """What ENXIO means here: a named pipe that no program has open for reading (yet)."""
    return " (a named pipe with no reader: retried until one opens it)" if e.errno == errno.ENXIO else ""


def _open_append(path: str) -> IO[str]:
    """``open(path, "a")``, except that a named pipe with no reader fails at once (ENXIO) instead of blocking: the
    worker waited in open() for ever, the sink ``connecting`` rather than ``down`` in the status file, and a
    close() left that thread behind (it wrote a HELLO into the pipe once a reader came, for a closed sink)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_NONBLOCK, 0o666)
    try:
        os.set_blocking(fd, True)  # once open, a slow reader holds the worker (never send()); its queue drops
        return os.fdopen(fd, "a", encoding="utf-8")
    except BaseException:
        os.close(fd)
        raise


class FileSink(ProtocolSink):
    scheme = "file"

    def __init__(self, url: str, path: str, options: SinkOptions) -> None:
        super().__init__(url, options)
        self.path = path
        self._fh: Optional[IO[str]] = None

    @classmethod
    def from_url(cls, url: str, **kw: Any) -> "FileSink":
        u: SinkUrl = parse_url(url)
        path = _local_path(url, u)
        options = SinkOptions.take(u, kw)
        u.reject_leftovers()
        reject_unknown_kw(url, kw)
        return cls(url, path, options)

    def _connect(self) -> None:
        try:
            self._fh = _open_append(self.path)
            self._end_cut_line()
        except OSError as e:
            self._disconnect()
            raise SinkUnavailableError(self.url, f"cannot open {self.path}: {e}{read_only_hint(e)}"
                                                 f"{_no_reader_hint(e)}") from e

    def _end_cut_line(self) -> None:
        """End the last line if a write cut it short (disk full, EFBIG): the HELLO written next must start
        a line of its own, not make one unparsable line of both."""
        assert self._fh is not None
        if not stat.S_ISREG(os.fstat(self._fh.fileno()).st_mode):
            return  # a FIFO or /dev/stdout: nothing to read back, and a reader there sees whole lines anyway
        with open(self.path, "rb") as f:
            if f.seek(0, os.SEEK_END) == 0:
                return
            f.seek(-1, os.SEEK_END)
            if f.read(1) == b"\n":
                return
        self._fh.write("\n")
        self._fh.flush()

    def _disconnect(self) -> None:
        fh, self._fh = self._fh, None
        if fh is not None:
            try:
                fh.close()
            except OSError:
                pass  # the write that failed already reported why

    def _write_messages(self, messages: list[Message]) -> bool:
        text = "".join(json.dumps(m.to_json(), separators=(",", ":")) + "\n" for m in messages)
        self._write_text(text)
        return True

    def _write_bytes(self, data: bytes) -> None:
        raise NotImplementedError("the file sink writes JSON lines, not frames")

    def _write_text(self, text: str) -> None:
        if self._fh is None:
            raise SinkUnavailableError(self.url, "file not open")
        try:
            self._fh.write(text)
            self._fh.flush()
        except OSError as e:
            raise SinkUnavailableError(self.url, f"write to {self.path} failed: {e}") from e


def _local_path(url: str, u: SinkUrl) -> str:
    """The file's path: percent-decoded, absolute, on this machine (host empty or ``localhost``)."""
    if u.netloc not in ("", "localhost"):
        # file://rel/path once meant a relative path; now a host, and another machine's file is not ours to write
        raise SinkConfigError(url, "host", u.netloc, "file:// takes a local, absolute path: file:///path/to/"
                                                     "joints.jsonl (or file://localhost/path/to/joints.jsonl)")
    path = unquote(u.path)
    if not path.startswith("/") or path == "/":
        raise SinkConfigError(url, "path", path, "expected file:///path/to/joints.jsonl")
    return path
