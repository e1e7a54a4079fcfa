"""udp:// on 127.0.0.1, file:// JSON lines, memory:// buffer."""
from __future__ import annotations

import errno
import json
import socket
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from firmware_host.errors import SinkConfigError, SinkUnavailableError
from firmware_host.protocol import Fault, Hello, Joints, Joints2D, StreamDecoder
from firmware_host.protocol.from_frame import camera_index, is_announced
from firmware_host.protocol.messages import Status
from firmware_host.sinks import open_sink
from firmware_host.sinks.memory_sink import MemorySink
from tests.firmware_host.joint_stream_helpers import (
    FAST_BACKOFF,
    FRAME_US,
    joints_seqs,
    make_frame,
    messages_of,
    wait_until,
)


def test_udp_one_packet_per_datagram() -> None:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(5)
    port = rx.getsockname()[1]
    sink = open_sink(f"udp://127.0.0.1:{port}?queue=16&send_2d=1", backoff=FAST_BACKOFF,
                     cameras=("left", "right"))
    try:
        assert sink.wait_connected(5)
        for seq in range(5):
            sink.send(make_frame(seq, joints_2d={"left": np.full((25, 3), 10.0), "right": np.full((25, 3), 20.0)}))
        datagrams = []
        while sum(1 for d in datagrams if isinstance(d, Joints)) < 5:
            data = rx.recv(2048)
            d = StreamDecoder()
            events = d.feed(data)
            assert len(events) == 1 and data.endswith(b"\x00")  # exactly one framed packet
            datagrams.append(events[0].message)
    finally:
        stats = sink.close()
        rx.close()
    assert isinstance(datagrams[0], Hello) and isinstance(datagrams[1], Status)
    assert joints_seqs(datagrams) == list(range(5))
    cams = [(m.header.seq, m.camera) for m in datagrams if isinstance(m, Joints2D)]
    assert cams[:2] == [(0, 0), (0, 1)]
    assert stats.sent == 5


def test_udp_to_a_broadcast_address() -> None:
    # the loopback net's broadcast address: without SO_BROADCAST the kernel refused every datagram
    # (EACCES) and the sink reconnected forever, sending nothing
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("0.0.0.0", 0))
    rx.settimeout(5)
    port = rx.getsockname()[1]
    sink = open_sink(f"udp://127.255.255.255:{port}?queue=16", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        sink.send(make_frame(0))
        received = []
        while not any(isinstance(m, Joints) for m in received):
            received += [e.message for e in StreamDecoder().feed(rx.recv(2048))]
    finally:
        stats = sink.close()
        rx.close()
    assert isinstance(received[0], Hello) and joints_seqs(received) == [0]
    assert stats.sent == 1 and stats.connect_failures == 0 and stats.disconnects == 0


@pytest.mark.parametrize("host", ["127.0.0.1", "[::1]"])
def test_udp_to_a_port_nobody_listens_on_keeps_sending(host: str) -> None:
    # Each datagram draws an ICMP port unreachable, which the next send on the sink's connected socket reports
    # (ECONNREFUSED) and fails unsent: the sink sends that datagram again, so the receiver that is not up yet
    # costs no frame and no reconnect (it reads stalled: test_sink_udp_refused.py).
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    probe = socket.socket(family, socket.SOCK_DGRAM)
    probe.bind(("::1" if ":" in host else "127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()  # the port is now closed
    sink = open_sink(f"udp://{host}:{port}?queue=64&status_s=0.01", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        for seq in range(20):
            sink.send(make_frame(seq))
            time.sleep(0.002)
        assert sink.wait_drained(5)
    finally:
        stats = sink.close()
    assert stats.sent == 20 and stats.dropped == 0 and stats.disconnects == 0 and stats.connect_failures == 0


def test_file_sink_writes_canonical_json_lines(tmp_path: Path) -> None:
    path = tmp_path / "joints.jsonl"
    sink = open_sink(f"file://{path}", backoff=FAST_BACKOFF, rig_id="rec")
    assert sink.wait_connected(5)
    for seq in range(3):
        sink.send(make_frame(seq))
    assert sink.wait_drained(5)
    sink.close()
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert [ln["type"] for ln in lines[:2]] == ["HELLO", "STATUS"] and lines[0]["rig_id"] == "rec"
    joints = [ln for ln in lines if ln["type"] == "JOINTS"]
    assert [j["seq"] for j in joints] == [0, 1, 2]
    # The same canonical form the decoders and vectors use: mm integers and 0..255 confidence.
    mem = open_sink("memory://", backoff=FAST_BACKOFF)
    mem.send(make_frame(0))
    assert mem.wait_drained(5)
    mem.close()
    wire = next(m for m in messages_of(mem.read()) if isinstance(m, Joints))
    assert {k: v for k, v in joints[0].items() if k != "send_us"} == {
        k: v for k, v in wire.to_json().items() if k != "send_us"
    }


def test_file_sink_reopens_after_the_file_goes_away(tmp_path: Path) -> None:
    folder = tmp_path / "usb-stick"
    sink = open_sink(f"file://{folder}/joints.jsonl", backoff=FAST_BACKOFF)
    wait_until(lambda: sink.stats().connect_failures >= 2, what="retries while the folder is missing")
    folder.mkdir()
    assert sink.wait_connected(5)
    sink.send(make_frame(0))
    assert sink.wait_drained(5)
    sink.close()
    assert '"seq":0' in (folder / "joints.jsonl").read_text()


def test_file_sink_whose_folder_is_removed_mid_run_is_down_then_writes_the_new_file(tmp_path: Path) -> None:
    # The open descriptor kept writing into the removed file's inode: 'up', every frame counted 'sent', nothing on
    # any disk, and nothing written once the folder came back (a USB stick's mount point removed and remade).
    import shutil

    folder = tmp_path / "usb-stick"
    folder.mkdir()
    path = folder / "joints.jsonl"
    sink = open_sink(path.as_uri() + "?status_s=3600", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        sink.send(make_frame(0))
        assert sink.wait_drained(5)
        shutil.rmtree(folder)
        sink.send(make_frame(1))
        wait_until(lambda: sink.stats().state == "down", what="the sink down once its file is gone")
        stats = sink.stats()
        assert stats.sent == 1 and stats.dropped_error == 1
        assert "removed or replaced" in (stats.last_error or "") or "No such file" in (stats.last_error or "")
        folder.mkdir()
        assert sink.wait_connected(5)
        sink.send(make_frame(2))
        assert sink.wait_drained(5)
    finally:
        sink.close()
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert [ln["type"] for ln in lines] == ["HELLO", "STATUS", "JOINTS"] and lines[2]["seq"] == 2
    assert lines[2]["flags"] & 0x02  # DROPPED: the frame the removed file swallowed is a gap the reader sees


def test_file_sink_follows_its_path_when_the_file_is_renamed_away(tmp_path: Path) -> None:
    # logrotate without copytruncate renames the file: the next lines go to a new file at the path, not the old one
    path = tmp_path / "joints.jsonl"
    sink = open_sink(path.as_uri() + "?status_s=3600", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        sink.send(make_frame(0))
        assert sink.wait_drained(5)
        path.rename(tmp_path / "joints.jsonl.1")
        sink.send(make_frame(1))
        wait_until(lambda: sink.stats().connects == 2, what="the new file opened")
        sink.send(make_frame(2))
        assert sink.wait_drained(5)
    finally:
        sink.close()
    old = [json.loads(line) for line in (tmp_path / "joints.jsonl.1").read_text().splitlines()]
    new = [json.loads(line) for line in path.read_text().splitlines()]
    assert [ln.get("seq") for ln in old if ln["type"] == "JOINTS"] == [0]
    assert [ln["type"] for ln in new][:2] == ["HELLO", "STATUS"]
    assert [ln.get("seq") for ln in new if ln["type"] == "JOINTS"][-1] == 2


def test_file_sink_on_a_read_only_path_says_how_the_service_may_write_there(tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """The unit's ProtectSystem=strict makes every folder but /run/ghnerf and /var/lib/ghnerf read-only, which
    --validate-config (outside the sandbox) cannot see: docs/daemon.md promises the failed write names the fix,
    but the sink said only "Read-only file system", as for a read-only medium."""
    import firmware_host.sinks.file_sink as file_sink
    from firmware_host.service_unit import read_only_hint
    path = tmp_path / "joints.jsonl"

    def read_only(name: Any, *args: Any, **kwargs: Any) -> Any:
        if str(name) == str(path):
            raise OSError(errno.EROFS, "Read-only file system", str(name))
        return open(name, *args, **kwargs)

    monkeypatch.setattr(file_sink, "open", read_only, raising=False)
    sink = open_sink(path.as_uri(), backoff=FAST_BACKOFF)
    try:
        wait_until(lambda: sink.stats().connect_failures >= 1, what="a failed open")
        error = sink.stats().last_error or ""
    finally:
        sink.close()
    assert f"cannot open {path}" in error and "Read-only file system" in error
    assert error.endswith(read_only_hint(OSError(errno.EROFS, "")))  # worded as the status file's (service_unit)
    assert "ReadWritePaths= in systemctl edit ghnerf" in error
    monkeypatch.undo()
    blocked = tmp_path / "not-a-folder"
    blocked.write_text("")
    sink = open_sink((blocked / "joints.jsonl").as_uri(), backoff=FAST_BACKOFF)  # ENOTDIR: no sandbox hint
    try:
        wait_until(lambda: sink.stats().connect_failures >= 1, what="a failed open")
        error = sink.stats().last_error or ""
        assert "cannot open" in error and "ReadWritePaths" not in error
    finally:
        sink.close()


class _CutShort:
    """``write_within`` whose next call stops half way through its data with ENOSPC, as on a full disk."""

    def __init__(self, real: Any) -> None:
        self.real = real
        self.armed = False

    def __call__(self, fd: int, data: bytes, timeout_s: float) -> int:
        if not self.armed:
            return self.real(fd, data, timeout_s)
        self.armed = False
        self.real(fd, data[: len(data) // 2], timeout_s)
        raise OSError(errno.ENOSPC, "No space left on device")


def test_file_sink_ends_a_line_a_failed_write_cut_short(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # the reopened file's HELLO went on the end of the half line: one unparsable line of both
    from firmware_host.sinks import file_sink

    cut = _CutShort(file_sink.write_within)
    monkeypatch.setattr(file_sink, "write_within", cut)
    path = tmp_path / "joints.jsonl"
    sink = open_sink(path.as_uri() + "?status_s=3600", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        sink.send(make_frame(0))
        assert sink.wait_drained(5)
        cut.armed = True  # idle: no STATUS due for an hour
        sink.send(make_frame(1))
        wait_until(lambda: sink.stats().connects == 2, what="the file reopened")
        sink.send(make_frame(2))
        assert sink.wait_drained(5)
    finally:
        sink.close()
    types = []
    for line in path.read_text().splitlines():
        try:
            types.append(json.loads(line)["type"])
        except json.JSONDecodeError:
            types.append("cut")
    assert types == ["HELLO", "STATUS", "JOINTS", "cut", "HELLO", "STATUS", "JOINTS"]


def test_file_sink_write_cut_in_its_2d_joints_sends_the_frame_in_part(tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """A pipe's reader that stops taking lines in frame 0's first JOINTS_2D line (send_2d=1) has its JOINTS line:
    frame 0 was counted dropped, and frame 1's JOINTS said DROPPED with no seq missing. Now it counts as sent and
    partial, as a udp:// frame whose JOINTS_2D met a full buffer. (A regular file stands in for the pipe: the
    write is cut as a timeout cuts it, without an error.)"""
    from firmware_host.protocol.constants import Flags
    from firmware_host.sinks import file_sink

    real = file_sink.write_within
    cuts: list[int] = []

    def write_within(fd: int, data: bytes, timeout_s: float) -> int:
        if cuts or b'"type":"JOINTS"' not in data[:data.index(b"\n")]:
            return real(fd, data, timeout_s)
        cuts.append(data.index(b"\n") + 6)  # the JOINTS line and 5 bytes of the first JOINTS_2D line
        return real(fd, data[:cuts[0]], timeout_s)

    monkeypatch.setattr(file_sink, "write_within", write_within)
    path = tmp_path / "joints.jsonl"
    two_d = {"left": np.full((25, 3), 10.0), "right": np.full((25, 3), 20.0)}
    sink = open_sink(path.as_uri() + "?status_s=3600&send_2d=1", backoff=FAST_BACKOFF, cameras=("left", "right"))
    try:
        assert sink.wait_connected(30)
        sink.send(make_frame(0, joints_2d=two_d))
        sink.send(make_frame(1, joints_2d=two_d))
        assert sink.wait_drained(30)
        stats = sink.stats()
    finally:
        sink.close()
    assert cuts
    assert (stats.sent, stats.partial, stats.dropped_error) == (2, 1, 0), stats
    assert "(after 1 of the frame's 3 packets went out)" in (stats.last_error or "")
    records = []
    for line in path.read_text().splitlines():
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            records.append({"type": "cut"})
    assert [r["type"] for r in records] == ["HELLO", "STATUS", "JOINTS", "cut", "JOINTS", "JOINTS_2D", "JOINTS_2D"]
    assert [r["seq"] for r in records if r["type"] == "JOINTS"] == [0, 1]
    assert not records[4]["flags"] & Flags.DROPPED  # no seq is missing: the flag must not say one is


def test_file_sink_writes_at_the_start_of_a_file_truncated_under_it(tmp_path: Path) -> None:
    # logrotate's copytruncate, as docs/protocol.md advises: no hole of NULs before the next line
    path = tmp_path / "joints.jsonl"
    sink = open_sink(path.as_uri() + "?status_s=3600", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        sink.send(make_frame(0))
        assert sink.wait_drained(5)
        path.write_bytes(b"")  # truncated, the file itself kept
        sink.send(make_frame(1))
        assert sink.wait_drained(5)
    finally:
        sink.close()
    assert [json.loads(line)["seq"] for line in path.read_text().splitlines()] == [1]


def test_file_sink_writes_into_a_fifo(tmp_path: Path) -> None:
    # file:///dev/stdout or a named pipe: nothing to read back for a cut line, and no error for trying
    import os
    import threading

    fifo = tmp_path / "joints.fifo"
    os.mkfifo(fifo)
    lines: list[str] = []

    def read() -> None:
        with open(fifo, encoding="utf-8") as f:
            lines.extend(line for _, line in zip(range(3), f))

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    sink = open_sink(fifo.as_uri() + "?status_s=3600", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        sink.send(make_frame(0))
        assert sink.wait_drained(5)
        reader.join(5)
    finally:
        sink.close()
    assert [json.loads(line)["type"] for line in lines] == ["HELLO", "STATUS", "JOINTS"]


def test_file_sink_into_a_fifo_without_a_reader_is_down_and_never_holds_its_worker(tmp_path: Path) -> None:
    # open() of a named pipe waits for a reader: the worker waited there for ever, the sink said "connecting" (not
    # "down") in the status file, and close() left that thread behind
    import os

    fifo = tmp_path / "joints.fifo"
    os.mkfifo(fifo)
    sink = open_sink(fifo.as_uri() + "?status_s=3600", backoff=FAST_BACKOFF)
    try:
        wait_until(lambda: sink.stats().state == "down", what="a pipe without a reader reported down")
        assert "a named pipe with no reader" in (sink.stats().last_error or "")

        with open(fifo, encoding="utf-8") as reader:  # a reader comes: the retry opens the pipe
            assert sink.wait_connected(5)
            assert json.loads(reader.readline())["type"] == "HELLO"

        def down_after_a_frame() -> bool:  # ... and goes: a write meets EPIPE, and the sink is down again
            sink.send(make_frame(0))
            return sink.stats().state == "down"

        wait_until(down_after_a_frame, what="down once the reader went")
        assert sink.stats().disconnects == 1
    finally:
        stats = sink.close(1.0)
        unblock = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)  # frees a worker stuck in open() (the old code's)
        os.close(unblock)
    assert stats.state == "closed" and not sink._thread.is_alive()


@pytest.mark.parametrize(("written", "opened"), [
    ("file://{folder}/my%20run%232/joints.jsonl", "my run#2/joints.jsonl"),  # Path.as_uri() quotes so
    ("file://localhost{folder}/joints.jsonl", "joints.jsonl"),  # RFC 8089: the local host, an absolute path
])
def test_file_urls_name_the_local_path(tmp_path: Path, written: str, opened: str) -> None:
    (tmp_path / "my run#2").mkdir()
    sink = open_sink(written.format(folder=tmp_path), backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
    finally:
        sink.close()
    assert json.loads((tmp_path / opened).read_text().splitlines()[0])["type"] == "HELLO"


def test_memory_sink_bounded_buffer_counts_overflow() -> None:
    sink = open_sink("memory://?max_bytes=1000&queue=16", backoff=FAST_BACKOFF)
    assert sink.wait_connected(5)
    for seq in range(6):  # HELLO+STATUS ~100 bytes, then 208 per frame: 4 fit
        sink.send(make_frame(seq))
    assert sink.wait_drained(5)
    stats = sink.close()
    assert stats.sent == 4 and stats.dropped_error == 2 and "buffer full" in (stats.last_error or "")
    assert joints_seqs(messages_of(sink.read())) == [0, 1, 2, 3]


def test_status_reports_drops_to_the_receiver() -> None:
    t = [0]

    def clock() -> int:  # a controllable clock: each call advances 0.4 s
        t[0] += 400_000
        return t[0]

    sink = open_sink("memory://?queue=1&status_s=1", backoff=FAST_BACKOFF, clock_us=clock)
    assert sink.wait_connected(5)
    for seq in range(20):  # a burst into a queue of one: most are dropped
        sink.send(make_frame(seq))
    assert sink.wait_drained(5)
    for seq in range(20, 25):  # then a calm stream, long enough for a STATUS to fall due
        sink.send(make_frame(seq))
        assert sink.wait_drained(5)
    stats = sink.close()
    statuses = [m for m in messages_of(sink.read()) if isinstance(m, Status)]
    assert stats.dropped > 0 and statuses[-1].dropped == stats.dropped
    # The first STATUS after the drops names the cause; later ones are back to OK.
    first = next(st for st in statuses if st.dropped > 0)
    assert first.fault == Fault.QUEUE_OVERFLOW and statuses[-1].fault == Fault.OK


def test_status_after_a_frame_captured_at_time_0_carries_that_time() -> None:
    """Capture time 0 is a time (a test clock, a recording whose clock starts at 0), not "no frame yet": the
    STATUS after such a frame said capture_us = now and latency 0, as before any frame."""
    t = [0]

    def clock() -> int:  # each call advances 0.4 s: every STATUS is due by the next write
        t[0] += 400_000
        return t[0]

    sink = open_sink("memory://?status_s=0.01", backoff=FAST_BACKOFF, clock_us=clock)
    assert sink.wait_connected(5)
    sink.send(make_frame(0, t0_us=0))
    assert sink.wait_drained(5)
    sink.close()
    messages = messages_of(sink.read())
    (frame,) = [i for i, m in enumerate(messages) if isinstance(m, Joints)]
    assert messages[frame].header.capture_us == 0
    after = [m for m in messages[frame:] if isinstance(m, Status)]
    assert after, "no STATUS after the frame"
    for status in after:
        assert status.header.capture_us == 0 and status.latency_us == status.header.send_us > 0


def test_status_and_hello_keep_coming_while_no_frame_does() -> None:
    """A stalled estimator is when the receiver most needs STATUS (its fault) and HELLO (a late joiner)."""
    sink = open_sink("memory://?status_s=0.05", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        sink.send(make_frame(0))
        assert sink.wait_drained(5)
        sink.read()  # the connect's HELLO + STATUS and frame 0's JOINTS
        sink.set_fault(Fault.ESTIMATOR_STALLED)  # then no frame at all
        got: list = []

        def stalled_status_seen() -> bool:
            got.extend(messages_of(sink.read()))
            return any(isinstance(m, Status) and m.fault == Fault.ESTIMATOR_STALLED for m in got)

        wait_until(stalled_status_seen, what="a STATUS with the fault while no frame comes")
        hellos = [m for m in got if isinstance(m, Hello)]
        assert hellos and not any(isinstance(m, Joints) for m in got)
    finally:
        stats = sink.close()
    assert stats.sent == 1 and stats.accounted == stats.submitted


def test_a_fault_that_clears_before_the_next_status_is_still_reported_once() -> None:
    # a camera that vanished and came back between two STATUS packets was never seen by the receiver
    sink = open_sink("memory://?status_s=0.05", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        sink.read()  # the connect's HELLO + STATUS
        sink.set_fault(Fault.CAMERA_FAULT)
        sink.set_fault(Fault.OK)  # cleared at once: no STATUS went out in between
        faults: list = []

        def two_statuses() -> bool:
            faults.extend(m.fault for m in messages_of(sink.read()) if isinstance(m, Status))
            return len(faults) >= 2

        wait_until(two_statuses, what="two STATUS packets")
    finally:
        sink.close()
    assert faults[:2] == [Fault.CAMERA_FAULT, Fault.OK]


def test_send_2d_needs_the_camera_names_it_numbers_and_budgets() -> None:
    with pytest.raises(SinkConfigError) as info:
        open_sink("memory://?send_2d=1")
    assert info.value.field == "cameras" and "send_2d=1" in str(info.value)


def test_2d_joints_of_an_unannounced_camera_are_left_out_not_the_frame(caplog: pytest.LogCaptureFixture) -> None:
    sink = open_sink("memory://?send_2d=1&cameras=left,right", backoff=FAST_BACKOFF)
    uv = np.full((25, 3), 10.0)
    try:
        assert sink.wait_connected(5)
        for seq in range(3):
            sink.send(make_frame(seq, joints_2d={"left": uv, "CAM_C": uv, 2: uv}))
        assert sink.wait_drained(5)
    finally:
        stats = sink.close()
    messages = messages_of(sink.read())
    assert joints_seqs(messages) == [0, 1, 2] and stats.sent == 3 and stats.dropped == 0
    assert [m.camera for m in messages if isinstance(m, Joints2D)] == [0, 0, 0]
    warnings = [r.getMessage() for r in caplog.records if "not among the announced cameras" in r.getMessage()]
    assert len(warnings) == 2  # once per unknown camera, not once per frame


def test_numpy_integer_camera_keys_number_their_cameras() -> None:
    # {i: uv for i in np.arange(2)}: np.int64 keys were looked up as names, so the sink warned "not among the
    # announced cameras" and left every 2D joint out; they number the cameras as Python ints do.
    sink = open_sink("memory://?send_2d=1&cameras=left,right", backoff=FAST_BACKOFF)
    uv = np.full((25, 3), 10.0)
    try:
        assert sink.wait_connected(5)
        sink.send(make_frame(0, joints_2d={np.int64(1): uv, np.uint8(0): uv}))
        assert sink.wait_drained(5)
    finally:
        stats = sink.close()
    assert stats.sent == 1
    assert [m.camera for m in messages_of(sink.read()) if isinstance(m, Joints2D)] == [0, 1]
    assert camera_index(np.int32(1), ["left", "right"]) == 1 and is_announced(np.int16(1), ["left", "right"])
    assert not is_announced(np.int64(2), ["left", "right"])
    with pytest.raises(KeyError, match="camera index 2 is not among the 2 announced"):
        camera_index(np.int64(2), ["left", "right"])


class _Clock:
    """A clock the test moves: the sink's STATUS schedule follows it, not the wall."""

    def __init__(self) -> None:
        self.us = 1_000_000

    def __call__(self) -> int:
        return self.us


def _statuses(data: bytes) -> list[Status]:
    return [m for m in messages_of(data) if isinstance(m, Status)]


def test_a_latched_fault_survives_a_status_that_could_not_be_written() -> None:
    # the STATUS that was to report the camera fault hit a full buffer; clearing the latch before the write
    # lost the fault for good
    clock = _Clock()
    sink = open_sink("memory://?max_bytes=300&status_s=1", backoff=FAST_BACKOFF, clock_us=clock)
    try:
        assert sink.wait_connected(5)  # HELLO + STATUS: 78 bytes held
        sink.set_fault(Fault.CAMERA_FAULT)
        sink.set_fault(Fault.OK)
        clock.us += 2_000_000
        sink.send(make_frame(0))  # JOINTS + HELLO + STATUS do not fit beside them
        assert sink.wait_drained(5) and sink.stats().dropped_error == 1
        assert [st.fault for st in _statuses(sink.read())] == [Fault.OK]  # only the connect's
        clock.us += 2_000_000
        got: list[Status] = []

        def a_status_came() -> bool:
            got.extend(_statuses(sink.read()))
            return bool(got)

        wait_until(a_status_came, what="the STATUS after the failed one")
    finally:
        sink.close()
    assert got[0].fault == Fault.CAMERA_FAULT


def test_an_unwritten_status_is_owed_by_the_next_frame() -> None:
    clock = _Clock()
    sink = open_sink("memory://?max_bytes=300&status_s=3600", backoff=FAST_BACKOFF, clock_us=clock)
    try:
        assert sink.wait_connected(5)
        sink.set_fault(Fault.ESTIMATOR_STALLED)
        clock.us += 3601_000_000
        sink.send(make_frame(0))  # its STATUS does not fit
        assert sink.wait_drained(5)
        sink.read()
        sink.send(make_frame(1))  # the next STATUS is an hour away, but this one is owed now
        assert sink.wait_drained(5)
        messages = messages_of(sink.read())
    finally:
        sink.close()
    assert joints_seqs(messages) == [1]
    assert [st.fault for st in messages if isinstance(st, Status)] == [Fault.ESTIMATOR_STALLED]


def test_link_errors_show_while_decimating() -> None:
    # a deliberate max_fps decimates all the time: RATE_LIMITED first hid every lost frame
    clock = _Clock()
    sink = open_sink("memory://?max_bytes=150&max_fps=10&status_s=1", backoff=FAST_BACKOFF, clock_us=clock)
    try:
        assert sink.wait_connected(5)
        sink.read()
        for seq in range(6):  # 30 fps into 10: two in three decimated, the rest too big for the buffer
            sink.send(make_frame(seq))
            assert sink.wait_drained(5)
        stats = sink.stats()
        assert stats.decimated > 0 and stats.dropped_error > 0
        clock.us += 2_000_000  # HELLO + STATUS alone fit
        got: list[Status] = []

        def a_status_came() -> bool:
            got.extend(_statuses(sink.read()))
            return bool(got)

        wait_until(a_status_came, what="an idle STATUS")
    finally:
        sink.close()
    assert got[0].fault == Fault.LINK_ERRORS


class _Unpluggable(MemorySink):
    """memory:// whose link can go away (writes raise SinkUnavailableError) and come back."""

    unplugged = False

    def _write_bytes(self, data: bytes) -> None:
        if self.unplugged:
            raise SinkUnavailableError(self.url, "unplugged")
        super()._write_bytes(data)


def test_the_first_status_after_an_outage_has_no_rate_from_before_it() -> None:
    clock = _Clock()
    sink = _Unpluggable.from_url("memory://?status_s=10&queue=64", backoff=FAST_BACKOFF, clock_us=clock).start()
    try:
        assert sink.wait_connected(5)
        for seq in range(30):  # one second at 30 fps, no STATUS due yet
            clock.us += FRAME_US
            sink.send(make_frame(seq))
            assert sink.wait_drained(5)
        sink.read()
        sink.unplugged = True
        clock.us += 100_000_000  # a 100 s outage
        sink.send(make_frame(30))
        wait_until(lambda: sink.stats().disconnects == 1, what="the link lost")
        sink.unplugged = False
        wait_until(lambda: sink.stats().connects == 2, what="connected again")
        statuses = _statuses(sink.read())
    finally:
        sink.close()
    assert statuses[0].fps_centi == 0  # not 30 frames over 101 s
    assert statuses[0].fault == Fault.LINK_ERRORS


def test_udp_frame_out_but_status_refused_counts_as_delivered(monkeypatch: pytest.MonkeyPatch) -> None:
    # JOINTS went out and only the HELLO behind it met a full send buffer: the frame was counted dropped
    # (and the next one flagged DROPPED, a gap the receiver never saw)
    from firmware_host.errors import SinkWriteError
    from firmware_host.protocol.encoder import encode
    from firmware_host.sinks.udp_sink import UdpSink

    sink = UdpSink.from_url("udp://127.0.0.1:9", clock_us=lambda: 5_000_000)  # never started
    sent: list[bytes] = []
    refuse = [True]

    def send(datagram: bytes) -> None:
        if refuse[0] and isinstance(messages_of(datagram)[0], Hello):
            refuse[0] = False
            raise SinkWriteError(sink.url, "socket send buffer full")
        sent.append(datagram)

    monkeypatch.setattr(sink._link, "send", send)
    sink._deliver(make_frame(0), 0)  # with HELLO + STATUS (the first); the HELLO refused
    assert [type(m) for d in sent for m in messages_of(d)] == [Joints]
    sink._deliver(make_frame(1), 0)  # the clock stands still: the owed STATUS comes with it
    assert [type(m) for d in sent[1:] for m in messages_of(d)] == [Joints, Hello, Status]
    # a HELLO + STATUS with no frame before it is not delivered when refused
    refuse[0] = True
    with pytest.raises(SinkWriteError):
        sink._write_messages([sink._hello(1), sink._status(1)[0]])
    assert encode(sink._hello(1)) not in sent[3:]


def test_udp_frame_out_whose_status_alone_is_refused_counts_as_delivered(monkeypatch: pytest.MonkeyPatch) -> None:
    # JOINTS and the HELLO behind it went out, only the STATUS met a full send buffer: the frame was counted
    # dropped (only a refused HELLO let it count as delivered)
    from firmware_host.errors import SinkWriteError
    from firmware_host.sinks.udp_sink import UdpSink

    sink = UdpSink.from_url("udp://127.0.0.1:9", clock_us=lambda: 5_000_000)  # never started
    sent: list[bytes] = []

    def send(datagram: bytes) -> None:
        if isinstance(messages_of(datagram)[0], Status):
            raise SinkWriteError(sink.url, "socket send buffer full")
        sent.append(datagram)

    monkeypatch.setattr(sink._link, "send", send)
    sink._deliver(make_frame(0), 0)  # with HELLO + STATUS (the first): delivered, the STATUS owed
    assert [type(m) for d in sent for m in messages_of(d)] == [Joints, Hello]
    assert sink._status_owed



def test_udp_frame_whose_2d_joints_meet_a_full_buffer_is_sent_in_part_and_flags_no_gap(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Frame 0's JOINTS goes out, its first JOINTS_2D meets a full send buffer: the listener has seq 0 and its 3D
    joints, no 2D. Before, the frame counted in dropped_error and frame 1's JOINTS said DROPPED, a gap whose seq
    the listener had received; now it counts as sent and partial (as vmc://'s second bundle), and no flag lies."""
    from firmware_host.errors import SinkWriteError
    from firmware_host.protocol.constants import Flags
    from firmware_host.sinks.udp_sink import DatagramLink

    real_send = DatagramLink.send
    refused: list[bytes] = []

    def send(link: DatagramLink, datagram: bytes) -> None:
        message = messages_of(datagram)[0]
        if not refused and isinstance(message, Joints2D) and message.header.seq == 0:
            refused.append(datagram)
            raise SinkWriteError(link.url, "socket send buffer full")
        real_send(link, datagram)

    monkeypatch.setattr(DatagramLink, "send", send)
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(30)
    two_d = {"left": np.full((25, 3), 10.0), "right": np.full((25, 3), 20.0)}
    sink = open_sink(f"udp://127.0.0.1:{rx.getsockname()[1]}?queue=16&send_2d=1", backoff=FAST_BACKOFF,
                     cameras=("left", "right"))
    try:
        assert sink.wait_connected(30)
        sink.send(make_frame(0, joints_2d=two_d))
        sink.send(make_frame(1, joints_2d=two_d))
        received: list = []
        while not any(isinstance(m, Joints2D) and (m.header.seq, m.camera) == (1, 1) for m in received):
            received += messages_of(rx.recv(2048))  # (a timeout raises: frame 1's last packet never came)
        wait_until(lambda: sink.stats().sent + sink.stats().dropped_error == 2, timeout=30, what="both frames counted")
        stats = sink.stats()
    finally:
        sink.close()
        rx.close()
    assert refused
    assert stats.sent == 2 and stats.partial == 1 and stats.dropped_error == 0
    assert "socket send buffer full" in (stats.last_error or "")
    joints = [m for m in received if isinstance(m, Joints)]
    assert [m.header.seq for m in joints] == [0, 1]
    assert not joints[1].header.flags & Flags.DROPPED  # no seq is missing: the flag must not say one is
    assert [(m.header.seq, m.camera) for m in received if isinstance(m, Joints2D)] == [(1, 0), (1, 1)]


def test_a_frame_sent_in_part_is_a_link_error_in_status() -> None:
    """Counted dropped, a frame sent in part made its interval's STATUS say LINK_ERRORS; counted sent and partial,
    it left STATUS saying OK while the listener lost the frame's JOINTS_2D: fault 3 again, with no field changed."""
    from dataclasses import replace

    from firmware_host.sinks.base import SinkStats
    from firmware_host.sinks.protocol_sink import ProtocolSink

    before = SinkStats(submitted=1, sent=1, decimated=0, dropped_queue=0, dropped_error=0, dropped_close=0,
                       queued=0, in_flight=0, connected=True, connects=1, connect_failures=0, disconnects=0,
                       last_error=None, state="up")
    after = replace(before, submitted=2, sent=2, partial=1)
    assert ProtocolSink._link_fault(before, after) == Fault.LINK_ERRORS
    assert ProtocolSink._link_fault(after, replace(after, submitted=3, sent=3)) == Fault.OK  # the next interval


_RECORD_UNTIL_KILLED = """
import sys
from firmware_host.sinks import open_sink
from tests.firmware_host.joint_stream_helpers import make_frame
sink = open_sink("file://" + sys.argv[1] + "?queue=64&status_s=0.01")
assert sink.wait_connected(5)
seq = 0
while True:
    sink.send(make_frame(seq))
    seq += 1
    if seq == 200:
        print("recording", flush=True)
"""


def test_a_recording_stopped_by_sigterm_is_whole_lines_to_its_last_frame(tmp_path: Path) -> None:
    # docs/protocol.md: one write per frame, flushed at once, so a killed daemon leaves no cut line
    import os
    import signal
    import subprocess
    import sys

    path = tmp_path / "joints.jsonl"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    proc = subprocess.Popen([sys.executable, "-c", _RECORD_UNTIL_KILLED, str(path)], stdout=subprocess.PIPE,
                            env=env, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline() == "recording\n"
        wait_until(lambda: path.stat().st_size > 100_000, what="a recording under way")
        proc.send_signal(signal.SIGTERM)  # no handler: killed wherever its writer thread was
        assert proc.wait(10) == -signal.SIGTERM
    finally:
        proc.kill()
    data = path.read_bytes()
    assert data.endswith(b"\n")
    messages = [json.loads(line) for line in data.splitlines()]
    seqs = [m["seq"] for m in messages if m["type"] == "JOINTS"]
    assert len(seqs) > 50 and seqs == sorted(set(seqs))


def test_file_sink_into_a_fifo_whose_reader_stops_reading_reads_stalled_and_never_holds_its_worker(
        tmp_path: Path) -> None:
    # Once open, the pipe was written blocking: a reader that stopped reading held the worker inside write() for
    # as long as it stayed away, the sink reading "up" (no error, nothing dropped but the queue's) and close()
    # leaving that thread behind.
    import fcntl
    import os

    fifo = tmp_path / "joints.fifo"
    os.mkfifo(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    try:
        fcntl.fcntl(reader, fcntl.F_SETPIPE_SZ, 4096)  # the smallest pipe: a few lines fill it
        sink = open_sink(fifo.as_uri() + "?status_s=3600&stall_s=0.2&write_timeout_ms=20&queue=2",
                         backoff=FAST_BACKOFF)
        seq = 0

        def send_one() -> None:
            nonlocal seq
            sink.send(make_frame(seq))
            seq += 1
            time.sleep(0.005)

        try:
            assert sink.wait_connected(5)

            def stalled() -> bool:  # the reader never reads: the pipe fills, then every write times out
                send_one()
                return sink.stats().state == "stalled"

            wait_until(stalled, what="a pipe nobody reads reported stalled")
            s = sink.stats()
            assert s.connected and s.dropped_error >= 1 and "the reader is not reading" in (s.last_error or "")
            assert s.stalled_s is not None and s.stalled_s >= 0.2
            data = b""

            def up_again() -> bool:  # the reader reads again: the next frame gets through
                nonlocal data
                try:
                    while chunk := os.read(reader, 65536):
                        data += chunk
                except BlockingIOError:
                    pass
                send_one()
                return sink.stats().state == "up"

            wait_until(up_again, what="up once the reader reads again")
            assert sink.wait_drained(5)
            assert sink.stats().stalled_s is None
        finally:
            stats = sink.close(1.0)
        assert stats.state == "closed" and not sink._thread.is_alive()  # type: ignore[attr-defined]
        try:
            while chunk := os.read(reader, 65536):
                data += chunk
        except BlockingIOError:
            pass
    finally:
        os.close(reader)
    lines = data.decode().splitlines()
    parsed = []
    for line in lines:  # a line cut by a timeout stands alone: every other line parses
        try:
            parsed.append(json.loads(line)["type"])
        except json.JSONDecodeError:
            parsed.append("cut")
    assert parsed[:3] == ["HELLO", "STATUS", "JOINTS"] and parsed.count("JOINTS") >= 2
    assert parsed.count("cut") <= stats.dropped_error


def test_file_sink_into_a_fifo_with_no_frames_is_up_again_once_its_reader_reads_a_status(tmp_path: Path) -> None:
    # The rig down, so no frame: the idle STATUS writes that time out made the sink "stalled", but one that got
    # through did not end it (only a frame did), so it read "stalled" with the reader back until the rig was.
    import fcntl
    import os

    fifo = tmp_path / "joints.fifo"
    os.mkfifo(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    try:
        fcntl.fcntl(reader, fcntl.F_SETPIPE_SZ, 4096)  # the smallest pipe: a few STATUS fill it
        sink = open_sink(fifo.as_uri() + "?status_s=0.02&stall_s=0.2&write_timeout_ms=20", backoff=FAST_BACKOFF)
        try:
            assert sink.wait_connected(5)
            wait_until(lambda: sink.stats().state == "stalled", what="stalled by STATUS writes nobody reads")
            assert sink.stats().submitted == 0

            def read_and_up() -> bool:
                try:
                    while os.read(reader, 65536):
                        pass
                except BlockingIOError:
                    pass
                time.sleep(0.01)
                return sink.stats().state == "up"

            wait_until(read_and_up, what="up once the reader reads a STATUS again")
            assert sink.stats().stalled_s is None
        finally:
            sink.close(1.0)
    finally:
        os.close(reader)
