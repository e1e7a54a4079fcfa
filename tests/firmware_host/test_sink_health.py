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
