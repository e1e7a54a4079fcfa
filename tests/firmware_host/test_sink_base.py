"""Sink base behaviour: bounded queue, accounting, reconnect with backoff, flags, close.

A small scripted backend (defined here, in the tests) stands in for a link so
each failure can be triggered exactly when wanted.
"""
from __future__ import annotations

import itertools
import logging
import threading
import time
from collections.abc import Iterator
from types import SimpleNamespace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.clock import ManualClock
from firmware_host.errors import SinkClosedError, SinkPartialWriteError, SinkUnavailableError, SinkWriteError
from firmware_host.protocol import Flags, JointFrame
from firmware_host.sinks import Sink, SinkOptions
from firmware_host.sinks import base as sink_base
from firmware_host.sinks.backoff import Backoff, BackoffPolicy
from firmware_host.sinks.rate import RateLimiter, serial_capacity_fps
from tests.firmware_host.joint_stream_helpers import FAST_BACKOFF, make_frame, wait_until


class ScriptedSink(Sink):
    """A link whose connects and writes fail on command; ``gate`` blocks writes."""

    def __init__(self, **opts: object) -> None:
        super().__init__("scripted://", SinkOptions(backoff=FAST_BACKOFF, **opts))  # type: ignore[arg-type]
        self.connect_failures_left = 0
        self.fail_next: list[Exception] = []
        self.gate = threading.Event()
        self.gate.set()
        self.writing = threading.Event()  # set as _deliver begins: the stall watch has the write's start by then
        self.delivered: list[tuple[int, int]] = []
        self.connect_calls = 0
        self.connect_reason = "not plugged in"

    def _connect(self) -> None:
        self.connect_calls += 1
        if self.connect_failures_left:
            self.connect_failures_left -= 1
            raise SinkUnavailableError(self.url, self.connect_reason)

    def _disconnect(self) -> None:
        pass

    def _deliver(self, frame: JointFrame, flags: int) -> None:
        self.writing.set()
        self.gate.wait()
        if self.fail_next:
            raise self.fail_next.pop(0)
        self.delivered.append((frame.sequence, flags))


def test_queue_drops_the_oldest_and_counts_it() -> None:
    sink = ScriptedSink(queue=3).start()
    sink.gate.clear()  # the link stalls on the first frame
    sink.send(make_frame(0))
    wait_until(lambda: sink.stats().in_flight == 1, what="frame 0 in flight")
    for seq in range(1, 11):
        sink.send(make_frame(seq))  # returns at once although nothing moves
    s = sink.stats()
    assert (s.queued, s.dropped_queue, s.submitted) == (3, 7, 11)
    assert s.accounted == s.submitted
    sink.gate.set()
    assert sink.wait_drained(5)
    assert [seq for seq, _ in sink.delivered] == [0, 8, 9, 10]  # newest kept
    assert sink.delivered[1][1] & Flags.DROPPED  # the first frame after the gap says so
    assert not sink.delivered[2][1] & Flags.DROPPED
    s = sink.close()
    assert (s.sent, s.dropped, s.accounted) == (4, 7, 11)


def test_connect_retries_with_backoff_while_producer_keeps_going() -> None:
    sink = ScriptedSink(queue=2)
    sink.connect_failures_left = 5
    sink.start()
    for seq in range(10):
        sink.send(make_frame(seq))
    wait_until(lambda: sink.stats().connected, what="connect after 5 failures")
    assert sink.wait_drained(5)
    s = sink.close()
    assert s.connect_failures == 5 and s.connects == 1
    assert s.last_error is not None and "not plugged in" in s.last_error
    assert s.sent + s.dropped_queue == 10 and s.sent >= 2


def test_unplug_mid_stream_reconnects_and_counts_the_lost_frame() -> None:
    sink = ScriptedSink().start()
    sink.send(make_frame(0))
    assert sink.wait_drained(5)
    sink.fail_next.append(SinkUnavailableError("scripted://", "unplugged"))
    sink.connect_failures_left = 2
    sink.send(make_frame(1))
    wait_until(lambda: sink.stats().connects == 2, what="reconnect")
    sink.send(make_frame(2))
    assert sink.wait_drained(5)
    s = sink.close()
    assert (s.sent, s.dropped_error, s.disconnects, s.connect_failures) == (2, 1, 1, 2)
    assert sink.delivered[-1] == (2, int(Flags.DROPPED))


def test_write_error_keeps_the_link() -> None:
    sink = ScriptedSink().start()
    sink.fail_next.append(SinkWriteError("scripted://", "stall"))
    sink.send(make_frame(0))
    sink.send(make_frame(1))
    assert sink.wait_drained(5)
    s = sink.close()
    assert (s.sent, s.dropped_error, s.disconnects, s.connects) == (1, 1, 0, 1)
    assert "stall" in (s.last_error or "")


def test_backend_bug_is_counted_not_fatal() -> None:
    sink = ScriptedSink().start()
    sink.fail_next.append(ZeroDivisionError("oops"))
    sink.send(make_frame(0))
    sink.send(make_frame(1))
    assert sink.wait_drained(5)
    s = sink.close()
    assert (s.sent, s.dropped_error) == (1, 1) and "ZeroDivisionError" in (s.last_error or "")


def test_unexpected_connect_error_is_retried() -> None:
    class Flaky(ScriptedSink):
        def _connect(self) -> None:
            self.connect_calls += 1
            if self.connect_calls == 1:
                raise RuntimeError("driver bug")

    sink = Flaky().start()
    assert sink.wait_connected(5)
    s = sink.close()
    assert s.connect_failures == 1 and s.connects == 1 and "RuntimeError: driver bug" in (s.last_error or "")


def test_close_counts_what_could_not_be_flushed() -> None:
    sink = ScriptedSink(queue=8)
    sink.connect_failures_left = 10**6  # never connects
    sink.start()
    for seq in range(5):
        sink.send(make_frame(seq))
    s = sink.close(timeout=2)
    assert (s.sent, s.dropped_close, s.queued, s.accounted) == (0, 5, 0, 5)
    with pytest.raises(SinkClosedError, match="scripted://"):
        sink.send(make_frame(6))


def test_close_flushes_a_live_link() -> None:
    sink = ScriptedSink(queue=8).start()
    wait_until(lambda: sink.stats().connected, what="connected")
    for seq in range(8):
        sink.send(make_frame(seq))
    s = sink.close(timeout=5)
    assert s.sent == 8 and s.dropped == 0


def test_decimation_flags_and_counts() -> None:
    sink = ScriptedSink(queue=64, max_fps=10).start()
    for seq in range(30):  # 30 fps for one second into a 10 fps cap
        sink.send(make_frame(seq))
    assert sink.wait_drained(5)
    s = sink.close()
    # 0.97 s of capture at <= 10 fps, plus the limiter's one-frame jitter tolerance.
    assert 9 <= s.sent <= 11 and s.sent + s.decimated == 30 and s.accounted == 30
    for (prev, _), (seq, flags) in zip(sink.delivered, sink.delivered[1:]):
        assert bool(flags & Flags.DECIMATED) == (seq - prev > 1)


def test_backoff_sequence() -> None:
    b = Backoff(BackoffPolicy(initial_s=0.1, factor=2, max_s=0.5))
    assert [b.next_delay() for _ in range(5)] == [0.1, 0.2, 0.4, 0.5, 0.5]
    b.reset()
    assert b.next_delay() == 0.1
    with pytest.raises(ValueError):
        BackoffPolicy(initial_s=0)


def test_rate_limiter_uses_the_link_fully_without_exceeding_it() -> None:
    cap = serial_capacity_fps(115200, 208)
    assert 49.8 < cap < 49.9
    lim = RateLimiter(cap)
    admitted = [t for t in range(0, 10_000_000, 16_667) if lim.admit(t)]  # 60 fps for 10 s
    rate = (len(admitted) - 1) / ((admitted[-1] - admitted[0]) / 1e6)
    assert 45 < rate <= cap


@settings(deadline=None)
@given(st.floats(1, 500), st.lists(st.integers(0, 40_000), min_size=2, max_size=400))
def test_rate_limiter_never_exceeds_its_cap(max_fps: float, gaps: list[int]) -> None:
    lim = RateLimiter(max_fps)
    t, admitted = 0, []
    for g in gaps:
        t += g
        if lim.admit(t):
            admitted.append(t)
    span_s = (admitted[-1] - admitted[0]) / 1e6
    # GCRA: at most one frame per interval on average, plus one frame of burst tolerance.
    assert len(admitted) <= max_fps * span_s + 2


def test_rate_limiter_without_cap_admits_everything() -> None:
    lim = RateLimiter(None)
    assert all(lim.admit(t) for t in range(0, 1000, 1))


def sink_records(caplog: pytest.LogCaptureFixture, level: int) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.name == "firmware_host.sinks.base" and r.levelno >= level]


def test_a_sink_that_never_connects_warns_once_per_error_and_says_it_is_down(
        caplog: pytest.LogCaptureFixture) -> None:
    sink = ScriptedSink()
    sink.connect_failures_left = 10**6
    assert sink.stats().state == "connecting"
    with caplog.at_level(logging.DEBUG, logger="firmware_host.sinks"):
        sink.start()
        # each failed connect is logged just after it is counted (outside the lock): wait for the lines, not the count
        wait_until(lambda: len(sink_records(caplog, logging.DEBUG)) >= 5, what="five failed connects logged")
        assert len(sink_records(caplog, logging.INFO)) == 1  # not one line per retry
        assert sink_records(caplog, logging.INFO)[0].levelno == logging.WARNING
        s = sink.stats()
        assert s.state == "down" and not s.connected and "not plugged in" in (s.last_error or "")

        sink.connect_reason = "permission denied"  # a new error is worth a line again
        wait_until(lambda: len(sink_records(caplog, logging.INFO)) >= 2, what="the new error logged")
        seen = sink.stats().connect_failures
        wait_until(lambda: sink.stats().connect_failures >= seen + 2, what="failures with the new error")
        warnings = sink_records(caplog, logging.INFO)
        assert [r.levelno for r in warnings] == [logging.WARNING, logging.WARNING]
        assert "permission denied" in warnings[1].getMessage()
        assert "permission denied" in (sink.stats().last_error or "")

        sink.connect_failures_left = 0  # plugged in: up again, and said so
        wait_until(lambda: sink.stats().connected, what="connect")
        assert sink.stats().state == "up"
        # the line is logged just after the state changes (outside the lock): wait for it, not race it
        wait_until(lambda: "connected again" in sink_records(caplog, logging.INFO)[-1].getMessage(),
                   what="'connected again' logged")
    assert sink.close().state == "closed"


def test_an_unexpected_connect_error_logs_its_traceback_once(caplog: pytest.LogCaptureFixture) -> None:
    class Broken(ScriptedSink):
        def _connect(self) -> None:
            self.connect_calls += 1
            raise RuntimeError("driver bug")

    sink = Broken()
    with caplog.at_level(logging.DEBUG, logger="firmware_host.sinks"):
        sink.start()
        wait_until(lambda: sink.stats().connect_failures >= 4, what="four failed connects")
        sink.close()
    loud = sink_records(caplog, logging.INFO)
    assert len(loud) == 1 and loud[0].exc_info is not None
    repeats = [r for r in sink_records(caplog, logging.DEBUG) if r.levelno == logging.DEBUG]
    assert len(repeats) >= 3 and all(r.exc_info is None for r in repeats)
    assert sink.stats().state == "closed" and "RuntimeError: driver bug" in (sink.stats().last_error or "")


def test_a_lost_link_reads_down_until_it_reconnects() -> None:
    sink = ScriptedSink().start()
    wait_until(lambda: sink.stats().connected, what="connected")
    sink.fail_next.append(SinkUnavailableError("scripted://", "unplugged"))
    sink.connect_failures_left = 10**6
    sink.send(make_frame(0))
    wait_until(lambda: sink.stats().connect_failures >= 1, what="a failed reconnect")
    s = sink.stats()
    assert s.state == "down" and "not plugged in" in (s.last_error or "")
    sink.connect_failures_left = 0
    wait_until(lambda: sink.stats().state == "up", what="reconnect")
    sink.close()


def test_a_link_that_opens_but_fails_its_first_write_warns_once_and_stays_down(
        caplog: pytest.LogCaptureFixture) -> None:
    """A port that opens but EIOs on HELLO (or a udp:// whose route is gone) is one outage: one WARNING,
    no "connected again" per retry, and the state never reads up in between."""
    class HelloFails(ScriptedSink):
        hello_fails = True
        disconnects_seen = 0

        def _on_connected(self) -> None:
            if self.hello_fails:
                raise SinkUnavailableError(self.url, "network unreachable")

        def _disconnect(self) -> None:
            self.disconnects_seen += 1

    sink = HelloFails()
    states: list[str] = []
    with caplog.at_level(logging.DEBUG, logger="firmware_host.sinks"):
        sink.start()
        deadline = time.monotonic() + 10.0  # a regression fails here instead of hanging CI
        while sink.stats().connect_failures < 6:
            states.append(sink.stats().state)
            assert time.monotonic() < deadline, "timed out waiting for 6 failed connects"
        loud = sink_records(caplog, logging.INFO)
        assert len(loud) == 1 and loud[0].levelno == logging.WARNING, [r.getMessage() for r in loud]
        assert "up" not in states
        s = sink.stats()
        assert s.state == "down" and s.connects == 0 and "network unreachable" in (s.last_error or "")
        assert sink.disconnects_seen >= 5  # each half-open link is released
        sink.hello_fails = False
        wait_until(lambda: sink.stats().state == "up", what="up once HELLO goes out")
        assert sink.stats().connects == 1
        wait_until(lambda: "connected again" in sink_records(caplog, logging.INFO)[-1].getMessage(),
                   what="'connected again' logged")
    assert sink.close().state == "closed"


@pytest.mark.parametrize("max_fps", [0.0, -1.0, float("nan"), float("inf"), 1e-320, 1e-6])
def test_rate_limiter_refuses_a_cap_it_cannot_keep(max_fps: float) -> None:
    # 0 divided by zero; -1 and NaN admitted every frame; 1e-320's interval overflowed to inf and then
    # admitted every frame too (inf - inf is NaN, and every comparison with it is false)
    with pytest.raises(ValueError, match="max_fps"):
        RateLimiter(max_fps)


@pytest.mark.parametrize("max_fps", [1 / 3600, 0.1, 0.4, 1.0])
def test_rate_limiter_keeps_a_slow_cap(max_fps: float) -> None:
    # below 0.5 fps (an interval over 2 s) every frame right after an admitted one was taken for a clock
    # a second back, restarted the schedule and went out: 23 frames in a minute at max_fps=0.1
    lim = RateLimiter(max_fps)
    interval_us = round(1e6 / max_fps)
    span_us = 10 * interval_us
    step = max(100_000, interval_us // 600)  # a frame every 0.1 s, or 600 per interval
    admitted = [t for t in range(0, span_us, step) if lim.admit(t)]
    assert 10 <= len(admitted) <= 11  # the cap over the span, plus the limiter's one frame of tolerance
    assert min(b - a for a, b in zip(admitted, admitted[1:])) >= interval_us // 2


def test_rate_limiter_after_the_clock_steps_back() -> None:
    lim = RateLimiter(10)
    assert [lim.admit(t) for t in (0, 100_000, 200_000)] == [True] * 3
    # half a second back: held (no burst) until half an interval past the last admitted frame, then paced
    assert [lim.admit(t) for t in (-300_000, 100_000, 250_000, 300_000, 350_000)] == [False, False, True, False, True]
    # more than a second back: a new session, admitted at once and paced from there
    assert [lim.admit(t) for t in (-5_000_000, -4_990_000, -4_900_000)] == [True, False, True]


@pytest.mark.parametrize("url", ["memory://?max_fps=1e-320", "memory://?max_fps=0.0001"])
def test_a_max_fps_below_a_frame_an_hour_is_refused_by_name(url: str) -> None:
    from firmware_host.errors import SinkConfigError
    from firmware_host.sinks import open_sink

    with pytest.raises(SinkConfigError) as info:
        open_sink(url)
    assert info.value.field == "max_fps" and "a frame an hour" in str(info.value)


@pytest.mark.parametrize("policy", [dict(max_s=float("inf")), dict(initial_s=1e12, max_s=1e12),
                                    dict(factor=float("inf")), dict(factor=float("nan"))])
def test_a_backoff_the_worker_cannot_wait_is_refused(policy: dict) -> None:
    # Event.wait(1e12) raises OverflowError: the worker died after the first failed connect
    with pytest.raises(ValueError, match="backoff policy"):
        BackoffPolicy(**policy)


# ---- stalled: up, but the receiver stopped reading (session 53) ---------------------------------------------


def send_failing(sink: ScriptedSink, seqs: Iterator[int]) -> bool:
    """Send the next frame with its write timing out (a receiver that stopped reading); whether the sink now
    reads stalled."""
    sink.fail_next.append(SinkWriteError("scripted://", "write timed out"))
    sink.send(make_frame(next(seqs)))
    time.sleep(0.01)
    return sink.stats().state == "stalled"


def test_a_link_that_drops_every_frame_reads_stalled_until_one_gets_through(caplog: pytest.LogCaptureFixture) -> None:
    # Every write timing out (a serial or USB receiver that stopped reading) only showed in dropped_error and
    # last_error: the state read "up" and the daemon's STATUS= line said nothing.
    sink = ScriptedSink(queue=1, stall_s=0.1).start()
    with caplog.at_level(logging.INFO, logger="firmware_host.sinks"):
        try:
            wait_until(lambda: sink.stats().connected, what="connected")
            seqs = itertools.count()
            wait_until(lambda: send_failing(sink, seqs), what="stalled")
            s = sink.stats()
            assert s.connected and s.stalled_s is not None and s.stalled_s >= 0.1
            assert "write timed out" in (s.last_error or "")

            def warned() -> list[logging.LogRecord]:
                return [r for r in sink_records(caplog, logging.WARNING) if "stalled" in r.getMessage()]

            wait_until(lambda: send_failing(sink, seqs) and bool(warned()), what="the stall logged")
            for _ in range(3):  # more failures: still one WARNING for this stall
                send_failing(sink, seqs)
            assert sink.wait_drained(5)
            warnings = warned()
            assert len(warnings) == 1, [r.getMessage() for r in warnings]
            sink.fail_next.clear()
            sink.send(make_frame(next(seqs)))  # gets through: up again at once
            assert sink.wait_drained(5)
            s = sink.stats()
            assert (s.state, s.stalled_s) == ("up", None)
            # logged by the worker just after it counts the frame (outside the lock): wait for it
            wait_until(lambda: any("get through again" in r.getMessage() for r in sink_records(caplog, logging.INFO)),
                       what="the stall's end logged")
        finally:
            sink.close()


def test_a_link_that_sends_every_frame_in_part_reads_stalled_until_one_goes_out_whole() -> None:
    """A frame sent in part (a vmc:// frame whose second bundle met a full send buffer) counted as a frame through:
    a sink whose every frame went out in part read ``up`` while the avatar's other bones never moved. It starts (and
    does not end) a stall now, still counted sent and partial; the first frame out whole ends it."""
    sink = ScriptedSink(queue=1, stall_s=0.1).start()
    try:
        wait_until(lambda: sink.stats().connected, timeout=30, what="connected")
        sink.fail_next.append(SinkPartialWriteError("scripted://", "socket send buffer full", 1, 2))
        sink.send(make_frame(0))
        assert sink.wait_drained(30)
        wait_until(lambda: sink.stats().state == "stalled", timeout=30, what="stalled after a frame sent in part")
        s = sink.stats()
        assert (s.sent, s.partial, s.dropped, s.accounted) == (1, 1, 0, 1)
        assert "socket send buffer full (after 1 of the frame's 2" in (s.last_error or "")
        sink.send(make_frame(1))  # out whole: the receiver has all of it
        assert sink.wait_drained(30)
        s = sink.stats()
        assert (s.state, s.stalled_s, s.sent, s.partial) == ("up", None, 2, 1)
    finally:
        sink.close()


def manual_monotonic(monkeypatch: pytest.MonkeyPatch) -> ManualClock:
    """The sink base's stall watch on a clock the test moves (this module's clock alone): on the real one a loaded
    host that took ``stall_s`` between a write and the check read ``stalled`` where the test meant no time to pass."""
    clock = ManualClock(1_000_000_000_000)
    monkeypatch.setattr(sink_base, "time", SimpleNamespace(monotonic=lambda: clock.now_ns() / 1e9))
    return clock


def test_a_link_that_fails_now_and_then_is_not_stalled(monkeypatch: pytest.MonkeyPatch) -> None:
    clock = manual_monotonic(monkeypatch)
    sink = ScriptedSink(stall_s=0.1).start()
    try:
        wait_until(lambda: sink.stats().connected, what="connected")
        for seq in range(20):  # every other frame lost, for longer than stall_s: the receiver still reads
            if seq % 2 == 0:
                sink.fail_next.append(SinkWriteError("scripted://", "short write"))
            sink.send(make_frame(seq))
            assert sink.wait_drained(5)
            assert sink.stats().state == "up", seq
            clock.advance(60_000_000)  # a failure the next frame did not end would read stalled a frame later
    finally:
        sink.close()


def test_a_write_that_never_returns_reads_stalled(monkeypatch: pytest.MonkeyPatch) -> None:
    # a blocking write (a named pipe whose reader stopped) fails nothing: its time in progress is what counts
    clock = manual_monotonic(monkeypatch)  # "just started" held on a host that took stall_s to look
    sink = ScriptedSink(stall_s=0.1).start()
    try:
        wait_until(lambda: sink.stats().connected, what="connected")
        sink.gate.clear()
        sink.send(make_frame(0))
        assert sink.writing.wait(5), "frame 0 never written"
        assert sink.stats().state == "up"  # just started
        clock.advance(99_000_000)
        assert sink.stats().state == "up"
        clock.advance(2_000_000)
        assert sink.stats().state == "stalled"  # past stall_s into the write
        sink.gate.set()
        assert sink.wait_drained(5)
        assert (sink.stats().state, sink.stats().stalled_s) == ("up", None)
    finally:
        sink.gate.set()
        sink.close()


def test_a_stalled_link_that_is_lost_reads_down_not_stalled() -> None:
    sink = ScriptedSink(queue=1, stall_s=0.1).start()
    try:
        wait_until(lambda: sink.stats().connected, what="connected")
        seqs = itertools.count()
        wait_until(lambda: send_failing(sink, seqs), what="stalled")
        assert sink.wait_drained(5)
        sink.connect_failures_left = 10**6
        sink.fail_next[:] = [SinkUnavailableError("scripted://", "unplugged")]
        sink.send(make_frame(next(seqs)))
        wait_until(lambda: sink.stats().connect_failures >= 1, what="a failed reconnect")
        assert (sink.stats().state, sink.stats().stalled_s) == ("down", None)
        sink.connect_failures_left = 0
        wait_until(lambda: sink.stats().connected, what="reconnected")
        assert sink.stats().state == "up"  # a new link: no stall carried over
    finally:
        sink.close()


class IdleScriptedSink(ScriptedSink):
    """A scripted link that writes (a STATUS, say) every 10 ms while no frame comes: ``idle`` is what each idle
    write does, ``"fail"`` (times out), ``"nothing"`` (nothing due) or ``"write"`` (gets through)."""

    def __init__(self, **opts: object) -> None:
        super().__init__(**opts)
        self.idle = "write"
        self.idle_writes = 0

    def _idle_timeout_s(self) -> float:
        return 0.01

    def _on_idle(self) -> bool:
        if self.idle == "fail":
            raise SinkWriteError("scripted://", "STATUS write timed out")
        self.idle_writes += self.idle == "write"
        return self.idle == "write"


def test_a_stall_ends_when_an_idle_write_gets_through_with_no_frame_to_send(caplog: pytest.LogCaptureFixture) -> None:
    # With the rig down no frame comes: a failed idle STATUS started a stall, but one that got through did not
    # end it (only a frame did), so a receiver that read again still saw the sink "stalled" until the rig was back.
    sink = IdleScriptedSink(stall_s=0.1).start()
    with caplog.at_level(logging.INFO, logger="firmware_host.sinks"):
        try:
            wait_until(lambda: sink.stats().connected, what="connected")
            sink.idle = "fail"
            wait_until(lambda: sink.stats().state == "stalled", what="stalled by failed idle writes")
            assert "STATUS write timed out" in (sink.stats().last_error or "")
            # the journal hears of it too (it did only when a frame failed)
            wait_until(lambda: any("stalled" in r.getMessage() for r in sink_records(caplog, logging.WARNING)),
                       what="the stall logged")
            sink.idle = "nothing"  # nothing written: the receiver may still be away
            time.sleep(0.1)
            assert sink.stats().state == "stalled"
            sink.idle = "write"
            wait_until(lambda: sink.stats().state == "up", what="up at the first idle write through")
            assert sink.stats().stalled_s is None and sink.stats().sent == 0 and sink.idle_writes >= 1
            wait_until(lambda: any("get through again" in r.getMessage()
                                   for r in sink_records(caplog, logging.INFO)), what="the stall's end logged")
        finally:
            sink.close()


@pytest.mark.parametrize("url", ["memory://?stall_s=0.01", "memory://?stall_s=1e9", "memory://?stall_s=nan",
                                 "memory://?stall_s=0"])
def test_a_stall_time_out_of_range_is_refused_by_name(url: str) -> None:
    from firmware_host.errors import SinkConfigError
    from firmware_host.sinks import open_sink

    with pytest.raises(SinkConfigError) as info:
        open_sink(url)
    assert info.value.field == "stall_s"


def test_stall_s_is_a_url_option_of_every_sink() -> None:
    from firmware_host.sinks import open_sink

    for url in ("memory://?stall_s=0.5", "udp://127.0.0.1:9?stall_s=0.5", "vmc://127.0.0.1:9?stall_s=0.5"):
        sink = open_sink(url)
        try:
            assert sink.options.stall_s == 0.5, url
        finally:
            sink.close()


class IdleFailsOnce(ScriptedSink):
    """A link whose idle write (a STATUS with no frame to send) finds it gone, once."""

    idle_error: SinkUnavailableError | None = None

    def _idle_timeout_s(self) -> float:
        return 0.01

    def _on_idle(self) -> bool:
        error, self.idle_error = self.idle_error, None
        if error is not None:
            raise error
        return False


@pytest.mark.parametrize("lost_in", ["a frame's write", "an idle write"])
def test_a_lost_link_is_logged_naming_the_url_once(caplog: pytest.LogCaptureFixture, lost_in: str) -> None:
    # "udp://h:9870: link lost (udp://h:9870: unavailable: sendto failed); reconnecting": the error's
    # text starts with the URL, and the line put the sink's before it
    sink = IdleFailsOnce()
    lost = SinkUnavailableError(sink.url, "sendto failed")
    with caplog.at_level(logging.WARNING, logger="firmware_host.sinks"):
        sink.start()
        try:
            wait_until(lambda: sink.stats().connected, what="connected")
            if lost_in == "a frame's write":
                sink.fail_next.append(lost)
                sink.send(make_frame(0))
            else:
                sink.idle_error = lost
            wait_until(lambda: sink.stats().disconnects == 1, what="the link lost")
        finally:
            sink.close()
    lines = [r.getMessage() for r in sink_records(caplog, logging.WARNING) if "link lost" in r.getMessage()]
    assert lines == ["scripted://: link lost (sendto failed); reconnecting"]


def test_a_sink_started_held_opens_nothing_until_released_and_closed_held_never_opens() -> None:
    """``start(held=True)``: the daemon's reload starts the sinks it adds before it commits (a worker thread may fail
    to start) and lets them open only once the sinks it removes let go of their ports."""
    sink = ScriptedSink().start(held=True)
    sink.send(make_frame(0))
    assert sink._thread is not None and sink._thread.is_alive()
    assert sink.connect_calls == 0 and not sink.stats().connected  # (held: nothing can have opened it yet)
    sink.release()
    assert sink.wait_connected(10) and sink.wait_drained(10)
    assert [seq for seq, _ in sink.delivered] == [0]
    sink.close()

    never = ScriptedSink().start(held=True)
    never.send(make_frame(0))
    stats = never.close(timeout=10)
    assert never._thread is not None and not never._thread.is_alive()
    assert never.connect_calls == 0 and (stats.connects, stats.connect_failures, stats.dropped_close) == (0, 0, 1)


def test_a_sink_whose_worker_cannot_start_closes_cleanly(monkeypatch) -> None:
    """Thread.start failing (a task limit) left the unstarted thread in place: close() raised "cannot join thread
    before it is started", and the daemon's refused reload could not close its other sinks behind it."""
    sink = ScriptedSink()

    def no_thread(thread: threading.Thread) -> None:
        raise RuntimeError("can't start new thread")

    with monkeypatch.context() as patch:
        patch.setattr(threading.Thread, "start", no_thread)
        with pytest.raises(RuntimeError, match="can't start new thread"):
            sink.start(held=True)
    stats = sink.close()
    assert sink.connect_calls == 0 and stats.state == "closed"


class _WaitWatchingCondition(threading.Condition):
    """A sink's condition that says when a thread first waits on it: a held worker waiting for its release."""

    def __init__(self) -> None:
        super().__init__()
        self.waited = threading.Event()

    def wait_for(self, predicate, timeout=None):  # type: ignore[no-untyped-def]
        self.waited.set()
        return super().wait_for(predicate, timeout)


def test_a_held_sink_closed_while_its_worker_waits_ends_it_and_a_release_after_that_opens_nothing() -> None:
    """A reload refused after its sinks started held closes them unreleased: the waiting worker must wake and end
    without opening the link, and a release() coming after the close() must neither open it nor raise."""
    sink = ScriptedSink()
    sink._cond = cond = _WaitWatchingCondition()  # before start: the worker waits on this one
    sink.start(held=True)
    assert cond.waited.wait(10), "the held worker never waited for its release"
    sink.send(make_frame(0))
    stats = sink.close(timeout=10)
    assert sink._thread is not None and not sink._thread.is_alive(), "a close() left the held worker waiting"
    sink.release()
    sink.release()
    assert sink.connect_calls == 0 and sink.delivered == []
    after = sink.stats()
    assert after == stats and (after.state, after.connects, after.dropped_close) == ("closed", 0, 1)
    with pytest.raises(SinkClosedError):
        sink.send(make_frame(1))
