"""udp://host:port - the protocol over UDP, one framed packet per datagram.

Each datagram carries one COBS frame with its 0x00 delimiter, so a receiver can
use the same stream decoder as on serial. UDP has no delivery feedback: losses
on the network show up only as sequence gaps at the receiver; the sender
counts what it could not send (full socket buffer, unreachable network); a frame whose JOINTS went out and whose
JOINTS_2D then met a full buffer counts as sent and ``partial``: the receiver has its seq, no gap. An IPv4
broadcast address (``udp://192.168.1.255:9000``) sends to every receiver on the subnet.

The socket is connected to the receiver's address, so the one answer the network gives, an ICMP port (or
host) unreachable for an earlier datagram, comes back as the error of the next send: nothing listens there
(a receiver not started, or a typo in the port). That error fails the send it comes with, sending nothing,
so the datagram is sent again at once: frames keep going out, and a receiver that starts gets the next one.
The refusals are kept as the link's state: a WARNING once, the sink ``stalled`` (after its ``stall_s``) with
the refusal as ``last_error``, and an INFO once a datagram sent ``REFUSAL_QUIET_S`` after the last refusal
drew none (counted in datagrams, not in time: a sink sending every few seconds, its rig down, is no quieter), as
a send ``REFUSAL_ANSWER_S`` or more after it finds (an answer sent back takes a while: a send just after it, such
as the second of a vmc:// frame's two bundles, cannot tell). Before,
the socket was unconnected and such a sink read ``up``, every frame ``sent``, with nobody receiving.

A host name is resolved to its IPv4 address when it has one (a receiver bound to
0.0.0.0 never hears ::1, which glibc may list first for ``localhost``), to IPv6
when that is all it has or the host is an IPv6 literal. The name is looked up
again every ``resolve_s`` (30, at least 1) seconds in a thread of its own, so a robot whose
DHCP or mDNS address changes is found again while the frames keep going out. While
the name still lists the address in use, that address is kept, whatever the order
of the answer (round-robin DNS, a host on two networks).
"""
from __future__ import annotations

import errno
import ipaddress
import logging
import socket
import threading
import time
from typing import Any, Optional

from drivers.url import shown_url
from firmware_host.addresses import ipv4_first
from firmware_host.errors import SinkConfigError, SinkPartialWriteError, SinkUnavailableError, SinkWriteError
from firmware_host.protocol.encoder import encode
from firmware_host.protocol.messages import Message
from firmware_host.sinks.options import SinkOptions, reject_unknown_kw
from firmware_host.sinks.protocol_sink import ProtocolSink, frame_packets
from firmware_host.sinks.url import SinkUrl, host_port, parse_url, positive_float

_log = logging.getLogger(__name__)

#: Seconds between lookups of a host name (``resolve_s``); IP literals are never looked up again.
RESOLVE_S = 30.0
#: Shortest ``resolve_s``: a lookup a second finds a moved robot soon enough, and a name server is not asked once
#: per frame (``resolve_s=1e-9`` was accepted: a lookup for every frame sent).
MIN_RESOLVE_S = 1.0
#: Seconds after the last refusal from which a datagram that draws none shows the receiver there again: Linux
#: answers a host's datagrams to a closed port with at most about one ICMP port unreachable a second
#: (``icmp_ratelimit``), so while nothing listens a datagram sent that long after the last refusal draws one.
REFUSAL_QUIET_S = 3.0
#: What an ICMP answer to an earlier datagram leaves on a connected UDP socket for its next send: port, host
#: or network unreachable. Host and network unreachable may also be the send's own (no route): the send
#: repeated tells them apart.
_ICMP_ERRNOS = frozenset({errno.ECONNREFUSED, errno.EHOSTUNREACH, errno.EHOSTDOWN, errno.ENETUNREACH})
#: Those of ``_ICMP_ERRNOS`` a send may meet on its own (no route now); a port refusal is always an answer.
_ROUTE_ERRNOS = _ICMP_ERRNOS - {errno.ECONNREFUSED}
#: Seconds a datagram's ICMP answer is given to come back (a round trip, a VPN's included) before a send that finds
#: none waiting shows the datagram drew none. The send right after it cannot: vmc:// sends a frame as two bundles
#: back to back, and after a pause past REFUSAL_QUIET_S the second ended the refusals while the first one's answer
#: was on its way (an INFO "a receiver is at ... again" with nobody there, then a new WARNING at the next frame).
REFUSAL_ANSWER_S = 1.0


def take_resolve_s(u: SinkUrl, kw: dict) -> float:
    """The ``resolve_s`` option of a udp:// or vmc:// URL (or keyword): at least ``MIN_RESOLVE_S``.

    :raises SinkConfigError: naming the URL, ``resolve_s`` and the value.
    """
    resolve_s = u.take("resolve_s", positive_float, RESOLVE_S, kw)
    if resolve_s < MIN_RESOLVE_S:
        raise SinkConfigError(u.url, "resolve_s", resolve_s, f"must be at least {MIN_RESOLVE_S:g} seconds (a name "
                                                             "looked up more often asks its name server per frame)")
    return resolve_s


def resolve(url: str, host: str, port: int, keep: Any = None) -> tuple[int, Any]:
    """``(family, sockaddr)`` for ``host``: its first IPv4 address, else its first address; ``keep`` (the
    sockaddr in use) instead while the name still lists it.

    :raises SinkUnavailableError: the name does not resolve (now).
    """
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
    except OSError as e:
        raise SinkUnavailableError(url, f"cannot resolve {host}:{port}: {e}") from e
    try:
        return ipv4_first(infos, keep)
    except ValueError as e:
        raise SinkUnavailableError(url, f"cannot resolve {host}:{port}: {e}") from e


def _no_route_twice(pending: OSError, again: OSError) -> bool:
    """Whether a send and its repeat both met host or network unreachable: the sends' own (no route now), not an
    ICMP answer to an earlier datagram."""
    return pending.errno in _ROUTE_ERRNOS and again.errno in _ROUTE_ERRNOS


def _is_ip_literal(host: str) -> bool:
    try:
        ipaddress.ip_address(host)
    except ValueError:
        return False
    return True


class DatagramLink:
    """A UDP socket connected to one address (for the network's refusals: module docstring); shared by the
    udp and vmc sinks.

    Only the sink's worker calls open/send/close; the lookup thread hands its answer over through
    ``_fresh`` and the worker applies it on its next send."""

    def __init__(self, url: str, host: str, port: int, resolve_s: float = RESOLVE_S) -> None:
        self.url, self.host, self.port = url, host, port
        self.shown = shown_url(url)  # as logs show it: without a password, on one line
        self.resolve_s = resolve_s
        self._sock: Optional[socket.socket] = None
        self._family = 0
        self._addr: Any = None
        self._is_name = not _is_ip_literal(host)
        self._lock = threading.Lock()  # guards _fresh, _looking_up, _resolved_at and _generation
        self._fresh: Optional[tuple[int, Any]] = None
        # Bumped by each open(): a lookup started for an earlier connection answers too late to be used.
        self._generation = 0
        self._looking_up = False
        self._resolved_at = 0.0
        # (first, last, why) of the current stretch of refused datagrams, monotonic seconds; replaced whole, as
        # stats() reads it from another thread. None: none refused within REFUSAL_QUIET_S.
        self._refusal: Optional[tuple[float, float, str]] = None
        # When the first datagram sent REFUSAL_QUIET_S or more after the stretch's last refusal went out (monotonic),
        # on this socket: the one whose answer, or none, ends the stretch (_end_refusal_if_answered). None: no such
        # datagram yet.
        self._quiet_probe: Optional[float] = None

    def open(self) -> None:
        family, addr = resolve(self.url, self.host, self.port)
        with self._lock:
            self._generation += 1
            self._fresh, self._resolved_at = None, time.monotonic()
        self._use(family, addr)

    def _use(self, family: int, addr: Any) -> None:
        """Send to ``addr`` from now on, with a new socket when it is another address: a UDP socket keeps the
        source address its first connect chose, which may be another interface's than the new route's."""
        if self._sock is None or family != self._family or addr != self._addr:
            sock = self._connected_socket(family, addr)
            self.close()  # (and the refusals of the old address, which say nothing of this one)
            self._sock, self._family = sock, family
        self._addr = addr

    def _connected_socket(self, family: int, addr: Any) -> socket.socket:
        """A non-blocking socket connected to ``addr`` (a UDP connect sends nothing): the network's refusals of
        what goes there come back as errors, which an unconnected socket never hears of."""
        try:
            sock = socket.socket(family, socket.SOCK_DGRAM)
        except OSError as e:
            raise SinkUnavailableError(self.url, f"cannot open a socket to {self.host}:{self.port}: {e}") from e
        try:
            sock.setblocking(False)  # a full send buffer must drop, not stall the worker
            if family == socket.AF_INET:
                # a broadcast address (192.168.1.255) reaches every console on the subnet; without this
                # flag the kernel refuses each datagram (EACCES) and the sink would reconnect forever
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
            sock.connect(addr)
        except OSError as e:  # no route to it now: retried with the backoff, as a failed send was
            sock.close()
            raise SinkUnavailableError(self.url, f"cannot send to {self.host}:{self.port}: {e}") from e
        return sock

    def close(self) -> None:
        sock, self._sock = self._sock, None
        self._refusal, self._quiet_probe = None, None
        if sock is not None:
            sock.close()

    def refusing(self) -> Optional[tuple[float, str]]:
        """``(since, why)`` from the first refusal of the receiver's side until a datagram sent ``REFUSAL_QUIET_S``
        after the last one draws none within ``REFUSAL_ANSWER_S`` (:meth:`_end_refusal_if_answered`); None otherwise.
        Safe from any thread."""
        refusal = self._refusal
        return None if refusal is None else (refusal[0], refusal[2])

    def _note_refusal(self, error: OSError) -> None:
        """Keep the refusal an ICMP answer left on the socket; a WARNING at the first of a stretch."""
        now = time.monotonic()
        if error.errno == errno.ECONNREFUSED:
            why = (f"nothing receives at {self.host}:{self.port}: its host refused a datagram (ICMP port "
                   "unreachable: no program has that UDP port open there)")
        else:
            why = f"{self.host}:{self.port} is unreachable: {error.strerror} (an ICMP answer to a datagram)"
        refusal = self._refusal
        first = now if refusal is None else refusal[0]
        self._refusal, self._quiet_probe = (first, now, why), None  # a datagram after this one must draw none
        if refusal is None:  # (not first == now: one send may note twice within a clock tick)
            _log.warning("%s: %s; still sending, so a receiver that starts gets the next frame", self.shown, why)

    def _note_sent(self, now: float) -> None:
        """Keep the datagram that went out at ``now`` as the stretch's quiet probe if it is the first one sent
        ``REFUSAL_QUIET_S`` or more after the last refusal."""
        refusal = self._refusal
        if refusal is not None and self._quiet_probe is None and now - refusal[1] >= REFUSAL_QUIET_S:
            self._quiet_probe = now

    def _end_refusal_if_answered(self, now: float) -> None:
        """End the refusals once the quiet probe (:meth:`_note_sent`) drew none: a send at ``now``,
        ``REFUSAL_ANSWER_S`` or more after it, found none pending. Judged by a datagram, not by the time passed:
        the idle STATUS of a sink whose rig is down goes out every ``status_s``, and at ``status_s=5`` each gap
        ended the stretch, a WARNING and an INFO at every datagram, and the sink never read ``stalled``. Nor by
        a send just after the probe, before its answer could come back (vmc://'s second bundle of a frame)."""
        refusal, probe = self._refusal, self._quiet_probe
        if refusal is not None and probe is not None and now - probe >= REFUSAL_ANSWER_S:
            self._refusal, self._quiet_probe = None, None
            _log.info("%s: no datagram refused for %g s: a receiver is at %s:%s again", self.shown,
                      REFUSAL_QUIET_S, self.host, self.port)

    def _refresh(self) -> None:
        """Apply a finished lookup; start the next one when due, in its own thread: a slow DNS or mDNS
        answer (seconds, for a name that went away) must not hold up the frames."""
        now = time.monotonic()
        with self._lock:
            fresh, self._fresh = self._fresh, None
            due = self._is_name and not self._looking_up and now - self._resolved_at >= self.resolve_s
            if due:
                self._looking_up, self._resolved_at = True, now
            generation = self._generation
        if fresh is not None and fresh[1] != self._addr:
            _log.info("%s: %s now resolves to %s (was %s)", self.shown, self.host, fresh[1][0], self._addr[0])
            self._use(*fresh)
        if due:
            # the thread gets what it needs as arguments: it never reads the worker's _addr
            threading.Thread(target=self._look_up, args=(generation, self._addr), name=f"resolve {self.host}",
                             daemon=True).start()

    def _look_up(self, generation: int, addr: Any) -> None:
        """One lookup for the connection ``generation`` (sending to ``addr`` when it started); its answer is
        dropped when the link was reopened meanwhile: that open() looked the name up afresh."""
        try:
            fresh: Optional[tuple[int, Any]] = resolve(self.url, self.host, self.port, keep=addr)
        except SinkUnavailableError as e:  # keep sending to the address it had; the next lookup may work
            _log.debug("%s; still sending to %s", e, addr[0] if addr else addr)
            fresh = None
        with self._lock:
            self._looking_up = False
            if fresh is not None and generation == self._generation:
                self._fresh = fresh

    def _send_past_a_pending_error(self, datagram: bytes) -> bool:
        """Send ``datagram``; an error an ICMP answer to an earlier one left on the socket fails this send unsent,
        so it is sent again, and the error kept (:meth:`refusing`) whatever the repeat meets: a full send buffer
        loses this datagram, yet the earlier one was refused all the same (before, that refusal went unrecorded and
        the sink named the full buffer only). An error the second send meets is raised; host or network unreachable
        met by both sends is their own (no route now, such as after the device's own address changed: the socket
        keeps the source address of its connect), not a refusal. True: an earlier datagram was refused."""
        assert self._sock is not None
        try:
            self._sock.send(datagram)
            return False
        except OSError as e:
            if e.errno not in _ICMP_ERRNOS:
                raise
            pending = e
        try:
            self._sock.send(datagram)
        except OSError as again:
            if not _no_route_twice(pending, again):
                self._note_refusal(pending)
            raise
        self._note_refusal(pending)
        return True

    def _naming_the_refusal(self, reason: str) -> str:
        """``reason`` a write failed for, and the refusals going on (why the sink reads stalled), if any."""
        refusal = self._refusal
        return reason if refusal is None else f"{reason}; {refusal[2]}"

    def send_in_turn(self, datagrams: list[bytes]) -> None:
        """Send one frame's ``datagrams`` in turn (vmc://'s two bundles, udp://'s JOINTS and JOINTS_2D).

        :raises SinkPartialWriteError: one after the first met a full send buffer: the receiver has the first ones,
            so the frame is sent in part, not lost (the rest is not sent later: the next frame supersedes it).
        :raises SinkWriteError: the first one did: nothing of the frame went out.
        :raises SinkUnavailableError: as :meth:`send` (the link is reopened; the frame counts as dropped).
        """
        for sent, datagram in enumerate(datagrams):
            try:
                self.send(datagram)
            except SinkWriteError as e:
                if not sent:
                    raise
                raise SinkPartialWriteError(self.url, e.reason, sent, len(datagrams)) from e

    def send(self, datagram: bytes) -> None:
        if self._sock is None:
            raise SinkUnavailableError(self.url, "socket not open")
        self._refresh()
        try:
            refused = self._send_past_a_pending_error(datagram)
        except BlockingIOError as e:
            raise SinkWriteError(self.url, self._naming_the_refusal("socket send buffer full")) from e
        except ConnectionRefusedError as e:  # refused again at once: this datagram is lost, the link is not
            self._note_refusal(e)
            raise SinkWriteError(self.url, self._refusal[2] if self._refusal else str(e)) from e
        except OSError as e:  # network down, route gone: recreate the socket after backoff
            raise SinkUnavailableError(self.url, f"send to {self.host}:{self.port} failed: {e}") from e
        now = time.monotonic()
        if not refused:
            self._end_refusal_if_answered(now)
        self._note_sent(now)


class UdpSink(ProtocolSink):
    scheme = "udp"

    def __init__(self, url: str, host: str, port: int, options: SinkOptions, resolve_s: float = RESOLVE_S) -> None:
        super().__init__(url, options)
        self._link = DatagramLink(url, host, port, resolve_s)

    @classmethod
    def from_url(cls, url: str, **kw: Any) -> "UdpSink":
        u: SinkUrl = parse_url(url)
        host, port = host_port(u)
        resolve_s = take_resolve_s(u, kw)
        options = SinkOptions.take(u, kw)
        u.reject_leftovers()
        reject_unknown_kw(url, kw)
        return cls(url, host, port, options, resolve_s)

    def _connect(self) -> None:
        self._link.open()

    def _disconnect(self) -> None:
        self._link.close()

    def _receiver_refusing(self, now: float) -> Optional[tuple[float, str]]:
        return self._link.refusing()

    def _write_messages(self, messages: list[Message]) -> bool:
        """One datagram per packet, so that a lost datagram loses one packet. Once the frame's JOINTS went out, a
        full send buffer cuts only what follows: its JOINTS_2D (:class:`SinkPartialWriteError`: the receiver has
        the frame's seq and 3D joints, no gap) or the HELLO + STATUS behind it (False: the STATUS is owed)."""
        n_frame = frame_packets(messages)
        # a JOINTS_2D cut is a frame sent in part (counted dropped before: the next JOINTS flagged DROPPED, no seq
        # missing)
        self._link.send_in_turn([encode(m) for m in messages[:n_frame]])
        for m in messages[n_frame:]:
            try:
                self._link.send(encode(m))
            except SinkWriteError:
                if not n_frame:
                    raise  # an idle (or first) HELLO + STATUS: not written
                return False  # the frame went out whole, only the HELLO + STATUS behind it did not
        return True

    def _write_bytes(self, data: bytes) -> None:
        self._link.send(data)
