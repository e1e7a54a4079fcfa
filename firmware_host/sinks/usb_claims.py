"""One sink per USB interface: which of a daemon's ``usb://`` sinks holds which interface of which board.

Two sinks of one daemon may name one board two ways, one by ``serial=`` and the other by ``port=``. The config
check refuses that pair when the board is plugged in at load (``daemon.config``); plugged in later, the first sink
to connect claimed the interface and the second met the kernel's EBUSY on every retry, logged as ``cannot claim
...: Resource busy``, which named neither the other sink nor the board. The daemon hands every ``usb://`` sink one
:class:`UsbClaims`; a sink takes its interface there before claiming it from the kernel, so the second is told
which sink of this daemon holds the board and by which name (:class:`UsbBoardTaken`).

The refused sink keeps retrying, quietly (the base class logs the refusal once per outage, at WARNING; its repeats
at DEBUG): what holds the board can change without a restart (a reload that removes the other sink, the board moved
to another socket), and then the waiting sink takes it. The daemon builds the registry whatever its sinks are, so it
opens no device and loads no libusb backend; it does import pyusb, through ``usb_select``
(:class:`~firmware_host.sinks.usb_select.BoardName`), a dependency of the package (pyproject.toml).
"""
from __future__ import annotations

import threading
from typing import NamedTuple, Optional

from drivers.url import shown_url
from firmware_host.errors import SinkUnavailableError
from firmware_host.sinks.usb_select import BoardName

__all__ = ["Claimant", "InterfaceOfBoard", "UsbBoardTaken", "UsbClaims", "name_text"]


class InterfaceOfBoard(NamedTuple):
    """One interface of one plugged-in board: what two sinks cannot both claim."""
    vid_pid: str
    """``"1209:0001"``."""
    board: str
    """Where the board is (:func:`~firmware_host.sinks.usb_select.board_place`): ``port 1-1.4``, or ``bus 1
    address 5 port unknown`` where the backend reports no port path."""
    interface: int


class Claimant(NamedTuple):
    """A sink holding (or asking for) an interface, as an error about it names the sink."""
    sink: object
    """The sink itself: who may let the claim go."""
    url: str
    """Its URL as configured (messages show it without its passwords)."""
    name: Optional[BoardName]
    """How its URL names the board (``serial=``, ``port=``); None: the first libusb lists."""


def name_text(name: Optional[BoardName]) -> str:
    """How a sink names its board, for a message."""
    return "no board (no serial= or port=: the first libusb lists)" if name is None else str(name)


class UsbBoardTaken(SinkUnavailableError):
    """Another sink of this daemon holds the interface of the board this sink's URL names: two names of one board
    (``serial=`` in one URL, ``port=`` in the other). Retried like any failed connect: the other sink may let go."""

    def __init__(self, url: str, name: Optional[BoardName], holder: Claimant, taken: InterfaceOfBoard) -> None:
        self.name, self.holder, self.taken = name, holder, taken
        super().__init__(url, (
            f"interface {taken.interface} of the {taken.vid_pid} board at {taken.board} is held by another sink of "
            f"this daemon, {shown_url(holder.url)}, which names it {name_text(holder.name)}; this sink names it "
            f"{name_text(name)}: two names of one board; remove one of the two sinks or name another board (this "
            "one takes the board once the other lets it go: a reload that removes it, the board moved)"))


class UsbClaims:
    """The interfaces a daemon's ``usb://`` sinks hold, by board; thread-safe (each sink connects on its own
    thread). One per daemon: sinks opened apart (``open_sink``) get none and meet the kernel's EBUSY instead."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._held: dict[InterfaceOfBoard, Claimant] = {}

    def take(self, interface: InterfaceOfBoard, claimant: Claimant) -> Optional[Claimant]:
        """Hold ``interface`` for ``claimant``; returns the other sink that holds it (nothing taken then), None
        when it is ``claimant``'s now."""
        with self._lock:
            holder = self._held.setdefault(interface, claimant)
        return None if holder.sink is claimant.sink else holder

    def let_go(self, interface: InterfaceOfBoard, sink: object) -> None:
        """``sink`` no longer holds ``interface`` (a claim another sink holds stays)."""
        with self._lock:
            if interface in self._held and self._held[interface].sink is sink:
                del self._held[interface]
