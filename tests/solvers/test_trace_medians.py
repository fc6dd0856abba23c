"""The trace's per-iteration median (a partition, not np.median, for start-up time)."""
import numpy as np
import pytest

from hapticsdk.solvers.results import _row_medians


@pytest.mark.parametrize("cols", [1, 2, 3, 4, 7, 10])
def test_row_medians_equal_numpy_median(cols):
    rng = np.random.default_rng(cols)
    a = rng.standard_normal((9, cols))
    a[0] = 1.0  # ties
    np.testing.assert_array_equal(_row_medians(a), np.median(a, axis=1))


def test_row_medians_with_nan_follow_numpy():
    a = np.array([[1.0, np.nan, 3.0], [1.0, 2.0, 3.0]])
    np.testing.assert_array_equal(_row_medians(a), np.median(a, axis=1))
