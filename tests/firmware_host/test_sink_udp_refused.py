"""udp:// and vmc:// to a port no program has open: the refusals the network gives back are the sink's state.

Each datagram to a closed port on 127.0.0.1 draws an ICMP port unreachable. The sink's socket used to be
unconnected, which never hears of it: the sink read ``up``, every frame ``sent``, with nobody receiving (a
receiver not started, a typo in the port). Now it reads ``stalled`` naming the refusal, still sending every
frame, and the first frame after a receiver starts reaches it.
"""
from __future__ import annotations

import errno
import logging
import os
import socket
import time
from types import SimpleNamespace

import pytest

from firmware_host.errors import SinkUnavailableError, SinkWriteError
from firmware_host.protocol import Joints, StreamDecoder
from firmware_host.sinks import open_sink, udp_sink
from tests.firmware_host.joint_stream_helpers import FAST_BACKOFF, make_frame, wait_until

STALL_S = 0.2


def _closed_port() -> int:
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    return port


def _send_for(sink, seconds: float, first_seq: int) -> int:
    """Frames every 10 ms for ``seconds``, each written (or failed) before the next: a worker a loaded host held
    up found the sink's queue of 4 full, its oldest frame dropped (``dropped_queue``), where each frame's own
    write is what these tests count. Returns the next seq."""
    seq, end = first_seq, time.monotonic() + seconds
    while time.monotonic() < end:
        sink.send(make_frame(seq))
        assert sink.wait_drained(5), f"frame {seq} still queued after 5 s"
        seq += 1
        time.sleep(0.01)
    return seq


def _stats_after_sending(url: str, seconds: float):
    """The stats of a sink opened on ``url`` that sent frames for ``seconds`` and drained, and the frames sent."""
    sink = open_sink(url, backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        seq = _send_for(sink, seconds, 0)
        assert sink.wait_drained(5)
        return sink.stats(), seq
    finally:
        sink.close()


@pytest.mark.parametrize("scheme", ["udp", "vmc"])
def test_a_port_nobody_listens_on_reads_stalled_naming_the_refusal_and_every_frame_goes_out(
        scheme: str, caplog: pytest.LogCaptureFixture) -> None:
    port = _closed_port()
    caplog.set_level(logging.INFO, logger="firmware_host.sinks.udp_sink")
    stats, seq = _stats_after_sending(f"{scheme}://127.0.0.1:{port}?stall_s={STALL_S}", STALL_S + 0.3)
    assert stats.state == "stalled" and stats.stalled_s is not None and stats.stalled_s >= STALL_S
    assert stats.last_error is not None
    assert f"nothing receives at 127.0.0.1:{port}" in stats.last_error and "ICMP port unreachable" in stats.last_error
    # the refusals cost no frame: each is an earlier datagram's, and the one it failed is sent again
    assert stats.sent == seq and stats.dropped == 0 and stats.disconnects == 0
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "nothing receives at" in warnings[0]  # once, not per datagram


def test_a_receiver_that_starts_gets_the_next_frame_and_the_sink_reads_up_again(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    monkeypatch.setattr(udp_sink, "REFUSAL_QUIET_S", 0.3)
    monkeypatch.setattr(udp_sink, "REFUSAL_ANSWER_S", 0.1)
    port = _closed_port()
    caplog.set_level(logging.INFO, logger="firmware_host.sinks.udp_sink")
    sink = open_sink(f"udp://127.0.0.1:{port}?stall_s={STALL_S}", backoff=FAST_BACKOFF)
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        assert sink.wait_connected(5)
        seq = _send_for(sink, STALL_S + 0.2, 0)
        assert sink.wait_drained(5)
        assert sink.stats().state == "stalled"
        # the last datagram's refusal waits on the socket for the next send: it must not cost that frame
        rx.bind(("127.0.0.1", port))
        rx.settimeout(5)
        first_after = seq
        sink.send(make_frame(first_after))
        received = [e.message for e in StreamDecoder().feed(rx.recv(2048))]
        while not any(isinstance(m, Joints) for m in received):
            received += [e.message for e in StreamDecoder().feed(rx.recv(2048))]
        assert [m.header.seq for m in received if isinstance(m, Joints)] == [first_after]
        _send_for(sink, 1.0, first_after + 1)  # past REFUSAL_QUIET_S + REFUSAL_ANSWER_S with none refused
        wait_until(lambda: sink.stats().state == "up", 5, "the sink up again")
    finally:
        stats = sink.close()
        rx.close()
    assert stats.dropped == 0
    assert any("no datagram refused" in r.getMessage() for r in caplog.records if r.levelno == logging.INFO)


def test_datagrams_further_apart_than_the_quiet_time_keep_the_refusal_and_read_stalled(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    # the rig down: only the idle STATUS goes out, every status_s. Each is refused, but with status_s past
    # REFUSAL_QUIET_S the time between them ended the refusal: a WARNING and an INFO at every datagram, and the
    # sink never read stalled. The quiet is judged by a datagram that draws no refusal, not by the time passed.
    monkeypatch.setattr(udp_sink, "REFUSAL_QUIET_S", 0.3)
    sent_at: list[float] = []
    real_send = udp_sink.DatagramLink.send

    def send(link, datagram: bytes) -> None:
        real_send(link, datagram)
        sent_at.append(time.monotonic())

    monkeypatch.setattr(udp_sink.DatagramLink, "send", send)
    port = _closed_port()
    caplog.set_level(logging.INFO, logger="firmware_host.sinks.udp_sink")
    sink = open_sink(f"udp://127.0.0.1:{port}?status_s=0.5&stall_s={STALL_S}", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        # three idle writes (a HELLO and a STATUS each), whatever the load: the gaps between them pass 0.3 s
        wait_until(lambda: len(sent_at) >= 6 and sent_at[-1] - sent_at[0] > 0.9, 10, "three idle writes")
        stats = sink.stats()
    finally:
        sink.close()
    assert stats.state == "stalled" and "nothing receives at" in (stats.last_error or "")
    said = [r.getMessage() for r in caplog.records if r.name == "firmware_host.sinks.udp_sink"]
    assert len(said) == 1 and "nothing receives at" in said[0]  # one WARNING, no "receiver ... again"


def test_the_refusal_waiting_on_the_socket_does_not_cost_the_datagram_it_fails() -> None:
    # the refusal of one datagram is reported by the next send, which it fails unsent: a receiver that starts
    # in between must still get that next one (sent again at once)
    port = _closed_port()
    link = udp_sink.DatagramLink(f"udp://127.0.0.1:{port}", "127.0.0.1", port)
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        link.open()
        link.send(b"refused\x00")
        time.sleep(0.05)  # the ICMP answer is on the socket
        rx.bind(("127.0.0.1", port))
        rx.settimeout(5)
        link.send(b"received\x00")
        assert rx.recv(64) == b"received\x00"
        refusing = link.refusing()
        assert refusing is not None and "ICMP port unreachable" in refusing[1]
    finally:
        link.close()
        rx.close()


class _ScriptedSocket:
    """Stands in for the link's socket: each send raises the next error of ``errors`` (None: sent)."""

    def __init__(self, errors: list) -> None:
        self.errors, self.sent = list(errors), []

    def send(self, datagram: bytes) -> int:
        error = self.errors.pop(0) if self.errors else None
        if error is not None:
            raise OSError(error, os.strerror(error))
        self.sent.append(datagram)
        return len(datagram)

    def close(self) -> None:
        pass


def _scripted_link(errors: list) -> tuple[udp_sink.DatagramLink, _ScriptedSocket]:
    link = udp_sink.DatagramLink("udp://192.0.2.7:9870", "192.0.2.7", 9870)
    sock = _ScriptedSocket(errors)
    link._sock, link._family, link._addr = sock, socket.AF_INET, ("192.0.2.7", 9870)
    return link, sock


def test_a_host_unreachable_an_icmp_answer_left_is_kept_and_the_datagram_sent() -> None:
    link, sock = _scripted_link([errno.EHOSTUNREACH])
    link.send(b"frame\x00")
    assert sock.sent == [b"frame\x00"]
    refusing = link.refusing()
    assert refusing is not None and refusing[1].startswith("192.0.2.7:9870 is unreachable: No route to host")


def test_no_route_on_the_send_itself_is_a_link_lost_not_a_refusal() -> None:
    # the device's own address changed under the connected socket: every send fails the same way; the sink
    # reopens its socket (SinkUnavailableError), and no ICMP answer is claimed
    link, sock = _scripted_link([errno.ENETUNREACH, errno.ENETUNREACH])
    with pytest.raises(SinkUnavailableError, match="Network is unreachable"):
        link.send(b"frame\x00")
    assert sock.sent == [] and link.refusing() is None


@pytest.mark.parametrize(("again", "raised"), [
    (errno.EAGAIN, SinkWriteError),  # the send buffer full: this datagram lost, the link up
    (errno.ECONNREFUSED, SinkWriteError),  # refused again at once
    (errno.ENETUNREACH, SinkUnavailableError),  # the route gone meanwhile: the socket is made again
    (errno.EPERM, SinkUnavailableError),  # a firewall's refusal of this datagram
])
def test_a_refusal_is_kept_whatever_the_datagram_sent_again_meets(
        again: int, raised: type, caplog: pytest.LogCaptureFixture) -> None:
    # The ICMP port unreachable an earlier datagram drew fails this send unsent; the send repeated met a full
    # buffer (or another error): the error was raised and the refusal never recorded, so the sink named only
    # the full buffer and counted no refusal. It is recorded now, whatever the repeat meets, and said once.
    caplog.set_level(logging.INFO, logger="firmware_host.sinks.udp_sink")
    link, sock = _scripted_link([errno.ECONNREFUSED, again])
    with pytest.raises(raised) as failed:
        link.send(b"frame\x00")
    assert sock.sent == []
    refusing = link.refusing()
    assert refusing is not None and refusing[1].startswith("nothing receives at 192.0.2.7:9870"), refusing
    assert "ICMP port unreachable" in refusing[1]
    if raised is SinkWriteError:  # the sink's last error for this datagram names the refusal too
        assert "nothing receives at 192.0.2.7:9870" in str(failed.value)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "nothing receives at" in warnings[0], warnings


def test_a_host_unreachable_met_by_both_sends_is_no_refusal_whatever_its_kind() -> None:
    # host unreachable, then network unreachable: the sends' own (no route now), no ICMP answer claimed
    link, sock = _scripted_link([errno.EHOSTUNREACH, errno.ENETUNREACH])
    with pytest.raises(SinkUnavailableError, match="Network is unreachable"):
        link.send(b"frame\x00")
    assert sock.sent == [] and link.refusing() is None


def test_refusals_within_one_clock_tick_warn_once(monkeypatch: pytest.MonkeyPatch,
                                                  caplog: pytest.LogCaptureFixture) -> None:
    # The WARNING was given when a refusal's time equalled its stretch's first: a second refusal read in the same
    # tick of a coarse clock (or the two a send with a refused repeat notes) warned again.
    monkeypatch.setattr(udp_sink.time, "monotonic", lambda: 100.0)
    caplog.set_level(logging.INFO, logger="firmware_host.sinks.udp_sink")
    link, sock = _scripted_link([errno.ECONNREFUSED, None, errno.ECONNREFUSED, None])
    link.send(b"one\x00")
    link.send(b"two\x00")
    assert sock.sent == [b"one\x00", b"two\x00"] and link.refusing()[0] == 100.0
    assert len([r for r in caplog.records if r.levelno == logging.WARNING]) == 1


def test_a_sink_whose_refused_datagrams_meet_a_full_buffer_reads_stalled_naming_the_refusal(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # every send: an earlier datagram's ICMP port unreachable, then a full send buffer on the repeat. The sink
    # read stalled (its writes failing) naming only "socket send buffer full": nobody told it nothing listens.
    script = [errno.ECONNREFUSED, errno.EAGAIN] * 1000
    monkeypatch.setattr(udp_sink.DatagramLink, "_connected_socket", lambda link, family, addr: _ScriptedSocket(script))
    stats, seq = _stats_after_sending(f"udp://192.0.2.7:9870?stall_s={STALL_S}", STALL_S + 0.2)
    assert stats.state == "stalled" and stats.stalled_s is not None and stats.stalled_s >= STALL_S
    assert "nothing receives at 192.0.2.7:9870" in (stats.last_error or ""), stats.last_error
    assert stats.sent == 0 and stats.dropped_error == seq and stats.disconnects == 0


def test_a_datagram_is_not_judged_unrefused_before_its_answer_could_come(monkeypatch: pytest.MonkeyPatch,
                                                                          caplog: pytest.LogCaptureFixture) -> None:
    # vmc:// sends a frame as two datagrams back to back and nothing while the rig is down. After a pause past
    # REFUSAL_QUIET_S the frame's second send found no refusal waiting, as the first datagram's ICMP answer was
    # still on its way, and ended the refusals: "a receiver is at ... again" (and the sink up) with nobody there,
    # then a new WARNING at the next frame. A datagram draws no refusal only if none is waiting once its answer
    # had time to come back (REFUSAL_ANSWER_S).
    clock = [100.0]
    monkeypatch.setattr(udp_sink, "time", SimpleNamespace(monotonic=lambda: clock[0]))  # this module's clock alone
    caplog.set_level(logging.INFO, logger="firmware_host.sinks.udp_sink")
    refused, sent = errno.ECONNREFUSED, None
    link, sock = _scripted_link([refused, sent,  # a frame's first datagram meets an earlier one's refusal
                                 sent,  # its second
                                 sent, sent,  # the rig down 10 s, then a frame: the refusal of its first is on its way
                                 refused, sent])  # the next frame meets it
    link.send(b"bundle 1\x00")
    link.send(b"bundle 2\x00")
    clock[0] += 10.0
    link.send(b"bundle 1\x00")
    clock[0] += 1e-5
    link.send(b"bundle 2\x00")
    refusing = link.refusing()
    assert refusing is not None and refusing[0] == 100.0  # the stretch goes on: nothing could have answered yet
    clock[0] += 0.033
    link.send(b"bundle 1\x00")
    assert link.refusing() is not None and link.refusing()[0] == 100.0
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1 and "nothing receives at" in said[0], said  # one WARNING, no "receiver ... again"


def test_a_datagram_that_drew_no_refusal_once_its_answer_could_come_ends_the_refusals(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    clock = [100.0]
    monkeypatch.setattr(udp_sink, "time", SimpleNamespace(monotonic=lambda: clock[0]))  # this module's clock alone
    caplog.set_level(logging.INFO, logger="firmware_host.sinks.udp_sink")
    link, sock = _scripted_link([errno.ECONNREFUSED, None])
    link.send(b"refused before\x00")
    while link.refusing() is not None and clock[0] < 110.0:  # a 30 fps stream that draws no refusal
        clock[0] += 0.033
        link.send(b"frame\x00")
    assert link.refusing() is None
    # not before a datagram sent REFUSAL_QUIET_S after the refusal had REFUSAL_ANSWER_S to draw one, nor long after
    assert udp_sink.REFUSAL_QUIET_S + udp_sink.REFUSAL_ANSWER_S <= clock[0] - 100.0
    assert clock[0] - 100.0 < udp_sink.REFUSAL_QUIET_S + udp_sink.REFUSAL_ANSWER_S + 0.1
    assert any("no datagram refused" in r.getMessage() for r in caplog.records if r.levelno == logging.INFO)
