"""An AVIF's rotate and mirror properties (``irot``, ``imir``), found and made harmless without decoding the image.

An AVIF (an ISOBMFF file: HEIF's boxes) may carry a display transform beside its pixels, as a JPEG's EXIF
orientation or a TIFF's Orientation tag does: ``irot`` turns the image by quarter turns anticlockwise, ``imir``
mirrors it, each a property box in ``meta`` > ``iprp`` > ``ipco`` that the image item is associated with. A rig's
calibration is of the sensor's pixel grid (``ghnerf_runtime.image_files`` says why), so a frame is read as stored.
OpenCV 5.0's AVIF decoder (libavif 1.4) applies neither box, but nothing promises its next version will not: as
for a TIFF's tag, the bytes handed to it say "no turn" (:func:`transforms_reset`) rather than relying on that.

Only box headers and the transform boxes' one byte are read; a file whose boxes this walk cannot follow (cut short,
malformed) is left as it is, for the decoder to decode or refuse.
"""
from __future__ import annotations

import struct
from typing import BinaryIO, Iterator

__all__ = ["is_isobmff", "transforms_reset"]

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
