"""file://path.jsonl - one JSON object per packet, in the canonical form of the test vectors.

The values are the quantised wire values (mm, confidence 0..255), so the file
is a faithful record of what robots received. Lines are flushed one by one; a
failed write (disk full, removed medium) closes the file and reopens it in
append mode with backoff.
"""
from __future__ import annotations

import json
from typing import IO, Any, Optional

from firmware_host.errors import SinkConfigError, SinkUnavailableError
from firmware_host.protocol.messages import Message
from firmware_host.sinks.options import SinkOptions, reject_unknown_kw
from firmware_host.sinks.protocol_sink import ProtocolSink
from firmware_host.sinks.url import SinkUrl, parse_url


class FileSink(ProtocolSink):
    scheme = "file"

    def __init__(self, url: str, path: str, options: SinkOptions) -> None:
        super().__init__(url, options)
        self.path = path
        self._fh: Optional[IO[str]] = None

    @classmethod
    def from_url(cls, url: str, **kw: Any) -> "FileSink":
        u: SinkUrl = parse_url(url)
        path = u.netloc + u.path  # file://rel/path.jsonl and file:///abs/path.jsonl
        if not path:
            raise SinkConfigError(url, "path", path, "expected file:///path/to/joints.jsonl")
        options = SinkOptions.take(u, kw)
        u.reject_leftovers()
        reject_unknown_kw(url, kw)
        return cls(url, path, options)

    def _connect(self) -> None:
        try:
            self._fh = open(self.path, "a", encoding="utf-8")
        except OSError as e:
            raise SinkUnavailableError(self.url, f"cannot open {self.path}: {e}") from e

    def _disconnect(self) -> None:
        fh, self._fh = self._fh, None
        if fh is not None:
            try:
                fh.close()
            except OSError:
                pass  # the write that failed already reported why

    def _write_messages(self, messages: list[Message]) -> None:
        text = "".join(json.dumps(m.to_json(), separators=(",", ":")) + "\n" for m in messages)
        self._write_text(text)

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
