"""Hostile joint-stream bytes for the decoder tests, Python's and C's alike (seeded numpy random): random bytes,
runs past the frame bound, frames cut short or flipped, valid CRCs around payloads no encoder makes."""
from __future__ import annotations

import struct

import numpy as np

from firmware_host.protocol import MsgType, Status, encode, make_header
from firmware_host.protocol.constants import MAX_FRAME_LEN, MAX_PACKET_LEN
from firmware_host.protocol.encoder import frame_packet, seal

# A frame every case ends with: the decoder must be back in step by then, whatever came before.
SENTINEL = Status(make_header(MsgType.STATUS, 7, 8, 9), 1, 2, 3, 4, 5)
SENTINEL_WIRE = encode(SENTINEL)
_KNOWN = (0x01, 0x02, 0x10, 0x11)


def sealed_nonsense(rng: np.random.Generator) -> bytes:
    """A valid CRC around a random payload: the parsers see counts, lengths and strings no encoder makes (joint
    counts 65..255, string lengths past their bound or past the packet), unknown types, other versions."""
    msg_type = int(rng.choice([*_KNOWN, *_KNOWN, int(rng.integers(256))]))
    version = int(rng.choice([1, 1, 1, 0, 2, 255]))
    size = int(rng.choice([0, 1, 2, 3, 5, 16, int(rng.integers(0, 64)), int(rng.integers(0, MAX_PACKET_LEN - 24))]))
    payload = rng.integers(0, 256, size, dtype=np.uint8)
    edges = np.array([0, 1, 8, 16, 25, 32, 33, 64, 65, 0x7E, 0x7F, 0xFF], np.uint8)
    payload = np.where(rng.random(size) < 0.5, rng.choice(edges, size), payload).astype(np.uint8)
    header = struct.pack("<BBBIQQ", version, msg_type, int(rng.integers(256)), 1, 2, 3)
    return frame_packet(seal(header + payload.tobytes()))


def hostile_piece(rng: np.random.Generator) -> bytes:
    """One piece of a hostile stream."""
    kind = int(rng.integers(7))
    if kind == 0:  # random bytes, zeros included
        return rng.integers(0, 256, int(rng.integers(1, 700)), dtype=np.uint8).tobytes()
    if kind == 1:  # a run without a delimiter, past the frame bound (at times far past it)
        n = int(rng.choice([MAX_FRAME_LEN, MAX_FRAME_LEN + 1, int(rng.integers(516, 5000)), 70_000]))
        return rng.integers(1, 256, n, dtype=np.uint8).tobytes()
    if kind == 2:  # a good frame cut short (no delimiter: glued to what follows)
        return SENTINEL_WIRE[: int(rng.integers(1, len(SENTINEL_WIRE) - 1))]
    if kind == 3:  # a good frame cut short and ended by a delimiter
        return SENTINEL_WIRE[: int(rng.integers(1, len(SENTINEL_WIRE) - 1))] + b"\x00"
    if kind == 4:  # a good frame with a byte flipped
        data = bytearray(SENTINEL_WIRE)
        data[int(rng.integers(len(data) - 1))] ^= 1 << int(rng.integers(8))
        return bytes(data)
    if kind == 5:
        return sealed_nonsense(rng)
    return b"\x00" * int(rng.integers(1, 4))  # idle delimiters



def hostile_stream(rng: np.random.Generator, pieces: int) -> bytes:
    return b"".join(hostile_piece(rng) for _ in range(pieces))
