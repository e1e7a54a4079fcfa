"""sd_notify over a real unix datagram socket, and the hang watchdog on a manual clock."""
from __future__ import annotations

import errno
import logging
import os
import socket
import threading
import uuid
from typing import Callable

import pytest

from firmware_host.daemon.notify import HangWatchdog, SystemdNotifier
from tests.firmware_host.joint_stream_helpers import wait_until


@pytest.fixture
def notify_socket(tmp_path):
    path = tmp_path / "notify.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    sock.settimeout(2.0)
    yield str(path), sock
    sock.close()


def _fields(sock: socket.socket) -> dict[str, str]:
    data = sock.recv(4096).decode()
    return dict(line.split("=", 1) for line in data.splitlines())


def test_messages_reach_the_socket(notify_socket):
    path, sock = notify_socket
    n = SystemdNotifier({"NOTIFY_SOCKET": path})
    assert n.enabled and n.watchdog_s is None
    assert n.notify(ready=1, status="warming up")
    assert _fields(sock) == {"READY": "1", "STATUS": "warming up"}
    n.close()


def test_a_value_stays_on_its_line(notify_socket):
    path, sock = notify_socket
    n = SystemdNotifier({"NOTIFY_SOCKET": path})
    assert n.notify(status="reload refused: bad.json:\nREADY=1\r\nline 3")
    assert _fields(sock) == {"STATUS": "reload refused: bad.json: READY=1 line 3"}
    n.close()


def test_abstract_namespace_socket():
    name = f"ghnerf-test-{uuid.uuid4().hex}"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind("\0" + name)
    sock.settimeout(2.0)
    try:
        n = SystemdNotifier({"NOTIFY_SOCKET": "@" + name})
        assert n.notify(stopping=1)
        assert _fields(sock) == {"STOPPING": "1"}
    finally:
        sock.close()


def test_without_systemd_nothing_is_sent():
    n = SystemdNotifier({})
    assert not n.enabled
    assert n.notify(ready=1) is False


def test_a_vanished_socket_is_not_fatal(tmp_path, caplog):
    n = SystemdNotifier({"NOTIFY_SOCKET": str(tmp_path / "gone.sock")})
    assert n.notify(ready=1) is False
    assert n.notify(ready=1) is False
    assert sum("cannot notify systemd" in r.message for r in caplog.records) == 1  # warned once


@pytest.mark.parametrize("env, expected", [
    ({"WATCHDOG_USEC": "4000000"}, 4.0),
    ({"WATCHDOG_USEC": "4000000", "WATCHDOG_PID": str(os.getpid())}, 4.0),
    ({"WATCHDOG_USEC": "4000000", "WATCHDOG_PID": "1"}, None),  # meant for another process
    ({"WATCHDOG_USEC": "0"}, None),
    ({"WATCHDOG_USEC": "soon"}, None),
])
def test_watchdog_interval_from_the_environment(env, expected):
    assert SystemdNotifier({"NOTIFY_SOCKET": "/nonexistent", **env}).watchdog_s == expected


class _Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_pings_only_while_the_loop_beats(notify_socket):
    path, sock = notify_socket
    clock = _Clock()
    n = SystemdNotifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "2000000"})
    wd = HangWatchdog(n, allowance_s=5.0, clock=clock)
    assert wd._interval == 1.0  # half of WatchdogSec
    wd.beat()
    clock.t += 4.0
    assert wd.check()
    assert _fields(sock) == {"WATCHDOG": "1"}
    assert wd.pings == 1


def test_hang_stops_pings_and_dumps_stacks_once(notify_socket, tmp_path):
    path, sock = notify_socket
    clock = _Clock()
    n = SystemdNotifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "2000000"})
    with open(tmp_path / "stacks.txt", "w+") as stacks:
        wd = HangWatchdog(n, allowance_s=5.0, clock=clock, stacks_to=stacks)
        wd.beat("estimating a pair")
        clock.t += 6.0
        assert not wd.check()
        assert not wd.check()
        stacks.seek(0)
        text = stacks.read()
    assert text.count("Current thread") + text.count("Thread 0x") >= 1
    assert text.count("test_hang_stops_pings_and_dumps_stacks_once") == 1  # dumped once, not per tick
    sock.settimeout(0.2)
    with pytest.raises(socket.timeout):
        sock.recv(4096)  # no WATCHDOG=1 while hung
    wd.beat()
    assert wd.check() and _fields(sock) == {"WATCHDOG": "1"}  # progress again: pings resume


def test_allow_covers_one_long_call(notify_socket):
    path, sock = notify_socket
    clock = _Clock()
    n = SystemdNotifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "2000000"})
    wd = HangWatchdog(n, allowance_s=5.0, clock=clock)
    with wd.allow(60.0, "opening the rig"):
        clock.t += 30.0
        assert wd.alive()
        clock.t += 31.0
        assert not wd.alive()
    assert wd.alive()  # the call returned: a beat
    clock.t += 6.0
    assert not wd.alive()  # back to the normal allowance


def test_thread_pings_on_its_own(notify_socket):
    path, sock = notify_socket
    n = SystemdNotifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "2000000"})
    wd = HangWatchdog(n, allowance_s=30.0, interval_s=0.01).start()
    try:
        assert _fields(sock) == {"WATCHDOG": "1"}
    finally:
        wd.stop()


def test_a_full_socket_never_blocks_the_sender(tmp_path):
    path = tmp_path / "full.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))  # never read: its queue fills
    try:
        n = SystemdNotifier({"NOTIFY_SOCKET": str(path)})
        results = [n.notify(status="x" * 200) for _ in range(2000)]  # returns: it did not block
        assert results[0] is True
        assert results.count(False) == n.dropped > 0
        sock.recv(4096)
        assert n.notify(watchdog=1)  # room again
    finally:
        sock.close()


def test_wakes_often_pings_at_half_the_watchdog(notify_socket):
    """The thread may wake often (to flag a stuck estimate in time) yet pings systemd only every WatchdogSec/2."""
    path, sock = notify_socket
    clock = _Clock()
    n = SystemdNotifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "30000000"})
    ticks = []
    wd = HangWatchdog(n, allowance_s=60.0, interval_s=0.5, clock=clock, on_tick=lambda where, s: ticks.append(s))
    assert wd._interval == 0.5
    for _ in range(40):  # 20 s of wakes
        wd.beat()
        wd.check()
        clock.t += 0.5
    assert len(ticks) == 40 and wd.pings == 2  # at 0 s and at 15 s


def test_the_time_before_start_is_not_a_hang():
    # the model loads between the watchdog's construction and its start: that took tens of seconds
    # and the first tick reported a hang with every thread's stack
    now = [100.0]
    wd = HangWatchdog(SystemdNotifier({}), allowance_s=1.0, interval_s=0.001, clock=lambda: now[0])
    assert wd._interval == 0.01  # not woken every millisecond
    now[0] += 40.0
    wd.start()
    try:
        assert wd.check()
        now[0] += 2.0
        assert not wd.check()  # a real hang still shows
    finally:
        wd.stop()


def test_a_wedge_stops_the_pings_for_good_and_is_reported_once(notify_socket, tmp_path, caplog):
    path, sock = notify_socket
    clock = _Clock()
    n = SystemdNotifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "2000000"})
    with open(tmp_path / "stacks.txt", "w+") as stacks:
        wd = HangWatchdog(n, allowance_s=5.0, clock=clock, stacks_to=stacks)
        wd.beat()
        assert wd.check() and _fields(sock) == {"WATCHDOG": "1"}
        wd.wedge("camera 'left' (0) still in a device call")
        for _ in range(3):  # the loop beats on (it waits and reopens): no ping, one report
            clock.t += 2.0
            wd.beat("waiting to reopen the rig")
            assert not wd.check()
        stacks.seek(0)
        assert stacks.read().count("test_a_wedge_stops_the_pings_for_good") == 1
    assert [r.getMessage() for r in caplog.records if "still in a device call" in r.getMessage()] == [
        "camera 'left' (0) still in a device call; watchdog pings stopped for systemd to restart the service, "
        "thread stacks follow"]
    sock.settimeout(0.2)
    with pytest.raises(socket.timeout):
        sock.recv(4096)


def _fill(sock_path: str) -> SystemdNotifier:
    """A notifier whose socket's queue is full (STATUS messages, dropped once it is) and a state message's wait is
    long enough for a loaded host."""
    n = SystemdNotifier({"NOTIFY_SOCKET": sock_path}, retry_s=30.0)
    for _ in range(100_000):
        if not n.notify(status="x" * 200):
            return n
    raise AssertionError("the socket's queue never filled")


def _drain_when(sock: socket.socket, ready: Callable[[], bool], got: list[bytes]) -> threading.Thread:
    """A thread standing in for systemd: once ``ready()``, reads every datagram queued into ``got``."""
    def drain() -> None:
        wait_until(ready, timeout=30, what="the state message waiting for room")
        sock.settimeout(2.0)
        try:
            while True:
                got.append(sock.recv(4096))
        except socket.timeout:
            pass

    thread = threading.Thread(target=drain, daemon=True)
    thread.start()
    return thread


@pytest.mark.parametrize("fields, line", [({"ready": 1, "status": "running"}, b"READY=1"),
                                          ({"stopping": 1}, b"STOPPING=1"),
                                          ({"reloading": 1, "monotonic_usec": 5}, b"RELOADING=1")])
def test_a_state_message_waits_for_room_in_a_full_queue(tmp_path, fields, line):
    """READY, STOPPING and RELOADING are sent once systemd reads again (within retry_s): a READY lost to a full
    queue left the start to TimeoutStartSec and a restart."""
    path = tmp_path / "full.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    try:
        n = _fill(str(path))
        dropped, got = n.dropped, []
        reader = _drain_when(sock, lambda: n.held >= 1, got)
        assert n.notify(**fields) is True
        reader.join(timeout=30)
        assert any(d.startswith(line) for d in got), got[-3:]
        assert n.dropped == dropped and n.held == 1
    finally:
        sock.close()


def test_watchdog_and_status_are_still_dropped_at_once_and_a_state_message_past_its_bound(tmp_path):
    path = tmp_path / "full.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))  # never read
    try:
        n = _fill(str(path))
        dropped = n.dropped
        assert n.notify(watchdog=1) is False and n.notify(status="y") is False
        assert n.held == 0 and n.dropped == dropped + 2  # never waited for room
        quick = SystemdNotifier({"NOTIFY_SOCKET": str(path)}, retry_s=0.05)
        assert quick.notify(ready=1) is False  # returns: bounded
        assert quick.held == 1 and quick.dropped == 1
    finally:
        sock.close()


class _NoBuffersOnce:
    """A socket whose first send fails with ENOBUFS (the kernel out of buffers for the queue), then sends."""

    def __init__(self) -> None:
        self.sent: list[bytes] = []
        self.failed = False

    def sendto(self, data: bytes, address: str) -> None:
        if not self.failed:
            self.failed = True
            raise OSError(errno.ENOBUFS, "No buffer space available")
        self.sent.append(data)

    def close(self) -> None:
        pass


def test_enobufs_counts_as_a_full_queue_not_a_missing_socket(caplog):
    n = SystemdNotifier({"NOTIFY_SOCKET": "/run/systemd/notify"})
    n._sock = _NoBuffersOnce()  # type: ignore[assignment]
    with caplog.at_level(logging.WARNING):
        assert n.notify(ready=1) is True
    assert n._sock.sent == [b"READY=1"]
    assert "cannot notify" not in caplog.text
