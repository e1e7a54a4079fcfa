"""Reading an image file a user gives (ghnerf-run's stills, ghcal's views, a ZJU-MoCap copy's frames and masks).

Its pixels as stored, never turned by an EXIF orientation tag (:data:`AS_STORED`): the tag is a display hint a phone
or camera sets per shot from its gravity sensor, while a rig's calibration (and a dataset's) is of the sensor's pixel
grid, the frames the live cameras deliver. Turned by it, as OpenCV does by default for every flag but
IMREAD_UNCHANGED, a phone held upright gave frames a quarter turn against the calibration, and a tag of 3 (half a
turn) kept the size and gave them upside down (wrong joints, no error).

``cv2.imread`` answers None for a file it cannot read, but raises a ``cv2.error`` for one whose header gives a size
beyond its limits (CV_IO_MAX_IMAGE_WIDTH/HEIGHT/PIXELS: a corrupt or hostile BMP, for one): each caller's error
naming the file was skipped for a traceback naming none. replay:// decodes its own way
(``drivers.backends.recording_format.load_image``, with :data:`AS_STORED` too, and catching the same).
"""
from __future__ import annotations

import os

import cv2
import numpy as np

__all__ = ["AS_STORED", "read_image_or_none"]

#: The decode flag that keeps an image's pixels as stored (IMREAD_UNCHANGED never turns them anyway).
AS_STORED = cv2.IMREAD_IGNORE_ORIENTATION


def read_image_or_none(path: str | os.PathLike, flags: int) -> np.ndarray | None:
    """``cv2.imread(path, flags)`` as stored (:data:`AS_STORED` added), or None where OpenCV cannot read the file,
    a size beyond its limits included."""
    try:
        return cv2.imread(os.fspath(path), flags | AS_STORED)  # (IMREAD_UNCHANGED is -1: it stays itself)
    except cv2.error:
        return None
