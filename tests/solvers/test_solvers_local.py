"""Polish (LM), GA+polish, DE, scipy DE, amortised table: closed loop and properties."""

import numpy as np
import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.solvers import CONSTRAINT_TOL, SolveProblem
from hapticsdk_ga.amortised import AmortisedSolver, AmortisedTable, _MEMO
from hapticsdk_ga.de import DESolver, ScipyDESolver
from hapticsdk_ga.polish import GAPolishSolver, PolishSolver


def _check(problem, res, fx, err_max):
    err, viol = fx.closed_loop(problem, res.x)
    assert np.allclose(err, res.error)
    assert np.all(np.percentile(err, 90) <= err_max), err
    assert np.all(viol[err <= problem.tolerance] <= CONSTRAINT_TOL)
    assert np.all(problem.space.contains(res.x))


@pytest.mark.parametrize("solver,err_max", [(PolishSolver(), 1e-5), (GAPolishSolver(), 1e-5),
                                            (DESolver(), 1e-2), (DESolver(strategy="rand1bin", generations=150), 1e-2)])
def test_closed_loop(problem, fx, solver, err_max):
    res = solver.solve(problem, seed=4)
    _check(problem, res, fx, err_max)
    assert len(res.trace) >= 2


def test_scipy_de_closed_loop(fx, model):
    p = fx.make_problem(n=3, model=model, seed=8)
    res = ScipyDESolver().solve(p, seed=0)
    _check(p, res, fx, 1e-2)
    a = ScipyDESolver(maxiter=5, target_error=0).solve(p, seed=1)
    b = ScipyDESolver(maxiter=5, target_error=0).solve(p, seed=1)
    assert np.array_equal(a.x, b.x)


def test_polish_meets_active_constraint(fx, model):
    """Targets produced ON the work constraint (W == MF^2/(2 GS)): the answer must meet it."""
    X = fx.feasible_points(model, 6, seed=31)
    X[:, 1] = 3.3 ** 2 / (2 * X[:, 0])
    X = np.clip(X, fx.LOWER, fx.UPPER)
    X[:, 1] = np.maximum(X[:, 1], 3.3 ** 2 / (2 * X[:, 0]))
    p = fx.make_problem(model.predict(X), model=model, x0=X * np.array([1.02, 1.0, 0.97, 1.0, 1.0]))
    res = PolishSolver(start="x0").solve(p, seed=0)
    err, viol = fx.closed_loop(p, res.x)
    assert np.all(viol <= CONSTRAINT_TOL) and np.all(err <= 1e-4)


def test_polish_from_x0_is_deterministic_and_batch_equals_single(fx, model):
    X = fx.feasible_points(model, 5, seed=17)
    x0 = np.clip(X * 1.05, fx.LOWER, fx.UPPER)
    T = model.predict(X)
    p = fx.make_problem(T, model=model, x0=x0)
    batch = PolishSolver(start="x0").solve(p, seed=None)
    for i in range(5):
        single = PolishSolver(start="x0").solve(fx.make_problem(T[i], model=model, x0=x0[i]), seed=None)
        assert np.allclose(single.x, batch.x[i], rtol=1e-9, atol=1e-12)


def test_polish_x0_required(problem):
    with pytest.raises(ValidationError, match="x0"):
        PolishSolver(start="x0").solve(problem)
    with pytest.raises(ValidationError):
        PolishSolver(start="nowhere").solve(problem)


def test_de_degenerate_bounds_and_determinism(fx, model):
    X = fx.feasible_points(model, 4, seed=3)
    lo, hi = fx.LOWER.copy(), fx.UPPER.copy()
    lo[3] = hi[3] = X[0, 3]
    X[:, 3] = X[0, 3]
    X[:, 4] = np.maximum(X[:, 4], X[0, 3] ** 2 * 0.5 + 0.01)
    p = SolveProblem(model.predict(X), ("hardness", "roughness"), model, fx.make_space(lo, hi),
                     constraints=fx.constraints())
    for S in (DESolver(generations=150), ScipyDESolver(), PolishSolver()):
        r = S.solve(p, seed=2)
        assert np.all(r.x[:, 3] == X[0, 3])
        assert np.median(r.error) <= p.tolerance
    a, b = DESolver(generations=5).solve(p, seed=9), DESolver(generations=5).solve(p, seed=9)
    assert np.array_equal(a.x, b.x)


def test_amortised_table_cache_and_lookup(fx, model, tmp_path):
    _MEMO.clear()
    p = fx.make_problem(n=15, model=model, seed=6)
    S = AmortisedSolver(grid=31, build_samples=4000, build_iter=10, cache_dir=str(tmp_path), polish_steps=3)
    res = S.solve(p, seed=0)
    _check(p, res, fx, p.tolerance)  # coarse 31 x 31 grid + 3 LM steps
    files = list((tmp_path / "amortised").glob("*.npz"))
    assert len(files) == 1
    tab = S.table(p)
    assert tab.X.shape == (31, 31, 5) and tab.reachable_fraction(p.tolerance) > 0.2
    assert S.table(p) is tab                           # the problem's setup memo
    assert tab.build_time_s > 0 and tab.source == "built"
    # disk cache round trip gives the same table (a fresh problem of the same setup)
    _MEMO.clear()
    tab2 = S.table(fx.make_problem(n=15, model=model, seed=6))
    assert tab2.source == "disk cache" and tab2.build_time_s == tab.build_time_s
    assert tab2 is not tab and np.array_equal(tab2.X, tab.X) and tab2.key == tab.key
    assert np.array_equal(AmortisedTable.load(files[0]).X, tab.X)
    # lookup: a node returns the node's features exactly; batch equals one-by-one
    node = tab.lookup((10 / 30, 20 / 30))
    assert np.allclose(node, tab.X[10, 20])
    many = tab.lookup(p.targets)
    one = np.array([tab.lookup(t) for t in p.targets])
    assert np.allclose(many, one, rtol=1e-12, atol=1e-12)
    # a different model gets a different key (the key hashes the model's outputs)
    p2 = fx.make_problem(n=3, model=fx.make_model(seed=5), seed=6)
    from hapticsdk_ga.amortised import problem_key
    opts = {"grid": 31, "build_samples": 4000, "build_iter": 10}
    assert problem_key(p2, opts) != problem_key(p, opts)


def test_amortised_no_disk_cache(fx, model, tmp_path, monkeypatch):
    monkeypatch.setenv("HAPTICSDK_CACHE_DIR", str(tmp_path))
    p = fx.make_problem(n=4, model=model, seed=16)
    S = AmortisedSolver(grid=11, build_samples=2000, build_iter=5, cache=False, polish_steps=0)
    S.solve(p, seed=0)
    assert not (tmp_path / "amortised").exists()
    with pytest.raises(ValidationError):
        AmortisedSolver(grid=1).solve(p)
