"""``joints3d.sorted_median``: the decoding's medians (session 71) are np.median's, to the bit, dtype and NaN included,
so that a faster median never moves a figure the estimator reports."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from ghnerf_runtime.joints3d import sorted_median


def _same(got, want) -> bool:
    """The same type (a numpy scalar or an array), dtype, shape and bits."""
    return (type(got) is type(want) and np.asarray(got).dtype == np.asarray(want).dtype
            and np.shape(got) == np.shape(want) and np.asarray(got).tobytes() == np.asarray(want).tobytes())


def _values(rng: np.random.Generator, trial: int, dtype) -> np.ndarray:
    n = int(rng.integers(1, 30))
    a = (rng.normal(size=n) * 10 ** rng.uniform(-5, 5)).astype(dtype)
    if trial % 5 == 0:
        a[rng.integers(0, n)] = -0.0
    if trial % 7 == 0:
        a[rng.integers(0, n)] = np.nan
    if trial % 11 == 0:
        a[rng.integers(0, n)] = -np.inf
    if trial % 13 == 0:
        a[:] = a[0]  # all tied (-0.0 ties included: np.median's mean sums from +0.0)
    return a


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_sorted_median_is_np_median_to_the_bit(dtype):
    rng = np.random.default_rng(71)
    for trial in range(3000):
        a = _values(rng, trial, dtype)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # (np.median of NaNs, on some numpy versions)
            assert _same(sorted_median(a), np.median(a)), a
            assert _same(sorted_median(list(a)), np.median(list(a))), a
            columns = a[: len(a) - len(a) % 2].reshape(-1, 2) if len(a) > 1 else a.reshape(1, 1)
            assert _same(sorted_median(columns, axis=0), np.median(columns, axis=0)), columns


def test_sorted_median_of_minus_zeros_and_a_nan_is_np_median_s():
    assert _same(sorted_median(np.array([-0.0, -0.0])), np.median(np.array([-0.0, -0.0])))  # 0.0, not -0.0
    assert _same(sorted_median(np.array([-0.0])), np.float64(0.0))
    assert np.isnan(sorted_median(np.array([1.0, np.nan, 2.0])))
    got = sorted_median(np.array([[1.0, 2.0], [np.nan, 4.0], [5.0, 6.0]]), axis=0)
    np.testing.assert_array_equal(got, [np.nan, 4.0])


def test_sorted_median_leaves_empty_slices_and_other_dtypes_to_np_median():
    for a in (np.array([3, 1, 2, 8]), np.array([1.5, 2.25], np.float16), [True, False, True]):
        assert _same(sorted_median(a), np.median(a))
    with pytest.warns(RuntimeWarning):
        assert np.isnan(sorted_median(np.array([])))
