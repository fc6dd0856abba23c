"""Unreachable and extreme targets, validation before work, many targets at once."""

import numpy as np
import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.solvers import Solver, SolverOutput
from hapticsdk_ga.amortised import AmortisedSolver
from hapticsdk_ga.de import DESolver
from hapticsdk_ga.ga import GASolver
from hapticsdk_ga.polish import GAPolishSolver, PolishSolver

SOLVERS = [GASolver(), DESolver(generations=30), PolishSolver(), GAPolishSolver(),
           AmortisedSolver(grid=21, build_samples=3000, build_iter=8, cache=False)]


@pytest.mark.parametrize("solver", SOLVERS, ids=lambda s: s.name)
def test_unreachable_targets_fail_with_residual(fx, solver):
    # a model whose outputs are scaled into (0.1, 0.9): a tanh output never reaches the
    # ends, so every target below is provably at least 0.1 + 0.1 away from reachable
    from hapticsdk.perception.models import MLPModel
    base = fx.make_model()
    w = dict(base.weights, y_min=np.full(2, 0.1), y_max=np.full(2, 0.9))
    model = MLPModel(w, base.feature_names, base.dimension_names, feature_space=base.feature_space)
    T = np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 1.0], [1.0, 0.0], [0.5, 0.0], [1.0, 1.0]])
    Y = model.predict(model.feature_space.random(20000, np.random.default_rng(0)))
    dist = np.abs(Y[None] - T[:, None]).sum(-1).min(1)   # best random sample, for reference
    p = fx.make_problem(T, model=model)
    res = solver.solve(p, seed=0)
    assert np.allclose(fx.closed_loop(p, res.x)[0], res.error)
    for r, t in zip(res, T):
        assert not r.success
        assert r.error > p.tolerance
        assert "target not reached" in r.message and "residual per dimension" in r.message
        assert np.all(p.space.contains(r.x))
    # the answer is the best that the solver found: no worse than the best random sample + slack
    assert np.all(res.error >= 0.1)
    if solver.name != "de":   # the nearest answer found meets the constraints
        assert np.all(np.array([r.constraint_violation for r in res]) <= 1e-9)
    if solver.name == "ga-polish":  # and is not far off the best of 20000 random samples
        assert np.median(res.error - dist) <= 0.05


def test_targets_at_0_and_1_are_answered_honestly(fx, model):
    T = np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 1.0], [1.0, 0.0], [0.0, 0.5], [1.0, 0.5]])
    p = fx.make_problem(T, model=model)
    res = GAPolishSolver().solve(p, seed=0)
    err, viol = fx.closed_loop(p, res.x)
    assert np.array_equal(res.success, (err <= p.tolerance) & (viol <= 1e-9))


def test_reachable_extremes_are_solved(fx, model):
    X = model.feature_space.random(20000, np.random.default_rng(1))
    cols = {n: X[:, i] for i, n in enumerate(fx.NAMES)}
    ok = np.ones(len(X), bool)
    for c in fx.constraints():
        ok &= c.violation(cols) == 0
    Y = model.predict(X[ok])
    idx = [Y[:, 0].argmin(), Y[:, 0].argmax(), Y[:, 1].argmin(), Y[:, 1].argmax()]
    p = fx.make_problem(Y[idx], model=model)
    res = GAPolishSolver().solve(p, seed=0)
    assert res.success.all(), [r.message for r in res]


@pytest.mark.parametrize("bad,field", [([np.nan, 0.5], "targets.hardness"), ([0.5, 1.2], "targets.roughness"),
                                       ([-0.1, 0.5], "targets.hardness"), ([[0.5, 0.5, 0.5]], "targets")])
def test_invalid_targets_raise_before_any_work(fx, model, bad, field):
    calls = []

    class Spy(Solver):
        name = "spy"

        def _solve(self, problem, rng, trace):
            calls.append(1)
            return SolverOutput(problem.space.clip(np.zeros((problem.n_targets, problem.n_features))), 0, 0)

    with pytest.raises(ValidationError) as ei:
        Spy().solve(fx.make_problem(bad, model=model))
    assert ei.value.field == field and not calls


def test_thousands_of_targets_polish(fx, model):
    T = fx.reachable_targets(model, 3000, seed=44)
    p = fx.make_problem(T, model=model)
    res = PolishSolver().solve(p, seed=0)
    err, viol = fx.closed_loop(p, res.x)
    assert len(res) == len(T) and np.allclose(err, res.error)
    assert np.mean(res.success) > 0.99
    assert np.all(p.space.contains(res.x))


def test_repeated_targets_each_solved(fx, model):
    t = fx.reachable_targets(model, 1, seed=45)
    p = fx.make_problem(np.repeat(t, 50, axis=0), model=model)
    assert PolishSolver().solve(p, seed=3).success.all()
    # the GA is stochastic with a fixed budget: nearly all copies succeed, each honestly scored
    r = GASolver().solve(p, seed=3)
    assert r.success.mean() >= 0.9 and np.allclose(fx.closed_loop(p, r.x)[0], r.error)


@pytest.mark.parametrize("name", ["S7", b"S7", "hardness 0.8, roughness 0.3"])
@pytest.mark.parametrize("dimensions", [None, ["hardness", "roughness"]])
def test_a_material_name_is_not_taken_for_intensities(name, dimensions):
    """hs.solve takes intensities; a name (what render() and scenes take) is refused with a
    pointer to the library, with or without dimensions, before any model is loaded. (Before,
    "S7" without dimensions was told to name its array's columns, and with them numpy
    read it as one string.)"""
    import hapticsdk as hs
    with pytest.raises(ValidationError) as ei:
        hs.solve(name, dimensions=dimensions)
    assert ei.value.field == "targets"
    assert "load_library().get(name).intensities" in str(ei.value) and repr(name) in str(ei.value)
    lib = hs.load_library()
    assert hs.solve(lib.get("S7").intensities, seed=1).success   # the way the message points to
