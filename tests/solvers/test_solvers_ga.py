"""GA: closed loop, determinism, bounds, options, stopping rules, batches."""

import numpy as np
import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.solvers import CONSTRAINT_TOL, SolveProblem
from hapticsdk_ga._common import Evaluator
from hapticsdk_ga.ga import GASolver


def test_paper_defaults():
    o = GASolver.default_options
    assert (o["population"], o["generations"], o["tournament"]) == (100, 50, 2)
    assert (o["crossover_fraction"], o["mutation_rate"]) == (0.6, 0.2)
    assert o["elite_count"] == 5


def test_closed_loop_batch(problem, fx):
    res = GASolver().solve(problem, seed=3)
    assert len(res) == problem.n_targets
    err, viol = fx.closed_loop(problem, res.x)
    assert np.all(err <= problem.tolerance) and np.all(viol <= CONSTRAINT_TOL)
    assert np.allclose(err, res.error)
    assert res.success.all()
    assert np.all(problem.space.contains(res.x))
    # trace: one row per generation (+ initial), monotone best error thanks to elitism
    best = [r["best_error"] for r in res.trace]
    assert len(best) == res.nit + 1
    assert np.all(np.diff([r["nfev"] for r in res.trace]) > 0)


def test_trace_monotone_with_elitism(fx):
    p = fx.make_problem(n=5, seed=7)
    res = GASolver(target_error=0, generations=15).solve(p, seed=1)
    for i in range(5):
        e = [row["best_error"] for row in res[i].trace]
        assert np.all(np.diff(e) <= 1e-15)


def test_deterministic_per_seed(problem):
    a = GASolver(generations=10).solve(problem, seed=11)
    b = GASolver(generations=10).solve(problem, seed=11)
    c = GASolver(generations=10, target_error=0).solve(problem, seed=12)
    assert np.array_equal(a.x, b.x)
    assert not np.array_equal(a.x, c.x)


def test_single_target_returns_one_result(fx, model):
    t = fx.reachable_targets(model, 1, seed=5)[0]
    p = fx.make_problem(t, model=model)
    r = GASolver().solve(p, seed=0)
    assert r.success and r.x.shape == (5,)
    err, _ = fx.closed_loop(p, r.x)
    assert err[0] == pytest.approx(r.error)


def test_stops_on_tolerance_and_on_generations(problem):
    r = GASolver().solve(problem, seed=0)
    # solved targets leave the active set: fewer rows evaluated than the full budget
    assert r.nfev < problem.n_targets * 100 * 51
    r1 = GASolver(generations=500).solve(problem, seed=0)
    assert r1.nit < 500 and "all targets within target_error" in r1[0].message
    r0 = GASolver(generations=0).solve(problem, seed=0)
    assert r0.nit == 0 and r0.nfev == problem.n_targets * 100
    r2 = GASolver(generations=3, target_error=0).solve(problem, seed=0)
    assert r2.nit == 3 and "generations exhausted" in r2[0].message


def test_time_budget_stops(problem):
    r = GASolver(generations=10_000, target_error=0, time_budget_s=1e-9).solve(problem, seed=0)
    assert r.nit == 0 and "time budget" in r[0].message


def test_x0_is_kept_by_elitism(fx, model):
    X = fx.feasible_points(model, 4, seed=9)
    p = fx.make_problem(model.predict(X), model=model, x0=X)
    r = GASolver(generations=0).solve(p, seed=0)
    assert np.all(r.error < 1e-12)


def test_penalty_forms_and_evaluator(fx, model):
    for form in ("paper", "normalised"):
        p = fx.make_problem(n=4, model=model, penalty=form)
        X = p.space.random(4 * 7, np.random.default_rng(0)).reshape(4, 7, 5)
        f, e, v = Evaluator(p)(X)
        d = p.evaluate(X, details=True)
        assert np.allclose(f, d["fitness"]) and np.allclose(e, d["error"]) and np.allclose(v, d["violation"])
        rows = np.array([2, 0])
        f2, _, _ = Evaluator(p)(X[rows], rows)
        assert np.allclose(f2, d["fitness"][rows])
        assert GASolver().solve(p, seed=1).success.all()


@pytest.mark.parametrize("opts", [{"population": 1}, {"generations": -1}, {"tournament": 0},
                                  {"crossover_fraction": 1.5}, {"mutation_rate": -0.1},
                                  {"elite_count": 100}, {"time_budget_s": 0}, {"init": "lhs"},
                                  {"population": 10.5}, {"target_error": -1}])
def test_bad_options_raise_before_work(problem, opts):
    with pytest.raises(ValidationError) as ei:
        GASolver(**opts).solve(problem, seed=0)
    assert ei.value.field.startswith("options.")


def test_unknown_option():
    with pytest.raises(ValidationError, match="valid"):
        GASolver(popsize=10)


def test_no_elitism_still_solves(problem):
    r = GASolver(elite_count=0, generations=80).solve(problem, seed=2)
    assert np.median(r.error) <= problem.tolerance


def test_degenerate_bounds(fx, model):
    """Two features pinned by lower == upper: they stay there, the rest still solves."""
    X = fx.feasible_points(model, 6, seed=4)
    lo, hi = fx.LOWER.copy(), fx.UPPER.copy()
    lo[2] = hi[2] = 120.0   # Fpeak pinned
    lo[0] = hi[0] = 1.5     # GS pinned
    X[:, 2], X[:, 0] = 120.0, 1.5
    X[:, 1] = np.maximum(X[:, 1], 3.3 ** 2 / 3.0 + 0.1)
    space = fx.make_space(lo, hi)
    p = SolveProblem(model.predict(X), ("hardness", "roughness"), model, space, constraints=fx.constraints())
    r = GASolver(generations=100).solve(p, seed=0)
    assert np.all(r.x[:, 2] == 120.0) and np.all(r.x[:, 0] == 1.5)
    assert np.median(r.error) <= p.tolerance


def test_all_features_degenerate(fx, model):
    x = fx.feasible_points(model, 1, seed=2)[0]
    space = fx.make_space(x, x)
    p = SolveProblem(model.predict(x)[0], ("hardness", "roughness"), model, space, constraints=fx.constraints())
    r = GASolver().solve(p, seed=0)
    assert np.array_equal(r.x, x) and r.error < 1e-12


def test_repeated_targets_and_large_batch(fx, model):
    t = fx.reachable_targets(model, 3, seed=21)
    T = np.repeat(t, 700, axis=0)          # 2100 targets, repeated
    p = fx.make_problem(T, model=model)
    r = GASolver(population=20, generations=4, target_error=0).solve(p, seed=0)
    assert r.x.shape == (2100, 5) and np.all(p.space.contains(r.x))
    err, _ = fx.closed_loop(p, r.x)
    assert np.allclose(err, r.error)
    # repeated targets share the stream position, not the answer: still all evaluated honestly
    assert len(np.unique(r.x[:700], axis=0)) > 1


def test_searching_a_subset_with_fixed_features(fx, model):
    X = fx.feasible_points(model, 5, seed=13)
    X[:, 2] = 100.0
    sub = model.feature_space.subset(("GS", "W", "AFpeak", "P"))
    p = SolveProblem(model.predict(X), ("hardness", "roughness"), model, sub, fixed={"Fpeak": 100.0},
                     constraints=fx.constraints())
    r = GASolver(generations=100).solve(p, seed=1)
    assert r.x.shape == (5, 4) and all(ri.x_dict["Fpeak"] == 100.0 for ri in r)
    assert np.median(r.error) <= p.tolerance


@pytest.mark.parametrize("size", [1, 2, 3])
def test_rank_selection_has_the_tournament_law(size):
    """Winners drawn through the ranks follow the law of a literal tournament of ``size``
    (drawn with replacement, lowest fitness wins): P(rank k) = ((p-k)^s - (p-k-1)^s) / p^s."""
    from hapticsdk_ga.ga import _rank_select
    rng = np.random.default_rng(5)
    r, p, n = 4, 20, 20000
    fit = rng.random((r, p))
    order = np.argsort(fit, axis=1)
    order_flat = order + (np.arange(r) * p)[:, None]
    win = _rank_select(order_flat, rng.random((r, n)), size)
    assert np.all(win // p == np.arange(r)[:, None])                 # each row picks its own
    rank = np.argsort(order, axis=1)                                  # rank of each individual
    got = np.bincount(rank.ravel()[win.ravel()], minlength=p) / win.size
    k = np.arange(p)
    law = ((p - k) ** size - (p - k - 1) ** size) / p ** size
    assert np.abs(got - law).max() < 4 * np.sqrt(law.max() / win.size)
    # the literal tournament, simulated, agrees with the law too (guards the formula)
    cand = rng.integers(0, p, size=(size, 200000))
    lit = np.bincount(cand.min(axis=0), minlength=p) / cand.shape[1]
    assert np.abs(lit - law).max() < 4 * np.sqrt(law.max() / cand.shape[1])


def test_generation_keeps_elites_and_bounds(fx):
    from hapticsdk_ga.ga import ga_generation
    rng = np.random.default_rng(2)
    r, p, d = 3, 30, 5
    lower, span = fx.LOWER, fx.UPPER - fx.LOWER
    pop = lower + rng.random((r, p, d)) * span
    fit = rng.random((r, p))
    new, esrc = ga_generation(pop, fit, lower, span, elite=4, n_cross=15, tournament=2,
                              mutation_rate=0.2, rng=rng)
    assert new.shape == pop.shape
    best4 = np.argsort(fit, axis=1)[:, :4]
    assert np.array_equal(esrc, best4 + (np.arange(r) * p)[:, None])
    assert np.array_equal(new[:, :4], np.take_along_axis(pop, best4[..., None], axis=1))
    assert np.array_equal(np.take(fit, esrc), np.sort(fit, axis=1)[:, :4])
    assert np.all((new >= lower) & (new <= lower + span))
    # crossover children: every gene comes from some parent of the same row, genes [:c]
    # from one parent and [c:] from another
    for i in range(r):
        for child in new[i, 4:19]:
            assert any(np.any(np.all(pop[i][:, :c] == child[:c], axis=1))
                       and np.any(np.all(pop[i][:, c:] == child[c:], axis=1)) for c in range(1, d))
    # mutation children: each gene is its parent's or a redraw within bounds; some differ
    mut = new[:, 19:]
    assert mut.shape[1] == p - 19
    same_as_some = [np.any(np.all(pop[i] == c, axis=1)) for i in range(r) for c in mut[i]]
    assert 0 < sum(same_as_some) < len(same_as_some)


def test_elites_not_reevaluated(problem):
    """The elites' fitness is reused: each generation evaluates population - elite rows."""
    res = GASolver(target_error=0, generations=6).solve(problem, seed=0)
    nfev = [row["nfev"] for row in res.trace]
    m = problem.n_targets
    assert nfev[0] == m * 100
    assert np.all(np.diff(nfev) == m * 95)


def test_mutation_law_rate_and_uniform_redraw(fx):
    """Mutation children: each gene changes with probability ``mutation_rate`` and then
    takes a value uniform within its bounds (binomial and histogram checks, 4 sigma)."""
    from hapticsdk_ga.ga import ga_generation
    rng = np.random.default_rng(9)
    r, p, d, rate = 40, 200, 5, 0.3
    lower, span = fx.LOWER, fx.UPPER - fx.LOWER
    pop = np.broadcast_to(lower + 0.123456 * span, (r, p, d)).copy()   # every parent equal
    new, _ = ga_generation(pop, rng.random((r, p)), lower, span, elite=0, n_cross=0, tournament=2,
                           mutation_rate=rate, rng=rng)
    changed = new != pop
    n = changed.size
    assert abs(changed.mean() - rate) < 4 * np.sqrt(rate * (1 - rate) / n)
    u = ((new - lower) / span)[changed]                 # the redrawn genes in unit coordinates
    assert u.min() >= 0 and u.max() < 1
    counts = np.histogram(u, bins=10, range=(0, 1))[0]
    k = u.size
    assert np.all(np.abs(counts - k / 10) < 4 * np.sqrt(k / 10 * 0.9))
    for j in range(d):                                  # every gene mutates, each at the rate
        assert abs(changed[..., j].mean() - rate) < 4 * np.sqrt(rate * (1 - rate) / (n / d))
