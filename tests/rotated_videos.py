"""MP4 videos carrying a rotation, as a phone held upright writes them, built here: OpenCV writes the video (mp4v),
then its track header's display matrix is set byte by byte (no ffmpeg CLI, no files from elsewhere). OpenCV's
FFmpeg backend turns such a video's frames by it unless ``CAP_PROP_ORIENTATION_AUTO`` is turned off."""
from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

#: The stored size of the test videos (width, height): odd, and not square, so a quarter turn shows in the size.
SIZE = (64, 48)
#: ISO BMFF display matrices {a, b, u, c, d, v, x, y, w} (16.16 fixed point, u, v, w 2.30) by the clockwise turn.
MATRICES = {0: (0x10000, 0, 0, 0, 0x10000, 0, 0, 0, 0x40000000),
            90: (0, 0x10000, 0, -0x10000, 0, 0, 0, 0, 0x40000000)}


def sample_frames(count: int = 3) -> list[np.ndarray]:
    """Frames mp4v keeps well enough to tell apart and to tell turned: flat blocks, a bright corner, one per frame."""
    w, h = SIZE
    frames = []
    for k in range(count):
        frame = np.zeros((h, w, 3), np.uint8)
        frame[:, : w // 2] = (200, 200, 200)
        frame[: h // 3] = (0, 0, 255)
        frame[:16, :16] = 255
        frame[-16:, -16:] = (0, 255, 80 * k)
        frames.append(frame)
    return frames


def write_mp4v(path: Path, frames: list[np.ndarray], fps: float = 10.0) -> Path:
    """``frames`` as an MP4 (mp4v) at ``path``; skips the test where this OpenCV cannot write one."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, SIZE)
    if not writer.isOpened():
        pytest.skip("this OpenCV build cannot write MP4 (mp4v): no FFmpeg, or one without the encoder")
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


def _boxes(data: bytes, start: int, end: int) -> Iterator[tuple[bytes, int, int]]:
    """The ISO BMFF boxes between ``start`` and ``end``: (type, where its payload starts, where it ends)."""
    at = start
    while at + 8 <= end:
        size, kind = struct.unpack(">I4s", data[at:at + 8])
        header = 8
        if size == 1:  # a 64-bit size follows the type
            size, header = struct.unpack(">Q", data[at + 8:at + 16])[0], 16
        elif size == 0:  # to the end of its parent
            size = end - at
        yield kind, at + header, at + size
        at += size


def _child(data: bytes, start: int, end: int, kind: bytes) -> tuple[int, int]:
    for found, body, box_end in _boxes(data, start, end):
        if found == kind:
            return body, box_end
    raise AssertionError(f"no {kind!r} box in the MP4 OpenCV wrote")


def turned_copy(source: Path, target: Path, degrees: int = 90) -> Path:
    """``source`` copied to ``target`` with its (single) track's display matrix set to turn it by ``degrees``
    clockwise; nothing else is changed: the frames' bytes are the same."""
    data = bytearray(source.read_bytes())
    moov = _child(data, 0, len(data), b"moov")
    trak = _child(data, *moov, b"trak")
    tkhd, _ = _child(data, *trak, b"tkhd")
    version = data[tkhd]
    # version and flags (4), times and track id (20, or 32 in version 1), reserved (8), layer, alternate group,
    # volume, reserved (2 each): then the matrix
    matrix_at = tkhd + 4 + (32 if version == 1 else 20) + 8 + 8
    assert struct.unpack(">9i", data[matrix_at:matrix_at + 36]) == MATRICES[0], "not the identity OpenCV writes"
    data[matrix_at:matrix_at + 36] = struct.pack(">9i", *MATRICES[degrees])
    target.write_bytes(bytes(data))
    return target


def decoded(path: Path) -> list[np.ndarray]:
    """Every frame of ``path`` as OpenCV decodes it with its own defaults."""
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame)
    capture.release()
    return frames


def rotation_stated(path: Path) -> float:
    """The rotation OpenCV reads in ``path``'s container (``CAP_PROP_ORIENTATION_META``), degrees."""
    capture = cv2.VideoCapture(str(path))
    try:
        return capture.get(cv2.CAP_PROP_ORIENTATION_META)
    finally:
        capture.release()


def phone_take(folder: Path) -> tuple[Path, Path, list[np.ndarray]]:
    """A video turned a quarter by its metadata, an unturned copy of the same frames, and the copy's decoded frames
    (what the turned one must read as). Skips where this OpenCV does not see the rotation at all."""
    folder.mkdir(parents=True, exist_ok=True)
    plain = write_mp4v(folder / "plain.mp4", sample_frames())
    turned = turned_copy(plain, folder / "turned.mp4", 90)
    if rotation_stated(turned) != 90:
        pytest.skip("this OpenCV build does not read an MP4's rotation (CAP_PROP_ORIENTATION_META)")
    return turned, plain, decoded(plain)
