"""Image files OpenCV treats oddly, built byte by byte (no files from elsewhere)."""
from __future__ import annotations

import struct

import cv2
import numpy as np

#: OpenCV's default limit on a decoded image's side (CV_IO_MAX_IMAGE_WIDTH/HEIGHT)
OPENCV_MAX_SIDE = 1 << 20


def bmp_beyond_opencv_s_limits() -> bytes:
    """A 40x30 BMP whose header says it is 2**21 wide: ``cv2.imread`` and ``cv2.imdecode`` raise a cv2.error
    for it (a size beyond OpenCV's limits), where an unreadable file gives None."""
    ok, buf = cv2.imencode(".bmp", np.zeros((30, 40, 3), np.uint8))
    assert ok
    data = bytearray(buf.tobytes())
    struct.pack_into("<i", data, 18, 2 * OPENCV_MAX_SIDE)  # the info header's width
    return bytes(data)
