"""``ghnerf-listen``: receive the joint stream where the robot would, and say what arrives.

The receiving end's check after installing the daemon (is the robot getting joints, how many, how
late, with what faults?), and a reference receiver in Python beside the C one in ``clients/c/``.

    ghnerf-listen udp://:9870                             # a summary line every second (IPv4 and IPv6)
    ghnerf-listen serial:///dev/ttyUSB0?baud=921600 --json  # every message as a JSON line
    ghnerf-listen udp://0.0.0.0:9870 --seconds 10           # IPv4 only; stop after 10 s (default: Ctrl-C)
    ghnerf-listen udp://239.255.0.1:9870                    # a multicast group (joined), as a sink sends to it

The summary: JOINTS messages per second, joints present per BODY_25 message (JOINTS of another joint set, which
version 1 does not define, counted apart: ``3 JOINTS of joint_set 7 (unknown: left out of joints present)``, as a
receiver that reads BODY_25 ignores them; they still count in the rate, latency, sequence and scene flags, which
their headers carry), the sender's latency
(``send_us - capture_us`` of the JOINTS headers: capture to the wire), sequence gaps (frames the
sender numbered but dropped or decimated, or the link lost; camera pairs the sender never made a
frame of take no number), late JOINTS (reordered: a seq up to :data:`LATE_WINDOW` behind the newest; one
that fills a gap takes it back out of the gaps) and duplicates, the newest STATUS by the sender's clock (one that
UDP delivers after a newer one is not shown; its fault code,
docs/protocol.md, and CALIBRATION SUSPECT when its flag says so) and HELLO, also the newest so written (with what
of its joint set, units and frame is not BODY_25 millimetres in the rig frame), the JOINTS flagged with each scene
flag (``3 several people``: two people seen, one person's joints sent; not a presence detector, docs/protocol.md;
``2 someone else``: the sender's scan for others, whose HELLO then reads ``(scans for someone else)``), and the
decoder's error counts (a noisy
serial line shows as ``crc``/``cobs`` errors). Each address sending to a udp:// port is a sender of its own,
counted apart; with several, each line and total starts with the sender's address (``10.0.0.7:40123: 30.0
JOINTS/s; ...``) and stderr says when another is heard; past :data:`MAX_PRODUCERS` the longest quiet is forgotten
(counted in the totals). A ``udp://`` sink that reopens its socket sends from a new port, a sender of its own whose
count starts afresh: the protocol names no producer to join the two by (docs/protocol.md, STATUS). ``--json`` lines
read from a udp:// port carry their sender's address first (``{"sender": "10.0.0.7:40123", "type": ...}``, one
sender or several); a serial link's are the canonical JSON alone. A seq further back is a restarted sender, not a
gap. Ctrl-C, SIGTERM or ``--seconds`` ends it with the totals on stderr (``, N of joint_set K (unknown)`` added
when any came).
Exit status: 0; 2 for a bad URL or a port that cannot be opened (named), or one that fails while read (an
unplugged serial port: the totals of what arrived until then are still printed).
"""
from __future__ import annotations

import argparse
import ipaddress
import json
import os
import select
import socket
import statistics
import struct
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Optional, TextIO
from urllib.parse import parse_qs, urlsplit

from drivers.url import UrlPartError, decode_url_part, dropped_characters, redact_location, shown_url
from firmware_host.addresses import ipv4_first
from firmware_host.errors import shown_value
from firmware_host.protocol.constants import (NO_FRAME_SEQ, PROTOCOL_VERSION, SCENE_FLAGS, CoordFrame, Fault, Flags,
                                              JointSet, Units)
from firmware_host.protocol.decoder import DecodeEvent, StreamDecoder
from firmware_host.protocol.messages import Hello, Joints, Message, Status
from firmware_host.sinks.url import host_name_problem, integer, ipv6_hint, location_host
from ghnerf_runtime.cli.seconds import positive_seconds
from ghnerf_runtime.cli.sigterm import sigterm_as_interrupt
from ghnerf_runtime.path_check import path_problem, shown as shown_path

__all__ = ["main", "open_port", "Tally", "Heard", "ListenError", "json_line", "SENDER_KEY"]

PROG = "ghnerf-listen"


class ListenError(Exception):
    """A URL or port the user fixes; printed as one line, exit status 2."""


class _UdpPort:
    """A UDP socket bound to ``host`` (its address family), or to every interface when ``host`` is empty:
    IPv6 and IPv4 on one socket where the machine has IPv6 (a sender whose name resolved to ::1 is
    heard too), IPv4 alone where it has not."""

    def __init__(self, host: str, port: int) -> None:
        self.sock = _bind_any(port) if not host else _bind(host, port)
        self.address = self.sock.getsockname()

    def read(self, timeout_s: float) -> bytes:
        return self.read_from(timeout_s)[0]

    def read_from(self, timeout_s: float) -> tuple[bytes, Optional[str]]:
        """A datagram and its sender's address (``192.0.2.7:40123``, ``[2001:db8::7]:40123``); ``b""`` and None
        when none came within ``timeout_s``."""
        ready, _, _ = select.select([self.sock], [], [], timeout_s)
        if not ready:
            return b"", None
        datagram, source = self.sock.recvfrom(65536)
        # A datagram is one whole frame (docs/protocol.md): one from a stray sender without the closing 0x00
        # is ended here, or the decoder glued it to the next datagram and lost that frame too.
        return (datagram if datagram.endswith(b"\x00") else datagram + b"\x00"), source_name(source)

    def close(self) -> None:
        self.sock.close()


#: The first 12 bytes of an IPv4-mapped IPv6 address (``::ffff:10.0.0.7``): an IPv4 sender on the dual-stack socket.
_V4_MAPPED = bytes(10) + b"\xff\xff"


def source_name(address: Any) -> str:
    """A datagram's sender as a user writes it: an IPv4 sender heard on the dual-stack socket (``::ffff:10.0.0.7``)
    as its IPv4 address, an IPv6 one in brackets. Read per datagram: inet_pton, not ipaddress (30 us a call)."""
    host, port = address[0], address[1]
    if ":" not in host:  # an IPv4 socket's sender
        return f"{host}:{port}"
    packed = socket.inet_pton(socket.AF_INET6, host.partition("%")[0])
    if packed[:12] == _V4_MAPPED:
        return f"{socket.inet_ntop(socket.AF_INET, packed[12:])}:{port}"
    return f"[{host}]:{port}"


def _cannot_listen(host: str, port: int, e: Exception) -> ListenError:
    where = f"[{host}]" if ":" in host else host
    return ListenError(f"udp://{where}:{port}: cannot listen: {getattr(e, 'strerror', None) or e}")


def _bind(host: str, port: int) -> socket.socket:
    """``host``'s IPv4 address if it has one (as the udp:// sink picks), else its first."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM, flags=socket.AI_PASSIVE)
        family, addr = ipv4_first(infos)
        sock = socket.socket(family, socket.SOCK_DGRAM)
    except (OSError, ValueError) as e:  # ValueError: an empty answer
        raise _cannot_listen(host, port, e) from e
    try:
        sock.bind(addr)
        _join_if_multicast(sock, family, addr)
    except OSError as e:
        sock.close()
        raise _cannot_listen(host, port, e) from e
    return sock


def _join_if_multicast(sock: socket.socket, family: int, addr: Any) -> None:
    """Join the group of a multicast ``addr`` (udp://239.1.2.3:9870, udp://[ff02::1%25eth0]:9870): a socket
    only bound to a group address hears nothing, though a udp:// sink sends to it fine. The kernel picks the
    interface (IPv4), or the zone does (IPv6; none: the default)."""
    ip = ipaddress.ip_address(addr[0].partition("%")[0])
    if not ip.is_multicast:
        return
    if family == socket.AF_INET:
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, ip.packed + socket.inet_aton("0.0.0.0"))
    else:
        sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_JOIN_GROUP, ip.packed + struct.pack("@I", addr[3]))


def _bind_any(port: int) -> socket.socket:
    """Every interface: dual-stack ``::`` (IPV6_V6ONLY off), or ``0.0.0.0`` where IPv6 is unavailable."""
    try:
        sock = socket.socket(socket.AF_INET6, socket.SOCK_DGRAM)
    except OSError:  # no IPv6 in this kernel (EAFNOSUPPORT)
        return _bind("0.0.0.0", port)
    try:
        sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 0)
        sock.bind(("::", port))
    except OSError:  # IPv6 disabled on the interfaces (EADDRNOTAVAIL), or no dual stack: IPv4 still works
        sock.close()
        return _bind("0.0.0.0", port)
    return sock


class _SerialPort:
    def __init__(self, device: str, baud: int) -> None:
        import serial

        try:
            self.port = serial.Serial(device, baud, timeout=0)
        except (serial.SerialException, OSError, ValueError) as e:
            # the device decoded from the URL (a %1B: an ESC), and pyserial's words quoting it: escaped
            raise ListenError(f"serial://{shown_path(device)}: cannot open: {shown_path(str(e))}") from e

    def read(self, timeout_s: float) -> bytes:
        import serial

        ready, _, _ = select.select([self.port.fileno()], [], [], timeout_s)
        if not ready:
            return b""
        try:
            return bytes(self.port.read(65536))
        except (serial.SerialException, OSError) as e:  # unplugged: say so rather than spin
            raise ListenError(f"serial://{self.port.port}: read failed: {e}") from e

    def close(self) -> None:
        self.port.close()


#: The query keys each scheme takes; any other is refused (``baudrate=921600`` once opened at 115200).
_ACCEPTED: dict[str, tuple[str, ...]] = {"udp": (), "serial": ("baud",)}


def _reject_unknown_keys(shown: str, query: dict[str, list[str]], accepted: Sequence[str]) -> None:
    unknown = sorted(k for k in query if k not in accepted)
    if unknown:
        takes = f"it takes {', '.join(accepted)}" if accepted else "it takes none"
        raise ListenError(f"{shown}: unknown parameter {', '.join(unknown)}; {takes}")


def _refuse_repeats(shown: str, query: dict[str, list[str]]) -> None:
    """``baud=9600&baud=921600`` is refused, as the sinks refuse it, rather than one of them quietly winning."""
    repeated = sorted(k for k, values in query.items() if len(values) > 1)
    if repeated:
        raise ListenError(f"{shown}: {', '.join(repeated)} given more than once")


def _serial_device(shown: str, device: str) -> str:
    """The ``serial://`` device path, percent-decoded as the serial sink's is (a '#' in a udev by-id name can only
    be written %23). An escape of a byte that is not UTF-8 is refused, as the sinks refuse it: decoded to U+FFFD,
    the listener tried to open a device never named. A device no file can be (a NUL byte, a name too long) is
    refused in :func:`ghnerf_runtime.path_check.path_problem`'s words: pyserial's ValueError read "cannot open"."""
    try:
        decoded = decode_url_part("the device", device)
    except UrlPartError as e:
        raise ListenError(f"{shown}: {e.field} {e.value} {e.why}") from None
    problem = path_problem(decoded)
    if problem is not None:
        raise ListenError(f"{shown}: the device {shown_path(decoded)}: {problem}")
    return decoded


def open_port(url: str, *, ephemeral: bool = False) -> "_UdpPort | _SerialPort":
    """``udp://[HOST]:PORT`` (bound; HOST defaults to all interfaces, IPv4 and IPv6) or ``serial:///dev/DEVICE?baud=N``.

    ``ephemeral``: accept port 0, a port the system picks (read it from ``.address``); the command line
    refuses it, since nothing would tell the sender which port to use. Its errors show the URL without any password
    (``drivers.url.redact_url``), as the sinks' do: a terminal's scrollback and a shell's log keep them; and on one
    line (``drivers.url.shown_url``: escaped where it holds a control character).
    """
    if not url:  # a "$UNSET" in a script: was ": the listener reads udp:// or serial://", the URL shown as nothing
        raise ListenError("the URL is empty: give udp://[HOST]:PORT or serial:///dev/DEVICE?baud=N")
    shown = shown_url(url)
    dropped = dropped_characters(url)
    if dropped is not None:  # urlsplit removed it: udp://:98<LF>70 listened on 9870 (the sinks' rule); first, as an
        raise ListenError(f"{shown}: {dropped}")  # ESC sequence's '[' read as a broken IPv6 host
    try:
        parts = urlsplit(url)
    except ValueError as e:  # e.g. "Invalid IPv6 URL": an unclosed [
        raise ListenError(f"{shown}: cannot be parsed: {e}") from None
    if "#" in url:
        # urlsplit drops a fragment, and with it what followed: serial:///dev/by-id/x#1?baud=9600 opened
        # /dev/by-id/x at 115200. The sinks refuse it too (firmware_host.sinks.url.parse_url)
        raise ListenError(f"{shown}: a '#' ends the URL (the rest, {parts.fragment!r}, would be ignored); write a "
                          "'#' in a device path as %23")
    scheme = parts.scheme.lower()  # UDP:// is udp:// (as for the sinks)
    # '+' is a plus, as the sinks read it (a form's '+' for a space made baud=%2B9600 read ' 9600'); a space is %20
    query = parse_qs(parts.query.replace("+", "%2B"), keep_blank_values=True)
    if scheme in _ACCEPTED:  # another scheme is refused as such below
        _reject_unknown_keys(shown, query, _ACCEPTED[scheme])
        _refuse_repeats(shown, query)
    if scheme == "udp":
        try:
            port = parts.port
        except ValueError as e:
            raise ListenError(f"{shown}: bad port: {e}{ipv6_hint(parts, 'udp', 9870)}") from None
        if port is None:
            raise ListenError(f"{shown}: give the port to listen on, e.g. udp://:9870{ipv6_hint(parts, 'udp', 9870)}")
        if port == 0 and not ephemeral:
            raise ListenError(f"{shown}: bad port 0: the system would pick one that no sender knows; "
                              f"give 1..65535, e.g. udp://:9870")
        try:
            host = location_host(parts, "udp")  # "": every interface
        except UrlPartError as e:
            raise ListenError(f"{shown}: {e.why} ({shown_value(e.field, e.value)!r})") from None
        problem = host_name_problem(host) if host else ""
        if problem:  # the sinks' rule, in their words (the resolver's own error was an IDNA codec's)
            raise ListenError(f"{shown}: bad host {host!r}: {problem}")
        return _UdpPort(host, port)
    if scheme == "serial":
        device = parts.netloc + parts.path
        if not device:
            raise ListenError(f"{shown}: give the device, e.g. serial:///dev/ttyUSB0?baud=921600")
        if parts.netloc or not parts.path.startswith("/"):
            # serial://dev/ttyUSB0 is the relative path dev/ttyUSB0 (its "dev" a URL's host): three slashes
            meant = (redact_location(parts.netloc) + parts.path).lstrip("/")  # a user:password@ shown as in `shown`
            raise ListenError(f"{shown}: the device is an absolute path, e.g. serial:///{meant}")
        try:  # the sinks' rule for whole numbers: a baud copied from a sink URL (0x1C200) means what it meant there
            baud = integer(query.get("baud", ["115200"])[0])
        except ValueError as e:
            raise ListenError(f"{shown}: baud must be a whole number: {e}") from None
        from firmware_host.sinks.serial_sink import MAX_BAUD, MIN_BAUD  # the sink's bounds: one rule for both ends

        if not MIN_BAUD <= baud <= MAX_BAUD:
            # past 2**31 - 1 pyserial's OverflowError escaped as a traceback; 0 asks termios to hang up the line
            raise ListenError(f"{shown}: baud must be in [{MIN_BAUD}, {MAX_BAUD}] (what termios can be asked for), "
                              f"got {baud}")
        return _SerialPort(_serial_device(shown, device), baud)
    raise ListenError(f"{shown}: the listener reads udp:// or serial:// (file:// sinks write JSON lines already)")


#: A JOINTS seq at most this many frames behind the newest is a reordered (late) datagram, one further back a
#: sender that restarted (at 0). A gap's frames are counted lost at once; one that arrives within the window
#: after all is taken back out of the loss and counted late instead.
LATE_WINDOW = 32
_SEQ_MOD = 1 << 32  # sequence numbers wrap (docs/protocol.md)
#: A HELLO of seq NO_FRAME_SEQ written at most this long before the newest JOINTS (and after the HELLO that began
#: their numbering, where one did) is that sender's own, duplicated or reordered on the link, not a new process:
#: about LATE_WINDOW frames at 30 fps. Kept short, so that a device that rebooted (its monotonic clock restarted) is
#: hardly ever mistaken for it.
STALE_HELLO_US = 1_000_000
#: A STATUS written at most this long before the one shown is an older datagram of the same sender (reordered or
#: duplicated on UDP) and is not shown; one written longer before comes from a device whose clock started again (a
#: reboot) and is. The same 1 s as :data:`STALE_HELLO_US`.
STALE_STATUS_US = STALE_HELLO_US


#: The scene flags (docs/protocol.md section 3) as the summary counts them: JOINTS of that kind per interval.
SCENE_WORDS = ((Flags.SEVERAL_PEOPLE, "several people"), (Flags.PRIOR_FALLBACK, "prior fallback"),
               (Flags.SINGLE_VIEW, "single view"), (Flags.CALIBRATION_SUSPECT, "calibration suspect"),
               (Flags.SOMEONE_ELSE, "someone else"))


def _scan_note(hello: Hello) -> str:
    """Whether the HELLO's sender scans for someone besides its subject (SOMEONE_ELSE announced): only then does a
    frame without the flag say "nobody else seen" rather than "nobody looked"."""
    return " (scans for someone else)" if hello.header.flags & Flags.SOMEONE_ELSE else ""


def _unexpected_layout(hello: Hello) -> str:
    """What of the HELLO's joint set, units and frame is not BODY_25 millimetres in the rig frame, the only values
    version 1 defines (docs/protocol.md, HELLO): the decoders pass another value through, so a receiver checks them
    itself. "" when all three are as expected."""
    odd = [f"{name} {value}" for name, value, known in (("joint_set", hello.joint_set, JointSet.BODY_25),
                                                       ("units", hello.units, Units.MILLIMETRES),
                                                       ("frame", hello.frame, CoordFrame.RIG)) if value != known]
    if not odd:
        return ""
    return f" (not BODY_25 in mm in the rig frame: {', '.join(odd)})"


#: A ``version`` error passed its CRC: a sender of another protocol version, not line noise (docs/protocol.md,
#: section 4).
_VERSION_HINT = (f" (version: whole frames of a protocol version other than {PROTOCOL_VERSION}, which this listener "
                 "does not read: a newer sender needs a newer ghnerf-listen)")


#: How a summary line and the totals name the JOINTS of a joint set other than BODY_25.
UNKNOWN_SET_LINE = "{n} JOINTS of joint_set {joint_set} (unknown: left out of joints present)"
UNKNOWN_SET_TOTAL = "{n} of joint_set {joint_set} (unknown)"


def _unknown_set_words(counts: dict[int, int], form: str) -> list[str]:
    """The JOINTS of each joint set other than BODY_25 (``counts``), in ``form`` (``{n}`` and ``{joint_set}``)."""
    return [form.format(n=n, joint_set=joint_set) for joint_set, n in sorted(counts.items())]


def _newer(send_us: int, shown_us: Optional[int]) -> bool:
    """Whether a STATUS or HELLO written at ``send_us`` replaces the one of its type shown (written at ``shown_us``;
    None: none, or a new numbering began since): written later on the sender's clock (which, unlike seq, orders the
    STATUS and HELLO of a sender that sends no frame, and does not wrap: u64 µs), or over :data:`STALE_STATUS_US`
    before it (a rebooted device). Shown as it arrived, one reordered behind a newer one on UDP read as the sender's
    state until the next (until session 74 for STATUS, 75 for HELLO: a reload's new rig id was undone by the old)."""
    return shown_us is None or send_us > shown_us or shown_us - send_us > STALE_STATUS_US


def _fault_name(code: int) -> str:
    try:
        return Fault(code).name
    except ValueError:  # a newer sender's code
        return str(code)


@dataclass
class Tally:
    """What arrived since the last summary (and in total).

    ``gaps`` / ``total_gaps``: JOINTS frames lost, the seqs skipped less those that came late after all;
    ``late`` / ``total_late``: JOINTS that arrived after a later seq (reordered on the link); ``duplicates`` /
    ``total_duplicates``: a seq that had arrived already. A summary's ``gaps`` are the frames skipped in its own
    interval that had not arrived by its end: one that arrives in a later interval is late there, and leaves
    the totals' loss.
    """

    joints: int = 0
    present: list[int] = field(default_factory=list)
    latency_ms: list[float] = field(default_factory=list)
    gaps: int = 0
    late: int = 0
    duplicates: int = 0
    scene: dict[str, int] = field(default_factory=dict)  # JOINTS per scene flag (SCENE_WORDS), this interval
    # JOINTS per joint set other than BODY_25 (version 1 defines none), this interval and in total: kept out of
    # ``present``, whose count a receiver reads as BODY_25 joints
    unknown_sets: dict[int, int] = field(default_factory=dict)
    total_unknown_sets: dict[int, int] = field(default_factory=dict)
    last_seq: Optional[int] = None
    status: Optional[Status] = None
    hello: Optional[Hello] = None
    total_joints: int = 0
    total_gaps: int = 0
    total_late: int = 0
    total_duplicates: int = 0
    status_at: float = 0.0
    hello_at: float = 0.0
    errors_before: dict[str, int] = field(default_factory=dict)
    # The LATE_WINDOW seqs up to the newest: those that arrived, and those skipped (each with the summary interval
    # it was counted lost in). Only seqs of the current numbering: a restart forgets them.
    _arrived: set[int] = field(default_factory=set, repr=False)
    _missing: dict[int, int] = field(default_factory=dict, repr=False)
    _interval: int = field(default=0, repr=False)
    # send_us of the earliest HELLO of seq NO_FRAME_SEQ that began the current numbering (None: begun by a JOINTS),
    # and of the newest JOINTS in it: a HELLO written between the two (or, begun by a JOINTS, shortly before the
    # newest) is this numbering's own, come late.
    _begun_us: Optional[int] = field(default=None, repr=False)
    _newest_us: Optional[int] = field(default=None, repr=False)
    # send_us of the STATUS and of the HELLO shown (None: none yet, or a new numbering began since, whose sender's
    # clock may be another): one written before it is an older one that UDP delivered late.
    _status_us: Optional[int] = field(default=None, repr=False)
    _hello_us: Optional[int] = field(default=None, repr=False)

    def add(self, message: Message) -> None:
        if isinstance(message, Joints):
            self.joints += 1
            self.total_joints += 1
            self._count_joints(message)
            h = message.header
            self.latency_ms.append((h.send_us - h.capture_us) / 1000.0)
            for flag, word in SCENE_WORDS:
                if h.flags & flag:
                    self.scene[word] = self.scene.get(word, 0) + 1
            self._sequence(h.seq, h.send_us)
        elif isinstance(message, Status):
            if _newer(message.header.send_us, self._status_us):
                self.status, self.status_at = message, time.monotonic()
                self._status_us = message.header.send_us
        elif isinstance(message, Hello):
            if message.header.seq == NO_FRAME_SEQ and not self._written_in_this_numbering(message.header.send_us):
                # a sender that has numbered no frame yet: a new process, whose JOINTS start again at 0, counted
                # from the seq its HELLO carries (frames lost before its first JOINTS arrives are gaps). Without
                # this, one that restarted within LATE_WINDOW of its old seq had its first frames read as late.
                self._begin_at_hello(message.header.send_us)
            if _newer(message.header.send_us, self._hello_us):  # after the numbering: a new sender's is shown
                self.hello, self.hello_at = message, time.monotonic()
                self._hello_us = message.header.send_us

    def _count_joints(self, message: Joints) -> None:
        """The joints present of a BODY_25 JOINTS; one of another joint set is only counted, by its set: a receiver
        that reads BODY_25 ignores it (docs/protocol.md, HELLO), so its joints are none of the ones it expects."""
        if message.joint_set == JointSet.BODY_25:
            self.present.append(int((~message.missing).sum()))
            return
        for counts in (self.unknown_sets, self.total_unknown_sets):
            counts[message.joint_set] = counts.get(message.joint_set, 0) + 1

    def _written_in_this_numbering(self, send_us: int) -> bool:
        """Whether a HELLO of seq NO_FRAME_SEQ was written after the one that began this numbering and shortly
        before its newest JOINTS (:data:`STALE_HELLO_US`): a duplicated or reordered datagram of this sender, not a
        new process (whose HELLO is written after its predecessor's frames, on the same monotonic clock). Taken for
        a new numbering, it counted the frames that had arrived since as lost. A numbering begun by a JOINTS has no
        HELLO of its own: one written before its newest JOINTS (strictly before: a new process writes after) is its
        sender's, come after its first frames (until session 72 those were counted lost)."""
        if self._newest_us is None:
            return False
        if self._begun_us is None:
            return send_us < self._newest_us and self._newest_us - send_us <= STALE_HELLO_US
        return self._begun_us <= send_us <= self._newest_us and self._newest_us - send_us <= STALE_HELLO_US

    def _begin_at_hello(self, send_us: int) -> None:
        if self._newest_us is None and self._begun_us is not None:  # another HELLO before any JOINTS: same start
            send_us = min(send_us, self._begun_us)
        else:  # a new sender: its clock may be another (rebooted), its next STATUS and HELLO are shown whatever
            self._status_us = self._hello_us = None
        self.last_seq, self._arrived, self._missing = NO_FRAME_SEQ, set(), {}
        self._begun_us, self._newest_us = send_us, None

    def _sequence(self, seq: int, send_us: int) -> None:
        """Count ``seq`` as the next frame, a gap's end, a late or repeated one, or a restarted sender's first."""
        if self.last_seq is None:
            self._restart(seq, send_us)
            return
        step = (seq - self.last_seq) % _SEQ_MOD
        if 0 < step < _SEQ_MOD // 2:  # forward: the frames stepped over are lost until they come late
            skipped = step - 1
            self.gaps += skipped
            self.total_gaps += skipped
            for k in range(max(1, step - LATE_WINDOW), step):  # only those that can still count as late
                self._missing[(self.last_seq + k) % _SEQ_MOD] = self._interval
            self.last_seq, self._newest_us = seq, send_us
            self._arrived.add(seq)
            self._forget_behind_window()
        elif step == 0 or _SEQ_MOD - step <= LATE_WINDOW:
            # Behind the newest, within the window: the newest stays the reference, or the step from this one up
            # to the next would count the frames that already arrived as a second gap.
            if seq in self._arrived:
                self.duplicates += 1
                self.total_duplicates += 1
                return
            self.late += 1
            self.total_late += 1
            self._arrived.add(seq)
            counted_in = self._missing.pop(seq, None)
            if counted_in is not None:  # else it was sent before the first seq heard: never counted lost
                self.total_gaps -= 1
                if counted_in == self._interval:
                    self.gaps -= 1
        else:  # a restarted sender: as after its HELLO, its next STATUS and HELLO are shown whatever their time
            self._restart(seq, send_us)
            self._status_us = self._hello_us = None

    def _restart(self, seq: int, send_us: int) -> None:
        """A new numbering (the first JOINTS heard, or a restarted sender): the old one's window is forgotten."""
        self._arrived, self._missing = {seq}, {}
        self.last_seq = seq
        self._begun_us, self._newest_us = None, send_us

    def _forget_behind_window(self) -> None:
        newest = self.last_seq
        assert newest is not None
        self._arrived = {s for s in self._arrived if (newest - s) % _SEQ_MOD <= LATE_WINDOW}
        self._missing = {s: i for s, i in self._missing.items() if (newest - s) % _SEQ_MOD <= LATE_WINDOW}

    def line(self, seconds: float, errors: dict[str, int]) -> str:
        parts = [f"{self.joints / max(seconds, 1e-9):.1f} JOINTS/s"]
        if self.present:
            parts.append(f"{statistics.mean(self.present):.1f} joints present")
        parts.extend(_unknown_set_words(self.unknown_sets, UNKNOWN_SET_LINE))
        if self.latency_ms:
            parts.append(f"latency {statistics.median(self.latency_ms):.1f} ms")
        parts.append(f"{self.gaps} seq gaps")
        if self.late:
            parts.append(f"{self.late} late (reordered)")
        if self.duplicates:
            parts.append(f"{self.duplicates} duplicate")
        parts.extend(f"{self.scene[word]} {word}" for _, word in SCENE_WORDS if word in self.scene)
        now = time.monotonic()
        if self.status is not None:
            age = f" ({now - self.status_at:.0f} s ago)" if now - self.status_at > 2 * seconds + 1 else ""
            suspect = ", CALIBRATION SUSPECT" if self.status.header.flags & Flags.CALIBRATION_SUSPECT else ""
            parts.append(f"sender fault {_fault_name(self.status.fault)}{suspect}, dropped {self.status.dropped}{age}")
        if self.hello is not None:
            age = f" ({now - self.hello_at:.0f} s ago)" if now - self.hello_at > 2 * seconds + 1 else ""
            # an older sender never sets the scene flags: their absence then says nothing of the scene
            older = "" if self.hello.header.flags & SCENE_FLAGS == SCENE_FLAGS else " (sends no scene flags)"
            layout = _unexpected_layout(self.hello)
            parts.append(f"rig {self.hello.rig_id!r} cameras {list(self.hello.cameras)}{older}"
                         f"{_scan_note(self.hello)}{layout}{age}")
        bad = {k: v - self.errors_before.get(k, 0) for k, v in errors.items() if v - self.errors_before.get(k, 0)}
        self.errors_before = dict(errors)
        if bad:
            parts.append(f"decode errors {bad}{_VERSION_HINT if 'version' in bad else ''}")
        self.joints, self.present, self.latency_ms, self.gaps, self.late, self.duplicates = 0, [], [], 0, 0, 0
        self.scene, self.unknown_sets = {}, {}
        self._interval += 1  # a frame skipped before now that comes late no longer changes this line's gaps
        return "; ".join(parts)


#: A sender not heard for this long while another is gets no line of its own any more: a udp:// sink that reopened
#: its socket (a reconnect, a reload) sends from another port, and its old address falls quiet for good.
QUIET_S = 10.0
#: The most senders kept apart on one port: past it the longest quiet is forgotten (counted in the totals). A sink
#: that reconnects often (a new source port each time) or stray datagrams from random ports grew the table, its
#: lines and totals without limit in a long session.
MAX_PRODUCERS = 64


@dataclass
class Producer:
    """One sender heard on the port: its own decoder (a datagram is a whole frame, so its decode errors are its
    own) and tally, and when it was last heard (``time.monotonic()``; 0.0: not yet)."""

    decoder: StreamDecoder = field(default_factory=StreamDecoder)
    tally: Tally = field(default_factory=Tally)
    heard_at: float = 0.0


def _waiting() -> dict[Optional[str], Producer]:
    return {None: Producer()}


@dataclass
class Heard:
    """The senders heard on one port by address, first heard first: each its own seq tally, STATUS and HELLO, which
    one tally mixed (one sender's frames read as the other's gaps and restarts; a STATUS hidden by another's newer
    clock). Key None: a serial link's one sender, or the first before its first datagram came (which takes it)."""

    producers: dict[Optional[str], Producer] = field(default_factory=_waiting)
    forgotten: int = 0  # senders forgotten past MAX_PRODUCERS, and the JOINTS they had sent
    forgotten_joints: int = 0
    noted_at: float = -QUIET_S  # when a new sender was last said on ``notes``, and how many came unsaid since
    unnoted: int = 0

    @property
    def first(self) -> Tally:
        return next(iter(self.producers.values())).tally

    def producer(self, source: Optional[str], now: float, notes: TextIO) -> Producer:
        """The sender at ``source`` (a new one when first heard, said on ``notes`` while another is heard too)."""
        if source not in self.producers:
            if list(self.producers) == [None]:
                self.producers = {source: self.producers[None]}
            else:
                self._note_another(source, now, notes)
                self._make_room()
                self.producers[source] = Producer()
        producer = self.producers[source]
        producer.heard_at = now
        return producer

    def _note_another(self, source: Optional[str], now: float, notes: TextIO) -> None:
        current = [f"{name} (heard {now - p.heard_at:.1f} s ago)" for name, p in self.producers.items()
                   if now - p.heard_at <= QUIET_S]
        if not current:  # the one before fell quiet long ago: a sender restarted elsewhere, its line replaced
            return
        if now - self.noted_at < QUIET_S:  # at most one note per QUIET_S: stray datagrams from random ports
            self.unnoted += 1
            return
        since = f" ({self.unnoted} more new senders since the last such note)" if self.unnoted else ""
        notes.write(f"{PROG}: another sender on this port: {source}, besides {', '.join(current)}{since}: two "
                    "senders (a receiver here mixes their frames) or one that reopened its socket; the summary "
                    "lines and totals name each sender\n")
        notes.flush()
        self.noted_at, self.unnoted = now, 0

    def _make_room(self) -> None:
        """Forget the longest quiet senders until a new one fits within :data:`MAX_PRODUCERS`."""
        while len(self.producers) >= max(MAX_PRODUCERS, 1):
            name = min(self.producers, key=lambda k: self.producers[k].heard_at)
            self.forgotten += 1
            self.forgotten_joints += self.producers.pop(name).tally.total_joints

    def _current(self, now: float) -> list[tuple[Optional[str], Producer]]:
        """The senders heard within :data:`QUIET_S`, and the last heard whenever (a lone sender gone quiet keeps
        its line, as before there were several)."""
        last = max(p.heard_at for p in self.producers.values())
        return [(name, p) for name, p in self.producers.items() if p.heard_at >= min(last, now - QUIET_S)]

    def lines(self, seconds: float, now: float) -> list[str]:
        """Each current sender's summary line, named when there are several; every tally starts a new interval."""
        current = {name for name, _ in self._current(now)}
        lines = [(name, p.tally.line(seconds, p.decoder.stats.errors)) for name, p in self.producers.items()]
        if len(current) == 1:
            return [line for name, line in lines if name in current]
        return [f"{name}: {line}" for name, line in lines if name in current]

    def totals(self) -> list[str]:
        """The totals line, one per sender (named) when several were heard."""
        if len(self.producers) == 1 and not self.forgotten:
            return [_totals(self.first)]
        lines = [f"{name}: {_totals(p.tally)}" for name, p in self.producers.items()]
        if self.forgotten:
            lines.append(f"{self.forgotten} more senders forgotten (the longest quiet, past {MAX_PRODUCERS} kept): "
                         f"{self.forgotten_joints} JOINTS messages from them")
        return lines


def _totals(tally: Tally) -> str:
    unknown = "".join(f", {words}" for words in _unknown_set_words(tally.total_unknown_sets, UNKNOWN_SET_TOTAL))
    return (f"{tally.total_joints} JOINTS messages, {tally.total_gaps} sequence gaps (lost), {tally.total_late} late "
            f"(reordered), {tally.total_duplicates} duplicate{unknown}")


#: The key ``--json`` adds to each line read from a udp:// port: its sender's address, as the summary lines name it.
#: On every such line, one sender or several, so that a reader can keep one sender's lines apart from the first
#: line on; a serial link has one sender, and its lines are the canonical JSON alone.
SENDER_KEY = "sender"


def json_line(event: DecodeEvent, sender: Optional[str]) -> str:
    """``event``'s canonical JSON (docs/protocol.md, section 9), its ``sender`` (None: a serial link) added first."""
    record = event.to_json()
    return json.dumps(record if sender is None else {SENDER_KEY: sender, **record})


def _reader(port: Any) -> Callable[[float], tuple[bytes, Optional[str]]]:
    """``port``'s read of what came and from whom: a UDP port names each datagram's sender, a serial one has one
    sender (looked up once, not per read)."""
    read_from = getattr(port, "read_from", None)
    return read_from if read_from is not None else lambda timeout_s: (port.read(timeout_s), None)


def listen(port: Any, *, seconds: Optional[float], as_json: bool, out: TextIO, every_s: float = 1.0,
           heard: Optional[Heard] = None, notes: Optional[TextIO] = None) -> Tally:
    """Read until ``seconds`` pass (None: until interrupted), writing summaries or JSON lines to ``out`` and a
    second sender's arrival to ``notes`` (stderr when None); counts into ``heard`` (a new one when None), which keeps
    what arrived if the port fails (:class:`ListenError`). Returns the first sender's tally."""
    heard = Heard() if heard is None else heard
    notes = sys.stderr if notes is None else notes
    read = _reader(port)
    start = last = time.monotonic()
    try:
        while seconds is None or time.monotonic() - start < seconds:
            data, source = read(0.1)
            now = time.monotonic()
            producer = heard.producer(source, now, notes) if data else None
            for event in producer.decoder.feed(data) if producer is not None else ():
                if event.message is not None:
                    producer.tally.add(event.message)
                if as_json:
                    out.write(json_line(event, source) + "\n")
                    out.flush()  # a reader at the end of a pipe sees each message as it comes
            now = time.monotonic()
            if not as_json and now - last >= every_s:
                for line in heard.lines(now - last, now):
                    out.write(line + "\n")
                    out.flush()  # each line alone: shorter than PIPE_BUF, a pipe takes it whole (docs/daemon.md)
                last = now
    except KeyboardInterrupt:  # Ctrl-C is how a listening session usually ends: keep the totals
        pass
    return heard.first


def main(argv: Sequence[str] | None = None) -> int:
    # the counters the docs describe (docs/daemon.md), in the words each line prints them in
    epilog = ("Each second a line: JOINTS/s, joints present, latency (capture to the wire), 'N seq gaps' (frames "
              f"lost), and when any came 'N late (reordered)' (a seq up to {LATE_WINDOW} behind the newest: one a "
              "gap stepped over leaves the lost frames) and 'N duplicate'; JOINTS flagged "
              f"{', '.join(repr(f'N {word}') for _, word in SCENE_WORDS)} (docs/protocol.md, section 3); "
              "'N JOINTS of joint_set K (unknown: left out of joints present)' for JOINTS of a joint set other than "
              "BODY_25 (the totals add 'N of joint_set K (unknown)'); "
              "the fault of the sender's newest STATUS by its send_us (', CALIBRATION SUSPECT' when flagged) "
              "and of its newest HELLO ('(sends no scene "
              "flags)' from a sender too old to set them; '(scans for someone else)' from one whose estimator scans "
              "for others, the only sender whose frames without 'someone else' say nobody else was seen; '(not "
              "BODY_25 in mm in the rig frame: ...)' when it announces other joints, units or frame); decode errors "
              "('version': a sender of a newer protocol). Several senders on a udp:// port: each counted apart, a "
              "line and a total each that start with its address, and a note on stderr when another is heard. "
              "Ctrl-C, SIGTERM or --seconds ends it with the totals. "
              "Counters: docs/daemon.md; protocol: docs/protocol.md")
    ap = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0], epilog=epilog)
    ap.add_argument("url", help="udp://[HOST]:PORT (no HOST: every interface, IPv4 and IPv6; a multicast HOST, "
                                "udp://239.255.0.1:PORT, is joined) or serial:///dev/DEVICE?baud=N (three "
                                "slashes: an absolute path)")
    ap.add_argument("--json", action="store_true",
                    help="every message (and decode error) as a JSON line, the wire's integers: a JOINTS row is "
                         "[x, y, z in mm (rig frame: x right, y down, z away from the cameras), confidence 0-255, "
                         "missing 0/1] (docs/protocol.md, sections 4 and 9); from a udp:// port each line starts "
                         f"with its sender's address, \"{SENDER_KEY}\": \"HOST:PORT\"")
    ap.add_argument("--seconds", type=positive_seconds, default=None,
                    help="stop after this long (default: Ctrl-C)")
    args = ap.parse_args(argv)
    try:
        port = open_port(args.url)  # port 0 refused: nobody would learn which port was bound
    except ListenError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    heard, status = Heard(), 0
    # SIGTERM (`timeout`, systemd, a supervisor on the robot) ends it as Ctrl-C does, with the totals (listen()
    # reads either as the end of the session): its default action killed the process with nothing said
    try:
        with sigterm_as_interrupt():
            listen(port, seconds=args.seconds, as_json=args.json, out=sys.stdout, heard=heard)
    except BrokenPipeError:  # `ghnerf-listen ... | head`: the reader has what it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except ListenError as e:  # e.g. the serial port unplugged: what arrived until then is still said below
        print(f"{PROG}: error: {e}", file=sys.stderr)
        status = 2
    finally:
        port.close()
    for line in heard.totals():
        print(line, file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
