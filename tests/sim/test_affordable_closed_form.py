"""The plan's largest affordable force in closed form (the cost is a convex quadratic in
the ramp's sum S, which rises with the force) against bisection and a dense grid: never
over the budget, never below the bisection's answer by more than its own resolution."""

import numpy as np
from hypothesis import given, settings, strategies as st

from hapticsdk.passivity import _affordable_scalar, affordable_force, plan_cost_j
from hapticsdk.passivity.plan import _BISECT, _affordable_bisect, _bisect_scalar

force = st.floats(0.0, 5.0)
ramp = st.floats(0.01, 3.3)
lead = st.floats(-2e-4, 2e-4)
push = st.one_of(st.just(0.0), st.floats(1e-7, 1e-3))
half_count = st.floats(0.0, 1e-4)
budget = st.floats(-2e-4, 2e-3)


@settings(max_examples=400, deadline=None)
@given(A=budget, p=force, s=ramp, up=st.floats(-1.0, 1.0), d=lead, cm=push, c=half_count)
def test_closed_form_is_the_largest_within_budget(A, p, s, up, d, cm, c):
    lo = p - s if p - s >= 0.0 else min(p + s, 0.0)
    hi = max(p + up * s, lo)
    a = _affordable_scalar(A, lo, hi, p, d, cm, s, c)
    ref = _bisect_scalar(A, lo, hi, p, d, cm, s, c)
    assert lo <= a <= hi
    # bisection stops within (hi - lo) 2^-_BISECT of the crossing, on its affordable side
    tol = (hi - lo) * 2.0 ** -(_BISECT - 1) + 1e-12 * (abs(hi) + s)
    if float(plan_cost_j(ref, p, d, cm, s, c)) <= A:
        assert float(plan_cost_j(a, p, d, cm, s, c)) <= A
        assert a >= ref - tol
        grid = np.linspace(lo, hi, 401)
        ok = grid[plan_cost_j(grid, p, d, cm, s, c) <= A]
        assert a >= ok.max() - tol
    else:
        # nothing fits: both give the ramp's lowest force
        assert a == lo == ref
    assert affordable_force(A, lo, hi, p, d, cm, s, c) == a


def test_vectorised_closed_form_equals_bisection():
    rng = np.random.default_rng(11)
    n = 20000
    p = rng.uniform(0, 3.3, n)
    s = rng.uniform(0.01, 3.3, n)
    lo = np.where(p - s >= 0, p - s, np.minimum(p + s, 0.0))
    hi = np.maximum(p + rng.uniform(-1, 1, n) * s, lo)
    d = rng.uniform(-2e-4, 2e-4, n)
    cm = rng.uniform(0, 1e-3, n) * rng.integers(0, 2, n)
    c = rng.uniform(0, 1e-4, n)
    # budgets around the cost of a force inside the range, so most answers are interior
    A = plan_cost_j(rng.uniform(lo, hi), p, d, cm, s, c) * rng.uniform(0.8, 1.2, n)
    a = affordable_force(A, lo, hi, p, d, cm, s, c)
    ref = _affordable_bisect(A, lo, hi, p, d, cm, s, c)
    interior = (a > lo) & (a < hi)
    assert interior.sum() > n // 4
    tol = (hi - lo) * 2.0 ** -(_BISECT - 1) + 1e-12 * (np.abs(hi) + s)
    assert np.all(np.abs(a - ref) <= tol)
    assert np.all((plan_cost_j(a, p, d, cm, s, c) <= A) | (a == lo))
