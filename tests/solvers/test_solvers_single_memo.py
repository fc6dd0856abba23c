"""One evaluation of a one-target answer: a backend that judges its answer with
``SolveProblem.evaluate_one`` (the amortised fast path does) and the core's evaluation of
that answer for the result share one model call; any other answer, problem or call is
evaluated afresh, and the result is the same as without the memo."""

from __future__ import annotations

import numpy as np

from hapticsdk.solvers import Solver, SolverOutput


class Judged(Solver):
    """Evaluates the option ``judge`` (each row, in order) with ``evaluate_one``, mutates
    the lists it got back, then returns the option ``x``."""

    name = "judged"
    default_options = {"x": None, "judge": ()}
    uses_rng = False

    def _solve(self, problem, rng, trace):
        for z in self.options["judge"]:
            fit, err, viol, I, pc = problem.evaluate_one(np.array(z, float))
            I[:] = [-1.0] * len(I)          # the caller's own lists
            pc.append(99.0)
        return SolverOutput(x=np.array([self.options["x"]], float), nfev=1, nit=0)


def _count_model_calls(monkeypatch, problem):
    calls = []
    real = type(problem)._evaluate_one

    def counted(self, x):
        calls.append(np.array(x, copy=True))
        return real(self, x)
    monkeypatch.setattr(type(problem), "_evaluate_one", counted)
    return calls


def _same_result(a, b):
    for k in ("x", "fun", "error", "constraint_violation", "intensities", "constraint_violations",
              "error_per_dimension", "success", "message"):
        if isinstance(a[k], np.ndarray):
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
        else:
            assert a[k] == b[k], k


def _answers(fx, model):
    X = fx.feasible_points(model, 3, seed=3)
    return X[0], X[1]


def _judged_setup(fx, model, monkeypatch):
    """Two feasible answers, a one-target problem whose target the first meets, the result
    a batch of one gives for that answer, and the counter of evaluations on the problem."""
    xa, xb = _answers(fx, model)
    T = model.predict(xa[None])[0]
    p = fx.make_problem(T, model=model)
    ref = Judged(x=xa).solve(fx.make_problem(T[None, :], model=model))[0]
    return xa, xb, p, ref, _count_model_calls(monkeypatch, p)


def test_the_answer_the_backend_judged_is_evaluated_once(fx, model, monkeypatch):
    xa, _, p, ref, calls = _judged_setup(fx, model, monkeypatch)
    r = Judged(x=xa, judge=[xa]).solve(p)
    assert len(calls) == 1
    _same_result(r, ref)          # the backend's changes to its lists did not reach the result
    assert p._one_memo is None    # nothing kept after the call


def test_another_answer_or_a_later_call_is_evaluated_afresh(fx, model, monkeypatch):
    xa, xb, p, ref, calls = _judged_setup(fx, model, monkeypatch)
    r = Judged(x=xa, judge=[xa, xb]).solve(p)     # the last one judged is not the answer
    assert len(calls) == 3
    _same_result(r, ref)
    calls.clear()
    p.evaluate_one(xa)                            # outside a solve: no memo
    p.evaluate_one(xa)
    assert len(calls) == 2


def test_a_derived_problem_does_not_see_the_memo(fx, model, monkeypatch):
    xa, _ = _answers(fx, model)
    T = model.predict(xa[None])[0]
    p = fx.make_problem(T, model=model)
    other = np.clip(T + 0.2, 0.0, 1.0)
    seen = {}

    class Derives(Solver):
        name = "derives"
        default_options = {}
        uses_rng = False

        def _solve(self, problem, rng, trace):
            problem.evaluate_one(xa)
            q = problem.with_targets(other)          # shares the setup, not the targets
            seen["err"] = q.evaluate_one(xa)[1]
            return SolverOutput(x=xa[None], nfev=1, nit=0)

    r = Derives().solve(p)
    assert seen["err"] == p.with_targets(other).evaluate_one(xa)[1]
    assert seen["err"] != r.error


def test_amortised_one_target_fast_path_evaluates_its_answer_once(fx, model, monkeypatch):
    from hapticsdk_ga.amortised import AmortisedSolver
    S = AmortisedSolver(grid=21, build_samples=2000, build_iter=8, cache=False)
    T = fx.reachable_targets(model, 6, seed=5)
    S.solve(fx.make_problem(T[0], model=model))          # builds the table (many evaluations)
    fast = 0
    for t in T:
        p = fx.make_problem(t, model=model)
        calls = _count_model_calls(monkeypatch, p)
        r = S.solve(p)
        monkeypatch.undo()
        fit, err, viol, I, pc = p.evaluate_one(r.x)      # afresh, outside the call
        assert (r.fun, r.error, r.constraint_violation) == (fit, err, viol)
        assert list(r.intensities.values()) == I and list(r.constraint_violations.values()) == pc
        if "Gauss-Newton" in r.message:
            fast += 1
            assert len(calls) == 1, r.message
    assert fast >= 1
