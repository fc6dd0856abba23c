"""build_problem / SolveProblem / Solver base, with in-process toy plugins."""

import numpy as np
import pytest

from hapticsdk import plugins
from hapticsdk.perception.dimensions import Constraint, DimensionRenderer, PerceptionDimension
from hapticsdk.errors import ModelError, SolverError, ValidationError
from hapticsdk.perception.features import Feature, FeatureSpace
from hapticsdk.perception.models import MLPModel
from hapticsdk.solvers.problems import build_problem, solve
from hapticsdk.solvers import Solver, SolverOutput


class MinWork(Constraint):
    """W >= 5.445 / GS"""
    name = "toy-work"
    features = ("GS", "W")

    def _bound_and_value(self, cols):
        return 3.3 ** 2 / (2 * cols["GS"]), cols["W"]


class _R(DimensionRenderer):
    def tick(self, inp):
        return []


class ToyHard(PerceptionDimension):
    name = "toyhard"
    features = (Feature("GS", "N/mm", 0.0, 100.0), Feature("W", "mJ", 0.0, 1000.0))
    default_model = "toymodel"

    def constraints(self, **ctx):
        return [MinWork()]

    def renderer(self, features, **kw):
        return _R()


class ToyRough(PerceptionDimension):
    name = "toyrough"
    features = (Feature("Fpeak", "Hz", 0.0, 250.0),)
    default_model = "toymodel"

    def renderer(self, features, **kw):
        return _R()


def toy_model():
    rng = np.random.default_rng(5)
    d, k = 4, 2
    w = dict(W1=rng.normal(size=(12, d)), b1=rng.normal(size=12) * 0.3, W2=rng.normal(size=(k, 12)) * 0.4,
             b2=np.zeros(k), x_min=np.array([0.1, 1.0, 20.0, 0.0]), x_max=np.array([4.5, 60.0, 200.0, 5.0]),
             y_min=np.full(k, 0.2), y_max=np.full(k, 0.8))  # outputs stay inside (0.2, 0.8)
    space = FeatureSpace((Feature("GS", "N/mm", 0.1, 4.5), Feature("W", "mJ", 1.0, 60.0),
                          Feature("Fpeak", "Hz", 20.0, 200.0), Feature("P", "", 0.0, 5.0)))
    return MLPModel(w, space.names, ["toyhard", "toyrough"], feature_space=space,
                    metadata={"feature_defaults": {"P": 1.5}}, name="toymodel")


class RandomSearch(Solver):
    """Test solver: best of n uniform samples per target, one model call."""
    name = "random"
    default_options = {"n": 4000, "lie": False}

    def _solve(self, problem, rng, trace):
        X = problem.space.random(problem.n_targets * self.options["n"], rng).reshape(
            problem.n_targets, self.options["n"], -1)
        f = problem.evaluate(X)
        best = X[np.arange(problem.n_targets), f.argmin(axis=1)]
        trace.record(X.shape[0] * X.shape[1], f.min(axis=1))
        if self.options["lie"]:  # a solver that returns garbage must not be believed
            best = problem.space.lower + 0 * best
        return SolverOutput(best, nfev=X.shape[0] * X.shape[1], nit=1)


@pytest.fixture(autouse=True)
def toys():
    plugins.registry("dimension").register("toyhard", ToyHard)
    plugins.registry("dimension").register("toyrough", ToyRough)
    model = toy_model()
    plugins.registry("model").register("toymodel", lambda: model)
    plugins.registry("solver").register("random", RandomSearch)
    from hapticsdk.solvers import problems
    problems._model_cache.pop("toymodel", None)
    yield model
    for kind, name in (("dimension", "toyhard"), ("dimension", "toyrough"), ("model", "toymodel"),
                       ("solver", "random")):
        plugins.registry(kind).unregister(name)
    problems._model_cache.pop("toymodel", None)


def test_space_uses_model_bounds_and_pins_unread_features(toys):
    p = build_problem({"toyhard": 0.5})
    assert p.space.names == ("GS", "W")          # Fpeak (toyrough) and P are not searched
    assert p.space["GS"].lower == 0.1 and p.space["W"].upper == 60.0
    assert p.fixed["P"] == 1.5                      # model metadata default
    assert p.fixed["Fpeak"] == pytest.approx(110.0)  # mid-range when no default
    assert [c.name for c in p.constraints] == ["toy-work"]


def test_closed_loop_reachable_target(toys):
    # a target the model reaches by construction, with the constraint met
    g = np.array([[2.0, 40.0, 80.0, 1.5]])
    t = toys.predict(g)[0]
    res = solve({"toyhard": t[0], "toyrough": t[1]}, method="random", seed=3,
                options={"n": 20000}, tolerance=0.05)
    pred = toys.predict(np.array([[res.x_dict[n] for n in toys.feature_names]]))[0]
    assert res.error == pytest.approx(abs(pred[0] - t[0]) + abs(pred[1] - t[1]))
    assert res.success == (res.error <= 0.05 and res.constraint_violation <= 1e-9)
    assert res.success, res.message
    assert res.trace and res.trace[-1]["nfev"] == 20000 and res.time_s > 0


def test_base_reevaluates_a_lying_solver(toys):
    res = solve({"toyhard": 0.9, "toyrough": 0.9}, method="random", seed=0, options={"lie": True})
    # x at the lower bounds: W = 1 mJ < 5.445/0.1 -> constraint violated, so no success
    assert not res.success
    assert res.constraint_violation > 0.9
    assert "constraints violated" in res.message


def test_unreachable_target_says_so_with_residual(toys):
    X = toys.feature_space.random(20000, np.random.default_rng(0))
    reach = toys.predict(X)
    # pick a target outside the sampled reachable set: beyond the max hardness
    t = 1.0
    assert t - reach[:, 0].max() >= 0.2
    res = solve({"toyhard": t}, method="random", seed=1)
    assert not res.success
    assert res.error_per_dimension["toyhard"] >= t - reach[:, 0].max() - 1e-3
    assert "residual" in res.message and "nearest intensities" in res.message


def test_batch_returns_one_result_per_target(toys):
    T = np.array([[0.2, 0.3], [0.5, 0.5], [0.5, 0.5]])
    res = solve(T, dimensions=["toyhard", "toyrough"], method="random", seed=2, options={"n": 500})
    assert len(res) == 3 and res.x.shape == (3, 3)
    assert np.all(np.isfinite(res.error))


@pytest.mark.parametrize("targets,field", [
    ({"toyhard": float("nan")}, "targets.toyhard"),
    ({"toyhard": 1.2}, "targets.toyhard"),
    ({"toyhard": -0.1}, "targets.toyhard"),
    ({"toyhard": "soft"}, "targets.toyhard"),
])
def test_bad_targets_raise_before_work(toys, targets, field):
    with pytest.raises(ValidationError) as e:
        build_problem(targets)
    assert e.value.field == field


def test_unknown_names_and_options(toys):
    from hapticsdk.errors import UnknownPluginError
    with pytest.raises(UnknownPluginError, match="toyhard"):
        build_problem({"toyhardd": 0.5})
    with pytest.raises(UnknownPluginError, match="random"):
        solve({"toyhard": 0.5}, method="nosuch")
    with pytest.raises(ValidationError, match="valid"):
        solve({"toyhard": 0.5}, method="random", options={"pop": 3})


def test_model_must_read_the_dimension_features(toys):
    from hapticsdk.perception.models import MLPModel
    small = MLPModel(dict(W1=np.ones((2, 1)), b1=np.zeros(2), W2=np.ones((2, 2)), b2=np.zeros(2),
                          x_min=[0.0], x_max=[1.0], y_min=[0, 0], y_max=[1, 1]), ["GS"], ["toyhard", "x"])
    with pytest.raises(ModelError, match="W"):
        build_problem({"toyhard": 0.5}, model=small)


def test_degenerate_bound_is_allowed(toys):
    p = build_problem({"toyhard": 0.5})
    p.space = p.space.with_bounds({"GS": (2.0, 2.0)})
    from hapticsdk.solvers import SolveProblem
    p2 = SolveProblem(p.targets, p.dimensions, p.model, p.space, p.fixed, p.constraints)
    res = RandomSearch(n=200).solve(p2, seed=0)
    assert res.x[0, 0] == 2.0


def test_solver_crash_is_wrapped(toys):
    class Crash(RandomSearch):
        name = "crash"

        def _solve(self, problem, rng, trace):
            raise ZeroDivisionError("oops")

    with pytest.raises(SolverError, match="crash"):
        Crash().solve(build_problem({"toyhard": 0.5}))
