"""Whether a rig's frame is levelled (y down along gravity, the floor at y = 0), carried through foreign files.

OpenCV FileStorage and anipose files have no word for a rig frame: read back, every rig looked like one in
a calibration tool's own frame, and ``ghcal import`` warned "not levelled" about the rig ``ghcal export``
had just written from a levelled one. So our writers record the first camera's levelling (its height above
the floor, pitch and roll: :func:`calibration.level.level_rig`'s arguments) in keys the formats' other
readers ignore (:data:`KEYS`), and our readers take it back as ``metadata["levelled"]`` only where the
file's poses still show it. A tool that re-solved the poses in a frame of its own (its first camera's,
say) keeps the keys but not the geometry; such a rig is read as not levelled, and
``metadata["source"]["levelling_mismatch"]`` says why.
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from calibration.formats._common import fail, show
from calibration.level import down_in_camera
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.rig import Rig

__all__ = ["KEYS", "TOOL_FORMATS", "levelling_of", "recorded_levelling", "levelling_metadata"]

#: The keys our writers add (OpenCV: top level; anipose: ``[metadata]``), in the order written.
KEYS = ("levelled_reference", "levelled_camera_height_m", "levelled_pitch_deg", "levelled_roll_deg")
#: The import formats whose frame is the writing tool's own until ``level_rig`` (or a verified record) says otherwise.
TOOL_FORMATS = ("opencv-yaml", "opencv-stereo-calib", "anipose-toml")
#: How far the file's poses may be from the levelling it records. Our writers' round trip is ~1e-12; these
#: let through a few printed digits and refuse any re-solved frame (1 mm, and 0.01 deg: 0.5 mm at 3 m).
HEIGHT_TOLERANCE_M = 1e-3
DOWN_TOLERANCE_DEG = 0.01


def _first_camera_levelling(camera: Camera) -> tuple[float, np.ndarray]:
    """The camera's height above the floor and gravity's direction in its frame, read as a levelled rig's."""
    return float(-camera.center[1]), camera.R[:, 1]


def levelling_of(rig: Rig) -> dict[str, Any] | None:
    """What the writers record: the first camera's levelling, or None where the rig's frame is a tool's own
    (imported and not levelled) or puts that camera on or under the floor (not a levelled frame)."""
    metadata = rig.metadata if isinstance(rig.metadata, dict) else {}
    source = metadata.get("source")
    if isinstance(source, dict) and source.get("format") in TOOL_FORMATS and "levelled" not in metadata:
        return None
    camera = rig.cameras[0]
    height, down = _first_camera_levelling(camera)
    # within HEIGHT_TOLERANCE_M of the floor: a tool's own frame (its first camera at the origin, up to float noise
    # that read "levelled already ... 0.000 m above the floor" on import), not a levelled one
    if not height > HEIGHT_TOLERANCE_M:
        return None
    # (+ 0.0: no "-0" roll printed for a level camera)
    return {"reference": camera.name, "camera_height_m": height,
            "pitch_deg": math.degrees(math.asin(float(np.clip(down[2], -1.0, 1.0)))) + 0.0,
            "roll_deg": math.degrees(math.atan2(-float(down[0]), float(down[1]))) + 0.0}


def recorded_levelling(path, values: Mapping[str, Any], prefix: str = "") -> dict[str, Any] | None:
    """The levelling a file records (``values``: key -> value, missing keys absent), checked; None without one.

    :raises RigFileError: some of :data:`KEYS` but not all, or a value of the wrong kind (naming ``prefix``+key).
    """
    present = [k for k in KEYS if k in values]
    if not present:
        return None
    missing = [k for k in KEYS if k not in values]
    if missing:
        raise fail(path, prefix + missing[0], f"missing: the file records a levelling in {', '.join(present)} "
                                              f"and needs all of {', '.join(KEYS)}")
    reference = values[KEYS[0]]
    if not isinstance(reference, str) or not reference:
        raise fail(path, prefix + KEYS[0], f"must be a camera's name, got {show(reference)}")
    numbers = []
    for key in KEYS[1:]:
        value = values[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise fail(path, prefix + key, f"must be a finite number, got {show(value)}")
        numbers.append(float(value))
    if not numbers[0] > 0:
        raise fail(path, prefix + KEYS[1], f"must be a positive height in metres, got {show(values[KEYS[1]])}")
    return {"reference": reference, "camera_height_m": numbers[0], "pitch_deg": numbers[1], "roll_deg": numbers[2]}


def _mismatch(cameras: Sequence[Camera], record: Mapping[str, Any]) -> str | None:
    """Why the cameras' poses do not show ``record`` (None: they do)."""
    if not cameras or cameras[0].name != record["reference"]:
        return (f"it names camera {record['reference']!r} as the first, but the first is "
                f"{cameras[0].name if cameras else None!r}")
    height, down = _first_camera_levelling(cameras[0])
    if not abs(height - record["camera_height_m"]) <= HEIGHT_TOLERANCE_M:
        return (f"camera {record['reference']!r} is {height:.4f} m above the floor in the file's poses, "
                f"{record['camera_height_m']:.4f} m in the levelling it records")
    expected = down_in_camera(record["pitch_deg"], record["roll_deg"])
    angle = math.degrees(math.acos(float(np.clip(down @ expected, -1.0, 1.0))))
    if not angle <= DOWN_TOLERANCE_DEG:
        return (f"camera {record['reference']!r} is tilted {angle:.3f} degrees away from the pitch "
                f"{record['pitch_deg']:.2f} and roll {record['roll_deg']:.2f} degrees it records")
    return None


def levelling_metadata(cameras: Sequence[Camera], record: Mapping[str, Any] | None, source: dict) -> dict:
    """The read rig's metadata: ``source``, and ``levelled`` where ``record`` is one the poses show (else
    ``source["levelling_mismatch"]`` says why it was not taken)."""
    if record is None:
        return {"source": source}
    problem = _mismatch(cameras, record)
    if problem is not None:
        return {"source": {**source, "levelling_mismatch": f"the file records a levelled frame, but {problem} "
                                                          "(re-solved by another tool?)"}}
    return {"source": source, "levelled": dict(record)}
