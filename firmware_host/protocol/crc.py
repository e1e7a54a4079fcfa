"""CRC-16/IBM-3740 (also called CRC-16/CCITT-FALSE), the packet check of the protocol.

Parameters (reveng catalogue): width 16, poly 0x1021, init 0xFFFF, refin false,
refout false, xorout 0x0000, check("123456789") = 0x29B1.
"""
from __future__ import annotations

import binascii

CRC_INIT = 0xFFFF


def crc16(data: bytes | bytearray | memoryview, crc: int = CRC_INIT) -> int:
    """CRC-16/IBM-3740 of ``data``; pass the previous value as ``crc`` to continue.

    ``binascii.crc_hqx`` is the same polynomial, unreflected, with a caller-chosen
    initial value, so it is exactly this CRC when started from 0xFFFF (and runs in C).

    >>> hex(crc16(b"123456789"))
    '0x29b1'
    """
    return binascii.crc_hqx(data, crc)
