"""usb:// through pyusb's real code on a fake IBackend (see fake_usb_backend for what it models)."""
from __future__ import annotations

import logging

import pytest
import usb.core

from firmware_host.protocol import Flags, Hello, Joints, decode_stream
from firmware_host.sinks import open_sink
from tests.firmware_host.fake_usb_backend import FakeBackend, FakeDevice
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


def test_stalled_endpoint_is_cleared_and_the_frame_counted() -> None:
    device = FakeDevice()
    sink = open_sink(URL, backend=FakeBackend(device), backoff=FAST_BACKOFF)
    assert sink.wait_connected(5)
    sink.send(make_frame(0))
    assert sink.wait_drained(5)
    device.stalled = True
    sink.send(make_frame(1))  # hits the stall
    assert sink.wait_drained(5)
    sink.send(make_frame(2))
    assert sink.wait_drained(5)
    stats = sink.close()
    assert device.halts_cleared == 1 and not device.stalled
    assert stats.dropped_error == 1 and stats.disconnects == 0 and stats.sent == 2
    assert "stalled" in (stats.last_error or "")
    joints = [m for m in messages_of(device.take()) if isinstance(m, Joints)]
    assert [m.header.seq for m in joints] == [0, 2]
    assert joints[1].header.flags & Flags.DROPPED


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
