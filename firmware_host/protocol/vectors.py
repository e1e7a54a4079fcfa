"""Shared test vectors for every joint-stream decoder (Python, C, firmware ports).

Regenerate the committed files with::

    python -m firmware_host.protocol.vectors --out tests/vectors/joint_stream

Each vector is ``NAME.bin`` (a byte stream) and ``NAME.json`` (the events a
decoder must produce, one per non-empty frame, and the resulting counters).

Expected events are written from how each stream was built, not by running a
decoder: intact frames expect the message that was encoded, and each damaged
frame is damaged in a way whose class is known by construction (a payload bit
flipped before framing is a ``crc`` error, a frame cut inside a COBS block is
a ``cobs`` error, and so on; the builder asserts the construction held).
"""
from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from cobs import cobs

from firmware_host.protocol.constants import (
    ALL_SCENE_FLAGS,
    ERROR_CODES,
    HEADER,
    MAX_FRAME_LEN,
    MAX_JOINTS,
    MAX_PACKET_LEN,
    SCENE_FLAGS,
    U32_MAX,
    U64_MAX,
    CoordFrame,
    Fault,
    Flags,
    JointSet,
    MsgType,
    Units,
)
from firmware_host.protocol.crc import crc16
from firmware_host.protocol.encoder import encode_packet, frame_packet
from firmware_host.protocol.messages import Hello, Joints, Joints2D, Message, Status, make_header

UNKNOWN_TYPE = 0x7F


@dataclass
class _Stream:
    description: str
    data: bytearray = field(default_factory=bytearray)
    events: list[dict[str, Any]] = field(default_factory=list)

    def message(self, msg: Message) -> "_Stream":
        self.data += frame_packet(encode_packet(msg))
        self.events.append(msg.to_json())
        return self

    def raw(self, data: bytes, event: dict[str, Any] | None) -> "_Stream":
        """Bytes whose frame (if it ends here) gives ``event``; None for no event."""
        self.data += data
        if event is not None:
            self.events.append(event)
        return self

    def error(self, data: bytes, code: str) -> "_Stream":
        assert code in ERROR_CODES
        return self.raw(data, {"error": code})

    def stats(self) -> dict[str, int]:
        s = {"frames": len(self.events), "messages": 0, "skipped": 0, **dict.fromkeys(ERROR_CODES, 0)}
        for ev in self.events:
            if "error" in ev:
                s[ev["error"]] += 1
            elif "skipped" in ev:
                s["skipped"] += 1
            else:
                s["messages"] += 1
        return s


# ---- message builders -------------------------------------------------------

# A plausible BODY_25 pose in the rig frame (mm): person 3 m in front, facing the cameras.
_POSE_MM = np.array(
    [
        [0, -520, 2900], [0, -380, 3000], [-180, -370, 3000], [-430, -370, 3000], [-680, -370, 3000],
        [180, -370, 3000], [430, -370, 3000], [680, -370, 3000], [0, 120, 3000], [-100, 120, 3000],
        [-100, 560, 3000], [-100, 980, 3000], [100, 120, 3000], [100, 560, 3000], [100, 980, 3000],
        [-35, -560, 2920], [35, -560, 2920], [-80, -540, 3000], [80, -540, 3000], [120, 1040, 2850],
        [160, 1040, 2870], [100, 1040, 3050], [-120, 1040, 2850], [-160, 1040, 2870], [-100, 1040, 3050],
    ],
    dtype=np.int16,
)


def _joints(seq: int, *, flags: int = 0, missing: Iterable[int] = (), t0: int = 1_000_000) -> Joints:
    miss = np.zeros(25, bool)
    miss[list(missing)] = True
    xyz = np.where(miss[:, None], 0, _POSE_MM + np.int16(seq % 7)).astype(np.int16)
    conf = np.where(miss, 0, 200 + (np.arange(25) % 50)).astype(np.uint8)
    h = make_header(MsgType.JOINTS, seq, t0 + seq * 33_333, t0 + seq * 33_333 + 41_000, flags)
    return Joints(h, int(JointSet.BODY_25), xyz, conf, miss)


def _joints2d(seq: int, camera: int, missing: Iterable[int] = (), flags: int = 0) -> Joints2D:
    miss = np.zeros(25, bool)
    miss[list(missing)] = True
    uv = np.stack([np.arange(25) * 40 + 100 * camera, np.arange(25) * 25 + 4], axis=1) * 4 + 1
    uv = np.where(miss[:, None], 0, uv).astype(np.int16)
    conf = np.where(miss, 0, 180).astype(np.uint8)
    h = make_header(MsgType.JOINTS_2D, seq, 1_000_000 + seq * 33_333, 1_000_000 + seq * 33_333 + 41_500, flags)
    return Joints2D(h, camera, int(JointSet.BODY_25), uv, conf, miss)


def _hello(seq: int = 0, flags: int = 0) -> Hello:
    h = make_header(MsgType.HELLO, seq, 999_000, 999_100, flags)
    return Hello(h, 1, int(JointSet.BODY_25), 25, int(Units.MILLIMETRES), int(CoordFrame.RIG),
                 "rig-A1", ("left", "right"))


def _status(seq: int, dropped: int = 0, decimated: int = 0, fault: int = Fault.OK, flags: int = 0) -> Status:
    h = make_header(MsgType.STATUS, seq, 1_000_000 + seq * 33_333, 1_000_000 + seq * 33_333 + 42_000, flags)
    return Status(h, 2997, 41_000, dropped, decimated, int(fault))


def _sealed(body: bytes) -> bytes:
    """header+payload -> packet with a correct CRC, bypassing the encoder's checks."""
    return body + crc16(body).to_bytes(2, "little")


def _header(msg_type: int, seq: int = 5, version: int = 1, flags: int = 0) -> bytes:
    return HEADER.pack(version, msg_type, flags, seq, 2_000_000, 2_040_000)


def _cobs_blocks(encoded: bytes) -> list[int]:
    """Offsets where each COBS block starts (its code byte)."""
    starts, i = [], 0
    while i < len(encoded):
        starts.append(i)
        i += encoded[i]
    assert i == len(encoded)
    return starts


def _cobs_blocks_codes(encoded: bytes) -> list[int]:
    return [encoded[i] for i in _cobs_blocks(encoded)]


# ---- vectors ------------------------------------------------------------------


def _v_hello() -> _Stream:
    s = _Stream("One HELLO: protocol 1, BODY_25, 25 joints, mm, rig frame, rig id and two cameras.")
    return s.message(_hello())


def _v_status() -> _Stream:
    return _Stream("One STATUS with drops, decimation and a fault code.").message(
        _status(77, dropped=3, decimated=120, fault=Fault.RATE_LIMITED)
    )


def _v_joints() -> _Stream:
    return _Stream("One JOINTS frame, BODY_25, all 25 joints present.").message(_joints(1))


def _v_joints_missing() -> _Stream:
    return _Stream("JOINTS with joints 0, 7, 8, 15 and 24 missing (mask bits 0,7 / 8 / 15 / 24).").message(
        _joints(2, missing=(0, 7, 8, 15, 24))
    )


def _v_joints_extremes() -> _Stream:
    xyz = np.zeros((25, 3), np.int16)
    xyz[0::2] = [-32768, 32767, -1]
    xyz[1::2] = [32767, -32768, 1]
    conf = np.array([1, 255] * 12 + [128], np.uint8)
    miss = np.zeros(25, bool)
    h = make_header(MsgType.JOINTS, U32_MAX, U64_MAX, U64_MAX, Flags.DECIMATED | Flags.DROPPED)
    return _Stream("JOINTS at the limits: int16 extremes, seq 2^32-1, u64 max timestamps, both flags.").message(
        Joints(h, 0, xyz, conf, miss)
    )


def _v_joints_2d() -> _Stream:
    return (
        _Stream("JOINTS then JOINTS_2D for cameras 0 and 1 of the same frame (same seq).")
        .message(_joints(3))
        .message(_joints2d(3, 0))
        .message(_joints2d(3, 1, missing=(4, 7)))
    )


def _v_session() -> _Stream:
    s = _Stream(
        "A session: leading delimiters, HELLO, STATUS, JOINTS 10, 11, 13 (DROPPED flag: 12 was "
        "dropped by the sender), 14, empty frames between packets, STATUS reporting the drop."
    )
    s.raw(b"\x00\x00", None)
    s.message(_hello(9)).message(_status(9))
    s.message(_joints(10)).message(_joints(11))
    s.raw(b"\x00", None)
    s.message(_joints(13, flags=Flags.DROPPED)).raw(b"\x00\x00\x00", None).message(_joints(14))
    return s.message(_status(14, dropped=1, fault=Fault.QUEUE_OVERFLOW))


def _v_scene_flags() -> _Stream:
    s = _Stream(
        "Scene flags: a HELLO announcing them (flags 0x3C), JOINTS 40-43 with SEVERAL_PEOPLE, PRIOR_FALLBACK, "
        "CALIBRATION_SUSPECT, and all four with DROPPED; a SINGLE_VIEW frame 44 (every 3D joint missing, "
        "camera 0's 2D joints, camera 1's all missing, all three packets flagged); a STATUS with "
        "CALIBRATION_SUSPECT; JOINTS 45 with the reserved bit 7, which decoders pass through; a HELLO of a "
        "sender that scans for others (flags 0x7C), JOINTS 46 and its JOINTS_2D with SOMEONE_ELSE, JOINTS 47 "
        "with every scene flag and DROPPED."
    )
    s.message(_hello(39, flags=SCENE_FLAGS))
    s.message(_joints(40, flags=Flags.SEVERAL_PEOPLE))
    s.message(_joints(41, flags=Flags.PRIOR_FALLBACK))
    s.message(_joints(42, flags=Flags.CALIBRATION_SUSPECT))
    s.message(_joints(43, flags=SCENE_FLAGS | Flags.DROPPED))
    s.message(_joints(44, flags=Flags.SINGLE_VIEW, missing=range(25)))
    s.message(_joints2d(44, 0, flags=Flags.SINGLE_VIEW))
    s.message(_joints2d(44, 1, missing=range(25), flags=Flags.SINGLE_VIEW))
    s.message(_status(44, flags=Flags.CALIBRATION_SUSPECT))
    s.message(_joints(45, flags=0x80))
    s.message(_hello(45, flags=ALL_SCENE_FLAGS))
    s.message(_joints(46, flags=Flags.SOMEONE_ELSE))
    s.message(_joints2d(46, 0, flags=Flags.SOMEONE_ELSE))
    return s.message(_joints(47, flags=ALL_SCENE_FLAGS | Flags.DROPPED))


def _v_unknown_type() -> _Stream:
    body = _header(UNKNOWN_TYPE) + bytes(range(1, 40))
    return (
        _Stream("A well-formed packet of unknown type 0x7F between two JOINTS: skipped, not an error.")
        .message(_joints(20))
        .raw(frame_packet(_sealed(body)), {"skipped": "unknown", "msg_type": UNKNOWN_TYPE})
        .message(_joints(21))
    )


def _v_future_version() -> _Stream:
    body = _header(MsgType.JOINTS, version=2) + b"\x00\x19" + bytes(200)
    return (
        _Stream("A packet claiming protocol version 2 (error 'version'), then a version-1 JOINTS.")
        .error(frame_packet(_sealed(body)), "version")
        .message(_joints(22))
    )


def _v_extension_bytes() -> _Stream:
    s = _Stream("JOINTS and STATUS with 9 extra bytes after the known fields: decoders ignore them.")
    for msg in (_joints(23), _status(23)):
        packet = encode_packet(msg)
        s.raw(frame_packet(_sealed(packet[:-2] + b"EXTENSION")), msg.to_json())
    return s


def _v_crc_corrupted() -> _Stream:
    s = _Stream("Three JOINTS; the 2nd has one payload bit flipped, a 4th has a CRC byte flipped. Both 'crc'.")
    s.message(_joints(30))
    bad = bytearray(encode_packet(_joints(31)))
    bad[60] ^= 0x10
    s.error(frame_packet(bytes(bad)), "crc")
    s.message(_joints(32))
    bad = bytearray(encode_packet(_joints(33)))
    bad[-1] ^= 0x01
    return s.error(frame_packet(bytes(bad)), "crc").message(_joints(34))


def _v_truncated() -> _Stream:
    s = _Stream(
        "Truncations: a frame cut inside a COBS block ('cobs'); a frame cut at a block boundary "
        "('crc'); a 10-byte packet ('short'); a frame whose delimiter was lost, merged with the "
        "next ('crc'); the stream ends inside a frame (no event)."
    )
    enc = cobs.encode(encode_packet(_joints(40)))
    longest = max(_cobs_blocks(enc), key=lambda i: enc[i])  # cut inside the longest block
    assert enc[longest] > 4
    s.error(enc[: longest + enc[longest] // 2] + b"\x00", "cobs")
    s.message(_joints(41))
    enc = cobs.encode(encode_packet(_joints(42)))
    cut = _cobs_blocks(enc)[-1]  # drop the whole last block: valid COBS, wrong CRC
    packet = cobs.decode(enc[:cut])
    assert len(packet) >= 25 and crc16(packet[:-2]) != int.from_bytes(packet[-2:], "little")
    s.error(enc[:cut] + b"\x00", "crc")
    s.error(frame_packet(encode_packet(_joints(43))[:10]), "short")
    merged = cobs.encode(encode_packet(_joints(44))) + cobs.encode(encode_packet(_joints(45)))
    packet = cobs.decode(merged)
    assert len(packet) <= MAX_PACKET_LEN and crc16(packet[:-2]) != int.from_bytes(packet[-2:], "little")
    s.error(merged + b"\x00", "crc")
    s.message(_joints(46))
    return s.raw(cobs.encode(encode_packet(_joints(47)))[:100], None)


def _v_garbage() -> _Stream:
    s = _Stream(
        "Garbage interleaved: a boot banner before the first delimiter ('cobs'), JOINTS, "
        "0x00 0x00 0xFF 0x00 (empty frames ignored, 0xFF alone is 'cobs'), JOINTS, "
        "two bytes glued to the front of a frame so it is lost ('crc'), JOINTS."
    )
    banner = b"U-Boot 2024.01 (Jan 01 2024)\r\n"
    assert banner[0] - 1 > len(banner) - 1  # first byte read as a code that overruns the frame
    s.error(banner + b"\x00", "cobs")
    s.message(_joints(50))
    s.raw(b"\x00\x00", None).error(b"\xff\x00", "cobs")
    s.message(_joints(51))
    glued = b"\x01\x01" + cobs.encode(encode_packet(_joints(52)))  # decodes to 00 00 + packet
    packet = cobs.decode(glued)
    assert crc16(packet[:-2]) != int.from_bytes(packet[-2:], "little")
    s.error(glued + b"\x00", "crc")
    return s.message(_joints(53))


def _nonzero_unknown_packet(length: int) -> bytes:
    """A valid packet of unknown type with no zero byte at all, so COBS uses 0xFF blocks."""
    head = HEADER.pack(1, UNKNOWN_TYPE, 0x03, 0x01010101, 0x0102030405060708, 0x0102030405060709)
    for salt in range(1, 256):
        body = head + bytes(((i * 7 + salt) % 255) + 1 for i in range(length - len(head) - 2))
        packet = _sealed(body)
        if 0 not in packet:
            return packet
    raise AssertionError("no salt gives a zero-free CRC")


def _v_limits() -> _Stream:
    s = _Stream(
        "Size limits: 600 bytes without a delimiter ('oversize'); a zero-free 512-byte packet "
        "(515 encoded bytes, three COBS blocks, skipped as unknown type); a zero-free 513-byte "
        "packet (516 encoded bytes, 'oversize'); a 513-byte packet with zeros (514 encoded bytes, "
        "'oversize' after decoding); a JOINTS padded to exactly 512 bytes (decoded)."
    )
    s.error(b"A" * 600 + b"\x00", "oversize")
    p512 = _nonzero_unknown_packet(MAX_PACKET_LEN)
    e512 = cobs.encode(p512)
    assert len(e512) == MAX_FRAME_LEN and e512[0] == 0xFF
    s.raw(e512 + b"\x00", {"skipped": "unknown", "msg_type": UNKNOWN_TYPE})
    p513 = _nonzero_unknown_packet(MAX_PACKET_LEN + 1)
    assert len(cobs.encode(p513)) == MAX_FRAME_LEN + 1
    s.error(cobs.encode(p513) + b"\x00", "oversize")
    body = encode_packet(_joints(60))[:-2]
    pad513 = _sealed(body + bytes(MAX_PACKET_LEN + 1 - 2 - len(body)))
    assert len(pad513) == 513 and len(cobs.encode(pad513)) <= MAX_FRAME_LEN
    s.error(cobs.encode(pad513) + b"\x00", "oversize")
    msg = _joints(61)
    body = encode_packet(msg)[:-2]
    s.raw(frame_packet(_sealed(body + bytes(MAX_PACKET_LEN - 2 - len(body)))), msg.to_json())
    return s


def _v_long_block() -> _Stream:
    n = 40
    xyz = np.full((n, 3), 0x0101, np.int16)
    xyz[:, 2] = np.arange(n) + 0x0201
    conf = np.full(n, 255, np.uint8)
    miss = np.zeros(n, bool)
    h = make_header(MsgType.JOINTS, 0x01020304, 0x0102030405060708, 0x0102030405060709, 1)
    msg = Joints(h, 99, xyz, conf, miss)
    assert 0xFF in _cobs_blocks_codes(cobs.encode(encode_packet(msg)))
    s = _Stream("JOINTS of 40 joints (joint set 99) whose payload has a 280-byte zero-free run (0xFF COBS code).")
    return s.message(msg)


def _v_joints_empty() -> _Stream:
    """Count 0: no mask byte, no joint; a decoder must not read a mask or a joint that is not there."""
    h = make_header(MsgType.JOINTS, 80, 3_000_000, 3_041_000, Flags.DROPPED)
    empty = np.zeros((0, 3), np.int16), np.zeros(0, np.uint8), np.zeros(0, bool)
    joints = Joints(h, int(JointSet.BODY_25), *empty)
    h2 = make_header(MsgType.JOINTS_2D, 80, 3_000_000, 3_041_500)
    joints_2d = Joints2D(h2, 1, int(JointSet.BODY_25), np.zeros((0, 2), np.int16), empty[1], empty[2])
    assert len(encode_packet(joints)) == HEADER.size + 2 + 2 and len(encode_packet(joints_2d)) == HEADER.size + 3 + 2
    return (
        _Stream("JOINTS and JOINTS_2D of 0 joints (count 0: no mask byte, no joint; a sender that found no one), "
                "then a BODY_25 JOINTS.")
        .message(joints)
        .message(joints_2d)
        .message(_joints(81))
    )


def _v_joints_max() -> _Stream:
    """The protocol's largest joint count: an 8-byte mask, its last bit the last joint's."""
    n = MAX_JOINTS
    idx = np.arange(n)
    xyz = np.stack([idx * 37 - 1200, 500 - idx * 11, 2500 + idx * 3], axis=1).astype(np.int16)
    miss = np.zeros(n, bool)
    miss[[0, 9, 31, 32, n - 1]] = True  # the first and last bit, and across the mask's middle bytes
    xyz[miss] = 0
    conf = np.where(miss, 0, 1 + idx % 255).astype(np.uint8)
    h = make_header(MsgType.JOINTS, 82, 3_100_000, 3_141_000)
    joints = Joints(h, 7, xyz, conf, miss)
    uv = np.stack([idx * 20 + 8, idx * 12 + 4], axis=1).astype(np.int16)
    uv[miss] = 0
    h2 = make_header(MsgType.JOINTS_2D, 82, 3_100_000, 3_141_500)
    joints_2d = Joints2D(h2, 0, 7, uv, np.where(miss, 0, 180).astype(np.uint8), miss)
    assert len(encode_packet(joints)) <= MAX_PACKET_LEN
    return (
        _Stream(f"JOINTS and JOINTS_2D of {n} joints (joint set 7), the most a packet carries: an 8-byte mask "
                f"with joints 0, 9, 31, 32 and {n - 1} missing.")
        .message(joints)
        .message(joints_2d)
    )


def _v_malformed() -> _Stream:
    s = _Stream(
        "Valid CRC but bad payloads, all 'malformed': JOINTS count 26 with 25 joints of data, "
        "JOINTS count 65, STATUS of 15 bytes, HELLO rig id with byte 0x80, HELLO rig id of 33 "
        "characters, HELLO with 9 cameras, JOINTS_2D cut in its mask; then one good JOINTS."
    )
    joints = encode_packet(_joints(70))[:-2]
    bad = bytearray(joints)
    bad[HEADER.size + 1] = 26
    s.error(frame_packet(_sealed(bytes(bad))), "malformed")
    s.error(frame_packet(_sealed(_header(MsgType.JOINTS) + bytes([0, 65]) + bytes(500 - 25 - 2))), "malformed")
    s.error(frame_packet(_sealed(_header(MsgType.STATUS) + bytes(range(1, 16)))), "malformed")
    hello = _header(MsgType.HELLO) + bytes([1, 0, 25, 0, 0])
    s.error(frame_packet(_sealed(hello + b"\x03r\x80g" + b"\x00")), "malformed")
    s.error(frame_packet(_sealed(hello + b"\x21" + b"r" * 33 + b"\x00")), "malformed")
    s.error(frame_packet(_sealed(hello + b"\x02r1\x09" + b"\x01c" * 9)), "malformed")
    s.error(frame_packet(_sealed(_header(MsgType.JOINTS_2D) + bytes([0, 0, 25, 0]))), "malformed")
    return s.message(_joints(71))


VECTORS = {
    "hello": _v_hello,
    "status": _v_status,
    "joints_body25": _v_joints,
    "joints_missing": _v_joints_missing,
    "joints_extremes": _v_joints_extremes,
    "joints_2d": _v_joints_2d,
    "session": _v_session,
    "scene_flags": _v_scene_flags,
    "unknown_type": _v_unknown_type,
    "future_version": _v_future_version,
    "extension_bytes": _v_extension_bytes,
    "crc_corrupted": _v_crc_corrupted,
    "truncated": _v_truncated,
    "garbage_interleaved": _v_garbage,
    "limits": _v_limits,
    "long_block": _v_long_block,
    "joints_empty": _v_joints_empty,
    "joints_max": _v_joints_max,
    "malformed": _v_malformed,
}


def _json_text(s: _Stream) -> str:
    # One event per line keeps diffs of the committed files readable.
    lines = [
        "{",
        f' "description": {json.dumps(s.description)},',
        f' "stats": {json.dumps(s.stats())},',
        ' "events": [',
        ",\n".join("  " + json.dumps(ev, separators=(",", ":")) for ev in s.events),
        " ]",
        "}",
    ]
    return "\n".join(lines) + "\n"


def build() -> dict[str, tuple[bytes, str]]:
    """name -> (stream bytes, expected JSON text)."""
    out = {}
    for name, make in VECTORS.items():
        s = make()
        out[name] = (bytes(s.data), _json_text(s))
    return out


def default_dir() -> Path:
    return Path(__file__).resolve().parents[2] / "tests" / "vectors" / "joint_stream"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=default_dir(), help="directory for NAME.bin / NAME.json")
    ap.add_argument("--check", action="store_true", help="only compare with the files there; exit 1 on a difference")
    args = ap.parse_args(argv)
    stale = []
    args.out.mkdir(parents=True, exist_ok=True)
    for name, (data, text) in build().items():
        for path, content in ((args.out / f"{name}.bin", data), (args.out / f"{name}.json", text.encode())):
            if args.check:
                if not path.exists() or path.read_bytes() != content:
                    stale.append(path)
            else:
                path.write_bytes(content)
    for p in stale:
        print(f"stale: {p}", file=sys.stderr)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
