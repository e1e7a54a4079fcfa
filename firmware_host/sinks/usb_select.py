"""Which of several USB devices of one VID:PID the usb:// sink takes: ``?serial=`` or ``?port=``.

Two identical boards share VID:PID, and libusb's order of them can change on a replug, so a URL can
name one by its serial number (a string descriptor, read from the device) or by its physical port
path (``BUS-PORT.PORT...``, the topology path Linux names the device by in sysfs and udev shows as
KERNELS, e.g. ``1-1.4``: bus 1, port 4 of the hub on root port 1; it stays put while the board stays
in that socket). The two are exclusive. Matching is pure bookkeeping on pyusb ``Device`` objects;
the sink decides what a miss means (wait with backoff, as for an absent device).
"""
from __future__ import annotations

import errno
import re
from dataclasses import dataclass
from typing import Any, Literal, Optional, Sequence, Union

import usb.core
import usb.util

#: A string descriptor is at most 255 bytes: 2 of header and 126 UTF-16 code units.
MAX_SERIAL_CHARS = 126

#: libusb reports at most 7 port numbers (USB 3.0's deepest tier); a bus and a port number are one byte.
MAX_PORT_DEPTH = 7

#: Where the repo says how to let the service open a USB receiver without root.
UDEV_HINT = ("add a udev rule for it (systemd/61-ghnerf-local.rules has a template; docs/daemon.md, "
             "'udev'; docs/protocol.md, section 7)")

_PORT_PATH = re.compile(r"([0-9]{1,3})-([0-9]{1,3}(?:\.[0-9]{1,3})*)")


@dataclass(frozen=True)
class PortPath:
    """A physical port path: the bus number and the port numbers from the root hub down."""
    bus: int
    ports: tuple[int, ...]

    def __str__(self) -> str:
        return f"{self.bus}-{'.'.join(str(p) for p in self.ports)}"


@dataclass(frozen=True)
class BoardName:
    """Which board of its VID:PID a ``usb://`` URL names: by its serial number string (``by`` "serial", ``value`` the
    string) or by the port path it is plugged into (``by`` "port", ``value`` a :class:`PortPath`). Two names of one
    kind and value are one board, two of one kind and other values two boards; a serial and a port may be one
    board, which only the bus tells."""
    by: Literal["serial", "port"]
    value: Union[str, PortPath]

    def __str__(self) -> str:
        """As the URL gives it, the serial quoted: ``serial='ABC123'``, ``port=1-1.4``."""
        return f"serial={self.value!r}" if self.by == "serial" else f"port={self.value}"


def parse_serial(raw: str) -> str:
    """The ``serial`` option: compared exactly (case and all) with the device's serial number string."""
    if not raw:
        raise ValueError("empty; give the serial number lsusb -v shows as iSerial, e.g. serial=ABC123")
    if len(raw) > MAX_SERIAL_CHARS:
        raise ValueError(f"{len(raw)} characters; a USB string descriptor holds at most {MAX_SERIAL_CHARS}")
    if not raw.isprintable():  # a %00 or %0A could never be matched and would garble the log line
        raise ValueError("holds a control character")
    return raw


def parse_port(raw: str) -> PortPath:
    """The ``port`` option: ``BUS-PORT[.PORT...]``, decimal, as Linux writes it (``1-1.4``)."""
    m = _PORT_PATH.fullmatch(raw)
    if m is None:
        raise ValueError("expected BUS-PORT[.PORT...] in decimal, e.g. port=1-1.4 (bus 1, ports 1 then 4; "
                         "udevadm info or ls /sys/bus/usb/devices shows it)")
    bus, ports = int(m.group(1)), tuple(int(p) for p in m.group(2).split("."))
    if bus > 255:
        raise ValueError(f"bus {bus} is past 255 (libusb's bus number is one byte)")
    if len(ports) > MAX_PORT_DEPTH:
        raise ValueError(f"{len(ports)} port numbers; a USB device is at most {MAX_PORT_DEPTH} hubs deep")
    bad = [p for p in ports if not 1 <= p <= 255]
    if bad:
        raise ValueError(f"port number {bad[0]} is outside 1..255 (ports are numbered from 1)")
    return PortPath(bus, ports)


def port_of(dev: Any) -> Optional[PortPath]:
    """The device's port path, or None where the backend does not know it (old libusb, some platforms)."""
    ports = getattr(dev, "port_numbers", None)
    if dev.bus is None or not ports:
        return None
    return PortPath(int(dev.bus), tuple(int(p) for p in ports))


class SerialReadError(Exception):
    """The serial number string descriptor could not be read; the message says why and what to do."""


def read_serial(dev: Any) -> Optional[str]:
    """The device's serial number string, None when it declares none (iSerialNumber 0).

    Calls ``usb.util.get_langids`` itself rather than ``Device.langids``, which swallows the USBError
    (a permission error turned into "The device has no langid").

    :raises SerialReadError: the device could not be opened (EACCES: no udev rule) or the descriptor
        request failed (a stall, a device gone); the message names the cause.
    """
    if not dev.iSerialNumber:
        return None
    try:
        langids = usb.util.get_langids(dev)
        if not langids:
            raise SerialReadError("serial unreadable: the device lists no string languages")
        return usb.util.get_string(dev, dev.iSerialNumber, langids[0])
    except usb.core.USBError as e:
        if e.errno in (errno.EACCES, errno.EPERM):
            raise SerialReadError(f"serial unreadable: permission denied ({e}); {UDEV_HINT}") from e
        raise SerialReadError(f"serial unreadable: {e}") from e
    except (ValueError, UnicodeDecodeError) as e:  # a malformed descriptor
        raise SerialReadError(f"serial unreadable: {e}") from e


def describe(dev: Any, note: str = "") -> str:
    """One device for a log line: bus, address, port path, then ``note`` (its serial number, or why not)."""
    port = port_of(dev)
    text = f"bus {dev.bus} address {dev.address} port {port if port is not None else 'unknown'}"
    return f"{text} {note}" if note else text


def board_place(dev: Any) -> str:
    """Where one board is, for a message about it: its port path (``port 1-1.4``), which stays while the board stays
    in that socket; where the backend reports none, its bus and address as :func:`describe` lists them (``bus 1
    address 5 port unknown``): one wording of an unknown port in every message."""
    port = port_of(dev)
    return f"port {port}" if port is not None else describe(dev)


def _serial_note(dev: Any) -> tuple[Optional[str], str]:
    """The device's serial number (None when it has none or it cannot be read) and how to log it."""
    try:
        serial = read_serial(dev)
    except SerialReadError as e:
        return None, f"({e})"
    return serial, ("(no serial number)" if serial is None else f"serial {serial!r}")


class NoMatch(Exception):
    """No device, or more than one, fits the selector; the message says what was looked for and found."""


def select(found: Sequence[Any], serial: Optional[str], port: Optional[PortPath], ids: str) -> Any:
    """The one device of ``found`` (all of VID:PID ``ids``) that has ``serial`` or sits at ``port``.

    Serial numbers are read from every device (the log then lists them all); the devices not taken
    have their handles closed. Exactly one of ``serial`` and ``port`` is given.

    :raises NoMatch: none matches, or several share that serial number (the message gives each one's ``port=``,
        or says that the backend reports no port path to choose by).
    """
    looked_for = f"serial {serial!r}" if serial is not None else f"port {port}"
    seen: list[str] = []
    hits: list[Any] = []
    for dev in found:
        if port is not None:  # the port path comes with enumeration: nothing to read from the device
            got_port = port_of(dev)
            if got_port == port:
                hits.append(dev)
            seen.append(describe(dev))
            continue
        got, note = _serial_note(dev)
        if got == serial:
            hits.append(dev)
        seen.append(describe(dev, note))
    chosen = hits[0] if len(hits) == 1 else None
    for dev in found:
        if dev is not chosen:
            usb.util.dispose_resources(dev)  # reading its serial opened it: closed now, not when the GC gets to it
    listed = "; ".join(seen)
    if not found:
        raise NoMatch(f"no device {ids} with {looked_for}: no {ids} found at all")
    if not hits:
        raise NoMatch(f"no device {ids} with {looked_for}; found {len(found)} of {ids}: {listed}")
    if len(hits) > 1:
        raise NoMatch(f"{len(hits)} devices {ids} have {looked_for} (boards flashed alike?); {_tell_apart(hits)} "
                      f"(found: {listed})")
    return hits[0]


def _tell_apart(alike: Sequence[Any]) -> str:
    """How to name one of boards that share a serial number: ``port=`` with each one's port path, ready to put in
    the URL in place of ``serial=``; where the backend reports no port path for one of them, that ``port=`` cannot
    tell them apart either, and what can."""
    ports = [port_of(dev) for dev in alike]
    if all(port is not None for port in ports):
        return "choose one by port= in place of serial=: " + " or ".join(f"port={port}" for port in ports)
    unknown = "; ".join(describe(dev) for dev, port in zip(alike, ports) if port is None)
    return (f"port= cannot choose between them either: this libusb reports no port path for {unknown}; give the "
            "boards serial numbers of their own (or use a libusb that reports port numbers)")
