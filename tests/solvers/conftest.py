"""Fixtures for the solver tests: a seeded random MLP perception model (5 features ->
hardness, roughness), the paper's two constraints, and targets reachable by construction
(model outputs of random feasible feature points). Nothing here depends on the model or
dimension plugins being installed."""

from __future__ import annotations

import numpy as np
import pytest

from hapticsdk.perception.dimensions import Constraint
from hapticsdk.perception.features import Feature, FeatureSpace
from hapticsdk.perception.models import MLPModel
from hapticsdk.solvers import SolveProblem

NAMES = ("GS", "W", "Fpeak", "AFpeak", "P")
UNITS = ("N/mm", "mJ", "Hz", "m/s^2", "(m/s^2)^2")
LOWER = np.array([0.05, 0.5, 10.0, 0.1, 0.01])
UPPER = np.array([5.0, 60.0, 240.0, 8.0, 40.0])
DF_HZ = 0.5


class WorkConstraint(Constraint):
    """W >= MF^2 / (2 GS), MF = 3.3 N (formula (4))."""

    name = "work"
    features = ("GS", "W")

    def _bound_and_value(self, cols):
        return 3.3 ** 2 / (2 * cols["GS"]), cols["W"]


class PowerConstraint(Constraint):
    """P >= AFpeak^2 * df (formula (5))."""

    name = "power"
    features = ("AFpeak", "P")

    def _bound_and_value(self, cols):
        return cols["AFpeak"] ** 2 * DF_HZ, cols["P"]


def make_space(lower=LOWER, upper=UPPER) -> FeatureSpace:
    return FeatureSpace(tuple(Feature(n, u, lo, hi) for n, u, lo, hi in zip(NAMES, UNITS, lower, upper)))


def make_model(seed: int = 0) -> MLPModel:
    r = np.random.default_rng(seed)
    w = {"W1": r.normal(size=(20, 5)) * 0.8, "b1": r.normal(size=20) * 0.3,
         "W2": r.normal(size=(2, 20)) * 0.4, "b2": r.normal(size=2) * 0.1,
         "x_min": LOWER, "x_max": UPPER, "y_min": np.zeros(2), "y_max": np.ones(2)}
    return MLPModel(w, NAMES, ("hardness", "roughness"), feature_space=make_space(), name=f"test-mlp-{seed}")


def constraints():
    return (WorkConstraint(), PowerConstraint())


def feasible_points(model, n: int, seed: int) -> np.ndarray:
    r = np.random.default_rng(seed)
    X = model.feature_space.random(8 * n + 16, r)
    cols = {k: X[:, i] for i, k in enumerate(NAMES)}
    ok = np.ones(len(X), bool)
    for c in constraints():
        ok &= c.violation(cols) == 0
    return X[ok][:n]


def reachable_targets(model, n: int, seed: int = 1) -> np.ndarray:
    return model.predict(feasible_points(model, n, seed))


def make_problem(targets=None, *, n: int = 10, seed: int = 1, model=None, space=None, **kw) -> SolveProblem:
    model = model or make_model()
    if targets is None:
        targets = reachable_targets(model, n, seed)
    return SolveProblem(targets, ("hardness", "roughness"), model, space or model.feature_space,
                        constraints=kw.pop("constraints", constraints()), **kw)


def closed_loop(problem: SolveProblem, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Run the model on the answer: (sum |I - T| per target, max violation per target)."""
    X = np.atleast_2d(x)
    G = problem.full_inputs(X)
    I = problem.model.predict(G)
    err = np.abs(I - np.atleast_2d(problem.targets)).sum(axis=1)
    cols = problem.columns(G)
    viol = np.zeros(len(X))
    for c in problem.constraints:
        viol = np.maximum(viol, c.violation(cols))
    return err, viol


@pytest.fixture(scope="session")
def model():
    return make_model()


@pytest.fixture
def problem(model):
    return make_problem(model=model, n=12)


@pytest.fixture(scope="session")
def fx():
    """The helpers above, for tests (test modules cannot import conftest by name)."""
    import types
    return types.SimpleNamespace(make_model=make_model, make_problem=make_problem, make_space=make_space,
                                 reachable_targets=reachable_targets, feasible_points=feasible_points,
                                 closed_loop=closed_loop, constraints=constraints, NAMES=NAMES,
                                 LOWER=LOWER, UPPER=UPPER, WorkConstraint=WorkConstraint,
                                 PowerConstraint=PowerConstraint)
