"""Packets -> messages, and a streaming frame decoder that resynchronises on 0x00.

Check order (the C decoder makes the same checks in the same order, so both
classify every frame identically):

1. ``oversize``: more than MAX_FRAME_LEN encoded bytes, or a decoded packet
   longer than MAX_PACKET_LEN;
2. ``cobs``: the frame ends inside a COBS block;
3. ``short``: fewer bytes than header + CRC;
4. ``crc``: CRC-16/IBM-3740 mismatch;
5. ``version``: a protocol version this decoder does not speak;
6. unknown message type: skipped, not an error (the protocol can grow);
7. ``malformed``: the payload is shorter than its fields, or a field is out of range.

Bytes after the fields a decoder knows are ignored, so messages can grow at the end.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np
from cobs import cobs

from firmware_host.errors import FrameError, UnknownMessageType
from firmware_host.protocol.constants import (
    CRC_LEN,
    ERROR_CODES,
    HEADER,
    HEADER_LEN,
    JOINT2D_BYTES,
    JOINT3D_BYTES,
    MAX_CAMERA_NAME_LEN,
    MAX_CAMERAS,
    MAX_FRAME_LEN,
    MAX_JOINTS,
    MAX_PACKET_LEN,
    MAX_RIG_ID_LEN,
    MIN_PACKET_LEN,
    PROTOCOL_VERSION,
    MsgType,
    mask_len,
)
from firmware_host.protocol.crc import crc16
from firmware_host.protocol.messages import Header, Hello, Joints, Joints2D, Message, Status

_J3D = np.dtype([("x", "<i2"), ("y", "<i2"), ("z", "<i2"), ("c", "u1")])
_J2D = np.dtype([("u", "<i2"), ("v", "<i2"), ("c", "u1")])
_STATUS = struct.Struct("<HIIIH")


def _need(payload: bytes, n: int, what: str) -> None:
    if len(payload) < n:
        raise FrameError("malformed", f"{what}: payload has {len(payload)} bytes, needs {n}")


def _missing(payload: bytes, offset: int, count: int) -> np.ndarray:
    bits = np.unpackbits(np.frombuffer(payload, np.uint8, mask_len(count), offset), bitorder="little")
    return bits[:count].astype(bool)


def _joints(h: Header, p: bytes) -> Joints:
    _need(p, 2, "JOINTS")
    joint_set, count = p[0], p[1]
    if count > MAX_JOINTS:
        raise FrameError("malformed", f"JOINTS count {count} > {MAX_JOINTS}")
    off = 2 + mask_len(count)
    _need(p, off + JOINT3D_BYTES * count, "JOINTS")
    rows = np.frombuffer(p, _J3D, count, off)
    xyz = np.stack([rows["x"], rows["y"], rows["z"]], axis=1).astype(np.int16)
    return Joints(h, joint_set, xyz, rows["c"].copy(), _missing(p, 2, count))


def _joints2d(h: Header, p: bytes) -> Joints2D:
    _need(p, 3, "JOINTS_2D")
    camera, joint_set, count = p[0], p[1], p[2]
    if count > MAX_JOINTS:
        raise FrameError("malformed", f"JOINTS_2D count {count} > {MAX_JOINTS}")
    off = 3 + mask_len(count)
    _need(p, off + JOINT2D_BYTES * count, "JOINTS_2D")
    rows = np.frombuffer(p, _J2D, count, off)
    uv = np.stack([rows["u"], rows["v"]], axis=1).astype(np.int16)
    return Joints2D(h, camera, joint_set, uv, rows["c"].copy(), _missing(p, 3, count))


def _status(h: Header, p: bytes) -> Status:
    _need(p, _STATUS.size, "STATUS")
    return Status(h, *_STATUS.unpack_from(p, 0))


def _ascii(p: bytes, off: int, max_len: int, what: str) -> tuple[str, int]:
    _need(p, off + 1, what)
    n = p[off]
    if n > max_len:
        raise FrameError("malformed", f"{what} length {n} > {max_len}")
    _need(p, off + 1 + n, what)
    raw = p[off + 1 : off + 1 + n]
    if not all(0x20 <= b <= 0x7E for b in raw):
        raise FrameError("malformed", f"{what} is not printable ASCII")
    return raw.decode("ascii"), off + 1 + n


def _hello(h: Header, p: bytes) -> Hello:
    _need(p, 5, "HELLO")
    version, joint_set, joint_count, units, frame = p[0], p[1], p[2], p[3], p[4]
    if joint_count > MAX_JOINTS:
        raise FrameError("malformed", f"HELLO joint_count {joint_count} > {MAX_JOINTS}")
    rig_id, off = _ascii(p, 5, MAX_RIG_ID_LEN, "HELLO rig_id")
    _need(p, off + 1, "HELLO cameras")
    n_cams = p[off]
    if n_cams > MAX_CAMERAS:
        raise FrameError("malformed", f"HELLO camera count {n_cams} > {MAX_CAMERAS}")
    off += 1
    cams = []
    for _ in range(n_cams):
        name, off = _ascii(p, off, MAX_CAMERA_NAME_LEN, "HELLO camera name")
        cams.append(name)
    return Hello(h, version, joint_set, joint_count, units, frame, rig_id, tuple(cams))


_PARSERS = {
    MsgType.JOINTS: _joints,
    MsgType.JOINTS_2D: _joints2d,
    MsgType.STATUS: _status,
    MsgType.HELLO: _hello,
}


def parse_packet(packet: bytes) -> Message:
    """Decode one COBS-decoded packet.

    :raises FrameError: with ``code`` short / crc / version / malformed.
    :raises UnknownMessageType: for a valid packet of a type this decoder does not know.
    """
    if len(packet) > MAX_PACKET_LEN:
        raise FrameError("oversize", f"packet of {len(packet)} bytes > {MAX_PACKET_LEN}")
    if len(packet) < MIN_PACKET_LEN:
        raise FrameError("short", f"packet of {len(packet)} bytes < {MIN_PACKET_LEN}")
    body = packet[:-CRC_LEN]
    got = int.from_bytes(packet[-CRC_LEN:], "little")
    want = crc16(body)
    if got != want:
        raise FrameError("crc", f"crc 0x{got:04x} != computed 0x{want:04x}")
    h = Header(*HEADER.unpack_from(body, 0))
    if h.version != PROTOCOL_VERSION:
        raise FrameError("version", f"protocol version {h.version} != {PROTOCOL_VERSION}")
    parser = _PARSERS.get(h.msg_type)  # type: ignore[call-overload]
    if parser is None:
        raise UnknownMessageType(h.msg_type)
    return parser(h, bytes(body[HEADER_LEN:]))


@dataclass(frozen=True)
class DecodeEvent:
    """What one frame turned into: a message, an error code, or a skipped unknown type."""

    kind: str  # "message" | "error" | "skipped"
    message: Optional[Message] = None
    code: Optional[str] = None
    msg_type: Optional[int] = None

    def to_json(self) -> dict[str, Any]:
        if self.kind == "message":
            assert self.message is not None
            return self.message.to_json()
        if self.kind == "error":
            return {"error": self.code}
        return {"skipped": "unknown", "msg_type": self.msg_type}


@dataclass
class DecoderStats:
    frames: int = 0  # non-empty frames seen (each gives exactly one event)
    messages: int = 0
    skipped: int = 0
    errors: dict[str, int] = field(default_factory=lambda: dict.fromkeys(ERROR_CODES, 0))

    def to_json(self) -> dict[str, int]:
        return {"frames": self.frames, "messages": self.messages, "skipped": self.skipped, **self.errors}


def decode_frame(encoded: bytes) -> DecodeEvent:
    """Classify the bytes between two delimiters (non-empty, without the 0x00)."""
    if len(encoded) > MAX_FRAME_LEN:
        return DecodeEvent("error", code="oversize")
    try:
        packet = cobs.decode(encoded)
    except cobs.DecodeError:
        return DecodeEvent("error", code="cobs")
    try:
        return DecodeEvent("message", message=parse_packet(packet))
    except FrameError as e:
        return DecodeEvent("error", code=e.code)
    except UnknownMessageType as e:
        return DecodeEvent("skipped", msg_type=e.msg_type)


class StreamDecoder:
    """Feed bytes in any chunking, get one event per non-empty frame.

    Holds at most MAX_FRAME_LEN bytes: a longer run without a delimiter is
    discarded and reported as ``oversize`` when its delimiter arrives. Empty
    frames (consecutive 0x00, used by senders to resynchronise) are ignored.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._overflow = False
        self.stats = DecoderStats()

    def feed(self, data: bytes | bytearray | memoryview) -> list[DecodeEvent]:
        data = bytes(data)
        events: list[DecodeEvent] = []
        start = 0
        while True:
            end = data.find(0, start)
            if end < 0:
                self._append(data[start:])
                return events
            self._append(data[start:end])
            ev = self._end_frame()
            if ev is not None:
                events.append(ev)
            start = end + 1

    def _append(self, chunk: bytes) -> None:
        if self._overflow or not chunk:
            return
        if len(self._buf) + len(chunk) > MAX_FRAME_LEN:
            self._overflow = True  # keep nothing; report when the delimiter comes
            self._buf.clear()
        else:
            self._buf += chunk

    def _end_frame(self) -> Optional[DecodeEvent]:
        if self._overflow:
            ev = DecodeEvent("error", code="oversize")
        elif not self._buf:
            return None
        else:
            ev = decode_frame(bytes(self._buf))
        self._buf.clear()
        self._overflow = False
        self.stats.frames += 1
        if ev.kind == "message":
            self.stats.messages += 1
        elif ev.kind == "skipped":
            self.stats.skipped += 1
        else:
            assert ev.code is not None
            self.stats.errors[ev.code] += 1
        return ev


def decode_stream(data: bytes) -> tuple[list[DecodeEvent], DecoderStats]:
    """Decode a whole byte string; a trailing frame without delimiter gives no event."""
    d = StreamDecoder()
    return d.feed(data), d.stats
