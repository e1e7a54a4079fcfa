"""A TIFF's first image file directory, read without decoding the image (the page OpenCV decodes).

One walk of the header for its readers: ``ghnerf_runtime.image_files`` (which sets the Orientation tag to 1
before OpenCV decodes a file, as OpenCV's TIFF decoder turns the image by it whatever the read flags),
``drivers.backends.recording_format.header_size`` (a replayed take's image sizes, read at open) and its
``payload_is_whole`` (whether a take cut short holds a TIFF whole: :func:`first_directory_end`). Classic TIFF and
BigTIFF, either byte order. Offsets and counts are read within the file's length: a corrupt header's may be beyond
any file (a BigTIFF's are 64-bit), and nothing here raises for them.

Later pages (directories) are not read, on purpose: OpenCV 5.0 decodes a multi-page TIFF's first page only
(cv2.imread and cv2.imdecode alike), whatever the later ones hold, and decodes it still where a later page is cut
short or corrupt (checked with cv2.imwritemulti's files in session 64: a second page of another size, a file cut in
its last directory; tests/drivers/test_replay_image_sizes.py). So the size read here, the turn reset and the
cut-short check are of the page decoded, and a later page cannot make an image read wrong.
"""
from __future__ import annotations

import operator
import struct
from dataclasses import dataclass
from typing import BinaryIO

__all__ = [
    "BITS_PER_SAMPLE", "COMPRESSION", "HEIGHT", "LAYOUTS", "ORIENTATION", "UPRIGHT", "DirectoryTags", "ImageData",
    "IMAGE_DATA_TAGS", "TiffEntry", "TiffLayout", "WIDTH", "first_directory", "first_directory_end", "image_data_in",
    "orientation_reset", "read_tags", "upright_reset",
]

#: The tags read here: ImageWidth, ImageLength, BitsPerSample, Compression, Orientation.
WIDTH, HEIGHT, BITS_PER_SAMPLE, COMPRESSION, ORIENTATION = 256, 257, 258, 259, 274
#: The Orientation that means the pixels are shown as stored (row 0 at the top, column 0 at the left).
UPRIGHT = 1
#: The most values read of one tag (BitsPerSample has one a sample: RGB with alpha and a few extra channels).
MOST_VALUES = 16
_SHORT, _LONG, _LONG8 = 3, 4, 16
#: Where the first directory's image data is: its strips' offsets and byte counts, or its tiles'.
_IMAGE_DATA_TAGS = ((273, 279), (324, 325))  # (StripOffsets, StripByteCounts), (TileOffsets, TileByteCounts)
_IMAGE_DATA_TAG_SET = frozenset(tag for pair in _IMAGE_DATA_TAGS for tag in pair)
#: The size of one value of each entry type (TIFF 6.0's twelve, BigTIFF's LONG8, SLONG8 and IFD8): an entry of
#: another type is skipped by libtiff, so where its values would be does not matter.
_TYPE_SIZES = {1: 1, 2: 1, 3: 2, 4: 4, 5: 8, 6: 1, 7: 1, 8: 2, 9: 4, 10: 8, 11: 4, 12: 8, 13: 4, 16: 8, 17: 8, 18: 8}
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


@dataclass(frozen=True)
class DirectoryTags:
    """Tags of a TIFF's first directory read in one walk (:func:`read_tags`), for a reader that asks several
    questions of one header (a decode's refusals and its turn reset): each tag as :func:`first_directory` would
    read it alone, so that one tag the walk cannot read leaves the others' answers as they were."""

    layout: TiffLayout
    entries: dict[int, TiffEntry]  # the tags read; one repeated, not of unsigned integers or cut short is left out

    def get(self, tag: int) -> TiffEntry | None:
        return self.entries.get(tag)


def first_directory(f: BinaryIO, layout: TiffLayout, tags: frozenset[int]) -> dict[int, TiffEntry] | None:
    """The entries of ``tags`` in the first image file directory (``f`` just past the byte order and version);
    ``None`` where the directory or a value is cut short, or one of those tags is repeated or not of unsigned
    integers (SHORT or LONG; in a BigTIFF, LONG8 too)."""
    walked = _walk_tags(f, layout, tags)
    if walked is None:
        return None
    found, unread = walked
    return None if unread else found


def read_tags(f: BinaryIO, tags: frozenset[int], unlimited: frozenset[int] = frozenset()) -> DirectoryTags | None:
    """The entries of ``tags`` in the first directory of ``f`` (at its start), each read as :func:`first_directory`
    reads it alone (none where the directory cannot be read), those ``unlimited`` of any number of values (a
    strip's offsets, one a strip: read within the file's length); None where ``f`` is no TIFF."""
    layout = LAYOUTS.get(f.read(4))
    if layout is None:
        return None
    walked = _walk_tags(f, layout, tags, unlimited)
    found, unread = walked if walked is not None else ({}, set())
    return DirectoryTags(layout, {tag: entry for tag, entry in found.items() if tag not in unread})


@dataclass(frozen=True)
class ImageData:
    """Where a TIFF's first directory's image data is: each strip's or tile's offset and byte count."""

    tiled: bool
    offsets: tuple[int, ...]
    counts: tuple[int, ...]

    @property
    def kind(self) -> str:
        return "tile" if self.tiled else "strip"


#: The tags giving where the image data is (StripOffsets, StripByteCounts, TileOffsets, TileByteCounts): read
#: with :func:`read_tags` among its ``unlimited`` (one value a strip or tile), for :func:`image_data_in`.
IMAGE_DATA_TAGS = _IMAGE_DATA_TAG_SET


def image_data_in(tags: DirectoryTags) -> ImageData | None:
    """The strips or tiles of a first directory whose :data:`IMAGE_DATA_TAGS` were read (``unlimited``); None
    where they were not read or do not pair up (libtiff refuses such a directory)."""
    for tiled, (offsets_tag, counts_tag) in zip((False, True), _IMAGE_DATA_TAGS):
        offsets, counts = tags.get(offsets_tag), tags.get(counts_tag)
        if offsets is not None and counts is not None and len(offsets.values) == len(counts.values):
            return ImageData(tiled, offsets.values, counts.values)
    return None


def _walk_tags(f: BinaryIO, layout: TiffLayout, tags: frozenset[int],
               unlimited: frozenset[int] = frozenset()) -> tuple[dict[int, TiffEntry], set[int]] | None:
    """The entries of ``tags`` in the first directory (``f`` just past the byte order and version), and the tags
    that cannot be read (repeated, not of unsigned integers, values cut short, more than :data:`MOST_VALUES` but
    for those ``unlimited``); None where the directory cannot."""
    directory = _first_directory_entries(f, layout)
    if directory is None:
        return None
    entries_at, entries = directory
    found: dict[int, TiffEntry] = {}
    unread: set[int] = set()
    for at in range(0, len(entries), layout.entry_size):
        tag, kind, number = struct.unpack(layout.order + layout.entry_head, entries[at:at + layout.entry_head_size])
        if tag not in tags or tag in unread:
            continue
        field_at = at + layout.entry_head_size
        most = None if tag in unlimited else MOST_VALUES
        values = _integers(f, layout, kind, number, entries[field_at:at + layout.entry_size], most)
        if values is None or tag in found:
            unread.add(tag)
            continue
        found[tag] = TiffEntry(kind, values, entries_at + field_at)
    return found, unread


def first_directory_end(f: BinaryIO, layout: TiffLayout) -> int | None:
    """How far into the file the first image file directory reaches (``f`` just past the byte order and version):
    the end of the directory itself (its next directory's offset included), of the values its entries hold
    elsewhere, and of its image data (each strip's or tile's offset plus byte count). A file shorter than that was
    cut short: libtiff writes the image data first, then the directory and its values. ``None`` where the directory
    cannot be read (cut short itself, or malformed: no strips nor tiles, offsets and counts not paired, repeated)."""
    directory = _first_directory_entries(f, layout)
    if directory is None:
        return None
    entries_at, entries = directory
    end = entries_at + len(entries) + struct.calcsize(layout.offset)
    image_data: dict[int, tuple[int, ...]] = {}
    field_size = layout.entry_size - layout.entry_head_size
    offset_code = layout.order + layout.offset
    for tag, kind, number, field in struct.iter_unpack(f"{layout.order}{layout.entry_head}{field_size}s", entries):
        values_size = _TYPE_SIZES.get(kind, 0) * number
        if values_size > field_size:  # held elsewhere: the field is their offset
            end = max(end, struct.unpack(offset_code, field)[0] + values_size)
        if tag in _IMAGE_DATA_TAG_SET:
            values = _integers(f, layout, kind, number, field, most=None)
            if values is None or tag in image_data:
                return None
            image_data[tag] = values
    data_end = _image_data_end(image_data)
    return None if data_end is None else max(end, data_end)


def _image_data_end(image_data: dict[int, tuple[int, ...]]) -> int | None:
    """Where the last strip's or tile's bytes end; ``None`` without strips or tiles whose offsets and byte counts
    pair up (libtiff refuses such a directory)."""
    for offsets_tag, counts_tag in _IMAGE_DATA_TAGS:
        offsets, counts = image_data.get(offsets_tag), image_data.get(counts_tag)
        if offsets is not None and counts is not None and len(offsets) == len(counts):
            return max(map(operator.add, offsets, counts))
    return None


def _first_directory_entries(f: BinaryIO, layout: TiffLayout) -> tuple[int, bytes] | None:
    """Where the first directory's entries start, and their bytes (``f`` just past the byte order and version);
    ``None`` where the file ends before them."""
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
    return entries_at, entries


def orientation_reset(f: BinaryIO) -> tuple[int, bytes] | None:
    """Where to write what (offset, bytes) in a TIFF (``f`` at its start) so that its first directory's Orientation
    is :data:`UPRIGHT` (:func:`upright_reset`); ``None`` where there is nothing to reset, or ``f`` is no TIFF."""
    tags = read_tags(f, frozenset({ORIENTATION}))
    return None if tags is None else upright_reset(tags)


def upright_reset(tags: DirectoryTags) -> tuple[int, bytes] | None:
    """Where to write what (offset, bytes) so that the first directory whose ``tags`` were read (Orientation among
    them) gives the Orientation :data:`UPRIGHT`: its one value, of its own type and byte order, in place. ``None``
    where there is nothing to reset: no Orientation or one already upright, or a directory this walk cannot read.
    An Orientation of several values is left as it is too: libtiff ignores it (it warns of the count)."""
    entry = tags.get(ORIENTATION)
    if entry is None or len(entry.values) != 1 or entry.values[0] == UPRIGHT:
        return None
    return entry.field_at, struct.pack(tags.layout.order + tags.layout.integer_types[entry.kind], UPRIGHT)


def _integers(f: BinaryIO, layout: TiffLayout, kind: int, number: int, field: bytes,
              most: int | None = MOST_VALUES) -> tuple[int, ...] | None:
    """An entry's unsigned integers: in the entry's value field where they fit (left-justified), else at the
    offset it holds; ``None`` for another type, more than ``most`` (no limit where None: a strip's offsets, one a
    strip, are read within the file's length), or values cut short."""
    code = layout.integer_types.get(kind)
    if code is None or number < 1 or (most is not None and number > most):
        return None
    size = number * struct.calcsize(code)  # counted, not asked of struct: a corrupt count can be 2**64 - 1
    if size > len(field):
        field = _read_at(f, struct.unpack(layout.order + layout.offset, field)[0], size)
        if len(field) < size:
            return None
    return struct.unpack_from(f"{layout.order}{number}{code}", field)


def _read_at(f: BinaryIO, offset: int, length: int) -> bytes:
    """``length`` bytes at ``offset``; fewer, or none, where the file ends first. A corrupt header's offsets and
    counts can be beyond any file (a BigTIFF's are 64-bit: too large to seek to, or to read as one buffer)."""
    end = f.seek(0, 2)
    if offset > end:
        return b""
    f.seek(offset)
    return f.read(min(length, end - offset))
