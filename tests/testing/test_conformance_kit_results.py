"""Kit rules that judge what a model or solver *does*, not what it says: a model whose
outputs do not move over its feature box (``responds``), non-finite intensities at the
box's landmarks (``shapes``: centre, face centres, declared defaults), a solver that
replaces the core's template (``template``), a result whose fields are missing or whose
claims differ from the model at its ``x``, or whose trace does not mean what its fields say
(``result``), and a solver that ignores a
constraint that is active at the unconstrained optimum (``constraints``). Each broken
variant is caught by its rule; the correct ones conform."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from hapticsdk.perception.models import PerceptionModel
from hapticsdk.plugins import registry
from hapticsdk.solvers import SolveProblem, Solver, SolverOutput
from hapticsdk.testing import check_model, check_solver
from hapticsdk.testing.conformance import (ACTIVE_OPTIMUM, ACTIVE_TARGETS, RESPONSE_MIN, format_report,
                                           reference_problem)
from kit_variants import API, GoodSolver, rules_of


# ---------------------------------------------------------------------------
# models: the inputs and outputs of the installed default model (so model-dimensions holds)
# ---------------------------------------------------------------------------

def _default():
    if "default" not in registry("model"):
        pytest.skip("the default model is not installed")
    return registry("model").load("default")()


class _Model(PerceptionModel):
    """A smooth model over the default model's features and dimensions; ``out`` maps the
    unit-box input ``U`` ``(n, d)`` to intensities ``(n, k)``."""
    hapticsdk_api = API

    def __init__(self, out, defaults=None) -> None:
        ref = _default()
        meta = {"feature_defaults": defaults} if defaults is not None else {}
        super().__init__(ref.feature_names, ref.dimension_names, feature_space=ref.feature_space,
                         metadata=meta, name="kit-results-model")
        self.out = out

    def _predict(self, X):
        U = self.feature_space.to_unit(X)
        return self.out(U, self.n_outputs)


def _smooth(U, k):
    s = U.mean(axis=1, keepdims=True)
    return np.repeat(0.5 * (1 + np.tanh(2 * s - 1)), k, axis=1)


def _nan_where(mask_fn):
    def out(U, k):
        Y = _smooth(U, k)
        with np.errstate(invalid="ignore", divide="ignore"):
            hit = mask_fn(U)
            Y[hit] = np.zeros(k)[None, :] / 0.0
        return Y
    return out


def _at(U, u):
    return np.all(np.abs(U - u) < 1e-12, axis=1)


def _one_flat(U, k):
    Y = _smooth(U, k)
    Y[:, -1] = 0.37
    return Y


def _scaled_in_mid_batches(U, k):
    """A chunked fast path for batches of 100..5000 rows that rescales each batch so that
    its largest intensity is 0.99: a row's prediction depends on the rows beside it, only
    there."""
    Y = _smooth(U, k)
    return Y * (0.99 / Y.max()) if 100 <= len(U) <= 5000 else Y


class _JacobianZeroAtBounds(_Model):
    """An analytic Jacobian whose columns are 0 where a feature sits on its bound (a
    clipped input's derivative taken as the clip's): right inside the box, wrong where a
    bounded solve ends up."""

    def jacobian(self, G, *, step=1e-6):
        J = np.array(super().jacobian(G, step=step))
        X = np.atleast_2d(np.asarray(G, float))
        at = (X <= self.feature_space.lower) | (X >= self.feature_space.upper)
        J[np.broadcast_to(at[:, None, :], J.shape)] = 0.0
        return J


MODEL_VARIANTS = {
    "constant": (lambda: _Model(lambda U, k: np.full((len(U), k), 0.5)), "responds"),
    # every output moves, but by a quarter of the tolerance over the whole box
    "nearly-constant": (lambda: _Model(lambda U, k: 0.5 + RESPONSE_MIN / 4 * (_smooth(U, k) - 0.5)), "responds"),
    "one-output-flat": (lambda: _Model(_one_flat), "responds"),
    "nan-at-centre": (lambda: _Model(_nan_where(lambda U: _at(U, 0.5))), "shapes"),
    # 0/0 where the first feature sits on its lower bound and every other at mid-range
    "nan-at-a-face-centre": (lambda: _Model(_nan_where(lambda U: _at(U, np.r_[0.0, np.full(U.shape[1] - 1, 0.5)]))),
                             "shapes"),
    "batch-dependent-mid-sizes": (lambda: _Model(_scaled_in_mid_batches), "vectorised"),
    "jacobian-zero-at-bounds": (lambda: _JacobianZeroAtBounds(_smooth), "jacobian"),
}


def _nan_at_defaults():
    ref = _default()
    u = np.linspace(0.2, 0.7, ref.n_features)   # no landmark but the declared defaults
    defaults = dict(zip(ref.feature_names, ref.feature_space.from_unit(u).tolist()))
    return _Model(_nan_where(lambda U: _at(U, u)), defaults=defaults)


MODEL_VARIANTS["nan-at-declared-defaults"] = (_nan_at_defaults, "shapes")


def test_the_correct_model_conforms():
    v = check_model(lambda: _Model(_smooth))
    assert v == [], format_report(v)


@pytest.mark.parametrize("name", list(MODEL_VARIANTS))
def test_each_broken_model_is_caught_by_its_rule(name):
    factory, rule = MODEL_VARIANTS[name]
    v = check_model(factory)
    assert rules_of(v) == {rule}, format_report(v)


def test_responds_names_the_flat_output():
    v = check_model(MODEL_VARIANTS["one-output-flat"][0])
    assert _default().dimension_names[-1] in str(v[0]) and _default().dimension_names[0] not in str(v[0])


# ---------------------------------------------------------------------------
# solvers
# ---------------------------------------------------------------------------

class _Overrides(GoodSolver):
    """Overrides the public ``solve`` and edits what the core returned with ``edit``."""

    def edit(self, res: Any, problem: SolveProblem) -> None:
        pass

    def solve(self, problem, *, seed=None, chunk_size=None):
        res = super().solve(problem, seed=seed, chunk_size=chunk_size)
        for r in ([res] if problem.single else []):
            self.edit(r, problem)
        return res


def _edit(name, fn):
    return type(name, (_Overrides,), {"edit": lambda self, r, p: fn(r, p)})


def _drop(*keys):
    return lambda r, p: [r.pop(k) for k in keys]


def _set(**kv):
    return lambda r, p: r.update(kv)


class _NoConstraints(GoodSolver):
    """Searches the problem without its constraints."""

    def _solve(self, problem, rng, trace):
        free = SolveProblem(targets=problem.targets, dimensions=problem.dimensions, model=problem.model,
                            space=problem.space, fixed=problem.fixed, constraints=(), penalty=problem.penalty,
                            tolerance=problem.tolerance)
        return super()._solve(free, rng, trace)


class _WeakPenalty(GoodSolver):
    """Weighs the constraint penalty a hundred times less than formula (6) does."""

    def _solve(self, problem, rng, trace):
        weak = SolveProblem(targets=problem.targets, dimensions=problem.dimensions, model=problem.model,
                            space=problem.space, fixed=problem.fixed, constraints=problem.constraints,
                            penalty=problem.penalty, tolerance=problem.tolerance, penalty_weight=0.01)
        return super()._solve(weak, rng, trace)


class _RewritesTargets(GoodSolver):
    """Writes what its answer reaches into ``problem.targets``: the core then scores an
    error of 0 against targets nobody asked for."""

    def _solve(self, problem, rng, trace):
        out = super()._solve(problem, rng, trace)
        I = problem.model.predict(problem.full_inputs(out.x))
        problem.targets[...] = I[:, problem._out_idx]
        return out


class _NfevZero(GoodSolver):
    """Evaluates the problem as :class:`GoodSolver` does but reports ``nfev=0`` (a counter
    kept on the wrong object, never added to the output)."""

    def _solve(self, problem, rng, trace):
        out = super()._solve(problem, rng, trace)
        return SolverOutput(out.x, nfev=0, nit=out.nit)


class _BatchUnseeded(GoodSolver):
    """Seeded for one target, but the batch path draws from a generator of its own, seeded
    from the OS: a batch is not reproducible from its seed."""

    def _solve(self, problem, rng, trace):
        return super()._solve(problem, rng if problem.n_targets == 1 else np.random.default_rng(), trace)


class _TraceEdited(GoodSolver):
    """Solves as :class:`GoodSolver` does, then spoils the trace it recorded with
    ``spoil(trace)``: what a convergence plot of the result shows."""

    def _solve(self, problem, rng, trace):
        out = super()._solve(problem, rng, trace)
        type(self).spoil(trace)
        return out


def _trace(name, spoil):
    return type(name, (_TraceEdited,), {"spoil": staticmethod(spoil)})


def _countdown(trace):
    """nfev recorded as the evaluations left, not those so far (it falls)."""
    trace.nfev[:] = [max(trace.nfev) * (len(trace.nfev) - i) for i in range(len(trace.nfev))]


def _nan_best(trace):
    """The last iteration's best error recorded as NaN (a 0/0 in the solver's own error)."""
    trace.best_error[-1] = trace.best_error[-1] * np.nan


SOLVER_VARIANTS = {
    # an honest override still bypasses the template
    "solve-overridden": (_Overrides, {"template"}),
    "scipy-fields-missing": (_edit("NoFields", _drop("fun", "message", "nfev")), {"template", "result"}),
    "time-missing": (_edit("NoTime", _drop("time_s")), {"template", "result"}),
    "x-moved-after-scoring": (_edit("Moved", lambda r, p: r.update(x=p.space.lower.copy())),
                              {"template", "result"}),
    "error-understated": (_edit("Understated", lambda r, p: r.update(error=r["error"] / 10 + 0.0)),
                          {"template", "result"}),
    "fun-understated": (_edit("FunLow", lambda r, p: r.update(fun=r["fun"] - 0.01)), {"template", "result"}),
    "violation-hidden": (type("Hidden", (_NoConstraints, _edit("Zero", _set(constraint_violation=0.0))), {}),
                         {"template", "result", "constraints"}),
    "success-flipped": (_edit("Flipped", lambda r, p: r.update(success=not r["success"])), {"template", "result"}),
    "nfev-not-a-count": (_edit("FloatNfev", lambda r, p: r.update(nfev=float(r["nfev"]) + 0.5)),
                         {"template", "result"}),
    "message-not-text": (_edit("NoText", _set(message=None)), {"template", "result"}),
    "targets-rewritten": (_RewritesTargets, {"result"}),
    "ignores-constraints": (_NoConstraints, {"constraints"}),
    "weak-penalty": (_WeakPenalty, {"constraints"}),
    "nfev-zero": (_NfevZero, {"result"}),
    "batch-unseeded": (_BatchUnseeded, {"determinism"}),
    "trace-nfev-falls": (_trace("Countdown", _countdown), {"result"}),
    "trace-best-error-nan": (_trace("NanBest", _nan_best), {"result"}),
    "trace-nfev-above-total": (_trace("Above", lambda t: t.nfev.__setitem__(-1, 10 ** 9)), {"result"}),
}


#: what the report of a variant says (the rule names the fault, not a KeyError it ran into)
SOLVER_WHY = {"scipy-fields-missing": "lacks ['fun', 'message', 'nfev']", "time-missing": "lacks ['time_s']",
              "error-understated": "error ", "fun-understated": "fun ", "success-flipped": "success ",
              "violation-hidden": "constraint_violation 0.0, but", "solve-overridden": "overrides ['solve']",
              "targets-rewritten": "but the model at the returned x gives",
              "nfev-zero": "nfev 0, but the model computed", "batch-unseeded": "for a batch of 2 targets",
              "trace-nfev-falls": "never falls", "trace-best-error-nan": "best_error nan",
              "trace-nfev-above-total": "the trace counts 1000000000 evaluations"}


def test_the_correct_solver_conforms():
    v = check_solver(GoodSolver)
    assert v == [], format_report(v)


@pytest.mark.parametrize("name", list(SOLVER_VARIANTS))
def test_each_broken_solver_is_caught_by_its_rule(name):
    cls, rules = SOLVER_VARIANTS[name]
    v = check_solver(cls)
    # the constraint-active problem shows a hidden violation or a moved x as well
    assert rules <= rules_of(v) <= rules | {"constraints"}, format_report(v)
    assert SOLVER_WHY.get(name, "") in format_report(v)


def test_a_result_overridden_below_the_public_method_is_caught():
    """Replacing the step that recomputes a one-target result is the template too."""
    cls = type("OwnSingle", (GoodSolver,), {"_solve_single": lambda self, p, rng: Solver._solve_single(self, p, rng)})
    assert "template" in rules_of(check_solver(cls))


def test_active_optimum_is_the_constrained_optimum():
    """The rule's reference value, by brute force over b/c: formula (6) (normalised) is
    smallest at b = 2c, where it is 1/6; ignoring the constraint gives 1/2 there."""
    p = reference_problem(ACTIVE_TARGETS)
    a = (np.arctanh(2 * ACTIVE_TARGETS[0] - 1) + 1) / 2
    c = 2.0
    r = np.linspace(0.1 / c, 10 / c, 20001)
    X = np.stack([np.full_like(r, a), r * c, np.full_like(r, c)], axis=1)
    f = p.evaluate(X[None])[0]
    assert f.min() == pytest.approx(ACTIVE_OPTIMUM, abs=1e-3)
    assert r[np.argmin(f)] == pytest.approx(2.0, abs=1e-3)
    free = reference_problem(ACTIVE_TARGETS, constrained=False)
    x_free = X[np.argmin(free.evaluate(X[None])[0])]
    assert p.evaluate(x_free[None, None])[0, 0] == pytest.approx(0.5, abs=1e-3)


@pytest.mark.parametrize("name", ["de", "ga", "polish"])
def test_first_party_solvers_meet_the_active_constraint(name):
    if name not in registry("solver"):
        pytest.skip(f"solver {name!r} not installed (hapticsdk-ga)")
    v = check_solver(name)
    assert v == [], format_report(v)
