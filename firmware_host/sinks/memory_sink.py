"""memory://[label] - the protocol into an in-process byte buffer, for tests and tools.

The label is not used: it only makes URLs differ where sinks are keyed by URL (two memory sinks in
one daemon config). Every memory sink has its own buffer, whatever its label; ``read()`` it from the
object ``open_sink`` returned.

A first-class backend, not a mock: frames go through the same queue, rate
limiter, encoder and framing as on a real link, and ``read()`` returns the
exact bytes a UART would have carried.

Does not model: link speed (the write is instant; use ``max_fps`` to cap),
latency, corruption, or disconnects. The buffer is bounded by ``max_bytes``
(default 1 MiB); a write that does not fit is dropped and counted, like a
stalled link.
"""
from __future__ import annotations

import threading
from typing import Any

from firmware_host.errors import SinkWriteError
from firmware_host.sinks.options import SinkOptions, reject_unknown_kw
from firmware_host.sinks.protocol_sink import ProtocolSink
from firmware_host.sinks.url import SinkUrl, parse_url, positive_int


class MemorySink(ProtocolSink):
    scheme = "memory"

    def __init__(self, url: str, max_bytes: int, options: SinkOptions) -> None:
        super().__init__(url, options)
        self.max_bytes = max_bytes
        self._buf = bytearray()
        self._buf_lock = threading.Lock()  # read() runs on the caller's thread

    @classmethod
    def from_url(cls, url: str, **kw: Any) -> "MemorySink":
        u: SinkUrl = parse_url(url)
        max_bytes = u.take("max_bytes", positive_int, 1 << 20, kw)
        options = SinkOptions.take(u, kw)
        u.reject_leftovers()
        reject_unknown_kw(url, kw)
        return cls(url, max_bytes, options)

    def read(self) -> bytes:
        """Everything written since the previous read."""
        with self._buf_lock:
            data = bytes(self._buf)
            self._buf.clear()
        return data

    def _connect(self) -> None:
        pass  # always available

    def _disconnect(self) -> None:
        pass

    def _write_bytes(self, data: bytes) -> None:
        with self._buf_lock:
            if len(self._buf) + len(data) > self.max_bytes:
                raise SinkWriteError(self.url, f"buffer full ({self.max_bytes} bytes); call read()")
            self._buf += data
