"""A sink that is down shows on the daemon's one-line status (``systemctl status ghnerf``).

The sinks' counters reach ``Health.status_line`` the way the daemon hands them to ``Health.report``:
``{url: dataclasses.asdict(sink.stats())}``.
"""
from __future__ import annotations

import dataclasses
from typing import Any

from firmware_host.daemon.health import Health, State
from firmware_host.sinks import Sink, open_sink
from tests.firmware_host.joint_stream_helpers import FAST_BACKOFF, wait_until


def counters(*sinks: Sink) -> dict[str, Any]:
    return {s.url: dataclasses.asdict(s.stats()) for s in sinks}


def test_a_sink_that_cannot_connect_is_named_with_its_error() -> None:
    missing = "serial:///nonexistent-ghnerf/ttyACM9?baud=921600"
    dead = open_sink(missing, backoff=FAST_BACKOFF)
    live = open_sink("memory://")
    try:
        wait_until(lambda: dead.stats().connect_failures >= 2 and live.stats().connected, what="both tried")
        health = Health(rig_url="sim://")
        health.enter(State.RUNNING)
        line = health.status_line(counters(dead, live))
    finally:
        dead.close()
        live.close()
    assert line.startswith("running: ")
    assert f"; sink {missing} down: cannot open /nonexistent-ghnerf/ttyACM9" in line
    assert "memory://" not in line  # up: nothing to say
    assert len(line) <= 200
    # Closed sinks (a reload removed them; their last counters stay in the report) are not down.
    assert health.status_line(counters(dead, live)) == health.status_line()


def test_the_state_and_a_refusal_keep_their_place_beside_sinks_that_are_down() -> None:
    health = Health(rig_url="depthai://")
    health.enter(State.WAITING)
    health.last_error = "cannot open depthai://: " + "X_LINK_DEVICE_NOT_FOUND " * 20
    health.reload_error = "reload refused: /etc/ghnerf/daemon.json: rig.ulr: unknown key"
    sinks = {f"udp://robot-{k}.local:9870": {"state": "down", "last_error": "unavailable: " + "x" * 80}
             for k in range(3)}
    line = health.status_line(sinks)
    assert len(line) <= 200 and line.startswith("waiting for the rig: cannot open depthai://")
    assert line.endswith("; reload refused: /etc/ghnerf/daemon.json: rig.ulr: unknown key")
    assert "; 3 sinks down" in line or "; sink udp://robot-0.local:9870 down" in line
    health.reload_error = None
    one = health.status_line({"udp://robot.local:9870": {"state": "down", "last_error": "no route"}})
    assert one.endswith("; sink udp://robot.local:9870 down: no route") and len(one) <= 200


def test_a_stalled_sink_is_named_with_how_long_and_its_error() -> None:
    # A receiver that stopped reading left the sink "up": systemctl status said nothing of it
    url = "serial:///dev/ttyACM0?baud=921600"
    error = f"{url}: write failed: write timed out after 100 ms (0 of 208 bytes out; the peer is not reading)"
    health = Health(rig_url="sim://")
    health.enter(State.RUNNING)
    line = health.status_line({url: {"state": "stalled", "stalled_s": 4.6, "connected": True, "last_error": error},
                               "memory://": {"state": "up", "stalled_s": None, "last_error": None}})
    assert line.endswith(f"; sink {url} stalled 5 s: write timed out after 100 ms (0 of 208 bytes out; the peer "
                         "is not reading)"), line
    assert "memory://" not in line and len(line) <= 200
    # a write that never returned has no error yet: say so rather than "not connected"
    line = health.status_line({"file:///run/joints.fifo": {"state": "stalled", "stalled_s": 3.0, "last_error": None}})
    assert line.endswith("; sink file:///run/joints.fifo stalled 3 s: a write that has not returned")


def test_many_sinks_down_and_stalled_are_counted_when_they_do_not_fit() -> None:
    health = Health(rig_url="depthai://")
    health.enter(State.WAITING)
    health.last_error = "cannot open depthai://: " + "X_LINK_DEVICE_NOT_FOUND " * 20
    health.reload_error = "reload refused: /etc/ghnerf/daemon.json: rig.ulr: unknown key"
    sinks = {f"udp://robot-{k}.local:9870": {"state": "down", "last_error": "unavailable: " + "x" * 80}
             for k in range(2)}
    sinks.update({f"serial:///dev/ttyACM{k}": {"state": "stalled", "stalled_s": 9.0, "last_error": "y" * 80}
                  for k in range(3)})
    line = health.status_line(sinks)
    assert len(line) <= 200
    assert "; 2 sinks down, 3 stalled" in line or "; sink udp://robot-0.local:9870 down" in line
    only_stalled = {k: v for k, v in sinks.items() if v["state"] == "stalled"}
    line = health.status_line(only_stalled)
    assert "; 3 sinks stalled" in line or "; sink serial:///dev/ttyACM0 stalled 9 s" in line


def test_a_real_stalled_sink_reaches_the_report_and_the_status_line() -> None:
    sink = open_sink("memory://?max_bytes=300&stall_s=0.1&status_s=3600", backoff=FAST_BACKOFF)
    from tests.firmware_host.joint_stream_helpers import make_frame

    seq = 0

    def stalled() -> bool:  # the buffer is never read: once full, every frame is dropped
        nonlocal seq
        sink.send(make_frame(seq))
        seq += 1
        return sink.stats().state == "stalled"

    try:
        wait_until(stalled, what="a memory sink never read reported stalled")
        health = Health(rig_url="sim://")
        health.enter(State.RUNNING)
        report = health.report(counters(sink))["sinks"]["memory://?max_bytes=300&stall_s=0.1&status_s=3600"]
        line = health.status_line(counters(sink))
    finally:
        sink.close()
    assert report["state"] == "stalled" and report["connected"] and report["stalled_s"] >= 0.1
    assert "stalled" in line and "buffer full (300 bytes); call read()" in line


def test_sinks_are_named_without_their_passwords_and_told_apart_when_only_those_differ() -> None:
    """The report's ``sinks`` and the STATUS line keyed each sink by its URL as configured, password and all (the
    status file is world-readable). Now by :func:`sink_keys`: redacted, and a second URL that differs only in its
    password (so its redacted name is the first one's) gets ``#2``, in the order given."""
    first, second = "memory://viewer:s3cret@here?max_bytes=64", "memory://viewer:hunter2@here?max_bytes=64"
    error = "memory://viewer:***@here?max_bytes=64: unavailable: the buffer is full"  # as the sink's error reads
    sinks = {first: {"state": "down", "last_error": error}, second: {"state": "up", "last_error": None},
             "memory://": {"state": "down", "last_error": None}}
    health = Health(rig_url="sim://")
    health.enter(State.RUNNING)
    report = health.report(sinks)
    assert list(report["sinks"]) == ["memory://viewer:***@here?max_bytes=64", "memory://viewer:***@here?max_bytes=64#2",
                                     "memory://"]
    assert report["sinks"]["memory://viewer:***@here?max_bytes=64#2"]["state"] == "up"  # the second one's counters
    line = health.status_line(sinks)
    assert line.endswith("; sink memory://viewer:***@here?max_bytes=64 down: the buffer is full; sink memory:// "
                         "down: not connected"), line
    assert "s3cret" not in line + str(report) and "hunter2" not in str(report)
    from firmware_host.daemon.health import sink_keys

    swapped = sink_keys([second, first])  # the order given decides which is #2
    assert swapped == {second: "memory://viewer:***@here?max_bytes=64",
                       first: "memory://viewer:***@here?max_bytes=64#2"}
