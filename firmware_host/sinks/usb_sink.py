"""usb://VID:PID?ep=0x01 - the protocol over a USB bulk OUT endpoint (pyusb).

Query: ``ep`` (bulk OUT endpoint address, required), ``interface`` (default 0),
``timeout_ms`` (default 100, at most 60000), plus the common options. The libusb backend
comes from ``libusb_package`` unless a pyusb backend is passed as ``backend=``.

Error handling: a stalled endpoint (EPIPE) has its halt cleared and the frame
dropped; a timeout drops the frame; a vanished device (ENODEV and anything
else) is released and searched for again with backoff.

A kernel driver bound to the interface (cdc_acm on a CDC board) is detached to
claim it and attached again when the sink lets the device go, so its
/dev/ttyACM* comes back once the daemon stops.
"""
from __future__ import annotations

import errno
import logging
from typing import Any, Optional

import usb.core
import usb.util

from firmware_host.errors import SinkConfigError, SinkUnavailableError, SinkWriteError
from firmware_host.sinks.options import SinkOptions, reject_unknown_kw
from firmware_host.sinks.protocol_sink import ProtocolSink
from firmware_host.sinks.url import SinkUrl, int_in, non_negative_int, parse_url

_log = logging.getLogger(__name__)

#: Longest bulk write: a joint frame a minute late is of no use, and libusb takes the timeout as an unsigned
#: 32-bit int in which 0 means never (ctypes wraps 2**32 ms to 0: a stalled receiver held the worker for ever).
MAX_TIMEOUT_MS = 60_000


def _vid_pid(url: str, netloc: str) -> tuple[int, int]:
    try:
        vid_s, pid_s = netloc.split(":")
        vid, pid = int(vid_s, 16), int(pid_s, 16)
    except ValueError as e:
        raise SinkConfigError(url, "VID:PID", netloc, "expected four hex digits each, e.g. usb://1209:0001") from e
    if not (0 <= vid <= 0xFFFF and 0 <= pid <= 0xFFFF):
        raise SinkConfigError(url, "VID:PID", netloc, "IDs are 16-bit")
    return vid, pid


def _out_endpoint(raw: str) -> int:
    ep = int(raw, 0)
    if not 0x01 <= ep <= 0x0F:
        raise ValueError("a bulk OUT endpoint address is 0x01..0x0F")
    return ep


class UsbSink(ProtocolSink):
    scheme = "usb"

    def __init__(
        self, url: str, vid: int, pid: int, ep: int, interface: int, timeout_ms: int,
        options: SinkOptions, backend: Any = None,
    ) -> None:
        super().__init__(url, options)
        self.vid, self.pid, self.ep, self.interface, self.timeout_ms = vid, pid, ep, interface, timeout_ms
        self._backend = backend
        self._dev: Optional[usb.core.Device] = None
        self._detached = False  # the sink detached the interface's kernel driver: attach it again on release

    @classmethod
    def from_url(cls, url: str, **kw: Any) -> "UsbSink":
        u: SinkUrl = parse_url(url)
        vid, pid = _vid_pid(url, u.netloc)
        if "ep" not in u.query and kw.get("ep") is None:
            raise SinkConfigError(url, "ep", None, "the bulk OUT endpoint is required, e.g. ?ep=0x01")
        ep = u.take("ep", _out_endpoint, 0, kw)
        interface = u.take("interface", non_negative_int, 0, kw)
        timeout_ms = u.take("timeout_ms", int_in(1, MAX_TIMEOUT_MS, "milliseconds"), 100, kw)
        backend = kw.pop("backend", None)
        options = SinkOptions.take(u, kw)
        u.reject_leftovers()
        reject_unknown_kw(url, kw)
        return cls(url, vid, pid, ep, interface, timeout_ms, options, backend)

    def _get_backend(self) -> Any:
        if self._backend is None:
            import libusb_package  # only when a real USB link is used

            self._backend = libusb_package.get_libusb1_backend()
            if self._backend is None:
                raise SinkUnavailableError(self.url, "libusb backend not available (libusb-package)")
        return self._backend

    def _connect(self) -> None:
        backend = self._get_backend()
        try:
            dev = usb.core.find(idVendor=self.vid, idProduct=self.pid, backend=backend)
        except usb.core.USBError as e:
            raise SinkUnavailableError(self.url, f"enumeration failed: {e}") from e
        if dev is None:
            raise SinkUnavailableError(self.url, f"no device {self.vid:04x}:{self.pid:04x}")
        try:
            self._configure(dev)
        except (usb.core.USBError, ValueError) as e:
            self._reattach(dev)
            usb.util.dispose_resources(dev)
            # The device is there but not as the URL describes it (interface, ep) or is held by another
            # program; the base class warns once per outage and per new error, as for any failed connect.
            raise SinkUnavailableError(self.url, f"cannot claim {self.vid:04x}:{self.pid:04x}: {e}") from e
        self._dev = dev

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

    def _reattach(self, dev: usb.core.Device) -> None:
        """Give the interface back to the kernel driver this sink detached; must not raise."""
        if not self._detached:
            return
        self._detached = False
        try:
            dev.attach_kernel_driver(self.interface)
        except (usb.core.USBError, NotImplementedError) as e:  # gone, or the driver was unloaded meanwhile
            _log.debug("%s: kernel driver of interface %d not attached again: %s", self.url, self.interface, e)

    def _write_bytes(self, data: bytes) -> None:
        if self._dev is None:
            raise SinkUnavailableError(self.url, "device not open")
        try:
            n = self._dev.write(self.ep, data, timeout=self.timeout_ms)
        except usb.core.USBTimeoutError as e:
            self._resync = True
            raise SinkWriteError(self.url, f"bulk write timed out after {self.timeout_ms} ms") from e
        except usb.core.USBError as e:
            if e.errno == errno.EPIPE:
                self._clear_stall()
                raise SinkWriteError(self.url, f"endpoint 0x{self.ep:02x} stalled; halt cleared") from e
            raise SinkUnavailableError(self.url, f"bulk write failed: {e}") from e
        if n != len(data):
            self._resync = True
            raise SinkWriteError(self.url, f"short bulk write: {n} of {len(data)} bytes")

    def _clear_stall(self) -> None:
        assert self._dev is not None
        try:
            self._dev.clear_halt(self.ep)
        except usb.core.USBError as e:
            raise SinkUnavailableError(self.url, f"clear_halt(0x{self.ep:02x}) failed: {e}") from e
        self._resync = True
