"""A decoder written from docs/protocol.md alone decodes every shared vector as the real decoders do.

The point is the doc, not the code: someone on the receiving side (a robot's firmware, a game console) writes
their decoder from docs/protocol.md. So every layout, limit and constant below is read out of the doc's text
(its tables, its stated sizes, its CRC parameters, its COBS steps, its check order), never imported from
``firmware_host.protocol``; the real encoder is used only to check the doc's examples. A rule the doc leaves out
or states wrongly makes this decoder disagree with a vector's expected events.
"""
from __future__ import annotations

import json
import re
import struct
from pathlib import Path
from typing import Any

import pytest
from cobs import cobs

from drivers.sim.scene import SceneConfig, SimScene
from firmware_host.protocol import decode_stream
from firmware_host.protocol.constants import MsgType
from firmware_host.protocol.encoder import encode, encode_packet, frame_packet
from firmware_host.protocol.messages import Status, make_header
from ghnerf_runtime.body25 import JOINT_NAMES
from tests.firmware_host.joint_stream_helpers import MASK_RULES_JOINTS, mask_rules_packet

ROOT = Path(__file__).resolve().parents[2]
DOC = (ROOT / "docs" / "protocol.md").read_text()
VECTOR_DIR = ROOT / "tests" / "vectors" / "joint_stream"
STRUCT_CODES = {"u8": "B", "u16": "H", "u32": "I", "u64": "Q", "i16": "h"}  # the doc's integer types


class DocFrameError(Exception):
    """A frame the doc's rules classify as an error; ``code`` is the doc's name for it."""

    def __init__(self, code: str) -> None:
        super().__init__(code)
        self.code = code


class DocSkipped(Exception):
    """A valid packet of a type the doc does not list."""

    def __init__(self, msg_type: int) -> None:
        super().__init__(msg_type)
        self.msg_type = msg_type


# ---- reading the doc ----------------------------------------------------------------------------------------


def section(heading: str) -> str:
    """The text under a heading (any level) up to the next heading of the same or a higher level."""
    m = re.search(rf"^(#+) {re.escape(heading)}.*$", DOC, re.M)
    assert m, f"docs/protocol.md has no heading {heading!r}"
    level = len(m.group(1))
    end = re.compile(rf"^#{{1,{level}}} ", re.M).search(DOC, m.end())
    return DOC[m.end(): end.start() if end else len(DOC)]


def table_rows(text: str) -> list[list[str]]:
    """Body rows of the first Markdown table in ``text``, cells stripped, header and rule left out."""
    m = re.search(r"(?m)(^\|.*\n)+", text)
    assert m, "no table"
    lines = m.group(0).splitlines()
    return [[c.strip() for c in ln.strip("|").split("|")] for ln in lines[2:]]


def one_int(pattern: str, text: str = DOC) -> int:
    m = re.search(pattern, text)
    assert m, f"docs/protocol.md does not state {pattern!r}"
    return int(m.group(1), 0)


def limit_in(cell: str) -> int:
    """The bound a cell states as ``≤ N``."""
    return one_int(r"≤ (\d+)", cell)


def hex_bytes(block: str) -> bytes:
    """Every two-digit hex token at the start of a line's columns (field notes after them are skipped)."""
    out = bytearray()
    for line in block.splitlines():
        line = re.sub(r"^(header|payload|crc)\s", "", line.strip())
        for token in line.split():
            if not re.fullmatch(r"[0-9a-f]{2}", token):
                break
            out.append(int(token, 16))
    return bytes(out)


def code_blocks(text: str) -> list[str]:
    return re.findall(r"```\n(.*?)```", text, re.S)


def byte_cell(cell: str) -> bytes:
    """A COBS example cell: hex bytes in backticks, ``× n`` repeating the group before it."""
    out = bytearray()
    for group, times in re.findall(r"`([0-9a-f ]+)`(?:\s*×\s*(\d+))?", cell):
        out += bytes.fromhex(group) * int(times or 1)
    return bytes(out)


# ---- the layout, as the doc states it -----------------------------------------------------------------------

MAX_PACKET = one_int(r"A \*\*packet\*\* is at most \*\*(\d+) bytes\*\*")
MAX_FRAME = one_int(r"At most \*\*(\d+) bytes\*\* may stand between two")
HEADER_SIZE = one_int(r"(?m)^## 3\. Header \((\d+) bytes\)")
CRC_SIZE = one_int(r"crc16 \((\d+) bytes, little-endian\)")
MSG_TYPES = {int(row[0], 16): row[1] for row in table_rows(section("4. Messages"))}


def header_struct() -> tuple[struct.Struct, list[str]]:
    rows = table_rows(section("3. Header"))
    names, fmt, offset = [], "<", 0
    for off, typ, name, _meaning in rows:
        assert int(off) == offset, f"header field {name} at offset {off}, the fields before end at {offset}"
        names.append(name)
        fmt += STRUCT_CODES[typ]
        offset += struct.calcsize("<" + STRUCT_CODES[typ])
    return struct.Struct(fmt), names


HEADER, HEADER_FIELDS = header_struct()
STATUS_ROWS = table_rows(section("STATUS (0x02)"))
STATUS = struct.Struct("<" + "".join(STRUCT_CODES[typ] for typ, _name, _m in STATUS_ROWS))
STATUS_FIELDS = [name for _typ, name, _m in STATUS_ROWS]


def joint_row_struct(message: str) -> struct.Struct:
    """The per-joint layout, from the ``joints`` row: ``i16 x, i16 y, ..., u8 confidence``."""
    row = next(r for r in table_rows(section(message)) if r[1] == "joints")
    types = re.findall(r"\b(u8|i16) \w+", row[2])
    assert int(row[0].split()[0]) == sum(struct.calcsize(STRUCT_CODES[t]) for t in types)
    return struct.Struct("<" + "".join(STRUCT_CODES[t] for t in types))


JOINT3D = joint_row_struct("JOINTS (0x10)")
JOINT2D = joint_row_struct("JOINTS_2D (0x11)")
HELLO_ROWS = {row[1]: row[2] for row in table_rows(section("HELLO (0x01)"))}
MAX_JOINTS = limit_in(HELLO_ROWS["joint_count"])
MAX_RIG_ID = limit_in(HELLO_ROWS["rig_id"])
MAX_CAMERAS = limit_in(HELLO_ROWS["camera_count"])
MAX_CAMERA_NAME = limit_in(HELLO_ROWS["camera names"])
CHECK_ORDER = [row[1].strip("`") for row in table_rows(section("5. Decoding rules"))]


def doc_crc(data: bytes) -> int:
    """CRC-16 by the parameters section 2 states, bit by bit (no table, no library)."""
    text = section("2. CRC")
    poly = one_int(r"polynomial\s+`(0x[0-9A-Fa-f]+)`", text)
    crc = one_int(r"initial value `(0x[0-9A-Fa-f]+)`", text)
    xorout = one_int(r"final XOR\s+`(0x[0-9A-Fa-f]+)`", text)
    assert "input and output not reflected" in text
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ poly) if crc & 0x8000 else crc << 1
            crc &= 0xFFFF
    return crc ^ xorout


# ---- the decoder, step by step as the doc says --------------------------------------------------------------


def doc_cobs_decode(frame: bytes) -> bytes:
    """Section 1, "COBS, byte by byte", steps 1-4."""
    out, i = bytearray(), 0
    while i < len(frame):
        n = frame[i]
        if len(frame) - (i + 1) < n - 1:
            raise DocFrameError("cobs")
        out += frame[i + 1: i + n]
        i += n
        if n < 0xFF and i < len(frame):
            out.append(0)
    return bytes(out)


def need(payload: bytes, n: int) -> None:
    if len(payload) < n:
        raise DocFrameError("malformed")


def mask_bits(payload: bytes, offset: int, count: int) -> list[int]:
    """Bit i, LSB first: byte i/8, bit i mod 8."""
    return [(payload[offset + i // 8] >> (i % 8)) & 1 for i in range(count)]


def doc_joints(payload: bytes, head: int, row: struct.Struct) -> tuple[list[int], list[list[int]]]:
    """Fields before the count, then count, mask and joints: shared by JOINTS and JOINTS_2D."""
    need(payload, head)
    count = payload[head - 1]
    if count > MAX_JOINTS:
        raise DocFrameError("malformed")
    mask_len = (count + 7) // 8
    need(payload, head + mask_len + row.size * count)
    missing = mask_bits(payload, head, count)
    rows = [list(row.unpack_from(payload, head + mask_len + row.size * i)) + [missing[i]] for i in range(count)]
    return list(payload[: head - 1]), rows


def doc_string(payload: bytes, offset: int, max_len: int) -> tuple[str, int]:
    need(payload, offset + 1)
    n = payload[offset]
    need(payload, offset + 1 + n)
    raw = payload[offset + 1: offset + 1 + n]
    if n > max_len or not all(0x20 <= b <= 0x7E for b in raw):
        raise DocFrameError("malformed")
    return raw.decode("ascii"), offset + 1 + n


def doc_hello(payload: bytes) -> dict[str, Any]:
    fixed = ["protocol_version", "joint_set", "joint_count", "units", "frame"]
    assert list(HELLO_ROWS)[: len(fixed)] == fixed
    need(payload, len(fixed))
    fields = dict(zip(fixed, payload))
    if fields["joint_count"] > MAX_JOINTS:
        raise DocFrameError("malformed")
    fields["rig_id"], off = doc_string(payload, len(fixed), MAX_RIG_ID)
    need(payload, off + 1)
    n_cameras, off = payload[off], off + 1
    if n_cameras > MAX_CAMERAS:
        raise DocFrameError("malformed")
    fields["cameras"] = []
    for _ in range(n_cameras):
        name, off = doc_string(payload, off, MAX_CAMERA_NAME)
        fields["cameras"].append(name)
    return fields


def doc_payload(name: str, payload: bytes) -> dict[str, Any]:
    if name == "STATUS":
        need(payload, STATUS.size)
        return dict(zip(STATUS_FIELDS, STATUS.unpack_from(payload)))
    if name == "HELLO":
        return doc_hello(payload)
    if name == "JOINTS":
        (joint_set,), joints = doc_joints(payload, 2, JOINT3D)
        return {"joint_set": joint_set, "joints": joints}
    (camera, joint_set), joints = doc_joints(payload, 3, JOINT2D)
    return {"camera": camera, "joint_set": joint_set, "joints": joints}


def doc_packet(packet: bytes) -> dict[str, Any]:
    """Section 5's checks after COBS, in its order; bytes past the known fields are ignored."""
    if len(packet) > MAX_PACKET:
        raise DocFrameError("oversize")
    if len(packet) < HEADER_SIZE + CRC_SIZE:
        raise DocFrameError("short")
    body = packet[:-CRC_SIZE]
    if int.from_bytes(packet[-CRC_SIZE:], "little") != doc_crc(body):
        raise DocFrameError("crc")
    header = dict(zip(HEADER_FIELDS, HEADER.unpack_from(body)))
    if header["version"] != 1:
        raise DocFrameError("version")
    name = MSG_TYPES.get(header["msg_type"])
    if name is None:
        raise DocSkipped(header["msg_type"])
    del header["msg_type"]
    return {"type": name, **header, **doc_payload(name, body[HEADER_SIZE:])}


def doc_frame_event(frame: bytes) -> dict[str, Any]:
    try:
        if len(frame) > MAX_FRAME:
            raise DocFrameError("oversize")
        return doc_packet(doc_cobs_decode(frame))
    except DocFrameError as e:
        return {"error": e.code}
    except DocSkipped as e:
        return {"skipped": "unknown", "msg_type": e.msg_type}


def doc_stream(data: bytes) -> tuple[list[dict[str, Any]], dict[str, int]]:
    """Frames end at each 0x00; empty ones are ignored; bytes after the last 0x00 give nothing yet."""
    events = [doc_frame_event(frame) for frame in data.split(b"\x00")[:-1] if frame]
    stats = {"frames": len(events), "messages": sum("type" in e for e in events),
             "skipped": sum("skipped" in e for e in events)}
    stats.update({code: sum(e.get("error") == code for e in events) for code in CHECK_ORDER if code != "skipped"
                  and code != "message"})
    return events, stats


# ---- tests --------------------------------------------------------------------------------------------------


def test_doc_states_the_sizes_the_decoders_use() -> None:
    assert (HEADER.size, HEADER_SIZE, CRC_SIZE, MAX_PACKET, MAX_FRAME) == (23, 23, 2, 512, 515)
    assert STATUS.size == one_int(r"STATUS \(0x02\) — (\d+) bytes")
    assert CHECK_ORDER == ["oversize", "cobs", "short", "crc", "version", "skipped", "malformed", "message"]
    # 512 bytes need ceil(512 / 254) = 3 COBS code bytes: the 515 the doc allows between delimiters
    assert MAX_FRAME == MAX_PACKET + -(-MAX_PACKET // 254)


def test_doc_crc_parameters_give_the_stated_check_value() -> None:
    assert doc_crc(b"123456789") == one_int(r'CRC\("123456789"\) = (0x[0-9A-F]+)')


def test_doc_cobs_examples_are_what_the_encoder_writes() -> None:
    rows = table_rows(section("COBS, byte by byte"))
    assert len(rows) >= 5
    for packet_cell, frame_cell in rows:
        packet, frame = byte_cell(packet_cell), byte_cell(frame_cell)
        assert frame_packet(packet) == frame, packet_cell
        assert doc_cobs_decode(frame[:-1]) == packet, packet_cell


def test_doc_cobs_steps_take_a_trailing_empty_block_as_packetserial_writes_it() -> None:
    packet = bytes(range(1, 255))  # 254 non-zero bytes: one full 0xFF block
    assert doc_cobs_decode(cobs.encode(packet)) == packet
    assert doc_cobs_decode(cobs.encode(packet) + b"\x01") == packet
    with pytest.raises(DocFrameError):
        doc_cobs_decode(b"\x05\x01\x02")  # the code asks for 4 bytes, 2 remain


def test_worked_example_bytes_in_the_doc_are_the_encoders_and_decode_by_the_doc() -> None:
    text = section("Worked example")
    packet_block, frame_block = code_blocks(text)[:2]
    packet, frame = hex_bytes(packet_block), hex_bytes(frame_block)
    msg = Status(make_header(MsgType.STATUS, 42, 1_000_000, 1_031_656), 3000, 42000, 3, 120, 1)
    assert encode_packet(msg) == packet
    assert encode(msg) == frame
    assert len(packet) == one_int(r"(\d+) packet bytes become", text)
    assert len(frame) == one_int(r"become (\d+) bytes on the wire", text)
    assert doc_crc(packet[:-2]) == one_int(r"of the \d+ bytes above = (0x[0-9A-F]+)", text)
    events, _ = doc_stream(frame)
    assert events == [{"type": "STATUS", "version": 1, "flags": 0, "seq": 42, "capture_us": 1_000_000,
                       "send_us": 1_031_656, "fps_centi": 3000, "latency_us": 42000, "dropped": 3,
                       "decimated": 120, "fault": 1}]


def test_doc_body25_order_is_the_runtimes() -> None:
    text = re.search(r"BODY_25 order: (.*?)\(`ghnerf_runtime/body25.py`\)", DOC, re.S)
    assert text
    pairs = re.findall(r"(\d+) (\w+)", text.group(1))
    assert [int(i) for i, _ in pairs] == list(range(len(pairs)))
    assert tuple(name for _, name in pairs) == tuple(JOINT_NAMES)


@pytest.mark.parametrize("name", sorted(p.stem for p in VECTOR_DIR.glob("*.bin")))
def test_doc_only_decoder_passes_vector(name: str) -> None:
    expected = json.loads((VECTOR_DIR / f"{name}.json").read_text())
    events, stats = doc_stream((VECTOR_DIR / f"{name}.bin").read_bytes())
    assert events == expected["events"]
    assert stats == expected["stats"]


def test_doc_only_decoder_keeps_malformed_and_oversize_apart_at_the_limits() -> None:
    big = b"\x01" * (MAX_FRAME + 1)
    events, _ = doc_stream(b"\x00" + big + b"\x00")
    assert events == [{"error": "oversize"}]


def test_mask_bit_decides_and_padding_bits_are_ignored_as_the_doc_says() -> None:
    frame = frame_packet(mask_rules_packet())
    events, _ = doc_stream(frame)
    assert [e["joints"] for e in events] == [MASK_RULES_JOINTS]
    assert [e.to_json()["joints"] for e in decode_stream(frame)[0]] == [MASK_RULES_JOINTS]


def test_a_person_facing_the_cameras_has_the_right_shoulder_at_negative_x() -> None:
    """docs/protocol.md, BODY_25 order: R and L are the person's own sides. The simulated rig's person faces the
    cameras at heading 0 (nose nearer the cameras than the neck)."""
    joints = SimScene(SceneConfig(seed=0, heading_deg=0.0)).joints_3d(0.0)
    index = {name: i for i, name in enumerate(JOINT_NAMES)}
    assert joints[index["Nose"], 2] < joints[index["Neck"], 2]
    assert joints[index["RShoulder"], 0] < 0.0 < joints[index["LShoulder"], 0]
