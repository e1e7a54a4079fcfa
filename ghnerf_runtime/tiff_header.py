"""A TIFF's first image file directory, read without decoding the image (the page OpenCV decodes).

One walk of the header for its two readers: ``ghnerf_runtime.image_files`` (which sets the Orientation tag to 1
before OpenCV decodes a file, as OpenCV's TIFF decoder turns the image by it whatever the read flags) and
``drivers.backends.recording_format.header_size`` (a replayed take's image sizes, read at open). Classic TIFF and
BigTIFF, either byte order. Offsets and counts are read within the file's length: a corrupt header's may be beyond
any file (a BigTIFF's are 64-bit), and nothing here raises for them.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import BinaryIO

__all__ = [
    "BITS_PER_SAMPLE", "COMPRESSION", "HEIGHT", "LAYOUTS", "ORIENTATION", "UPRIGHT", "TiffEntry", "TiffLayout", "WIDTH",
    "first_directory", "orientation_reset",
]

#: The tags read here: ImageWidth, ImageLength, BitsPerSample, Compression, Orientation.
WIDTH, HEIGHT, BITS_PER_SAMPLE, COMPRESSION, ORIENTATION = 256, 257, 258, 259, 274
#: The Orientation that means the pixels are shown as stored (row 0 at the top, column 0 at the left).
UPRIGHT = 1
#: The most values read of one tag (BitsPerSample has one a sample: RGB with alpha and a few extra channels).
MOST_VALUES = 16
_SHORT, _LONG, _LONG8 = 3, 4, 16
_CLASSIC_INTEGERS = {_SHORT: "H", _LONG: "I"}
_BIG_INTEGERS = {**_CLASSIC_INTEGERS, _LONG8: "Q"}


@dataclass(frozen=True)
class TiffLayout:
    """Where a TIFF's first image file directory is and how its entries are laid out: classic TIFF (4-byte
    offsets, 12-byte entries) or BigTIFF (8-byte offsets, 20-byte entries), in either byte order."""

    order: str  # struct's byte order
    preamble: bytes  # what follows the byte order and version before the first directory's offset
    offset: str  # the first directory's offset
    count: str  # a directory's entry count
    entry_size: int
    integer_types: dict[int, str]  # the unsigned integer entry types read (SHORT, LONG, LONG8): struct codes

    @property
    def first_ifd_at(self) -> int:
        return 4 + len(self.preamble) + struct.calcsize(self.offset)

    @property
    def entry_head(self) -> str:  # tag, type, number of values
        return "HH" + ("Q" if self.entry_size == 20 else "I")

    @property
    def entry_head_size(self) -> int:
        return struct.calcsize("<" + self.entry_head)


#: A TIFF's first four bytes (byte order, version: 42 classic, 43 BigTIFF) and its layout. A BigTIFF's offsets are
#: 8 bytes long (then a reserved 0) before its first directory's offset.
LAYOUTS = {
    b"II*\x00": TiffLayout("<", b"", "I", "H", 12, _CLASSIC_INTEGERS),
    b"MM\x00*": TiffLayout(">", b"", "I", "H", 12, _CLASSIC_INTEGERS),
    b"II+\x00": TiffLayout("<", struct.pack("<HH", 8, 0), "Q", "Q", 20, _BIG_INTEGERS),
    b"MM\x00+": TiffLayout(">", struct.pack(">HH", 8, 0), "Q", "Q", 20, _BIG_INTEGERS),
}


@dataclass(frozen=True)
class TiffEntry:
    """One tag of a directory: its type, its values, and where its value field is in the file (holding the values
    themselves where they fit, else their offset)."""

    kind: int
    values: tuple[int, ...]
    field_at: int


def first_directory(f: BinaryIO, layout: TiffLayout, tags: frozenset[int]) -> dict[int, TiffEntry] | None:
    """The entries of ``tags`` in the first image file directory (``f`` just past the byte order and version);
    ``None`` where the directory or a value is cut short, or one of those tags is repeated or not of unsigned
    integers (SHORT or LONG; in a BigTIFF, LONG8 too)."""
    head = f.read(layout.first_ifd_at - 4)
    if len(head) < layout.first_ifd_at - 4 or head[:len(layout.preamble)] != layout.preamble:
        return None
    (ifd_at,) = struct.unpack(layout.order + layout.offset, head[len(layout.preamble):])
    raw = _read_at(f, ifd_at, struct.calcsize(layout.count))
    if len(raw) < struct.calcsize(layout.count):
        return None
    (count,) = struct.unpack(layout.order + layout.count, raw)
    entries_at = ifd_at + len(raw)
    entries = _read_at(f, entries_at, count * layout.entry_size)
    if len(entries) < count * layout.entry_size:
        return None  # a directory past the end of a file cut short
    found: dict[int, TiffEntry] = {}
    for at in range(0, len(entries), layout.entry_size):
        tag, kind, number = struct.unpack(layout.order + layout.entry_head, entries[at:at + layout.entry_head_size])
        if tag not in tags:
            continue
        field_at = at + layout.entry_head_size
        values = _integers(f, layout, kind, number, entries[field_at:at + layout.entry_size])
        if values is None or tag in found:
            return None
        found[tag] = TiffEntry(kind, values, entries_at + field_at)
    return found


def orientation_reset(f: BinaryIO) -> tuple[int, bytes] | None:
    """Where to write what (offset, bytes) in a TIFF (``f`` at its start) so that its first directory's Orientation
    is :data:`UPRIGHT`: its one value, of its own type and byte order, in place. ``None`` where there is nothing
    to reset: not a TIFF, no Orientation or one already upright, or a directory this walk cannot read. An
    Orientation of several values is left as it is too: libtiff ignores it (it warns of the count)."""
    layout = LAYOUTS.get(f.read(4))
    if layout is None:
        return None
    entry = (first_directory(f, layout, frozenset({ORIENTATION})) or {}).get(ORIENTATION)
    if entry is None or len(entry.values) != 1 or entry.values[0] == UPRIGHT:
        return None
    return entry.field_at, struct.pack(layout.order + layout.integer_types[entry.kind], UPRIGHT)


def _integers(f: BinaryIO, layout: TiffLayout, kind: int, number: int, field: bytes) -> tuple[int, ...] | None:
    """An entry's unsigned integers: in the entry's value field where they fit (left-justified), else at the
    offset it holds; ``None`` for another type, more than :data:`MOST_VALUES`, or values cut short."""
    code = layout.integer_types.get(kind)
    if code is None or not 1 <= number <= MOST_VALUES:
        return None
    codes = layout.order + code * number
    if struct.calcsize(codes) > len(field):
        field = _read_at(f, struct.unpack(layout.order + layout.offset, field)[0], struct.calcsize(codes))
        if len(field) < struct.calcsize(codes):
            return None
    return struct.unpack_from(codes, field)


def _read_at(f: BinaryIO, offset: int, length: int) -> bytes:
    """``length`` bytes at ``offset``; fewer, or none, where the file ends first. A corrupt header's offsets and
    counts can be beyond any file (a BigTIFF's are 64-bit: too large to seek to, or to read as one buffer)."""
    end = f.seek(0, 2)
    if offset > end:
        return b""
    f.seek(offset)
    return f.read(min(length, end - offset))
