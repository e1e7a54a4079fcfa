"""udp:// on 127.0.0.1, file:// JSON lines, memory:// buffer."""
from __future__ import annotations

import json
import socket
from pathlib import Path

import numpy as np
import pytest

from firmware_host.errors import SinkConfigError
from firmware_host.protocol import Fault, Hello, Joints, Joints2D, StreamDecoder
from firmware_host.protocol.messages import Status
from firmware_host.sinks import open_sink
from tests.firmware_host.joint_stream_helpers import FAST_BACKOFF, joints_seqs, make_frame, messages_of, wait_until


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
