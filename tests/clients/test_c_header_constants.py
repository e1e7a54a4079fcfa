"""clients/c/ghjoints.h states the protocol's constants a second time: they must be the Python ones.

The header's ``#define``s and its ``ghj_result`` enum are read as text (no compiler needed, so this runs
where the C tests skip) and compared with ``firmware_host.protocol.constants``, the wire protocol's source
of truth. The differential tests catch a wrong bound only on inputs that reach it; a fault code, a flag or
a message type that C names differently from Python is passed through by both decoders and caught by none.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from firmware_host.protocol import constants as proto

REPO = Path(__file__).resolve().parents[2]
HEADER = REPO / "clients" / "c" / "ghjoints.h"
SOURCE = REPO / "clients" / "c" / "ghjoints.c"

# "#define NAME 0x10u /* comment */": an integer literal with an optional unsigned/long suffix.
_DEFINE = re.compile(r"^\s*#\s*define\s+(GHJ_\w+)\s+(0[xX][0-9A-Fa-f]+|\d+)[uUlL]*\s*(?:/\*.*)?$")
_ENUM_MEMBER = re.compile(r"^\s*(GHJ_\w+)\s*=\s*(-?\d+)\s*,?")


def _literal(text: str) -> int:
    return int(text, 16) if text.lower().startswith("0x") else int(text)


def header_defines(text: str) -> dict[str, int]:
    """Every ``#define GHJ_...`` of an integer literal; a name defined twice (with different values) fails."""
    found: dict[str, int] = {}
    for number, line in enumerate(text.splitlines(), 1):
        m = _DEFINE.match(line)
        if not m:
            continue
        name, value = m.group(1), _literal(m.group(2))
        if name in found and found[name] != value:
            raise AssertionError(f"{HEADER.name}:{number}: {name} defined again as {value}, was {found[name]}")
        found[name] = value
    return found


def result_enum(text: str) -> dict[str, int]:
    """The members of ``typedef enum {...} ghj_result``."""
    m = re.search(r"typedef\s+enum\s*\{(.*?)\}\s*ghj_result\s*;", text, re.S)
    assert m, f"{HEADER}: no ghj_result enum"
    return {k.group(1): int(k.group(2)) for k in map(_ENUM_MEMBER.match, m.group(1).splitlines()) if k}


@pytest.fixture(scope="module")
def defines() -> dict[str, int]:
    return header_defines(HEADER.read_text())


def _group(defines: dict[str, int], prefix: str) -> dict[str, int]:
    return {name[len(prefix):]: value for name, value in defines.items() if name.startswith(prefix)}


def test_sizes_and_bounds_match(defines):
    expected = {
        "GHJ_PROTOCOL_VERSION": proto.PROTOCOL_VERSION,
        "GHJ_HEADER_LEN": proto.HEADER_LEN,
        "GHJ_CRC_LEN": proto.CRC_LEN,
        "GHJ_MAX_PACKET_LEN": proto.MAX_PACKET_LEN,
        "GHJ_MAX_FRAME_LEN": proto.MAX_FRAME_LEN,
        "GHJ_PROTOCOL_MAX_JOINTS": proto.MAX_JOINTS,
        "GHJ_MAX_JOINTS": proto.MAX_JOINTS,  # the default capacity: every packet the protocol allows
        "GHJ_MAX_RIG_ID_LEN": proto.MAX_RIG_ID_LEN,
        "GHJ_MAX_CAMERAS": proto.MAX_CAMERAS,
        "GHJ_MAX_CAMERA_NAME_LEN": proto.MAX_CAMERA_NAME_LEN,
    }
    actual = {name: defines.get(name) for name in expected}
    assert actual == expected


@pytest.mark.parametrize("prefix, enum, skip", [
    ("GHJ_MSG_", proto.MsgType, ()),
    ("GHJ_FLAG_", proto.Flags, ("NONE",)),  # no flag is 0, not a define
    ("GHJ_FAULT_", proto.Fault, ()),
])
def test_named_codes_match_both_ways(defines, prefix, enum, skip):
    """Every Python member has a C define of the same name and value, and C has none that Python lacks."""
    python = {member.name: int(member.value) for member in enum if member.name not in skip}
    assert _group(defines, prefix) == python


def test_the_scene_flags_mask_matches(defines):
    """GHJ_SCENE_FLAGS (what a HELLO's flags announce) is the Python SCENE_FLAGS, and names exactly the scene
    flags: a firmware masks a frame's flags with it to tell the estimate's bits from the link's."""
    assert defines.get("GHJ_SCENE_FLAGS") == proto.SCENE_FLAGS
    scene = {"SEVERAL_PEOPLE", "PRIOR_FALLBACK", "SINGLE_VIEW", "CALIBRATION_SUSPECT"}
    assert sum(defines[f"GHJ_FLAG_{name}"] for name in scene) == proto.SCENE_FLAGS


def test_the_mask_of_a_sender_that_scans_for_others_matches(defines):
    """GHJ_ALL_SCENE_FLAGS (the HELLO of a sender that scans for others, since session 65) is the Python
    ALL_SCENE_FLAGS: GHJ_SCENE_FLAGS and GHJ_FLAG_SOMEONE_ELSE, bit 6, the reserved bit before."""
    assert defines.get("GHJ_FLAG_SOMEONE_ELSE") == 0x40 == int(proto.Flags.SOMEONE_ELSE)
    assert defines.get("GHJ_ALL_SCENE_FLAGS") == proto.ALL_SCENE_FLAGS == proto.hello_scene_flags(True)
    assert defines["GHJ_ALL_SCENE_FLAGS"] == defines["GHJ_SCENE_FLAGS"] | defines["GHJ_FLAG_SOMEONE_ELSE"]


def test_results_follow_the_protocol_s_check_order():
    """ghj_result's errors are -1, -2, ... in docs/protocol.md section 5's order (ERROR_CODES); the decoders'
    event names (ghj_result_name, ghj_dump, ghnerf-listen) come from them."""
    members = result_enum(HEADER.read_text())
    errors = {name[len("GHJ_ERR_"):].lower(): value for name, value in members.items()
              if name.startswith("GHJ_ERR_") and name != "GHJ_ERR_CONFIG"}  # a build error, not the protocol's
    assert errors == {code: -(k + 1) for k, code in enumerate(proto.ERROR_CODES)}
    assert members["GHJ_ERR_CONFIG"] == min(members.values())  # after every protocol error
    names = dict(re.findall(r'case (GHJ_\w+): return "(\w+)";', SOURCE.read_text()))
    assert {names[f"GHJ_ERR_{code.upper()}"] for code in proto.ERROR_CODES} == set(proto.ERROR_CODES)


def test_the_max_joints_guard_and_the_decoder_use_the_protocol_s_bound(defines):
    """The header's #error range and ghjoints.c's count checks name GHJ_PROTOCOL_MAX_JOINTS rather than
    repeating 64, so the comparison above covers them too."""
    header = HEADER.read_text()
    assert re.search(r"#if GHJ_MAX_JOINTS < 1 \|\| GHJ_MAX_JOINTS > GHJ_PROTOCOL_MAX_JOINTS\b", header)
    body = re.sub(r"/\*.*?\*/", "", SOURCE.read_text(), flags=re.S)
    assert not re.search(rf"\b{proto.MAX_JOINTS}u?\b", body), f"{SOURCE.name} repeats {proto.MAX_JOINTS}"
    assert body.count("> GHJ_PROTOCOL_MAX_JOINTS") == 3  # JOINTS, JOINTS_2D, HELLO's joint_count


@pytest.mark.parametrize("line, value", [
    ("#define GHJ_MSG_JOINTS 0x10u", 16),
    ("#define GHJ_MAX_FRAME_LEN 515u  /* COBS-encoded bytes */", 515),
    ("  #  define GHJ_X 7", 7),
])
def test_header_defines_reads_literals(line, value):
    name = line.split("define")[1].split()[0]
    assert header_defines(line) == {name: value}


def test_header_defines_refuses_a_second_different_value():
    with pytest.raises(AssertionError, match="GHJ_X defined again as 2, was 1"):
        header_defines("#define GHJ_X 1u\n#define GHJ_X 2u\n")


def test_the_decoder_reads_fields_byte_by_byte():
    """docs/c-decoder.md promises any byte order and alignment: the little-endian wire is read from single bytes
    with shifts. A cast to a wider pointer, a memcpy into a field or a byte-order macro would tie it to the host."""
    body = re.sub(r"/\*.*?\*/", "", SOURCE.read_text(), flags=re.S)
    wide_cast = re.compile(r"\(\s*(?:const\s+)?u?int(?:16|32|64)_t\s*\*\s*\)")
    assert not wide_cast.search(body), wide_cast.search(body)
    for word in ("memcpy", "memmove", "__BYTE_ORDER__", "htons", "ntohs", "htole", "le16toh", "le32toh", "le64toh"):
        assert word not in body, f"{SOURCE.name} uses {word}"
    # every multi-byte field goes through the readers that shift bytes into place
    assert re.search(r"static uint16_t rd_u16\(const uint8_t \*p\).*p\[1\] << 8", body)
    assert re.search(r"static uint32_t rd_u32\(const uint8_t \*p\)", body)
