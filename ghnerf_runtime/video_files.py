"""Video files read as stored: their frames as the sensor gave them, never turned by the container's rotation.

A phone held upright writes its video sideways and a rotation beside it (the MP4/MOV ``tkhd`` box's matrix, or a
display-matrix side data): a display hint, like an image's EXIF orientation. OpenCV's FFmpeg backend turns every
decoded frame by it by default (``CAP_PROP_ORIENTATION_AUTO`` is on in OpenCV 5.0), so such a video's frames came a
quarter turn against the rig's calibration, which is of the sensor's pixel grid (docs/recording-format.md,
"Images": an image's EXIF orientation is ignored for the same reason). And a still image is no video
(:func:`is_still_image`), though FFmpeg opens a PNG or JPEG as a one-frame video: both callers refuse it, pointing at
their way of taking stills. Helpers for ``drivers`` (``opencv://``) and ``ghnerf-run``, both of which open video
files; cv2 only, so ``drivers`` imports them without the runtime's heavier modules.
"""
from __future__ import annotations

import logging
import math
import os
from typing import Any

import cv2

__all__ = ["is_still_image", "read_as_stored"]

log = logging.getLogger(__name__)


def read_as_stored(capture: Any, shown: str) -> bool:
    """Have the opened video file ``capture`` (a ``cv2.VideoCapture``) decode its frames as stored, its rotation
    metadata ignored; its stated width and height become the stored ones too. Call it before the first frame is
    read. Not for a camera device or a stream (nothing to turn there).

    Returns whether the frames are read as stored. A backend that keeps the rotation on (it refuses the property,
    and still reads it as on) is warned of, naming ``shown`` (the file as messages show it), and its frames come as
    it decodes them: a quarter turn of a non-square frame is then refused by the size checks against a rig, half a
    turn is not seen. A backend that does not know the property (it reads 0) does not turn frames by it.
    """
    capture.set(cv2.CAP_PROP_ORIENTATION_AUTO, 0)
    if capture.get(cv2.CAP_PROP_ORIENTATION_AUTO) == 0:
        return True
    degrees = capture.get(cv2.CAP_PROP_ORIENTATION_META)
    stated = f" (its container says {degrees:g} degrees)" if math.isfinite(degrees) and degrees else ""
    log.warning("video %s: OpenCV's capture backend did not let its rotation metadata%s be ignored: its frames may "
                "come turned against the rig's calibration, which is of the frames as stored", shown, stated)
    return False


def is_still_image(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a file OpenCV's image reader takes (told by its content, not its name) holding one image:
    opened as a video, FFmpeg plays it as one frame, and the stream ends after its first pair. An animated PNG or
    GIF (several images) plays as a video; an image-sequence pattern (``left_%04d.png``) is no file."""
    path = os.fspath(path)
    if not os.path.isfile(path) or not cv2.haveImageReader(path):
        return False
    try:
        return cv2.imcount(path) == 1
    except cv2.error:  # a header its reader cannot count: left to the video reader
        return False
