"""One target per call: ``Solver.solve`` on a one-row problem takes a plain-float path
(``SolveProblem.evaluate_one``, no batch arrays). Its result must be the one a batch of one
gives, field by field, and ``evaluate_one`` must give what ``evaluate`` gives: both penalty
forms, a penalty weight, a constraint with a zero bound and one with its own penalty."""

from __future__ import annotations

import numpy as np
import pytest

from hapticsdk.perception.dimensions import Constraint
from hapticsdk.solvers import SolveResult, Solver, SolverOutput
from hapticsdk_ga.amortised import AmortisedSolver
from hapticsdk_ga.ga import GASolver
from hapticsdk_ga.polish import PolishSolver


class ZeroBound(Constraint):
    """W >= 30 written as ``W - 30 >= 0``: a bound of 0 (the relative violation divides by 1)."""

    name = "zero-bound"
    features = ("W",)

    def _bound_and_value(self, cols):
        return np.zeros_like(cols["W"]), cols["W"] - 30.0


class OwnPenalty(Constraint):
    """Fpeak <= 200 with its own penalty and violation (not the base formulas)."""

    name = "own-penalty"
    features = ("Fpeak",)

    def _bound_and_value(self, cols):
        return cols["Fpeak"] - 200.0, np.zeros_like(cols["Fpeak"])

    def penalty(self, cols, form="paper"):
        over = np.maximum(cols["Fpeak"] - 200.0, 0.0)
        return over ** 2 if form == "paper" else over / 200.0

    def violation(self, cols):
        return np.maximum(cols["Fpeak"] - 200.0, 0.0) / 200.0


def _fields_equal(a: SolveResult, b: SolveResult) -> None:
    assert set(a) == set(b)
    for k in a:
        if k == "time_s" or (k == "trace" and a[k]):
            continue
        if isinstance(a[k], np.ndarray):
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
        else:
            assert a[k] == b[k], k
    assert [{k: v for k, v in r.items() if k != "time_s"} for r in a.trace] == \
        [{k: v for k, v in r.items() if k != "time_s"} for r in b.trace]


@pytest.mark.parametrize("solver", [PolishSolver(), PolishSolver(max_iter=1, starts=1),
                                    GASolver(generations=3, population=12),
                                    AmortisedSolver(grid=9, build_samples=400, build_iter=4, cache=False,
                                                    polish_steps=0)])
@pytest.mark.parametrize("which", ["reachable", "unreachable"])
def test_one_target_result_equals_a_batch_of_one(fx, model, solver, which):
    T = fx.reachable_targets(model, 1, seed=5)[0] if which == "reachable" else np.array([1.0, 0.0])
    single = fx.make_problem(T, model=model)
    batch = fx.make_problem(T[None, :], model=model)
    assert single.single and not batch.single
    a = solver.solve(single, seed=11)
    b = solver.solve(batch, seed=11)[0]
    _fields_equal(a, b)
    if which == "unreachable":
        assert not a.success and "target not reached" in a.message


class FixedAnswer(Solver):
    """Returns the option ``x`` for every target (outside the bounds if asked)."""

    name = "fixed"
    default_options = {"x": None}

    def _solve(self, problem, rng, trace):
        trace.record(1, np.zeros(problem.n_targets))
        return SolverOutput(x=np.tile(self.options["x"], (problem.n_targets, 1)), nfev=1, nit=0, message="fixed")


def test_one_target_answer_is_clipped_and_judged_by_its_constraints(fx, model):
    lo, hi = fx.LOWER, fx.UPPER
    x = np.array([hi[0] + 3.0, lo[1], 0.5 * (lo[2] + hi[2]), hi[3], lo[4]])   # GS beyond its bound
    inside = np.clip(x, lo, hi)
    T = model.predict(inside)[0]            # met exactly at the clipped answer ...
    single = fx.make_problem(T, model=model)
    a = FixedAnswer(x=x).solve(single, seed=0)
    b = FixedAnswer(x=x).solve(fx.make_problem(T[None, :], model=model), seed=0)[0]
    _fields_equal(a, b)
    np.testing.assert_array_equal(a.x, inside)
    assert a.error == 0.0 and a.constraint_violation > 0      # ... but W, P below their bounds
    assert not a.success and "constraints violated" in a.message


@pytest.mark.parametrize("penalty", ["paper", "normalised"])
@pytest.mark.parametrize("weight", [1.0, 2.5])
@pytest.mark.parametrize("own", [False, True])
def test_evaluate_one_equals_evaluate(fx, model, penalty, weight, own):
    # without OwnPenalty every constraint uses the base formulas (one bound_and_value call each)
    cons = fx.constraints() + (ZeroBound(),) + ((OwnPenalty(),) if own else ())
    p = fx.make_problem(np.array([0.4, 0.6]), model=model, constraints=cons, penalty=penalty,
                        penalty_weight=weight)
    X = model.feature_space.random(300, np.random.default_rng(2))
    viol_seen = np.zeros(len(cons), bool)
    for x in X:   # one row each: a matrix product may round a row differently inside a larger batch
        ref = p.evaluate(x[None, None, :], details=True, per_constraint=True)
        fit, err, viol, I, pc = p.evaluate_one(x)
        assert fit == ref["fitness"][0, 0] and err == ref["error"][0, 0] and viol == ref["violation"][0, 0]
        assert I == ref["intensities"][0, 0].tolist() and pc == ref["violations"][0, 0].tolist()
        viol_seen |= np.array(pc) > 0
    assert viol_seen.all()          # every constraint was violated somewhere (the branches ran)


class SmallBound(Constraint):
    """AFpeak / 10 >= 0.3: a bound below 1 (dividing by it or by 1 differ)."""

    name = "small-bound"
    features = ("AFpeak",)

    def _bound_and_value(self, cols):
        return np.full_like(cols["AFpeak"], 0.3), cols["AFpeak"] / 10.0


@pytest.mark.parametrize("penalty", ["paper", "normalised"])
def test_batched_evaluate_equals_each_constraints_own_formulas(fx, model, penalty):
    """The stacked penalty/violation of ``evaluate`` against ``Constraint.penalty`` and
    ``Constraint.violation`` called one by one (the definitions)."""
    cons = fx.constraints() + (ZeroBound(), SmallBound())
    p = fx.make_problem(np.array([[0.4, 0.6]]), model=model, constraints=cons, penalty=penalty)
    X = model.feature_space.random(500, np.random.default_rng(4))
    out = p.evaluate(X[None], details=True, per_constraint=True)
    cols = p.columns(X)
    V = np.stack([c.violation(cols) for c in cons], axis=1)
    pen = sum(c.penalty(cols, penalty) for c in cons)
    np.testing.assert_allclose(out["violations"][0], V, rtol=1e-12, atol=0)
    np.testing.assert_allclose(out["violation"][0], V.max(axis=1), rtol=1e-12, atol=0)
    err = np.abs(model.predict(X) - p.targets).sum(axis=1)
    np.testing.assert_allclose(out["fitness"][0], err + pen, rtol=1e-12, atol=1e-15)
    assert ((V > 0) & (V < 1)).any(axis=0).all() and (V == 0).any(axis=0).all()   # met and not, each
