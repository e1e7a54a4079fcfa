"""The C receiver and ``ghnerf-listen`` count one stream alike.

The stream is what a receiver meets in the field: a producer's output reopened near the 2^32 wrap (its HELLO
carries the producer's last number), a frame the sender dropped (DROPPED), then the producer restarting: a
boot banner, HELLO and STATUS with seq 2^32 - 1 (no frame sent yet), JOINTS from 0 with a reordered datagram,
a duplicate, a CRC-corrupted packet, a write cut short and bytes glued to a frame. The C side is ``ghj_dump``
(every frame's result and the decoder's counters) and the code in docs/c-decoder.md, run as written: the UART
example counts lost frames, the UDP one feeds datagrams. Compared are only the counters both define the same
way: the decoder's (frames, messages, skipped, each error), JOINTS received, and seq gaps where no datagram
came late (a late one is counted by rules still being settled for the listener; the UART example never sees
one).
"""
from __future__ import annotations

import io
import json
import random
import socket
import struct
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from firmware_host import listen
from firmware_host.protocol import Flags, Hello, Joints, MsgType, Status, encode, make_header
from firmware_host.protocol.constants import ERROR_CODES
from tests.clients.c_build import C_DIR, compile_c, doc_code_blocks, require_compiler, sanitizer_flags
from tests.clients.test_c_doc_examples import C_BOARD

NONE_SENT = 2**32 - 1  # HELLO/STATUS seq before the producer's first frame (docs/protocol.md, section 3)

# --- the stream ---------------------------------------------------------------------------------------------


def _joints(seq: int, flags: int = 0) -> bytes:
    xyz = np.full((25, 3), seq % 1000, np.int16)
    return encode(Joints(make_header(MsgType.JOINTS, seq, 1000 + seq, 2000 + seq, flags), 0, xyz,
                         np.full(25, 200, np.uint8), np.zeros(25, bool)))


def _hello(seq: int, send_us: int = 20) -> bytes:
    return encode(Hello(make_header(MsgType.HELLO, seq, 10, send_us), 1, 0, 25, 0, 0, "rig-A1", ("left", "right")))


def _status(seq: int) -> bytes:
    return encode(Status(make_header(MsgType.STATUS, seq, 10, 30), 0, 0, 0, 0, 0))


def _crc_corrupted(seq: int) -> bytes:
    frame = bytearray(_joints(seq))
    frame[40] ^= 0x04  # a payload byte, nonzero either way: the frame stays COBS-valid
    assert frame[40] != 0
    return bytes(frame)


def _cut(seq: int) -> bytes:
    return _joints(seq)[:90]  # a write cut short: no delimiter; the sender's next write begins with 0x00


def datagrams(*, late: bool) -> tuple[list[bytes], int, int]:
    """The stream as the sender's writes (one datagram each on UDP), the JOINTS among them that decode, and
    the frames lost on the way (seq gaps). ``late``: frame 4 arrives after frame 5 instead of before it."""
    writes: list[bytes] = [b"\x00", _hello(2**32 - 3), _status(2**32 - 3)]  # an output reopened near the wrap
    writes += [_joints(s) for s in (2**32 - 2, 2**32 - 1, 0, 1)]  # the wrap is no gap
    writes += [_joints(3, Flags.DROPPED)]  # 2 dropped by the sender: a gap of 1
    writes += [_joints(s) for s in range(4, 41)]  # far enough from 0 that a restart is no late datagram
    good, lost = 4 + 1 + 37, 1
    # The producer restarts: its boot banner, then a leading 0x00 ends that garbage as one bad frame.
    writes += [b"ghnerf-daemon 1.0 starting\r\n", b"\x00", _hello(NONE_SENT), _status(NONE_SENT)]
    writes += [_joints(s) for s in (0, 1, 2, 3)]  # 40 -> 0: a restart, no gap; HELLO's 2^32 - 1 counts no frame
    writes += [_joints(5), _joints(4)] if late else [_joints(4), _joints(5)]
    writes += [_joints(5)]  # a duplicate: no gap
    writes += [_crc_corrupted(6), _joints(7)]  # 6 lost to the CRC
    writes += [_cut(8), b"\x00" + _joints(9)]  # 8 cut short, its fragment discarded at the next 0x00
    writes += [b"\x01\x02\x03" + _joints(10), _joints(11)]  # stray bytes glued to 10: both lost
    good, lost = good + 4 + 2 + 1 + 1 + 1 + 1, lost + 3
    return writes, good, lost


# --- the C side -------------------------------------------------------------------------------------------------

# The UART example of docs/c-decoder.md, fed from stdin: its main loop calls idle() with the receive ring
# drained, so idle() plays the UART, and at the end of the input prints what the example counted.
UART_DRIVER = r"""
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
static ghj_doc_usart usart_regs;
ghj_doc_usart *USART1 = &usart_regs;
void board_init(void) {}
void uart_init(unsigned long baud) { (void)baud; }
void led_blink(unsigned fault) { (void)fault; }
void arm_move_to(int16_t x, int16_t y, int16_t z) { (void)x; (void)y; (void)z; }
void idle(void)
{
    unsigned n = 0;
    int c;
    while (n < RX_SIZE - 1u && (c = getchar()) != EOF) {
        usart_regs.RDR = (uint8_t)c;
        USART1_IRQHandler();
        n++;
    }
    if (n == 0u) {
        printf("{\"lost_frames\":%" PRIu32 ",\"messages\":%" PRIu32 ",\"frames\":%" PRIu32 "}\n", lost_frames,
               dec.stats.messages, dec.stats.frames);
        exit(0);
    }
}
"""

# The UDP example, fed datagrams from stdin as [u16 length, little-endian][payload]; prints the decoder's
# counters and the JOINTS it handed over. The UART example before it declares dec and pkt (its main renamed).
UDP_DRIVER = r"""
#undef main
#include <inttypes.h>
#include <stdio.h>
static uint32_t joints_seen;
void handle_packet(const ghj_packet *p) { if (p->header.msg_type == GHJ_MSG_JOINTS) joints_seen++; }
void board_init(void) {}
void uart_init(unsigned long baud) { (void)baud; }
void led_blink(unsigned fault) { (void)fault; }
void arm_move_to(int16_t x, int16_t y, int16_t z) { (void)x; (void)y; (void)z; }
void idle(void) {}
ghj_doc_usart *USART1;
int main(void)
{
    static uint8_t datagram[65535];
    uint8_t len_le[2];
    ghj_init(&dec);
    while (fread(len_le, 1, 2, stdin) == 2) {
        size_t len = (size_t)len_le[0] | ((size_t)len_le[1] << 8);
        if (fread(datagram, 1, len, stdin) != len) return 2;
        on_udp_datagram(datagram, len);
    }
    printf("{\"joints\":%" PRIu32 ",\"stats\":{\"frames\":%" PRIu32 ",\"messages\":%" PRIu32 ",\"skipped\":%" PRIu32
           ",\"oversize\":%" PRIu32 ",\"cobs\":%" PRIu32 ",\"short\":%" PRIu32 ",\"crc\":%" PRIu32
           ",\"version\":%" PRIu32 ",\"malformed\":%" PRIu32 "}}\n", joints_seen, dec.stats.frames,
           dec.stats.messages, dec.stats.skipped, dec.stats.err_oversize, dec.stats.err_cobs, dec.stats.err_short,
           dec.stats.err_crc, dec.stats.err_version, dec.stats.err_malformed);
    return 0;
}
"""


def _build_doc_program(tmp_path: Path, name: str, source: str, extra: list[str]) -> Path:
    cc = require_compiler()
    src = tmp_path / f"{name}.c"
    src.write_text(source)
    return compile_c(cc, tmp_path / name, [src, C_DIR / "ghjoints.c"], [*extra, *sanitizer_flags(cc, tmp_path)])


@pytest.fixture(scope="module")
def uart_example(tmp_path_factory: pytest.TempPathFactory) -> Path:
    uart = doc_code_blocks("c")[0]
    return _build_doc_program(tmp_path_factory.mktemp("uart"), "uart_example", C_BOARD + uart + UART_DRIVER, [])


@pytest.fixture(scope="module")
def udp_example(tmp_path_factory: pytest.TempPathFactory) -> Path:
    blocks = doc_code_blocks("c")
    udp = [b for b in blocks if "on_udp_datagram" in b]
    assert udp, "docs/c-decoder.md has no UDP example (on_udp_datagram)"
    source = C_BOARD + blocks[0] + "void handle_packet(const ghj_packet *p);\n" + udp[0] + UDP_DRIVER
    return _build_doc_program(tmp_path_factory.mktemp("udp"), "udp_example", source, ["-Dmain=doc_uart_main"])


def _run_c(exe: Path, data: bytes, *args: str) -> list[dict[str, Any]]:
    proc = subprocess.run([str(exe), *args], input=data, capture_output=True, timeout=60)
    assert proc.returncode == 0 and proc.stderr == b"", proc.stderr.decode(errors="replace")
    return [json.loads(line) for line in proc.stdout.decode().splitlines()]


# --- the listener side ----------------------------------------------------------------------------------------


class _Replay:
    """A port that hands the listener the given reads, then ends it as Ctrl-C does."""

    def __init__(self, reads: list[bytes]) -> None:
        self.reads = list(reads)

    def read(self, timeout_s: float) -> bytes:
        if not self.reads:
            raise KeyboardInterrupt
        return self.reads.pop(0)


class _FirstN:
    """A real UDP port of the listener, ended (as Ctrl-C does) after ``n`` datagrams were read."""

    def __init__(self, port: Any, n: int) -> None:
        self.port, self.left = port, n

    def read(self, timeout_s: float) -> bytes:
        if self.left == 0:
            raise KeyboardInterrupt
        data = self.port.read(5.0)
        assert data, "a datagram sent over loopback did not arrive"
        self.left -= 1
        return data


def _listener(port: Any) -> tuple[list[dict[str, Any]], listen.Tally]:
    out = io.StringIO()
    tally = listen.listen(port, seconds=None, as_json=True, out=out)
    return [json.loads(line) for line in out.getvalue().splitlines()], tally


def _counters(events: list[dict[str, Any]]) -> dict[str, int]:
    """The decoder counters as the listener's JSON lines give them (one line per non-empty frame)."""
    counts = {"frames": len(events), "messages": 0, "skipped": 0, **dict.fromkeys(ERROR_CODES, 0)}
    for e in events:
        key = "messages" if "type" in e else "skipped" if "skipped" in e else e["error"]
        counts[key] += 1
    return counts


# --- the tests -----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("chunk", [1, 7, 4096])
def test_stream_events_and_counters_agree(ghj_dump: Path, tmp_path: Path, chunk: int) -> None:
    writes, good, _ = datagrams(late=True)
    data = b"".join(writes)
    path = tmp_path / "stream.bin"
    path.write_bytes(data)
    *c_events, c_stats = _run_c(ghj_dump, b"", "-c", str(chunk), str(path))
    rng = random.Random(chunk)
    cuts = sorted(rng.sample(range(1, len(data)), 40))
    py_events, tally = _listener(_Replay([data[a:b] for a, b in zip([0, *cuts], [*cuts, len(data)])]))

    assert c_events == py_events  # every frame classified alike, every field decoded alike
    assert c_stats["stats"] == _counters(py_events)
    joints = sum(e.get("type") == "JOINTS" for e in c_events)
    assert joints == tally.total_joints == good
    # What the stream holds, so the comparison is not of two empty lists: the banner, the corrupted, cut and
    # glued frames are one error each.
    assert [e["error"] for e in c_events if "error" in e] == ["cobs", "crc", "cobs", "crc"]
    assert [e["seq"] for e in c_events if e.get("type") in ("HELLO", "STATUS")] == [2**32 - 3] * 2 + [NONE_SENT] * 2


def test_uart_example_counts_lost_frames_as_the_listener_does(ghj_dump: Path, uart_example: Path) -> None:
    """docs/c-decoder.md's loss count: the wrap, HELLO/STATUS 2^32 - 1 before JOINTS 0, the restart and the
    duplicate are no gaps; the dropped, corrupted, cut and glued frames are. (In order: a late datagram is
    counted by other rules, and the UART example never meets one.)"""
    writes, good, lost = datagrams(late=False)
    data = b"".join(writes)
    [uart] = _run_c(uart_example, data)
    *c_events, c_stats = _run_c(ghj_dump, data, "-")
    _, tally = _listener(_Replay([data]))
    assert uart["lost_frames"] == tally.total_gaps == lost
    assert tally.total_joints == good
    assert uart["messages"] == c_stats["stats"]["messages"] and uart["frames"] == c_stats["stats"]["frames"]


def test_hello_before_the_first_frame_is_no_gap(uart_example: Path) -> None:
    """The smallest case of the rule the daemon now follows: HELLO and STATUS carry 2^32 - 1 before JOINTS 0,
    and the last frame's number after it."""
    data = b"\x00" + _hello(NONE_SENT) + _status(NONE_SENT) + _joints(0)
    data += _status(0) + _hello(0) + _joints(1) + _joints(3)  # the last frame sent, then one gap
    [uart] = _run_c(uart_example, data)
    _, tally = _listener(_Replay([data]))
    assert uart["lost_frames"] == tally.total_gaps == 1


def test_udp_example_and_listener_agree_datagram_by_datagram(udp_example: Path) -> None:
    """One sender write per datagram, over loopback to the listener's own UDP port. A datagram without its
    0x00 (the cut write, the banner) is ended where it stops, by the listener and by docs/c-decoder.md's UDP
    example alike; fed to the decoder as it came, it took the next datagram's frame down with it."""
    writes, good, _ = datagrams(late=True)
    writes = [w for w in writes if w != b"\x00"]  # the sender's leading 0x00 is for byte streams

    port = listen.open_port("udp://127.0.0.1:0", ephemeral=True)
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for w in writes:
                tx.sendto(w, port.address)
        py_events, tally = _listener(_FirstN(port, len(writes)))
    finally:
        port.close()
    [c] = _run_c(udp_example, b"".join(struct.pack("<H", len(w)) + w for w in writes))
    assert c["stats"] == _counters(py_events)
    assert c["joints"] == tally.total_joints == good


@pytest.mark.parametrize("old_last", [2**32 - 8, 2**31 + 5, 30], ids=["8-before-wrap", "past-2^31", "30"])
def test_restart_after_hello_none_sent_starts_a_new_numbering(uart_example: Path, old_last: int) -> None:
    """A producer that restarts with its old seq within 32 of the new one (or past 2^31 frames): only the HELLO of
    seq 2^32 - 1 tells that apart from a gap or a late datagram. Before it, 2^32 - 8 -> 0 was a step of 8 (7
    frames lost) and 2^31 + 5 -> 0 one of 2^31 - 5; 30 -> 0 the listener read as late. The stream loses 1 frame
    before the restart and 1 after it; a second restart, 5 -> 0, loses none; a third loses its first two, counted
    from the seq its HELLO carries."""
    data = b"\x00" + _hello(old_last - 3) + _joints(old_last - 2) + _joints(old_last)  # old_last - 1 lost
    # each restarted producer's HELLO is written after its predecessor's frames (one monotonic clock): the listener
    # takes one written among them for a duplicated or reordered datagram
    later = 1 << 40
    data += _hello(NONE_SENT, later) + _status(NONE_SENT)  # the restarted producer, before its first frame
    data += b"".join(_joints(s) for s in (0, 1, 2, 4, 5))  # 3 lost
    data += _hello(NONE_SENT, later + 1) + b"".join(_joints(s) for s in (0, 1, 2))  # restarted again, 5 -> 0
    data += _hello(NONE_SENT, later + 2) + b"".join(_joints(s) for s in (2, 3))  # again, its frames 0 and 1 lost
    [uart] = _run_c(uart_example, data)
    _, tally = _listener(_Replay([data]))
    assert tally.total_joints == 2 + 5 + 3 + 2 and tally.total_late == 0
    assert uart["lost_frames"] == tally.total_gaps == 4


def _joints_of_set(seq: int, joint_set: int) -> bytes:
    xyz = np.zeros((10, 3), np.int16)
    return encode(Joints(make_header(MsgType.JOINTS, seq, 1000 + seq, 2000 + seq), joint_set, xyz,
                         np.full(10, 200, np.uint8), np.zeros(10, bool)))


def test_uart_example_counts_a_joints_of_another_joint_set_as_no_lost_frame(uart_example: Path) -> None:
    """One seq numbers every JOINTS, whatever its joint set (docs/protocol.md, HELLO): the UART example skips the
    joints of a set it does not read, not their seq. It counted the seq of BODY_25 JOINTS only, so a JOINTS of
    another set between two was a lost frame; the listener counts it as arrived."""
    data = b"\x00" + _hello(NONE_SENT) + _joints(0) + _joints_of_set(1, 7) + _joints(2) + _joints(4)
    [uart] = _run_c(uart_example, data)
    _, tally = _listener(_Replay([data]))
    assert uart["lost_frames"] == tally.total_gaps == 1
