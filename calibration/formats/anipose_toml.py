"""anipose / aniposelib ``calibration.toml``: read with ``tomllib``, written by a small emitter.

Layout (as aniposelib's ``CameraGroup.dump`` writes it): one table per camera, taken in
sorted section order (as aniposelib's ``CameraGroup.load``), plus an optional ``[metadata]`` table::

    [cam_0]
    name = "left"
    size = [1280, 800]                       # width, height (pixels)
    matrix = [[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]
    distortions = [k1, k2, p1, p2, k3]       # OpenCV order
    rotation = [rx, ry, rz]                  # Rodrigues vector, world -> camera
    translation = [tx, ty, tz]               # world -> camera, in the board's units

    [metadata]
    adjusted = false
    error = 0.31

Keys read per camera table: ``name`` (string or integer, as aniposelib writes the names it was given, numbers
included; default the table name),
``size``, ``matrix``, ``distortions``, ``rotation``, ``translation`` (all required) and
``fisheye`` (true or false; if true the file is rejected: the fisheye model is not supported). Other
keys are ignored. Every top-level table except ``metadata`` is a camera (``metadata`` must be a table too:
``metadata = 5`` is refused, naming it); from
``metadata`` an optional ``rig_id`` string, our ``working_volume_min``/``max``, our
``units_to_metres`` (checked against the argument) and our ``levelled_*`` keys (the first
camera's height and tilt in a levelled rig frame; :mod:`calibration.formats._frame`) are read
(our exporter writes them; aniposelib ignores them).

Units: anipose's translations are in whatever unit the calibration board was measured
in (often millimetres), so ``units_to_metres`` is a required argument. The world frame
is anipose's (usually the first camera or the board), not our floor-origin rig frame, unless
the file records a levelling that its poses show (``metadata["levelled"]``).
"""
from __future__ import annotations

import math
import os
import tomllib
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from calibration.formats._common import (
    as_array,
    check_units,
    fail,
    make_camera,
    make_rig,
    not_text_problem,
    refuse_skew,
    show,
)
from calibration.formats._frame import KEYS as LEVELLING_KEYS, levelling_metadata, levelling_of, recorded_levelling
from ghnerf_runtime.geometry.rig import Rig, WorkingVolume
from ghnerf_runtime.rig_file import write_text_atomic

_CAMERA_KEYS = ("size", "matrix", "distortions", "rotation", "translation")

__all__ = ["read_anipose_toml", "write_anipose_toml", "dumps_anipose_toml"]


def load_toml(path: str | os.PathLike) -> dict[str, Any]:
    """The TOML document in ``path``, or a :class:`RigFileError` naming the file and why it does not read: one
    reading for :func:`read_anipose_toml` and ``ghcal import``'s look for a recorded unit, which passed over a
    file not UTF-8 or nested too deeply and asked for --units-to-metres instead (session 75)."""
    try:
        raw = Path(path).read_bytes()
        if problem := not_text_problem(raw[:4096], "TOML"):
            raise fail(path, None, problem)
        text = raw.decode("utf-8-sig")  # a byte-order mark (Windows editors): tomllib refused line 1
    except OSError as e:
        raise fail(path, None, f"cannot read: {e.strerror or e}") from e
    except UnicodeDecodeError as e:
        raise fail(path, None, f"not UTF-8 text (byte {e.start}): {e.reason}") from e
    if not text.strip():  # read as a rig of no cameras, named as one
        raise fail(path, None, "the file is empty")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise fail(path, None, f"invalid TOML: {e}") from e
    except RecursionError as e:  # tomllib parses arrays and inline tables recursively: a traceback before
        raise fail(path, None, "invalid TOML: nested too deeply") from e


def read_anipose_toml(
    path: str | os.PathLike,
    *,
    units_to_metres: float,
    volume: WorkingVolume | None = None,
    rig_id: str | None = None,
) -> Rig:
    """Read an anipose ``calibration.toml``.

    Args:
        path: the TOML file.
        units_to_metres: metres per unit of ``translation`` (0.001 when the board was
            measured in millimetres). Required: anipose files do not say.
        volume: the working volume; default :func:`default_working_volume`.
        rig_id: default ``metadata.rig_id`` from the file, else the file's stem.

    Returns:
        The :class:`Rig`, cameras in sorted section order (as aniposelib loads them), metadata
        ``{"source": {"format": "anipose-toml", "path", "units_to_metres"}}``, plus ``"levelled"``
        where the file records a levelled frame that its poses show.

    Raises:
        RigFileError: naming the file and the field (``cam_1.matrix``); invalid TOML
            gives tomllib's line and column.
    """
    units = check_units(units_to_metres)
    p = Path(path)
    doc = load_toml(path)

    declared = doc.get("metadata", {}).get("units_to_metres") if isinstance(doc.get("metadata"), dict) else None
    if declared is not None:  # ours: the unit the writer was given; aniposelib files say nothing
        if isinstance(declared, bool) or not isinstance(declared, (int, float)) or not (math.isfinite(declared)
                                                                                     and declared > 0):
            # inf passed here and was then called a unit that contradicts the argument
            raise fail(path, "metadata.units_to_metres", f"must be a positive finite number, got {show(declared)}")
        if not math.isclose(float(declared), units, rel_tol=1e-9):
            raise fail(path, "metadata.units_to_metres", f"the file says {declared!r} m per unit, the argument "
                                                         f"{units!r}: the rig would be scaled by their ratio")
    cameras, fields = [], []
    file_rig_id, file_volume, levelling = None, None, None
    # aniposelib's CameraGroup.load takes the cameras in sorted key order, whatever the file's order
    for section, table in sorted(doc.items(), key=lambda item: item[0]):
        if not isinstance(table, dict):
            if section == "metadata":  # "must be a camera table" read as if a camera were wanted there
                raise fail(path, "metadata", f"must be a table ([metadata]), got {show(table)}")
            raise fail(path, section, f"top-level key must be a camera table, got {show(table)}")
        if section == "metadata":
            if "rig_id" in table:
                file_rig_id = table["rig_id"]
                if not isinstance(file_rig_id, str) or not file_rig_id:
                    raise fail(path, "metadata.rig_id", f"must be a non-empty string, got {show(file_rig_id)}")
            if "working_volume_min" in table or "working_volume_max" in table:  # ours: metres, rig frame
                lo, hi = (as_array(path, f"metadata.{k}", _numbers(path, f"metadata.{k}", table.get(k)), [(3,)],
                                   "a 3-vector (metres)") for k in ("working_volume_min", "working_volume_max"))
                if np.any(hi <= lo):
                    raise fail(path, "metadata.working_volume_max", f"must exceed working_volume_min, got {lo} .. {hi}")
                file_volume = WorkingVolume(lo, hi)
            levelling = recorded_levelling(path, table, prefix="metadata.")  # ours: the rig frame was levelled
            continue
        cameras.append(_camera(path, section, table, units))
        fields.append(section)
    metadata = levelling_metadata(cameras, levelling,
                                  {"format": "anipose-toml", "path": str(path), "units_to_metres": units})
    return make_rig(path, cameras, fields, volume=volume if volume is not None else file_volume,
                    rig_id=rig_id or file_rig_id or p.stem, metadata=metadata, list_field="cam_0",
                    pair_t=(path, f"{fields[1]}.translation" if len(fields) > 1 else "cam_1.translation"))


def _camera(path, section: str, table: dict, units: float):
    fisheye = table.get("fisheye", False)
    if not isinstance(fisheye, bool):
        # read by truth, an empty string or list passed as pinhole, and "false" was refused as a fisheye
        raise fail(path, f"{section}.fisheye", f"must be true or false (as aniposelib writes it), got {show(fisheye)}")
    if fisheye:
        raise fail(path, f"{section}.fisheye", "the fisheye model is not supported (only the OpenCV pinhole model)")
    for key in _CAMERA_KEYS:
        if key not in table:
            raise fail(path, f"{section}.{key}", f"missing required key {key!r} in camera table [{section}]")
    name = table.get("name", section)
    # aniposelib writes the names it was given, numbered cameras (1, 2) as TOML integers: those are names too
    if isinstance(name, bool) or not isinstance(name, (str, int)) or name == "":
        raise fail(path, f"{section}.name", f"must be a non-empty string, got {show(name)}")
    size = table["size"]
    if not isinstance(size, list) or len(size) != 2:
        raise fail(path, f"{section}.size", f"must be [width, height], got {show(size)}")
    rvec = as_array(path, f"{section}.rotation", _numbers(path, f"{section}.rotation", table["rotation"]), [(3,)],
                    "a Rodrigues 3-vector")
    R, _ = cv2.Rodrigues(rvec.reshape(3, 1))
    t = as_array(path, f"{section}.translation", _numbers(path, f"{section}.translation", table["translation"]),
                 [(3,)], "a 3-vector")
    return make_camera(
        path, section, name=str(name), width=size[0], height=size[1],
        K=_numbers(path, f"{section}.matrix", table["matrix"]),
        dist=_numbers(path, f"{section}.distortions", table["distortions"]),
        R=R, t=t * units, K_key="matrix", dist_key="distortions", R_key="rotation", t_key="translation",
        size_keys=("size", "size"),
    )


def _numbers(path, field: str, value: Any) -> Any:
    """Reject booleans and strings hiding in TOML arrays (numpy would coerce them)."""
    def walk(v):
        if isinstance(v, list):
            for x in v:
                walk(x)
        elif isinstance(v, bool) or not isinstance(v, (int, float)):
            raise fail(path, field, f"must contain only numbers, got {show(value)}")
    walk(value)
    return value


# --------------------------------------------------------------------------- writer
def _toml_string(s: str) -> str:
    out = ['"']
    for ch in s:
        code = ord(ch)
        if ch == '"':
            out.append('\\"')
        elif ch == "\\":
            out.append("\\\\")
        elif ch in "\b\t\n\f\r":
            out.append({"\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}[ch])
        elif code < 0x20 or code == 0x7F:
            out.append(f"\\u{code:04X}")
        else:
            out.append(ch)
    out.append('"')
    return "".join(out)


def _toml_float(x: float) -> str:
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"non-finite number {x}")
    text = repr(x)  # shortest round-trip form; always has '.', 'e' or is 'inf'/'nan'
    return text if any(c in text for c in ".e") else text + ".0"


def _toml_array(values) -> str:
    return "[" + ", ".join(_toml_float(v) for v in values) + "]"


def dumps_anipose_toml(rig: Rig, *, units_to_metres: float) -> str:
    """The ``calibration.toml`` text for ``rig`` (see the module docstring for the layout).

    Args:
        rig: the rig.
        units_to_metres: metres per unit of the written ``translation`` (0.001 writes mm).
    """
    units = check_units(units_to_metres)
    refuse_skew(rig.cameras, "an anipose calibration.toml")
    lines = [f"# anipose calibration written by ghnerf; translation unit = {units!r} m, rotation = Rodrigues (world -> camera)"]
    digits = len(str(len(rig.cameras) - 1))  # cam_00..cam_11: readers sort the sections (aniposelib does)
    for i, cam in enumerate(rig.cameras):
        rvec, _ = cv2.Rodrigues(np.ascontiguousarray(cam.R))
        dist = cam.dist if cam.dist.size else np.zeros(5)
        lines += [
            "",
            f"[cam_{i:0{digits}d}]",
            f"name = {_toml_string(cam.name)}",
            f"size = [{int(cam.width)}, {int(cam.height)}]",
            "matrix = [" + ", ".join(_toml_array(row) for row in cam.K) + "]",
            f"distortions = {_toml_array(dist)}",
            f"rotation = {_toml_array(rvec.reshape(-1))}",
            f"translation = {_toml_array(cam.t / units)}",
        ]
    lines += ["", "[metadata]", "adjusted = false", f"rig_id = {_toml_string(rig.rig_id)}",
              f"units_to_metres = {units!r}",  # read back and checked against the reader's argument
              f"working_volume_min = {_toml_array(rig.volume.min_corner)}",  # metres, whatever the translations'
              f"working_volume_max = {_toml_array(rig.volume.max_corner)}"]
    levelling = levelling_of(rig)
    if levelling is not None:  # the rig frame is levelled: read back, the rig needs no --camera-height
        lines += [f"{LEVELLING_KEYS[0]} = {_toml_string(levelling['reference'])}"]
        lines += [f"{key} = {_toml_float(levelling[name])}"
                  for key, name in zip(LEVELLING_KEYS[1:], ("camera_height_m", "pitch_deg", "roll_deg"))]
    return "\n".join(lines + [""])


def write_anipose_toml(rig: Rig, path: str | os.PathLike, *, units_to_metres: float) -> None:
    """Write ``rig`` as an anipose ``calibration.toml`` (atomically)."""
    write_text_atomic(path, dumps_anipose_toml(rig, units_to_metres=units_to_metres))
