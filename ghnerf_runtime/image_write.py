"""Writing an image file whole or not at all (ghnerf-run's --out image, ghnerf-demo's OUT/sim_pair.png).

``cv2.imwrite`` truncates the file first and says no more than False: a full disk left an earlier run's image cut
short. The image is encoded in memory and put in place by :func:`~ghnerf_runtime.rig_file.write_bytes_atomic`.
"""
from __future__ import annotations

import os

import cv2
import numpy as np

from ghnerf_runtime.errors import ImageWriteError, RigFileError
from ghnerf_runtime.rig_file import write_bytes_atomic

__all__ = ["write_image_atomic"]


def write_image_atomic(path: str | os.PathLike, image: np.ndarray) -> None:
    """``image`` encoded as ``path``'s suffix says, then written in place of any earlier file there.

    Raises:
        ImageWriteError: OpenCV cannot encode it (an unknown suffix), or the file cannot be written (its reason
            names the cause; an earlier file there is left as it was).
    """
    data = _encoded(path, image)
    try:
        write_bytes_atomic(path, data)
    except RigFileError as e:
        cause = getattr(e.__cause__, "strerror", None) or e
        raise ImageWriteError(os.fspath(path), f"cannot write the image ({cause}); an earlier file there is left "
                                               "as it was") from None


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
