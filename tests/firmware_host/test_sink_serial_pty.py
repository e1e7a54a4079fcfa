"""serial:// over a real pty pair, through pyserial.

The sink opens a symlink to the pty's /dev/pts/N slave, the way a real device
is reached through /dev/serial/by-id/...: closing the master is the unplug
(the slave node disappears and writes fail with EIO), and pointing the
symlink at a fresh pty is the replug.
"""
from __future__ import annotations

import logging
import os
import select
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from firmware_host.protocol import Flags, Hello, Joints, decode_stream
from firmware_host.sinks import open_sink
from tests.firmware_host.joint_stream_helpers import FAST_BACKOFF, joints_seqs, make_frame, messages_of, wait_until


class PtyPort:
    """One pty pair at ``link``; a thread drains the master into ``data``."""

    def __init__(self, link: Path) -> None:
        self.link = link
        self.master, slave = os.openpty()
        self.slave_name = os.ttyname(slave)
        os.close(slave)  # the sink opens it by name
        tmp = link.with_suffix(".tmp")
        os.symlink(self.slave_name, tmp)
        os.replace(tmp, link)  # atomic swap, like udev
        self._lock = threading.Lock()
        self._data = bytearray()
        self._stop = threading.Event()
        self._draining = threading.Event()
        self._draining.set()
        self._thread = threading.Thread(target=self._drain, daemon=True)
        self._thread.start()

    def _drain(self) -> None:
        while not self._stop.is_set():
            if not self._draining.wait(0.01):
                continue  # paused: the reader stalls, the pty's buffer fills
            ready, _, _ = select.select([self.master], [], [], 0.01)
            if ready:
                try:
                    chunk = os.read(self.master, 65536)
                except OSError:  # EIO while no slave is open
                    continue
                with self._lock:
                    self._data += chunk

    @property
    def data(self) -> bytes:
        with self._lock:
            return bytes(self._data)

    def pause(self) -> None:
        self._draining.clear()

    def resume(self) -> None:
        self._draining.set()

    def unplug(self) -> None:
        self._stop.set()
        self._thread.join()
        self.link.unlink()
        os.close(self.master)


@pytest.fixture
def link(tmp_path: Path) -> Path:
    return tmp_path / "ttyJOINTS"


def test_frames_arrive_in_order_after_hello(link: Path) -> None:
    port = PtyPort(link)
    # By its /dev/pts/N name here; the other tests go through the symlink.
    sink = open_sink(f"serial://{port.slave_name}?baud=921600&queue=32", backoff=FAST_BACKOFF, rig_id="bench-1")
    try:
        assert sink.wait_connected(5)
        for seq in range(20):
            sink.send(make_frame(seq))
        wait_until(lambda: len(joints_seqs(messages_of(port.data))) == 20, what="20 frames on the pty")
        msgs = messages_of(port.data)
        assert isinstance(msgs[0], Hello) and msgs[0].rig_id == "bench-1"
        assert port.data[0] == 0  # leading delimiter resynchronises the receiver
        assert joints_seqs(msgs) == list(range(20))
        assert all(m.header.flags == 0 for m in msgs if isinstance(m, Joints))
    finally:
        stats = sink.close()
        port.unplug()
    assert stats.sent == 20 and stats.dropped == 0


def test_low_baud_is_decimated_with_a_warning(link: Path, caplog: pytest.LogCaptureFixture) -> None:
    port = PtyPort(link)
    url = f"serial://{link}?baud=115200&fps=60&queue=200"
    with caplog.at_level(logging.WARNING, logger="firmware_host.sinks"):
        sink = open_sink(url, backoff=FAST_BACKOFF)
    assert any(url in r.getMessage() and "decimating" in r.getMessage() for r in caplog.records)
    capacity = sink.link_capacity_fps()
    assert 49 < capacity < 50  # 208 bytes per frame, 11520 bytes/s, 10 % headroom
    try:
        assert sink.wait_connected(5)
        for seq in range(120):  # two seconds of capture at 60 fps
            sink.send(make_frame(seq, period_us=16_667))
        assert sink.wait_drained(5)
        wait_until(lambda: len(joints_seqs(messages_of(port.data))) == sink.stats().sent, what="all sent frames")
    finally:
        stats = sink.close()
        port.unplug()
    joints = [m for m in messages_of(port.data) if isinstance(m, Joints)]
    span_s = (joints[-1].header.capture_us - joints[0].header.capture_us) / 1e6
    assert len(joints) <= capacity * span_s + 2  # never more than the UART carries
    assert stats.decimated == 120 - len(joints) and stats.dropped == 0
    # DECIMATED marks exactly the frames that follow a deliberate gap.
    for prev, m in zip(joints, joints[1:]):
        gap = m.header.seq - prev.header.seq > 1
        assert bool(m.header.flags & Flags.DECIMATED) == gap


def test_unplug_is_detected_retried_and_recovered(link: Path) -> None:
    port = PtyPort(link)
    sink = open_sink(f"serial://{link}?baud=921600&queue=16", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        for seq in range(10):
            sink.send(make_frame(seq))
        wait_until(lambda: len(joints_seqs(messages_of(port.data))) == 10, what="frames before unplug")
        before = port.data
        port.unplug()

        # Unplugged: the producer keeps sending, the sink notices, retries, and counts drops.
        for seq in range(10, 40):
            sink.send(make_frame(seq))
            if seq == 10:
                wait_until(lambda: sink.stats().disconnects == 1, what="unplug detected")
        wait_until(lambda: sink.stats().connect_failures >= 3, what="retries while the port is gone")
        s = sink.stats()
        assert not s.connected and s.dropped >= 30 - 16 and s.accounted == s.submitted

        port = PtyPort(link)  # replug: a new pty behind the same path
        wait_until(lambda: sink.stats().connected, what="reconnect")
        for seq in range(40, 50):
            sink.send(make_frame(seq))
        assert sink.wait_drained(5)
        wait_until(lambda: 40 in joints_seqs(messages_of(port.data)) and 49 in joints_seqs(messages_of(port.data)),
                   what="frames after replug")
        after = port.data
    finally:
        stats = sink.close()
        port.unplug()

    assert after[0] == 0 and isinstance(messages_of(after)[0], Hello)  # resync + HELLO on the new link
    received = joints_seqs(messages_of(before)) + joints_seqs(messages_of(after))
    assert received == sorted(received) and received[-1] == 49
    # Nothing is lost silently: every gap in the sequence is a counted drop.
    assert len(received) == stats.sent
    assert 50 - len(received) == stats.dropped
    assert stats.disconnects == 1 and stats.connects == 2
    first_after = next(m for m in messages_of(after) if isinstance(m, Joints))
    assert first_after.header.flags & Flags.DROPPED


def test_missing_port_keeps_retrying_without_blocking(tmp_path: Path) -> None:
    sink = open_sink(f"serial://{tmp_path}/nothing-here?baud=115200&queue=2", backoff=FAST_BACKOFF)
    for seq in range(50):
        sink.send(make_frame(seq))  # returns at once although there is no port
    wait_until(lambda: sink.stats().connect_failures >= 2, what="retries")
    s = sink.close()
    assert s.sent == 0 and s.dropped == 50
    assert "nothing-here" in (s.last_error or "")


def count_writes_to(monkeypatch: pytest.MonkeyPatch, device: str) -> list[int]:
    """Count ``os.write`` calls on file descriptors open on ``device`` (pyserial's and the sink's)."""
    calls = [0]
    real_write = os.write
    targets: dict[int, bool] = {}

    def counting_write(fd: int, data: bytes) -> int:
        if fd not in targets:
            try:
                targets[fd] = os.readlink(f"/proc/self/fd/{fd}") == device
            except OSError:
                targets[fd] = False
        if targets[fd]:
            calls[0] += 1
        return real_write(fd, data)

    monkeypatch.setattr(os, "write", counting_write)
    return calls


def test_a_stalled_reader_costs_no_busy_loop_and_sent_is_what_arrives(
        link: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    port = PtyPort(link)
    writes = count_writes_to(monkeypatch, port.slave_name)
    # status_s: only JOINTS per frame, so every frame is one packet on the wire
    sink = open_sink(f"serial://{link}?baud=921600&queue=4&write_timeout_ms=40&status_s=3600",
                     backoff=FAST_BACKOFF)
    seq = 0

    def send_for(seconds: float) -> None:
        nonlocal seq
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            sink.send(make_frame(seq))
            seq += 1
            time.sleep(0.005)

    try:
        assert sink.wait_connected(5)
        port.pause()  # the receiver stops reading: the pty's buffer (some kB) fills, then every write waits
        deadline = time.monotonic() + 10
        while sink.stats().dropped_error < 3 and time.monotonic() < deadline:
            send_for(0.05)
        assert sink.stats().dropped_error >= 3, "the stall never showed"
        before, tried_before = writes[0], sink.stats().sent + sink.stats().dropped_error
        send_for(0.5)  # stalled throughout
        tried = sink.stats().sent + sink.stats().dropped_error - tried_before
        # Each frame waits for room (select), it does not retry the write in a loop until the timeout.
        assert writes[0] - before <= 3 * tried + 5, (writes[0] - before, tried)
        port.resume()
        send_for(0.2)
        assert sink.wait_drained(5)
        wait_until(lambda: len(received_joints(port.data)) >= sink.stats().sent, what="the sent frames")
    finally:
        stats = sink.close()
        port.unplug()
    joints = received_joints(port.data)
    assert stats.dropped_error >= 3 and stats.accounted == stats.submitted
    # A frame counted as sent arrived, and a frame counted as dropped did not.
    assert len(joints) == stats.sent
    assert [m.header.seq for m in joints] == sorted(m.header.seq for m in joints)


def received_joints(data: bytes) -> list[Joints]:
    """The JOINTS packets decoded; frames cut by a write timeout are skipped as decode errors."""
    events, _ = decode_stream(data)
    return [e.message for e in events if isinstance(e.message, Joints)]


@pytest.mark.parametrize("short_by, delivered", [
    ("joints", False),  # the JOINTS packet cut: the frame is lost, the receiver drops the fragment
    ("joints_delimiter", True),  # all but its 0x00, which the next write's leading delimiter supplies
    ("status", True),  # only the trailing HELLO + STATUS cut: the frame is out
])
def test_what_a_cut_write_counts_as_delivered(monkeypatch: pytest.MonkeyPatch, short_by: str, delivered: bool) -> None:
    from firmware_host.errors import SinkWriteError
    from firmware_host.protocol.encoder import encode
    from firmware_host.protocol.from_frame import joints_message
    from firmware_host.sinks.serial_sink import SerialSink

    sink = SerialSink.from_url("serial:///dev/ttyGHNERF-unused?baud=921600")  # never started: no port
    sink._resync = False
    messages = [joints_message(make_frame(0), 1, 0), sink._hello(1), sink._status(1)[0]]
    joints_len = len(encode(messages[0]))
    out = {"joints": joints_len - 2, "joints_delimiter": joints_len - 1, "status": joints_len + 5}[short_by]
    monkeypatch.setattr(sink, "_write_within", lambda data, timeout_s: out)
    if delivered:
        assert sink._write_messages(messages) is False  # delivered, but its STATUS is owed
    else:
        with pytest.raises(SinkWriteError, match="timed out"):
            sink._write_messages(messages)
    assert sink._resync  # either way the next write starts with 0x00


def test_a_write_cut_in_its_2d_joints_sends_the_frame_in_part(monkeypatch: pytest.MonkeyPatch) -> None:
    """send_2d=1: the JOINTS packet out, the first JOINTS_2D cut. The receiver decodes the frame's seq and 3D joints
    (the next write's 0x00 ends the cut packet): it was counted dropped, and the next frame said DROPPED with no
    seq missing. Now the frame is sent in part (SinkPartialWriteError), as udp:// sends it."""
    import numpy as np

    from firmware_host.errors import SinkPartialWriteError
    from firmware_host.protocol.encoder import encode
    from firmware_host.protocol.from_frame import joints2d_messages, joints_message
    from firmware_host.sinks.serial_sink import SerialSink

    sink = SerialSink.from_url("serial:///dev/ttyGHNERF-unused?baud=921600&send_2d=1&cameras=left,right")
    sink._resync = False
    frame = make_frame(0, joints_2d={"left": np.full((25, 3), 10.0), "right": np.full((25, 3), 20.0)})
    messages = [joints_message(frame, 1, 0), *joints2d_messages(frame, 1, ("left", "right"), 0)]
    assert len(messages) == 3
    monkeypatch.setattr(sink, "_write_within", lambda data, timeout_s: len(encode(messages[0])) + 4)
    with pytest.raises(SinkPartialWriteError, match=r"timed out .*\(after 1 of the frame's 3 packets went out\)"):
        sink._write_messages(messages)
    assert sink._resync  # the next write's 0x00 ends the cut JOINTS_2D


def test_a_status_cut_off_a_delivered_frame_is_owed_by_the_next(monkeypatch: pytest.MonkeyPatch) -> None:
    # the frame counted as out, so the STATUS behind it counted as out too: its latched fault was lost
    from firmware_host.protocol import Fault, Status
    from firmware_host.protocol.encoder import encode
    from firmware_host.protocol.from_frame import joints_message
    from firmware_host.sinks.serial_sink import SerialSink

    sink = SerialSink.from_url("serial:///dev/ttyGHNERF-unused?baud=921600", clock_us=lambda: 5_000_000)
    cut_at = len(encode(joints_message(make_frame(0), 1, 0))) + 6  # 0x00, the JOINTS packet, part of HELLO
    writes: list[bytes] = []

    def write_within(data: bytes, timeout_s: float) -> int:
        writes.append(bytes(data))
        return cut_at if len(writes) == 1 else len(data)

    monkeypatch.setattr(sink, "_write_within", write_within)
    sink.set_fault(Fault.CAMERA_FAULT)
    sink.set_fault(Fault.OK)
    sink._deliver(make_frame(0), 0)  # with HELLO + STATUS (the first), cut
    sink._deliver(make_frame(1), 0)  # the clock stands still: no STATUS due but the owed one
    statuses = [m for m in messages_of(writes[1]) if isinstance(m, Status)]
    assert [st.fault for st in statuses] == [Fault.CAMERA_FAULT]


def test_write_bytes_cut_short_makes_the_next_write_start_a_new_frame(monkeypatch: pytest.MonkeyPatch) -> None:
    """``_write_bytes`` keeps the framing like ``_write_messages``: after a partial write the next write
    begins with a 0x00 (the receiver drops the cut frame), and a write that did go out does not."""
    from firmware_host.errors import SinkWriteError
    from firmware_host.protocol import encode
    from firmware_host.protocol.from_frame import joints_message
    from firmware_host.sinks.serial_sink import SerialSink

    sink = SerialSink.from_url("serial:///dev/null-never-opened")
    writes: list[bytes] = []
    limit = [5]  # bytes the port takes per write

    def write_within(data: bytes, timeout_s: float) -> int:
        writes.append(bytes(data))
        return min(limit[0], len(data))

    monkeypatch.setattr(sink, "_write_within", write_within)
    packet = encode(joints_message(make_frame(0), 0, 0))
    sink._resync = False
    with pytest.raises(SinkWriteError):
        sink._write_bytes(packet)  # cut after 5 bytes
    limit[0] = 10**6
    sink._write_bytes(packet)
    sink._write_bytes(packet)
    assert writes == [packet, b"\x00" + packet, packet]


class _PortQueue:
    """Stands in for the tty's output queue (TIOCOUTQ) of a port that holds ``stuck`` bytes: a pty's
    queue reads 0, a USB CDC port whose receiver stopped reading keeps its bytes until flushed."""

    def __init__(self, stuck: int, drains_after_polls: int | None = None) -> None:
        self.stuck, self.polls, self.drains_after_polls = stuck, 0, drains_after_polls
        self.calls: list[str] = []

    def out_waiting(self) -> int:
        self.polls += 1
        if self.drains_after_polls is not None and self.polls > self.drains_after_polls:
            self.stuck = 0
        return self.stuck


def _patch_port_queue(monkeypatch: pytest.MonkeyPatch, queue: _PortQueue) -> None:
    import serial

    real_reset, real_close = serial.Serial.reset_output_buffer, serial.Serial.close

    def reset_output_buffer(self: serial.Serial) -> None:
        queue.calls.append("discard")
        queue.stuck = 0
        real_reset(self)

    def close(self: serial.Serial) -> None:
        if self.is_open:
            queue.calls.append("close")
        real_close(self)

    monkeypatch.setattr(serial.Serial, "out_waiting", property(lambda self: queue.out_waiting()))
    monkeypatch.setattr(serial.Serial, "reset_output_buffer", reset_output_buffer)
    monkeypatch.setattr(serial.Serial, "close", close)


def test_closing_a_port_whose_queue_does_not_drain_discards_it_before_the_close(
        link: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # The kernel's close of such a port (/dev/ttyACM* with the receiver stalled) waits for the queue up to
    # closing_wait (30 s), past TimeoutStopSec=20: the queue is given CLOSE_DRAIN_S, then discarded.
    from firmware_host.sinks.serial_sink import CLOSE_DRAIN_S

    port = PtyPort(link)
    queue = _PortQueue(stuck=4096)
    _patch_port_queue(monkeypatch, queue)
    sink = open_sink(f"serial://{link}?baud=921600", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        sink.send(make_frame(0))
        assert sink.wait_drained(5)
        t0 = time.monotonic()
        sink.close()
        took = time.monotonic() - t0
    finally:
        port.unplug()
    assert queue.calls == ["discard", "close"]
    assert CLOSE_DRAIN_S <= took < CLOSE_DRAIN_S + 1.0, took


def test_closing_a_port_whose_queue_drains_in_time_discards_nothing(
        link: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    port = PtyPort(link)
    queue = _PortQueue(stuck=300, drains_after_polls=3)  # a frame still on the wire, gone in ~30 ms
    _patch_port_queue(monkeypatch, queue)
    sink = open_sink(f"serial://{link}?baud=921600&queue=32&status_s=3600", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        for seq in range(5):
            sink.send(make_frame(seq))
        assert sink.wait_drained(5)
        wait_until(lambda: len(received_joints(port.data)) == 5, what="the five frames")
        stats = sink.close()
    finally:
        port.unplug()
    assert queue.calls == ["close"] and queue.polls >= 4
    assert stats.sent == 5


def test_closing_an_unplugged_port_does_not_wait_for_its_queue() -> None:
    # After an unplug the port's ioctls fail (EIO): nothing is left to send, the close is immediate.
    from firmware_host.sinks.serial_sink import _drain_then_discard
    import serial

    master, slave = os.openpty()
    ser = serial.Serial(os.ttyname(slave), 921600)
    os.close(slave)
    os.close(master)  # the unplug
    t0 = time.monotonic()
    try:
        assert _drain_then_discard(ser, 5.0)
    finally:
        ser.close()
    assert time.monotonic() - t0 < 1.0


def test_a_receiver_that_stops_reading_makes_the_port_read_stalled_then_up(link: Path) -> None:
    # Every frame timing out showed only in dropped_error and last_error: the state read "up"
    port = PtyPort(link)
    sink = open_sink(f"serial://{link}?baud=921600&queue=4&write_timeout_ms=20&status_s=3600&stall_s=0.2",
                     backoff=FAST_BACKOFF)
    seq = 0

    def send_then(state: str) -> bool:
        nonlocal seq
        sink.send(make_frame(seq))
        seq += 1
        time.sleep(0.005)
        return sink.stats().state == state

    try:
        assert sink.wait_connected(5)
        port.pause()
        wait_until(lambda: send_then("stalled"), timeout=10, what="stalled once the pty's buffer is full")
        s = sink.stats()
        assert s.connected and s.stalled_s is not None and s.stalled_s >= 0.2
        assert "the peer is not reading" in (s.last_error or "")
        port.resume()
        wait_until(lambda: send_then("up"), timeout=10, what="up once the receiver reads again")
        assert sink.stats().stalled_s is None
    finally:
        sink.close()
        port.unplug()


HOLD_LOCK = """
import fcntl, os, sys, time
fd = os.open(sys.argv[1], os.O_RDWR | os.O_NOCTTY)
fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # what another sink's pyserial exclusive=True takes
print("held", flush=True)
time.sleep(60)
"""


def test_a_port_another_process_holds_names_that_process_and_the_node_the_link_leads_to(link: Path) -> None:
    """pyserial said only "Could not exclusively lock port ...: Resource temporarily unavailable", retried for ever:
    the message now says another writer holds the port, which one, and where a by-id link leads."""
    port = PtyPort(link)
    holder = subprocess.Popen([sys.executable, "-c", HOLD_LOCK, port.slave_name], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        sink = open_sink(f"serial://{link}?baud=921600", backoff=FAST_BACKOFF)
        sink.send(make_frame(0))
        wait_until(lambda: sink.stats().connect_failures >= 1, what="a refused open")
        said = sink.stats().last_error or ""
        assert f"cannot open {link} (which is {port.slave_name}): pid {holder.pid}" in said
        assert "holds its exclusive lock: one writer per port" in said
    finally:
        holder.kill()
        holder.wait()
    wait_until(lambda: sink.stats().connects >= 1, what="the open once the holder let go")
    sink.close()
    port.unplug()
