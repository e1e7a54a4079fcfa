"""Reading an image file a user gives (ghnerf-run's stills, ghcal's views, a ZJU-MoCap copy's frames and masks).

``cv2.imread`` answers None for a file it cannot read, but raises a ``cv2.error`` for one whose header gives a size
beyond its limits (CV_IO_MAX_IMAGE_WIDTH/HEIGHT/PIXELS: a corrupt or hostile BMP, for one): each caller's error
naming the file was skipped for a traceback naming none. replay:// decodes its own way
(``drivers.backends.recording_format.load_image``, which catches the same).
"""
from __future__ import annotations

import os

import cv2
import numpy as np

__all__ = ["read_image_or_none"]


def read_image_or_none(path: str | os.PathLike, flags: int) -> np.ndarray | None:
    """``cv2.imread(path, flags)``, or None where OpenCV cannot read the file, a size beyond its limits included."""
    try:
        return cv2.imread(os.fspath(path), flags)
    except cv2.error:
        return None
