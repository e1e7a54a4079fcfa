"""Float joints -> wire integers (pure numpy).

Rules (docs/protocol.md, "Rig frame and quantisation"):
- coordinates are rounded to the nearest millimetre (3D) or quarter pixel (2D);
- a joint is missing when any coordinate or its confidence is NaN, its
  confidence is <= 0, or a coordinate does not fit in int16; a missing joint is
  sent as zeros with its bit set in the mask;
- confidence 0..1 maps to 1..255 for present joints, so 0 always means missing; a
  confidence above 1 (inf included) is sent as 255.
"""
from __future__ import annotations

import numpy as np

from firmware_host.protocol.constants import UV_SCALE

_I16_MIN, _I16_MAX = -32768, 32767
_MM_PER_M = 1000.0


def _rounded(values: np.ndarray, scale: float) -> np.ndarray:
    """``values`` in wire units (mm, quarter pixels), rounded to the nearest one; call within np.errstate (a value
    past about 1e305 overflows to inf)."""
    return np.rint(np.asarray(values, np.float64) * scale)


def _fit_int16(scaled: np.ndarray) -> np.ndarray:
    """Per row: whether every rounded value is a number within int16 (NaN and inf are not)."""
    return ((scaled >= _I16_MIN) & (scaled <= _I16_MAX)).all(axis=1)


def xyz_fits_the_wire(xyz_m: np.ndarray) -> np.ndarray:
    """(J,3) rig-frame metres -> (J,) whether each joint's coordinates fit a JOINTS message once rounded to the
    nearest millimetre (-32.768 m and 32.7674 m do, 32.7676 m does not; NaN and inf do not): the encoder's own
    rule, for a sink that must leave out what the wire would mark missing (vmc://)."""
    with np.errstate(invalid="ignore", over="ignore"):  # inf and NaN fail the bound: nothing to warn
        return _fit_int16(_rounded(xyz_m, _MM_PER_M))


def _quantise(values: np.ndarray, conf: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    # A coordinate (or confidence) past about 1e305 overflows to inf when scaled; the rules below make it
    # missing (or 255), so numpy's "overflow encountered" warning told nothing, and under -W error it raised.
    with np.errstate(invalid="ignore", over="ignore"):
        scaled = _rounded(values, scale)
        conf = conf.astype(np.float64)
        missing = ~_fit_int16(scaled) | ~(conf > 0.0)  # NaN confidence fails "> 0" too
        q = np.where(missing[:, None], 0.0, scaled).astype(np.int16)
        c = np.clip(np.rint(conf * 255.0), 1.0, 255.0)
        c = np.where(missing, 0.0, c).astype(np.uint8)
    return q, c, missing


def quantise_joints_3d(joints_3d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(J,4) metres + confidence -> (xyz_mm int16 (J,3), conf uint8 (J,), missing bool (J,))."""
    j = np.asarray(joints_3d)
    return _quantise(j[:, :3], j[:, 3], _MM_PER_M)


def quantise_joints_2d(joints_2d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(J,3) pixels + confidence -> (uv quarter-pixels int16 (J,2), conf uint8, missing bool)."""
    j = np.asarray(joints_2d)
    return _quantise(j[:, :2], j[:, 2], float(UV_SCALE))
