"""hapticsdk.quantiles against numpy.percentile / numpy.median, bit for bit."""
import numpy as np
import pytest

from hapticsdk.quantiles import median, percentile

QS = [0.0, 10.0, 25.0, 50.0, 90.0, 99.0, 99.9, 100.0, 33.3]


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 10, 101, 1000])
def test_percentile_equals_numpy(n):
    rng = np.random.default_rng(n)
    for a in (rng.standard_normal(n), rng.integers(0, 4, n).astype(float), rng.exponential(1e-6, n)):
        assert percentile(a, QS) == [float(x) for x in np.percentile(a, QS)]
        assert percentile(a, 99.0) == float(np.percentile(a, 99.0))
        assert median(a) == float(np.median(a))


def test_nan_gives_nan_and_bad_input_is_refused():
    assert all(np.isnan(percentile([1.0, np.nan, 2.0], [10, 50])))
    with pytest.raises(ValueError):
        percentile([], 50)
    with pytest.raises(ValueError):
        percentile([1.0], 101)
