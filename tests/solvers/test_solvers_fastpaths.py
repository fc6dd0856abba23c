"""The GA's inner-loop fast paths give exactly the numbers of the general code.

* ``_generation_one`` (one row, buffers reused) vs ``ga_generation`` without a workspace;
* ``SolveProblem.evaluate`` with reused :class:`~hapticsdk.solvers.EvalBuffers` (and the
  lazy violation, ``EvalBuffers.violation_at``) vs a plain ``evaluate``;
* a whole GA run (one target, and a batch) with the fast paths vs with them switched off.

Exact equality throughout: the fast paths run the same floating-point operations in the
same order, only into preallocated memory.
"""

import numpy as np
import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.solvers import Trace

import hapticsdk_ga._common as common
import hapticsdk_ga.ga as ga


@pytest.mark.parametrize("d, elite, n_cross, tournament, rate", [
    (5, 5, 57, 2, 0.2),      # the paper's settings
    (5, 0, 30, 3, 0.5),
    (5, 2, 0, 1, 1.0),       # mutation only, every gene redrawn
    (1, 1, 10, 2, 0.3),      # one gene: no crossover cut
    (4, 3, 20, 2, 0.0),      # no mutation
])
def test_one_row_generation_equals_general_path(fx, d, elite, n_cross, tournament, rate):
    p = 100
    lower, span = fx.LOWER[:d], (fx.UPPER - fx.LOWER)[:d]
    seed_rng = np.random.default_rng(7)
    pop0 = lower + seed_rng.random((1, p, d)) * span
    work = ga.GAWorkspace(1, p, d, elite, n_cross)
    work.pops[0][:] = pop0
    pop_fast, pop_gen = work.pops[0], pop0.copy()
    r_fast, r_gen = np.random.default_rng(11), np.random.default_rng(11)
    for _ in range(6):      # several generations: both buffers, the cached views and tables
        fit = seed_rng.random((1, p))
        new_gen, e_gen = ga.ga_generation(pop_gen, fit, lower, span, elite=elite, n_cross=n_cross,
                                          tournament=tournament, mutation_rate=rate, rng=r_gen)
        new_fast, e_fast, children = ga._generation_one(pop_fast, fit.argsort(axis=1), lower, span, elite,
                                                        n_cross, tournament, rate, r_fast, work)
        assert np.array_equal(new_fast, new_gen)
        assert np.array_equal(e_fast, e_gen)
        assert np.array_equal(children, new_gen[:, elite:])
        assert new_fast.base is work.pops[0] or new_fast.base is work.pops[1] or new_fast is work.pops[0]
        pop_fast, pop_gen = new_fast, new_gen
    assert r_fast.random() == r_gen.random()      # the same number of draws


def _X(problem, shape, seed):
    r = np.random.default_rng(seed)
    lo, hi = problem.space.lower, problem.space.upper
    X = lo + r.random(shape + (len(lo),)) * (hi - lo)
    X.reshape(-1, len(lo))[::7, 3] = 0.0     # AFpeak 0: a zero bound (|b| = 0 read as 1)
    X.reshape(-1, len(lo))[::5, 1] = 0.0     # W 0: violated
    return X


@pytest.mark.parametrize("form", ["paper", "normalised"])
@pytest.mark.parametrize("shape, rows", [((12, 95), None), ((4, 95), [1, 5, 6, 11]), ((3, 7), [0, 2, 9])])
def test_evaluate_with_buffers_equals_plain(problem, form, shape, rows):
    rows_a = None if rows is None else np.array(rows)
    w = problem.eval_buffers(shape, form)
    for seed in range(3):     # reused buffers: nothing of one call leaks into the next
        X = _X(problem, shape, seed)
        ref = problem.evaluate(X, penalty=form, details=True, rows=rows_a, finite=True)
        got = problem.evaluate(X, penalty=form, details=True, rows=rows_a, finite=True, work=w)
        for k in ("fitness", "error", "violation", "intensities"):
            assert np.array_equal(got[k], ref[k]), k
        assert (ref["violation"] > 0).any() and (ref["violation"] == 0).any()
        f, e, v = problem.evaluate_into(w, X, rows_a)
        assert np.array_equal(f, ref["fitness"]) and np.array_equal(e, ref["error"])
        assert np.array_equal(v, ref["violation"])
        # lazy: no violation array; violation_at gives the same numbers at any rows
        w.lazy = True
        f, e, v = problem.evaluate_into(w, X, rows_a)
        assert np.array_equal(f, ref["fitness"]) and np.array_equal(e, ref["error"])
        flat = ref["violation"].reshape(-1)
        if form == "paper":
            assert v is None
        idx = np.arange(flat.size)[::3]
        assert np.array_equal(w.violation_at(idx), flat[idx])
        assert w.violation_at(int(idx[-1])) == flat[idx[-1]]
        w.lazy = False
    if rows is not None:     # the same buffers, other targets of the same count
        other = np.array(sorted(set(range(problem.n_targets)) - set(rows))[:len(rows)])
        X = _X(problem, shape, 9)
        ref = problem.evaluate(X, penalty=form, details=True, rows=other, finite=True)
        got = problem.evaluate(X, penalty=form, details=True, rows=other, finite=True, work=w)
        assert np.array_equal(got["fitness"], ref["fitness"]) and np.array_equal(got["error"], ref["error"])


def test_buffers_of_another_shape_are_not_used(problem):
    X = _X(problem, (12, 95), 0)
    w = problem.eval_buffers((12, 50))
    ref = problem.evaluate(X, details=True)
    got = problem.evaluate(X, details=True, work=w)
    assert np.array_equal(got["fitness"], ref["fitness"])
    assert not np.shares_memory(got["fitness"], w.pen)
    with pytest.raises(ValidationError):
        problem.evaluate_into(w, X)


def test_trace_repeat_shares_the_last_row():
    t = Trace(2)
    with pytest.raises(ValueError):
        t.repeat(1)
    t.record(5, np.array([0.75, 0.5]), np.array([0.5, 0.5]))
    e, v = np.array([0.5, 0.25]), np.array([0.0, 0.125])
    t.record(10, e, v)
    e[:] = 9.0                       # the solver keeps updating its arrays: the trace has copies
    t.repeat(20)
    rows = t.per_target()
    assert [r["best_error"] for r in rows[1]] == [0.5, 0.25, 0.25]
    assert [r["constraint_violation"] for r in rows[1]] == [0.5, 0.125, 0.125]
    assert [r["nfev"] for r in rows[0]] == [5, 10, 20]


def _general_generation_one(pop, order, lower, span, elite, n_cross, tournament, rate, rng, work):
    """The general ga_generation in place of the one-row path (no workspace)."""
    out, esrc = ga.ga_generation(pop, None, lower, span, elite=elite, n_cross=n_cross, tournament=tournament,
                                 mutation_rate=rate, rng=rng, order=order)
    return out, esrc, out[:, elite:]


def _plain_evaluator_lazy(self, X, rows=None):
    """Evaluator.lazy without buffers: a plain evaluate, the violation computed in full."""
    d = self.problem.evaluate(X, details=True, rows=rows, finite=self.finite)
    self.nfev += d["fitness"].size
    return d["fitness"], d["error"], d["violation"]


@pytest.mark.parametrize("n, opts", [
    (1, dict(target_error=0, generations=12)),
    (12, dict(target_error=0, generations=12)),
    (12, dict(target_error=2e-3, generations=40)),    # targets leave the batch: fewer rows
    (1, dict(target_error=0, generations=12, init="nearest", stall_generations=4, population=40)),
])
def test_ga_run_equals_run_without_fast_paths(fx, model, monkeypatch, n, opts):
    problem = fx.make_problem(model=model, n=n)
    if n == 1:
        problem = problem.with_targets(problem.targets[0])    # one target: a SolveResult
    fast = ga.GASolver(**opts).solve(problem, seed=5)
    monkeypatch.setattr(ga, "_generation_one", _general_generation_one)
    monkeypatch.setattr(common.Evaluator, "lazy", _plain_evaluator_lazy)
    plain = ga.GASolver(**opts).solve(problem, seed=5)
    assert np.array_equal(np.asarray(fast.x), np.asarray(plain.x))
    assert np.array_equal(np.asarray(fast.fun), np.asarray(plain.fun))
    assert fast.nfev == plain.nfev
    strip = lambda tr: [{k: v for k, v in row.items() if k != "time_s"} for row in tr]  # noqa: E731
    assert strip(fast.trace) == strip(plain.trace)
    if n == 1:
        assert strip(fast.trace)[0] != strip(fast.trace)[-1]      # the run improved (a real check)


def test_work_constraint_fast_path_equals_masked_formula():
    """hardness.work: MF^2 / (2 GS) where GS > 0 and +inf elsewhere (0, -0.0, negative,
    NaN), whether every GS is positive (one plain division) or not; no warning."""
    dim = pytest.importorskip("hapticsdk_hardness.dimension")
    c = dim.WorkConstraint()
    mf2 = dim.MF_N ** 2

    def expected(gs):
        gs = np.asarray(gs, float)
        out = np.full(gs.shape, np.inf)
        pos = gs > 0
        out[pos] = mf2 / (2.0 * gs[pos])
        return out

    cases = [np.array([0.5, 1.0, 2.3, 10.0]), np.array([0.5, 0.0, 2.0]), np.array([1.0, -0.0]),
             np.array([3.0, -1.0]), np.array([np.nan, 1.0]), np.array([[1.0, 2.0], [4.0, 0.0]]),
             np.array([[1.0, 2.0], [4.0, 8.0]]), np.array(2.0), np.zeros(0)]
    with np.errstate(all="raise"):
        for gs in cases:
            bound, value = c.bound_and_value({"GS": gs, "W": np.ones(np.shape(gs))})
            assert np.array_equal(bound, expected(gs)), gs
            assert np.shape(bound) == np.shape(gs)


def _model_of(dims, seed=3):
    from hapticsdk.perception.models import MLPModel
    r = np.random.default_rng(seed)
    k = len(dims)
    w = {"W1": r.normal(size=(20, 5)) * 0.8, "b1": r.normal(size=20) * 0.3,
         "W2": r.normal(size=(k, 20)) * 0.4, "b2": r.normal(size=k) * 0.1,
         "x_min": np.asarray([0.0, 0.0, 0.0, 0.0, 0.0]), "x_max": np.asarray([10.0, 100.0, 500.0, 50.0, 500.0]),
         "y_min": np.zeros(k), "y_max": np.ones(k)}
    return w


@pytest.mark.parametrize("dims, targeted", [(("hardness", "roughness", "warmth"), ("hardness", "roughness", "warmth")),
                                            (("hardness", "roughness"), ("roughness",)),
                                            (("hardness", "roughness", "warmth"), ("warmth", "hardness"))])
@pytest.mark.parametrize("form", ["paper", "normalised"])
def test_buffers_equal_plain_for_other_than_two_targeted_dimensions(fx, dims, targeted, form):
    """The error term is summed over the targeted dimensions: with one or three of them
    (a third-party dimension next to the paper's two; one dimension alone), buffered,
    lazy and plain evaluation give the same fitness, error and violation (the two-column
    case has its own path; a three-dimension sum once read a buffer only that path fills)."""
    from hapticsdk.perception.models import MLPModel
    from hapticsdk.solvers import SolveProblem
    model = MLPModel(_model_of(dims), fx.NAMES, dims, feature_space=fx.make_space(), name="test-k")
    T = np.random.default_rng(4).uniform(0.1, 0.9, (6, len(targeted)))
    p = SolveProblem(T, targeted, model, model.feature_space, constraints=fx.constraints())
    for shape in ((6, 95), (6, 7)):
        w = p.eval_buffers(shape, form)
        w.err.fill(1e9)    # what a stale buffer would add
        for seed in range(2):
            X = _X(p, shape, seed)
            ref = p.evaluate(X, penalty=form, details=True, finite=True)
            got = p.evaluate(X, penalty=form, details=True, finite=True, work=w)
            for key in ("fitness", "error", "violation"):
                assert np.array_equal(got[key], ref[key]), (key, shape)
            w.lazy = True
            f, e, _ = p.evaluate_into(w, X)
            assert np.array_equal(f, ref["fitness"]) and np.array_equal(e, ref["error"])
            w.lazy = False
