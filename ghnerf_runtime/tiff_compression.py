"""The TIFF compressions this OpenCV decodes, and their names: one place for every reader of images.

OpenCV decodes a TIFF with its bundled libtiff (4.7.1 in OpenCV 5.0.0), which treats a first directory's
Compression value (tag 259) in one of three ways. Measured in session 64 by tagging a small uncompressed TIFF with
each of the 65536 values and decoding it (``cv2.imdecode`` and ``cv2.imread``; 8 and 16 bits, 1, 3 and 4 channels;
libtiff's messages read), and by the compressions ``cv2.imwrite`` writes (``tests/ghnerf_runtime/
test_tiff_compression.py`` checks both against the OpenCV installed):

* a codec libtiff has and this build includes (:data:`DECODED`): the file decodes, or fails (None) where its data
  or layout does not fit the codec (CCITT fax is 1-bit only, ThunderScan 4-bit, NeXT 2-bit, SGILog LogLuv);
* a codec libtiff has and this build leaves out (old-style JPEG, PixarLog, JBIG, LERC, LZMA, Zstandard, WebP):
  OpenCV fails (None; libtiff prints "... compression support is not configured");
* a value libtiff knows no codec for (JPEG 2000's 34712, and every value not named here): libtiff reports
  "Compression scheme 34712 strip decoding is not implemented" to its error handler, which OpenCV only logs, and
  OpenCV returns an image of the stored size holding zeros: an all-black frame, no error to catch.

So a TIFF whose compression is not in :data:`DECODED` is refused from its header before any decode
(``ghnerf_runtime.image_files``), whichever of the last two it is, and its error names the compression.
"""
from __future__ import annotations

import cv2

__all__ = ["DECODED", "NAMES", "name", "refusal"]

#: The Compression values (tag 259) OpenCV 5.0.0's libtiff decodes: none, CCITT modified Huffman RLE, Group 3 and
#: Group 4 fax, LZW, JPEG, deflate (Adobe's code and the old one), NeXT, CCITT RLE word-aligned, PackBits,
#: ThunderScan, SGILog and SGILog24. ``cv2.imwrite`` writes six of them (1, 5, 7, 8, 32773, 32946).
DECODED = frozenset({1, 2, 3, 4, 5, 7, 8, 32766, 32771, 32773, 32809, 32946, 34676, 34677})

#: Registered Compression values (libtiff's tiff.h) by name, for messages.
NAMES = {
    1: "none", 2: "CCITT modified Huffman RLE", 3: "CCITT Group 3 fax", 4: "CCITT Group 4 fax", 5: "LZW",
    6: "old-style JPEG", 7: "JPEG", 8: "deflate (Adobe)", 9: "JBIG (ITU-T T.85)", 10: "JBIG colour (ITU-T T.43)",
    32766: "NeXT 2-bit RLE", 32771: "CCITT RLE word-aligned", 32773: "PackBits", 32809: "ThunderScan",
    32908: "Pixar film", 32909: "PixarLog", 32946: "deflate", 32947: "Kodak DCS", 34661: "JBIG",
    34676: "SGILog", 34677: "SGILog24", 34712: "JPEG 2000", 34887: "LERC", 34892: "lossy JPEG (DNG)",
    34925: "LZMA", 50000: "Zstandard", 50001: "WebP", 50002: "JPEG XL", 52546: "JPEG XL (DNG)",
}


def name(compression: int) -> str:
    """A Compression value's name, e.g. "JPEG 2000"; "unregistered" for a value no codec is known by."""
    return NAMES.get(compression, "unregistered")


def refusal(compression: int) -> str | None:
    """Why a TIFF of ``compression`` does not decode, e.g. "a TIFF of Compression 34712 (JPEG 2000), which OpenCV
    5.0.0's libtiff does not decode: rewrite it uncompressed or with LZW, deflate or PackBits"; ``None`` for a
    compression it decodes."""
    if compression in DECODED:
        return None
    return (f"a TIFF of Compression {compression} ({name(compression)}), which OpenCV {cv2.__version__}'s libtiff "
            f"does not decode: rewrite it uncompressed or with LZW, deflate or PackBits")
