"""An AVIF's rotate and mirror properties (``irot``, ``imir``), found and made harmless without decoding the image.

An AVIF (an ISOBMFF file: HEIF's boxes) may carry a display transform beside its pixels, as a JPEG's EXIF
orientation or a TIFF's Orientation tag does: ``irot`` turns the image by quarter turns anticlockwise, ``imir``
mirrors it, each a property box in ``meta`` > ``iprp`` > ``ipco`` that the image item is associated with. A rig's
calibration is of the sensor's pixel grid (``ghnerf_runtime.image_files`` says why), so a frame is read as stored.
OpenCV 5.0's AVIF decoder (libavif 1.4) applies neither box, but nothing promises its next version will not: as
for a TIFF's tag, the bytes handed to it say "no turn" (:func:`transforms_reset`) rather than relying on that.

A clean aperture (``clap``, a crop) is not looked at, on purpose: OpenCV 5.0 ignores it too (libavif leaves it to
the application) and decodes the whole stored image, the sensor's pixel grid (checked with crops centred and off
centre in session 64; tests/drivers/test_replay_image_sizes.py). A decoder applying it could not misread a replayed
frame without a word: replay measures an AVIF by decoding it (no size is read from its boxes), so a crop of another
size than the rig's would be refused at open, and the cut-short check (:func:`item_data_end`) reads no size.

Only box headers and the transform boxes' one byte are read; a file whose boxes this walk cannot follow (cut short,
malformed) is left as it is, for the decoder to decode or refuse.

:func:`item_data_end` reads the item locations (``iloc``) too: how far into the file its ``meta`` box and its items'
data reach, so that a replayed take cut short can tell an AVIF cut before its end without decoding it.
"""
from __future__ import annotations

import struct
from typing import BinaryIO, Iterator

__all__ = ["is_isobmff", "item_data_end", "transforms_reset"]

#: Where an ISOBMFF file's first box's type is (its ``ftyp``): bytes 4 to 8, after the box's size.
_FTYP_AT, FTYP = 4, b"ftyp"
#: The boxes holding the item properties, from the file's top level down, and how many bytes each has before its
#: children: ``meta`` is a full box (a version and flags), ``iprp`` and ``ipco`` are plain containers.
_PROPERTY_PATH = ((b"meta", 4), (b"iprp", 0), (b"ipco", 0))
#: The rotate and mirror boxes: an 8-byte header and one byte (``irot``: the angle in its low two bits; ``imir``:
#: the axis). A mirror has no "none" value, so an ``imir`` is rewritten as an ``irot`` of angle 0 (libavif decodes
#: an item with two such).
_ROTATE, _MIRROR = b"irot", b"imir"
_TRANSFORM_BODY_SIZE = 1
_NO_TURN = _ROTATE + b"\x00"  # the box's type and its one byte: written over an irot's or imir's
#: The item locations box (in ``meta``): where each item's data is (its extents).
_ITEM_LOCATIONS = b"iloc"
#: An item's data read from the file itself (construction method 0: file offsets), or from ``meta``'s ``idat``
#: (1); libavif decodes no item of another method (2: in another item) nor in another file (a data reference).
_FILE_OFFSETS, _IN_IDAT = 0, 1
#: The most boxes walked at one level: each is at least a header long, but a hostile file could hold millions.
_MOST_BOXES = 4096
_HEADER, _LARGE_HEADER = 8, 16


def is_isobmff(head: bytes) -> bool:
    """Whether a file starting with ``head`` (its first 8 bytes or more) is an ISOBMFF file (AVIF, HEIF, MP4)."""
    return head[_FTYP_AT:_FTYP_AT + len(FTYP)] == FTYP


def transforms_reset(f: BinaryIO) -> list[tuple[int, bytes]]:
    """Where to write what (offset, bytes) in an ISOBMFF file (``f`` at its start) so that none of its item
    properties turns or mirrors its image: each ``irot`` of a non-zero angle, and each ``imir``, made an ``irot``
    of angle 0, in place (the same 9 bytes). Empty where there is none, or the boxes cannot be followed."""
    size = f.seek(0, 2)
    start, stop = 0, size
    for kind, before_children in _PROPERTY_PATH:
        found = next(((body, end) for box_kind, body, end in _boxes(f, start, stop) if box_kind == kind), None)
        if found is None:
            return []
        start, stop = found[0] + before_children, found[1]
    resets = []
    for kind, body, end in _boxes(f, start, stop):
        if kind in (_ROTATE, _MIRROR) and end - body == _TRANSFORM_BODY_SIZE and _turns(f, kind, body):
            resets.append((body - len(_ROTATE), _NO_TURN))  # over the type and the one byte
    return resets


def _turns(f: BinaryIO, kind: bytes, body: int) -> bool:
    """Whether a 9-byte ``irot`` or ``imir`` at ``body`` (its one byte) turns or mirrors the image."""
    if kind == _MIRROR:
        return True
    f.seek(body)
    return bool(f.read(1)[0] & 3)


def _boxes(f: BinaryIO, start: int, stop: int) -> Iterator[tuple[bytes, int, int]]:
    """Each box from ``start`` to ``stop``: its type, where its body starts and where it ends. Stops at a box
    running past ``stop`` or shorter than its header (cut short or malformed), and after :data:`_MOST_BOXES`."""
    at = start
    for _ in range(_MOST_BOXES):
        if at + _HEADER > stop:
            return
        f.seek(at)
        head = f.read(_HEADER)
        size, kind = struct.unpack(">I4s", head)
        body = at + _HEADER
        if size == 1:  # a 64-bit size follows the type
            large = f.read(_LARGE_HEADER - _HEADER)
            if len(large) < _LARGE_HEADER - _HEADER:
                return
            size, body = struct.unpack(">Q", large)[0], at + _LARGE_HEADER
        elif size == 0:  # the box runs to the end of its container
            size = stop - at
        if size < body - at or at + size > stop:
            return
        yield kind, body, at + size
        at += size


def item_data_end(f: BinaryIO) -> int | None:
    """How far into an ISOBMFF file (AVIF) the boxes and data its decoder reads reach, read from box headers and
    the item locations (``iloc``) only: the end of its ``meta`` box (found among its top-level boxes, each before
    it whole), and of each item's data extents. A file shorter than that was cut short: a writer may put the image
    data (``mdat``) before ``meta`` or after it. ``None`` where no ``meta`` box with item locations is found
    whole, or they cannot be read (cut short, malformed, an item of data libavif does not read)."""
    size = f.seek(0, 2)
    meta = next(((body, end) for kind, body, end in _boxes(f, 0, size) if kind == b"meta"), None)
    if meta is None:
        return None
    iloc = next(((body, end) for kind, body, end in _boxes(f, meta[0] + 4, meta[1]) if kind == _ITEM_LOCATIONS),
                None)
    if iloc is None:
        return None
    f.seek(iloc[0])
    extents_end = _extents_end(f.read(iloc[1] - iloc[0]))
    return None if extents_end is None else max(meta[1], extents_end)


def _extents_end(iloc: bytes) -> int | None:
    """Where the last byte of the items' data in the file ends, from an ``iloc`` box's body (ISO/IEC 14496-12
    8.11.3: versions 0 to 2); an extent of length 0 (to the end of the file) counts to its offset. ``None`` where
    the box is cut short, of another version, or locates an item's data elsewhere than in this file."""
    fields = _Fields(iloc)
    version = fields.number(1)
    fields.number(3)  # flags
    sizes = fields.number(2)
    offset_size, length_size, base_size = sizes >> 12, (sizes >> 8) & 15, (sizes >> 4) & 15
    index_size = sizes & 15 if version in (1, 2) else 0
    if version not in (0, 1, 2) or not {offset_size, length_size, base_size, index_size} <= {0, 4, 8}:
        return None
    end = 0
    for _ in range(fields.number(4 if version == 2 else 2)):
        fields.number(4 if version == 2 else 2)  # item ID
        method = fields.number(2) & 15 if version in (1, 2) else _FILE_OFFSETS
        reference, base = fields.number(2), fields.number(base_size)
        if reference != 0 or method not in (_FILE_OFFSETS, _IN_IDAT):
            return None
        for _ in range(fields.number(2)):
            fields.number(index_size)
            offset, length = fields.number(offset_size), fields.number(length_size)
            if method == _FILE_OFFSETS:
                end = max(end, base + offset + length)
        if fields.cut_short:
            return None
    return None if fields.cut_short else end


class _Fields:
    """Big-endian unsigned numbers read in turn from a box's body; past its end each is 0 and ``cut_short`` set
    (each item's and extent's loop is bounded by the numbers read, so a short body ends them quickly)."""

    def __init__(self, data: bytes) -> None:
        self._data, self._at, self.cut_short = data, 0, False

    def number(self, size: int) -> int:
        if self._at + size > len(self._data):
            self.cut_short = True
            return 0
        value = int.from_bytes(self._data[self._at:self._at + size], "big")
        self._at += size
        return value
