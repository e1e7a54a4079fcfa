"""serial:///dev/ttyACM0?baud=921600 - the protocol over a UART or USB CDC port (pyserial).

Query: ``baud`` (default 115200), ``write_timeout_ms`` (default 100), plus the
common options. The rate is capped at what the baud rate carries (8N1, with
headroom); a faster producer is decimated with a warning, never backed up.
Unplug shows up as a failed write (EIO on Linux); the port is then reopened by
path with backoff, so use a stable path such as /dev/serial/by-id/....
"""
from __future__ import annotations

from typing import Any, Optional

import serial

from firmware_host.errors import SinkConfigError, SinkUnavailableError, SinkWriteError
from firmware_host.sinks.options import SinkOptions, reject_unknown_kw
from firmware_host.sinks.protocol_sink import ProtocolSink
from firmware_host.sinks.rate import serial_capacity_fps
from firmware_host.sinks.url import SinkUrl, parse_url, positive_int


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
        baud = u.take("baud", positive_int, 115200, kw)
        timeout_ms = u.take("write_timeout_ms", positive_int, 100, kw)
        options = SinkOptions.take(u, kw)
        u.reject_leftovers()
        reject_unknown_kw(url, kw)
        return cls(url, port, baud, timeout_ms / 1000.0, options)

    def link_capacity_fps(self) -> float:
        return serial_capacity_fps(self.baud, self.frame_bytes())

    def _connect(self) -> None:
        try:
            # exclusive: a second process writing the same port would interleave frames.
            self._ser = serial.Serial(self.port, self.baud, write_timeout=self.write_timeout_s, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as e:
            raise SinkUnavailableError(self.url, f"cannot open {self.port}: {e}") from e

    def _disconnect(self) -> None:
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except (serial.SerialException, OSError):
                pass  # already gone; nothing left to release

    def _write_bytes(self, data: bytes) -> None:
        if self._ser is None:
            raise SinkUnavailableError(self.url, "port not open")
        try:
            self._ser.write(data)
        except serial.SerialTimeoutException as e:
            # Part of a frame may be out: the next write starts with a delimiter.
            self._resync = True
            raise SinkWriteError(self.url, f"write timed out after {self.write_timeout_s * 1000:.0f} ms") from e
        except (serial.SerialException, OSError) as e:
            raise SinkUnavailableError(self.url, f"write to {self.port} failed: {e}") from e
