"""The C decoder on the hostile streams of tests/firmware_host/hostile_stream.py, against the Python decoder, and
on the bounds a microcontroller lives by: a run without a delimiter longer than a 16-bit counter holds, and the
resynchronisation that follows it.

test_c_decoder.py mutates three vectors and test_c_differential.py draws frames of at most 515 bytes; neither
feeds a run of 70 000 bytes, the exact 515/516-byte runs, or a stream that ends inside a frame."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from firmware_host.protocol import decode_stream
from tests.firmware_host.hostile_stream import SENTINEL, SENTINEL_WIRE, hostile_stream


def _dump(exe: Path, path: Path, chunk: int) -> tuple[list[dict], dict]:
    proc = subprocess.run([str(exe), "-c", str(chunk), str(path)], capture_output=True, text=True)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr[-2000:]
    lines = [json.loads(line) for line in proc.stdout.splitlines()]
    assert "stats" in lines[-1]
    return lines[:-1], lines[-1]["stats"]


@pytest.mark.parametrize("seed", [541, 542])
def test_c_and_python_agree_on_hostile_streams(ghj_dump: Path, tmp_path: Path, seed: int) -> None:
    rng = np.random.default_rng(seed)
    # Each case ends with a leading 0x00 and a good frame, so both decoders must be back in step at its end.
    data = b"".join(hostile_stream(rng, int(rng.integers(1, 6))) + b"\x00" + SENTINEL_WIRE for _ in range(60))
    path = tmp_path / "hostile.bin"
    path.write_bytes(data)
    py_events, py_stats = decode_stream(data)
    want = [e.to_json() for e in py_events]
    assert want.count(SENTINEL.to_json()) >= 60
    for chunk in (1, int(rng.integers(2, 600)), 4096):
        events, stats = _dump(ghj_dump, path, chunk)
        for i, (got, exp) in enumerate(zip(events, want)):
            assert got == exp, f"seed {seed}, chunk {chunk}, frame {i}"
        assert len(events) == len(want) and stats == py_stats.to_json()


@pytest.mark.parametrize("run_len", [514, 515, 516, 65_535, 65_536, 65_536 + 515, 200_000])
def test_c_resynchronises_after_a_run_of_any_length(ghj_dump: Path, tmp_path: Path, run_len: int) -> None:
    """A run without 0x00 glued to a good frame is one frame: ``oversize`` once it passes 515 encoded bytes
    (GHJ_MAX_FRAME_LEN), however long it goes on (a 16-bit count that wrapped would take the tail for a new
    frame), then the next frame decodes."""
    run = (bytes(range(1, 256)) * (run_len // 255 + 1))[:run_len]
    path = tmp_path / "run.bin"
    path.write_bytes(run + SENTINEL_WIRE + SENTINEL_WIRE)
    for chunk in (1, 4096):
        events, stats = _dump(ghj_dump, path, chunk)
        assert events[0] == {"error": "oversize"} and events[1] == SENTINEL.to_json(), (run_len, chunk)
        assert stats["frames"] == 2
    py_events, _ = decode_stream(path.read_bytes())
    assert [e.to_json() for e in py_events] == events


def test_a_stream_that_ends_inside_a_frame_reports_nothing_for_it(ghj_dump: Path, tmp_path: Path) -> None:
    """Bytes after the last delimiter are a frame still arriving: no event in C or Python, whatever they are."""
    path = tmp_path / "cut.bin"
    path.write_bytes(SENTINEL_WIRE + SENTINEL_WIRE[:-1])
    events, stats = _dump(ghj_dump, path, 1)
    assert events == [SENTINEL.to_json()] and stats["frames"] == 1
    assert [e.to_json() for e in decode_stream(path.read_bytes())[0]] == events


def _edge_messages() -> list:
    """Every message type at its size extremes: joint counts 0, 1, 25 and 64, the longest HELLO and the empty one,
    a STATUS of all-ones fields, times at 0 and 2^64 - 1."""
    from firmware_host.protocol import Hello, Joints, Joints2D, MsgType, Status, make_header

    out: list = []
    for n in (0, 1, 25, 64):
        out.append(Joints(make_header(MsgType.JOINTS, 2**32 - 1, 2**64 - 1, 0, 0xFF), 0, np.full((n, 3), -1, np.int16),
                          np.full(n, 255, np.uint8), np.arange(n) % 3 == 0))
        out.append(Joints2D(make_header(MsgType.JOINTS_2D, 0, 0, 2**64 - 1), 7, 0, np.full((n, 2), -32768, np.int16),
                            np.zeros(n, np.uint8), np.zeros(n, bool)))
    out.append(Status(make_header(MsgType.STATUS, 1, 2, 3), 0xFFFF, 2**32 - 1, 2**32 - 1, 2**32 - 1, 0xFFFF))
    out.append(Hello(make_header(MsgType.HELLO, 2**32 - 1, 0, 0), 1, 0, 64, 0, 0, "~" * 32, ("c" * 16,) * 8))
    out.append(Hello(make_header(MsgType.HELLO, 0, 0, 0), 1, 0, 0, 0, 0, "", ()))
    return out


def test_c_and_python_agree_on_every_cut_and_every_flipped_bit(ghj_dump: Path, tmp_path: Path) -> None:
    """Each edge message cut after every byte of its packet (resealed, so the payload checks decide, and not), its
    frame cut after every byte and ended there, and each bit of its frame flipped: one event per frame, the same
    in C and Python, and no flipped bit decodes to a message (one bit is always within the CRC's reach)."""
    from firmware_host.protocol import encode, encode_packet
    from firmware_host.protocol.encoder import frame_packet, seal

    cuts, flips = bytearray(), bytearray()
    for msg in _edge_messages():
        packet, frame = encode_packet(msg), encode(msg)
        for n in range(1, len(packet)):
            cuts += frame_packet(packet[:n]) + frame_packet(seal(packet[:n]))
        for n in range(1, len(frame) - 1):
            cuts += frame[:n] + b"\x00"
        for i in range(len(frame) - 1):
            for b in range(8):
                flipped = bytearray(frame)
                flipped[i] ^= 1 << b
                flips += b"\x00" + flipped  # a flip to 0x00 splits the frame: the leading 0x00 ends what is left
    counts = []
    for data in (bytes(cuts), bytes(flips)):
        path = tmp_path / "edges.bin"
        path.write_bytes(data)
        py_events, py_stats = decode_stream(data)
        events, stats = _dump(ghj_dump, path, 4096)
        assert events == [e.to_json() for e in py_events] and stats == py_stats.to_json()
        counts.append(stats)
    cut, flip = counts
    # the resealed cuts reach the payload checks; a cut that keeps a whole message's fields is a message
    assert cut["malformed"] > 0 and cut["short"] > 0 and cut["cobs"] > 0 and cut["messages"] > 0
    assert flip["messages"] == 0 and flip["crc"] > 0 and flip["cobs"] > 0
