"""Reading an image file a user gives (ghnerf-run's stills, ghcal's views, a ZJU-MoCap copy's frames and masks).

Its pixels as stored, never turned by an EXIF orientation tag (:data:`AS_STORED`): the tag is a display hint a phone
or camera sets per shot from its gravity sensor, while a rig's calibration (and a dataset's) is of the sensor's pixel
grid, the frames the live cameras deliver. Turned by it, as OpenCV does by default for every flag but
IMREAD_UNCHANGED, a phone held upright gave frames a quarter turn against the calibration, and a tag of 3 (half a
turn) kept the size and gave them upside down (wrong joints, no error).

A TIFF's own Orientation tag (274) turns it too: OpenCV's TIFF decoder (5.0, libtiff 4.7) applies it whatever the
read flags, IMREAD_IGNORE_ORIENTATION and IMREAD_UNCHANGED included, where a JPEG's, PNG's or WebP's EXIF
orientation is ignored. So a TIFF whose first directory's tag is not 1 is decoded from a copy of its bytes with the
tag set to 1 (``ghnerf_runtime.tiff_header.orientation_reset``): its stored pixels, whatever the decoder does with
a tag, rather than an undoing of the turn that OpenCV's next version may no longer make. An AVIF's rotate and
mirror properties (``irot``, ``imir``) are made "no turn" the same way (``ghnerf_runtime.avif_header``): OpenCV 5.0
applies neither, a later decoder might.

``cv2.imread`` answers None for a file it cannot read, but raises a ``cv2.error`` for one whose header gives a size
beyond its limits (CV_IO_MAX_IMAGE_WIDTH/HEIGHT/PIXELS: a corrupt or hostile BMP, for one): each caller's error
naming the file was skipped for a traceback naming none. replay:// reads its files' bytes itself
(``drivers.backends.recording_format.load_image``) and decodes them with :func:`decode_image_or_none`.

A TIFF whose compression OpenCV does not decode is None too, told from its header (``ghnerf_runtime.
tiff_compression``): for most such values (JPEG 2000's 34712, any unregistered one) OpenCV returned an image of
the stored size holding zeros, an all-black frame, having only logged libtiff's error;
:func:`tiff_compression_refusal` says why (:func:`unread_cause`, the one chain of causes for any read that failed).

A TIFF whose strips or tiles do not hold their data is None too, told from its header (:func:`tiff_data_refusal`):
one running past the file's end (cut short; OpenCV gave None already, the cause unnamed), or, uncompressed and of
several strips or tiles, one holding fewer bytes than its rows need (OpenCV delivered the rest black, libtiff only
warning). Garbage inside compressed data (LZW, deflate, PackBits) gives no such sign: OpenCV decodes it partly
black or scrambled, cv2.imread and cv2.imdecode alike, libtiff's errors only logged (measured in session 66), and
nothing short of decoding the data again could tell.

A JPEG is decoded from a copy of its bytes (``cv2.imdecode``), as replay decodes a take's: OpenCV's file reader
filled one cut short with grey (libjpeg's "Premature end of JPEG file" only logged), where imdecode refuses it;
:func:`jpeg_cut_short` names the cause (session 74).
"""
from __future__ import annotations

import enum
import io
import os
from dataclasses import dataclass
from typing import BinaryIO

import cv2
import numpy as np

from ghnerf_runtime import avif_header, tiff_compression, tiff_header
from ghnerf_runtime.path_check import is_utf8

__all__ = ["AS_STORED", "UnreadCause", "UnreadKind", "decode_image_or_none", "decoded_from_memory_because",
           "jpeg_cut_short", "read_image_or_none", "samples_not_8_bit", "tiff_compression_refusal", "tiff_data_refusal",
           "unread_because", "unread_cause"]

#: The decode flag that keeps an image's pixels as stored (IMREAD_UNCHANGED never turns them anyway), a JPEG's,
#: PNG's or WebP's EXIF orientation ignored; a TIFF's Orientation tag and an AVIF's irot and imir need more
#: (:func:`_with_resets`).
AS_STORED = cv2.IMREAD_IGNORE_ORIENTATION


def read_image_or_none(path: str | os.PathLike, flags: int) -> np.ndarray | None:
    """``cv2.imread(path, flags)`` as stored (:data:`AS_STORED` added; a TIFF's Orientation tag and an AVIF's
    rotate and mirror properties ignored too), or None where OpenCV cannot read the file, a size beyond its limits
    included. The file is opened once: its header read there serves the sample check, the turn resets and, where
    the bytes must be decoded from memory, the read of the rest."""
    try:
        with open(path, "rb") as f:
            resets = _resets_unless_refused(f, flags)
            if resets is None:
                return None
            if _memory_decode_because(path, resets) is not None or _is_jpeg(f):
                f.seek(0)
                return _decoded_with(np.fromfile(f, dtype=np.uint8), resets, flags)
    except (OSError, ValueError):  # ValueError: a NUL byte in the path
        return None
    try:  # cv2.imread's own file reader: a tiled TIFF it refuses from memory decodes here (recording_format)
        return cv2.imread(os.fspath(path), flags | AS_STORED)  # (IMREAD_UNCHANGED is -1: it stays itself)
    except cv2.error:
        return None


#: A JPEG's first bytes: its start-of-image marker and the next marker's 0xFF.
_JPEG_START = b"\xff\xd8\xff"
#: A JPEG's end-of-image marker, and the bytes a writer may pad a file with after it (zeros, 0xFF fill).
_JPEG_END, _JPEG_PADDING = b"\xff\xd9", b"\x00\xff"


def _is_jpeg(f: BinaryIO) -> bool:
    """Whether ``f`` holds a JPEG, which is decoded from memory: OpenCV's file reader fills a JPEG cut short with
    grey (and only logs libjpeg's "Premature end"), where ``cv2.imdecode`` refuses it, as replay's read does."""
    f.seek(0)
    return f.read(len(_JPEG_START)) == _JPEG_START


def jpeg_cut_short(path: str | os.PathLike) -> str | None:
    """Why a JPEG that did not decode is cut short: its bytes, but for trailing padding, do not end at its
    end-of-image marker (FFD9); None for another image, one that ends so, or a file that cannot be opened. Called
    once the decode failed, so a JPEG with bytes after its end (a trailer, which decodes) is never asked."""
    try:
        with open(path, "rb") as f:
            if not _is_jpeg(f):
                return None
            data = f.read()
    except (OSError, ValueError):  # ValueError: a NUL byte in the path
        return None
    if data.rstrip(_JPEG_PADDING).endswith(_JPEG_END):
        return None
    return f"it is a JPEG cut short ({len(_JPEG_START) + len(data)} bytes, not ending at its end-of-image marker FFD9)"


def _decodes_to_8_bits(flags: int) -> bool:
    """Whether a read with ``flags`` makes 8-bit samples (IMREAD_COLOR, IMREAD_GRAYSCALE), not the file's own."""
    return flags != cv2.IMREAD_UNCHANGED and not flags & cv2.IMREAD_ANYDEPTH


#: What a decode reads of a TIFF's first directory, in one walk (:func:`_resets_unless_refused`): its compression
#: and sample size (refusals) and its Orientation (the turn reset).
_DECODE_TAGS = frozenset({tiff_header.COMPRESSION, tiff_header.BITS_PER_SAMPLE, tiff_header.ORIENTATION})


def _resets_unless_refused(f: BinaryIO, flags: int) -> list[tuple[int, bytes]] | None:
    """The :func:`_turn_resets` of ``f`` (at its start), or None where it is a TIFF that OpenCV does not decode with
    ``flags`` (:func:`_tiff_refuses`). A TIFF's first directory is walked once for both."""
    head = f.read(4)
    f.seek(0)
    if head not in tiff_header.LAYOUTS:
        return _turn_resets(f)
    tags = tiff_header.read_tags(f, _DECODE_TAGS | _DATA_TAGS, unlimited=tiff_header.IMAGE_DATA_TAGS)
    if _tiff_refuses(tags, flags) or _data_refusal(f, tags) is not None:
        return None
    reset = tiff_header.upright_reset(tags)
    return [] if reset is None else [reset]


def _tiff_refuses(tags: tiff_header.DirectoryTags, flags: int) -> bool:
    """Whether a TIFF whose first directory's ``tags`` were read is one that OpenCV does not decode with ``flags``:
    its compression (:func:`_compression_refusal`; for most such, OpenCV delivered zeros), or samples of more than
    16 bits read as 8 (OpenCV fails on those too, printing libtiff's "Sorry, can not handle images with 32-bit
    samples"). False for a header that cannot be read."""
    if _compression_refusal(tags) is not None:
        return True
    return _decodes_to_8_bits(flags) and _samples_wider_than(tags, 16)


def _compression_refusal(tags: tiff_header.DirectoryTags | None) -> str | None:
    """Why a TIFF whose first directory's ``tags`` were read does not decode in OpenCV: its one Compression value,
    where ``ghnerf_runtime.tiff_compression`` says it is not decoded; None for another format (no ``tags``), another
    compression, none given (uncompressed), or one of several values or a header that cannot be read (libtiff
    refuses the file: OpenCV returns None)."""
    compression = None if tags is None else tags.get(tiff_header.COMPRESSION)
    if compression is None or len(compression.values) != 1:
        return None
    return tiff_compression.refusal(compression.values[0])


def tiff_compression_refusal(path: str | os.PathLike) -> str | None:
    """Why :func:`read_image_or_none` and :func:`decode_image_or_none` give None for ``path``, where it is a TIFF
    of a compression OpenCV does not decode: e.g. "a TIFF of Compression 34712 (JPEG 2000), which OpenCV 5.0.0's
    libtiff does not decode: ..."; None for another image, or a file that cannot be opened."""
    try:
        with open(path, "rb") as f:
            return _compression_refusal(tiff_header.read_tags(f, frozenset({tiff_header.COMPRESSION})))
    except (OSError, ValueError):  # ValueError: a NUL byte in the path
        return None


#: The tags telling how many bytes an uncompressed strip or tile holds: SamplesPerPixel, RowsPerStrip,
#: PlanarConfiguration, TileWidth, TileLength (with the size, BitsPerSample and Compression).
_SAMPLES, _ROWS_PER_STRIP, _PLANAR, _TILE_WIDTH, _TILE_LENGTH = 277, 278, 284, 322, 323
_DATA_TAGS = frozenset({tiff_header.WIDTH, tiff_header.HEIGHT, tiff_header.BITS_PER_SAMPLE, tiff_header.COMPRESSION,
                        _SAMPLES, _ROWS_PER_STRIP, _PLANAR, _TILE_WIDTH, _TILE_LENGTH}) | tiff_header.IMAGE_DATA_TAGS
_UNCOMPRESSED, _SEPARATE_PLANES = 1, 2


def tiff_data_refusal(path: str | os.PathLike) -> str | None:
    """Why a TIFF's strips or tiles do not hold its image (:func:`_data_refusal`), e.g. "its strip 3 runs past
    the file's end (to byte 12554 of 12454): cut short"; None for another image, a TIFF whose data is there, or a
    file that cannot be opened."""
    try:
        with open(path, "rb") as f:
            return _data_refusal(f, tiff_header.read_tags(f, _DATA_TAGS, unlimited=tiff_header.IMAGE_DATA_TAGS))
    except (OSError, ValueError):  # ValueError: a NUL byte in the path
        return None


def _data_refusal(f: BinaryIO, tags: tiff_header.DirectoryTags | None) -> str | None:
    """Why the first directory (its ``tags`` read, :data:`_DATA_TAGS`) of the TIFF ``f`` does not hold its image:
    a strip or tile running past the file's end, or one uncompressed holding fewer bytes than it needs
    (:func:`_bytes_needed`); None where it does, or for a directory whose strips cannot be read (libtiff refuses
    those itself)."""
    data = None if tags is None else tiff_header.image_data_in(tags)
    if data is None:
        return None
    size = f.seek(0, 2)
    for number, (offset, count) in enumerate(zip(data.offsets, data.counts), start=1):
        if offset + count > size:
            return f"its {data.kind} {number} runs past the file's end (to byte {offset + count} of {size}): cut short"
    needed = _bytes_needed(tags, data)
    if needed is None:  # compressed, or one strip: nothing to count (a decode's hot path, every strip else)
        return None
    for number, (count, need) in enumerate(zip(data.counts, needed), start=1):
        if count < need:
            return (f"its {data.kind} {number} holds {count} of the {need} bytes its pixels need "
                    f"(uncompressed): OpenCV would deliver the rest black")
    return None


def _single(tags: tiff_header.DirectoryTags, tag: int, default: int | None = None) -> int | None:
    """A tag's one value; ``default`` where it is absent; None where it has several."""
    entry = tags.get(tag)
    if entry is None:
        return default
    return entry.values[0] if len(entry.values) == 1 else None


def _bytes_needed(tags: tiff_header.DirectoryTags, data: tiff_header.ImageData) -> list[int] | None:
    """How many bytes each uncompressed strip or tile holds at least: its rows (a strip's, the last one's fewer;
    a tile's, all of them) of its samples (one plane's where the samples are in separate planes). None where the
    data is compressed (its size is the codec's), the header does not say, or there is one strip: libtiff then
    takes a byte count too small for a wrong one and reads the rows the file holds (checked in session 66)."""
    width, height = _single(tags, tiff_header.WIDTH), _single(tags, tiff_header.HEIGHT)
    samples, planar = _single(tags, _SAMPLES, 1), _single(tags, _PLANAR, 1)
    bits = tags.get(tiff_header.BITS_PER_SAMPLE)
    if (_single(tags, tiff_header.COMPRESSION, _UNCOMPRESSED) != _UNCOMPRESSED or None in (width, height, samples,
            planar) or bits is None or not width or not height or (not data.tiled and len(data.counts) == 1)):
        return None
    chunk_samples = 1 if planar == _SEPARATE_PLANES else samples
    if data.tiled:
        tile_width, tile_length = _single(tags, _TILE_WIDTH), _single(tags, _TILE_LENGTH)
        if not tile_width or not tile_length:
            return None
        return [(tile_width * chunk_samples * max(bits.values) + 7) // 8 * tile_length] * len(data.counts)
    rows_per_strip = min(_single(tags, _ROWS_PER_STRIP, height) or height, height)
    row_bytes = (width * chunk_samples * max(bits.values) + 7) // 8
    strips_a_plane = -(-height // rows_per_strip)
    return [min(rows_per_strip, height - (n % strips_a_plane) * rows_per_strip) * row_bytes
            for n in range(len(data.counts))]


def _samples_wider_than(tags: tiff_header.DirectoryTags, bits: int) -> bool:
    """Whether a TIFF whose first directory's ``tags`` were read gives samples of more than ``bits`` bits; False
    for a header that cannot be read."""
    sample_bits = tags.get(tiff_header.BITS_PER_SAMPLE)
    return sample_bits is not None and max(sample_bits.values, default=0) > bits


def samples_not_8_bit(path: str | os.PathLike) -> str | None:
    """Why an image that failed to decode as 8-bit BGR (IMREAD_COLOR) did, where OpenCV reads it as stored: its
    samples' type, e.g. "float32 samples (640x480, 3 channels): only 8- or 16-bit images decode to 8 bits" (a TIFF
    of 32- or 64-bit samples, float or integer, whose range 0-1 or 0-255 no header says); None where OpenCV cannot
    read it at all, or reads 8- or 16-bit samples. It decodes the file a second time: call it only once the first
    decode failed."""
    image = read_image_or_none(path, cv2.IMREAD_UNCHANGED)
    if image is None or image.size == 0 or (image.dtype.kind in "iu" and image.dtype.itemsize <= 2):
        # 8- or 16-bit samples decode, signed too: the first decode failed otherwise (a JPEG cut short, which
        # imdecode refuses and the file reader fills in grey, was "uint8 samples: only 8- or 16-bit images decode")
        return None
    channels = 1 if image.ndim == 2 else image.shape[2]
    return (f"{image.dtype.name} samples ({image.shape[1]}x{image.shape[0]}, {channels} channel"
            f"{'' if channels == 1 else 's'}): only 8- or 16-bit images decode to 8 bits")


class UnreadKind(enum.Enum):
    """What an :class:`UnreadCause` says of the file, for a caller whose error tells them apart (replay's
    ``load_image``: a layout it refuses, a corrupt frame)."""

    #: A valid image of a layout this OpenCV does not decode, whatever the read's flags (a TIFF's compression).
    REFUSED_LAYOUT = "refused layout"
    #: A file that does not hold its image (a TIFF's strip cut short or holding too few bytes): corrupt.
    DAMAGED = "damaged"
    #: A valid image that this OpenCV decodes, but not with the read's flags (float samples read to 8 bits).
    NOT_WITH_THESE_FLAGS = "not with these flags"


@dataclass(frozen=True)
class UnreadCause:
    """Why an image file did not read, where the file says (:func:`unread_cause`): ``text`` phrased to follow its
    name and a colon ("it is a TIFF of Compression 34712 (JPEG 2000), ...", "its strip 2 runs past ...", "it has
    float32 samples (...)"), and its ``kind``."""

    text: str
    kind: UnreadKind


def unread_cause(path: str | os.PathLike, flags: int) -> UnreadCause | None:
    """Why :func:`read_image_or_none` (or :func:`decode_image_or_none` of its bytes) gave None for ``path`` read
    with ``flags``, where the file says: a TIFF of a compression OpenCV does not decode
    (:func:`tiff_compression_refusal`), a TIFF whose strips do not hold its image (:func:`tiff_data_refusal`), or,
    read to 8 bits, samples that do not decode so (:func:`samples_not_8_bit`); None for a file corrupt otherwise,
    missing or unknown. The one chain of causes for every caller (ghnerf-run, ghcal, the ZJU-MoCap reader through
    :func:`unread_because`; replay's ``load_image``): a new cause is added here. Call it once the read failed: the
    sample check decodes the file again."""
    compression = tiff_compression_refusal(path)
    if compression is not None:
        return UnreadCause(f"it is {compression}", UnreadKind.REFUSED_LAYOUT)
    data = tiff_data_refusal(path)
    if data is not None:
        return UnreadCause(data, UnreadKind.DAMAGED)
    cut = jpeg_cut_short(path)
    if cut is not None:
        return UnreadCause(cut, UnreadKind.DAMAGED)
    samples = samples_not_8_bit(path) if _decodes_to_8_bits(flags) else None
    return None if samples is None else UnreadCause(f"it has {samples}", UnreadKind.NOT_WITH_THESE_FLAGS)


def unread_because(path: str | os.PathLike, flags: int) -> str | None:
    """The text of :func:`unread_cause`: "it is a TIFF of Compression 34712 (JPEG 2000), ...", "its strip 2 runs
    past the file's end ...", "it has float32 samples (...)"; None for a file corrupt otherwise, missing or unknown.
    Every caller's error names it: ZJU-MoCap's frames were "missing or unreadable" whatever the cause."""
    cause = unread_cause(path, flags)
    return None if cause is None else cause.text


def decoded_from_memory_because(path: str | os.PathLike) -> str | None:
    """Why :func:`read_image_or_none` decodes ``path`` from a copy of its bytes rather than through
    ``cv2.imread``'s file reader (which decodes some layouts that OpenCV refuses from memory), e.g. "its name is
    not UTF-8"; None where the file reader reads it (or the file cannot be opened). The choice is
    :func:`_memory_decode_because`'s, as for the read: replay calls a file corrupt on its word."""
    try:
        with open(path, "rb") as f:
            resets = _turn_resets(f)
    except (OSError, ValueError):  # as the read; ValueError: a NUL byte in the path, which the name check refuses
        resets = []
    return _memory_decode_because(path, resets)


#: Why a file is decoded from a copy of its bytes (:func:`_memory_decode_because`).
_NAME_NOT_TAKEN = "its name is not UTF-8 or holds a NUL byte, which OpenCV's file reader cannot be given"
_TURN_RESET = ("its orientation (a TIFF's Orientation tag, an AVIF's irot or imir) is not 'as stored', and is "
               "reset in a copy of its bytes that OpenCV then decodes from memory")


def _memory_decode_because(path: str | os.PathLike, resets: list[tuple[int, bytes]]) -> str | None:
    """The one choice between decoding ``path`` from a copy of its bytes and ``cv2.imread``'s file reader, given its
    :func:`_turn_resets`: why the bytes (a name OpenCV cannot be given, a turn to reset), or None for the file
    reader. :func:`read_image_or_none` reads by it and :func:`decoded_from_memory_because` tells it."""
    if not _opencv_can_take(path):
        return _NAME_NOT_TAKEN
    return _TURN_RESET if resets else None


def _opencv_can_take(path: str | os.PathLike) -> bool:
    """Whether ``cv2.imread`` may be given ``path``: a name that is not UTF-8 (bytes kept as surrogates, as a
    folder listing gives them) crashes OpenCV (a segmentation fault), and one holding a NUL byte is read only up to
    it (another file); such a path is read as bytes (and a NUL byte refused by Python)."""
    text = os.fspath(path)
    return is_utf8(text) and "\x00" not in text


def decode_image_or_none(data: np.ndarray, flags: int) -> np.ndarray | None:
    """``cv2.imdecode(data, flags)`` (``data`` a file's bytes as uint8) as stored, as :func:`read_image_or_none`
    reads a file; None where OpenCV cannot decode it, a size beyond its limits included. Only a TIFF's header is
    read (once copied, for its refusals and its turn reset); a JPEG's or PNG's bytes go to OpenCV as they are."""
    if data[:4].tobytes() not in tiff_header.LAYOUTS:
        return _decoded_with(data, _turn_resets_in(data), flags)
    resets = _resets_unless_refused(io.BytesIO(data.tobytes()), flags)
    if resets is None:
        return None  # as read_image_or_none
    return _decoded_with(data, resets, flags)


def _decoded_with(data: np.ndarray, resets: list[tuple[int, bytes]], flags: int) -> np.ndarray | None:
    """``cv2.imdecode`` of ``data`` with ``resets`` (its :func:`_turn_resets`) written to a copy; None where OpenCV
    cannot decode it."""
    try:
        return cv2.imdecode(_with_resets(data, resets), flags | AS_STORED)
    except cv2.error:
        return None


def _turn_resets(f: BinaryIO) -> list[tuple[int, bytes]]:
    """Where to write what (offset, bytes) in a file (``f`` at its start) so that a decoder delivers its pixels as
    stored: a TIFF's Orientation tag set to 1, an AVIF's rotate and mirror properties made "no turn". Other formats
    are told by their first 8 bytes, and need none."""
    head = f.read(8)
    f.seek(0)
    if head[:4] in tiff_header.LAYOUTS:
        reset = tiff_header.orientation_reset(f)  # (a decode reads it with its refusals: _resets_unless_refused)
        return [] if reset is None else [reset]
    if avif_header.is_isobmff(head):
        return avif_header.transforms_reset(f)
    return []


def _turn_resets_in(data: np.ndarray) -> list[tuple[int, bytes]]:
    """The :func:`_turn_resets` of a file's bytes. Only a TIFF's or an ISOBMFF file's bytes are read further."""
    head = data[:8].tobytes()
    if head[:4] not in tiff_header.LAYOUTS and not avif_header.is_isobmff(head):
        return []
    return _turn_resets(io.BytesIO(data.tobytes()))


def _with_resets(data: np.ndarray, resets: list[tuple[int, bytes]]) -> np.ndarray:
    """``data``, or a copy with ``resets`` written: OpenCV then decodes its pixels as stored."""
    if not resets:
        return data
    patched = data.copy()
    for offset, replacement in resets:
        patched[offset:offset + len(replacement)] = np.frombuffer(replacement, np.uint8)
    return patched
