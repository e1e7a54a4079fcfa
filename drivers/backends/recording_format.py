"""The on-disk layout of a rig recording (docs/recording-format.md), shared by ``record+`` and ``replay://``.

A recording is a directory::

    manifest.json        format, version, rig (rig-file dict), image format, source, complete flag, counters
    frames.jsonl         one JSON row per frame, appended as frames are written
    images/<camera>/00000000.png   (or .jpg)
    truth/<camera>/00000000.npz    ground truth, when the source had it

Rows live in a JSON-lines journal rather than inside ``manifest.json`` so that a
recording cut short (power loss, crash) keeps every frame written so far and
nothing is rewritten per frame. Every load error names the file and the field.
"""
from __future__ import annotations

import functools
import io
import json
import math
import re
import struct
import tokenize
import zipfile
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, BinaryIO

import cv2
import numpy as np

from drivers.errors import RigInitializationError, RigOperationError
from drivers.frames import CameraTruth, Frame
from ghnerf_runtime import avif_header, tiff_header
from ghnerf_runtime.errors import RigFileError
from ghnerf_runtime.geometry import Rig
from ghnerf_runtime.image_files import (
    UnreadKind,
    decode_image_or_none,
    decoded_from_memory_because,
    read_image_or_none,
    unread_cause,
)
from ghnerf_runtime.path_check import shown
from ghnerf_runtime.json_keys import JsonTextError, first_repeat, loads_remembering
from ghnerf_runtime.rig_file import rig_from_dict, rig_to_dict, write_text_atomic

FORMAT = "ghnerf-rig-recording"
VERSION = 1
MANIFEST = "manifest.json"
FRAMES = "frames.jsonl"
IMAGE_FORMATS = {"png": ".png", "jpg": ".jpg"}
_TRUTH_FIELDS = ("joints_2d", "visible", "mask", "depth", "part_labels")
_MANIFEST_KEYS = ("format", "version", "rig", "image_format", "source", "created_utc", "complete", "counters")
_ROW_KEYS = ("camera", "index", "timestamp_ns", "image", "truth", "scene_time_s")
_SAFE_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")
#: The range of a journal row's ``index`` and ``timestamp_ns`` (signed 64-bit).
INT64_MIN, INT64_MAX = -(2**63), 2**63 - 1


@dataclass(frozen=True)
class FrameRow:
    """One line of ``frames.jsonl``: where one frame's image and truth are, and when it was captured."""

    camera: str
    index: int
    timestamp_ns: int
    image: str  # path relative to the recording directory
    truth: str | None = None  # npz path relative to the recording directory
    scene_time_s: float | None = None
    line: int = field(default=0, compare=False)  # where it was read in frames.jsonl (0: not read from one)

    def to_json(self) -> str:
        return json.dumps(
            {
                "camera": self.camera,
                "index": self.index,
                "timestamp_ns": self.timestamp_ns,
                "image": self.image,
                "truth": self.truth,
                "scene_time_s": self.scene_time_s,
            },
            allow_nan=False,
        )


@dataclass
class Manifest:
    """Everything about a recording except the frame rows."""

    rig: Rig
    image_format: str = "png"
    source: str = ""
    created_utc: str = ""
    complete: bool = False  # set when the recorder closed cleanly
    counters: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {
            "format": FORMAT,
            "version": VERSION,
            "rig": rig_to_dict(self.rig),
            "image_format": self.image_format,
            "source": self.source,
            "created_utc": self.created_utc,
            "complete": self.complete,
            "counters": self.counters,
        }


#: The counter a close that stopped waiting for a dead disk leaves in the manifest: its ``close_timeout_s``.
CLOSE_TIMED_OUT = "close_timed_out_s"


def why_not_closed(manifest: Manifest) -> str:
    """What a take not closed cleanly says of why, as a clause (empty where its manifest does not say)."""
    timeout = manifest.counters.get(CLOSE_TIMED_OUT)
    if timeout is None:
        return ""
    said = "the take's last frames were not written: the disk stopped answering"
    if isinstance(timeout, (int, float)) and not isinstance(timeout, bool):  # counters are another tool's to edit
        return f" ({said}, its close gave up after close_timeout_s={timeout:g})"
    return f" ({said})"


def _safe(name: str) -> bool:
    return bool(_SAFE_NAME.match(name)) and name not in (".", "..")


def camera_dir_name(rig: Rig, camera: str) -> str:
    """A file-system-safe directory name for a camera: its name, or ``cam<i>`` when the name is unsafe
    (``_cam<i>`` and so on when another camera is called that)."""
    if _safe(camera):
        return camera
    taken = {n for n in rig.names if _safe(n)}
    name = f"cam{rig.names.index(camera)}"
    while name in taken:
        name = "_" + name
    return name


def write_manifest(directory: Path, manifest: Manifest) -> None:
    """Atomically (re)write ``manifest.json``."""
    try:
        write_text_atomic(directory / MANIFEST, json.dumps(manifest.to_dict(), indent=1, allow_nan=False) + "\n")
    except RigFileError as e:
        raise RigOperationError(f"cannot write recording manifest {shown(str(directory / MANIFEST))}: {e}") from e


def _fail(path: Path, field_name: str | None, message: str) -> RigInitializationError:
    where = f"recording file {shown(str(path))}" + (f", field {field_name!r}" if field_name else "")
    return RigInitializationError(f"{where}: {message}")


def read_manifest(directory: Path, *, warn: bool = True) -> Manifest:
    """Load and validate ``manifest.json``. ``warn=False`` logs none of the rig's warnings
    (:func:`ghnerf_runtime.rig_file.rig_warnings`): ``replay://`` logs them at its open, once per daemon run.

    Raises:
        RigInitializationError: naming the file and field (missing, unknown or ill-typed key,
            wrong format or version, invalid rig).
    """
    path = directory / MANIFEST
    if directory.exists() and not directory.is_dir():  # said "does not exist" of a file that does
        raise RigInitializationError(f"recording directory {shown(str(directory))} is a file, not a folder: "
                                     f"replay:// takes the folder holding {MANIFEST}")
    if not directory.is_dir():
        raise RigInitializationError(f"recording directory {shown(str(directory))} does not exist")
    try:
        data = _json_value(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise _fail(path, None, "missing: not a recording directory (no manifest.json)") from None
    except (OSError, UnicodeDecodeError) as e:
        raise _fail(path, None, f"cannot read: {e}") from e
    except ValueError as e:
        raise _fail(path, None, str(e)) from e
    if not isinstance(data, dict):
        raise _fail(path, None, f"must be a JSON object, got {type(data).__name__}")
    if data.get("format") != FORMAT:
        raise _fail(path, "format", f"must be {FORMAT!r}, got {data.get('format')!r}")
    if data.get("version") != VERSION:
        raise _fail(path, "version", f"unsupported version {data.get('version')!r}; this build reads {VERSION}")
    for key in _MANIFEST_KEYS:
        if key not in data:
            raise _fail(path, key, "missing")
    unknown = sorted(set(data) - set(_MANIFEST_KEYS))
    if unknown:
        raise _fail(path, unknown[0], f"unknown key(s) {unknown}")
    if data["image_format"] not in IMAGE_FORMATS:
        raise _fail(path, "image_format", f"must be one of {sorted(IMAGE_FORMATS)}, got {data['image_format']!r}")
    for key, kind in (("source", str), ("created_utc", str), ("complete", bool), ("counters", dict)):
        if not isinstance(data[key], kind):
            raise _fail(path, key, f"must be a {kind.__name__}, got {data[key]!r}")
    try:
        rig = rig_from_dict(data["rig"], warn=warn)
    except RigFileError as e:
        raise _fail(path, f"rig.{e.field}" if e.field else "rig", str(e)) from e
    return Manifest(rig, data["image_format"], data["source"], data["created_utc"], data["complete"], data["counters"])


def _check_row(path: Path, line_no: int, obj: Any, rig: Rig) -> FrameRow:
    where = f"line {line_no}"
    if not isinstance(obj, dict):
        raise _fail(path, None, f"{where}: a row must be a JSON object, got {obj!r}")
    for key in _ROW_KEYS:
        if key not in obj:
            raise _fail(path, key, f"{where}: missing")
    unknown = sorted(set(obj) - set(_ROW_KEYS))
    if unknown:
        raise _fail(path, unknown[0], f"{where}: unknown key(s) {unknown}")
    pair = [c.name for c in rig.pair]  # only the pair is recorded and paired (a rig may list more cameras)
    if obj["camera"] not in pair:
        raise _fail(path, "camera", f"{where}: {obj['camera']!r} is not a camera of the rig's pair {pair}")
    for key in ("index", "timestamp_ns"):
        # 64-bit, as every clock and counter that records them is: a larger one (a corrupt digit run) was taken,
        # and opening the take then failed with a bare OverflowError from numpy, naming no file or line.
        if isinstance(obj[key], bool) or not isinstance(obj[key], int) or not INT64_MIN <= obj[key] <= INT64_MAX:
            raise _fail(path, key, f"{where}: must be a 64-bit integer, got {obj[key]!r}")
    for key in ("image", "truth"):
        value = obj[key]
        if value is None and key == "truth":
            continue
        if not isinstance(value, str) or not value or Path(value).is_absolute() or ".." in Path(value).parts:
            raise _fail(path, key, f"{where}: must be a relative path inside the recording, got {value!r}")
    st = obj["scene_time_s"]
    if st is not None and (isinstance(st, bool) or not isinstance(st, (int, float)) or not math.isfinite(st)):
        raise _fail(path, "scene_time_s", f"{where}: must be a finite number or null, got {st!r}")
    return FrameRow(
        obj["camera"], obj["index"], obj["timestamp_ns"], obj["image"], obj["truth"],
        None if st is None else float(st), line=line_no,
    )


def read_rows(directory: Path, manifest: Manifest) -> list[FrameRow]:
    """Load ``frames.jsonl``, rows in journal order.

    A recording that was not closed cleanly (``complete: false``) may end in a
    half-written line, or one of NUL bytes (a file extended but not written before
    a power cut); that last line is ignored. Anywhere else a bad line is an error.

    Raises:
        RigInitializationError: naming the file, line and field.
    """
    path = directory / FRAMES
    try:
        lines = path.read_bytes().split(b"\n")
    except FileNotFoundError:
        raise _fail(path, None, "missing (every recording has a frame journal, even an empty one)") from None
    except OSError as e:
        raise _fail(path, None, f"cannot read: {e}") from e
    last = max((n for n, line in enumerate(lines, start=1) if line.strip()), default=0)
    rows = []
    for n, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            obj = _parse_line(line)
        except ValueError as e:
            if n == last and not manifest.complete:
                break  # torn final write of an interrupted recording
            raise _fail(path, None, f"line {n}: {e}") from e
        rows.append(_check_row(path, n, obj, manifest.rig))
    return rows


def _parse_line(line: bytes) -> Any:
    if b"\0" in line:
        raise ValueError("NUL bytes (a write the disk never completed)")
    try:
        return _json_value(line.decode("utf-8"))
    except UnicodeDecodeError as e:
        raise ValueError(f"not UTF-8: {e.reason}") from e


def _json_value(text: str) -> Any:
    """``text`` as JSON, or a ValueError saying why not. Besides invalid JSON: nesting too deep and an integer
    of more digits than Python converts (a RecursionError or ValueError traceback from a replay's open, and from
    the daemon's config check), and a key given twice in one object (JSON keeps the last: a hand-edited
    manifest's first value was lost without a word)."""
    try:
        value = loads_remembering(text)
    except JsonTextError as e:
        if e.line is not None and "\n" not in text.strip():  # a journal line is one line: its column says where
            raise ValueError(f"invalid JSON at column {e.column}: {e.reason}") from e
        raise
    repeated = first_repeat(value)
    if repeated is not None:
        raise ValueError(f"duplicate key {repeated!r} (JSON keeps only its last value)")
    return value


def broken_rows_split(directory: Path, rows: list[FrameRow]) -> tuple[list[FrameRow], list[FrameRow]]:
    """A take cut short (``complete: false``): ``rows`` split into those whose files are whole and those whose image
    (:func:`image_is_whole`) or truth (:func:`payload_is_whole`) is missing, empty or cut short, each in journal
    order: the dropped ones are named in replay's warning.

    Journal rows can reach the disk before their files, and with several writer threads and no per-frame
    fsync the rows a power cut tore need not be the last ones: every broken row is dropped, wherever it is.
    A ``complete: true`` take promises whole files, so there any broken row is reported when it is opened.
    """
    kept, dropped = [], []
    for row in rows:
        whole = image_is_whole(directory / row.image) and (row.truth is None
                                                           or payload_is_whole(directory / row.truth))
        (kept if whole else dropped).append(row)
    return kept, dropped


def file_is_whole(path: Path) -> bool:
    """A file that exists and is not empty."""
    try:
        return path.stat().st_size > 0
    except OSError:
        return False


#: How a payload file is told whole from its start: its open file and its size.
_WholeCheck = Callable[[BinaryIO, int], bool]

#: How each payload file ends, and how far from its end that starts: PNG's IEND chunk (empty: its length, type
#: and CRC), JPEG's end-of-image marker, the npz's zip end-of-central-directory record (no archive comment is
#: written). A BMP, TIFF or WebP has no end mark: its header says how long it is (:data:`_WALKS`).
_PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"
_TRAILERS = {".png": (_PNG_END, len(_PNG_END)), ".jpg": (b"\xff\xd9", 2), ".jpeg": (b"\xff\xd9", 2),
             ".npz": (b"PK\x05\x06", 22)}


def image_is_whole(path: Path) -> bool:
    """:func:`payload_is_whole` for an image, where a suffix it does not know (``.jpe``, ``.dib``, ``.pam``, ``.pfm``,
    ``.sr``, ``.exr``, ``.hdr``, ``.jp2``, ``.gif``, ...) is whole where the file decodes (:func:`_decodes`): a
    file cut short was only checked for being there and not empty, then played and a corrupt frame."""
    return _is_whole(path, _decodes)


def payload_is_whole(path: Path) -> bool:
    """A file that exists, is not empty and, for an image or truth file, ends as its format ends.

    A power cut can leave a file with only its first blocks on disk: not empty, yet undecodable, and replay
    would fail on it mid-take; a few bytes read from its end tell. A PNG or JPEG another tool wrote may hold bytes
    after its end (a trailer, padding, an MPF second image): it is whole where its chunks, or segments and scans,
    walked from its start reach that end (:data:`_WALKS`), which a file cut before it cannot. A JPEG ending at its
    end marker is whole where its segments also reach its first scan, and where more scans follow its scans reach
    it too (:data:`_END_CONFIRMS`): one cut at the end of an EXIF thumbnail, or in a segment between a progressive
    JPEG's scans, may end on the same bytes. A BMP, TIFF or WebP is whole when it is as long as its header
    says. The suffix is matched whatever its case (``.JPG``). Another suffix: there and not empty
    (:func:`image_is_whole` decodes such an image).
    """
    return _is_whole(path, None)


def _is_whole(path: Path, unknown_suffix: _WholeCheck | None) -> bool:
    """:func:`payload_is_whole`, a file of a suffix it does not know checked by ``unknown_suffix`` (else there and
    not empty)."""
    suffix = path.suffix.lower()
    trailer, walk = _TRAILERS.get(suffix), _WALKS.get(suffix, unknown_suffix)
    if trailer is None and walk is None:
        return file_is_whole(path)
    try:
        with open(path, "rb") as f:
            size = f.seek(0, 2)
            if trailer is not None and _ends_with(f, size, *trailer):
                confirm = _END_CONFIRMS.get(suffix)
                f.seek(0)
                return confirm is None or confirm(f, size)  # the recorder's own files: a few bytes, headers read
            if walk is None:
                return False
            f.seek(0)
            return walk(f, size)  # only files not ending at their format's end mark
    except OSError:
        return False


def _ends_with(f: BinaryIO, size: int, marker: bytes, span: int) -> bool:
    """Whether ``marker`` starts ``span`` bytes before the end of a file of ``size`` bytes."""
    if size < span:
        return False
    f.seek(size - span)
    return f.read(len(marker)) == marker


def _png_reaches_its_end(f: BinaryIO, size: int) -> bool:
    """Whether a PNG's chunks, walked from its signature by their lengths (length, type, data, CRC), reach an
    IEND chunk whose CRC is right; whatever follows it does not matter. Only the chunk headers are read."""
    if f.read(len(_PNG_SIGNATURE)) != _PNG_SIGNATURE:
        return False
    while True:  # each pass moves on by at least a chunk header: it ends at IEND or the end of the file
        head = f.read(8)
        if len(head) < 8:
            return False
        length, kind = struct.unpack(">I4s", head)
        if kind == b"IEND":
            body = f.read(length + 4)
            return len(body) == length + 4 and struct.unpack(">I", body[length:])[0] == zlib.crc32(kind + body[:length])
        if f.tell() + length + 4 > size:
            return False  # the chunk runs past the end: cut short
        f.seek(length + 4, 1)  # the data and its CRC


def _jpeg_ending_at_its_marker_is_whole(f: BinaryIO, size: int) -> bool:
    """Whether a JPEG whose last bytes are an end-of-image marker's (FF D9) ends at its own. Its marker segments,
    walked by their lengths from its start (only their headers read), must reach its first scan: one cut at the end
    of an EXIF thumbnail, inside the APP1 segment holding it, ends on those bytes too. Where that scan is its only
    one, that is all: a cut cannot end on them in entropy-coded data (a 0xFF byte there is followed only by 0x00 or
    a restart marker). Where more scans follow (a progressive JPEG's, or a sequential one's of one component at a
    time), a cut inside a segment between two scans (the next scan's tables, a comment) may end on them too: the
    file is then walked to its end, its scans' data included (:func:`_jpeg_reaches_its_end`)."""
    first_scan = _jpeg_first_scan(f, size)
    if first_scan is None:
        return False
    if first_scan.is_the_only_one:
        return True
    f.seek(0)
    return _jpeg_reaches_its_end(f.read())


@dataclass(frozen=True)
class _JpegFirstScan:
    """What a JPEG's frame header and first scan header say of how many scans it has."""

    frame_marker: int | None  # None: no frame header before the first scan
    frame_components: int
    scan_components: int

    @property
    def is_the_only_one(self) -> bool:
        """A sequential frame's scan holding every component is its only one (each component is in one scan)."""
        return (self.frame_marker is not None and self.frame_marker not in _JPEG_PROGRESSIVE_FRAMES
                and self.scan_components == self.frame_components)


def _jpeg_first_scan(f: BinaryIO, size: int) -> _JpegFirstScan | None:
    """A JPEG's frame and first scan headers, its marker segments walked by their lengths from its start;
    ``None`` where they do not reach a scan (a segment running past the end: cut short; or malformed)."""
    if f.read(len(_JPEG_START)) != _JPEG_START:
        return None
    frame_marker, frame_components = None, 0
    while True:  # each pass moves on by at least a marker: it ends at a scan or the end of the file
        marker = _jpeg_marker(f)
        if marker is None or marker in (0x00, 0xD8, 0xD9):
            return None  # the end of the file before any scan, or malformed
        if marker == _JPEG_TEM or marker in _JPEG_RST:
            continue  # standalone: no length
        length = _jpeg_segment_length(f)
        if length is None or f.tell() + length > size:
            return None  # the segment runs past the end: cut short
        if marker == _JPEG_SOS:
            return _JpegFirstScan(frame_marker, frame_components, f.read(1)[0] if length else 0)
        if marker in _JPEG_FRAMES:
            body = f.read(length)  # precision, height, width, then the number of components
            frame_marker, frame_components = marker, body[5] if len(body) > 5 else 0
        else:
            f.seek(length, 1)


def _jpeg_file_reaches_its_end(f: BinaryIO, size: int) -> bool:
    return _jpeg_reaches_its_end(f.read())  # the whole file: only those not ending at the marker are walked


def _bmp_is_as_long_as_its_header_says(f: BinaryIO, size: int) -> bool:
    """Whether a BMP holds all its header says it holds: its file size (``bfSize``, at byte 2), its info header,
    and its pixel data (from ``bfOffBits``, at byte 10: :func:`_bmp_pixel_bytes`). A writer leaving its file size
    0 leaves the others to tell."""
    head = f.read(14 + 24)  # file header; info header's size, width, height, planes, bits, compression, image size
    if len(head) < 18 or not head.startswith(_BMP_START):
        return False
    file_size, pixels_at, info_size = struct.unpack("<I4xII", head[2:18])
    return size >= max(file_size, 14 + info_size, pixels_at + _bmp_pixel_bytes(head, info_size))


def _bmp_pixel_bytes(head: bytes, info_size: int) -> int:
    """The size of a BMP's pixel data: uncompressed, its rows'; compressed, the image size its info header
    gives; 0 where it does not (cut short, or a compressed layout whose image size is left 0)."""
    if info_size == 12:  # the OS/2 core header: 16-bit width and height, uncompressed
        if len(head) < 26:
            return 0
        width, height, _planes, bits = struct.unpack("<HHHH", head[18:26])
        compression, image_size = 0, 0
    else:
        if len(head) < 38:
            return 0
        width, height, _planes, bits, compression, image_size = struct.unpack("<iiHHII", head[18:38])
    if compression not in (0, _BMP_BITFIELDS):
        return image_size  # run-length coded (or JPEG, PNG inside): only the header's image size tells
    return (abs(width) * bits + 31) // 32 * 4 * abs(height)  # rows padded to 4 bytes, as OpenCV reads them


def _tiff_holds_its_first_directory(f: BinaryIO, size: int) -> bool:
    """Whether a TIFF holds its first directory (the page OpenCV decodes), the values it points at and its image
    data, each strip or tile to its last byte (:func:`ghnerf_runtime.tiff_header.first_directory_end`); only
    the directory and the strips' offsets and byte counts are read."""
    layout = tiff_header.LAYOUTS.get(f.read(4))
    if layout is None:
        return False
    end = tiff_header.first_directory_end(f, layout)
    return end is not None and end <= size


#: A WebP's RIFF size counts its bytes after the RIFF header (8 bytes); libwebp refuses one below 12 (the
#: ``WEBP`` tag and one chunk header).
_RIFF_HEADER_SIZE, _WEBP_SMALLEST_RIFF_SIZE = 8, 12


def _webp_holds_its_riff_size(f: BinaryIO, size: int) -> bool:
    """Whether a WebP holds as many bytes as its RIFF header says (libwebp decodes none of one holding fewer);
    bytes after them (another tool's trailer) do not matter, as libwebp does not read them."""
    head = f.read(_RIFF_HEADER_SIZE + 4)
    if len(head) < _RIFF_HEADER_SIZE + 4 or head[:4] != b"RIFF" or head[8:] != b"WEBP":
        return False
    riff_size = struct.unpack("<I", head[4:8])[0]
    return _WEBP_SMALLEST_RIFF_SIZE <= riff_size and _RIFF_HEADER_SIZE + riff_size <= size


#: A binary PBM's, PGM's or PPM's magic number and its samples a pixel (PBM: bits, its rows padded to a byte).
_PNM_SAMPLES = {b"P4": 0, b"P5": 1, b"P6": 3}
#: The ASCII ones (P1 to P3), whose length their header does not give.
_PNM_ASCII = (b"P1", b"P2", b"P3")
#: How much of a PNM's start is read for its header: longer (comments) is not checked (taken as whole).
_PNM_HEADER_MOST = 4096
_PNM_BYTES_16_BIT_MAXVAL = 256  # a maxval from this up: two bytes a sample
#: A header number after whitespace and comments, and the one byte OpenCV reads after it (the pixels start after
#: the last number's).
_PNM_TOKEN = re.compile(rb"(?:\s|#[^\r\n]*[\r\n])*(\d+)[\s\S]")


def _pnm_holds_its_pixels(f: BinaryIO, size: int) -> bool:
    """Whether a binary PBM, PGM or PPM (P4, P5, P6) holds the pixel data its header gives the size of: width x
    height samples (one or three, of two bytes where maxval is 256 or more; a PBM's rows of bits padded to a byte),
    from right after the one whitespace byte ending its header, as OpenCV reads it. Numbers follow whitespace and
    ``#`` comments. An ASCII one (P1 to P3), or one whose header runs past :data:`_PNM_HEADER_MOST`, is whole
    where it decodes (:func:`_decodes`): its length cannot be told from its header, and OpenCV 5.0 decodes none
    cut short (a sample cut in its digits, or the separator after the last one lost: None)."""
    head = f.read(_PNM_HEADER_MOST)
    magic = head[:2]
    if magic in _PNM_ASCII:
        return _decodes(f, size)
    if magic not in _PNM_SAMPLES:
        return False
    numbers, at = [], 2
    for _ in range(2 if magic == b"P4" else 3):  # width, height (and maxval, but for a PBM)
        token = _PNM_TOKEN.match(head, at)
        if token is None:  # cut in its header, unless too long a header to read
            return len(head) == _PNM_HEADER_MOST and _decodes(f, size)
        numbers.append(int(token.group(1)))
        at = token.end()  # past the one whitespace byte after the number
    return size >= at + _pnm_pixel_bytes(magic, numbers)


def _pnm_pixel_bytes(magic: bytes, numbers: list[int]) -> int:
    """The size of a binary PNM's pixel data from its header's width, height (and maxval)."""
    width, height = numbers[:2]
    if magic == b"P4":
        return (width + 7) // 8 * height
    sample_bytes = 2 if numbers[2] >= _PNM_BYTES_16_BIT_MAXVAL else 1
    return width * height * _PNM_SAMPLES[magic] * sample_bytes


def _decodes(f: BinaryIO, size: int) -> bool:
    """Whether an image whose length its header does not give (an ASCII PNM) or whose format is not walked here
    decodes, as :func:`load_image` decodes it from memory: the whole file is read and decoded, so only for those.
    OpenCV 5.0 decodes none of these cut short (checked in session 66 for ASCII PNM, Sun raster, Radiance HDR,
    JPEG 2000, GIF, PAM, PFM, ``.jpe`` and ``.dib`` cut at half, 90%, 99% and one byte short)."""
    f.seek(0)
    data = np.frombuffer(f.read(), np.uint8)
    return data.size > 0 and decode_image_or_none(data, _DECODE_FLAGS) is not None


def _avif_holds_its_item_data(f: BinaryIO, size: int) -> bool:
    """Whether an AVIF holds its ``meta`` box and each item's data extents, from its box headers and item
    locations (``iloc``) only (:func:`ghnerf_runtime.avif_header.item_data_end`); bytes after them do not matter."""
    if not avif_header.is_isobmff(f.read(8)):
        return False
    end = avif_header.item_data_end(f)
    return end is not None and end <= size


def _jpeg_reaches_its_end(data: bytes) -> bool:
    """Whether a JPEG's marker segments, walked by their lengths (as :func:`_jpeg_size` walks them), and its scans'
    entropy-coded data, walked to the marker after each, reach an end-of-image marker. Searched for, one could be
    found inside a segment (an EXIF thumbnail's); in entropy-coded data a 0xFF byte is followed only by 0x00 or a
    restart marker."""
    if not data.startswith(_JPEG_START):
        return False
    f = io.BytesIO(data)
    f.seek(len(_JPEG_START))
    while True:
        marker = _jpeg_marker(f)
        if marker is None:
            return False
        if marker == _JPEG_EOI:
            return True
        if marker == _JPEG_TEM or marker in _JPEG_RST:
            continue  # standalone: no length
        length = None if marker in (0x00, 0xD8) else _jpeg_segment_length(f)
        if length is None:
            return False  # a stuffed byte or a second start where a marker is due: malformed; or cut short
        f.seek(length, 1)
        if marker == _JPEG_SOS:
            f.seek(_jpeg_scan_end(data, f.tell()))


def _jpeg_scan_end(data: bytes, pos: int) -> int:
    """Where the marker after a scan's entropy-coded data (from ``pos``) starts; the data's end if none does."""
    while True:
        pos = data.find(b"\xff", pos)
        if pos < 0 or pos + 1 >= len(data):
            return len(data)
        following = data[pos + 1]
        if following == 0x00 or following in _JPEG_RST:
            pos += 2  # a stuffed 0xFF data byte, or a restart marker inside the scan
        else:
            return pos


#: What a payload file ending at its format's end mark must also show to be whole: a JPEG's segments reach its
#: first scan (an EXIF thumbnail inside APP1 ends with the same marker as the image), and its later scans, if any,
#: its end (a segment between two scans may hold the same bytes).
_END_CONFIRMS = {".jpg": _jpeg_ending_at_its_marker_is_whole, ".jpeg": _jpeg_ending_at_its_marker_is_whole}
#: How a payload file not ending at its format's end mark is walked from its start to tell whether it is whole.
_WALKS = {".png": _png_reaches_its_end, ".jpg": _jpeg_file_reaches_its_end, ".jpeg": _jpeg_file_reaches_its_end,
          ".bmp": _bmp_is_as_long_as_its_header_says, ".tif": _tiff_holds_its_first_directory,
          ".tiff": _tiff_holds_its_first_directory, ".webp": _webp_holds_its_riff_size,
          ".avif": _avif_holds_its_item_data,
          **dict.fromkeys((".pbm", ".pgm", ".ppm", ".pnm", ".pxm"), _pnm_holds_its_pixels)}


# ------------------------------------------------------------------ payloads
def encode_image(image: np.ndarray, image_format: str, jpeg_quality: int) -> bytes:
    ext = IMAGE_FORMATS[image_format]
    params = [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality] if image_format == "jpg" else [cv2.IMWRITE_PNG_COMPRESSION, 1]
    ok, buf = cv2.imencode(ext, image, params)
    if not ok:
        raise RigOperationError(f"OpenCV could not encode a {image.shape} image as {image_format}")
    return buf.tobytes()


#: How a recorded image is decoded: 8-bit BGR, its pixels as stored, its orientation (EXIF, or a TIFF's tag)
#: ignored on purpose (ghnerf_runtime.image_files says why: the rig's calibration is of the sensor's pixel grid).
#: It also makes the header's size the decoded size (header_size).
_DECODE_FLAGS = cv2.IMREAD_COLOR


class RefusedLayoutError(RigOperationError):
    """A recorded image that is valid, but of a layout this OpenCV does not decode: a TIFF of a compression it
    does not decode (``ghnerf_runtime.tiff_compression``) or of samples that do not decode to 8 bits (float or
    32-bit), or one it does not decode from memory
    (:func:`tiff_decoding_refusal`) which its file reader cannot be given either (:func:`load_image`); raised by
    its read, a corrupt frame as any image that does not decode, its message naming the cause and the remedy."""


def load_image(path: Path) -> np.ndarray:
    """Decode a recorded image as ``(H, W, 3)`` uint8 BGR, its pixels as stored (its orientation ignored:
    ``ghnerf_runtime.image_files.decode_image_or_none``).

    Raises:
        RefusedLayoutError: a valid image this OpenCV does not decode (:func:`_read_from_the_file`), or a TIFF
            of a compression it does not decode (before session 64's review, an all-black frame for most).
        RigOperationError: naming the file when it is missing or cannot be decoded.
    """
    try:
        data = np.fromfile(path, dtype=np.uint8)
    except OSError as e:
        raise RigOperationError(f"recording image {shown(str(path))} cannot be read: {e.strerror or e}") from e
    image = decode_image_or_none(data, _DECODE_FLAGS) if data.size else None
    if image is None:
        refusal = tiff_decoding_refusal(path)  # read only for one that failed
        if refusal is not None:
            return _read_from_the_file(path, refusal)
        raise _unread_error(path)
    return image


def _unread_error(path: Path) -> RigOperationError:
    """The error of a recorded image that did not decode (but for a layout refused from memory only): the cause
    the file gives (``ghnerf_runtime.image_files.unread_cause``, the chain every reader shares), typed by its kind
    (:data:`_UNREAD_ERRORS`), else "corrupt"."""
    cause = unread_cause(path, _DECODE_FLAGS)
    if cause is None:
        return RigOperationError(f"recording image {shown(str(path))} is corrupt (OpenCV cannot decode it)")
    error_type, verb = _UNREAD_ERRORS[cause.kind]
    return error_type(f"recording image {shown(str(path))} {verb}: {cause.text}")


#: A recorded image's error and verb for each kind of :class:`UnreadCause`: a valid image of a layout this OpenCV
#: refuses is a :class:`RefusedLayoutError` (a take of only those is refused at its open, the remedy named), and so
#: is a valid one of samples that do not decode to 8 bits (a float TIFF: called corrupt before session 63, and a
#: take of only those refused at open as corrupt before session 66); a damaged one is corrupt.
_UNREAD_ERRORS: Mapping[UnreadKind, tuple[type[RigOperationError], str]] = MappingProxyType({
    UnreadKind.REFUSED_LAYOUT: (RefusedLayoutError, "does not decode"),
    UnreadKind.DAMAGED: (RigOperationError, "is corrupt"),
    UnreadKind.NOT_WITH_THESE_FLAGS: (RefusedLayoutError, "does not decode"),
})


def _read_from_the_file(path: Path, refusal: str) -> np.ndarray:
    """An image of a layout OpenCV refuses to decode from memory (``refusal``: :func:`tiff_decoding_refusal`), read
    through its file reader, which takes those tiles (a mapped file), as stored. Where that fails too: a
    :class:`RefusedLayoutError` naming the cause where the file reader was not used (an orientation to ignore,
    which is reset in memory, or a name not UTF-8: the image may well be valid); else the file reader failed on
    the file itself, which is corrupt (a RigOperationError: the layout's refusal would call a corrupt file
    valid)."""
    image = read_image_or_none(path, _DECODE_FLAGS)
    if image is not None:
        return image
    memory_only = decoded_from_memory_because(path)
    if memory_only is not None:
        raise RefusedLayoutError(f"recording image {shown(str(path))} does not decode: it is {refusal}; OpenCV's "
                                 f"file reader, which decodes such tiles, is not used for it: {memory_only}")
    raise RigOperationError(f"recording image {shown(str(path))} is corrupt (OpenCV cannot decode it, from memory nor "
                            f"through its file reader)")


#: The first bytes of the formats :func:`header_size` reads: the two the recorder writes (IMAGE_FORMATS), and BMP.
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_JPEG_START = b"\xff\xd8"
_BMP_START = b"BM"
#: PNG chunks before the image data after which the decoded size may not be IHDR's: APNG's animation control (the
#: frame decoded need not be IHDR's size). EXIF (eXIf) does not: load_image ignores its orientation.
_PNG_SIZE_CHANGERS = (b"acTL",)
#: JPEG start-of-frame markers (SOF0-SOF15 but DHT, JPG and DAC, which share the range), where the size is.
_JPEG_FRAMES = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
_JPEG_SOS, _JPEG_TEM, _JPEG_EOI = 0xDA, 0x01, 0xD9
#: Progressive frames (SOF2, SOF6, SOF10, SOF14): their image is spread over several scans.
_JPEG_PROGRESSIVE_FRAMES = frozenset({0xC2, 0xC6, 0xCA, 0xCE})
_JPEG_RST = range(0xD0, 0xD8)
#: BMP info headers OpenCV reads the size from (BITMAPINFOHEADER, 40 bytes, and its longer versions up to V5's
#: 124; the 12-byte OS/2 core header is decoded instead), and the pixel layouts it decodes: (bits, compression).
_BMP_INFO_SIZES = range(40, 125)
_BMP_LAYOUTS = frozenset({(1, 0), (4, 0), (8, 0), (24, 0), (32, 0), (16, 0), (16, 3), (32, 3), (4, 2), (8, 1)})
#: 16-bit BI_BITFIELDS: OpenCV 5.0 decodes only these colour masks (red, green, blue: 5-6-5 and 5-5-5), and reads
#: them from the 12 bytes right after the info header whatever its size. A V4/V5 header (52 to 124 bytes) holds
#: its masks inside it, so such a file decodes only where its writer repeated them after the header.
_BMP_16_BIT_MASKS = (struct.pack("<III", 0xF800, 0x07E0, 0x001F), struct.pack("<III", 0x7C00, 0x03E0, 0x001F))
_BMP_BITFIELDS = 3
#: A palette layout (up to 8 bits) whose colours-used count is above this fails OpenCV's header check.
_BMP_MAX_COLOURS_USED = 256
#: OpenCV's default limits on a decoded image (CV_IO_MAX_IMAGE_WIDTH/HEIGHT/PIXELS): a header beyond them is
#: decoded instead (refused there, or allowed by OPENCV_IO_MAX_IMAGE_* set higher), not taken as a size.
_OPENCV_MAX_SIDE, _OPENCV_MAX_PIXELS = 1 << 20, 1 << 30
#: A TIFF's SamplesPerPixel, PlanarConfiguration, TileWidth and TileLength (its tiles' size in bytes, with
#: BitsPerSample: a tile holds every sample, or one where the samples are in separate planes).
_TIFF_SAMPLES, _TIFF_PLANAR, _TIFF_TILE_WIDTH, _TIFF_TILE_LENGTH = 277, 284, 322, 323
_TIFF_SEPARATE_PLANES = 2
#: The tags the size reader reads from a TIFF's first directory.
_TIFF_SIZE_TAGS = frozenset({tiff_header.WIDTH, tiff_header.HEIGHT, tiff_header.BITS_PER_SAMPLE,
                             tiff_header.COMPRESSION, _TIFF_SAMPLES, _TIFF_PLANAR, _TIFF_TILE_WIDTH,
                             _TIFF_TILE_LENGTH})
_TIFF_UNCOMPRESSED = 1
#: OpenCV 5.0 decodes an 8-bit TIFF of one or three samples with libtiff's RGBA reader, which, reading from memory
#: (cv2.imdecode, as load_image does; not a mapped file), refuses an uncompressed tile whose size in bytes is not a
#: multiple of this ("Invalid tile byte count ... Expected 768, got 1024": its read buffer is rounded up to it, then
#: compared with the tile's size). cv2.imread of the same file decodes it, and so do libtiff's own tools: the file
#: is valid.
_LIBTIFF_READ_BUFFER_STEP = 1024
_TIFF_BITS_DECODED = frozenset({8, 16})
#: The TIFF compressions whose header gives the size, those cv2.imwrite writes (none, LZW, JPEG, Adobe and old
#: deflate, PackBits): another one that OpenCV decodes (CCITT fax, ...; ghnerf_runtime.tiff_compression.decoded)
#: is decoded to tell, as a BMP layout OpenCV does not read is, and one it does not decode has no size (its read
#: names the compression: load_image).
_TIFF_COMPRESSIONS = frozenset({1, 5, 7, 8, 32946, 32773})
#: A VP8X chunk's animation flag; the chunks holding a WebP's image; a VP8 key frame's start code; VP8L's signature.
_WEBP_ANIMATED = 0x02
_WEBP_BITSTREAMS = (b"VP8 ", b"VP8L")
_VP8_START_CODE, _VP8L_SIGNATURE = b"\x9d\x01\x2a", 0x2F


def header_size(path: Path) -> tuple[int, int] | None:
    """A PNG, JPEG, BMP, TIFF or WebP image's ``(width, height)`` read from its header, without decoding it;
    ``None`` where the header cannot say which size :func:`load_image` would decode: another format, a header cut
    short or malformed (a bad IHDR checksum, a segment running past the end), an animated PNG or WebP, a BMP
    layout or TIFF compression OpenCV does not read. Orientation does not matter: :func:`load_image` decodes the
    pixels as stored, ignoring an EXIF orientation and a TIFF's Orientation tag, so the stored size is the decoded.

    Strict on purpose: ``None`` is never a size, and the caller decodes the file instead (:func:`image_size`).
    """
    try:
        with open(path, "rb") as f:
            start = f.read(_HEADER_START)
            for signature, read_size in _SIZE_READERS:
                if start.startswith(signature):
                    f.seek(len(signature))
                    return read_size(f)
    except OSError:
        pass  # unreadable: its read names it
    return None


def _png_size(f: BinaryIO) -> tuple[int, int] | None:
    """IHDR's size, once the chunks up to the image data (IDAT) show nothing that changes it."""
    ihdr = f.read(8 + 13 + 4)  # length, type; width, height, depth, colour type, compression, filter, interlace; CRC
    if len(ihdr) < 25 or ihdr[:8] != b"\x00\x00\x00\x0dIHDR" or \
            struct.unpack(">I", ihdr[21:])[0] != zlib.crc32(ihdr[4:21]):
        return None
    width, height = struct.unpack(">II", ihdr[8:16])
    if not _decodable(width, height):
        return None
    while True:  # each pass moves on by at least a chunk header: it ends at IDAT or the end of the file
        head = f.read(8)
        if len(head) < 8:
            return None  # no image data: not decodable
        length, kind = struct.unpack(">I4s", head)
        if kind == b"IDAT":
            return width, height
        if kind in _PNG_SIZE_CHANGERS:
            return None
        f.seek(length + 4, 1)  # the data and its CRC


def _jpeg_size(f: BinaryIO) -> tuple[int, int] | None:
    """The frame header's size, once the marker segments up to the first scan (SOS) show exactly one frame header.
    Any others before it (APPn as EXIF, JFIF or XMP, COM, DQT, DHT, DRI) are skipped by their lengths."""
    size = None
    while True:
        marker = _jpeg_marker(f)
        if marker is None:
            return None
        if marker == _JPEG_SOS:
            return size
        if marker == _JPEG_TEM or marker in _JPEG_RST:
            continue  # standalone: no length
        if marker in (0x00, 0xD8, 0xD9):
            return None  # a stuffed byte, a second start or an end before the first scan: malformed
        length = _jpeg_segment_length(f)
        if length is None:
            return None
        if marker in _JPEG_FRAMES:
            body = f.read(length)
            if size is not None or length < 5 or len(body) < length:
                return None  # two frame headers, or one cut short
            height, width = struct.unpack(">HH", body[1:5])
            if not _decodable(width, height):
                return None  # height 0: given after the first scan (DNL), which OpenCV's decoder refuses anyway
            size = (width, height)
        else:
            f.seek(length, 1)  # past the end of a file cut short: the next read finds nothing


def _jpeg_segment_length(f: BinaryIO) -> int | None:
    """The length of a marker segment's data after its two length bytes (read here); ``None`` where cut short or
    shorter than those two bytes."""
    raw = f.read(2)
    if len(raw) < 2 or struct.unpack(">H", raw)[0] < 2:
        return None
    return struct.unpack(">H", raw)[0] - 2


def _jpeg_marker(f: BinaryIO) -> int | None:
    """The next marker's code, past the 0xFF fill bytes before it; ``None`` at the end or where no marker is."""
    head = f.read(2)
    if len(head) < 2 or head[0] != 0xFF:
        return None
    marker = head[1]
    while marker == 0xFF:
        byte = f.read(1)
        if not byte:
            return None
        marker = byte[0]
    return marker


def _bmp_size(f: BinaryIO) -> tuple[int, int] | None:
    """The info header's width and height (negative for rows stored top-down, the height is its magnitude)
    where OpenCV decodes its layout; the file header is 14 bytes, the info header follows."""
    head = f.read(14 + 36)  # file header; info header's size, width, height, planes, bits, compression, ..., colours
    if len(head) < 50:
        return None
    info_size, width, height, _planes, bits, compression = struct.unpack("<IiiHHI", head[14:34])
    if info_size not in _BMP_INFO_SIZES or (bits, compression) not in _BMP_LAYOUTS:
        return None
    if bits <= 8 and struct.unpack("<I", head[46:50])[0] > _BMP_MAX_COLOURS_USED:
        return None
    if (bits, compression) == (16, _BMP_BITFIELDS) and not _bmp_masks_decodable(f, info_size):
        return None
    height = abs(height)  # negative: rows stored top-down
    return (width, height) if _decodable(width, height) else None


def _bmp_masks_decodable(f: BinaryIO, info_size: int) -> bool:
    """Whether a 16-bit BI_BITFIELDS file has, where OpenCV reads them, colour masks it decodes."""
    f.seek(14 + info_size)
    return f.read(12) in _BMP_16_BIT_MASKS


def _tiff_size(f: BinaryIO, layout: tiff_header.TiffLayout) -> tuple[int, int] | None:
    """The first image file directory's ImageWidth and ImageLength (the page OpenCV decodes), where OpenCV
    decodes its layout (:func:`_tiff_layout_decodable`). Its Orientation does not matter: :func:`load_image`
    decodes the pixels as stored (ghnerf_runtime.image_files sets the tag to 1 first)."""
    entries = tiff_header.first_directory(f, layout, _TIFF_SIZE_TAGS)
    if entries is None:
        return None
    tags = {tag: entry.values for tag, entry in entries.items()}
    if not _tiff_layout_decodable(tags) or _tiff_tile_refusal(tags) is not None:
        return None  # decoded to tell (image_size): a later OpenCV may read the tiles this one refuses
    width, height = tags[tiff_header.WIDTH][0], tags[tiff_header.HEIGHT][0]
    return (width, height) if _decodable(width, height) else None


def _tiff_layout_decodable(tags: dict[int, tuple[int, ...]]) -> bool:
    """Whether OpenCV decodes a TIFF of these tags, 8-bit, to its stored size: one width and height, a compression
    it decodes, and samples of 8 or 16 bits (32 and 64, integer or float, it does not decode to 8 bits)."""
    single = all(len(tags.get(tag, (1,))) == 1
                 for tag in (tiff_header.WIDTH, tiff_header.HEIGHT, tiff_header.COMPRESSION))
    return (single and tiff_header.WIDTH in tags and tiff_header.HEIGHT in tags
            and tags.get(tiff_header.COMPRESSION, (1,))[0] in _TIFF_COMPRESSIONS
            and set(tags.get(tiff_header.BITS_PER_SAMPLE, (1,))) <= _TIFF_BITS_DECODED)


def _tiff_tile_refusal(tags: dict[int, tuple[int, ...]]) -> str | None:
    """Why OpenCV 5.0 may refuse to decode a TIFF of these tags from memory (:data:`_LIBTIFF_READ_BUFFER_STEP`):
    uncompressed tiles whose size in bytes is not a multiple of 1024; ``None`` for any other layout."""
    tile = tags.get(_TIFF_TILE_WIDTH, (0,))[0], tags.get(_TIFF_TILE_LENGTH, (0,))[0]
    if not all(tile) or tags.get(tiff_header.COMPRESSION, (_TIFF_UNCOMPRESSED,))[0] != _TIFF_UNCOMPRESSED:
        return None
    samples = tags.get(_TIFF_SAMPLES, (1,))[0]
    samples_a_tile = 1 if tags.get(_TIFF_PLANAR, (1,))[0] == _TIFF_SEPARATE_PLANES else samples
    tile_bytes = tile[0] * tile[1] * samples_a_tile * max(tags.get(tiff_header.BITS_PER_SAMPLE, (1,))) // 8
    if tile_bytes % _LIBTIFF_READ_BUFFER_STEP == 0:
        return None
    return (f"an uncompressed tiled TIFF whose {tile[0]}x{tile[1]} tiles of {samples} sample(s) are {tile_bytes} "
            f"bytes, not a multiple of {_LIBTIFF_READ_BUFFER_STEP}: OpenCV {cv2.__version__}'s libtiff refuses "
            f"such tiles read from memory ('Invalid tile byte count'), though the file is valid; rewrite the take's "
            f"TIFFs in strips, compressed (LZW), or with tiles of a multiple of {_LIBTIFF_READ_BUFFER_STEP} bytes")


def tiff_decoding_refusal(path: Path) -> str | None:
    """Why OpenCV may refuse to decode this image although it is valid (:func:`_tiff_tile_refusal`), from its
    header; ``None`` for another format or layout, or a header that cannot be read."""
    try:
        with open(path, "rb") as f:
            layout = tiff_header.LAYOUTS.get(f.read(4))
            entries = None if layout is None else tiff_header.first_directory(f, layout, _TIFF_SIZE_TAGS)
    except OSError:
        return None
    return None if entries is None else _tiff_tile_refusal({tag: e.values for tag, e in entries.items()})


def _webp_size(f: BinaryIO) -> tuple[int, int] | None:
    """A still WebP's size from its first chunk: a lossy (``VP8 ``) or lossless (``VP8L``) bitstream's header,
    or an extended file's (``VP8X``) canvas, where it is not animated and its bitstream's header gives the same
    size (libwebp refuses a still image of another size than its canvas)."""
    if f.read(8)[4:] != b"WEBP":  # past the RIFF size
        return None  # a RIFF file of another kind (a WAV, an AVI)
    kind, length = _riff_chunk_head(f)
    if kind != b"VP8X":
        return _webp_bitstream_size(f, kind, length)
    extended = f.read(10)
    if length < 10 or len(extended) < 10 or extended[0] & _WEBP_ANIMATED:
        return None
    canvas = (int.from_bytes(extended[4:7], "little") + 1, int.from_bytes(extended[7:10], "little") + 1)
    f.seek(length - 10 + length % 2, 1)
    while kind is not None:  # the chunks before the bitstream (ALPH, ICCP) are walked past by their lengths
        kind, length = _riff_chunk_head(f)
        if kind in _WEBP_BITSTREAMS:
            size = _webp_bitstream_size(f, kind, length)
            return size if size == canvas else None
        f.seek(length + length % 2, 1)
    return None


def _riff_chunk_head(f: BinaryIO) -> tuple[bytes | None, int]:
    """The next RIFF chunk's four-character kind and data length; ``(None, 0)`` at the end of the file."""
    head = f.read(8)
    if len(head) < 8:
        return None, 0
    return head[:4], struct.unpack("<I", head[4:])[0]


def _webp_bitstream_size(f: BinaryIO, kind: bytes | None, length: int) -> tuple[int, int] | None:
    """The size a VP8 key frame's or a VP8L image's header gives (``f`` at the chunk's data); ``None`` for another
    chunk, or a header libwebp would refuse (VP8: not a shown key frame, a profile above 3, a first partition not
    inside the chunk; VP8L: not version 0)."""
    if kind == b"VP8 ":
        head = f.read(10)  # frame tag (3 bytes), start code (3), width and height (14 bits and a scale each)
        if len(head) < 10 or head[3:6] != _VP8_START_CODE:
            return None
        tag = int.from_bytes(head[:3], "little")
        key_frame, profile, shown, first_partition = not tag & 1, (tag >> 1) & 7, (tag >> 4) & 1, tag >> 5
        if not key_frame or profile > 3 or not shown or first_partition >= length:
            return None
        width, height = (value & 0x3FFF for value in struct.unpack("<HH", head[6:10]))  # the scale: a display hint
    elif kind == b"VP8L":
        head = f.read(5)
        if len(head) < 5 or head[0] != _VP8L_SIGNATURE:
            return None
        bits = int.from_bytes(head[1:], "little")
        if bits >> 29:
            return None  # a version other than 0
        width, height = (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1
    else:
        return None
    return (width, height) if _decodable(width, height) else None


def _bmp_size_from_its_start(f: BinaryIO) -> tuple[int, int] | None:
    f.seek(0)  # its offsets are counted from the file's start
    return _bmp_size(f)


#: Each format header_size reads: its first bytes, and the reader of its size (``f`` just past those bytes).
_SIZE_READERS = (
    (_PNG_SIGNATURE, _png_size),
    (_JPEG_START, _jpeg_size),
    (_BMP_START, _bmp_size_from_its_start),
    (b"RIFF", _webp_size),
    *((start, functools.partial(_tiff_size, layout=layout)) for start, layout in tiff_header.LAYOUTS.items()),
)
_HEADER_START = max(len(signature) for signature, _ in _SIZE_READERS)


def _decodable(width: int, height: int) -> bool:
    """Whether OpenCV decodes an image of this size at its default limits (beyond them it raises)."""
    return 0 < width <= _OPENCV_MAX_SIDE and 0 < height <= _OPENCV_MAX_SIDE and width * height <= _OPENCV_MAX_PIXELS


class UndecodableImageError(RigInitializationError):
    """A take whose images of one camera all fail to decode at open (``replay``'s ``size_error``), one at least
    valid but of a layout this OpenCV does not decode (:class:`RefusedLayoutError`): its message names the file
    and the cause."""


def image_size(path: Path) -> tuple[int, int] | RefusedLayoutError | None:
    """A recorded image's ``(width, height)``: from its header (:func:`header_size`), else decoded (another
    format, a header it cannot read); for one that does not decode, the :class:`RefusedLayoutError` of a valid
    image this OpenCV refuses (:func:`load_image`), else ``None`` (corrupt: its read names it). Each is a
    corrupt frame when read; the caller decides what a take of them is."""
    size = header_size(path)
    if size is not None:
        return size
    try:
        image = load_image(path)
    except RefusedLayoutError as e:
        return e
    except RigOperationError:
        return None
    return image.shape[1], image.shape[0]


def write_truth(path: Path, truth: CameraTruth | None, joints_3d: np.ndarray | None) -> None:
    """Store ground truth as an npz archive (deflate level 1: the maps compress ~100x, quickly)."""
    arrays: dict[str, np.ndarray] = {}
    if truth is not None:
        arrays.update({name: np.asarray(getattr(truth, name)) for name in _TRUTH_FIELDS})
    if joints_3d is not None:
        arrays["joints_3d"] = np.asarray(joints_3d)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as archive:
        for name, array in arrays.items():
            with archive.open(f"{name}.npy", "w", force_zip64=True) as f:
                np.lib.format.write_array(f, np.ascontiguousarray(array), allow_pickle=False)


def load_truth(path: Path) -> tuple[CameraTruth | None, np.ndarray | None]:
    """Read what :func:`write_truth` stored.

    Raises:
        RigOperationError: naming the file (and the array) when it is missing, a folder, unreadable or corrupt.
    """
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
    except FileNotFoundError as e:
        raise RigOperationError(f"recording truth file {shown(str(path))} is missing") from e
    except IsADirectoryError as e:
        raise RigOperationError(f"recording truth file {shown(str(path))} is a folder, not a file") from e
    except OSError as e:
        if e.errno is None:  # no OS reason: a format complaint raised as OSError, a damaged file
            raise RigOperationError(f"recording truth file {shown(str(path))} is corrupt: {e}") from e
        # permission, I/O error: the OS's reason, not "corrupt" (the file may be whole)
        raise RigOperationError(f"recording truth file {shown(str(path))} cannot be read: {e.strerror or e}") from e
    except (ValueError, zipfile.BadZipFile, EOFError, zlib.error, NotImplementedError, tokenize.TokenError) as e:
        # zlib.error: a member's deflate data damaged; NotImplementedError: zipfile's word for a damaged member's
        # compression method; TokenError: numpy's parse of a damaged .npy header (each a traceback from a read)
        raise RigOperationError(f"recording truth file {shown(str(path))} is corrupt: {e}") from e
    joints_3d = arrays.pop("joints_3d", None)
    if not arrays:
        return None, joints_3d
    missing = [name for name in _TRUTH_FIELDS if name not in arrays]
    if missing:
        raise RigOperationError(f"recording truth file {shown(str(path))}: array(s) {missing} missing")
    return CameraTruth(**{name: arrays[name] for name in _TRUTH_FIELDS}), joints_3d


def frame_has_truth(frame: Frame) -> bool:
    return frame.truth is not None or frame.joints_3d is not None
