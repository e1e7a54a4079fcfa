"""Writing an image file whole or not at all (ghnerf-run's --out image, ghnerf-demo's OUT/sim_pair.png).

``cv2.imwrite`` truncates the file first and says no more than False: a full disk left an earlier run's image cut
short. The image is encoded in memory and put in place by :func:`~ghnerf_runtime.rig_file.write_bytes_atomic`;
a path that leads to no regular file (a FIFO a viewer reads, a device) is written into instead, since a file
renamed over a FIFO leaves its reader waiting.
"""
from __future__ import annotations

import os
import stat

import cv2
import numpy as np

from ghnerf_runtime.errors import ImageWriteError, RigFileError
from ghnerf_runtime.rig_file import write_bytes_atomic, write_bytes_into

__all__ = ["write_image_atomic"]


def write_image_atomic(path: str | os.PathLike, image: np.ndarray) -> None:
    """``image`` encoded as ``path``'s suffix says, then written in place of any earlier file there.

    Raises:
        ImageWriteError: OpenCV cannot encode it (an unknown suffix), or the file cannot be written (its reason
            names the cause; an earlier file there is left as it was).
    """
    data = _encoded(path, image)
    if _not_a_regular_file(path):
        _write_into(path, data)
        return
    try:
        write_bytes_atomic(path, data)
    except RigFileError as e:
        cause = getattr(e.__cause__, "strerror", None) or e
        raise ImageWriteError(os.fspath(path), f"cannot write the image ({cause}); an earlier file there is left "
                                               "as it was") from None


def _not_a_regular_file(path: str | os.PathLike) -> bool:
    """``path`` (through links) is there and is no regular file: a FIFO a viewer reads, a device."""
    try:
        return not stat.S_ISREG(os.stat(path).st_mode)
    except OSError:  # not there (made by the write), or said by the write
        return False


def _write_into(path: str | os.PathLike, data: bytes) -> None:
    """``data`` written whole into the FIFO or device at ``path``."""
    try:
        write_bytes_into(path, data)
    except OSError as e:
        raise ImageWriteError(os.fspath(path), f"cannot write the image ({e.strerror or e})") from None


def _encoded(path: str | os.PathLike, image: np.ndarray) -> bytes:
    """``image`` encoded in memory as ``path``'s suffix says."""
    suffix = os.path.splitext(os.fspath(path))[1]
    try:
        encoded, data = cv2.imencode(suffix, image)
    except cv2.error as e:
        raise ImageWriteError(os.fspath(path), f"cannot encode the image: {e}") from None
    if not encoded:
        raise ImageWriteError(os.fspath(path), "cannot encode the image")
    return data.tobytes()
