"""The versioned JSON rig file: load, validate, save (atomically).

The format is specified in docs/rig-file.md; docs/examples/rig.json is a complete
example. In short::

    {
      "format": "ghnerf-rig",
      "version": 1,
      "rig_id": "bench-01",
      "units": "m",
      "cameras": [
        {"name": "left", "width": 1280, "height": 800,
         "K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]],
         "distortion": {"model": "opencv", "coefficients": [k1, k2, p1, p2, k3]},
         "R": [[...], [...], [...]],   # rig -> camera rotation
         "t": [tx, ty, tz]},           # rig -> camera translation, metres
        ...
      ],
      "working_volume": {"min": [x, y, z], "max": [x, y, z]},
      "metadata": {...}                 # optional, free-form JSON object
    }

Every error is a :class:`~ghnerf_runtime.errors.RigFileError` that names the file,
the field path (``cameras[1].K``) and the offending value. Unknown keys are errors.
This is the only module of ``ghnerf_runtime`` that touches the file system.
"""
from __future__ import annotations

import json
import logging
import math
import os
import uuid
from collections.abc import Collection
from pathlib import Path
from typing import Any

import numpy as np

from ghnerf_runtime.bound_text import past_bound
from ghnerf_runtime.contract import MAX_DEPTH_M, MAX_NEAR_FAR_MARGIN_M, box_reach
from ghnerf_runtime.errors import GeometryError, RigFileError
from ghnerf_runtime.geometry.camera import (DISTORTION_NAMES, Camera, fold_terms_text, folded_by_tangential,
                                            nearest_rotation)
from ghnerf_runtime.geometry.rig import Rig, WorkingVolume
from ghnerf_runtime.json_keys import JsonTextError, loads_remembering, nested_deeper_than, remember_repeats
from ghnerf_runtime.path_check import is_utf8

log = logging.getLogger(__name__)

FORMAT = "ghnerf-rig"
VERSION = 1
UNITS = "m"
DISTORTION_MODELS = ("opencv",)
DISTORTION_LENGTHS = (0, 4, 5, 8, 12, 14)
#: Tolerance on ``|R R^T - I|`` and ``det R - 1`` for a rotation to be accepted; it is then snapped to
#: the nearest rotation. A file that prints six decimals is off by up to about 1e-6 (0.0001 degree).
ROTATION_TOLERANCE = 1e-4
#: How far the principal point may lie from the image centre, as a fraction of the image's width (x)
#: and height (y). Real lenses sit within a few per cent of it (lens-to-sensor mounting tolerance); a
#: calibration made at another image size and read with this one is off by a sixth of the image
#: (1280x720 read as 1920x1080) or a quarter (the other way), which the old "inside the image" test
#: let through. 10 % leaves margin on both sides.
PRINCIPAL_POINT_TOLERANCE = 0.1
#: Focal lengths (fx, fy) as a multiple of the image's longer side, outside which no lens on a body-capture rig
#: lies: 0.01 is a 179-degree view through the pinhole part (fisheyes are modelled by their distortion), 100 a
#: 0.6-degree one. Past them a file holds a typo or another unit (1e308 loaded and gave NaN pixels).
FOCAL_RANGE = (0.01, 100.0)
#: Largest skew ``|K[0][1]|`` as a share of ``fx``. The skew is ``-fx cot(theta)``, theta the angle between the
#: sensor's pixel axes, which lithography makes square: OpenCV (so ``ghcal``) has no skew term, and the tools that
#: have one (MATLAB's ``EstimateSkew``, Bouguet's ``alpha_c``) fit it only when asked. 0.1 is pixel axes 5.7
#: degrees off square, far past any sensor; the solvers' ``block_volume`` (``fx / hypot(fx, s)``)
#: is still 0.995 there. Past it a file holds a typo: a skew of 1e14 fx loaded, and every pair was refused by the
#: triangulation (``block_volume`` below ``MIN_BLOCK_VOLUME``), naming the camera but not the file.
MAX_SKEW_SHARE = 0.1
#: Largest magnitude of a distortion coefficient. A lens's are small numbers (the example rig's below 0.05; a wide
#: lens's rational model, numerator and denominator nearly cancelling, runs larger, which this leaves room for).
#: Past it a file holds a typo or a fit that diverged: k1 = 1e308 loaded (the lens fold check only warned), and
#: the projection overflowed to inf/NaN pixels.
MAX_DISTORTION = 1e3
#: Largest rig file read, bytes: the example rig (docs/examples/rig.json) is 1.5 KB, so this holds hundreds of cameras
#: with their metadata; anything larger (a log, an image, /dev/zero named by mistake) is refused before it is read.
MAX_RIG_FILE_BYTES = 1 << 20
#: Deepest nesting of objects and lists in ``metadata`` (the object itself is level 1): free-form notes are shallow;
#: between about 500 and 1000 the JSON parser took the file and the copy of the metadata (recursive) failed with a
#: bare RecursionError naming no file (a file is now refused past ``json_keys.MAX_JSON_DEPTH``), and a deeper dict given
#: to :func:`rig_from_dict` failed so in ``json.dumps``.
MAX_METADATA_DEPTH = 100
#: Largest image width or height: the runtime's remap tables (OpenCV's fixed-point maps) address
#: pixels with 16-bit integers. It also keeps absurd sizes (10**400) from overflowing the float checks.
MAX_IMAGE_SIDE = 32767
#: Farthest 2D joint coordinate, pixels, the joint stream carries: JOINTS_2D sends u and v as 16-bit quarter pixels
#: (docs/protocol.md; ``firmware_host.protocol.quantize``), 32767 / 4; one past it goes out as missing. Loading warns
#: of a pair camera whose image reaches past it (wider or taller than 8192 pixels).
WIRE_2D_MAX_PX = 32767 / 4
#: Smallest angle (degrees) between the pair's lines of sight to the working volume's centre before loading warns that
#: the pair is too narrow for its distance (baseline over distance, in radians, for a pair facing the volume). Twice the
#: default ``joints3d.min_ray_angle_deg`` (0.5), which drops a joint whose rays meet at less: the angle shrinks further
#: towards the volume's far side. Measured on the simulated scene at 3 m (``benchmarks/measure_baseline.py``,
#: docs/rig-file.md): 1.9 degrees (a 10 cm pair, the narrowest the model learnt) gave 67 mm MPJPE, 1.14 (6 cm) 82 mm,
#: 0.57 (3 cm) a quarter of the pairs with no joint and 0.38 (2 cm) nearly every joint missing, all loading without a
#: word. An angle, not a depth per pixel: the runtime's 2D errors scale with the person's crop, not the sensor's
#: pixels. Session 66 measured it with 50, 80 and 110-degree lenses at 3 and 5 m (``--angles --distances --hfovs``),
#: the depth per pixel of disparity at 1 degree spanning 0.25-1.28 m: at 0.5 degree half to two thirds of the pairs
#: had no joint in every one, at 0.75 and over at most 1.7 %; 3 m through a 50-degree lens at 0.5 degree (0.50 m per
#: pixel) lost two thirds of its pairs where 5 m through a 110-degree one at 2 degrees (0.64 m per pixel) lost none.
#: The example rig's is 1.56.
MIN_PAIR_ANGLE_DEG = 1.0
#: Heights above the floor (the rig frame's ``-y``, metres) a camera may stand at without a warning: a camera on the
#: floor to a hall's ceiling (rooms' ceilings are about 3 m), the range ``ghcal solve``'s floor view and ``ghcal
#: solve/import --camera-height`` accept, so a rig they level is not warned about. The runtime reads the floor at
#: y = 0: the skeleton prior's inputs keep each joint's height above it, and a rig whose origin was moved 50 m up
#: loaded and gave every joint missing (docs/rig-file.md, "Baseline and camera height").
CAMERA_HEIGHT_RANGE_M = (0.05, 10.0)
#: Farthest the working volume's y range may lie from the floor (y = 0) before loading warns that a person standing
#: on it is outside the volume: the default ``joints3d.max_outside_box_m``, past which a joint outside the volume is
#: missing. The rig frame moved 1 m up (cameras 2.3 m high: no height warning) gave 142 mm MPJPE against 30 mm, 3 m up
#: 507 mm (``benchmarks/measure_baseline.py``): the skeleton prior reads each joint's height above y = 0.
MAX_VOLUME_FLOOR_GAP_M = 0.5
#: Height (metres) of the standing person whose view :func:`person_in_view_share` judges: a tall adult (the simulator's
#: people are 1.6-2.0 m), standing on the floor (y = 0) at the working volume's centre (:func:`standing_person`).
STANDING_PERSON_M = 1.8
#: Smallest share of :data:`STANDING_PERSON_M`'s height, standing at the working volume's centre, that each camera of
#: the pair must show before loading warns that the person does not fit the view (their head or feet cut). Measured
#: with the simulator's rig through a 50-degree lens, the pair 4 degrees apart (``benchmarks/measure_baseline.py``,
#: docs/rig-file.md "A person who does not fit the view"): 0.62 of the height in view (the subject 1.5 m ahead) lost
#: 67 % of the pairs (no joint at all), 0.78 (2 m) 38 %, 0.97 (2.5 m) 5 %, the whole height (3 m) none; through
#: 80-130-degree lenses the whole height was in view from 1.5 m on. Not higher: ``ghcal synth``'s rig until session 68
#: (calibration.render.example_rig) shows 0.84 (its head cut), and a shipped rig is not warned of (its rig since,
#: ``synth_rig``, the whole height); the bench's simulated placements (2000 of ``RigPlacement.random``) show 0.97 at
#: least, the example rig and the simulator's default the whole height.
MIN_PERSON_IN_VIEW_SHARE = 0.75
#: Share of that height under which loading notes (INFO, not a warning) a rig the warning spares: the 0.75-0.97 band
#: still costs pairs (through the 50-degree lens 0.78 in view lost 38 % of them, 0.97 5 %), and ``ghcal synth``'s rig
#: until session 68, aimed down at the floor for its floor view, shows 0.84 (heads cut nearer than 8 m: on 12 of the
#: bench's people it gave 99 mm MPJPE, pitched 17 degrees instead 50 mm; session 67, docs/rig-file.md). A note, not a
#: warning: that shipped rig must load without one, and the cost depends on where people stand. 36 of the 37 points
#: (0.973) are spared: the bench's placements show 0.97 at least.
PERSON_IN_VIEW_NOTE_SHARE = 0.97
#: Spacing (metres) of the points along the standing person's height that :func:`person_in_view_share` projects,
#: and so their number (37 for 1.8 m): the share's step.
_PERSON_STEP_M = 0.05
_PERSON_SAMPLES = round(STANDING_PERSON_M / _PERSON_STEP_M) + 1
#: Step (metres) of the depths :func:`volume_edge_notes` tries for the nearest (farthest) one at which both pair
#: cameras show the standing person whole: the depth it gives is one to type into the rig file's ``working_volume``.
EDGE_FIT_STEP_M = 0.1
# where the edge notes send the reader (the doc's section checked by tests/test_docs_sections.py)
_EDGES_DOC = "(docs/rig-file.md, \"A person at the volume's edges\")"

_TOP_REQUIRED = ("format", "version", "rig_id", "units", "cameras", "working_volume")
_TOP_OPTIONAL = ("metadata",)
_CAMERA_KEYS = ("name", "width", "height", "K", "distortion", "R", "t")
_DISTORTION_KEYS = ("model", "coefficients")
_VOLUME_KEYS = ("min", "max")

__all__ = [
    "FORMAT",
    "VERSION",
    "load_rig",
    "save_rig",
    "checked_rig_text",
    "rig_to_dict",
    "rig_from_dict",
    "dumps_rig",
    "loads_rig",
    "write_text_atomic",
    "write_bytes_atomic",
    "utf8_bytes",
    "write_bytes_into",
    "principal_point_problem",
    "focal_length_problem",
    "skew_problem",
    "distortion_problem",
    "volume_reach_problem",
    "volume_reach_problem_from",
    "lens_fold_warning",
    "rig_warnings",
    "log_warnings_and_notes",
    "pair_angle_deg",
    "narrow_pair_warning",
    "camera_height_warning",
    "MIN_PAIR_ANGLE_DEG",
    "CAMERA_HEIGHT_RANGE_M",
    "volume_floor_warning",
    "MAX_VOLUME_FLOOR_GAP_M",
    "standing_person",
    "standing_person_px",
    "person_in_view_share",
    "person_outside_view_warning",
    "STANDING_PERSON_M",
    "MIN_PERSON_IN_VIEW_SHARE",
    "PERSON_IN_VIEW_NOTE_SHARE",
    "person_partly_in_view_note",
    "volume_edge_notes",
    "EDGE_FIT_STEP_M",
    "rig_notes",
    "rig_warnings_and_notes",
    "PRINCIPAL_POINT_TOLERANCE",
    "MAX_DISTORTION",
    "MAX_SKEW_SHARE",
    "MAX_RIG_FILE_BYTES",
    "MAX_METADATA_DEPTH",
    "WIRE_2D_MAX_PX",
    "wire_2d_range_warning",
]


# --------------------------------------------------------------------------- helpers
def _show(value: Any, limit: int = 120) -> str:
    """Short printable form of a (JSON) value for error messages."""
    try:
        text = json.dumps(value, allow_nan=True, default=repr)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


class _Checker:
    """Validation with the file name bound, so every error names file + field."""

    def __init__(self, path: str | None):
        self.path = path

    def fail(self, field: str | None, message: str) -> RigFileError:
        return RigFileError(message, path=self.path, field=field)

    def mapping(self, value: Any, field: str, required: tuple, optional: tuple = ()) -> dict:
        label = field or "the document"
        if not isinstance(value, dict):
            return self._raise(field, f"{label} must be a JSON object, got {type(value).__name__} {_show(value)}")
        for key in getattr(value, "duplicates", ()):
            self._raise(_join(field, key), f"duplicate key {key!r}")
        allowed = required + optional
        for key in value:
            if key not in allowed:
                self._raise(_join(field, key), f"unknown key {key!r} in {label} (allowed: {', '.join(allowed)})")
        for key in required:
            if key not in value:
                self._raise(_join(field, key), f"missing required key {key!r} in {label}")
        return value

    def _raise(self, field, message):
        raise self.fail(field, message)

    def string(self, value: Any, field: str) -> str:
        if not isinstance(value, str) or not value:
            self._raise(field, f"must be a non-empty string, got {_show(value)}")
        if not is_utf8(value):  # a lone surrogate escape ("\ud800"): the file could not be saved again
            self._raise(field, f"must be UTF-8 text (no lone surrogate escapes), got {_show(value)}")
        return value

    def positive_int(self, value: Any, field: str, limit: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
            self._raise(field, f"must be a positive integer, got {_show(value)}")
        if limit is not None and value > limit:
            self._raise(field, f"must be at most {limit}, got {_show(value)}")
        return value

    def array(self, value: Any, field: str, shape: tuple | None = None, what: str = "", label: str = "") -> np.ndarray:
        """A nested list of finite numbers of the given shape (``None`` entries mean any length); ``label``
        ("camera 'left': ") starts the message of a non-finite number."""
        expect = what or ("x".join("N" if s is None else str(s) for s in shape) + " array of numbers" if shape else "list of numbers")
        found = _shape_of(value)
        if found is None:
            self._raise(field, f"must be a {expect}, got {_show(value)}")
        if shape is not None and (len(found) != len(shape) or any(s is not None and s != f for s, f in zip(shape, found))):
            self._raise(field, f"must be a {expect}, got shape {'x'.join(map(str, found)) or 'scalar'}: {_show(value)}")
        try:
            arr = np.asarray(value, dtype=np.float64)
        except OverflowError:  # an integer beyond any float, e.g. 10**400
            arr = np.array(np.inf)
        if not np.all(np.isfinite(arr)):
            self._raise(field, f"{label}must contain only finite numbers, got {_show(value)}")
        return arr


_RESIZE_ADVICE = ("a calibration of another image size? Give the size it was calibrated at, then resize the camera "
                  "to the images' size with Camera.resized(width, height)")


def principal_point_problem(K: Any, width: int, height: int, *, advice: str = _RESIZE_ADVICE) -> str | None:
    """Why ``K``'s principal point does not belong to a ``width`` x ``height`` image (ending in ``advice``);
    None when it does. The centre is ``((w - 1) / 2, (h - 1) / 2)`` (pixel centres, as :meth:`Camera.resized`).
    """
    K = np.asarray(K, dtype=np.float64)
    cx, cy = float(K[0, 2]), float(K[1, 2])
    off_x, off_y = abs(cx - (width - 1) / 2) / width, abs(cy - (height - 1) / 2) / height
    if off_x <= PRINCIPAL_POINT_TOLERANCE and off_y <= PRINCIPAL_POINT_TOLERANCE:
        return None
    tol = PRINCIPAL_POINT_TOLERANCE
    return (f"its principal point ({cx:g}, {cy:g}) lies {past_bound(off_x, tol, 0, '%')} of the width and "
            f"{past_bound(off_y, tol, 0, '%')} of the height "
            f"from the centre of the {width}x{height} image (a real lens: within {PRINCIPAL_POINT_TOLERANCE:.0%}): "
            + advice)


def focal_length_problem(K: Any, width: int, height: int, *,
                         advice: str = "a typo, or a focal length in other units?") -> str | None:
    """Why ``K``'s focal lengths are not a lens's for a ``width`` x ``height`` image (``FOCAL_RANGE``; ending in
    ``advice``); None when they are."""
    K = np.asarray(K, dtype=np.float64)
    side = float(max(width, height))
    low, high = FOCAL_RANGE[0] * side, FOCAL_RANGE[1] * side
    for name, f in (("fx", float(K[0, 0])), ("fy", float(K[1, 1]))):
        if not low <= f <= high:
            fov = math.degrees(2.0 * math.atan(side / (2.0 * f))) if f > 0 else float("nan")
            return (f"its focal length {name} = {past_bound(f, low if f < low else high, 6)} px is outside "
                    f"{low:g}-{high:g} px ({FOCAL_RANGE[0]:g}-{FOCAL_RANGE[1]:g} times the {width}x{height} image's "
                    f"longer side; a {fov:.3g}-degree view): " + advice)
    return None


def skew_problem(K: Any) -> str | None:
    """Why ``K``'s skew ``K[0][1]`` is not a sensor's (beyond ``MAX_SKEW_SHARE`` of ``fx`` in magnitude); None when
    it is."""
    K = np.asarray(K, dtype=np.float64)
    fx, skew = float(K[0, 0]), float(K[0, 1])
    if abs(skew) <= MAX_SKEW_SHARE * fx:
        return None
    off_square = 90.0 - math.degrees(math.atan2(fx, abs(skew)))  # how far the pixel axes are from square
    return (f"its skew K[0][1] = {skew:g} px is {past_bound(abs(skew) / fx, MAX_SKEW_SHARE, 3)} times fx = {fx:g} px "
            f"(pixel axes {off_square:.3g} degrees off square; a sensor's: at most {MAX_SKEW_SHARE:g} times fx, 0 from "
            "OpenCV): a typo, or a matrix in another layout?")


def distortion_problem(dist: Any, *, advice: str = "a typo, or a calibration that diverged?") -> str | None:
    """Why OpenCV coefficients ``dist`` are not a real lens's (one beyond ``MAX_DISTORTION`` in magnitude, or not
    finite), naming the first such coefficient and ending in ``advice``; None when they are."""
    d = np.asarray(dist, dtype=np.float64).reshape(-1)
    for name, value in zip(DISTORTION_NAMES, d.tolist()):
        if not abs(value) <= MAX_DISTORTION:  # NaN too
            return (f"its distortion coefficient {name} = {value!r} is beyond any lens's (|coefficient| at most "
                    f"{MAX_DISTORTION:g}): " + advice)
    return None


def _join(parent: str, key: str) -> str:
    return f"{parent}.{key}" if parent else key


def _shape_of(value: Any) -> tuple | None:
    """Shape of a rectangular nested list of numbers, or None if it is not one."""
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return ()
    if not isinstance(value, list):
        return None
    if not value:
        return (0,)
    shapes = {_shape_of(v) for v in value}
    if len(shapes) != 1 or None in shapes:
        return None
    return (len(value),) + shapes.pop()


# --------------------------------------------------------------------------- dict <-> Rig
def rig_from_dict(data: Any, *, path: str | os.PathLike | None = None, warn: bool = True) -> Rig:
    """Validate a parsed rig document and build the :class:`Rig`.

    Args:
        data: the parsed JSON document (a dict).
        path: the file it came from, used only in messages.
        warn: log :func:`rig_warnings` (and :func:`rig_notes`, at INFO); ``False`` where the caller logs them (a rig
            source, once per daemon run) or reads its own text back (:func:`save_rig`).

    Returns:
        The rig; cameras keep the file's order (the first two are the stereo pair).

    Raises:
        RigFileError: naming ``path`` and the field path (e.g. ``cameras[1].K``) and
            showing the bad value: missing, unknown or duplicate keys, wrong types or
            shapes, non-finite numbers, an unsupported format/version/units/distortion
            model, a K that is not a pinhole matrix, an R that is not a rotation, a
            working volume with ``max <= min`` or reaching farther from a camera than the model's
            near/far resolve (:func:`volume_reach_problem`), duplicate camera names.
    """
    chk = _Checker(None if path is None else str(path))
    if not isinstance(data, dict):
        chk._raise(None, f"the document must be a JSON object, got {type(data).__name__} {_show(data)}")
    for key in ("format", "version"):
        if key not in data:
            chk._raise(key, f"missing required key {key!r} in the document")
    fmt = data["format"]
    if fmt != FORMAT:
        chk._raise("format", f"must be {FORMAT!r} (this is not a ghnerf rig file?), got {_show(fmt)}")
    version = data["version"]
    if isinstance(version, bool) or not isinstance(version, int):
        chk._raise("version", f"must be an integer, got {_show(version)}")
    if version != VERSION:
        chk._raise("version", f"unsupported version {version}: this build reads version {VERSION} only")
    chk.mapping(data, "", _TOP_REQUIRED, _TOP_OPTIONAL)

    rig_id = chk.string(data["rig_id"], "rig_id")
    if data["units"] != UNITS:
        chk._raise("units", f"must be {UNITS!r} (metres), got {_show(data['units'])}")

    cams_raw = data["cameras"]
    if not isinstance(cams_raw, list):
        chk._raise("cameras", f"must be a list of camera objects, got {_show(cams_raw)}")
    if len(cams_raw) < 2:
        chk._raise("cameras", f"a rig needs at least two cameras, got {len(cams_raw)}")
    cameras = []
    seen: dict[str, int] = {}
    for i, raw in enumerate(cams_raw):
        cam = _camera_from_dict(chk, raw, f"cameras[{i}]")
        if cam.name in seen:
            chk._raise(f"cameras[{i}].name", f"duplicate camera name {cam.name!r} (also cameras[{seen[cam.name]}])")
        seen[cam.name] = i
        cameras.append(cam)

    vol = chk.mapping(data["working_volume"], "working_volume", _VOLUME_KEYS)
    lo = chk.array(vol["min"], "working_volume.min", (3,), "3-vector of numbers")
    hi = chk.array(vol["max"], "working_volume.max", (3,), "3-vector of numbers")
    if np.any(hi <= lo):
        chk._raise("working_volume", f"max {hi.tolist()} must exceed min {lo.tolist()} on every axis")
    with np.errstate(over="ignore"):
        span = np.concatenate([hi - lo, hi + lo])  # the size and (twice) the centre
    if not np.all(np.isfinite(span)):  # +-1e308: loaded, and its size or centre was inf
        chk._raise("working_volume", f"from {lo.tolist()} to {hi.tolist()} is too large (its size overflows)")
    metadata = data.get("metadata", {})
    if not isinstance(metadata, dict):
        chk._raise("metadata", f"must be a JSON object, got {_show(metadata)}")
    if nested_deeper_than(metadata, MAX_METADATA_DEPTH):  # before anything below walks it recursively
        chk._raise("metadata", f"is nested more than {MAX_METADATA_DEPTH} levels deep (objects and lists; "
                               "MAX_METADATA_DEPTH): free-form notes, not data")
    try:  # what save_rig could not write back (it refuses NaN; a lone surrogate cannot be UTF-8)
        metadata_text = json.dumps(metadata, allow_nan=False, ensure_ascii=False)
    except ValueError:
        chk._raise("metadata", f"must contain only finite numbers, got {_show(metadata)}")
    if not is_utf8(metadata_text):
        chk._raise("metadata", f"must be UTF-8 text (no lone surrogate escapes), got {_show(metadata)}")
    try:
        rig = Rig(tuple(cameras), WorkingVolume(lo, hi), rig_id=rig_id, metadata=_plain(metadata))
    except GeometryError as e:  # pragma: no cover - every case is checked above
        raise chk.fail(None, str(e)) from e
    problem = rig.baseline_problem()
    if problem:
        chk._raise("cameras[1].t", problem)
    if far := rig.far_camera_problem():
        chk._raise(f"cameras[{far[0]}].t", far[1])
    if too_far := volume_reach_problem(rig):
        chk._raise("working_volume", too_far)
    if warn:
        log_warnings_and_notes(rig, path)
    return rig


def log_warnings_and_notes(rig: Rig, path: str | os.PathLike | None, *, leave_out: Collection[str] = ()) -> None:
    """Log what loading warns of (WARNING) and notes (INFO), each message led by the file's name: as the rig loads,
    and where a tool writes it (``ghcal solve``, ``import``, ``synth``), in the same words. Those in ``leave_out``
    are not logged: the tool said them in its own words already."""
    warnings, notes = rig_warnings_and_notes(rig)
    where = f"{path}: " if path else ""
    for message in warnings:
        if message not in leave_out:
            log.warning("%s%s", where, message)
    for message in notes:
        if message not in leave_out:
            log.info("%s%s", where, message)


def rig_warnings(rig: Rig) -> list[str]:
    """What loading warns of in a rig it accepts: a lens model folding inside its image, a pair too narrow for its
    working distance, a camera at an implausible height above the floor, a working volume off the floor, a person
    standing at the volume's centre who does not fit the pair's views, a pair camera whose 2D joints the joint stream
    cannot carry in part."""
    return rig_warnings_and_notes(rig)[0]


def rig_notes(rig: Rig) -> list[str]:
    """What loading notes (logs at INFO) of a rig it does not warn of: a person standing at the volume's centre
    partly out of the pair's views, under :data:`PERSON_IN_VIEW_NOTE_SHARE` of their height, and one at the volume's
    near or far edge cut by a pair camera (:func:`volume_edge_notes`); not where :func:`rig_warnings` speaks of the
    volume or the framing already."""
    return rig_warnings_and_notes(rig)[1]


def rig_warnings_and_notes(rig: Rig) -> tuple[list[str], list[str]]:
    """:func:`rig_warnings` and :func:`rig_notes` together, each check run once: the notes hang on the warnings
    (none where the volume or the framing is warned of), and loading called both, so it ran the volume's check twice
    and projected the standing person three times."""
    warnings = [lens_fold_warning(cam) for cam in rig.cameras if cam.fold_inside_image()]
    if narrow := narrow_pair_warning(rig):
        warnings.append(narrow)
    warnings.extend(filter(None, (camera_height_warning(cam) for cam in rig.cameras)))
    notes: list[str] = []
    if floor := volume_floor_warning(rig):
        warnings.append(floor)  # (a volume off the floor holds no one standing: the framing is not judged)
    else:
        outside, partly = _framing_warning_and_note(rig)
        if outside:
            warnings.append(outside)  # (its advice, to move or aim the cameras, holds for the edges too)
        else:
            notes.extend(filter(None, [partly, *volume_edge_notes(rig)]))
    warnings.extend(filter(None, (wire_2d_range_warning(cam) for cam in rig.pair)))
    return warnings, notes


def pair_angle_deg(rig: Rig, point: np.ndarray) -> float:
    """The angle (degrees) between the lines from ``point`` to the pair's two camera centres: the angle at which
    the pair's rays to ``point`` meet. NaN where ``point`` is a camera's centre (no line of sight from it): a
    working volume centred on a camera divided by zero and failed the load with ZeroDivisionError."""
    a, b = (cam.center - np.asarray(point, float) for cam in rig.pair)
    lengths = float(np.linalg.norm(a)) * float(np.linalg.norm(b))
    if lengths == 0.0:
        return math.nan
    return math.degrees(math.acos(min(1.0, max(-1.0, float(a @ b) / lengths))))


def narrow_pair_warning(rig: Rig) -> str | None:
    """Why the pair is too narrow for where it looks (its lines of sight to the working volume's centre under
    :data:`MIN_PAIR_ANGLE_DEG` apart), or None."""
    a, b = rig.pair
    centre = rig.volume.center
    angle = pair_angle_deg(rig, centre)
    if not angle < MIN_PAIR_ANGLE_DEG:  # (NaN: the centre on a camera has no angle to judge)
        return None
    distance = float(np.linalg.norm(centre - 0.5 * (a.center + b.center)))
    return (f"cameras {a.name!r} and {b.name!r} are {rig.baseline * 1e3:.0f} mm apart and {distance:.2f} m from the "
            f"working volume's centre: their rays meet there at {past_bound(angle, MIN_PAIR_ANGLE_DEG, 2, 'f')} "
            f"degrees (under {MIN_PAIR_ANGLE_DEG:g}, "
            "MIN_PAIR_ANGLE_DEG), so the 3D joints will be far off in depth, or missing where their rays meet under "
            "joints3d.min_ray_angle_deg (docs/rig-file.md, \"Baseline and camera height\"). Mount the cameras "
            "farther apart")


def volume_floor_warning(rig: Rig) -> str | None:
    """Why a person standing on the floor (y = 0) would be outside ``rig``'s working volume (its y range more than
    :data:`MAX_VOLUME_FLOOR_GAP_M` from the floor), or None."""
    top, bottom = float(rig.volume.min_corner[1]), float(rig.volume.max_corner[1])  # y down: min is the top
    gap = -bottom if bottom < 0.0 else top
    if gap <= MAX_VOLUME_FLOOR_GAP_M:
        return None
    where = "above" if bottom < 0.0 else "below"
    shown = past_bound(gap, MAX_VOLUME_FLOOR_GAP_M, 2, "f")  # never "0.50 m" for 0.5001 m
    return (f"working volume: y from {top:g} to {bottom:g} lies {shown} m {where} the floor (y = 0, y down; over "
            f"{MAX_VOLUME_FLOOR_GAP_M:g} m, MAX_VOLUME_FLOOR_GAP_M): a person standing on the floor is outside it, "
            "their joints missing, and the skeleton prior reads heights from y = 0. Is the origin on the floor, y "
            "pointing down? A standing person's volume reaches y = 0 (docs/examples/rig.json: -2.2 to 0.05)")


def standing_person(volume: WorkingVolume, samples: int = _PERSON_SAMPLES) -> np.ndarray:
    """``(samples, 3)`` points from the feet to the head of a :data:`STANDING_PERSON_M` person standing at ``volume``'s
    centre's x and z on the floor (y = 0, y down), or on the volume's nearest y to it where the volume does not reach
    the floor (then within :data:`MAX_VOLUME_FLOOR_GAP_M` of it, or :func:`volume_floor_warning` speaks)."""
    centre = volume.center
    feet = min(max(0.0, float(volume.min_corner[1])), float(volume.max_corner[1]))
    heights = np.linspace(0.0, STANDING_PERSON_M, samples)
    return np.stack([np.full(samples, centre[0]), feet - heights, np.full(samples, centre[2])], axis=-1)


def standing_person_px(cam: Camera, volume: WorkingVolume) -> float:
    """How tall (image pixels, pinhole) ``cam`` shows the person of :func:`standing_person` standing at ``volume``'s
    centre: what the cold tiles' bound and the framing benchmarks read."""
    feet_head = cam.project(standing_person(volume, samples=2), distort=False)[0]
    return float(np.linalg.norm(feet_head[1] - feet_head[0]))


def person_in_view_share(cam: Camera, volume: WorkingVolume) -> float:
    """The share of the height of a person standing at ``volume``'s centre (:func:`standing_person`) that lies inside
    ``cam``'s image, lens model included (a point behind the camera or past the lens's fold counts as outside)."""
    return float(_inside_image(cam, standing_person(volume)).mean())


def _inside_image(cam: Camera, points: np.ndarray) -> np.ndarray:
    """Which of ``points`` (rig frame, ``(N, 3)``) lie inside ``cam``'s image, lens model included (behind the camera
    or past the lens's fold: outside)."""
    uv, _ = cam.project(points)
    # the image's edges: pixel centres at whole numbers, so from -0.5 to the side less 0.5
    with np.errstate(invalid="ignore"):  # NaN pixels: outside
        return ((uv[:, 0] >= -0.5) & (uv[:, 0] <= cam.width - 0.5)
                & (uv[:, 1] >= -0.5) & (uv[:, 1] <= cam.height - 0.5))


def person_outside_view_warning(rig: Rig) -> str | None:
    """Why a person standing at the working volume's centre does not fit the pair's views (under
    :data:`MIN_PERSON_IN_VIEW_SHARE` of their height inside a camera's image), naming each such camera, or None."""
    return _outside_view_words(rig, _pair_shares(rig))


def person_partly_in_view_note(rig: Rig) -> str | None:
    """What a person standing at the working volume's centre costs where a camera of the pair shows under
    :data:`PERSON_IN_VIEW_NOTE_SHARE` of their height (and, in :func:`rig_notes`, not under the warned
    :data:`MIN_PERSON_IN_VIEW_SHARE`), naming each such camera, or None."""
    return _partly_in_view_words(rig, _pair_shares(rig))


def _framing_warning_and_note(rig: Rig) -> tuple[str | None, str | None]:
    """:func:`person_outside_view_warning` and, where it is None, :func:`person_partly_in_view_note`: the person
    projected once for both."""
    shares = _pair_shares(rig)
    warning = _outside_view_words(rig, shares)
    return warning, None if warning else _partly_in_view_words(rig, shares)


def _outside_view_words(rig: Rig, shares: list[tuple[str, float]]) -> str | None:
    """:func:`person_outside_view_warning`'s words, from the pair's :func:`_pair_shares`."""
    cut = _cameras_showing_under(shares, MIN_PERSON_IN_VIEW_SHARE)
    if not cut:
        return None
    return (f"{_person_at_centre(rig)} does not fit the view: {'; '.join(cut)} (under {MIN_PERSON_IN_VIEW_SHARE:.0%}, "
            "MIN_PERSON_IN_VIEW_SHARE), so their cut joints are missing and whole pairs may have none "
            "(docs/rig-file.md, \"A person who does not fit the view\"). Move the cameras farther from the volume, "
            "fit wider lenses or aim the cameras at the volume's centre")


def _partly_in_view_words(rig: Rig, shares: list[tuple[str, float]]) -> str | None:
    """:func:`person_partly_in_view_note`'s words, from the pair's :func:`_pair_shares`."""
    cut = _cameras_showing_under(shares, PERSON_IN_VIEW_NOTE_SHARE)
    if not cut:
        return None
    return (f"{_person_at_centre(rig)} is partly out of view: {'; '.join(cut)} (under {PERSON_IN_VIEW_NOTE_SHARE:.0%}, "
            "PERSON_IN_VIEW_NOTE_SHARE). Their cut joints are missing, and pairs may have none: on the simulated scene "
            "through a 50-degree lens 78% of the height in view lost 38% of the pairs, 97% lost 5% "
            "(docs/rig-file.md, \"A person who does not fit the view\"). If people stand there, aim the cameras at "
            "the volume's centre or move them farther from it")


def _person_at_centre(rig: Rig) -> str:
    """The person the framing warning and note speak of, and where they stand (the working volume's centre)."""
    centre = rig.volume.center
    return (f"a {STANDING_PERSON_M:g} m person standing at the working volume's centre (x {centre[0]:.2f}, z "
            f"{centre[2]:.2f} m)")


def _pair_shares(rig: Rig) -> list[tuple[str, float]]:
    """Each pair camera's name and the share of the height of the person standing at the working volume's centre
    it shows (:func:`person_in_view_share`)."""
    return [(cam.name, person_in_view_share(cam, rig.volume)) for cam in rig.pair]


def _cameras_showing_under(shares: list[tuple[str, float]], share_bound: float) -> list[str]:
    """``camera 'name' shows N% of their height`` for each of :func:`_pair_shares` under ``share_bound``."""
    return [f"camera {name!r} shows {share:.0%} of their height" for name, share in shares if share < share_bound]


def volume_edge_notes(rig: Rig) -> list[str]:
    """What loading notes of a person standing at the working volume's near and at its far edge (its centre's x, on the
    floor) whom a pair camera shows under :data:`MIN_PERSON_IN_VIEW_SHARE` of their height: the centre's check passed
    a volume that starts nearer than the lenses frame anyone (``ghcal solve``'s default 0.5 m; session 69). Each note
    names the cameras, what they cut and the nearest (farthest) depth at which both show the person whole."""
    edges = tuple(zip(("near", "far"), _depth_range(rig.volume)))
    people = _people_at(rig.volume, np.array([depth for _, depth in edges]))  # both edges in one projection a camera
    shown = [(cam.name, _inside_per_person(cam, people)) for cam in rig.pair]
    notes: list[str] = []
    grid = None  # the depths both cameras show the person whole at: searched once, and only for a cut edge
    for k, (edge, depth) in enumerate(edges):
        cut = [_cut_words(name, inside[k]) for name, inside in shown if inside[k].mean() < MIN_PERSON_IN_VIEW_SHARE]
        if cut:
            grid = grid if grid is not None else _whole_grid(rig)
            notes.append(f"a {STANDING_PERSON_M:g} m person standing at the working volume's {edge} edge (x "
                         f"{rig.volume.center[0]:.2f}, z {depth:.2f} m) is cut: {'; '.join(cut)} (under "
                         f"{MIN_PERSON_IN_VIEW_SHARE:.0%}, MIN_PERSON_IN_VIEW_SHARE). {_edge_advice(rig, edge, *grid)}")
    return notes


def _people_at(volume: WorkingVolume, depths: np.ndarray) -> np.ndarray:
    """:func:`standing_person` standing at each of ``depths`` (z) in turn, ``(len(depths) * samples, 3)``."""
    people = np.repeat(standing_person(volume)[None], len(depths), axis=0)
    people[..., 2] = depths[:, None]
    return people.reshape(-1, 3)


def _depth_range(volume: WorkingVolume) -> tuple[float, float]:
    """The working volume's near and far edges along ``z`` (rig frame, metres)."""
    return float(volume.min_corner[2]), float(volume.max_corner[2])


def _inside_per_person(cam: Camera, people: np.ndarray) -> np.ndarray:
    """:func:`_inside_image` of :func:`_people_at`'s ``people``, one row per person (feet to head)."""
    return _inside_image(cam, people).reshape(-1, _PERSON_SAMPLES)


def _cut_words(name: str, inside: np.ndarray) -> str:
    """``camera 'name' shows N% of their height, their head out of view`` from ``inside``, feet to head."""
    ends = [part for part, seen in (("head", inside[-1]), ("feet", inside[0])) if not seen]
    cut = f"their {' and '.join(ends)}" if ends else "part of their body"
    return f"camera {name!r} shows {float(inside.mean()):.0%} of their height, {cut} out of view"


def _whole_grid(rig: Rig) -> tuple[np.ndarray, np.ndarray]:
    """The depths on :data:`EDGE_FIT_STEP_M`'s grid within the working volume, nearest first, and whether both pair
    cameras show the whole person standing at each: one projection per camera for all of them (loading's cost)."""
    near, far = _depth_range(rig.volume)
    steps = np.arange(math.ceil(near / EDGE_FIT_STEP_M - 1e-6), math.floor(far / EDGE_FIT_STEP_M + 1e-6) + 1)
    depths = np.round(steps * EDGE_FIT_STEP_M, 6)
    people = _people_at(rig.volume, depths)
    whole = np.ones(len(depths), dtype=bool)
    for cam in rig.pair:
        whole &= _inside_per_person(cam, people).all(axis=1)
    return depths, whole


def _edge_advice(rig: Rig, edge: str, depths: np.ndarray, whole: np.ndarray) -> str:
    """Where both pair cameras show the person whole nearest the ``edge`` (of :func:`_whole_grid`'s ``depths``), and
    what to do of it."""
    near, far = _depth_range(rig.volume)
    if not whole.any():
        return (f"No depth within the volume (z {near:.2f}-{far:.2f} m, every {EDGE_FIT_STEP_M:g} m) shows them whole "
                f"in both cameras: move the cameras back, fit wider lenses or aim them at the volume {_EDGES_DOC}")
    fit = float(depths[whole][0 if edge == "near" else -1])
    key, where, beyond = ("min", "nearest", "nearer") if edge == "near" else ("max", "farthest", "farther")
    return (f"Both cameras show them whole at z {fit:.1f} m, the {where} (every {EDGE_FIT_STEP_M:g} m): if no one "
            f"stands {beyond}, set the volume's {edge} edge there (working_volume.{key}[2] = {fit:.1f}; ghcal "
            f"solve/import: --volume); if people do, move or aim the cameras {_EDGES_DOC}")


def wire_2d_range_warning(cam: Camera) -> str | None:
    """Why some of ``cam``'s 2D joints cannot go out on the joint stream (its image reaches past
    :data:`WIRE_2D_MAX_PX`: pixel centres at integers, the last pixel's far edge at ``side - 0.5``), or None. They
    went out missing with no word."""
    if max(cam.width, cam.height) - 0.5 <= WIRE_2D_MAX_PX:
        return None
    return (f"camera {cam.name!r} is {cam.width}x{cam.height} pixels, but the joint stream sends 2D joints as 16-bit "
            f"quarter pixels (docs/protocol.md, JOINTS_2D): its 2D joints past {WIRE_2D_MAX_PX:g} px (WIRE_2D_MAX_PX) "
            "are sent as missing; its 3D joints are unaffected")


def camera_height_warning(cam: Camera) -> str | None:
    """Why ``cam`` stands where no rig's camera does (its height above the floor, ``-y``, outside
    :data:`CAMERA_HEIGHT_RANGE_M`), or None."""
    lo, hi = CAMERA_HEIGHT_RANGE_M
    height = -float(cam.center[1])
    if lo <= height <= hi:
        return None
    shown = past_bound(height, lo if height < lo else hi, 2, "f")  # never "10.00 m" for 10.001 m
    shown = "0.00" if shown == "-0.00" else shown  # a camera on the floor to rounding
    return (f"camera {cam.name!r} stands {shown} m above the floor (y = 0, y down), outside the {lo:g}-{hi:g} m "
            "(CAMERA_HEIGHT_RANGE_M) of a camera on the floor to a hall's ceiling: the runtime reads heights from the "
            "floor (the skeleton prior) and every joint may come out missing. Is the origin on the floor below the "
            "cameras' midpoint, y pointing down? Level the rig (calibration.level.level_rig, "
            "ghcal import --camera-height)")


def lens_fold_warning(cam: Camera) -> str:
    """What loading says of a camera whose lens model folds over inside its image (:meth:`Camera.fold_inside_image`),
    naming the coefficients at fault where its tangential or thin-prism terms fold it (:meth:`Camera.fold_terms`)."""
    where = f"camera {cam.name!r}: its lens model folds over {cam.lens_limit:.2f} (normalised radius) from the centre"
    if terms := cam.fold_terms():
        hold = " (`ghcal solve --no-tangential` holds p1 and p2 at 0)" if folded_by_tangential(terms) else ""
        return (f"{where}, inside the image, by its tangential or thin-prism terms ({fold_terms_text(terms)}): "
                "pixels beyond it count as outside the image. A calibration that went wrong (views that did not "
                f"cover the frame?): calibrate again{hold}")
    return (f"{where}, before the image corners: pixels beyond it count as outside the image. A calibration with "
            "the rational model (8 coefficients) usually covers the whole frame")


def volume_reach_problem(rig: Rig) -> str | None:
    """Why the model cannot sweep ``rig``'s working volume from one of its cameras, or None: grown by the widest
    near/far margin the runtime may add (:data:`~ghnerf_runtime.contract.MAX_NEAR_FAR_MARGIN_M`), it reaches
    farther than :data:`~ghnerf_runtime.contract.MAX_DEPTH_M` from the camera along one of its axes, where
    ``near_far_from_box`` refuses it (``DepthRangeError``): on every pair, since a pair with no subject tracked
    sweeps the whole volume."""
    return volume_reach_problem_from(rig.volume, rig.cameras)


def volume_reach_problem_from(volume: WorkingVolume, cameras: Collection) -> str | None:
    """:func:`volume_reach_problem` for ``volume`` seen from ``cameras`` (each with ``name``, ``K``, ``R``, ``t``):
    the rule, for a tool that checks a volume before it has the rig's cameras (``ghcal solve --volume``)."""
    lo, hi = volume.min_corner, volume.max_corner
    for cam in cameras:
        reach = box_reach(cam, np.stack([lo, hi]), MAX_NEAR_FAR_MARGIN_M)
        if not reach <= MAX_DEPTH_M:
            return (f"from {lo.tolist()} to {hi.tolist()} reaches {reach:.6g} m from camera {cam.name!r} (grown by "
                    f"the {MAX_NEAR_FAR_MARGIN_M:g} m near/far margin the runtime may add), farther than the "
                    f"{MAX_DEPTH_M:g} m (MAX_DEPTH_M) the model's near/far resolve: every pair would fail. A volume "
                    "in millimetres read as metres? The working volume is in metres")
    return None


def _plain(value: Any) -> Any:
    """Drop the duplicate-tracking dict subclass from parsed metadata."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


def _camera_from_dict(chk: _Checker, raw: Any, field: str) -> Camera:
    raw = chk.mapping(raw, field, _CAMERA_KEYS)
    name = chk.string(raw["name"], f"{field}.name")
    width = chk.positive_int(raw["width"], f"{field}.width", MAX_IMAGE_SIDE)
    height = chk.positive_int(raw["height"], f"{field}.height", MAX_IMAGE_SIDE)

    K = chk.array(raw["K"], f"{field}.K", (3, 3))
    if not (K[0, 0] > 0 and K[1, 1] > 0) or K[2, 2] != 1.0 or np.any(K[2, :2] != 0) or K[1, 0] != 0:
        chk._raise(
            f"{field}.K",
            f"must be a pinhole matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got {K.tolist()}",
        )
    problem = principal_point_problem(K, width, height) or focal_length_problem(K, width, height) or skew_problem(K)
    if problem:
        chk._raise(f"{field}.K", f"camera {name!r}: {problem}")

    dist_raw = chk.mapping(raw["distortion"], f"{field}.distortion", _DISTORTION_KEYS)
    model = dist_raw["model"]
    if model not in DISTORTION_MODELS:
        chk._raise(f"{field}.distortion.model", f"unsupported distortion model {_show(model)} (supported: {', '.join(DISTORTION_MODELS)})")
    coef_field = f"{field}.distortion.coefficients"
    dist = chk.array(dist_raw["coefficients"], coef_field, (None,), "list of numbers", label=f"camera {name!r}: ")
    if problem := distortion_problem(dist):
        chk._raise(coef_field, f"camera {name!r}: {problem}")
    if dist.size not in DISTORTION_LENGTHS:
        chk._raise(coef_field, f"must have 0, 4, 5, 8, 12 or 14 coefficients, got {dist.size}: {dist.tolist()}")
    if dist.size == 14 and np.any(dist[12:] != 0):
        chk._raise(coef_field, f"tilt terms tx, ty (the last two) must be 0, got {dist[12:].tolist()}")

    R = chk.array(raw["R"], f"{field}.R", (3, 3))
    with np.errstate(over="ignore", invalid="ignore"):  # entries of 1e200 overflow: dev is then inf, refused below
        dev = float(np.abs(R @ R.T - np.eye(3)).max())
        det = float(np.linalg.det(R))
    if dev > ROTATION_TOLERANCE or abs(det - 1.0) > ROTATION_TOLERANCE:
        chk._raise(
            f"{field}.R",
            f"must be a rotation matrix (orthonormal, det +1): max |R R^T - I| = {dev:.3g}, det = {det:.6g}, "
            f"got {R.tolist()}",
        )
    if dev > 1e-12:
        R = nearest_rotation(R)
    t = chk.array(raw["t"], f"{field}.t", (3,), "3-vector of numbers")
    try:
        return Camera(name, width, height, K, dist=dist, R=R, t=t)
    except GeometryError as e:  # pragma: no cover - every case is checked above
        raise chk.fail(field, str(e)) from e


def rig_to_dict(rig: Rig, *, path: str | os.PathLike | None = None) -> dict:
    """The rig as a plain JSON-ready dict (the layout of docs/rig-file.md).

    Args:
        rig: the rig.
        path: the file it is meant for, used only in error messages.

    Raises:
        RigFileError: ``rig.metadata`` is not JSON-serialisable (field ``metadata``).
    """
    try:
        metadata = json.loads(json.dumps(rig.metadata, allow_nan=False))
    except (TypeError, ValueError) as e:
        raise RigFileError(
            f"must be JSON-serialisable (finite numbers, string keys), got {_show(rig.metadata)}: {e}",
            path=None if path is None else str(path),
            field="metadata",
        ) from e
    return {
        "format": FORMAT,
        "version": VERSION,
        "rig_id": rig.rig_id,
        "units": UNITS,
        "cameras": [
            {
                "name": cam.name,
                "width": int(cam.width),
                "height": int(cam.height),
                "K": cam.K.tolist(),
                "distortion": {"model": "opencv", "coefficients": cam.dist.tolist()},
                "R": cam.R.tolist(),
                "t": cam.t.tolist(),
            }
            for cam in rig.cameras
        ],
        "working_volume": {"min": rig.volume.min_corner.tolist(), "max": rig.volume.max_corner.tolist()},
        "metadata": metadata,
    }


# --------------------------------------------------------------------------- text
def _emit(value: Any, indent: int) -> str:
    """JSON with one line per matrix row / short vector; exact (repr) floats."""
    pad, inner = " " * indent, " " * (indent + 2)
    if isinstance(value, dict):
        if not value:
            return "{}"
        items = [f"{inner}{json.dumps(str(k), ensure_ascii=False)}: {_emit(v, indent + 2)}" for k, v in value.items()]
        return "{\n" + ",\n".join(items) + "\n" + pad + "}"
    if isinstance(value, list):
        if all(not isinstance(v, (dict, list)) for v in value):
            return "[" + ", ".join(_emit(v, 0) for v in value) + "]"
        return "[\n" + ",\n".join(inner + _emit(v, indent + 2) for v in value) + "\n" + pad + "]"
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"non-finite number {value}")
    return json.dumps(value, ensure_ascii=False, allow_nan=False)


def dumps_rig(rig: Rig, *, path: str | os.PathLike | None = None) -> str:
    """The rig file text (UTF-8 JSON, trailing newline). ``path`` is used only in errors."""
    return _emit(rig_to_dict(rig, path=path), 0) + "\n"


def loads_rig(text: str, *, path: str | os.PathLike | None = None, warn: bool = True) -> Rig:
    """Parse and validate rig file text. ``path`` is used only in messages; ``warn=False`` logs none of
    :func:`rig_warnings` nor :func:`rig_notes` (the caller logs them: a rig source, once per daemon run)."""
    where = None if path is None else str(path)
    if not text.strip():  # JSON's "Expecting value" at line 1 did not say so
        raise RigFileError("the file is empty", path=where)
    try:
        # NaN/Infinity literals parse to floats here and are then rejected with the field name.
        data = loads_remembering(text)
    except JsonTextError as e:  # invalid, nested thousands deep, or an integer past 4300 digits
        raise RigFileError(str(e), path=where) from e
    return rig_from_dict(data, path=path, warn=warn)


def load_rig(path: str | os.PathLike, *, warn: bool = True) -> Rig:
    """Read and validate a rig file; ``warn=False`` logs none of :func:`rig_warnings` nor :func:`rig_notes` (the
    caller logs them).

    Raises:
        RigFileError: the file cannot be read, is not UTF-8, is not valid JSON (the message
            gives line and column) or fails validation (see :func:`rig_from_dict`).
    """
    path = Path(path)
    try:
        with path.open("rb") as f:
            # the size before reading, and a read that stops past it: a file that grows, or a device, holds no more
            size = os.fstat(f.fileno()).st_size
            raw = f.read(MAX_RIG_FILE_BYTES + 1) if size <= MAX_RIG_FILE_BYTES else b""
            size = max(size, len(raw))
    except OSError as e:
        raise RigFileError(f"cannot read rig file: {e.strerror or e}", path=str(path)) from e
    except ValueError as e:  # a path with a NUL character
        raise RigFileError(f"cannot read rig file: {e}", path=str(path).replace("\0", "\\x00")) from e
    if size > MAX_RIG_FILE_BYTES:
        what = f"{size} bytes" if len(raw) <= MAX_RIG_FILE_BYTES else f"more than {MAX_RIG_FILE_BYTES} bytes"
        raise RigFileError(f"the file holds {what}, over the {MAX_RIG_FILE_BYTES} (1 MiB, MAX_RIG_FILE_BYTES) a rig file "
                           "may: not a rig file?", path=str(path))
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise RigFileError(f"not UTF-8 text (byte {e.start}): {e.reason}", path=str(path)) from e
    return loads_rig(text, path=path, warn=warn)


def save_rig(rig: Rig, path: str | os.PathLike) -> None:
    """Write ``rig`` to ``path`` atomically (see :func:`write_text_atomic`).

    The text is produced and read back with :func:`load_rig`'s checks in memory before the
    file system is touched, so a rig that cannot be written (e.g. non-JSON metadata, or a
    principal point, image size or baseline :func:`load_rig` would refuse) leaves the old
    file as it was.

    Raises:
        RigFileError: the rig cannot be serialised, or the file cannot be written.
    """
    write_text_atomic(path, checked_rig_text(rig, path))


def checked_rig_text(rig: Rig, path: str | os.PathLike) -> str:
    """The text :func:`save_rig` writes to ``path``, read back with the reader's every check, nothing written: for a
    caller that must know the file can be written before it touches others (``ghcal`` keeps the previous one).

    Raises:
        RigFileError: the rig cannot be serialised, or the reader refuses the text.
    """
    text = dumps_rig(rig, path=path)
    # a file the reader refuses is worse than none: read the text back with the reader's every check (a Camera
    # accepts what the file may not hold, such as a 40000-pixel side from an imported calibration)
    rig_from_dict(json.loads(text, object_pairs_hook=remember_repeats), path=path, warn=False)
    return text


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Replace ``path`` with ``text`` (UTF-8) so that readers see the old or the new file, never half.

    Writes a temporary file in the same directory, flushes and fsyncs it, renames it over
    ``path`` (``os.replace`` is atomic on POSIX and Windows) and fsyncs the directory. An
    existing file's permission bits are kept; a new file gets the usual ``0666 & ~umask``.
    A symbolic link is written through: its target is replaced, the link stays.
    On any failure the temporary file is removed and the old file is untouched.

    Raises:
        RigFileError: the file cannot be written.
    """
    write_bytes_atomic(path, utf8_bytes(path, text))


def utf8_bytes(path: str | os.PathLike, text: str) -> bytes:
    """``text`` encoded as UTF-8 for a write to ``path``: :func:`write_text_atomic`'s, and a gzipped writer's.

    Raises:
        RigFileError: the text holds what UTF-8 cannot (a lone surrogate in a name or the metadata).
    """
    try:
        return text.encode("utf-8")
    except UnicodeEncodeError as e:
        raise RigFileError(f"cannot write file: the text is not UTF-8 ({e.reason} at character {e.start})",
                           path=str(path)) from e


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    """:func:`write_text_atomic` for bytes (a file copied as it is, whatever it holds).

    Raises:
        RigFileError: the file cannot be written.
    """
    path = Path(path)
    if path.is_symlink():  # write through the link (a rig file linked from /etc): replacing it would cut the link
        path = Path(os.path.realpath(path))
    directory = path.parent if str(path.parent) else Path(".")
    tmp = directory / f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:12]}.tmp"
    try:
        mode = path.stat().st_mode & 0o7777 if path.exists() else None
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
            if mode is not None:
                os.chmod(tmp, mode)
            os.replace(tmp, path)
        except BaseException:
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass
            raise
        try:  # make the rename itself durable; not possible on every platform
            dir_fd = os.open(directory, os.O_RDONLY)
        except OSError:
            return
        try:
            os.fsync(dir_fd)
        except OSError:
            pass
        finally:
            os.close(dir_fd)
    except OSError as e:
        raise RigFileError(f"cannot write file: {e.strerror or e}", path=str(path)) from e


def write_bytes_into(path: str | os.PathLike, data: bytes, *, wait_for_reader: bool = True) -> None:
    """``data`` written whole into the FIFO or device at ``path`` (renamed over, a FIFO leaves its reader waiting
    and a device node is replaced). ``wait_for_reader=False``: a FIFO with no reader is an OSError (ENXIO) rather
    than an open that blocks until one comes.

    Raises:
        OSError: it cannot be opened or written.
    """
    fd = os.open(path, os.O_WRONLY | (0 if wait_for_reader else os.O_NONBLOCK))
    try:
        view = memoryview(data)
        while view:  # os.write may write part of it
            view = view[os.write(fd, view):]
    finally:
        os.close(fd)
