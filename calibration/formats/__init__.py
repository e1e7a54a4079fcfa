"""Import/export of foreign calibration files to and from :class:`~ghnerf_runtime.geometry.rig.Rig`.

* :mod:`calibration.formats.opencv_yaml`: OpenCV ``FileStorage`` YAML (the
  single-camera ``camera_matrix``/``distortion_coefficients`` layout of OpenCV's
  calibration sample, our multi-camera ``cameras:`` layout, and the ``M1 D1 M2 D2 R T``
  layout of OpenCV's ``stereo_calib`` sample).
* :mod:`calibration.formats.anipose_toml`: anipose / aniposelib ``calibration.toml``.

Foreign files carry no working volume: pass one, or get
:func:`default_working_volume`. Nor do they say whether their frame is levelled: our writers
record it, and our readers take it back where the poses show it (:mod:`calibration.formats._frame`). Every error is a
:class:`~ghnerf_runtime.errors.RigFileError` naming the file and the field.
Keys are documented in docs/rig-file.md ("Importing and exporting").
"""
from calibration.formats._common import default_working_volume
from calibration.formats.anipose_toml import dumps_anipose_toml, read_anipose_toml, write_anipose_toml
from calibration.formats.opencv_yaml import (
    dumps_opencv_rig,
    read_opencv_camera,
    read_opencv_rig,
    write_opencv_camera,
    write_opencv_rig,
    write_opencv_text,
)

__all__ = [
    "default_working_volume",
    "dumps_anipose_toml",
    "dumps_opencv_rig",
    "read_anipose_toml",
    "write_anipose_toml",
    "read_opencv_camera",
    "read_opencv_rig",
    "write_opencv_camera",
    "write_opencv_rig",
    "write_opencv_text",
]
