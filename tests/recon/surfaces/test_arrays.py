"""``recon.surfaces._arrays.unique_sorted``: ``np.unique``'s values of integer arrays."""

import numpy as np
import pytest

from recon.surfaces._arrays import unique_sorted


@pytest.mark.parametrize("shape, low, high, dtype", [
    ((0,), 0, 1, np.int64),
    ((1,), -5, 5, np.int64),
    ((10_000,), -50, 50, np.int64),        # many repeats, negative values
    ((3_000, 3), 0, 2_000, np.int64),      # faces: flattened
    ((5_000,), 0, 2**40, np.int64),        # grid keys: mostly distinct
    ((4_000,), 0, 300, np.int32),
])
def test_unique_sorted_is_numpys_unique(shape, low, high, dtype):
    values = np.random.default_rng(3).integers(low, high, shape).astype(dtype)
    before = values.copy()
    got = unique_sorted(values)
    want = np.unique(values)
    assert got.dtype == want.dtype and got.shape == want.shape
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(values, before)  # the input is not sorted in place


def test_unique_sorted_refuses_floats():
    with pytest.raises(TypeError, match="integer"):
        unique_sorted(np.array([0.0, -0.0, np.nan]))
