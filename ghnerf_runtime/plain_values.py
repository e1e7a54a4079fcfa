"""NumPy values where a Python one is asked for: one place for the checks the configs, the wire messages, the sink
URLs and the sizes share, and the JSON default of the training files (numpy only, so ``drivers`` and ``firmware_host``
import it without the runtime's heavier modules).

A NumPy scalar (np.int64, np.float32, np.bool_) comes from arrays and comparisons; kept as given it failed
``json.dumps`` later (a config's ``config_to_dict``, the file:// sink's worker), and ``np.True_`` is no ``bool`` to
``isinstance``, so a flag's check let it through as the number 1.
"""
from __future__ import annotations

import math
import numbers
import operator

import numpy as np

__all__ = ["converts_to_finite_float", "is_finite_number", "is_real_number", "is_true_false", "numpy_for_json",
           "plain_scalar", "whole_number_or_none", "whole_valued_or_none"]


def plain_scalar(value: object) -> object:
    """A NumPy scalar or 0-d array as the Python value it holds (np.int64 -> int, np.float32 -> float, np.bool_ ->
    bool, np.array(-5) -> -5), anything else as it is."""
    zero_d = isinstance(value, np.ndarray) and value.ndim == 0
    return value.item() if isinstance(value, np.generic) or zero_d else value


def is_true_false(value: object) -> bool:
    """Whether ``value`` is True/False, Python's or NumPy's: what a number's check refuses (True was read as 1)."""
    return isinstance(value, (bool, np.bool_))


def is_real_number(value: object) -> bool:
    """A real number, Python's or NumPy's, not True/False (finite or not: the caller bounds it)."""
    return isinstance(value, numbers.Real) and not is_true_false(value)


def is_finite_number(value: object) -> bool:
    """A real number (:func:`is_real_number`) that is neither NaN nor infinite. Not ``math.isfinite`` or
    ``np.isfinite``: an integer beyond float64 (10**400, from a JSON config) made them raise; it is finite."""
    return is_real_number(value) and value == value and abs(value) != float("inf")  # type: ignore[operator, arg-type]


def converts_to_finite_float(value: object) -> bool:
    """Whether ``math.isfinite`` finds ``value`` finite; False where it raises (None, text: TypeError; an int past
    float64: OverflowError). Narrower and cheaper than :func:`is_finite_number`, for checks on every call (that one
    added 11 % to ``slerp_rotation``, session 73): 10**400 is not finite here, and True/False and a 0-d array pass
    as the float they convert to (a caller that refuses them checks first)."""
    try:
        return math.isfinite(value)  # type: ignore[arg-type]
    except (TypeError, OverflowError):
        return False


def whole_number_or_none(value: object) -> int | None:
    """``value`` as a Python int where it is a whole number (a Python or NumPy integer: what ``operator.index``
    takes), not True/False; else None (a float, text: the caller says why in its own words)."""
    if is_true_false(value):
        return None
    try:
        return operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        return None


def whole_valued_or_none(value: object) -> int | None:
    """``value`` as a Python int where it is a number without a fraction (640, 640.0, np.int64(640),
    np.float32(640)), not True/False; else None (640.5, NaN, infinity, text). Wider than
    :func:`whole_number_or_none`: for sizes and pixel positions computed in floating point. A complex number,
    Python's or NumPy's, is None too: ``int`` refuses Python's but drops a NumPy one's imaginary part (with a
    warning), so np.complex128(640) was 640 where 640+0j was refused."""
    if is_true_false(value) or np.iscomplexobj(value):
        return None
    try:
        whole = int(value)  # type: ignore[call-overload]
    except (TypeError, ValueError, OverflowError):  # None, text that is no number, NaN, infinity
        return None
    return whole if whole == value else None  # int("640") == "640" is False: text is refused


def numpy_for_json(value: object) -> object:
    """A ``json.dumps`` default: a NumPy scalar as its Python value, an array as (nested) lists (a 0-d one as its
    value).

    :raises TypeError: for anything else, as ``json.dumps`` does without a default.
    """
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
