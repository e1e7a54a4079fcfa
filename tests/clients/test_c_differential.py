"""The C decoder against the Python encoder: random messages over every field's full range decode to the values
that were encoded, and packets built to reach the payload parsers (a valid CRC around random payloads, random
COBS block structure) are classified as the Python decoder classifies them.

The mutation test in test_c_decoder.py starts from three vectors, so nearly every frame it makes fails its CRC
and the field values are those of the vectors; these streams cover what it cannot: seq 2^32 - 1, u64 times at
and above 2^63, i16 extremes, 64-joint masks, every byte value in the free u8 fields, HELLO strings with the
characters JSON escapes, extension bytes, and malformed payloads behind a valid CRC."""
from __future__ import annotations

import json
import random
import struct
import subprocess
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
from cobs import cobs

from firmware_host.protocol import decode_stream, encode, encode_packet, frame_packet
from firmware_host.protocol.encoder import seal
from firmware_host.protocol.messages import Header, Hello, Joints, Joints2D, Message, Status
from tests.firmware_host.joint_stream_helpers import MASK_RULES_JOINTS, mask_rules_packet

U32_EDGES = (0, 1, 0x7FFF_FFFF, 0x8000_0000, 0xFFFF_FFFF)
U64_EDGES = (0, 1, 2**32 - 1, 2**32, 2**63 - 1, 2**63, 2**64 - 1)
I16_EDGES = (-32768, -32767, -1, 0, 1, 255, 256, 32767)


def _dump(exe: Path, path: Path, chunk: int) -> tuple[list[dict], dict]:
    proc = subprocess.run([str(exe), "-c", str(chunk), str(path)], capture_output=True, text=True)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr[-2000:]
    lines = [json.loads(line) for line in proc.stdout.splitlines()]
    assert "stats" in lines[-1]
    return lines[:-1], lines[-1]["stats"]


class _Gen:
    """Random protocol messages whose every field is drawn from its whole range, edges weighted up."""

    def __init__(self, seed: int) -> None:
        self.rng = random.Random(seed)

    def u(self, bits: int, edges: tuple[int, ...] = ()) -> int:
        r = self.rng
        return r.choice(edges) if edges and r.random() < 0.4 else r.randrange(2**bits)

    def header(self, msg_type: int) -> Header:
        return Header(1, msg_type, self.u(8), self.u(32, U32_EDGES), self.u(64, U64_EDGES), self.u(64, U64_EDGES))

    def text(self, max_len: int) -> str:
        r = self.rng
        alphabet = [chr(c) for c in range(0x20, 0x7F)] + ['"', "\\"] * 8  # JSON escapes these two
        return "".join(r.choice(alphabet) for _ in range(r.choice([0, max_len, r.randint(0, max_len)])))

    def joint_rows(self, n: int, dims: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r = self.rng
        coords = np.array([[r.choice(I16_EDGES) if r.random() < 0.3 else r.randrange(-32768, 32768)
                            for _ in range(dims)] for _ in range(n)], np.int16).reshape(n, dims)
        conf = np.array([r.randrange(256) for _ in range(n)], np.uint8)
        missing = np.array([r.random() < 0.3 for _ in range(n)], bool)
        return coords, conf, missing

    def message(self) -> Message:
        r = self.rng
        kind = r.randrange(4)
        if kind == 0:
            xyz, conf, missing = self.joint_rows(r.choice([0, 1, 25, 64, r.randint(0, 64)]), 3)
            return Joints(self.header(0x10), self.u(8), xyz, conf, missing)
        if kind == 1:
            uv, conf, missing = self.joint_rows(r.choice([0, 25, 64, r.randint(0, 64)]), 2)
            return Joints2D(self.header(0x11), self.u(8), self.u(8), uv, conf, missing)
        if kind == 2:
            return Status(self.header(0x02), self.u(16), self.u(32, U32_EDGES), self.u(32, U32_EDGES),
                          self.u(32, U32_EDGES), self.u(16))
        cameras = tuple(self.text(16) for _ in range(r.randint(0, 8)))
        return Hello(self.header(0x01), self.u(8), self.u(8), r.randint(0, 64), self.u(8), self.u(8), self.text(32),
                     cameras)

    def frame(self, msg: Message) -> bytes:
        """The message on the wire, sometimes with extension bytes after its fields (the growth rule: ignored)."""
        packet = encode_packet(msg)
        room = 512 - len(packet)
        if room and self.rng.random() < 0.25:
            extra = bytes(self.rng.randrange(256) for _ in range(self.rng.randint(1, min(room, 40))))
            return frame_packet(seal(packet[:-2] + extra))
        return encode(msg)

    def sealed_payload(self) -> bytes:
        """A valid CRC around a random payload of a known (or unknown, or another version's) type: the payload
        parsers see lengths, counts and strings no encoder makes."""
        r = self.rng
        msg_type = r.choice([0x01, 0x02, 0x10, 0x11, 0x01, 0x10, r.randrange(256)])
        size = r.choice([0, 1, 2, 3, 5, 15, 16, r.randint(0, 60), r.randint(0, 512 - 25)])
        payload = bytearray(r.choice([0, 1, 8, 16, 25, 32, 33, 64, 65, 0x1F, 0x20, 0x7E, 0x7F, 0xFF,
                                      r.randrange(256)]) for _ in range(size))
        if msg_type == 0x01 and size > 6 and r.random() < 0.5:  # a HELLO that is nearly right
            payload[2] = r.choice([25, 64, 65])
            payload[5] = r.randint(0, min(size - 6, 33))
        version = r.choice([1, 1, 1, 1, 0, 2, 255])
        return frame_packet(seal(struct.pack("<BBBIQQ", version, msg_type, self.u(8), 5, 6, 7) + bytes(payload)))

    def cobs_blocks(self) -> bytes:
        """Random COBS structure: 0xFF blocks, empty blocks, blocks cut short, runs past 515 bytes."""
        r = self.rng
        out = bytearray()
        for _ in range(r.randint(1, 5)):
            code = r.choice([1, 2, 0xFE, 0xFF, 0xFF, r.randrange(1, 256)])
            body = code - 1 if r.random() < 0.8 else r.randrange(code)
            out.append(code)
            out += bytes(r.randrange(1, 256) for _ in range(body))
        return bytes(out) + b"\x00"


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_c_decodes_what_the_python_encoder_encoded(ghj_dump: Path, tmp_path: Path, seed: int) -> None:
    gen = _Gen(seed)
    msgs = [gen.message() for _ in range(250)]
    data = b"".join(gen.frame(m) + (b"\x00" if gen.rng.random() < 0.1 else b"") for m in msgs)
    path = tmp_path / "stream.bin"
    path.write_bytes(data)
    expected = [m.to_json() for m in msgs]
    for chunk in (1, gen.rng.randint(2, 300), 4096):
        events, stats = _dump(ghj_dump, path, chunk)
        for i, (got, want) in enumerate(zip(events, expected)):
            assert got == want, f"seed {seed}, message {i}, chunk {chunk}"
        assert len(events) == len(expected)
        assert stats["messages"] == stats["frames"] == len(msgs)


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_c_and_python_classify_packets_behind_a_valid_crc_alike(ghj_dump: Path, tmp_path: Path, seed: int) -> None:
    gen = _Gen(seed)
    makers: list[Callable[[], bytes]] = [gen.sealed_payload, gen.sealed_payload, gen.cobs_blocks,
                                         lambda: gen.frame(gen.message())]
    data = b"".join(gen.rng.choice(makers)() for _ in range(400))
    path = tmp_path / "stream.bin"
    path.write_bytes(data)
    py_events, py_stats = decode_stream(data)
    events, stats = _dump(ghj_dump, path, gen.rng.choice([1, 5, 4096]))
    want = [e.to_json() for e in py_events]
    for i, (got, exp) in enumerate(zip(events, want)):
        assert got == exp, f"seed {seed}, frame {i}"
    assert len(events) == len(want)
    assert stats == py_stats.to_json()
    # The streams reach every outcome, so agreement is not agreement on CRC errors alone.
    for outcome in ("messages", "skipped", "oversize", "cobs", "short", "version", "malformed"):
        assert stats[outcome] > 0, outcome


SPEC_EXAMPLE = bytes.fromhex(
    "03 01 02 02 2a 01 01 04 40 42 0f 01 01 01 01 04 e8 bd 0f 01 01 01 01"
    "05 b8 0b 10 a4 01 02 03 01 01 02 78 01 01 02 01 03 d5 f8 00")


def test_c_decodes_the_spec_worked_example(ghj_dump: Path, tmp_path: Path) -> None:
    """docs/protocol.md section 2: the 43 wire bytes of its STATUS example give the values it lists."""
    path = tmp_path / "example.bin"
    path.write_bytes(SPEC_EXAMPLE)
    events, stats = _dump(ghj_dump, path, 1)
    assert events == [{"type": "STATUS", "version": 1, "flags": 0, "seq": 42, "capture_us": 1_000_000,
                       "send_us": 1_031_656, "fps_centi": 3000, "latency_us": 42_000, "dropped": 3,
                       "decimated": 120, "fault": 1}]
    assert stats["frames"] == stats["messages"] == 1


def _zero_free_packet(length: int) -> bytes:
    """A valid JOINTS packet of ``length`` bytes without a zero byte (extension bytes fill it), so its COBS
    encoding is full 0xFF blocks: the case where encoders differ in writing a final empty block."""
    header = bytes([1, 0x10, 1]) + b"\x01" * 20
    for fill in range(1, 256):
        body = header + bytes([1, 1, 1]) + b"\x07" * 7
        packet = seal(body + bytes([fill]) * (length - 2 - len(body)))
        if 0 not in packet:
            return packet
    raise AssertionError(f"no zero-free packet of {length} bytes")


def test_c_reads_the_mask_and_cobs_rules_of_the_spec(ghj_dump: Path, tmp_path: Path) -> None:
    """docs/protocol.md: the mask bit decides and padding bits are ignored (JOINTS); a full last COBS block with
    or without PacketSerial's final empty block decodes alike (section 1, "COBS, byte by byte")."""
    full_block = _zero_free_packet(254)
    stream = (b"\x00" + frame_packet(mask_rules_packet()) + frame_packet(full_block)
              + cobs.encode(full_block) + b"\x01\x00")
    path = tmp_path / "rules.bin"
    path.write_bytes(stream)
    events, stats = _dump(ghj_dump, path, 1)
    assert events == [e.to_json() for e in decode_stream(stream)[0]]
    assert events[0]["joints"] == MASK_RULES_JOINTS
    assert events[1] == events[2] and stats["messages"] == 3
