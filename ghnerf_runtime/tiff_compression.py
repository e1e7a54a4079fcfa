"""The TIFF compressions this OpenCV decodes, and their names: one place for every reader of images.

OpenCV decodes a TIFF with its bundled libtiff (4.7.1 in OpenCV 5.0.0), which treats a first directory's
Compression value (tag 259) in one of three ways. Measured in session 64 by tagging a small uncompressed TIFF with
each of the 65536 values and decoding it (``cv2.imdecode`` and ``cv2.imread``; 8 and 16 bits, 1, 3 and 4 channels;
libtiff's messages read), and by the compressions ``cv2.imwrite`` writes (``tests/ghnerf_runtime/
test_tiff_compression.py`` checks both against the OpenCV installed):

* a codec libtiff has and this build includes (:func:`decoded`): the file decodes, or fails (None) where its data
  or layout does not fit the codec (CCITT fax is 1-bit only, ThunderScan 4-bit, NeXT 2-bit, SGILog LogLuv);
* a codec libtiff has and this build leaves out (old-style JPEG, PixarLog, JBIG, LERC, LZMA, Zstandard, WebP):
  OpenCV fails (None; libtiff prints "... compression support is not configured");
* a value libtiff knows no codec for (JPEG 2000's 34712, and every value not named here): libtiff reports
  "Compression scheme 34712 strip decoding is not implemented" to its error handler, which OpenCV only logs, and
  OpenCV returns an image of the stored size holding zeros: an all-black frame, no error to catch.

So a TIFF whose compression OpenCV does not decode (:func:`decoded`) is refused from its header before any decode
(``ghnerf_runtime.image_files``), whichever of the last two it is, and its error names the compression.

Which codecs a build includes is its own: OpenCV 5.0.0's wheel leaves WebP (50001) out, 5.1's (allowed by the
pyproject floor) is reported to include it. So the compressions every build's libtiff decodes are listed
(:data:`BUILT_IN`), and each optional one a sample file can be built for (:data:`PROBED`: WebP) is asked of the
installed OpenCV by decoding a tiny in-memory TIFF once per process (:func:`decoded`): a build that decodes it
accepts that compression, one that does not refuses it, naming the build.
"""
from __future__ import annotations

import contextlib
import functools
import struct
from collections.abc import Callable, Iterator

import cv2
import numpy as np

__all__ = ["BUILT_IN", "NAMES", "PROBED", "decoded", "decodes_sample", "name", "opencv_log_silenced", "refusal",
           "single_strip_rgb_tiff", "webp_sample"]

#: The Compression values (tag 259) every OpenCV 5 build's libtiff decodes (its built-in codecs): none, CCITT
#: modified Huffman RLE, Group 3 and Group 4 fax, LZW, JPEG, deflate (Adobe's code and the old one), NeXT, CCITT RLE
#: word-aligned, PackBits, ThunderScan, SGILog and SGILog24. ``cv2.imwrite`` writes six of them (1, 5, 7, 8, 32773,
#: 32946).
BUILT_IN = frozenset({1, 2, 3, 4, 5, 7, 8, 32766, 32771, 32773, 32809, 32946, 34676, 34677})

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


#: libtiff's Compression value for WebP (tiff.h's COMPRESSION_WEBP), the one optional codec probed.
_WEBP = 50001
#: The image a probe's sample holds: one grey, 8-bit BGR (WebP's lossless mode keeps it exactly).
_PROBE_SIDE, _PROBE_LEVEL = 8, 97


def _probe_image() -> np.ndarray:
    return np.full((_PROBE_SIDE, _PROBE_SIDE, 3), _PROBE_LEVEL, np.uint8)


def webp_sample() -> bytes:
    """A tiny 8-bit RGB TIFF of :func:`_probe_image` whose one strip is WebP-compressed (Compression 50001): a
    lossless WebP bitstream of the whole strip, as libtiff's WebP codec writes one. Built byte by byte, as no
    build without that codec can write one."""
    ok, webp = cv2.imencode(".webp", _probe_image(), [cv2.IMWRITE_WEBP_QUALITY, 101])  # above 100: lossless
    if not ok:
        return b""  # no WebP encoder either: the probe fails, and 50001 is refused
    return single_strip_rgb_tiff(_PROBE_SIDE, _PROBE_SIDE, _WEBP, webp.tobytes())


def single_strip_rgb_tiff(width: int, height: int, compression: int, strip: bytes) -> bytes:
    """A little-endian classic TIFF of one 8-bit RGB strip: header, BitsPerSample's three values, the strip, then
    the directory (libtiff's order)."""
    bits_at, strip_at = 8, 16  # BitsPerSample's three SHORTs, padded to 8 bytes
    ifd_at = strip_at + len(strip) + len(strip) % 2  # a directory starts on an even offset
    entries = [  # tag, type (3 SHORT, 4 LONG), count, value or offset
        (256, 4, 1, width), (257, 4, 1, height), (258, 3, 3, bits_at), (259, 3, 1, compression),
        (262, 3, 1, 2), (273, 4, 1, strip_at), (277, 3, 1, 3), (278, 4, 1, height), (279, 4, 1, len(strip)),
        (284, 3, 1, 1),
    ]
    directory = struct.pack("<H", len(entries)) + b"".join(
        struct.pack("<HHIHH" if kind == 3 and count == 1 else "<HHII", tag, kind, count, value,
                    *((0,) if kind == 3 and count == 1 else ())) for tag, kind, count, value in entries)
    return (b"II*\0" + struct.pack("<I", ifd_at) + struct.pack("<HHHH", 8, 8, 8, 0) + strip
            + b"\0" * (len(strip) % 2) + directory + struct.pack("<I", 0))


#: The optional codecs a build may include, each with the builder of a tiny TIFF compressed by it whose decode
#: tells (:func:`decoded`). WebP: OpenCV 5.1's wheels are reported to include it, 5.0.0's leave it out.
PROBED: dict[int, Callable[[], bytes]] = {_WEBP: webp_sample}


def decodes_sample(sample: bytes) -> bool:
    """Whether the installed OpenCV decodes ``sample`` (a probe's TIFF) to its image: None (codec left out) and an
    image of zeros (no codec known) are no. libtiff's error for a codec left out is silenced: the probe expects
    it."""
    if not sample:
        return False
    with opencv_log_silenced():
        try:
            image = cv2.imdecode(np.frombuffer(sample, np.uint8), cv2.IMREAD_COLOR)
        except cv2.error:
            image = None
    return image is not None and np.array_equal(image, _probe_image())


@contextlib.contextmanager
def opencv_log_silenced() -> Iterator[None]:
    """OpenCV's log (libtiff's warnings and errors, which it only logs) off inside the block, its level restored
    after: for a decode whose failure is expected and told otherwise."""
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        cv2.utils.logging.setLogLevel(level)


@functools.cache
def decoded() -> frozenset[int]:
    """The Compression values the installed OpenCV decodes: :data:`BUILT_IN`, and each of :data:`PROBED` whose
    sample it decodes. Probed once per process (a few tiny decodes; the build does not change while it runs).

    The cache is a memo of a fact about the process (which OpenCV it imported), not state that changes: like
    ``cv2.__version__`` it holds for the process's life, so it is kept here rather than on an object every reader of
    an image (``image_files``, replay, ``ghcal``, the data loaders: free functions) would have to be handed. A test
    that changes :data:`PROBED` or fakes the decode clears it (``decoded.cache_clear()``)."""
    return BUILT_IN | {compression for compression, sample in PROBED.items() if decodes_sample(sample())}


def refusal(compression: int) -> str | None:
    """Why a TIFF of ``compression`` does not decode, e.g. "a TIFF of Compression 34712 (JPEG 2000), which OpenCV
    5.0.0's libtiff does not decode: rewrite it uncompressed or with LZW, deflate or PackBits"; ``None`` for a
    compression it decodes (:func:`decoded`). For an optional codec (:data:`PROBED`) it says this build was
    probed and lacks it: another OpenCV build may decode the file as it is."""
    if compression in BUILT_IN or compression in decoded():
        return None
    lacking = (" (its libtiff was built without that codec, as a decode of a sample showed; an OpenCV build that "
               "includes it decodes the file as it is)" if compression in PROBED else "")
    return (f"a TIFF of Compression {compression} ({name(compression)}), which OpenCV {cv2.__version__}'s libtiff "
            f"does not decode{lacking}: rewrite it uncompressed or with LZW, deflate or PackBits")
