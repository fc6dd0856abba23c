"""The dimension ``timing`` rule's growth test (``dimension_rules._grows``): a tick cost
that grows with the run is caught even when one of its four points falls back, and an
unchanged cost whose fastest tick jumps once is not.

The points are fastest-tick costs (us) after 1, 2, 4 and 8 s, measured on the kit's
broken variant ``MedianOfAll`` (tests/testing/test_conformance_kit_in_use.py), whose tick
takes the median of every input so far. One run in 12 on a quiet machine, and once in a
suite run next to two busy loops, its 8 s point came out below its 4 s point, and the
old rule (every point rising) let it through."""

from __future__ import annotations

import pytest

from hapticsdk.testing.conformance import GROWTH_POINTS_S
from hapticsdk.testing.conformance.dimension_rules import _growth_exponent, _grows

GROWING = [
    (48.3, 83.1, 144.4, 285.1),   # the common runs
    (26.8, 44.2, 81.0, 150.0),
    (47.5, 80.2, 151.5, 149.7),   # the 8 s point fell back (missed by the old rule)
    (47.0, 75.7, 77.8, 200.1),    # the 4 s point barely rose
]
#: an unchanged cost whose fastest tick jumps once by 2 x (more than the 1.8 x memory-regime
#: jump seen), at each of the three places, and a slow drift of 10 % per doubling
STEADY = [(30, 30, 60, 60), (30, 60, 60, 60), (30, 30, 30, 60), (30, 33, 36.3, 39.9), (30, 29, 31, 30)]


def _pts(costs_us):
    return [(s, c * 1e-6) for s, c in zip(GROWTH_POINTS_S, costs_us)]


@pytest.mark.parametrize("costs", GROWING)
def test_a_cost_that_grows_with_the_run_is_caught_even_when_a_point_falls_back(costs):
    assert _grows(_pts(costs))


@pytest.mark.parametrize("costs", STEADY)
def test_a_steady_cost_with_one_jump_is_not_caught(costs):
    assert not _grows(_pts(costs))


def test_the_growth_exponent_is_the_log_log_slope():
    # independent reasoning: cost = c t^p gives exactly p, whatever c
    for p in (0.0, 0.5, 1.0, 2.0):
        assert _growth_exponent([(s, 3e-6 * s ** p) for s in GROWTH_POINTS_S]) == pytest.approx(p, abs=1e-12)
    # one step of factor r between the 2 s and 4 s points: 2 ln2 ln r / (5 ln2^2) = 0.4 log2 r
    assert _growth_exponent(_pts((30, 30, 60, 60))) == pytest.approx(0.4, abs=1e-12)
