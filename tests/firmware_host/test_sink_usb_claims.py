"""Two usb:// sinks of one daemon on one board (one URL's serial=, the other's port=): the second is told which sink
holds the board, once, and takes it when that one lets go (firmware_host/sinks/usb_claims.py)."""
from __future__ import annotations

import logging
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from firmware_host.sinks import open_sink, usb_claims
from firmware_host.sinks.usb_claims import Claimant, InterfaceOfBoard, UsbClaims
from firmware_host.sinks.usb_select import BoardName
from tests.firmware_host.fake_usb_backend import FakeBackend, FakeDevice, two_boards
from tests.firmware_host.joint_stream_helpers import FAST_BACKOFF, joints_seqs, make_frame, messages_of, wait_until

REPO = Path(__file__).resolve().parents[2]
BY_SERIAL = "usb://1209:0001?ep=0x01&serial=ABC123"
BY_PORT = "usb://1209:1?ep=0x01&port=1-1.4"
NAMES = {BY_SERIAL: "serial='ABC123'", BY_PORT: "port=1-1.4"}
#: How long the slow journal takes over each line: longer than a refused connect's bookkeeping, so a test that
#: reads the journal as soon as the counter moves sees a line short.
SLOW_JOURNAL_S = 0.02


class _SlowJournal(logging.Handler):
    """A journal handler that takes its time (journald under load): the sink's worker logs a refused connect
    after counting it, so the line reaches the handlers above this one ``SLOW_JOURNAL_S`` after the count."""

    def emit(self, record: logging.LogRecord) -> None:
        time.sleep(SLOW_JOURNAL_S)


@contextmanager
def _journal_taking(delay_s: float) -> Iterator[None]:
    """The sinks' lines pass a handler that takes ``delay_s`` over each before reaching caplog's (on the root
    logger); 0: none."""
    if not delay_s:
        yield
        return
    handler, sinks = _SlowJournal(), logging.getLogger("firmware_host.sinks")
    sinks.addHandler(handler)
    try:
        yield
    finally:
        sinks.removeHandler(handler)


def _held_lines(caplog: pytest.LogCaptureFixture) -> list[logging.LogRecord]:
    """The journal's lines saying the board is held by another sink."""
    return [r for r in caplog.records if "held by another sink" in r.getMessage()]


def test_without_the_daemons_claims_the_second_sink_meets_the_kernels_ebusy() -> None:
    """What session 65 left when the board is plugged in after the config check (sinks opened apart still meet it):
    the fake answers a second handle's claim as usbfs does, and the error names neither the other sink nor the
    board."""
    board = two_boards()[0]
    first = open_sink(BY_SERIAL, backend=FakeBackend(board), backoff=FAST_BACKOFF)
    try:
        assert first.wait_connected(5)
        second = open_sink(BY_PORT, backend=FakeBackend(board), backoff=FAST_BACKOFF)
        wait_until(lambda: second.stats().connect_failures >= 2, what="two refused connects")
        assert (second.close().last_error or "").endswith("cannot claim 1209:0001: [Errno 16] Resource busy")
    finally:
        first.close()


@pytest.mark.parametrize("journal_delay_s", [0.0, SLOW_JOURNAL_S], ids=["journal-prompt", "journal-slow"])
@pytest.mark.parametrize(("holder_url", "waiter_url"), [(BY_SERIAL, BY_PORT), (BY_PORT, BY_SERIAL)])
def test_a_board_named_by_serial_and_by_port_is_refused_to_the_second_sink_naming_both_once(
        holder_url: str, waiter_url: str, journal_delay_s: float, caplog: pytest.LogCaptureFixture) -> None:
    """The refusal is in the journal once at WARNING, its repeats at DEBUG. The worker logs a refused connect after
    counting it (outside the sink's lock: handlers may be slow), so the test waits for the lines themselves, not
    for the counter: under load (and always with the slow journal) the fifth line came after the fifth count."""
    board = two_boards()[0]
    claims = UsbClaims()
    holder = open_sink(holder_url, backend=FakeBackend(board), backoff=FAST_BACKOFF, claims=claims)
    try:
        assert holder.wait_connected(5)
        with _journal_taking(journal_delay_s), caplog.at_level(logging.DEBUG, logger="firmware_host.sinks"):
            waiter = open_sink(waiter_url, backend=FakeBackend(board), backoff=FAST_BACKOFF, claims=claims)
            wait_until(lambda: len(_held_lines(caplog)) >= 5, what="five refusals in the journal")
        stats = waiter.stats()
        assert stats.connect_failures >= 5
        assert stats.state == "down"
        assert stats.last_error == (
            f"{waiter_url}: unavailable: interface 0 of the 1209:0001 board at port 1-1.4 is held by another sink of "
            f"this daemon, {holder_url}, which names it {NAMES[holder_url]}; this sink names it {NAMES[waiter_url]}: "
            "two names of one board; remove one of the two sinks or name another board (this one takes the board "
            "once the other lets it go: a reload that removes it, the board moved)")
        said = _held_lines(caplog)
        assert [r.levelno for r in said if r.levelno >= logging.WARNING] == [logging.WARNING]  # once, not per retry
        assert len(said) >= 5  # the repeats at DEBUG
        assert board.claimed == {0}  # the holder's claim, untouched by the refused sink
        holder.send(make_frame(0))
        assert holder.wait_drained(5)
        assert joints_seqs(messages_of(board.take())) == [0]
        holder.close()  # as a reload that removes it does: the waiting sink takes the board
        assert waiter.wait_connected(5)
        waiter.send(make_frame(1))
        assert waiter.wait_drained(5)
        waiter.close(timeout=5)  # the board released before the check below, however loaded the host
    finally:
        holder.close()
    assert joints_seqs(messages_of(board.take())) == [1]
    assert not board.claimed and board.open_handles == 0


def test_a_board_of_no_port_path_is_named_by_bus_and_address_as_the_device_listing_names_it() -> None:
    """The refusal said ``bus 1 address 5 (port unknown)`` where the sink's listing of devices (and docs/protocol.md)
    says ``bus 1 address 5 port unknown``: one wording now (usb_select.board_place)."""
    board = FakeDevice(address=5, serial="ABC123", port_numbers=())
    claims = UsbClaims()
    holder = open_sink(BY_SERIAL, backend=FakeBackend(board), backoff=FAST_BACKOFF, claims=claims)
    try:
        assert holder.wait_connected(5)
        waiter = open_sink(BY_SERIAL, backend=FakeBackend(board), backoff=FAST_BACKOFF, claims=claims)
        wait_until(lambda: waiter.stats().connect_failures >= 1, what="a refused connect")
        assert "interface 0 of the 1209:0001 board at bus 1 address 5 port unknown is held by another sink" in (
            waiter.close().last_error or "")
    finally:
        holder.close()


def test_two_boards_named_apart_by_serial_and_by_port_both_stream() -> None:
    first, second = two_boards()
    claims = UsbClaims()
    sinks = [open_sink(url, backend=FakeBackend(first, second), backoff=FAST_BACKOFF, claims=claims)
             for url in ("usb://1209:0001?ep=0x01&serial=XYZ789", BY_PORT)]
    for seq, sink in enumerate(sinks):
        assert sink.wait_connected(5)
        sink.send(make_frame(seq))
        assert sink.wait_drained(5)
        sink.close()
    assert joints_seqs(messages_of(second.take())) == [0] and joints_seqs(messages_of(first.take())) == [1]


def test_a_sink_whose_claim_the_kernel_refuses_lets_the_interface_go() -> None:
    """Another program holds the board: each sink meets EBUSY and holds nothing in the daemon's claims, so the
    other sink's error is the kernel's, not "held by another sink"."""
    board = two_boards()[0]
    board.held_elsewhere = True
    claims = UsbClaims()
    sinks = [open_sink(url, backend=FakeBackend(board), backoff=FAST_BACKOFF, claims=claims)
             for url in (BY_SERIAL, BY_PORT)]
    try:
        for sink in sinks:
            wait_until(lambda: sink.stats().connect_failures >= 3, what="three refused connects")
            assert (sink.stats().last_error or "").endswith("Resource busy")
    finally:
        for sink in sinks:
            sink.close()


def test_only_the_holder_lets_its_claim_go() -> None:
    claims = UsbClaims()
    interface = InterfaceOfBoard("1209:0001", "port 1-1.4", 0)
    first, second = object(), object()
    mine = Claimant(first, BY_SERIAL, BoardName("serial", "ABC123"))
    assert claims.take(interface, mine) is None
    assert claims.take(interface, mine) is None  # its own again: a reconnect
    assert claims.take(interface, Claimant(second, BY_PORT, None)) == mine
    claims.let_go(interface, second)  # not its claim: it stays
    assert claims.take(interface._replace(interface=1), Claimant(second, BY_PORT, None)) is None  # another interface
    assert claims.take(interface, Claimant(second, BY_PORT, None)) == mine
    claims.let_go(interface, first)
    assert claims.take(interface, Claimant(second, BY_PORT, None)) is None


def test_the_claims_module_imports_pyusb_through_usb_select_and_loads_no_libusb_backend_as_its_docstring_says() -> None:
    """Its docstring said "Nothing here imports pyusb", but ``usb_select`` (BoardName) imports ``usb.core``."""
    loaded = subprocess.run(
        [sys.executable, "-c", "import sys, firmware_host.sinks.usb_claims; print(' '.join(sorted(sys.modules)))"],
        capture_output=True, text=True, check=True, cwd=REPO).stdout.split()
    assert "usb.core" in loaded and "libusb_package" not in loaded
    doc = " ".join((usb_claims.__doc__ or "").split())
    assert "it does import pyusb, through ``usb_select``" in doc and "loads no libusb backend" in doc
