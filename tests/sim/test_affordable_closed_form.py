"""The plan's largest affordable force in closed form (the cost is a convex quadratic in
the ramp's sum S, which rises with the force) against bisection and a dense grid: never
over the budget, never below the bisection's answer by more than its own resolution."""

import numpy as np
import pytest

pytest.importorskip("hypothesis", reason="hypothesis (the test extra) is not installed")
from hypothesis import example, given, settings, strategies as st  # noqa: E402

from hapticsdk.passivity import _affordable_scalar, affordable_force, plan_cost_j  # noqa: E402
from hapticsdk.passivity.plan import _BISECT, _affordable_bisect, _bisect_scalar  # noqa: E402

force = st.floats(-5.0, 5.0)   # a held extra below 0 meets all three pieces of the cost
ramp = st.floats(0.01, 3.3)
lead = st.floats(-2e-4, 2e-4)
push = st.one_of(st.just(0.0), st.floats(1e-7, 1e-3))
half_count = st.floats(0.0, 1e-4)
budget = st.floats(-2e-4, 2e-3)


@settings(max_examples=400, deadline=None, derandomize=True, database=None)
@given(A=budget, p=force, s=ramp, up=st.floats(-1.0, 1.0), d=lead, cm=push, c=half_count)
# a feasible interval of 1e-83 N, which the bisection cannot see (found by hypothesis)
@example(A=0.0, p=1.0, s=1.0, up=0.0, d=-4.743468065667994e-87, cm=0.00025335694201713427, c=2.619190167828226e-188)
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
        # the bisection found nothing (its minimiser is resolved only to 2^-30 of the
        # range): the closed form gives the ramp's lowest force, or a force that fits in a
        # feasible interval too narrow for the bisection to see
        assert ref == lo
        assert a == lo or float(plan_cost_j(a, p, d, cm, s, c)) <= A
    assert affordable_force(A, lo, hi, p, d, cm, s, c) == a


def _typical(n, seed, least=0.0):
    """Draws of the tick's own sizes: forces up to 3.3 N (held forces from ``least``: below 0
    meets all three pieces of the cost; a quarter of them exactly 0, a contact's start),
    leads of +-0.2 mm, free-arm terms up to 1e-3 m/N, half counts up to 0.1 mm; budgets
    around the cost of a force inside the range, so most answers are interior."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(least, 3.3, n)
    p[rng.random(n) < 0.25] = 0.0    # a contact's first ticks: nothing held yet
    s = rng.uniform(0.01, 3.3, n)
    lo = np.where(p - s >= 0, p - s, np.minimum(p + s, 0.0))
    hi = np.maximum(p + rng.uniform(-1, 1, n) * s, lo)
    d = rng.uniform(-2e-4, 2e-4, n)
    cm = rng.uniform(0, 1e-3, n) * rng.integers(0, 2, n)
    c = rng.uniform(0, 1e-4, n)
    A = plan_cost_j(rng.uniform(lo, hi), p, d, cm, s, c) * rng.uniform(0.8, 1.2, n)
    return A, lo, hi, p, d, cm, s, c


@pytest.mark.parametrize("least", [0.0, -3.0])
def test_vectorised_closed_form_equals_bisection(least):
    A, lo, hi, p, d, cm, s, c = _typical(20000, 11, least)
    a = affordable_force(A, lo, hi, p, d, cm, s, c)
    ref = _affordable_bisect(A, lo, hi, p, d, cm, s, c)
    interior = (a > lo) & (a < hi)
    assert interior.sum() > a.size // 4
    tol = (hi - lo) * 2.0 ** -(_BISECT - 1) + 1e-12 * (np.abs(hi) + s)
    assert np.all(np.abs(a - ref) <= tol)
    assert np.all((plan_cost_j(a, p, d, cm, s, c) <= A) | (a == lo))


@pytest.mark.parametrize("least", [0.0, -3.0])
def test_the_closed_form_answers_without_the_bisection(monkeypatch, least):
    """The answers are checked and bisection takes over where a check fails, so a wrong
    closed form would still give right answers, only slower: on inputs of the tick's own
    sizes the bisection must not be needed (none in 20 000 draws of three seeds, measured)."""
    from hapticsdk.passivity import plan

    vec, scalar = [], []
    real_vec, real_scalar = plan._affordable_bisect, plan._bisect_scalar
    monkeypatch.setattr(plan, "_affordable_bisect", lambda *a: vec.append(a) or real_vec(*a))
    monkeypatch.setattr(plan, "_bisect_scalar", lambda *a: scalar.append(a) or real_scalar(*a))
    args = _typical(20000, 5, least)
    out = plan.affordable_force(*args)
    interior = (out > args[1]) & (out < args[2])
    assert interior.sum() > 5000
    for k in range(2000):
        plan._affordable_scalar(*(float(v[k]) for v in args))
    assert not vec and not scalar, (len(vec), len(scalar))


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
# half counts from 1 nm (subnormal ones lose the products' precision)
@given(a=st.floats(-5.0, 5.0), p=st.floats(-5.0, 5.0), s=ramp, c=st.one_of(st.just(0.0), st.floats(1e-9, 1e-4)))
def test_the_plan_pays_the_quantisation_term_the_book_adds_for_it(a, p, s, c):
    """With no motion (lead 0, no free arm) the cost is the booked bound's quantisation term
    over the plan's forces, ``(Delta/2) sum |dX|`` = ``(Delta/2) (|a - p| + |a|)`` (the step
    to ``a``, then a monotone ramp to 0): exactly, where ``S(a) = a``; above ``max(p, 0)``
    and ``s`` it charges ``S(a) >= a`` for ``|a|``. So it is also at least ``(Delta/2)|p|``,
    the bound's open tail now, which a bound of the true energy at the plan's end needs."""
    cost = float(plan_cost_j(a, p, 0.0, 0.0, s, c))
    book = c * (abs(a - p) + abs(a))
    slack = 1e-12 * c * (abs(a) + abs(p) + s)
    assert cost >= book - slack
    assert cost >= c * abs(p) - slack
    if a <= s or a < max(p, 0.0):
        assert cost == pytest.approx(book, rel=1e-12, abs=slack)


def test_the_benchmark_s_own_cells_need_no_bisection(monkeypatch):
    """The batch controller over 100 drawn cells (``draw_cells(100, 1)``) never falls back to
    the bisection. Two rounding edges did send it there (10 calls on these cells, 24 of
    9613 on 300): a force held at its last answer leaves a budget spent to the edge, whose
    root lands within rounding of the piece's edge; and a root within half a resolution
    above ``lo``, or a range ``hi - lo`` so small that a step back of 1e-12 of the force
    scale overshot the check's resolution."""
    from hapticsdk.benchmarks.stability_random import draw_cells, run_cells
    from hapticsdk.passivity import batch, plan

    calls, rows = [], []
    real = plan._affordable_bisect
    monkeypatch.setattr(plan, "_affordable_bisect", lambda *a: calls.append(a) or real(*a))

    def record(*args):
        out = plan.affordable_force(*args)
        rows.append(np.stack([np.broadcast_to(np.asarray(v, float), np.shape(out)) for v in (*args, out)], axis=1))
        return out
    monkeypatch.setattr(batch, "affordable_force", record)
    run_cells(draw_cells(100, 1), controllers=("sdk",))
    assert not calls, f"{len(calls)} batch calls fell back to the bisection"
    rows = np.concatenate(rows)
    A, lo, hi, p, d, cm, s, c, out = rows.T
    assert np.all((lo <= out) & (out <= hi))
    # the tick's scalar form, on the same inputs: the same answers, no bisection either
    scalar = []
    monkeypatch.setattr(plan, "_bisect_scalar", lambda *a: scalar.append(a) or 0.0)
    interesting = np.flatnonzero((out > lo) & (out < hi) | (np.abs(p) < 1e-9))
    for k in interesting:
        assert plan._affordable_scalar(*rows[k, :8].tolist()) == out[k], k
    assert not scalar, f"{len(scalar)} scalar calls fell back to the bisection"


@pytest.mark.parametrize("least", [0.0, -3.0])
def test_a_budget_one_ulp_under_hi_s_cost_needs_no_bisection(monkeypatch, least):
    """``hi`` just over the budget: where the cost still falls at ``hi`` (no force from the
    held one up fits) the answer can lie just under ``max(p, 0)``, below the pieces' jump;
    where it rises, within rounding under ``hi``. The closed form finds both, equal to the
    bisection's answer within its resolution, in the vectorised and the scalar form."""
    from hapticsdk.passivity import plan

    A, lo, hi, p, d, cm, s, c = _typical(20000, 3, least)
    A = np.nextafter(plan_cost_j(hi, p, d, cm, s, c), -np.inf)
    vec, scalar = [], []
    real_vec, real_scalar = plan._affordable_bisect, plan._bisect_scalar
    monkeypatch.setattr(plan, "_affordable_bisect", lambda *a: vec.append(a) or real_vec(*a))
    monkeypatch.setattr(plan, "_bisect_scalar", lambda *a: scalar.append(a) or real_scalar(*a))
    out = plan.affordable_force(A, lo, hi, p, d, cm, s, c)
    for k in range(20000):
        assert plan._affordable_scalar(*(float(v[k]) for v in (A, lo, hi, p, d, cm, s, c))) == out[k]
    assert not vec and not scalar, (len(vec), len(scalar))
    ref = real_vec(A, lo, hi, p, d, cm, s, c)
    tol = (hi - lo) * 2.0 ** -(_BISECT - 1) + 1e-12 * (np.abs(hi) + s)
    assert np.all(np.abs(out - ref) <= tol)
    assert np.all((plan_cost_j(out, p, d, cm, s, c) <= A) | (out == lo))


@pytest.mark.parametrize("least", [0.0, -3.0])
def test_a_budget_spent_to_hi_on_the_rising_side_answers_half_a_resolution_under_it(least):
    """A force held at its last answer spends the budget to the edge: with ``hi`` one ulp over
    the budget where the cost rises at ``hi``, only the root's rounding puts it at ``hi``,
    and the answer is half a bisection resolution under it (docs/runtime.md, Passivity:
    "the answer is half a resolution under the end"). So where the force half a
    resolution under ``hi`` fits, no answer lies lower, beyond the root's own rounding (a
    root that rounding left an ulp over the budget steps back half a resolution from
    where it landed; the same 1e-12 of the force scale as the tests above allow it); nor is
    any answer above ``hi`` or over the budget."""
    from hapticsdk.passivity import plan

    A, lo, hi, p, d, cm, s, c = _typical(20000, 3, least)
    A = np.nextafter(plan_cost_j(hi, p, d, cm, s, c), -np.inf)
    out = affordable_force(A, lo, hi, p, d, cm, s, c)
    P = plan._pieces(p, d, c)
    rising = plan._piece_slope(hi, P, cm, s) > 0.0
    half = hi - 0.5 * (hi - lo) * 2.0 ** -_BISECT
    room = rising & (hi > lo) & (half >= lo) & (plan_cost_j(half, p, d, cm, s, c) <= A)
    assert room.sum() > 1000          # the case is common on the tick's own sizes
    assert np.all(out[room] <= hi[room])
    assert np.all(plan_cost_j(out[room], p[room], d[room], cm[room], s[room], c[room]) <= A[room])
    rounding = 1e-12 * (np.abs(hi) + s)
    assert np.all(out[room] >= half[room] - rounding[room])
    for k in np.flatnonzero(room)[:500]:
        args = [float(v[k]) for v in (A, lo, hi, p, d, cm, s, c)]
        assert _affordable_scalar(*args) >= half[k] - rounding[k]


@pytest.mark.parametrize("least", [0.0, -3.0])
def test_a_budget_spent_exactly_to_hi_answers_hi(least):
    """``hi`` when it fits, and fitting is a cost at most the budget: with the budget exactly
    the cost of ``hi`` (as the same function computes it) the answer is ``hi`` itself, in
    the vectorised and in the scalar form (docs/runtime.md, Passivity: "`hi` when it
    fits")."""
    A, lo, hi, p, d, cm, s, c = _typical(2000, 7, least)
    A = plan_cost_j(hi, p, d, cm, s, c)
    assert np.array_equal(affordable_force(A, lo, hi, p, d, cm, s, c), hi)
    for k in range(2000):
        args = [float(v[k]) for v in (A, lo, hi, p, d, cm, s, c)]
        assert _affordable_scalar(*args) == args[2], k


@pytest.mark.parametrize("least, above", [(0.0, False), (-3.0, False), (0.0, True)])
def test_where_lo_does_not_fit_and_the_cost_rises_from_it_no_root_is_needed(monkeypatch, least, above):
    """The servo's most common case is settled before the roots (docs/runtime.md, Passivity:
    "Before the roots, one test settles the servo's most common case"): where ``lo`` does
    not fit and the cost rises from it, nothing fits, since the cost only rises further;
    the scalar form answers ``lo`` without a root, the piece walk or the bisection. Drawn
    with the budget one ulp under the cost of ``lo`` (``lo`` just does not fit), on the
    tick's own sizes, with a held force >= 0 (the fast path) and below 0, and with the
    range above the held force (``lo > p``: the fast path's piece from ``p`` up)."""
    from hapticsdk.passivity import plan

    A, lo, hi, p, d, cm, s, c = _typical(4000, 13, least)
    if above:
        lo = p + np.random.default_rng(14).uniform(0.0, 1.0, p.size) * s
        hi = np.maximum(hi, lo + s)
    A = np.nextafter(plan_cost_j(lo, p, d, cm, s, c), -np.inf)
    rising = (hi > lo) & (plan._piece_slope(lo, plan._pieces(p, d, c), cm, s) > 0.0)
    assert rising.sum() > 1000
    calls = []
    for name in ("_root_force", "_nothing_fits_scalar", "_bisect_scalar", "_checked_scalar"):
        real = getattr(plan, name)
        monkeypatch.setattr(plan, name, lambda *a, _n=name, _r=real: calls.append(_n) or _r(*a))
    for k in np.flatnonzero(rising):
        args = [float(v[k]) for v in (A, lo, hi, p, d, cm, s, c)]
        assert plan._affordable_scalar(*args) == args[1], k
        assert not calls, (k, calls)


@pytest.mark.parametrize("least", [0.0, -3.0])
def test_nothing_fits_is_declared_only_when_no_piece_has_room(least):
    """The closed form's "nothing fits" is checked at each piece's minimiser within
    ``[lo, hi]`` (docs/runtime.md, Passivity: ""nothing fits" must hold at each piece's
    minimiser too"): asked directly, the check answers ``lo`` only where no force in
    ``[lo, hi]`` fits (by a dense grid), and hands every other case to the bisection,
    whose answer fits; the pieces below the top one are checked as well."""
    from hapticsdk.passivity import plan

    A, lo, hi, p, d, cm, s, c = _typical(3000, 17, least)
    grid = np.linspace(0.0, 1.0, 201)
    below_top = 0
    for k in range(3000):
        args = [float(v[k]) for v in (A, lo, hi, p, d, cm, s, c)]
        xs = lo[k] + grid * (hi[k] - lo[k])
        fits = plan_cost_j(xs, p[k], d[k], cm[k], s[k], c[k]) <= A[k]
        out = plan._nothing_fits_scalar(*args)
        if out == lo[k] and not fits[0]:
            assert not fits.any(), k
        else:
            assert out == plan._bisect_scalar(*args)
            assert float(plan_cost_j(out, p[k], d[k], cm[k], s[k], c[k])) <= A[k]
            below_top += out < max(p[k], 0.0)
    assert below_top > 100           # answers on a piece under the top one
