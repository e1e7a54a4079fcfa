"""udp:// (and vmc://) host names: IPv4 preferred, looked up again while streaming, never holding up the frames.

``socket.getaddrinfo`` is replaced by a scripted resolver for the name ``robot.test``; the datagrams go
to real sockets on the loopback.
"""
from __future__ import annotations

import socket
import threading
import time
from typing import Any

import pytest

from firmware_host.protocol import Joints, StreamDecoder
from firmware_host.sinks import open_sink
from firmware_host.sinks import udp_sink
from tests.firmware_host.joint_stream_helpers import FAST_BACKOFF, make_frame, wait_until

NAME = "robot.test"


@pytest.fixture
def fast_lookups(monkeypatch: pytest.MonkeyPatch) -> None:
    """Lets these tests look a name up every few ms: the floor (``MIN_RESOLVE_S``, 1 s) would make each wait
    seconds for the lookups it watches."""
    monkeypatch.setattr(udp_sink, "MIN_RESOLVE_S", 0.001)


class Resolver:
    """Answers ``robot.test`` with ``answers`` (sockaddrs, in glibc's order); other names as usual."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, *answers: tuple) -> None:
        self.answers = list(answers)
        self.calls = 0
        self.release = threading.Event()  # cleared: lookups of the name hang until it is set
        self.release.set()
        self._real = socket.getaddrinfo
        monkeypatch.setattr(udp_sink.socket, "getaddrinfo", self)

    def __call__(self, host: Any, port: Any, *args: Any, **kwargs: Any) -> list:
        if host != NAME:
            return self._real(host, port, *args, **kwargs)
        self.calls += 1
        self.release.wait(10)
        return [(socket.AF_INET6 if ":" in addr[0] else socket.AF_INET, socket.SOCK_DGRAM, 17, "", addr)
                for addr in self.answers]


def receiver() -> socket.socket:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.setblocking(False)
    return rx


def joints_read(rx: socket.socket) -> list[int]:
    seqs = []
    while True:
        try:
            data = rx.recv(4096)
        except BlockingIOError:
            return seqs
        seqs += [e.message.header.seq for e in StreamDecoder().feed(data) if isinstance(e.message, Joints)]


def test_a_name_listed_with_ipv6_first_is_sent_to_its_ipv4_address(monkeypatch: pytest.MonkeyPatch) -> None:
    # glibc lists ::1 first for localhost on many hosts; a receiver bound to 0.0.0.0 never hears it
    rx = receiver()
    port = rx.getsockname()[1]
    Resolver(monkeypatch, ("::1", port, 0, 0), ("127.0.0.1", port))
    received: list[int] = []

    def three_read() -> bool:
        received.extend(joints_read(rx))
        return len(received) >= 3

    sink = open_sink(f"udp://{NAME}:{port}?queue=16", backoff=FAST_BACKOFF)
    try:
        for seq in range(3):
            sink.send(make_frame(seq))
        assert sink.wait_drained(5)
        wait_until(three_read, what="3 frames")
    finally:
        sink.close()
        rx.close()
    assert received == [0, 1, 2]


def test_an_ipv6_only_name_or_literal_still_uses_ipv6() -> None:
    assert udp_sink.resolve("udp://[::1]:9", "::1", 9)[0] == socket.AF_INET6


@pytest.mark.parametrize("scheme", ["udp", "vmc"])
def test_a_name_is_looked_up_again_without_holding_up_the_frames(
        monkeypatch: pytest.MonkeyPatch, scheme: str, fast_lookups: None) -> None:
    old, new = receiver(), receiver()
    resolver = Resolver(monkeypatch, old.getsockname())
    sink = open_sink(f"{scheme}://{NAME}:{old.getsockname()[1]}?queue=64&resolve_s=0.05", backoff=FAST_BACKOFF)
    seq = 0

    def send_until(predicate: Any, what: str) -> None:
        def step() -> bool:
            nonlocal seq
            sink.send(make_frame(seq))
            seq += 1
            time.sleep(0.005)
            return predicate()
        wait_until(step, what=what)

    try:
        assert sink.wait_connected(5)
        resolver.release.clear()  # the next lookup hangs (a name that went away: mDNS waits seconds)
        send_until(lambda: resolver.calls >= 2, "a second lookup")
        sent_before = sink.stats().sent
        send_until(lambda: sink.stats().sent >= sent_before + 10, "frames while the lookup hangs")
        assert old.recv(4096)  # still to the address it had
        resolver.answers = [new.getsockname()]  # the robot got a new address (DHCP lease, mDNS)
        resolver.release.set()
        send_until(lambda: new_got_one(new), "datagrams at the new address")
    finally:
        stats = sink.close()
        old.close()
        new.close()
    assert stats.connects == 1 and stats.dropped == 0  # no reconnect: the socket just sends elsewhere


def new_got_one(rx: socket.socket) -> bool:
    try:
        return bool(rx.recv(4096))
    except BlockingIOError:
        return False


def test_a_lookup_started_before_a_reconnect_does_not_undo_its_answer(monkeypatch: pytest.MonkeyPatch) -> None:
    """A slow lookup of the old connection that answers after close() + open() is stale: the datagrams go
    on to the address the new open() found."""
    old_rx, new_rx = receiver(), receiver()
    answer = [old_rx.getsockname()]
    gate = threading.Event()
    real = socket.getaddrinfo

    def getaddrinfo(host: Any, port: Any, *args: Any, **kwargs: Any) -> list:
        if host != NAME:
            return real(host, port, *args, **kwargs)
        addr = answer[0]  # the answer as of the moment the lookup starts
        if threading.current_thread().name.startswith("resolve"):
            gate.wait(10)
        return [(socket.AF_INET, socket.SOCK_DGRAM, 17, "", addr)]

    monkeypatch.setattr(udp_sink.socket, "getaddrinfo", getaddrinfo)
    link = udp_sink.DatagramLink("udp://robot.test:1", NAME, 1, resolve_s=0.001)
    try:
        link.open()
        time.sleep(0.01)
        link.send(b"a")  # starts a lookup in the background; it hangs, holding the old answer
        wait_until(lambda: link._looking_up, what="a lookup in flight")
        link.close()
        answer[0] = new_rx.getsockname()  # the robot moved while the link was down
        link.open()
        gate.set()
        wait_until(lambda: not link._looking_up, what="the stale lookup to finish")
        link.send(b"b")
        time.sleep(0.05)
        got_new = new_rx.recv(100)
        assert got_new == b"b"
        assert old_rx.recv(100) == b"a"
        with pytest.raises(BlockingIOError):
            old_rx.recv(100)  # nothing after the reconnect went to the old address
    finally:
        gate.set()
        link.close()
        old_rx.close()
        new_rx.close()


class RotatingResolver(Resolver):
    """Round-robin DNS: each answer lists the same addresses, the first moved to the end."""

    def __call__(self, host: Any, port: Any, *args: Any, **kwargs: Any) -> list:
        infos = super().__call__(host, port, *args, **kwargs)
        if host == NAME:
            self.answers = self.answers[1:] + self.answers[:1]
        return infos


@pytest.mark.parametrize("scheme", ["udp", "vmc"])
def test_a_name_with_several_addresses_stays_on_the_one_in_use(monkeypatch: pytest.MonkeyPatch, scheme: str,
                                                                fast_lookups: None) -> None:
    # Each lookup of a round-robin name (or a robot on Wi-Fi and Ethernet) lists its addresses in another
    # order: taking the first every resolve_s moved the stream from one to the other and back.
    first, second = receiver(), receiver()
    resolver = RotatingResolver(monkeypatch, first.getsockname(), second.getsockname())
    sink = open_sink(f"{scheme}://{NAME}:{first.getsockname()[1]}?queue=64&resolve_s=0.01", backoff=FAST_BACKOFF)
    seq = 0

    def step() -> bool:
        nonlocal seq
        sink.send(make_frame(seq))
        seq += 1
        time.sleep(0.005)
        return resolver.calls >= 6

    try:
        assert sink.wait_connected(5)
        wait_until(step, what="several lookups")
        assert sink.wait_drained(5)
        assert new_got_one(first)
        with pytest.raises(BlockingIOError):
            second.recv(4096)  # listed by every lookup, but never the address in use
    finally:
        sink.close()
        first.close()
        second.close()
    answer = [(socket.AF_INET, socket.SOCK_DGRAM, 17, "", a) for a in (("10.0.0.2", 9), ("10.0.0.1", 9))]
    assert udp_sink.ipv4_first(answer, keep=("10.0.0.1", 9)) == (socket.AF_INET, ("10.0.0.1", 9))
    assert udp_sink.ipv4_first(answer, keep=("10.0.0.3", 9)) == (socket.AF_INET, ("10.0.0.2", 9))  # gone: the first
    v6_first = [(socket.AF_INET6, socket.SOCK_DGRAM, 17, "", ("::1", 9, 0, 0)), *answer]
    assert udp_sink.ipv4_first(v6_first, keep=("::1", 9, 0, 0))[0] == socket.AF_INET  # IPv4 still preferred


@pytest.mark.parametrize("scheme", ["udp", "vmc"])
@pytest.mark.parametrize("value", ["1e-9", "0.05", "0.999"])
def test_a_lookup_period_below_the_floor_is_refused_by_name(scheme: str, value: str) -> None:
    # resolve_s=1e-9 was taken: a name server asked once for every frame sent
    from firmware_host.errors import SinkConfigError

    with pytest.raises(SinkConfigError) as info:
        open_sink(f"{scheme}://{NAME}:9?resolve_s={value}")
    assert info.value.field == "resolve_s" and info.value.value == float(value)
    assert f"at least {udp_sink.MIN_RESOLVE_S:g} seconds" in str(info.value)


@pytest.mark.parametrize("scheme", ["udp", "vmc"])
def test_a_lookup_period_at_the_floor_is_taken(scheme: str) -> None:
    sink = open_sink(f"{scheme}://127.0.0.1:9?resolve_s={udp_sink.MIN_RESOLVE_S:g}")
    try:
        assert sink._link.resolve_s == udp_sink.MIN_RESOLVE_S  # type: ignore[attr-defined]
    finally:
        sink.close()
