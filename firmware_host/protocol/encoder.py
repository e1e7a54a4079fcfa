"""Messages -> packets -> COBS frames.

A packet is ``header | payload | crc16-le``; a frame is ``cobs(packet) | 0x00``.
"""
from __future__ import annotations

import operator
import struct

import numpy as np
from cobs import cobs

from firmware_host.errors import EncodeError
from firmware_host.protocol.constants import (
    HEADER,
    JOINT2D_BYTES,
    JOINT3D_BYTES,
    MAX_CAMERA_NAME_LEN,
    MAX_CAMERAS,
    MAX_JOINTS,
    MAX_PACKET_LEN,
    MAX_RIG_ID_LEN,
    U32_MAX,
    U64_MAX,
    mask_len,
)
from firmware_host.protocol.crc import crc16
from firmware_host.protocol.messages import Header, Hello, Joints, Joints2D, Message, Status

_J3D = np.dtype([("x", "<i2"), ("y", "<i2"), ("z", "<i2"), ("c", "u1")])
_J2D = np.dtype([("u", "<i2"), ("v", "<i2"), ("c", "u1")])
_STATUS = struct.Struct("<HIIIH")
assert _J3D.itemsize == JOINT3D_BYTES and _J2D.itemsize == JOINT2D_BYTES


def _check_range(name: str, value: int, hi: int) -> None:
    # A whole number first (Python or numpy integers, IntEnum/IntFlag): a float such as 1e6 or 3.0 passed the
    # range test and then failed in struct.pack or bytes() with an error that named no field.
    try:
        number = operator.index(value)
    except TypeError:
        raise EncodeError(name, value, f"must be a whole number in 0..{hi}") from None
    if not 0 <= number <= hi:
        raise EncodeError(name, value, f"must be in 0..{hi}")


def _header_bytes(h: Header) -> bytes:
    _check_range("header.version", h.version, 0xFF)
    _check_range("header.msg_type", h.msg_type, 0xFF)
    _check_range("header.flags", h.flags, 0xFF)
    _check_range("header.seq", h.seq, U32_MAX)
    _check_range("header.capture_us", h.capture_us, U64_MAX)
    _check_range("header.send_us", h.send_us, U64_MAX)
    return HEADER.pack(h.version, h.msg_type, h.flags, h.seq, h.capture_us, h.send_us)


def _joint_count(name: str, n: int) -> None:
    if n > MAX_JOINTS:
        raise EncodeError(name, n, f"at most {MAX_JOINTS} joints per packet")


def _check_joint_array(name: str, values: np.ndarray, shape: tuple[int, ...], dtype: type) -> None:
    """A joint array of ``shape`` whose values fit the wire's ``dtype`` (int16 or uint8): numpy's cast would
    wrap 40000 mm to -25536 silently, and a mask of another length makes a packet every decoder refuses. The
    device's own arrays (``quantize``) already have the wire's dtype, so only other callers pay the range scan."""
    values = np.asarray(values)
    if values.shape != shape:
        raise EncodeError(name, values.shape, f"must have the shape {shape}")
    if values.dtype != dtype and values.size:
        # np.iinfo knows no bool: a 0/1 integer mask raised numpy's "Invalid integer data type", naming nothing
        lo, hi = (0, 1) if dtype is np.bool_ else (np.iinfo(dtype).min, np.iinfo(dtype).max)
        if not (np.issubdtype(values.dtype, np.integer) or np.issubdtype(values.dtype, np.bool_)) \
                or values.min() < lo or values.max() > hi:
            raise EncodeError(name, f"{values.dtype} in [{values.min()}, {values.max()}]",
                              f"must be whole numbers in [{lo}, {hi}]")


def _mask(missing: np.ndarray) -> bytes:
    return np.packbits(missing.astype(bool), bitorder="little").tobytes()


def _joints_payload(m: Joints) -> bytes:
    n = len(m.conf)
    _joint_count("joints.count", n)
    _check_range("joints.joint_set", m.joint_set, 0xFF)
    _check_joint_array("joints.xyz_mm", m.xyz_mm, (n, 3), np.int16)
    _check_joint_array("joints.conf", m.conf, (n,), np.uint8)
    _check_joint_array("joints.missing", m.missing, (n,), np.bool_)
    rows = np.empty(n, dtype=_J3D)
    rows["x"], rows["y"], rows["z"] = m.xyz_mm[:, 0], m.xyz_mm[:, 1], m.xyz_mm[:, 2]
    rows["c"] = m.conf
    return bytes((m.joint_set, n)) + _mask(m.missing) + rows.tobytes()


def _joints2d_payload(m: Joints2D) -> bytes:
    n = len(m.conf)
    _joint_count("joints_2d.count", n)
    _check_range("joints_2d.camera", m.camera, 0xFF)
    _check_range("joints_2d.joint_set", m.joint_set, 0xFF)
    _check_joint_array("joints_2d.uv_q", m.uv_q, (n, 2), np.int16)
    _check_joint_array("joints_2d.conf", m.conf, (n,), np.uint8)
    _check_joint_array("joints_2d.missing", m.missing, (n,), np.bool_)
    rows = np.empty(n, dtype=_J2D)
    rows["u"], rows["v"] = m.uv_q[:, 0], m.uv_q[:, 1]
    rows["c"] = m.conf
    return bytes((m.camera, m.joint_set, n)) + _mask(m.missing) + rows.tobytes()


def _status_payload(m: Status) -> bytes:
    _check_range("status.fps_centi", m.fps_centi, 0xFFFF)
    _check_range("status.latency_us", m.latency_us, U32_MAX)
    _check_range("status.dropped", m.dropped, U32_MAX)
    _check_range("status.decimated", m.decimated, U32_MAX)
    _check_range("status.fault", m.fault, 0xFFFF)
    return _STATUS.pack(m.fps_centi, m.latency_us, m.dropped, m.decimated, m.fault)


def _ascii_field(name: str, text: str, max_len: int) -> bytes:
    # Printable ASCII only, so a C decoder can print and compare it without UTF-8 handling.
    if not isinstance(text, str):
        raise EncodeError(name, text, f"must be a str of printable ASCII, at most {max_len} characters")
    if len(text) > max_len or not all(0x20 <= ord(ch) <= 0x7E for ch in text):
        raise EncodeError(name, text, f"must be printable ASCII, at most {max_len} characters")
    return bytes((len(text),)) + text.encode("ascii")


def _hello_payload(m: Hello) -> bytes:
    for name, v in (
        ("hello.protocol_version", m.protocol_version),
        ("hello.joint_set", m.joint_set),
        ("hello.units", m.units),
        ("hello.frame", m.frame),
    ):
        _check_range(name, v, 0xFF)
    _check_range("hello.joint_count", m.joint_count, MAX_JOINTS)
    if isinstance(m.cameras, (str, bytes)):
        # cameras="left" went out as four cameras "l", "e", "f", "t": a sequence of names is meant
        raise EncodeError("hello.cameras", m.cameras, "must be a sequence of camera names, not one string")
    if len(m.cameras) > MAX_CAMERAS:
        raise EncodeError("hello.cameras", m.cameras, f"at most {MAX_CAMERAS} cameras")
    parts = [bytes((m.protocol_version, m.joint_set, m.joint_count, m.units, m.frame))]
    parts.append(_ascii_field("hello.rig_id", m.rig_id, MAX_RIG_ID_LEN))
    parts.append(bytes((len(m.cameras),)))
    parts.extend(_ascii_field("hello.cameras", c, MAX_CAMERA_NAME_LEN) for c in m.cameras)
    return b"".join(parts)


def payload_bytes(msg: Message) -> bytes:
    """The payload of ``msg`` (everything between header and CRC)."""
    if isinstance(msg, Joints):
        return _joints_payload(msg)
    if isinstance(msg, Joints2D):
        return _joints2d_payload(msg)
    if isinstance(msg, Status):
        return _status_payload(msg)
    if isinstance(msg, Hello):
        return _hello_payload(msg)
    raise TypeError(f"not a protocol message: {type(msg).__name__}")


def seal(body: bytes) -> bytes:
    """Append the little-endian CRC to header+payload, giving a packet."""
    if len(body) + 2 > MAX_PACKET_LEN:
        raise EncodeError("packet.length", len(body) + 2, f"packets are at most {MAX_PACKET_LEN} bytes")
    return body + crc16(body).to_bytes(2, "little")


def encode_packet(msg: Message) -> bytes:
    """Header + payload + CRC, not yet COBS-framed."""
    return seal(_header_bytes(msg.header) + payload_bytes(msg))


def frame_packet(packet: bytes) -> bytes:
    """COBS-encode a packet and append the 0x00 delimiter."""
    return cobs.encode(packet) + b"\x00"


def encode(msg: Message) -> bytes:
    """One message -> the bytes to put on the wire."""
    return frame_packet(encode_packet(msg))


def joints_packet_len(count: int) -> int:
    """Decoded packet size of a JOINTS message with ``count`` joints."""
    return HEADER.size + 2 + mask_len(count) + JOINT3D_BYTES * count + 2


def joints2d_packet_len(count: int) -> int:
    return HEADER.size + 3 + mask_len(count) + JOINT2D_BYTES * count + 2


def wire_len(packet_len: int) -> int:
    """Bytes on the wire for a packet of ``packet_len`` bytes, worst case: COBS adds
    one byte per 254 (at least one) and the delimiter adds one."""
    return packet_len + max(1, (packet_len + 253) // 254) + 1
