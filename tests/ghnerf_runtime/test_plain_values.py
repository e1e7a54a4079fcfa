"""``ghnerf_runtime.plain_values``: the NumPy-value checks the configs, wire messages and sink URLs share."""
from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from ghnerf_runtime.plain_values import converts_to_finite_float, is_finite_number, is_real_number, is_true_false, \
    numpy_for_json, plain_scalar, whole_number_or_none, whole_valued_or_none


@pytest.mark.parametrize("value, plain", [(np.int64(7), 7), (np.float32(2.5), 2.5), (np.True_, True),
                                          (np.str_("a"), "a")])
def test_a_numpy_scalar_comes_back_as_the_python_value_it_holds(value, plain):
    out = plain_scalar(value)
    assert out == plain and type(out) is type(plain)


@pytest.mark.parametrize("value", [7, 2.5, True, "a", None, (1, 2)])
def test_anything_else_comes_back_as_it_is(value):
    assert plain_scalar(value) is value


def test_an_array_is_not_a_scalar_and_comes_back_as_it_is():
    a = np.arange(3)
    assert plain_scalar(a) is a


@pytest.mark.parametrize("value, expected", [(True, True), (np.False_, True), (1, False), (np.int8(0), False),
                                             ("yes", False), (None, False)])
def test_true_false_is_python_or_numpy_bool_alone(value, expected):
    assert is_true_false(value) is expected


@pytest.mark.parametrize("value", [3, -2.5, math.inf, math.nan, np.float32(0.5), np.uint16(9), Fraction(1, 3),
                                   10 ** 400])
def test_real_numbers_of_either_kind_are_real(value):
    assert is_real_number(value)


@pytest.mark.parametrize("value", [True, np.True_, "5", None, 1j, np.complex64(1), np.array([1.0])])
def test_true_false_text_complex_and_arrays_are_not(value):
    assert not is_real_number(value)


@pytest.mark.parametrize("value, whole", [(3, 3), (-7, -7), (np.int64(5), 5), (np.uint8(255), 255),
                                          (10 ** 30, 10 ** 30)])
def test_whole_numbers_of_either_kind_come_back_as_python_ints(value, whole):
    out = whole_number_or_none(value)
    assert out == whole and type(out) is int


@pytest.mark.parametrize("value", [True, np.False_, 2.0, np.float32(2), "2", None, Fraction(4, 2)])
def test_true_false_floats_and_text_are_no_whole_number(value):
    assert whole_number_or_none(value) is None


@pytest.mark.parametrize("value", [3, -2.5, np.float32(0.5), np.uint16(9), Fraction(1, 3), 10 ** 400, -(10 ** 400)])
def test_finite_numbers_of_either_kind_are_finite_an_integer_beyond_float64_too(value):
    assert is_finite_number(value)


@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan, np.float32("nan"), np.float64("-inf"), True,
                                   np.True_, "5", None, 1j, np.array([1.0])])
def test_non_finite_numbers_and_what_is_no_real_number_are_not_finite(value):
    assert not is_finite_number(value)


@pytest.mark.parametrize("value, plain", [(np.array(-5), -5), (np.array(2.5, dtype=np.float32), 2.5),
                                          (np.array(True), True)])
def test_a_zero_d_array_comes_back_as_the_python_value_it_holds(value, plain):
    out = plain_scalar(value)
    assert out == plain and type(out) is type(plain)


@pytest.mark.parametrize("value, whole", [(640, 640), (640.0, 640), (np.int64(-3), -3), (np.float32(8), 8),
                                          (10 ** 400, 10 ** 400), (Fraction(4, 2), 2)])
def test_numbers_without_a_fraction_come_back_as_python_ints(value, whole):
    out = whole_valued_or_none(value)
    assert out == whole and type(out) is int


@pytest.mark.parametrize("value", [True, np.True_, 640.5, math.nan, math.inf, "640", b"640", np.str_("640"), None,
                                   1j, 640 + 0j, np.complex128(640), np.complex64(8), np.array(640 + 0j)])
def test_true_false_fractions_non_finite_numbers_and_text_are_not_whole_valued(value):
    assert whole_valued_or_none(value) is None


@pytest.mark.parametrize("value, plain", [(np.float32(2.5), 2.5), (np.int64(7), 7), (np.bool_(True), True),
                                          (np.array(3), 3), (np.arange(3), [0, 1, 2])])
def test_numpy_values_are_written_to_json_as_python_values(value, plain):
    out = numpy_for_json(value)
    assert out == plain and type(out) is type(plain)


def test_what_is_not_numpy_is_left_to_json_to_refuse():
    with pytest.raises(TypeError, match="not JSON serialisable: object"):
        numpy_for_json(object())


@pytest.mark.parametrize("value, finite", [
    (0.5, True), (np.float32(2.5), True), (np.int64(-3), True), (np.array(0.25), True), (Fraction(1, 3), True),
    (True, True), (np.True_, True),  # as the float they convert to: a caller that refuses them checks first
    (math.nan, False), (-math.inf, False), (np.float64("nan"), False),
    (10**400, False), (None, False), ("0.5", False), (1j, False),  # math.isfinite's OverflowError, TypeError
])
def test_converts_to_finite_float_is_math_isfinite_without_its_errors(value, finite):
    # the one check slerp_rotation's alpha and the estimator's capture time share (session 74: two copies before)
    assert converts_to_finite_float(value) is finite
