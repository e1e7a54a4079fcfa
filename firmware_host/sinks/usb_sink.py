"""usb://VID:PID?ep=0x01 - the protocol over a USB bulk OUT endpoint (pyusb).

VID and PID are hexadecimal, 1 to 4 digits each (``0x`` allowed). Query: ``ep`` (bulk OUT endpoint
address, required), ``interface`` (default 0, at most 255), ``timeout_ms`` (default 100, at most 60000),
plus the common options. The libusb backend comes from ``libusb_package`` unless a pyusb backend is
passed as ``backend=``.

Which device: ``serial=ABC123`` takes the one whose serial number string is that, ``port=1-1.4`` the one
at that physical port path (bus 1, ports 1 then 4; see usb_select); the two are exclusive. A selector
that matches nothing is a failed connect like an absent device (retried with backoff), its message
naming what was looked for and the serials or ports of the VID:PID devices that were there, including a
serial that could not be read (permission: the udev rule). Without a selector, with several devices of
that VID:PID plugged in, the first libusb lists is used and a warning names them all (the order can
change on a replug) and says how to choose.

Error handling: a stalled endpoint (EPIPE) has its halt cleared and the frame written once more (a
second stall drops it); a timeout or a short write drops the frame, and the next write starts with a
0x00 so the receiver discards the cut fragment; a vanished device (ENODEV and anything else) is
released and searched for again with backoff. One frame holds the worker at most ``2 * timeout_ms``
(the write and its retry); ``send()`` never waits for it.

Two sinks of one daemon on one board: the daemon passes every usb:// sink one ``claims=``
(:class:`~firmware_host.sinks.usb_claims.UsbClaims`); a sink takes its interface there before claiming it, and
one that finds it held by another sink (a board named by ``serial=`` in one URL and by ``port=`` in the other,
plugged in after the config was read) fails to connect with :class:`~firmware_host.sinks.usb_claims.UsbBoardTaken`,
naming both sinks, both names and the board, and waits: the other may let go.

A kernel driver bound to the interface (cdc_acm on a CDC board) is detached to
claim it and attached again when the sink lets the device go, so its
/dev/ttyACM* comes back once the daemon stops.
"""
from __future__ import annotations

import errno
import logging
import re
from typing import Any, NamedTuple, Optional

import usb.core
import usb.util

from firmware_host.errors import SinkConfigError, SinkUnavailableError, SinkWriteError
from firmware_host.sinks.options import SinkOptions, reject_unknown_kw
from firmware_host.sinks.protocol_sink import ProtocolSink
from firmware_host.sinks.url import SinkUrl, int_in, integer, parse_url
from firmware_host.sinks.usb_claims import Claimant, InterfaceOfBoard, UsbBoardTaken, UsbClaims
from firmware_host.sinks.usb_select import (BoardName, NoMatch, PortPath, board_place, describe, parse_port,
                                             parse_serial, port_of, select)

_log = logging.getLogger(__name__)

#: Longest bulk write: a joint frame a minute late is of no use, and libusb takes the timeout as an unsigned
#: 32-bit int in which 0 means never (ctypes wraps 2**32 ms to 0: a stalled receiver held the worker for ever).
MAX_TIMEOUT_MS = 60_000


#: One USB ID: 1 to 4 hex digits, ``0x`` allowed. int(s, 16) alone also took "1_2", "-1" and non-ASCII digits.
_HEX_ID = re.compile(r"(?:0[xX])?[0-9a-fA-F]{1,4}")

#: Interface numbers are a descriptor byte (bInterfaceNumber).
MAX_INTERFACE = 255


def _vid_pid(url: str, netloc: str) -> tuple[int, int]:
    """VID and PID of ``usb://VID:PID``; an error names which of the two is wrong and its text."""
    if netloc.count(":") != 1:
        raise SinkConfigError(url, "VID:PID", netloc, "expected two hex IDs, e.g. usb://1209:0001")
    ids = []
    for name, text in zip(("VID", "PID"), netloc.split(":")):
        if not _HEX_ID.fullmatch(text):
            # a 16-bit ID has at most four hex digits: 10000 is past 0xffff
            raise SinkConfigError(url, name, text, "expected a 16-bit hex ID, 1 to 4 digits (0000..ffff), "
                                                   "e.g. usb://1209:0001")
        ids.append(int(text, 16))
    return ids[0], ids[1]


def _out_endpoint(raw: str) -> int:
    ep = integer(raw)
    if not 0x01 <= ep <= 0x0F:
        raise ValueError("a bulk OUT endpoint address is 0x01..0x0F")
    return ep


class ClaimedInterface(NamedTuple):
    """What a ``usb://`` URL claims, as far as the URL tells (:func:`claimed_interface`)."""
    vid_pid: str
    """``"1209:0001"``: the IDs as numbers, however the URL spelled them."""
    board: Optional[BoardName]
    """Which board of that VID:PID (``serial=``, ``port=``); None: the first libusb lists."""
    interface: int


def claimed_interface(url: str) -> Optional[ClaimedInterface]:
    """What a ``usb://`` URL claims: its VID:PID, which board of them and the interface; None for a URL the sink
    refuses (its own check says why). Two URLs that give one claim claim one interface whatever their spelling
    (``usb://1209:1`` is ``usb://0x1209:0x0001``) or ``ep``: the second claim fails. Two claims that name their
    boards apart, one by ``serial=`` and one by ``port=``, may still name one board, which only the bus tells
    (:func:`named_board_now`)."""
    sink = _unstarted_sink(url)
    if sink is None:
        return None
    return ClaimedInterface(sink.vid_pid, sink.board_name, sink.interface)


def named_board_now(url: str, backend: Any = None) -> Optional[PortPath]:
    """The port path of the board a ``usb://`` URL's ``serial=`` or ``port=`` names, when exactly one plugged-in
    board of its VID:PID fits it now (:meth:`UsbSink.named_board_now`); None for a URL the sink refuses or that
    names no board."""
    sink = _unstarted_sink(url, backend)
    return None if sink is None else sink.named_board_now()


def _unstarted_sink(url: str, backend: Any = None) -> Optional["UsbSink"]:
    """The sink of ``url``, built but not started (it holds nothing), to read what its URL says; None for a URL the
    sink refuses (its own check says why, at start)."""
    try:
        return UsbSink.from_url(url, backend=backend)
    except (SinkConfigError, ValueError):
        return None


class UsbSink(ProtocolSink):
    scheme = "usb"

    def __init__(
        self, url: str, vid: int, pid: int, ep: int, interface: int, timeout_ms: int,
        options: SinkOptions, backend: Any = None, serial: Optional[str] = None, port: Optional[PortPath] = None,
        claims: Optional[UsbClaims] = None,
    ) -> None:
        super().__init__(url, options)
        self.vid, self.pid, self.ep, self.interface, self.timeout_ms = vid, pid, ep, interface, timeout_ms
        self.serial, self.port = serial, port  # at most one: which of several devices of VID:PID
        self._backend = backend
        self._claims = claims  # the daemon's: which of its sinks holds which interface (None: not checked)
        self._held: Optional[InterfaceOfBoard] = None  # what this sink took in _claims
        self._dev: Optional[usb.core.Device] = None
        self._detached = False  # the sink detached the interface's kernel driver: attach it again on release
        self._warned_several = False  # "several devices match" is said once per sink, not on every reconnect

    @classmethod
    def from_url(cls, url: str, **kw: Any) -> "UsbSink":
        u: SinkUrl = parse_url(url)
        vid, pid = _vid_pid(url, u.netloc)
        if u.path not in ("", "/"):  # usb://1209:0001/2 was taken as 1209:0001, the rest ignored
            raise SinkConfigError(url, "path", u.path, "a usb:// URL has no path: usb://VID:PID?ep=0x01")
        if "ep" not in u.query and kw.get("ep") is None:
            raise SinkConfigError(url, "ep", None, "the bulk OUT endpoint is required, e.g. ?ep=0x01")
        ep = u.take("ep", _out_endpoint, 0, kw)
        interface = u.take("interface", int_in(0, MAX_INTERFACE, "a descriptor byte"), 0, kw)
        timeout_ms = u.take("timeout_ms", int_in(1, MAX_TIMEOUT_MS, "milliseconds"), 100, kw)
        serial = u.take("serial", parse_serial, None, kw)
        port = u.take("port", parse_port, None, kw)
        if serial is not None and port is not None:  # two answers to "which board" could disagree
            raise SinkConfigError(url, "port", str(port), f"give serial= or port=, not both (serial={serial!r})")
        backend = kw.pop("backend", None)
        claims = kw.pop("claims", None)
        options = SinkOptions.take(u, kw)
        u.reject_leftovers()
        reject_unknown_kw(url, kw)
        return cls(url, vid, pid, ep, interface, timeout_ms, options, backend, serial, port, claims)

    @property
    def vid_pid(self) -> str:
        """``"1209:0001"``: the IDs as numbers, however the URL spelled them."""
        return f"{self.vid:04x}:{self.pid:04x}"

    @property
    def board_name(self) -> Optional[BoardName]:
        """How the URL names its board (``serial=``, ``port=``); None: the first libusb lists."""
        if self.serial is not None:
            return BoardName("serial", self.serial)
        return None if self.port is None else BoardName("port", self.port)

    def _get_backend(self) -> Any:
        if self._backend is None:
            import libusb_package  # only when a real USB link is used

            self._backend = libusb_package.get_libusb1_backend()
            if self._backend is None:
                raise SinkUnavailableError(self.url, "libusb backend not available (libusb-package)")
        return self._backend

    def _find_all(self) -> list:
        """The devices of this VID:PID plugged in now: enumeration only, none opened."""
        backend = self._get_backend()
        try:
            return list(usb.core.find(find_all=True, idVendor=self.vid, idProduct=self.pid, backend=backend))
        except usb.core.USBError as e:
            raise SinkUnavailableError(self.url, f"enumeration failed: {e}") from e

    def named_board_now(self) -> Optional[PortPath]:
        """The port path of the board this sink's ``serial=`` or ``port=`` names, when exactly one plugged-in board
        fits it now; None without a selector, with no libusb, when none or several fit, or when the board's port
        path is unknown. What the daemon's config check compares: one board named by its serial and by its port
        is one destination. Enumerates and reads serial strings only: nothing is configured, claimed or reset,
        and every handle opened to read a serial is closed again."""
        if self.serial is None and self.port is None:
            return None  # the first board libusb lists: an order that can change, so no board of its own
        try:
            found = self._find_all()
        except (SinkUnavailableError, ImportError):  # no libusb here: no board can be seen either
            return None
        try:
            dev = select(found, self.serial, self.port, self.vid_pid)
        except NoMatch:
            return None
        try:
            return port_of(dev)
        finally:
            usb.util.dispose_resources(dev)

    def _connect(self) -> None:
        found = self._find_all()
        dev = self._choose(found)
        self._take_interface(dev)
        try:
            self._configure(dev)
        except (usb.core.USBError, ValueError) as e:
            self._reattach(dev)
            usb.util.dispose_resources(dev)
            self._let_interface_go()
            # The device is there but not as the URL describes it (interface, ep) or is held by another
            # program; the base class warns once per outage and per new error, as for any failed connect.
            raise SinkUnavailableError(self.url, f"cannot claim {self.vid_pid}: {e}") from e
        self._dev = dev

    def _choose(self, found: list) -> usb.core.Device:
        """The device to claim: the one the selector names, else the first libusb lists."""
        ids = self.vid_pid
        if self.serial is not None or self.port is not None:
            try:
                return select(found, self.serial, self.port, ids)
            except NoMatch as e:  # as an absent device: the right board may be plugged in later
                raise SinkUnavailableError(self.url, str(e)) from None
        if not found:
            raise SinkUnavailableError(self.url, f"no device {ids}")
        dev = found[0]
        if len(found) > 1 and not self._warned_several:
            # which one is first is libusb's order and may change on a replug: frames could go to the other board
            self._warned_several = True
            _log.warning("%s: %d devices %s found (%s); using the first, bus %s address %s; choose one with "
                         "?port=BUS-PORT (as listed) or ?serial=", self.shown, len(found), ids,
                         ", ".join(describe(d) for d in found), dev.bus, dev.address)
        return dev

    def _take_interface(self, dev: usb.core.Device) -> None:
        """Take this sink's interface of ``dev`` in the daemon's claims before the kernel is asked: another of its
        sinks on it (one board named two ways) is named, not met as EBUSY on every retry. Nothing on the board is
        touched when it is refused.

        :raises UsbBoardTaken: another sink of this daemon holds it.
        """
        if self._claims is None:
            return
        wanted = InterfaceOfBoard(self.vid_pid, board_place(dev), self.interface)
        holder = self._claims.take(wanted, Claimant(self, self.url, self.board_name))
        if holder is not None:
            usb.util.dispose_resources(dev)  # reading its serial may have opened it
            raise UsbBoardTaken(self.url, self.board_name, holder, wanted)
        self._held = wanted

    def _let_interface_go(self) -> None:
        """Give back what :meth:`_take_interface` took: another sink of the daemon may have it now."""
        held, self._held = self._held, None
        if held is not None and self._claims is not None:
            self._claims.let_go(held, self)

    def _configure(self, dev: usb.core.Device) -> None:
        try:
            cfg = dev.get_active_configuration()
        except usb.core.USBError:  # unconfigured device
            dev.set_configuration()
            cfg = dev.get_active_configuration()
        try:
            if dev.is_kernel_driver_active(self.interface):
                dev.detach_kernel_driver(self.interface)
                self._detached = True
        except NotImplementedError:
            pass  # backends without kernel drivers (macOS, Windows, fakes)
        try:
            intf = cfg[(self.interface, 0)]
        except (IndexError, KeyError):
            raise ValueError(f"configuration {cfg.bConfigurationValue} has no interface {self.interface}") from None
        ep = usb.util.find_descriptor(intf, bEndpointAddress=self.ep)
        if ep is None or usb.util.endpoint_type(ep.bmAttributes) != usb.util.ENDPOINT_TYPE_BULK:
            raise ValueError(f"interface {self.interface} has no bulk OUT endpoint 0x{self.ep:02x}")
        usb.util.claim_interface(dev, self.interface)

    def _disconnect(self) -> None:
        dev, self._dev = self._dev, None
        if dev is not None:
            try:
                usb.util.release_interface(dev, self.interface)
            except (usb.core.USBError, ValueError):
                pass  # the device is probably gone
            self._reattach(dev)
            usb.util.dispose_resources(dev)
        self._let_interface_go()  # after the kernel's claim is released: the next sink's claim then succeeds

    def _reattach(self, dev: usb.core.Device) -> None:
        """Give the interface back to the kernel driver this sink detached; must not raise."""
        if not self._detached:
            return
        self._detached = False
        try:
            dev.attach_kernel_driver(self.interface)
        except (usb.core.USBError, NotImplementedError) as e:  # gone, or the driver was unloaded meanwhile
            _log.debug("%s: kernel driver of interface %d not attached again: %s", self.shown, self.interface, e)

    def _write_bytes(self, data: bytes) -> None:
        if self._dev is None:
            raise SinkUnavailableError(self.url, "device not open")
        if not self._bulk_write(data):
            return
        # A stall the device raised once (a full buffer, a transient error) need not cost the frame: clear
        # the halt and write it once more, after a 0x00 that ends whatever part the stalled transfer left.
        self._clear_stall()
        if self._bulk_write(data if data.startswith(b"\x00") else b"\x00" + data):
            self._clear_stall()
            raise SinkWriteError(self.url, f"endpoint 0x{self.ep:02x} stalled again after its halt was cleared; "
                                           "halt cleared, frame dropped")

    def _bulk_write(self, data: bytes) -> bool:
        """One bulk transfer of ``data``; True when the endpoint stalled (the caller clears it).

        :raises SinkWriteError: timeout or short write (the next write resyncs the receiver).
        :raises SinkUnavailableError: any other USB error (the device is gone).
        """
        assert self._dev is not None
        try:
            n = self._dev.write(self.ep, data, timeout=self.timeout_ms)
        except usb.core.USBTimeoutError as e:
            self._resync = True
            raise SinkWriteError(self.url, f"bulk write timed out after {self.timeout_ms} ms") from e
        except usb.core.USBError as e:
            if e.errno == errno.EPIPE:
                return True
            raise SinkUnavailableError(self.url, f"bulk write failed: {e}") from e
        if n != len(data):
            self._resync = True
            raise SinkWriteError(self.url, f"short bulk write: {n} of {len(data)} bytes")
        return False

    def _clear_stall(self) -> None:
        assert self._dev is not None
        try:
            self._dev.clear_halt(self.ep)
        except usb.core.USBError as e:
            raise SinkUnavailableError(self.url, f"clear_halt(0x{self.ep:02x}) failed: {e}") from e
        self._resync = True
