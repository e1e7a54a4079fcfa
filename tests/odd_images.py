"""Image files OpenCV treats oddly, built byte by byte (no files from elsewhere)."""
from __future__ import annotations

import struct

import cv2
import numpy as np

#: OpenCV's default limit on a decoded image's side (CV_IO_MAX_IMAGE_WIDTH/HEIGHT)
OPENCV_MAX_SIDE = 1 << 20


def bmp_beyond_opencv_s_limits() -> bytes:
    """A 40x30 BMP whose header says it is 2**21 wide: ``cv2.imread`` and ``cv2.imdecode`` raise a cv2.error
    for it (a size beyond OpenCV's limits), where an unreadable file gives None."""
    ok, buf = cv2.imencode(".bmp", np.zeros((30, 40, 3), np.uint8))
    assert ok
    data = bytearray(buf.tobytes())
    struct.pack_into("<i", data, 18, 2 * OPENCV_MAX_SIDE)  # the info header's width
    return bytes(data)


#: The colour masks of a BI_BITFIELDS BMP (red, green, blue): 16-bit 5-6-5 and 5-5-5, one OpenCV does not decode
#: (4-4-4), and 32-bit 8-8-8.
BMP_MASKS = {"565": (0xF800, 0x07E0, 0x001F), "555": (0x7C00, 0x03E0, 0x001F), "444": (0x0F00, 0x00F0, 0x000F),
             "888": (0xFF0000, 0x00FF00, 0x0000FF)}


def bmp_built(bits: int, compression: int, info_size: int, *, masks: str = "", masks_in_header: bool = False,
              masks_after_header: bool = False, colours_used: int = 0, width: int = 5, height: int = 3) -> bytes:
    """A BMP of ``width`` x ``height`` built byte by byte, as a writer lays one out: the 14-byte file header, an
    info header of ``info_size`` bytes (zeros past the first 40, but the colour masks at its bytes 40-52 where
    ``masks_in_header``, as V2 to V5 headers hold them), the masks after it where ``masks_after_header`` (as a
    40-byte header's follow it), a palette of ``2**bits`` colours up to 8 bits, then the pixels: rows padded to
    4 bytes, or for RLE (compression 1 and 2) one run a row, each row's end and the bitmap's end."""
    mask_bytes = struct.pack("<III", *BMP_MASKS[masks]) if masks else b""
    extra = bytearray(info_size - 40)
    if masks_in_header:
        extra[:12] = mask_bytes
    after = mask_bytes if masks_after_header else b""
    palette = bytes(n % 256 for n in range(4 << bits)) if bits <= 8 else b""
    if compression in (1, 2):
        pixels = (bytes([width, 0x11 if compression == 2 else 1]) + b"\x00\x00") * height + b"\x00\x01"
    else:
        row = (width * bits + 31) // 32 * 4
        pixels = bytes(n % 256 for n in range(row * height))
    offset = 14 + info_size + len(after) + len(palette)
    info = struct.pack("<IiiHHIIiiII", info_size, width, height, 1, bits, compression, len(pixels), 2835, 2835,
                       colours_used, 0)
    return b"BM" + struct.pack("<IHHI", offset + len(pixels), 0, 0, offset) + info + bytes(extra) + after + palette \
        + pixels
