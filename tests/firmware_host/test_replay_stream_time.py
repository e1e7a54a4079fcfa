"""A take replayed into the joint stream: the capture times a receiver sees are on the sender's clock.

A ``replay://`` streamed the take's recorded stamps (another boot's, or another machine's, monotonic
clock) as JOINTS capture times, so ``ghnerf-listen`` showed a latency of hours or days, or a negative
one. The take here is recorded on a clock three days ahead of this one, as a device with a longer
uptime would record it; the demo replays it (``--truth-only``: no model) to a ``udp://`` sink, and the
listener's own tally reads what arrives.
"""
from __future__ import annotations

import time

import pytest

import drivers
from firmware_host import demo, listen
from firmware_host.protocol.decoder import StreamDecoder
from firmware_host.protocol.messages import Joints
from tests.firmware_host.joint_stream_helpers import record_take

DAYS_AHEAD_NS = 3 * 86_400 * 10**9
PAIRS = 12


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    """A 30 fps take recorded on a clock three days ahead of this host's, and its recorded first-camera stamps."""
    root = tmp_path_factory.mktemp("replay-time")
    out = root / "take"
    clock = drivers.ManualClock(time.monotonic_ns() + DAYS_AHEAD_NS)
    url = f"record+sim://?fps=30&width=64&height=48&seed=1&policy=all&cache={root / 'cache'}&out={out}&lossless=1"
    return out, record_take(url, clock, PAIRS)  # the pairs pass through with the stamps recorded


def _stream_through_the_demo(tmp_path, url: str) -> list[Joints]:
    """Run the demo on ``url`` into a udp:// sink; the JOINTS messages the listener's port received."""
    port = listen.open_port("udp://127.0.0.1:0", ephemeral=True)
    try:
        rc = demo.main(["--truth-only", "--url", url, "--seconds", "10", "--out", str(tmp_path / "out"),
                        "--sink", f"udp://127.0.0.1:{port.address[1]}"])
        assert rc == 0
        decoder, joints = StreamDecoder(), []
        while data := port.read(0.5):  # the datagrams wait in the socket's buffer
            joints += [e.message for e in decoder.feed(data) if isinstance(e.message, Joints)]
    finally:
        port.close()
    return joints


def test_a_replay_streams_capture_times_on_the_senders_clock(take, tmp_path):
    out, recorded = take
    joints = _stream_through_the_demo(tmp_path, f"replay://{out}")
    assert len(joints) == len(recorded)
    tally = listen.Tally()
    for message in joints:
        tally.add(message)
    # Capture to the wire, as ghnerf-listen computes it: the replay's few ms, not -3 days.
    assert all(0 <= ms < 1000 for ms in tally.latency_ms), tally.latency_ms
    # The recorded spacing (smoothing, tracking and rate limits see the take as it was); 1 us: rounding to us.
    sent = [m.header.capture_us for m in joints]
    for i, t in enumerate(recorded):
        assert abs((sent[i] - sent[0]) - (t - recorded[0]) // 1000) <= 1, i


def test_keep_time_streams_the_recorded_capture_times(take, tmp_path):
    out, recorded = take
    joints = _stream_through_the_demo(tmp_path, f"replay://{out}?keep_time=1")
    assert [m.header.capture_us for m in joints] == [t // 1000 for t in recorded]


def test_a_take_before_the_clock_s_zero_kept_is_refused_naming_the_stamp(tmp_path, capsys):
    """A take whose recorded stamps are negative (the recording format's signed 64-bit allows them) played with
    ``keep_time=1``: the joint stream carries capture times as unsigned microseconds, and the demo's first frame
    failed in ``JointFrame`` with a traceback. Now one line naming the camera, the stamp and the way out (exit 2);
    re-stamped (the default) the same take streams."""
    out = tmp_path / "take"
    url = f"record+sim://?fps=30&width=64&height=48&seed=1&policy=all&cache={tmp_path / 'cache'}&out={out}&lossless=1"
    assert max(record_take(url, drivers.ManualClock(-10**9), PAIRS)) < 0
    rc = demo.main(["--truth-only", "--url", f"replay://{out}?keep_time=1", "--seconds", "10",
                    "--out", str(tmp_path / "kept"), "--sink", "memory://"])
    error = capsys.readouterr().err
    assert rc == 2
    assert "camera 'left' frame 0 was captured at timestamp_ns=-1000000000" in error and "keep_time=1" in error, error
    assert len(_stream_through_the_demo(tmp_path, f"replay://{out}")) == PAIRS
