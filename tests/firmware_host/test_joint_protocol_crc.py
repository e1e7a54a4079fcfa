"""CRC-16/IBM-3740 against a bit-by-bit reference and the worked example in docs/protocol.md."""
from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_host.protocol.crc import crc16


def crc16_reference(data: bytes) -> int:
    """Straight from the definition: poly 0x1021, init 0xFFFF, MSB first, no final xor."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def test_check_value_of_the_catalogue() -> None:
    assert crc16(b"123456789") == 0x29B1 == crc16_reference(b"123456789")


@settings(deadline=None)
@given(st.binary(max_size=600))
def test_matches_bitwise_reference(data: bytes) -> None:
    assert crc16(data) == crc16_reference(data)


@settings(deadline=None)
@given(st.binary(max_size=100), st.binary(max_size=100))
def test_can_be_continued_across_chunks(a: bytes, b: bytes) -> None:
    assert crc16(b, crc16(a)) == crc16(a + b)


def test_worked_example_in_docs() -> None:
    # The STATUS packet worked through byte by byte in docs/protocol.md.
    body = bytes.fromhex(
        "01 02 00 2a000000 40420f0000000000 e8bd0f0000000000 b80b 10a40000 03000000 78000000 0100"
    )
    assert crc16(body) == crc16_reference(body) == 0xF8D5
