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
a tag, rather than an undoing of the turn that OpenCV's next version may no longer make.

``cv2.imread`` answers None for a file it cannot read, but raises a ``cv2.error`` for one whose header gives a size
beyond its limits (CV_IO_MAX_IMAGE_WIDTH/HEIGHT/PIXELS: a corrupt or hostile BMP, for one): each caller's error
naming the file was skipped for a traceback naming none. replay:// reads its files' bytes itself
(``drivers.backends.recording_format.load_image``) and decodes them with :func:`decode_image_or_none`.
"""
from __future__ import annotations

import io
import os

import cv2
import numpy as np

from ghnerf_runtime import tiff_header

__all__ = ["AS_STORED", "decode_image_or_none", "read_image_or_none"]

#: The decode flag that keeps an image's pixels as stored (IMREAD_UNCHANGED never turns them anyway), a JPEG's,
#: PNG's or WebP's EXIF orientation ignored; a TIFF's Orientation tag needs more (:func:`_tiff_as_stored`).
AS_STORED = cv2.IMREAD_IGNORE_ORIENTATION


def read_image_or_none(path: str | os.PathLike, flags: int) -> np.ndarray | None:
    """``cv2.imread(path, flags)`` as stored (:data:`AS_STORED` added; a TIFF's Orientation tag ignored too), or
    None where OpenCV cannot read the file, a size beyond its limits included."""
    if _tiff_orientation_reset_of(path) is not None:
        try:
            data = np.fromfile(os.fspath(path), dtype=np.uint8)
        except OSError:
            return None
        return decode_image_or_none(data, flags)
    try:
        return cv2.imread(os.fspath(path), flags | AS_STORED)  # (IMREAD_UNCHANGED is -1: it stays itself)
    except cv2.error:
        return None


def decode_image_or_none(data: np.ndarray, flags: int) -> np.ndarray | None:
    """``cv2.imdecode(data, flags)`` (``data`` a file's bytes as uint8) as stored, as :func:`read_image_or_none`
    reads a file; None where OpenCV cannot decode it, a size beyond its limits included."""
    try:
        return cv2.imdecode(_tiff_as_stored(data), flags | AS_STORED)
    except cv2.error:
        return None


def _tiff_orientation_reset_of(path: str | os.PathLike) -> tuple[int, bytes] | None:
    """A TIFF file's :func:`ghnerf_runtime.tiff_header.orientation_reset` (its header only read); None for
    another file, or one that cannot be opened (its read says so)."""
    try:
        with open(path, "rb") as f:
            return tiff_header.orientation_reset(f)
    except OSError:
        return None


def _tiff_as_stored(data: np.ndarray) -> np.ndarray:
    """``data``, or where it is a TIFF whose Orientation tag is not 1, a copy with the tag set to 1: OpenCV then
    decodes its pixels as stored. Other formats are told by their first four bytes, and not copied."""
    if data[:4].tobytes() not in tiff_header.LAYOUTS:
        return data
    reset = tiff_header.orientation_reset(io.BytesIO(data.tobytes()))
    if reset is None:
        return data
    offset, upright = reset
    patched = data.copy()
    patched[offset:offset + len(upright)] = np.frombuffer(upright, np.uint8)
    return patched
