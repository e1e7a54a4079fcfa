"""usb:// through pyusb's real code on a fake IBackend (see fake_usb_backend for what it models)."""
from __future__ import annotations

import logging

import pytest
import usb.core

from firmware_host.protocol import Flags, Hello, Joints, decode_stream
from firmware_host.sinks import open_sink
from tests.firmware_host.fake_usb_backend import FakeBackend, FakeDevice, two_boards
from tests.firmware_host.joint_stream_helpers import FAST_BACKOFF, joints_seqs, make_frame, messages_of, wait_until

URL = "usb://1209:0001?ep=0x01&queue=16"


def test_fake_backend_works_with_pyusb_find() -> None:
    dev = usb.core.find(idVendor=0x1209, idProduct=0x0001, backend=FakeBackend(FakeDevice()))
    assert dev is not None and dev.idVendor == 0x1209
    assert usb.core.find(idVendor=0x1209, idProduct=0x0002, backend=FakeBackend(FakeDevice())) is None


def test_frames_reach_the_bulk_endpoint() -> None:
    device = FakeDevice()
    sink = open_sink(URL, backend=FakeBackend(device), backoff=FAST_BACKOFF, rig_id="usb-rig")
    assert sink.wait_connected(5)
    for seq in range(10):
        sink.send(make_frame(seq))
    assert sink.wait_drained(5)
    stats = sink.close()
    msgs = messages_of(device.take())
    assert isinstance(msgs[0], Hello) and msgs[0].rig_id == "usb-rig"
    assert joints_seqs(msgs) == list(range(10))
    assert device.configuration == 1  # the sink configured the unconfigured device
    assert stats.sent == 10 and stats.dropped == 0


def test_a_stalled_endpoint_is_cleared_and_the_frame_written_again() -> None:
    # the frame that met a stall was dropped although the halt was cleared and the endpoint took the next one
    device = FakeDevice()
    sink = open_sink(URL, backend=FakeBackend(device), backoff=FAST_BACKOFF)
    assert sink.wait_connected(5)
    sink.send(make_frame(0))
    assert sink.wait_drained(5)
    device.stalled = True
    sink.send(make_frame(1))  # hits the stall, then goes out once the halt is cleared
    assert sink.wait_drained(5)
    sink.send(make_frame(2))
    assert sink.wait_drained(5)
    stats = sink.close()
    assert device.halts_cleared == 1 and not device.stalled
    assert stats.dropped_error == 0 and stats.disconnects == 0 and stats.sent == 3
    events, decoded = decode_stream(device.take())
    joints = [e.message for e in events if isinstance(e.message, Joints)]
    assert [m.header.seq for m in joints] == [0, 1, 2] and sum(decoded.errors.values()) == 0
    assert not any(m.header.flags & Flags.DROPPED for m in joints)


def test_an_endpoint_that_stalls_again_costs_one_frame_and_no_more_tries() -> None:
    device = FakeDevice()
    sink = open_sink(URL, backend=FakeBackend(device), backoff=FAST_BACKOFF)
    assert sink.wait_connected(5)
    sink.send(make_frame(0))
    assert sink.wait_drained(5)
    writes = device.writes
    device.stall_next = 2  # the write and its one retry both stall
    sink.send(make_frame(1))
    assert sink.wait_drained(5)
    sink.send(make_frame(2))
    assert sink.wait_drained(5)
    stats = sink.close()
    assert device.writes - writes == 3 and device.halts_cleared == 2 and not device.stalled
    assert stats.dropped_error == 1 and stats.disconnects == 0 and stats.sent == 2
    assert "stalled again" in (stats.last_error or "")
    joints = [m for m in messages_of(device.take()) if isinstance(m, Joints)]
    assert [m.header.seq for m in joints] == [0, 2]
    assert joints[1].header.flags & Flags.DROPPED


def test_a_short_bulk_write_drops_the_frame_and_the_receiver_resyncs() -> None:
    # a half frame must not run into the next frame's bytes: the next write starts with a delimiter
    device = FakeDevice()
    sink = open_sink(URL, backend=FakeBackend(device), backoff=FAST_BACKOFF)
    assert sink.wait_connected(5)
    device.short_write = 50
    sink.send(make_frame(0))
    assert sink.wait_drained(5)
    sink.send(make_frame(1))
    assert sink.wait_drained(5)
    stats = sink.close()
    assert stats.dropped_error == 1 and "short bulk write: 50 of" in (stats.last_error or "")
    events, decoded = decode_stream(device.take())
    joints = [e.message for e in events if isinstance(e.message, Joints)]
    assert [m.header.seq for m in joints] == [1] and joints[0].header.flags & Flags.DROPPED
    assert sum(decoded.errors.values()) == 1


def test_with_two_matching_devices_the_first_is_used_and_a_warning_says_so(
        caplog: pytest.LogCaptureFixture) -> None:
    first, second = FakeDevice(address=7), FakeDevice(address=9)
    with caplog.at_level(logging.WARNING, logger="firmware_host.sinks"):
        sink = open_sink(URL, backend=FakeBackend(first, second), backoff=FAST_BACKOFF)
        assert sink.wait_connected(5)
        sink.send(make_frame(0))
        assert sink.wait_drained(5)
        first.unplug()  # reconnects: to the second now, and the warning is not repeated
        sink.send(make_frame(1))
        wait_until(lambda: sink.stats().connects == 2, what="reconnected")
        first.plug()
        sink.send(make_frame(2))
        assert sink.wait_drained(5)
        sink.close()
    warnings = [r.getMessage() for r in caplog.records if "devices 1209:0001 found" in r.getMessage()]
    assert len(warnings) == 1
    assert "2 devices" in warnings[0] and "using the first, bus 1 address 7" in warnings[0]
    assert joints_seqs(messages_of(first.take())) == [0]
    assert joints_seqs(messages_of(second.take())) == [2]


@pytest.mark.parametrize(("url", "field", "value"), [
    ("usb://10000:0001?ep=0x01", "VID", "10000"),  # 0x10000 is past 16 bits
    ("usb://1209:10000?ep=0x01", "PID", "10000"),
    ("usb://12g9:0001?ep=0x01", "VID", "12g9"),
    ("usb://1_2:0001?ep=0x01", "VID", "1_2"),  # int(s, 16) took it as 0x12
    ("usb://-1:0001?ep=0x01", "VID", "-1"),
    ("usb://1209:?ep=0x01", "PID", ""),
    ("usb://1209?ep=0x01", "VID:PID", "1209"),
    ("usb://?ep=0x01", "VID:PID", ""),
    ("usb://1209:0001/0002?ep=0x01", "path", "/0002"),  # the path was ignored
    ("usb://1209:0001?ep=0x01&interface=256", "interface", "256"),  # retried forever as "no interface 256"
])
def test_a_usb_url_error_names_the_field_and_value(url: str, field: str, value: str) -> None:
    from firmware_host.errors import SinkConfigError
    from firmware_host.sinks.usb_sink import UsbSink

    with pytest.raises(SinkConfigError) as info:
        UsbSink.from_url(url)
    assert (info.value.field, info.value.value) == (field, value)


@pytest.mark.parametrize(("netloc", "ids"), [("1209:0001", (0x1209, 1)), ("0x1209:0XFFFF", (0x1209, 0xFFFF)),
                                             ("ABCD:ef01", (0xABCD, 0xEF01)), ("0:1", (0, 1))])
def test_usb_ids_are_hex(netloc: str, ids: tuple[int, int]) -> None:
    from firmware_host.sinks.usb_sink import UsbSink

    sink = UsbSink.from_url(f"usb://{netloc}/?ep=0x01&interface=255")
    assert (sink.vid, sink.pid, sink.interface) == (*ids, 255)


def test_device_that_disappears_is_found_again() -> None:
    device = FakeDevice()
    sink = open_sink(URL, backend=FakeBackend(device), backoff=FAST_BACKOFF)
    assert sink.wait_connected(5)
    sink.send(make_frame(0))
    assert sink.wait_drained(5)
    device.unplug()
    sink.send(make_frame(1))  # ENODEV on the old handle
    wait_until(lambda: sink.stats().disconnects == 1, what="disappearance noticed")
    wait_until(lambda: sink.stats().connect_failures >= 2, what="searching while absent")
    assert not sink.stats().connected
    device.plug()
    wait_until(lambda: sink.stats().connected, what="found again")
    for seq in range(2, 6):
        sink.send(make_frame(seq))
    assert sink.wait_drained(5)
    stats = sink.close()
    assert "No such device" in (stats.last_error or "") or "no device" in (stats.last_error or "")
    received = joints_seqs(messages_of(device.take()))
    assert received == [0, 2, 3, 4, 5]
    assert stats.sent == 5 and stats.dropped == 1 and stats.connects == 2


def test_absent_device_at_start_is_waited_for() -> None:
    device = FakeDevice(present=False)
    sink = open_sink(URL, backend=FakeBackend(device), backoff=FAST_BACKOFF)
    wait_until(lambda: sink.stats().connect_failures >= 2, what="retries")
    assert "no device 1209:0001" in (sink.stats().last_error or "")
    device.plug()
    assert sink.wait_connected(5)
    sink.send(make_frame(7))
    assert sink.wait_drained(5)
    sink.close()
    assert joints_seqs(messages_of(device.take())) == [7]


@pytest.mark.parametrize(("query", "words"), [("ep=0x02", ["0x02"]), ("ep=0x01&interface=1", ["no interface 1"])])
def test_a_device_unlike_its_url_is_warned_about_once_and_retried(
    query: str, words: list[str], caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING):
        sink = open_sink(f"usb://1209:0001?{query}", backend=FakeBackend(FakeDevice()), backoff=FAST_BACKOFF)
        wait_until(lambda: sink.stats().connect_failures >= 3, what="three connect attempts")
        stats = sink.close()
    for word in words:
        assert word in (stats.last_error or "")
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) == 1 and "cannot claim" in warnings[0].getMessage()  # no traceback per attempt


def test_an_interface_another_program_holds_is_waited_for_with_one_warning(
        caplog: pytest.LogCaptureFixture) -> None:
    device = FakeDevice(held_elsewhere=True)
    with caplog.at_level(logging.WARNING):
        sink = open_sink(URL, backend=FakeBackend(device), backoff=FAST_BACKOFF)
        wait_until(lambda: sink.stats().connect_failures >= 3, what="three connect attempts")
        assert sink.stats().state == "down" and "Resource busy" in (sink.stats().last_error or "")
        device.held_elsewhere = False  # the other program let go
        assert sink.wait_connected(5)
        sink.send(make_frame(0))
        assert sink.wait_drained(5)
        sink.close()
    assert len([r for r in caplog.records if r.levelno >= logging.WARNING]) == 1
    assert joints_seqs(messages_of(device.take())) == [0]


def test_a_kernel_driver_detached_to_claim_the_board_is_attached_again() -> None:
    # a CDC board's /dev/ttyACM* stayed gone after the daemon stopped
    device = FakeDevice(kernel_driver=True)
    sink = open_sink(URL, backend=FakeBackend(device), backoff=FAST_BACKOFF)
    assert sink.wait_connected(5)
    assert device.detaches == 1 and not device.kernel_driver
    sink.send(make_frame(0))
    assert sink.wait_drained(5)
    sink.close()
    assert device.kernel_driver and device.attaches == 1 and not device.claimed
    assert joints_seqs(messages_of(device.take())) == [0]


def test_a_kernel_driver_is_attached_again_when_the_device_is_not_as_the_url_says() -> None:
    device = FakeDevice(kernel_driver=True)
    sink = open_sink("usb://1209:0001?ep=0x02", backend=FakeBackend(device), backoff=FAST_BACKOFF)
    wait_until(lambda: sink.stats().connect_failures >= 2, what="two connect attempts")
    sink.close()
    assert device.kernel_driver and device.attaches == device.detaches >= 2


def test_a_bulk_write_that_times_out_part_way_costs_the_receiver_that_frame_only() -> None:
    device = FakeDevice()
    sink = open_sink(URL, backend=FakeBackend(device), backoff=FAST_BACKOFF)
    assert sink.wait_connected(5)
    sink.send(make_frame(0))
    assert sink.wait_drained(5)
    device.time_out_after = 40  # frame 1's first 40 bytes reach the board, then the transfer times out
    sink.send(make_frame(1))
    assert sink.wait_drained(5)
    for seq in (2, 3):
        sink.send(make_frame(seq))
    assert sink.wait_drained(5)
    stats = sink.close()
    assert stats.dropped_error == 1 and stats.disconnects == 0 and "timed out" in (stats.last_error or "")
    events, decoded = decode_stream(device.take())
    joints = [e.message for e in events if isinstance(e.message, Joints)]
    # the 0x00 the next write starts with ends the cut frame: one decode error, not frame 2 as well
    assert [m.header.seq for m in joints] == [0, 2, 3]
    assert sum(decoded.errors.values()) == 1
    assert joints[1].header.flags & Flags.DROPPED and not joints[2].header.flags & Flags.DROPPED


def test_a_board_that_stops_taking_transfers_reads_stalled_then_up() -> None:
    # every bulk write timing out (firmware that stopped reading its endpoint) left the sink "up"
    device = FakeDevice()
    sink = open_sink(URL + "&stall_s=0.1&status_s=3600", backend=FakeBackend(device), backoff=FAST_BACKOFF)
    seq = 0

    def send_then(state: str, times_out: bool) -> bool:
        nonlocal seq
        if times_out:
            device.time_out_after = 0  # the board takes none of this transfer
        sink.send(make_frame(seq))
        seq += 1
        assert sink.wait_drained(5)
        return sink.stats().state == state

    try:
        assert sink.wait_connected(5)
        wait_until(lambda: send_then("stalled", True), what="stalled while every transfer times out")
        s = sink.stats()
        assert s.connected and s.disconnects == 0 and "timed out" in (s.last_error or "")
        assert send_then("up", False) and sink.stats().stalled_s is None  # the first frame through
    finally:
        sink.close()


# ---- choosing one of two boards of one VID:PID: ?serial= and ?port= ----

def send_frame_0(url: str, backend: FakeBackend) -> None:
    """Frame 0 through a sink opened on ``url`` over ``backend``, once connected, drained, then the sink closed."""
    sink = open_sink(url, backend=backend, backoff=FAST_BACKOFF)
    assert sink.wait_connected(5)
    sink.send(make_frame(0))
    assert sink.wait_drained(5)
    sink.close()


@pytest.mark.parametrize(("query", "chosen"), [
    ("serial=ABC123", 0), ("serial=XYZ789", 1), ("port=1-1.4", 0), ("port=1-2", 1),
])
def test_a_selector_sends_to_the_board_it_names(query: str, chosen: int) -> None:
    boards = two_boards()
    send_frame_0(f"{URL}&{query}", FakeBackend(*boards))
    assert joints_seqs(messages_of(boards[chosen].take())) == [0]
    other = boards[1 - chosen]
    assert other.take() == b"" and not other.claimed
    assert other.open_handles == 0  # reading its serial opened it: that handle must not stay open


def test_the_selected_board_is_found_again_after_a_replug_in_another_order() -> None:
    # the gap: after a replug libusb may list the other board first, and frames went to it
    first, second = two_boards()
    backend = FakeBackend(first, second)
    sink = open_sink(f"{URL}&serial=XYZ789", backend=backend, backoff=FAST_BACKOFF)
    assert sink.wait_connected(5)
    second.unplug()
    backend.devices = (second, first)  # plugged back in, now listed first... as it happens
    sink.send(make_frame(1))
    wait_until(lambda: sink.stats().disconnects == 1, what="unplug noticed")
    second.plug()
    wait_until(lambda: sink.stats().connected, what="found again")
    sink.send(make_frame(2))
    assert sink.wait_drained(5)
    sink.close()
    assert first.take() == b""
    assert joints_seqs(messages_of(second.take())) == [2]


@pytest.mark.parametrize(("query", "words"), [
    ("serial=NOPE", ["no device 1209:0001 with serial 'NOPE'", "found 2 of 1209:0001",
                     "bus 1 address 7 port 1-1.4 serial 'ABC123'", "bus 1 address 9 port 1-2 serial 'XYZ789'"]),
    ("port=1-3", ["no device 1209:0001 with port 1-3", "found 2 of 1209:0001",
                  "bus 1 address 7 port 1-1.4", "bus 1 address 9 port 1-2"]),
])
def test_a_selector_that_matches_nothing_is_waited_for_and_says_what_it_found(
        query: str, words: list[str], caplog: pytest.LogCaptureFixture) -> None:
    boards = two_boards()
    backend = FakeBackend(*boards)
    with caplog.at_level(logging.WARNING, logger="firmware_host.sinks"):
        sink = open_sink(f"{URL}&{query}", backend=backend, backoff=FAST_BACKOFF)
        wait_until(lambda: sink.stats().connect_failures >= 3, what="three connect attempts")
        assert sink.stats().state == "down"
        # the right board turns up: taken without a restart, like an absent device plugged in
        wanted = FakeDevice(address=11, serial="NOPE", port_numbers=(3,))
        backend.devices = (*boards, wanted)
        assert sink.wait_connected(5)
        sink.send(make_frame(0))
        assert sink.wait_drained(5)
        sink.close()
    warnings = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) == 1  # once per outage, not on every retry
    for word in words:
        assert word in warnings[0]
    assert joints_seqs(messages_of(wanted.take())) == [0]
    assert all(b.take() == b"" and b.open_handles == 0 for b in boards)


def test_a_selector_with_no_board_of_that_vid_pid_says_so() -> None:
    sink = open_sink(f"{URL}&port=1-1.4", backend=FakeBackend(FakeDevice(present=False)), backoff=FAST_BACKOFF)
    wait_until(lambda: sink.stats().connect_failures >= 2, what="retries")
    stats = sink.close()
    assert "no device 1209:0001 with port 1-1.4: no 1209:0001 found at all" in (stats.last_error or "")


def test_a_serial_that_cannot_be_read_for_permission_names_the_udev_rule() -> None:
    board = FakeDevice(serial="ABC123", access_denied=True)
    sink = open_sink(f"{URL}&serial=ABC123", backend=FakeBackend(board), backoff=FAST_BACKOFF)
    wait_until(lambda: sink.stats().connect_failures >= 2, what="retries")
    error = sink.stats().last_error or ""
    assert "serial unreadable: permission denied" in error and "Access denied" in error
    assert "udev rule" in error and "systemd/61-ghnerf-local.rules" in error
    board.access_denied = False  # the rule was added and udevadm trigger run: no restart needed
    assert sink.wait_connected(5)
    sink.close()


def test_a_board_whose_serial_read_fails_is_listed_and_the_other_still_chosen() -> None:
    first, second = two_boards()
    first.string_stall = True  # a firmware that stalls string requests
    send_frame_0(f"{URL}&serial=XYZ789", FakeBackend(first, second))
    assert joints_seqs(messages_of(second.take())) == [0] and first.take() == b""
    # and when it is the only one, the log says why its serial is not known
    sink = open_sink(f"{URL}&serial=ABC123", backend=FakeBackend(first), backoff=FAST_BACKOFF)
    wait_until(lambda: sink.stats().connect_failures >= 2, what="retries")
    stats = sink.close()
    assert "port 1-1.4 (serial unreadable: [Errno 32] Pipe error)" in (stats.last_error or "")


def test_two_boards_with_one_serial_are_not_guessed_between() -> None:
    first, second = two_boards()
    second.serial = first.serial  # flashed alike
    sink = open_sink(f"{URL}&serial=ABC123", backend=FakeBackend(first, second), backoff=FAST_BACKOFF)
    wait_until(lambda: sink.stats().connect_failures >= 2, what="retries")
    stats = sink.close()
    error = stats.last_error or ""
    assert "2 devices 1209:0001 have serial 'ABC123'" in error
    # each board's port path, as the option that takes it (the list of all boards found left the reader to build it)
    assert "choose one by port= in place of serial=: port=1-1.4 or port=1-2 (found: " in error, error
    assert "port 1-1.4 serial 'ABC123'; bus 1 address 9 port 1-2 serial 'ABC123'" in error
    assert not first.claimed and not second.claimed and first.open_handles == second.open_handles == 0
    # and the option named takes its board
    send_frame_0(f"{URL}&port=1-2", FakeBackend(first, second))
    assert joints_seqs(messages_of(second.take())) == [0] and first.take() == b""


def test_boards_with_one_serial_and_no_port_path_are_refused_saying_port_cannot_choose() -> None:
    # port= was offered where the backend reports no port path, so it could never match either board
    first, second = two_boards()
    second.serial = first.serial
    second.port_numbers = ()  # this libusb reports none for it
    sink = open_sink(f"{URL}&serial=ABC123", backend=FakeBackend(first, second), backoff=FAST_BACKOFF)
    wait_until(lambda: sink.stats().connect_failures >= 2, what="retries")
    error = sink.close().last_error or ""
    assert "port= cannot choose between them either: this libusb reports no port path for bus 1 address 9 port " \
           "unknown; give the boards serial numbers of their own" in error, error
    assert "choose one by port=" not in error


def test_without_a_selector_no_string_descriptor_is_read() -> None:
    # the default is unchanged: no serial read (which could fail on permissions), the first board taken
    first, second = two_boards()
    send_frame_0(URL, FakeBackend(first, second))
    assert first.string_reads == second.string_reads == 0
    assert joints_seqs(messages_of(first.take())) == [0] and second.take() == b""


def test_the_several_devices_warning_lists_ports_and_how_to_choose(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="firmware_host.sinks"):
        sink = open_sink(URL, backend=FakeBackend(*two_boards()), backoff=FAST_BACKOFF)
        assert sink.wait_connected(5)
        sink.close()
    [warning] = [r.getMessage() for r in caplog.records if "devices 1209:0001 found" in r.getMessage()]
    assert "bus 1 address 7 port 1-1.4, bus 1 address 9 port 1-2" in warning and "?port=" in warning


@pytest.mark.parametrize(("query", "field", "value"), [
    ("serial=ABC123&port=1-1.4", "port", "1-1.4"),  # which board would win?
    ("serial=", "serial", ""),
    ("serial=" + "A" * 127, "serial", "A" * 127),  # a string descriptor holds 126 characters
    ("serial=AB%00C", "serial", "AB\x00C"),
    ("port=", "port", ""),
    ("port=1", "port", "1"),  # a bus alone
    ("port=1-", "port", "1-"),
    ("port=1-1..4", "port", "1-1..4"),
    ("port=1-0", "port", "1-0"),  # ports are numbered from 1
    ("port=1-256", "port", "1-256"),
    ("port=256-1", "port", "256-1"),
    ("port=1-1.2.3.4.5.6.7.8", "port", "1-1.2.3.4.5.6.7.8"),  # deeper than USB allows
    ("port=1:1.4", "port", "1:1.4"),
    ("port=usb1/1-1.4", "port", "usb1/1-1.4"),
])
def test_a_bad_selector_is_refused_naming_option_and_value(query: str, field: str, value: str) -> None:
    from firmware_host.errors import SinkConfigError
    from firmware_host.sinks.usb_sink import UsbSink

    with pytest.raises(SinkConfigError) as info:
        UsbSink.from_url(f"usb://1209:0001?ep=0x01&{query}")
    assert (info.value.field, info.value.value) == (field, value)


def test_selectors_parse_and_may_come_as_keywords() -> None:
    from firmware_host.errors import SinkConfigError
    from firmware_host.sinks.usb_select import PortPath
    from firmware_host.sinks.usb_sink import UsbSink

    sink = UsbSink.from_url("usb://1209:0001?ep=0x01&port=3-1.2.7")
    assert (sink.port, sink.serial) == (PortPath(3, (1, 2, 7)), None) and str(sink.port) == "3-1.2.7"
    sink = UsbSink.from_url("usb://1209:0001?ep=0x01", serial="ab+c d")
    assert (sink.serial, sink.port) == ("ab+c d", None)
    assert UsbSink.from_url("usb://1209:0001?ep=0x01&serial=a%2Bb+c").serial == "a+b+c"  # '+' is a plus
    with pytest.raises(SinkConfigError) as info:
        UsbSink.from_url("usb://1209:0001?ep=0x01&serial=X", port="1-2")
    assert info.value.field == "port"
