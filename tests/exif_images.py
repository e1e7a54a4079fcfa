"""Images tagged with an EXIF orientation, as a phone writes them, built byte by byte (no files from elsewhere):
OpenCV turns such an image by its tag for every read flag but IMREAD_UNCHANGED and IMREAD_IGNORE_ORIENTATION."""
from __future__ import annotations

import struct
import zlib

# one segment builder for these images and the benchmark's take of phone JPEGs
from benchmarks.time_replay_open import jpeg_segment

__all__ = ["exif_orientation", "jpeg_segment", "jpeg_turned", "png_turned"]


def exif_orientation(orientation: int) -> bytes:
    """A big-endian TIFF block holding one tag, the EXIF orientation (6: turn a quarter, as a phone held upright
    writes it; 3: half a turn)."""
    return b"MM\x00*\x00\x00\x00\x08" + struct.pack(">HHHIHH", 1, 0x0112, 3, 1, orientation, 0) + b"\x00" * 4


def jpeg_turned(jpeg: bytes, orientation: int = 6) -> bytes:
    """``jpeg`` with an APP1 EXIF segment holding ``orientation``, first after its start marker."""
    return jpeg[:2] + jpeg_segment(0xE1, b"Exif\x00\x00" + exif_orientation(orientation)) + jpeg[2:]


def png_turned(png: bytes, orientation: int = 6) -> bytes:
    """``png`` with an eXIf chunk holding ``orientation``, right after its signature and IHDR."""
    exif = exif_orientation(orientation)
    chunk = struct.pack(">I", len(exif)) + b"eXIf" + exif + struct.pack(">I", zlib.crc32(b"eXIf" + exif))
    return png[:33] + chunk + png[33:]
