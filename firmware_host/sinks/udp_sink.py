"""udp://host:port - the protocol over UDP, one framed packet per datagram.

Each datagram carries one COBS frame with its 0x00 delimiter, so a receiver can
use the same stream decoder as on serial. UDP has no delivery feedback: losses
on the network show up only as sequence gaps at the receiver; the sender
counts what it could not send (full socket buffer, unreachable network). An IPv4
broadcast address (``udp://192.168.1.255:9000``) sends to every receiver on the subnet.
"""
from __future__ import annotations

import socket
from typing import Any, Optional

from firmware_host.errors import SinkUnavailableError, SinkWriteError
from firmware_host.protocol.encoder import encode
from firmware_host.protocol.messages import Message
from firmware_host.sinks.options import SinkOptions, reject_unknown_kw
from firmware_host.sinks.protocol_sink import ProtocolSink
from firmware_host.sinks.url import SinkUrl, host_port, parse_url


class DatagramLink:
    """An unconnected UDP socket to one address; shared by the udp and vmc sinks."""

    def __init__(self, url: str, host: str, port: int) -> None:
        self.url, self.host, self.port = url, host, port
        self._sock: Optional[socket.socket] = None
        self._addr: Any = None

    def open(self) -> None:
        try:
            family, _, _, _, addr = socket.getaddrinfo(self.host, self.port, type=socket.SOCK_DGRAM)[0]
            sock = socket.socket(family, socket.SOCK_DGRAM)
        except OSError as e:
            raise SinkUnavailableError(self.url, f"cannot resolve or open {self.host}:{self.port}: {e}") from e
        sock.setblocking(False)  # a full send buffer must drop, not stall the worker
        if family == socket.AF_INET:
            # a broadcast address (192.168.1.255) reaches every console on the subnet; without this
            # flag the kernel refuses each datagram (EACCES) and the sink would reconnect forever
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        self._sock, self._addr = sock, addr

    def close(self) -> None:
        sock, self._sock = self._sock, None
        if sock is not None:
            sock.close()

    def send(self, datagram: bytes) -> None:
        if self._sock is None:
            raise SinkUnavailableError(self.url, "socket not open")
        try:
            self._sock.sendto(datagram, self._addr)
        except BlockingIOError as e:
            raise SinkWriteError(self.url, "socket send buffer full") from e
        except OSError as e:  # network down, route gone: recreate the socket after backoff
            raise SinkUnavailableError(self.url, f"sendto {self.host}:{self.port} failed: {e}") from e


class UdpSink(ProtocolSink):
    scheme = "udp"

    def __init__(self, url: str, host: str, port: int, options: SinkOptions) -> None:
        super().__init__(url, options)
        self._link = DatagramLink(url, host, port)

    @classmethod
    def from_url(cls, url: str, **kw: Any) -> "UdpSink":
        u: SinkUrl = parse_url(url)
        host, port = host_port(u)
        options = SinkOptions.take(u, kw)
        u.reject_leftovers()
        reject_unknown_kw(url, kw)
        return cls(url, host, port, options)

    def _connect(self) -> None:
        self._link.open()

    def _disconnect(self) -> None:
        self._link.close()

    def _write_messages(self, messages: list[Message]) -> None:
        for m in messages:  # one packet per datagram: a lost datagram loses one packet
            self._link.send(encode(m))

    def _write_bytes(self, data: bytes) -> None:
        self._link.send(data)
