"""Image files OpenCV treats oddly, built byte by byte (no files from elsewhere)."""
from __future__ import annotations

import io
import struct

import cv2
import numpy as np

from ghnerf_runtime import tiff_header

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


#: TIFF entry types by their struct codes (BYTE, ASCII, SHORT, LONG, RATIONAL, UNDEFINED, LONG8).
_TIFF_TYPE_CODES = {1: "B", 2: "B", 3: "H", 4: "I", 5: "II", 7: "B", 16: "Q"}
#: The tags whose values are offsets into the file (StripOffsets, TileOffsets), moved with the data.
_TIFF_OFFSET_TAGS = (273, 324)


def tiff_entries(data: bytes) -> dict[int, tuple[int, tuple]]:
    """A little-endian classic TIFF's (as OpenCV writes one) first directory: tag -> (type, values)."""
    assert data[:4] == b"II*\x00"
    (at,) = struct.unpack_from("<I", data, 4)
    (count,) = struct.unpack_from("<H", data, at)
    entries = {}
    for n in range(count):
        tag, kind, number, field = struct.unpack_from("<HHI4s", data, at + 2 + 12 * n)
        codes = "<" + _TIFF_TYPE_CODES[kind] * number
        size = struct.calcsize(codes)
        raw = field if size <= 4 else data[struct.unpack("<I", field)[0]:][:size]
        entries[tag] = (kind, struct.unpack_from(codes, raw))
    return entries


def tiff_laid_out(data: bytes, order: str = "<", big: bool = False, changed: dict | None = None) -> bytes:
    """An 8-bit TIFF OpenCV wrote (little-endian, classic) laid out again, built byte by byte: in byte order
    ``order`` (``"<"`` or ``">"``), as a BigTIFF where ``big``, with ``changed`` tags (tag -> (type, values);
    None drops one). The image data stays where it was, after a header of the new length; the directory and
    the values not fitting in it follow it."""
    entries = tiff_entries(data)
    for tag, entry in (changed or {}).items():
        entries.pop(tag) if entry is None else entries.__setitem__(tag, entry)
    (old_ifd,) = struct.unpack_from("<I", data, 4)
    header = (b"II" if order == "<" else b"MM") + (struct.pack(order + "HHHQ", 43, 8, 0, 16) if big
                                                    else struct.pack(order + "HI", 42, 8))
    shift = len(header) - 8
    body = bytearray(header + data[8:old_ifd])
    field_size, offset_code = (8, "Q") if big else (4, "I")
    directory = struct.pack(order + ("Q" if big else "H"), len(entries))
    for tag in sorted(entries):
        kind, values = entries[tag]
        if tag in _TIFF_OFFSET_TAGS:
            values = tuple(v + shift for v in values)
        raw = struct.pack(order + _TIFF_TYPE_CODES[kind] * (len(values) // len(_TIFF_TYPE_CODES[kind])), *values)
        if len(raw) > field_size:
            body += b"\x00" * (len(body) % 2)
            field, body = struct.pack(order + offset_code, len(body)), body + raw
        else:
            field = raw.ljust(field_size, b"\x00")
        directory += struct.pack(order + ("HHQ" if big else "HHI"), tag, kind,
                                 len(values) // len(_TIFF_TYPE_CODES[kind])) + field
    body += b"\x00" * (len(body) % 2)
    struct.pack_into(order + offset_code, body, len(header) - field_size, len(body))
    return bytes(body + directory + bytes(field_size))


def tiff_tiled(image: np.ndarray, tile: tuple[int, int], *, separate_planes: bool = False) -> bytes:
    """An 8-bit ``image`` (gray, or BGR stored as RGB) as an uncompressed tiled TIFF laid out as libtiff writes one:
    its header, its tiles (``tile``: width, height; those at the right and bottom edges padded; with
    ``separate_planes``, each sample's tiles in turn, one sample a tile), then its directory. libtiff's own writer
    (TIFFWriteTile) puts the same tiles in the same place (its directory giving the width, height and tile byte
    counts as SHORT, not LONG)."""
    height, width = image.shape[:2]
    samples = 1 if image.ndim == 2 else image.shape[2]
    stored = image.reshape(height, width, samples)[..., ::-1] if samples == 3 else image.reshape(height, width, samples)
    planes = [stored[..., [n]] for n in range(samples)] if separate_planes else [stored]
    tiles = []
    for plane in planes:
        for y in range(0, height, tile[1]):
            for x in range(0, width, tile[0]):
                padded = np.zeros((tile[1], tile[0], plane.shape[2]), np.uint8)
                part = plane[y:y + tile[1], x:x + tile[0]]
                padded[:part.shape[0], :part.shape[1]] = part
                tiles.append(padded.tobytes())
    offsets = tuple(8 + sum(len(t) for t in tiles[:n]) for n in range(len(tiles)))
    bare = b"II*\x00" + struct.pack("<I", offsets[-1] + len(tiles[-1])) + b"".join(tiles) + bytes(2 + 4)
    return tiff_laid_out(bare, changed={
        256: (4, (width,)), 257: (4, (height,)), 258: (3, (8,) * samples), 259: (3, (1,)),
        262: (3, (2 if samples >= 3 else 1,)), 277: (3, (samples,)), 284: (3, (2 if separate_planes else 1,)),
        322: (3, (tile[0],)), 323: (3, (tile[1],)), 324: (4, offsets), 325: (4, tuple(len(t) for t in tiles))})


def riff_chunk(kind: bytes, body: bytes) -> bytes:
    """One RIFF chunk: its kind, length and data, padded to an even length."""
    return kind + struct.pack("<I", len(body)) + body + b"\x00" * (len(body) % 2)


def webp_extended(simple: bytes, *, flags: int = 0, canvas: tuple[int, int] | None = None,
                  after: bytes = b"") -> bytes:
    """A simple WebP (one VP8 or VP8L chunk, as OpenCV writes it) as an extended one: a VP8X chunk with ``flags``
    and the canvas size ``canvas`` (the image's where None: read back with OpenCV), its bitstream chunk, then
    ``after`` (chunks: EXIF, XMP)."""
    if canvas is None:
        decoded = cv2.imdecode(np.frombuffer(simple, np.uint8), cv2.IMREAD_UNCHANGED)
        canvas = (decoded.shape[1], decoded.shape[0])
    vp8x = riff_chunk(b"VP8X", bytes([flags, 0, 0, 0]) + (canvas[0] - 1).to_bytes(3, "little")
                      + (canvas[1] - 1).to_bytes(3, "little"))
    body = b"WEBP" + vp8x + simple[12:] + after
    return b"RIFF" + struct.pack("<I", len(body)) + body


def isobmff_boxes(data: bytes, start: int, stop: int) -> dict[bytes, tuple[int, int]]:
    """The boxes from ``start`` to ``stop`` of an ISOBMFF file as OpenCV writes an AVIF (32-bit sizes, each type
    once): type -> (where the box starts, its size)."""
    boxes, at = {}, start
    while at < stop:
        size, kind = struct.unpack_from(">I4s", data, at)
        boxes[kind] = (at, size)
        at += size
    return boxes


def avif_transform(kind: bytes, value: int) -> bytes:
    """An ``irot`` (``value``: quarter turns anticlockwise) or ``imir`` (``value``: the axis) property box."""
    return struct.pack(">I4sB", 9, kind, value)


def avif_with_properties(data: bytes, properties: list[bytes]) -> bytes:
    """An AVIF OpenCV wrote (one item, meta before mdat) with ``properties`` (boxes) added to its ``ipco`` and
    associated, as essential, with its item in ``ipma``; its sizes and ``iloc``'s data offsets moved to match.
    Built byte by byte: OpenCV writes no rotate or mirror property."""
    out = bytearray(data)
    meta = isobmff_boxes(out, 0, len(out))[b"meta"]
    inside_meta = isobmff_boxes(out, meta[0] + 12, meta[0] + meta[1])  # meta is a full box: 4 more bytes
    iprp = inside_meta[b"iprp"]
    ipco, ipma = (isobmff_boxes(out, iprp[0] + 8, iprp[0] + iprp[1])[kind] for kind in (b"ipco", b"ipma"))
    known = len(isobmff_boxes(out, ipco[0] + 8, ipco[0] + ipco[1]))
    version, flags, entries = out[ipma[0] + 8], out[ipma[0] + 11], struct.unpack_from(">I", out, ipma[0] + 12)[0]
    assert (version, flags & 1, entries) == (0, 0, 1)  # 16-bit item ids, one-byte associations, one item
    count_at = ipma[0] + 16 + 2  # past the item id
    associations = bytes(0x80 | (known + n + 1) for n in range(len(properties)))  # essential, 1-based index
    grow = len(associations) + sum(len(box) for box in properties)
    out[count_at + 1 + out[count_at]:count_at + 1 + out[count_at]] = associations
    out[count_at] += len(properties)
    struct.pack_into(">I", out, ipma[0], ipma[1] + len(associations))
    out[ipco[0] + ipco[1]:ipco[0] + ipco[1]] = b"".join(properties)  # before ipma: insert it after ipma's edits
    for box, more in ((ipco, grow - len(associations)), (iprp, grow), (meta, grow)):
        struct.pack_into(">I", out, box[0], box[1] + more)
    _move_item_data(out, inside_meta[b"iloc"][0], grow)
    return bytes(out)


def _move_item_data(out: bytearray, iloc_at: int, shift: int) -> None:
    """Add ``shift`` to each extent offset of an ``iloc`` box (version 0 or 1, no base offsets)."""
    version = out[iloc_at + 8]
    offset_size, length_size = out[iloc_at + 12] >> 4, out[iloc_at + 12] & 15
    base_size, index_size = out[iloc_at + 13] >> 4, (out[iloc_at + 13] & 15) if version == 1 else 0
    assert version in (0, 1) and base_size == 0 and offset_size in (4, 8)
    (items,), at = struct.unpack_from(">H", out, iloc_at + 14), iloc_at + 16
    code = ">I" if offset_size == 4 else ">Q"
    for _ in range(items):
        at += 2 + (2 if version == 1 else 0) + 2  # item id, construction method, data reference index
        (extents,), at = struct.unpack_from(">H", out, at), at + 2
        for _ in range(extents):
            at += index_size
            struct.pack_into(code, out, at, struct.unpack_from(code, out, at)[0] + shift)
            at += offset_size + length_size


#: A 64x64 image: OpenCV writes it in two strips (42 rows, then 22), whatever the compression.
STRIPS_IMAGE = np.random.default_rng(66).integers(1, 256, (64, 64, 3), np.uint8)


def tiff_with_strip_count(compression: int, strip: int, count_of) -> bytes:
    """:data:`STRIPS_IMAGE` as OpenCV writes a TIFF of ``compression``, strip ``strip`` (from 0)'s byte count set to
    ``count_of(count, file size, offset)``, in place (SHORT or LONG, in the entry or where it points)."""
    data = bytearray(cv2.imencode(".tiff", STRIPS_IMAGE, [cv2.IMWRITE_TIFF_COMPRESSION, compression])[1].tobytes())
    tags = tiff_header.read_tags(io.BytesIO(bytes(data)), tiff_header.IMAGE_DATA_TAGS,
                                 unlimited=tiff_header.IMAGE_DATA_TAGS)
    offsets, counts = tags.get(273), tags.get(279)
    code = "<H" if counts.kind == 3 else "<I"
    size = struct.calcsize(code)
    at = counts.field_at if size * len(counts.values) <= 4 else struct.unpack_from("<I", data, counts.field_at)[0]
    struct.pack_into(code, data, at + size * strip, count_of(counts.values[strip], len(data), offsets.values[strip]))
    return bytes(data)
