"""A pyusb backend (usb.backend.IBackend) with simulated vendor-class devices (one, or more of one VID:PID).

It lets ``usb.core.find(backend=...)``, ``Device.set_configuration``,
``usb.util.claim_interface``, ``Device.write`` and ``Device.clear_halt`` run
through pyusb's real code. The device has one configuration with one
interface holding a bulk OUT endpoint (0x01) and a bulk IN endpoint (0x81).

Modelled: descriptors for enumeration; configuration state; bulk OUT writes
(bytes are appended to ``device.received``); a stalled endpoint (writes raise
USBError with errno EPIPE until ``clear_halt``; ``stall_next`` stalls that many
of the coming writes, each until its ``clear_halt``); a write that returns
fewer bytes than asked (``short_write``: the next write takes that many); a
write that times out part way (``time_out_after``: that many bytes arrive, then
USBTimeoutError, as libusb reports a bulk transfer whose later packets the
device never took); disappearance (the device leaves enumeration and every call
on an open handle raises USBError with errno ENODEV, also after it comes back:
a replugged device needs a new handle); a kernel driver bound to the interface
(``kernel_driver``, as cdc_acm holds a CDC board's /dev/ttyACM*): claiming
fails with EBUSY until it is detached, and ``attach_kernel_driver`` binds it
again; an interface another program holds (``held_elsewhere``: EBUSY); an
interface claimed through another open handle (``claimers``: EBUSY, as Linux's
usbfs answers a second open of the device, in this process or another, until
the first releases it or is closed); several
devices of one VID:PID (``FakeBackend(first, second)``, listed in that order,
told apart by ``address``, ``bus`` and ``port_numbers``); a serial number string
(``serial``: iSerialNumber is 3 when set, 0 when None) read through pyusb's own
``usb.util.get_langids``/``get_string``, which reach ``ctrl_transfer`` with a
standard GET_DESCRIPTOR request (string descriptor 0 lists ``langids``; a
language the device does not list, any other request, or ``string_stall`` is
answered with a stall, EPIPE, as a device does; ``string_reads`` counts them;
``open_handles`` those opened and not closed); a
device node the user may not open (``access_denied``: ``open_device`` raises
USBError with errno EACCES, as libusb does on Linux without a udev rule, so
string reads and claiming both fail).

Not modelled: other control transfers, IN/interrupt/iso transfers, timing,
packet sizes, alternate settings, hubs and parents (``port_numbers`` is just
reported), more than one configuration.
"""
from __future__ import annotations

import array
import errno
import struct
import threading
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Optional

import usb.backend
import usb.core


@dataclass
class FakeDevice:
    vid: int = 0x1209
    pid: int = 0x0001
    received: bytearray = field(default_factory=bytearray)
    present: bool = True
    stalled: bool = False
    configuration: int = 0  # 0 = unconfigured
    claimed: set = field(default_factory=set)
    claimers: dict = field(default_factory=dict)  # interface -> the open handle that claimed it
    generation: int = 0  # bumped on every unplug: old handles go stale
    writes: int = 0
    halts_cleared: int = 0
    time_out_after: Optional[int] = None  # the next write delivers this many bytes, then times out
    stall_next: int = 0  # this many of the coming writes stall the endpoint (each needs a clear_halt)
    short_write: Optional[int] = None  # the next write takes this many bytes and returns that count
    address: int = 5
    kernel_driver: bool = False  # a kernel driver is bound to interface 0
    held_elsewhere: bool = False  # another program claimed interface 0: claiming fails with EBUSY
    detaches: int = 0
    attaches: int = 0
    bus: int = 1
    port_numbers: tuple = (1,)  # (): a backend that reports no port path (old libusb, some platforms)
    serial: Optional[str] = None  # the serial number string; None: the device declares none
    langids: tuple = (0x0409,)  # string descriptor 0: the languages its strings come in
    string_stall: bool = False  # string descriptor requests stall (EPIPE), as on a buggy firmware
    access_denied: bool = False  # opening fails with EACCES (Linux, no udev rule for the user)
    string_reads: int = 0
    open_handles: int = 0  # opened and not yet closed (a handle left open keeps the device busy)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def unplug(self) -> None:
        with self.lock:
            self.present = False
            self.generation += 1
            self.configuration = 0
            self.claimed.clear()
            self.claimers.clear()

    def plug(self) -> None:
        with self.lock:
            self.present = True
            self.stalled = False

    def take(self) -> bytes:
        with self.lock:
            data = bytes(self.received)
            self.received.clear()
            return data


_ENODEV = usb.core.USBError("No such device (it may have been disconnected)", error_code=-4, errno=errno.ENODEV)
_EPIPE = usb.core.USBError("Pipe error", error_code=-9, errno=errno.EPIPE)

_GET_DESCRIPTOR = 0x06
_STANDARD_IN_TO_DEVICE = 0x80  # bmRequestType: device-to-host, standard, recipient device
_DESC_STRING = 3
_SERIAL_INDEX = 3  # iSerialNumber when the device has a serial


def _string_descriptor(payload: bytes) -> bytes:
    return bytes((2 + len(payload), _DESC_STRING)) + payload


class FakeBackend(usb.backend.IBackend):
    def __init__(self, device: FakeDevice, *more: FakeDevice) -> None:
        super().__init__()
        self.device = device
        self.devices = (device, *more)

    # ---- enumeration and descriptors ----

    def enumerate_devices(self):
        yield from (d for d in self.devices if d.present)

    def get_parent(self, dev):
        return None

    def get_device_descriptor(self, dev):
        return SimpleNamespace(
            bLength=18, bDescriptorType=1, bcdUSB=0x0200, bDeviceClass=0xFF, bDeviceSubClass=0,
            bDeviceProtocol=0, bMaxPacketSize0=64, idVendor=dev.vid, idProduct=dev.pid, bcdDevice=0x0100,
            iManufacturer=0, iProduct=0, iSerialNumber=0 if dev.serial is None else _SERIAL_INDEX,
            bNumConfigurations=1, address=dev.address, bus=dev.bus,
            port_number=dev.port_numbers[-1] if dev.port_numbers else None,
            port_numbers=dev.port_numbers, speed=2,
        )

    def get_configuration_descriptor(self, dev, config):
        if config != 0:
            raise IndexError(config)
        return SimpleNamespace(
            bLength=9, bDescriptorType=2, wTotalLength=32, bNumInterfaces=1, bConfigurationValue=1,
            iConfiguration=0, bmAttributes=0x80, bMaxPower=50, extra_descriptors=b"",
        )

    def get_interface_descriptor(self, dev, intf, alt, config):
        if (intf, alt, config) != (0, 0, 0):
            raise IndexError((intf, alt, config))  # pyusb iterates until IndexError
        return SimpleNamespace(
            bLength=9, bDescriptorType=4, bInterfaceNumber=0, bAlternateSetting=0, bNumEndpoints=2,
            bInterfaceClass=0xFF, bInterfaceSubClass=0, bInterfaceProtocol=0, iInterface=0,
            extra_descriptors=b"",
        )

    def get_endpoint_descriptor(self, dev, ep, intf, alt, config):
        if (intf, alt, config) != (0, 0, 0) or ep not in (0, 1):
            raise IndexError((ep, intf, alt, config))
        return SimpleNamespace(
            bLength=7, bDescriptorType=5, bEndpointAddress=(0x01, 0x81)[ep], bmAttributes=0x02,
            wMaxPacketSize=64, bInterval=0, bRefresh=0, bSynchAddress=0, extra_descriptors=b"",
        )

    # ---- handles ----

    def _check(self, handle) -> FakeDevice:
        dev = handle.device
        if not dev.present or handle.generation != dev.generation:
            raise _ENODEV
        return dev

    def open_device(self, dev):
        if not dev.present:
            raise _ENODEV
        if dev.access_denied:
            raise usb.core.USBError("Access denied (insufficient permissions)", error_code=-3, errno=errno.EACCES)
        dev.open_handles += 1
        return SimpleNamespace(device=dev, generation=dev.generation)

    def close_device(self, dev_handle):
        dev = dev_handle.device
        dev.open_handles -= 1
        for intf in [i for i, holder in dev.claimers.items() if holder is dev_handle]:  # closing releases
            dev.claimed.discard(intf)
            del dev.claimers[intf]

    def set_configuration(self, dev_handle, config_value):
        self._check(dev_handle).configuration = config_value

    def get_configuration(self, dev_handle):
        return self._check(dev_handle).configuration

    def claim_interface(self, dev_handle, intf):
        dev = self._check(dev_handle)
        other_handle = dev.claimers.get(intf, dev_handle) is not dev_handle
        if dev.kernel_driver or dev.held_elsewhere or other_handle:
            raise usb.core.USBError("Resource busy", error_code=-6, errno=errno.EBUSY)
        dev.claimed.add(intf)
        dev.claimers[intf] = dev_handle

    def release_interface(self, dev_handle, intf):
        dev = self._check(dev_handle)
        if dev.claimers.get(intf) is dev_handle:
            dev.claimed.discard(intf)
            del dev.claimers[intf]

    def is_kernel_driver_active(self, dev_handle, intf):
        return self._check(dev_handle).kernel_driver

    def detach_kernel_driver(self, dev_handle, intf):
        dev = self._check(dev_handle)
        dev.kernel_driver = False
        dev.detaches += 1

    def attach_kernel_driver(self, dev_handle, intf):
        dev = self._check(dev_handle)
        if intf in dev.claimed:
            raise usb.core.USBError("Resource busy", error_code=-6, errno=errno.EBUSY)
        dev.kernel_driver = True
        dev.attaches += 1

    # ---- transfers ----

    def ctrl_transfer(self, dev_handle, bmRequestType, bRequest, wValue, wIndex, data, timeout):
        """Only GET_DESCRIPTOR for string descriptors (what usb.util.get_string sends); the rest stalls."""
        dev = self._check(dev_handle)
        kind, index = wValue >> 8, wValue & 0xFF
        with dev.lock:
            dev.string_reads += 1
            if (bmRequestType, bRequest, kind) != (_STANDARD_IN_TO_DEVICE, _GET_DESCRIPTOR, _DESC_STRING) \
                    or dev.string_stall:
                raise _EPIPE
            if index == 0:
                desc = _string_descriptor(struct.pack(f"<{len(dev.langids)}H", *dev.langids))
            elif index == _SERIAL_INDEX and dev.serial is not None and wIndex in dev.langids:
                desc = _string_descriptor(dev.serial.encode("utf-16-le"))
            else:
                raise _EPIPE
        n = min(len(desc), len(data))
        data[:n] = array.array("B", desc[:n])  # pyusb hands an array('B') to fill and keeps the first n bytes
        return n

    def bulk_write(self, dev_handle, ep, intf, data, timeout):
        dev = self._check(dev_handle)
        if intf not in dev.claimed:
            raise usb.core.USBError("interface not claimed", error_code=-5, errno=errno.EBUSY)
        if ep != 0x01:
            raise usb.core.USBError("invalid endpoint", error_code=-2, errno=errno.EINVAL)
        with dev.lock:
            dev.writes += 1
            if dev.stall_next > 0:
                dev.stall_next -= 1
                dev.stalled = True
            if dev.stalled:
                raise usb.core.USBError("Pipe error", error_code=-9, errno=errno.EPIPE)
            if dev.short_write is not None:
                n, dev.short_write = dev.short_write, None
                dev.received += bytes(data[:n])
                return n
            if dev.time_out_after is not None:
                dev.received += bytes(data[: dev.time_out_after])
                dev.time_out_after = None
                raise usb.core.USBTimeoutError("Operation timed out", error_code=-7, errno=errno.ETIMEDOUT)
            dev.received += bytes(data)
        return len(data)

    def clear_halt(self, dev_handle, ep):
        dev = self._check(dev_handle)
        with dev.lock:
            dev.stalled = False
            dev.halts_cleared += 1


def two_boards() -> tuple[FakeDevice, FakeDevice]:
    """Two identical boards of 1209:0001: libusb lists the first (serial ``ABC123``, port ``1-1.4``) first; only
    serial and port tell it from the second (serial ``XYZ789``, port ``1-2``)."""
    return (FakeDevice(address=7, serial="ABC123", port_numbers=(1, 4)),
            FakeDevice(address=9, serial="XYZ789", port_numbers=(2,)))
