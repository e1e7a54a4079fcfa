"""OpenCV ``FileStorage`` YAML camera files, read and written by ``cv2.FileStorage``.

Three layouts are read; the keys are exactly these (anything else in the file, such as
``calibration_time`` or ``avg_reprojection_error``, is ignored):

Single camera (OpenCV's calibration sample, ``out_camera_data.yml``), top-level keys:
    ``camera_matrix`` or ``K``              3x3 matrix (required)
    ``distortion_coefficients`` or ``D``    Nx1 / 1xN matrix or sequence, N in 0/4/5/8/12/14 (required)
    ``image_width`` + ``image_height``      integers, or ``image_size`` [w, h] (both: they must agree); else
                                            the ``image_size`` argument (required one way; given beside
                                            the file's own size, it must agree with it, unless another
                                            camera of a multi-camera file states none: the argument is its)
    ``R``                                   3x3 matrix or 3-vector Rodrigues (optional, default I)
    ``T``                                   3-vector, file units (optional, default 0)
    ``name``                                string (optional; default the file's stem)
    ``fisheye_model`` or ``fisheye``        if non-zero the file is refused (``cv::fisheye``'s model is not
                                            supported; the calibration sample writes ``fisheye_model``)

Multi-camera (our export; one map per camera, in rig order):
    ``cameras``     sequence of maps, each with the single-camera keys above; ``R`` and
                    ``T`` are required there (rig -> camera, ``X_cam = R X + T``), and
                    ``name`` defaults to ``cam<i>``
    ``rig_id``      string (optional)
    ``levelled_reference``, ``levelled_camera_height_m``, ``levelled_pitch_deg``, ``levelled_roll_deg``
                    (optional, all or none; our writer's): the rig frame is levelled, the first camera
                    this high and tilted so; taken as ``metadata["levelled"]`` where the poses show it
                    (:mod:`calibration.formats._frame`)

Stereo pair (OpenCV's ``stereo_calib`` sample: ``intrinsics.yml`` + ``extrinsics.yml``):
    ``M1``, ``D1``, ``M2``, ``D2``   intrinsics of cameras 1 and 2 (required)
    ``R``, ``T``                     camera 1 -> camera 2 (required; from this file or
                                     ``extrinsics_path``, where this file's, if any, must agree);
                                     ``R1 R2 P1 P2 Q`` are ignored
    ``image_width`` + ``image_height`` or ``image_size``: optional (stereo_calib writes
                                     neither, so pass ``image_size``)
    The rig frame is camera 1's frame; cameras are named ``left`` and ``right``.

Matrices may be ``!!opencv-matrix`` nodes (read as the digits of their ``data``; one whose ``dt``
changes them, ``dt: i`` for 320.5, is refused) or plain (nested) sequences. Translations are
multiplied by ``units_to_metres`` on reading and divided by it on writing; OpenCV
calibrations come out in the units of the board's square size (often millimetres), so a
stereo_calib or single-camera file whose ``T`` is not zero needs ``units_to_metres``: from
the argument, else from the file's own ``units_to_metres`` key (our writers store it), else
it is an error; the multi-camera layout (ours) is in metres unless its key says otherwise. Writers
produce the multi-camera / single-camera layouts with 17 significant digits (lossless),
store ``units_to_metres`` and (multi-camera) the working volume in metres
(``working_volume_min`` / ``working_volume_max``, which OpenCV ignores) and, for a rig in a
levelled frame, the ``levelled_*`` keys, and replace the file atomically; a name ending in ``.gz``
(``rig.yml.gz``) is written gzipped, as ``cv2.FileStorage`` writes and reads it, in the format of the
suffix before it. A name ending in ``.gz`` and a digit (``rig.yml.gz9``, OpenCV's gzip at level 9) is read
from the file named, gunzipped; it is not written, as OpenCV opens ``rig.yml.gz`` for it. Nor is a ``.gz`` in
another case (``rig.yml.GZ``): OpenCV gzips only the lower-case name, and reads and writes this one as plain text;
it is read by its bytes, gzip or plain text.
"""
from __future__ import annotations

import gzip
import math
import os
import re
import zlib
from pathlib import Path
from typing import Any, Sequence

import cv2
import numpy as np

from calibration.formats._common import (
    as_array,
    check_units,
    fail,
    join,
    make_camera,
    not_text_problem,
    make_rig,
    refuse_skew,
    rotation,
    show,
)
from calibration.formats._frame import KEYS as LEVELLING_KEYS, levelling_metadata, levelling_of, recorded_levelling
from ghnerf_runtime.errors import RigFileError
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.rig import Rig, WorkingVolume
from ghnerf_runtime.rig_file import utf8_bytes, write_bytes_atomic

_K_KEYS = ("camera_matrix", "K")
_D_KEYS = ("distortion_coefficients", "D")
#: OpenCV's calibration sample writes ``fisheye_model: 1`` for a ``cv::fisheye`` calibration, whose four
#: coefficients (k1..k4, equidistant) would otherwise be read as the pinhole model's k1 k2 p1 p2.
_FISHEYE_KEYS = ("fisheye_model", "fisheye")

__all__ = ["format_suffix", "gzip_name_problem", "gzipped", "named_with_gzip_level", "read_opencv_camera",
           "read_opencv_rig", "write_opencv_camera", "write_opencv_rig", "write_opencv_text"]

#: A name ending so is a gzipped file to ``cv2.FileStorage``, which reads and writes it so itself; its test is
#: case-sensitive (persistence.cpp; cv2 5.0 writes plain text for "rig.yml.GZ" and cannot read gzip under it).
GZIP_SUFFIX = ".gz"
#: A suffix ``cv2.FileStorage`` reads as gzip at a compression level (persistence.cpp: ``.gz`` and one digit); it
#: opens the name without the digit.
_GZIP_LEVEL = re.compile(r"\.gz[0-9]", re.IGNORECASE)
_GZIP_MAGIC = b"\x1f\x8b"
_BOM = b"\xef\xbb\xbf"

#: How much of a file is looked at for the marks of one that is not FileStorage text (NULs, UTF-16).
_SNIFF_BYTES = 4096
#: How far (radians) an intrinsics file's R may be from its extrinsics file's and be the same pose: past the rounding
#: of 6 printed digits, not a change any calibration would make.
_SAME_POSE_TOLERANCE = 1e-5
#: How far (share of the baseline |T|) an intrinsics file's T may be from its extrinsics file's and be the same: a T
#: in metres written with 6 decimals (0.5 um steps) is up to 5e-5 of the shortest baseline a rig may have (10 mm,
#: MIN_BASELINE_M). 1e-5 of the largest component refused such a copy of a 30 mm baseline, showing the two equal.
_SAME_T_TOLERANCE = 1e-4
_ONE_POSE_HINT = ("two poses for the pair; leave out extrinsics_path (--extrinsics) to use this file's, or delete "
                  "R and T from this file to use the other's")


# --------------------------------------------------------------------------- reading helpers
def _open(path) -> cv2.FileStorage:
    p = Path(path)
    if not p.is_file():
        raise fail(path, None, "no such file" if not p.exists() else "not a regular file")
    try:
        with open(p, "rb") as f:
            head = f.read(_SNIFF_BYTES)
        # FileStorage's own words for an empty file: "(-215:Assertion failed) buf in function 'open'"
        if not head.strip() and not p.read_bytes().strip():
            raise fail(path, None, "the file is empty")
        # "rig.yml.gz9": FileStorage takes the 9 for a compression level and opens rig.yml.gz, another file (or
        # none); "rig.yml.GZ": it reads gzip as text. Only a lower-case .gz is left to it: these are read here
        data = _gunzipped(p) if gzipped(p) and p.suffix != GZIP_SUFFIX else None
        if data is not None:
            if not data.strip():
                raise fail(path, None, "the file is empty, gzipped")
            head = data[:_SNIFF_BYTES]
        if not gzipped(p) or data is not None:  # FileStorage reads a gzipped file itself
            if problem := not_text_problem(head, "OpenCV FileStorage (YAML, XML or JSON)"):
                raise fail(path, None, problem)
        bom = len(_BOM) if head.startswith(_BOM) else 0  # Windows editors' mark: FileStorage refused line 1's syntax
        if bom or data is not None:
            text = (p.read_bytes() if data is None else data)[bom:].decode("utf-8")
            fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
        else:
            fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
    except OSError as e:
        raise fail(path, None, f"cannot read: {e.strerror or e}") from e
    except UnicodeDecodeError as e:
        raise fail(path, None, f"not UTF-8 text (byte {e.start + bom}): {e.reason}") from e
    except (cv2.error, SystemError) as e:
        cause = e.__cause__ or e
        msg = str(cause).split("error: ", 1)[-1].strip()
        raise fail(path, None, f"cannot parse OpenCV YAML: {msg}") from e
    if not fs.isOpened():
        raise fail(path, None, "cannot open as an OpenCV FileStorage file")
    try:
        _refuse_duplicate_keys(fs.root(), path)
    except RigFileError:
        fs.release()
        raise
    return fs


def _refuse_duplicate_keys(root, path) -> None:
    """A key given twice in one map, named (``cameras[0].image_width``). OpenCV reads the first and JSON and YAML
    readers the last: a corrected value typed in below the old line was dropped without a word."""
    stack = [(root, "")]
    while stack:  # not recursive: a file nested thousands deep would hit Python's recursion limit
        node, field = stack.pop()
        if node.isMap():
            keys, seen = _keys(node), set()
            for key in keys:
                if key in seen:
                    raise fail(path, join(field, key), f"is given {keys.count(key)} times in one map: OpenCV reads "
                                                       "the first, other readers the last; keep one")
                seen.add(key)
            stack.extend((node.getNode(key), join(field, key)) for key in keys)
        elif node.isSeq():
            stack.extend((node.at(i), f"{field}[{i}]") for i in range(node.size()))


def _keys(node) -> tuple[str, ...]:
    return tuple(node.keys()) if node.isMap() else ()


def _numeric(node, path, field: str) -> np.ndarray | None:
    """A number, matrix or (nested) sequence of numbers; None when the node is missing."""
    if node.empty() or node.isNone():
        return None
    if node.isInt() or node.isReal():
        return np.array(node.real())
    if node.isString():
        if node.string() == "...":  # OpenCV's reading of a last key left without a value (a file cut short)
            raise fail(path, field, "has no value (the file cut short?)")
        raise fail(path, field, f"must be a number or a matrix, got the string {node.string()!r}")
    if node.isMap():
        keys = _keys(node)
        if "data" not in keys:
            if {"rows", "cols", "dt"} & set(keys):  # a matrix whose data was cut off: said as a stray map
                raise fail(path, field, f"an !!opencv-matrix without its data (it has {', '.join(keys)}; the file cut "
                                        "short?)")
            raise fail(path, field, f"must be a number or a matrix, got a map with keys {list(keys)}")
        if count := _matrix_count_problem(node):  # OpenCV's words: "nelems == m.total()*m.channels()"
            raise fail(path, field, f"malformed !!opencv-matrix: {count}")
        try:
            mat = node.mat()
        except cv2.error as e:
            msg = str(e).split("error: ", 1)[-1].strip()
            raise fail(path, field, f"malformed !!opencv-matrix: {msg}") from e
        if mat is None:  # OpenCV reads a 0-element matrix as None
            return np.zeros(0)
        return _matrix_as_written(node, np.asarray(mat, dtype=np.float64), path, field)
    if node.isSeq():
        items = [_numeric(node.at(i), path, f"{field}[{i}]") for i in range(node.size())]
        if any(item is None for item in items):
            raise fail(path, field, "must be a sequence of numbers, got an empty element")
        try:
            return np.array(items, dtype=np.float64)
        except ValueError:
            raise fail(path, field, "must be a rectangular (nested) sequence of numbers") from None
    raise fail(path, field, "must be a number or a matrix")


def _matrix_count_problem(node) -> str | None:
    """Why an ``!!opencv-matrix``'s ``data`` does not fill its ``rows`` x ``cols`` (x channels); None: it does, or
    the node is malformed otherwise (OpenCV names that)."""
    rows, cols, dt, data = (node.getNode(k) for k in ("rows", "cols", "dt", "data"))
    if not (rows.isInt() and cols.isInt() and dt.isString() and data.isSeq()):
        return None
    digits = re.match(r"\d*", dt.string()).group()
    channels = int(digits) if digits else 1
    want = int(rows.real()) * int(cols.real()) * channels
    if data.size() == want:
        return None
    shape = f"rows {int(rows.real())} x cols {int(cols.real())}" + (f" x {channels} channels" if channels != 1 else "")
    return f"{shape} is {want} values, but data has {data.size()}"


def _matrix_as_written(node, mat: np.ndarray, path, field: str) -> np.ndarray:
    """An ``!!opencv-matrix``'s values as its ``data`` prints them, checked against ``mat`` (OpenCV's reading).

    OpenCV converts ``data`` to the type ``dt`` names, silently: ``dt: i`` read a principal point of 320.5
    as 320 and ``dt: u`` a focal length of 600 as 255. A value ``dt`` cannot hold is refused, naming both;
    float32's rounding (``dt: f``) is not a loss, and the digits printed are taken.
    """
    data = node.getNode("data")
    if not data.isSeq() or data.size() != mat.size:
        return mat
    items = [data.at(i) for i in range(data.size())]
    if not all(item.isInt() or item.isReal() for item in items):
        return mat
    written = np.array([item.real() for item in items], dtype=np.float64)
    read = mat.reshape(-1)
    changed = ~np.isclose(read, written, rtol=1e-6, atol=0.0, equal_nan=True)
    if np.any(changed):
        k = int(np.argmax(changed))
        dt = node.getNode("dt").string() if node.getNode("dt").isString() else "?"
        raise fail(path, field, f"dt: {dt} cannot hold data[{k}] = {float(written[k])!r}: OpenCV reads it as "
                                f"{float(read[k])!r} ({int(changed.sum())} of {changed.size} values change); "
                                "write the matrix with dt: d")
    return written.reshape(mat.shape)


def _pick(node, keys: Sequence[str], path, field: str, required: bool = True) -> tuple[str, Any]:
    """The one alias of ``keys`` present in map ``node``, and its numeric value."""
    present = [k for k in keys if k in _keys(node)]
    if len(present) > 1:
        raise fail(path, join(field, present[1]), f"both {present[0]!r} and {present[1]!r} are given; use one")
    if not present:
        if required:
            raise fail(path, join(field, keys[0]), f"missing required key {' or '.join(map(repr, keys))}")
        return keys[0], None
    key = present[0]
    value = _numeric(node.getNode(key), path, join(field, key))
    if value is None:
        raise fail(path, join(field, key), "is empty")
    return key, value


def _image_size(node, path, field: str, image_size, *, checked: bool = True) -> tuple[Any, Any, tuple[str, str]]:
    """Width, height and the keys they came from (for error messages): the file's, else the ``image_size``
    argument's; both given, they must agree where ``checked`` (False: the argument is for the file's other
    cameras, which state none)."""
    pair, size = _width_height(node, path, field), _size_key(node, path, field)
    if pair is not None and size is not None and pair != size:  # image_width won without a word
        raise fail(path, join(field, "image_size"), f"is [{size[0]:.10g}, {size[1]:.10g}], but image_width and "
                                                    f"image_height are {pair[0]:.10g} and {pair[1]:.10g}: keep one")
    given = _size_argument(path, image_size)
    if pair is None and size is None:
        if given is None:
            raise fail(path, join(field, "image_width"), "missing image size: give image_width + image_height or "
                                                         "image_size in the file, or the image_size argument")
        return given[0], given[1], ("image_size argument", "image_size argument")
    (w, h), keys = (pair, ("image_width", "image_height")) if pair is not None else (size, ("image_size",) * 2)
    if checked and given is not None and (w, h) != given:  # the file's size was taken, the argument dropped unsaid
        key = keys[0] if w != given[0] else keys[1]
        raise fail(path, join(field, key), f"gives the image size {w:.10g}x{h:.10g}, but the image_size argument "
                                           f"(--image-size) is {show(given[0])}x{show(given[1])}: the argument is for "
                                           "files that give none; leave it out to take the file's, or correct the "
                                           "file")
    return w, h, keys


def _states_size(node) -> bool:
    """Whether a camera's map states its image size (any of the keys: one alone is refused when it is read)."""
    return any(key in _keys(node) for key in ("image_width", "image_height", "image_size"))


def _size_argument(path, image_size) -> tuple[Any, Any] | None:
    """The ``image_size`` argument as (width, height); None when not given."""
    if image_size is None:
        return None
    try:  # a frame's shape (h, w, 3) or "640x480" raised a bare ValueError / TypeError when unpacked
        w, h = image_size
    except (TypeError, ValueError):
        raise fail(path, "image_size argument", f"must be (width, height), got {show(image_size)}") from None
    return w, h


def _width_height(node, path, field: str) -> tuple[float, float] | None:
    """``image_width`` and ``image_height``; None when neither is given."""
    keys = _keys(node)
    if "image_width" not in keys and "image_height" not in keys:
        return None
    w = _numeric(node.getNode("image_width"), path, join(field, "image_width"))
    h = _numeric(node.getNode("image_height"), path, join(field, "image_height"))
    if w is None or h is None:
        raise fail(path, join(field, "image_width" if w is None else "image_height"),
                   "missing (both image_width and image_height are needed)")
    if w.size != 1 or h.size != 1:
        raise fail(path, join(field, "image_width"),
                   f"image_width and image_height must be numbers, got {show(w)}, {show(h)}")
    return float(w.reshape(-1)[0]), float(h.reshape(-1)[0])


def _size_key(node, path, field: str) -> tuple[float, float] | None:
    """``image_size`` as (width, height); None when not given."""
    if "image_size" not in _keys(node):
        return None
    size = _numeric(node.getNode("image_size"), path, join(field, "image_size"))
    if size is None or size.size != 2:
        raise fail(path, join(field, "image_size"), f"must be [width, height], got {show(size)}")
    w, h = (float(v) for v in size.reshape(-1))
    return w, h


def _string(node, path, field: str) -> str | None:
    if node.empty() or node.isNone():
        return None
    if not node.isString() or not node.string():
        got = node.real() if node.isInt() or node.isReal() else "an empty or non-scalar node"
        raise fail(path, field, f"must be a non-empty string, got {got}")
    return node.string()


def _refuse_fisheye(node, path, field: str) -> None:
    for key in _FISHEYE_KEYS:
        if key in _keys(node):
            value = _numeric(node.getNode(key), path, join(field, key))
            if value is not None and np.any(value != 0):
                got = ", ".join(f"{v:g}" for v in value.reshape(-1))
                raise fail(path, join(field, key), f"is {got}: the fisheye model is not supported (only OpenCV's "
                                                   "pinhole model; its coefficients mean something else)")


def _camera(node, path, field: str, *, default_name: str, image_size, units: float, need_pose: bool,
            size_checked: bool = True) -> Camera:
    _refuse_fisheye(node, path, field)
    name = _string(node.getNode("name"), path, join(field, "name")) if "name" in _keys(node) else None
    k_key, K = _pick(node, _K_KEYS, path, field)
    d_key, D = _pick(node, _D_KEYS, path, field)
    w, h, size_keys = _image_size(node, path, field, image_size, checked=size_checked)
    keys = _keys(node)
    if need_pose or "R" in keys or "T" in keys:
        _, R = _pick(node, ("R",), path, field)
        _, T = _pick(node, ("T",), path, field)
    else:
        R, T = np.eye(3), np.zeros(3)
    return make_camera(path, field, name=name or default_name, width=w, height=h, K=K, dist=D, R=R,
                       t=np.asarray(T, dtype=np.float64) * units, K_key=k_key, dist_key=d_key,
                       size_keys=size_keys)


def _units(root, path, given: float | None, needed: bool) -> float:
    """``units_to_metres``: the argument, else the file's key, else 1.0 when no translation needs it.
    An argument that contradicts the file's key is an error: one of them is wrong, and the rig would be
    scaled by their ratio (a baseline of 75 m)."""
    if given is not None:
        given = check_units(given)
    if "units_to_metres" in _keys(root):
        value = _numeric(root.getNode("units_to_metres"), path, "units_to_metres")
        if value is None or value.size != 1:
            raise fail(path, "units_to_metres", f"must be a number, got {show(value)}")
        try:
            declared = check_units(float(value.reshape(-1)[0]))
        except Exception as e:
            raise fail(path, "units_to_metres", str(e)) from None
        if given is not None and not math.isclose(given, declared, rel_tol=1e-9):
            raise fail(path, "units_to_metres", f"the file says {declared!r} m per unit, the argument {given!r}: "
                                                "leave the argument out to use the file's")
        return declared
    if given is not None:
        return given
    if needed:
        raise fail(path, "T", "OpenCV calibrations give T in the units of the board's square size (often "
                              "millimetres) and this file does not say which: pass units_to_metres (0.001 for mm, "
                              "1.0 for m)")
    return 1.0


def _has_translation(node, path) -> bool:
    keys = _keys(node)
    if "T" not in keys:
        return False
    try:  # not node.mat(): it raises for a plain sequence, so T: [0, 0, 0] demanded units_to_metres
        T = _numeric(node.getNode("T"), path, "T")
    except RigFileError:
        return True  # malformed: the camera reader names it
    return T is None or bool(np.any(T != 0))


def _levelling_values(root, path) -> dict[str, Any]:
    """Our writer's ``levelled_*`` keys, as Python values (:func:`recorded_levelling` checks them)."""
    values: dict[str, Any] = {}
    for key in LEVELLING_KEYS:
        if key not in _keys(root):
            continue
        node = root.getNode(key)
        if node.isString():
            values[key] = node.string()
        else:
            value = _numeric(node, path, key)
            values[key] = float(value.reshape(-1)[0]) if value is not None and value.size == 1 else value
    return values


def _volume(root, path) -> WorkingVolume | None:
    keys = _keys(root)
    if "working_volume_min" not in keys and "working_volume_max" not in keys:
        return None
    lo = as_array(path, "working_volume_min", _pick(root, ("working_volume_min",), path, "")[1], [(3,)], "a 3-vector")
    hi = as_array(path, "working_volume_max", _pick(root, ("working_volume_max",), path, "")[1], [(3,)], "a 3-vector")
    if np.any(hi <= lo):
        raise fail(path, "working_volume_max", f"must exceed working_volume_min on every axis, got {lo} .. {hi}")
    return WorkingVolume(lo, hi)


# --------------------------------------------------------------------------- public readers
def read_opencv_camera(path: str | os.PathLike, *, name: str | None = None, image_size: tuple[int, int] | None = None,
                       units_to_metres: float | None = None) -> Camera:
    """Read the single-camera layout (see the module docstring for the keys).

    Args:
        path: the YAML file.
        name: camera name; default the file's ``name`` key, else the file's stem.
        image_size: ``(width, height)`` when the file has no image size; where it has one, they must agree.
        units_to_metres: metres per unit of ``T`` in the file; default the file's own
            ``units_to_metres``; needed when the file has a non-zero ``T`` and no such key.

    Returns:
        The :class:`Camera` (identity pose unless the file has ``R``/``T``).

    Raises:
        RigFileError: naming the file and the key, e.g. ``camera_matrix``.
    """
    fs = _open(path)
    try:
        root = fs.root()
        if "cameras" in _keys(root) or "M1" in _keys(root):
            raise fail(path, None, "this is a multi-camera file; use read_opencv_rig")
        units = _units(root, path, units_to_metres, needed=_has_translation(root, path))
        cam = _camera(root, path, "", default_name=Path(path).stem, image_size=image_size, units=units, need_pose=False)
    finally:
        fs.release()
    return cam if name is None else Camera(name, cam.width, cam.height, cam.K, cam.dist, cam.R, cam.t)


def read_opencv_rig(
    path: str | os.PathLike,
    *,
    extrinsics_path: str | os.PathLike | None = None,
    image_size: tuple[int, int] | None = None,
    volume: WorkingVolume | None = None,
    rig_id: str | None = None,
    units_to_metres: float | None = None,
) -> Rig:
    """Read the multi-camera or the stereo_calib layout (see the module docstring).

    Args:
        path: the YAML file (``intrinsics.yml`` for the stereo_calib layout).
        extrinsics_path: stereo_calib's ``extrinsics.yml`` when ``R``/``T`` are not in ``path``.
        image_size: ``(width, height)`` for cameras whose entry has no image size. Where every entry has one,
            each must agree with it (refused, naming both, where the file's was taken and the argument dropped
            unsaid); where some entry has none, the argument is theirs and the others keep their own sizes.
        volume: the working volume; default the file's (``working_volume_min`` / ``_max``, our
            writer stores it), else :func:`default_working_volume`.
        rig_id: default the file's ``rig_id``, else the file's stem.
        units_to_metres: metres per unit of ``T`` in the file; default the file's own
            ``units_to_metres``, else metres for the multi-camera layout (ours). Required for
            the stereo_calib layout, whose ``T`` is in the board's units.

    Returns:
        The :class:`Rig`, metadata ``{"source": {"format", "path", "units_to_metres"}}``, plus
        ``"levelled"`` where the file records a levelled frame that its poses show.

    Raises:
        RigFileError: naming the file and the field, e.g. ``cameras[1].camera_matrix``.
    """
    fs = _open(path)
    try:
        root = fs.root()
        keys = _keys(root)
        if "cameras" in keys:
            layout = "opencv-yaml"
            if extrinsics_path is not None:  # ignored, a mistyped or wrong file passed unseen ("wrote rig.json")
                raise fail(path, "cameras", f"holds each camera's R and T (the multi-camera layout): extrinsics_path "
                                            f"(--extrinsics) {str(extrinsics_path)!r} goes with stereo_calib's "
                                            "intrinsics.yml only; leave it out")
            units = _units(root, path, units_to_metres, needed=False)  # our layout: metres unless it says
            if volume is None:
                volume = _volume(root, path)
            seq = root.getNode("cameras")
            if not seq.isSeq():
                raise fail(path, "cameras", "must be a sequence of camera maps")
            cameras, fields = [], []
            nodes = [seq.at(i) for i in range(seq.size())]
            # a hand-written file where one camera states its size and another does not: the argument is the
            # second's, not checked against the first's (it was refused where they differed)
            for_unsized = any(node.isMap() and not _states_size(node) for node in nodes)
            for i, node in enumerate(nodes):
                field = f"cameras[{i}]"
                if not node.isMap():
                    raise fail(path, field, "must be a map of camera keys")
                cameras.append(_camera(node, path, field, default_name=f"cam{i}", image_size=image_size, units=units,
                                       need_pose=True, size_checked=not for_unsized))
                fields.append(field)
            file_rig_id = _string(root.getNode("rig_id"), path, "rig_id") if "rig_id" in keys else None
            levelling = recorded_levelling(path, _levelling_values(root, path))  # ours: the frame was levelled
            list_field, pair_t = "cameras", (path, "cameras[1].T")
        elif "M1" in keys:
            layout = "opencv-stereo-calib"
            # the pose first: a mistyped --extrinsics was named only after a unit was asked for and given
            pose = _stereo_pose(root, path, extrinsics_path)
            units = _units(root, path, units_to_metres, needed=True)
            cameras, fields = _stereo_calib(root, path, pose, image_size, units)
            file_rig_id, list_field, levelling = None, "M1", None
            pair_t = (path if extrinsics_path is None else extrinsics_path, "T")
        else:
            raise fail(path, None, "no known layout: expected a 'cameras' sequence (multi-camera) or 'M1', 'D1', "
                                   f"'M2', 'D2', 'R', 'T' (stereo_calib); found keys {list(keys)}")
    finally:
        fs.release()
    metadata = levelling_metadata(cameras, levelling,
                                  {"format": layout, "path": str(path), "units_to_metres": units})
    return make_rig(path, cameras, fields, volume=volume, rig_id=rig_id or file_rig_id or Path(path).stem,
                    metadata=metadata, list_field=list_field, pair_t=pair_t)


def _stereo_pose(root, path, extrinsics_path) -> tuple[np.ndarray, np.ndarray]:
    """stereo_calib's ``R`` and ``T`` (camera 1 -> camera 2, file units): ``path``'s own (``root``) without
    ``extrinsics_path``, else that file's."""
    if extrinsics_path is None:
        return _pose(root, path)
    ext_fs = _open(extrinsics_path)
    try:
        R, T = _pose(ext_fs.root(), extrinsics_path)
    finally:
        ext_fs.release()
    _refuse_another_pose(root, path, extrinsics_path, R, T)
    return R, T


def _pose(root, path) -> tuple[np.ndarray, np.ndarray]:
    """``R`` (a matrix) and ``T`` of map ``root``."""
    return _pose_part(root, path, "R"), _pose_part(root, path, "T")


def _pose_part(root, path, key: str) -> np.ndarray:
    """``R`` (as a matrix) or ``T`` of map ``root``, checked here so that their errors name the file they came from."""
    _, value = _pick(root, (key,), path, "")
    return rotation(path, key, value) if key == "R" else as_array(path, key, value, [(3,)], "a 3-vector")


def _refuse_another_pose(root, path, extrinsics_path, R: np.ndarray, T: np.ndarray) -> None:
    """Refuse an ``R`` or ``T`` in the intrinsics file (``root``) that is not the extrinsics file's: the extrinsics
    file won without a word, though one of the two is another calibration's pose (stereo_calib writes them to the
    extrinsics file only). Agreeing values (a merged file) are fine."""
    keys = _keys(root)
    if "R" in keys:
        mine = _pose_part(root, path, "R")
        angle = float(np.linalg.norm(cv2.Rodrigues(mine.T @ R)[0]))
        if angle > _SAME_POSE_TOLERANCE:
            raise fail(path, "R", f"is {math.degrees(angle):.3g} deg from the R of {extrinsics_path}: "
                                  f"{_ONE_POSE_HINT}")
    if "T" in keys:
        mine = _pose_part(root, path, "T")
        apart = float(np.abs(mine - T).max())
        if apart > _SAME_T_TOLERANCE * max(np.linalg.norm(mine), np.linalg.norm(T)):
            # how far apart said too: shown to 6 digits, two T past the tolerance may print the same
            raise fail(path, "T", f"is {show(mine)}, {apart:.2g} from the T of {extrinsics_path} {show(T)}: "
                                  f"{_ONE_POSE_HINT}")


def _stereo_calib(root, path, pose, image_size, units) -> tuple[list[Camera], list[str]]:
    _refuse_fisheye(root, path, "")
    *size, size_keys = _image_size(root, path, "", image_size)
    R, T = pose[0], pose[1] * units  # pose: T in file units
    cams = []
    for i, (name, rot, trans) in enumerate((("left", np.eye(3), np.zeros(3)), ("right", R, T)), start=1):
        _, K = _pick(root, (f"M{i}",), path, "")
        _, D = _pick(root, (f"D{i}",), path, "")
        cams.append(make_camera(path, "", name=name, width=size[0], height=size[1], K=K, dist=D, R=rot, t=trans,
                                K_key=f"M{i}", dist_key=f"D{i}", size_keys=size_keys))
    return cams, ["", ""]


# --------------------------------------------------------------------------- writers
def _write_camera(fs: cv2.FileStorage, cam: Camera, units: float, with_name: bool) -> None:
    if with_name:
        fs.write("name", cam.name)
    fs.write("image_width", int(cam.width))
    fs.write("image_height", int(cam.height))
    fs.write("camera_matrix", np.ascontiguousarray(cam.K))
    fs.write("distortion_coefficients", np.ascontiguousarray(cam.dist.reshape(1, -1)))
    fs.write("R", np.ascontiguousarray(cam.R))
    fs.write("T", np.ascontiguousarray((cam.t / units).reshape(3, 1)))


#: The FileStorage format written for a destination's suffix (YAML for any other): a ``rig.xml`` used to
#: hold YAML text, which OpenCV reads by content but a tool that parses the XML itself does not.
_FORMATS = {".xml": (cv2.FILE_STORAGE_FORMAT_XML, "XML"), ".json": (cv2.FILE_STORAGE_FORMAT_JSON, "JSON")}
_YAML = (cv2.FILE_STORAGE_FORMAT_YAML, "YAML")


def gzipped(path) -> bool:
    """Whether ``path`` names a gzipped FileStorage file (``rig.yml.gz``, or ``rig.yml.gz9``:
    :func:`named_with_gzip_level`)."""
    return Path(path).suffix.lower() == GZIP_SUFFIX or named_with_gzip_level(path)


def named_with_gzip_level(path) -> bool:
    """Whether ``path`` ends in ``.gz`` and a digit (``rig.yml.gz9``), which ``cv2.FileStorage`` takes for gzip at
    that compression level, 0 to 9, opening the name without the digit (``rig.yml.gz``) to read or write it."""
    return _GZIP_LEVEL.fullmatch(Path(path).suffix) is not None


def gzip_name_problem(path) -> str | None:
    """Why a FileStorage file is not written to ``path`` (None: it may be): a gzip name no OpenCV program opens as
    this file: ``.gz`` in another case (``rig.yml.GZ``), which ``cv2.FileStorage`` reads and writes as plain text,
    or ``.gz`` and a digit (:func:`named_with_gzip_level`), which it takes for a compression level, opening the name
    without it."""
    p = Path(path)
    if not gzipped(p):
        return None
    meant = p.with_suffix(GZIP_SUFFIX).name
    if not p.suffix.startswith(GZIP_SUFFIX):  # .GZ, .Gz, .GZ9: OpenCV's test for gzip is case-sensitive
        return (f"OpenCV gzips only a lower-case .gz name and reads {p.name} as plain text, so no OpenCV program "
                f"could read this file; name it {meant} (written gzipped)")
    if named_with_gzip_level(p):
        return (f"OpenCV reads the digit after .gz as a compression level, so it opens {meant} for this name and no "
                f"OpenCV program could read this file; name it {meant} (written gzipped)")
    return None


def _gunzipped(path: Path) -> bytes:
    """The bytes of ``path``, a gzip name ``cv2.FileStorage`` does not read as this file (:func:`gzip_name_problem`),
    unpacked where it is gzip (plain text is taken as it is, as zlib's reader takes it in a ``.gz`` file).

    Raises:
        RigFileError: naming ``path``: gzip that is cut short or damaged.
    """
    data = path.read_bytes()
    if not data.startswith(_GZIP_MAGIC):
        return data
    try:
        return gzip.decompress(data)
    except (EOFError, OSError, zlib.error) as e:  # cut short; a bad header (BadGzipFile); a bad stream or CRC
        raise fail(path, None, f"cannot unpack it as gzip: {e}") from e


def format_suffix(path) -> str:
    """The suffix, lower case, that picks the format of ``path``: the one before ``.gz`` for a gzipped file, as
    OpenCV takes it (``rig.xml.gz``: ``.xml``)."""
    p = Path(path)
    return Path(p.stem).suffix.lower() if gzipped(p) else p.suffix.lower()


def _format_name(path) -> str:
    """The FileStorage format written to ``path``, as messages name it (a .json export was said to be YAML)."""
    return _FORMATS.get(format_suffix(path), _YAML)[1]


def _memory_writer(path) -> cv2.FileStorage:
    fmt = _FORMATS.get(format_suffix(path), _YAML)[0]
    return cv2.FileStorage("", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY | fmt)


def write_opencv_text(path: str | os.PathLike, text: str) -> None:
    """Replace ``path`` atomically with ``text`` (from :func:`dumps_opencv_rig`) as OpenCV would write it there:
    gzipped where the name ends in ``.gz`` (``rig.yml.gz`` was plain text, which a tool that gunzips it refuses).

    Raises:
        RigFileError: the file cannot be written; its name ends in ``.gz`` and a digit, or in ``.gz`` in another
            case (:func:`gzip_name_problem`).
    """
    if problem := gzip_name_problem(path):
        raise fail(path, None, problem)
    data = utf8_bytes(path, text)
    # mtime 0: the same rig exports the same bytes
    write_bytes_atomic(path, gzip.compress(data, mtime=0) if gzipped(path) else data)


def _check_strings_read_back(text: str, path, expected: dict[str, tuple[Any, str]]) -> None:
    """OpenCV writes strings unquoted: ``true``, ``null`` or a trailing space come back as a number, nothing or
    another name. Refuse to write a file whose strings (field -> (node, value)) would not read back as given."""
    try:
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError):  # a name '"' left OpenCV's own text unreadable: a traceback from ghcal export
        field = next((f for f, (_, value) in expected.items() if not _reads_back(value, path)), None)
        if field is None:  # pragma: no cover - each string alone reads back, the file does not
            raise fail(path, None, "OpenCV cannot read back the text it wrote for this rig") from None
        raise fail(path, field, f"{expected[field][1]!r} would not read back from OpenCV FileStorage as written "
                                "(OpenCV cannot read the text it wrote): choose another") from None
    try:
        for field, (where, value) in expected.items():
            node = where(fs.root())
            if not (node.isString() and node.string() == value):
                fmt = _format_name(path)
                why = f"it comes back as {_as_read(node)}" + ("; OpenCV does not quote it" if fmt == "YAML" else "")
                raise fail(path, field, f"{value!r} would not read back from OpenCV {fmt} as written ({why}): "
                                        "choose another")
    finally:
        fs.release()


def _as_read(node) -> str:
    """What a string written to ``node`` came back as, for a message: a string, a number or nothing."""
    if node.isString():
        return repr(node.string())
    if node.isInt() or node.isReal():
        return f"the number {node.real():g}"
    return "nothing"


def _reads_back(value: str, path) -> bool:
    """Whether ``value`` alone, written as a string in the format of ``path``, reads back as itself."""
    fs = _memory_writer(path)
    fs.write("value", value)
    try:
        back = cv2.FileStorage(fs.releaseAndGetString(), cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError):
        return False
    try:
        node = back.getNode("value")
        return node.isString() and node.string() == value
    finally:
        back.release()


def write_opencv_rig(rig: Rig, path: str | os.PathLike, *, units_to_metres: float = 1.0) -> None:
    """Write the multi-camera layout (``rig_id``, ``units_to_metres``, the working volume, ``cameras``).

    Args:
        rig: the rig.
        path: destination, replaced atomically; gzipped where its name ends in ``.gz``.
        units_to_metres: metres per unit of the written ``T`` (1.0: metres).
    """
    write_opencv_text(path, dumps_opencv_rig(rig, path, units_to_metres=units_to_metres))


def dumps_opencv_rig(rig: Rig, path: str | os.PathLike, *, units_to_metres: float = 1.0) -> str:
    """The text :func:`write_opencv_rig` writes to ``path`` (its suffix, the one before any ``.gz``, picks YAML, XML
    or JSON; errors name it; :func:`write_opencv_text` writes it, gzipped for ``.gz``), checked
    as it is, nothing written: ``ghcal export`` keeps the file it replaces only once the export can be made."""
    if problem := gzip_name_problem(path):
        raise fail(path, None, problem)
    units = check_units(units_to_metres)
    refuse_skew(rig.cameras, f"an OpenCV {_format_name(path)} file")
    fs = _memory_writer(path)
    if format_suffix(path) != ".json":  # OpenCV writes comments into JSON as //, which JSON has not
        fs.writeComment(" ghnerf rig exported for OpenCV FileStorage; R, T map rig -> camera (X_cam = R X + T)")
    fs.write("rig_id", rig.rig_id)
    fs.write("units_to_metres", float(units))
    fs.write("working_volume_min", np.ascontiguousarray(rig.volume.min_corner.reshape(3, 1)))  # metres
    fs.write("working_volume_max", np.ascontiguousarray(rig.volume.max_corner.reshape(3, 1)))
    levelling = levelling_of(rig)
    if levelling is not None:  # the rig frame is levelled: read back, the rig needs no --camera-height
        fs.write(LEVELLING_KEYS[0], levelling["reference"])
        for key, name in zip(LEVELLING_KEYS[1:], ("camera_height_m", "pitch_deg", "roll_deg")):
            fs.write(key, float(levelling[name]))
    fs.startWriteStruct("cameras", cv2.FileNode_SEQ)
    for cam in rig.cameras:
        fs.startWriteStruct("", cv2.FileNode_MAP)
        _write_camera(fs, cam, units, with_name=True)
        fs.endWriteStruct()
    fs.endWriteStruct()
    text = fs.releaseAndGetString()
    strings = {"rig_id": (lambda root: root.getNode("rig_id"), rig.rig_id)}
    for i, cam in enumerate(rig.cameras):
        strings[f"cameras[{i}].name"] = (lambda root, i=i: root.getNode("cameras").at(i).getNode("name"), cam.name)
    if levelling is not None:  # the first camera's name again: checked above, named as the camera's
        strings[LEVELLING_KEYS[0]] = (lambda root: root.getNode(LEVELLING_KEYS[0]), levelling["reference"])
    _check_strings_read_back(text, path, strings)
    return text


def write_opencv_camera(camera: Camera, path: str | os.PathLike, *, units_to_metres: float = 1.0) -> None:
    """Write the single-camera layout, plus ``name``, ``R`` and ``T`` (readers that do not know them ignore them)."""
    units = check_units(units_to_metres)
    refuse_skew([camera], f"an OpenCV {_format_name(path)} file")
    fs = _memory_writer(path)
    _write_camera(fs, camera, units, with_name=True)
    fs.write("units_to_metres", float(units))
    text = fs.releaseAndGetString()
    _check_strings_read_back(text, path, {"name": (lambda root: root.getNode("name"), camera.name)})
    write_opencv_text(path, text)
