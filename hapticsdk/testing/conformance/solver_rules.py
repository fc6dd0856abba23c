"""The rules of the ``solver`` kind (``RULES['solver']``), judged on the kit's reference
problem (:class:`ReferenceModel`, :func:`reference_problem`: a smooth model with known
inverses) by what the model says at the ``x`` a solver returns, never by what its result
claims."""

from __future__ import annotations

import json
from typing import Any, Mapping, cast

import numpy as np

from ...perception.dimensions import Constraint
from ...errors import ValidationError
from ...perception.features import Feature, FeatureSpace
from ...perception.models import PerceptionModel
from ...solvers import CONSTRAINT_TOL, SolveProblem, SolveResult, Solver
from .runner import _Ctx, _run_rules
from .values import _finite


class ReferenceModel(PerceptionModel):
    """A smooth 3-feature, 2-dimension model with known inverses (kit use only).

    ``I1 = (1 + tanh(2 a - 1)) / 2`` over ``a`` in [0, 1] (unitless),
    ``I2 = b / (b + c)`` over ``b`` in [0.1, 10] and ``c`` in [1, 5].
    """

    def __init__(self) -> None:
        space = FeatureSpace((Feature("a", "1", 0.0, 1.0), Feature("b", "1", 0.1, 10.0),
                              Feature("c", "1", 1.0, 5.0)))
        super().__init__(space.names, ("d1", "d2"), feature_space=space,
                         metadata={"feature_defaults": {"a": 0.5, "b": 1.0, "c": 2.0}}, name="reference")

    def _predict(self, X: np.ndarray) -> np.ndarray:
        i1 = (1 + np.tanh(2 * X[:, 0] - 1)) / 2
        i2 = X[:, 1] / (X[:, 1] + X[:, 2])
        return np.stack([i1, i2], axis=1)


class _RefConstraint(Constraint):
    """b >= 2 c (kit reference constraint)."""

    name = "reference.b-over-c"
    features = ("b", "c")

    def _bound_and_value(self, cols: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        return 2 * np.asarray(cols["c"]), np.asarray(cols["b"])


def reference_problem(targets: Any = (0.4, 0.75), *, constrained: bool = True, tolerance: float = 0.02) -> SolveProblem:
    """A reachable problem on :class:`ReferenceModel` (with ``b >= 2c`` when ``constrained``;
    ``d2 = 0.75`` needs ``b = 3c``, feasible)."""
    m = ReferenceModel()
    return SolveProblem(targets=np.asarray(targets, float), dimensions=("d1", "d2"), model=m,
                        space=cast(FeatureSpace, m.feature_space), constraints=(_RefConstraint(),) if constrained else (),
                        penalty="normalised", tolerance=tolerance)


#: what every solve result carries: scipy.optimize's fields, and the error, constraint
#: violation and run time the SDK promises with every result
RESULT_FIELDS = ("x", "fun", "success", "message", "nfev", "error", "constraint_violation", "time_s")
#: how far a result's error, fun and constraint_violation may be from the kit's
#: recomputation at its ``x`` (absolute; fun relative to max(1, |fun|)): both evaluate the
#: float64 reference model at the same ``x`` by different paths (a batch, one row of plain
#: floats), so they differ by rounding, a few units in the last place of numbers <= 1 per
#: term (~1e-15); this allows 1000 times that and is 10 orders below the reference tolerance
REPORT_ATOL = 1e-12
#: targets of the reference problem whose unconstrained optimum breaks the constraint:
#: ``d2 = 0.5`` needs ``b = c``; with ``b >= 2c`` the best is ``b = 2c``, ``d2 = 2/3``
ACTIVE_TARGETS = (0.4, 0.5)
#: formula (6) (normalised penalty) at the constrained optimum of ACTIVE_TARGETS: ``d1``
#: met, ``|2/3 - 1/2|`` on ``d2``, no violation. Below ``b = 2c`` the penalty ``(2c - b)/2c``
#: rises by 1/2 per unit of ``b/c`` while the error falls by ``1/(b/c + 1)^2 <= 1/4``, so
#: nothing infeasible scores lower; ignoring the constraint scores ``0 + 1/2``
ACTIVE_OPTIMUM = 1.0 / 6.0


def _solver_core_overrides(cls: type) -> list[str]:
    """The methods of :class:`Solver`'s template (public ``solve`` and the steps through
    which it validates, calls ``_solve`` and recomputes the result) that ``cls`` replaces."""
    return [m for m in ("solve", "_call_backend", "_solve_single") if getattr(cls, m, None) is not getattr(Solver, m)]


def _at_x(res: Any, problem: SolveProblem) -> tuple[float, float, float]:
    """(formula (6), error, constraint violation) the core computes at the ``x`` of ``res``
    for the (one-target) ``problem``."""
    fit, err, viol, _, _ = problem.evaluate_one(problem.clip(np.asarray(res["x"], float)[None, :])[0])
    return fit, err, viol


def _judge_result(res: Any, problem: SolveProblem, where: str) -> tuple[float, float, float]:
    """``res`` carries :data:`RESULT_FIELDS` and what it claims (error, fun, violation,
    success) is what the core computes at its ``x`` for the (one-target) ``problem``.
    Returns that (:func:`_at_x`)."""
    missing = [k for k in RESULT_FIELDS if not (isinstance(res, Mapping) and k in res)]
    assert not missing, f"{where}: the result lacks {missing} (every result carries {list(RESULT_FIELDS)})"
    x = np.asarray(res["x"], float)
    assert x.shape == (problem.n_features,) and np.isfinite(x).all(), f"{where}: x {res['x']!r}"
    assert isinstance(res["success"], (bool, np.bool_)), f"{where}: success is {type(res['success']).__name__}"
    assert isinstance(res["message"], str), f"{where}: message is {type(res['message']).__name__}"
    assert isinstance(res["nfev"], (int, np.integer)) and not isinstance(res["nfev"], bool) and res["nfev"] >= 0, \
        f"{where}: nfev {res['nfev']!r} is not a count"
    assert _finite(res["time_s"]) and res["time_s"] is not None and res["time_s"] >= 0, \
        f"{where}: time_s {res['time_s']!r}"
    fit, err, viol = _at_x(res, problem)
    claims = {"error": (res["error"], err, REPORT_ATOL),
              "constraint_violation": (res["constraint_violation"], viol, REPORT_ATOL),
              "fun": (res["fun"], fit, REPORT_ATOL * max(1.0, abs(fit)))}
    for k, (said, true, tol) in claims.items():
        assert _finite(said) and said is not None and abs(float(said) - true) <= tol, \
            f"{where}: {k} {said!r}, but the model at the returned x gives {true:.6g}"
    ok = err <= problem.tolerance and viol <= CONSTRAINT_TOL
    near = abs(err - problem.tolerance) <= REPORT_ATOL or abs(viol - CONSTRAINT_TOL) <= REPORT_ATOL
    assert near or bool(res["success"]) == ok, \
        (f"{where}: success {bool(res['success'])}, but at the returned x the error is {err:.3g} (tolerance "
         f"{problem.tolerance:g}) and the constraint violation {viol:.3g}")
    return fit, err, viol


def _judge_trace(res: Any, where: str) -> None:
    """The trace ``res`` carries (a result's per-target rows, or a batch's) is what its
    fields mean: ``nfev`` the evaluations so far, a count that never falls and never
    exceeds the result's total ``nfev``; ``best_error`` (a sum of absolute intensity
    errors) and ``constraint_violation`` (0 when met) finite and >= 0 in every row.
    Nothing else is asked of it: a solver may record its best by formula (6), so its
    best error may rise while the penalty falls."""
    trace = res.get("trace") if isinstance(res, Mapping) else getattr(res, "trace", None)
    if trace is None:
        return   # a result without a trace is judged by RESULT_FIELDS (it is not one of them)
    total = res["nfev"] if isinstance(res, Mapping) else getattr(res, "nfev", None)
    last = 0
    for i, row in enumerate(trace):
        n = row["nfev"]
        assert isinstance(n, (int, np.integer)) and not isinstance(n, bool) and last <= n, \
            (f"{where}: trace row {i} has nfev {n!r} after {last} (nfev in a trace counts the evaluations so "
             f"far: it never falls)")
        last = int(n)
        for k in ("best_error", "constraint_violation"):
            v = row[k]
            assert _finite(v) and v is not None and float(v) >= 0.0, \
                (f"{where}: trace row {i} has {k} {v!r} (an error or a violation is a finite number >= 0; "
                 f"Trace.record takes the best error per target and its violation)")
    assert total is None or last <= int(total), \
        (f"{where}: the trace counts {last} evaluations, but the result's nfev is {total} (nfev in a trace "
         f"counts the evaluations so far, at most all of them)")


def _problem_snapshot(problem: SolveProblem) -> dict[str, Any]:
    """What a caller sets on a :class:`SolveProblem` (and may solve again with, or hand to
    another solver), as copies: the targets, dimensions, fixed inputs, constraints (the
    objects), penalty form and weight, tolerance, starting points, and the searched
    features' names and bounds."""
    return {"targets": np.array(problem.targets, float), "dimensions": tuple(problem.dimensions),
            "fixed": dict(problem.fixed), "constraints": [id(c) for c in problem.constraints],
            "penalty": problem.penalty, "penalty_weight": problem.penalty_weight, "tolerance": problem.tolerance,
            "x0": None if problem.x0 is None else np.array(problem.x0, float),
            "space": (tuple(problem.space.names), np.array(problem.space.lower, float),
                      np.array(problem.space.upper, float))}


def _problem_changes(before: Mapping[str, Any], after: Mapping[str, Any]) -> list[str]:
    """The fields of :func:`_problem_snapshot` that differ between ``before`` and ``after``,
    each as ``field: before -> after``."""
    def same(a: Any, b: Any) -> bool:
        if isinstance(a, tuple) and isinstance(b, tuple):
            return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
        if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
            return a is not None and b is not None and np.array_equal(a, b)
        return bool(a == b)

    def short(v: Any) -> str:
        return np.array2string(v, precision=4, threshold=6) if isinstance(v, np.ndarray) else repr(v)
    return [f"{k}: {short(before[k])} -> {short(after[k])}" for k in before if not same(before[k], after[k])]


def _solver_rules(ctx: _Ctx, options: Mapping[str, Any]) -> None:
    def make() -> Solver:
        return ctx.obj(**dict(options))

    # the rules solve the same reference problems: each (targets, seed) is solved once, on
    # a new solver, and judged at its x once (a solver that spoils its own copy of the
    # problem spoils no other rule's: each rule judges against a problem of its own)
    solved: dict[tuple[str, int], Any] = {}
    judged: dict[tuple[str, int], tuple[float, float, float]] = {}

    def key(targets: Any, seed: int) -> tuple[str, int]:
        return repr(np.asarray(targets, float).tolist()), seed

    # how many rows the model computed while each solve ran
    rows: dict[tuple[str, int], int] = {}
    # what each solve changed in the problem it was handed (the caller's object)
    changed: dict[tuple[str, int], list[str]] = {}

    def solve(targets: Any, seed: int) -> Any:
        k = key(targets, seed)
        if k not in solved:
            problem = reference_problem(np.array(targets, float))
            model = problem.model
            counted = [0]
            predict = model._predict

            def counting(X: np.ndarray) -> np.ndarray:
                counted[0] += len(X)
                return predict(X)
            model._predict = counting  # type: ignore[method-assign]
            before = _problem_snapshot(problem)
            try:
                solved[k] = make().solve(problem, seed=seed)
            finally:
                del model._predict
            rows[k] = counted[0]
            changed[k] = _problem_changes(before, _problem_snapshot(problem))
        return solved[k]

    def at_x(targets: Any, seed: int) -> tuple[float, float, float]:
        k = key(targets, seed)
        if k not in judged:
            judged[k] = _at_x(solve(targets, seed), reference_problem(targets))
        return judged[k]

    def r_template() -> None:
        over = _solver_core_overrides(ctx.obj)
        assert not over, (f"overrides {over} of the Solver template: implement _solve only, so the core "
                          f"validates the problem and recomputes every result from the model at x")

    def r_result() -> None:
        # judged against a problem of its own: the solver's copy is the solver's to spoil
        for targets in ((0.4, 0.75), ACTIVE_TARGETS):   # reachable; out of reach behind the constraint
            judged[key(targets, 0)] = _judge_result(solve(targets, 0), reference_problem(targets), f"target {targets}")
        T = np.array([[0.3, 0.7], ACTIVE_TARGETS])
        batch = solve(T, 1)
        assert len(batch) == len(T), f"a batch of {len(T)} targets gave {len(batch)} results"
        for i, r in enumerate(batch):
            _judge_result(r, reference_problem(T[i]), f"batch target {i}")
        for asked, seed in ((np.array((0.4, 0.75)), 0), (np.array(ACTIVE_TARGETS), 0), (T, 1)):
            k = key(asked, seed)
            res = solved[k]
            # the core evaluates each answer once (one row per target) after _solve: rows
            # beyond that are the solver's own evaluations, which nfev counts
            own = rows[k] - (len(res) if isinstance(res, list) else 1)
            for r in (res if isinstance(res, list) else [res]):
                assert own <= 0 or int(r["nfev"]) >= 1, \
                    (f"target {asked.tolist()}: nfev {r['nfev']!r}, but the model computed {own} "
                     f"rows for the solve (nfev counts the objective's evaluations)")
                # each evaluation of the objective is a row the model computes (the problem
                # is new to the solve, so nothing was computed for it before): a count above
                # the rows is evaluations that never happened
                assert int(r["nfev"]) <= max(own, 0), \
                    (f"target {asked.tolist()}: nfev {r['nfev']!r}, but the model computed only {max(own, 0)} "
                     f"rows for the solve besides the core's own evaluation of the answer (nfev counts the "
                     f"objective's evaluations, each a row of the model; it cannot exceed them)")
            # the problem is the caller's: solved again, or by another solver, it must be
            # what the caller set (a solver's working copy is SolveProblem.with_targets' or
            # its own)
            assert not changed[k], \
                (f"target {asked.tolist()}: solve() changed the problem it was handed ({'; '.join(changed[k])}): "
                 f"the problem is the caller's, who may solve it again or with another solver; change a "
                 f"copy (problem.with_targets(problem.targets) is a shallow one) instead")
        # what the trace of each says (after the totals: a total that is wrong is named as such)
        for asked, seed in ((np.array((0.4, 0.75)), 0), (np.array(ACTIVE_TARGETS), 0)):
            _judge_trace(solved[key(asked, seed)], f"target {asked.tolist()}")
        for i, r in enumerate(batch):
            _judge_trace(r, f"batch target {i}")
        _judge_trace(batch, "the batch's trace")

    def r_constraints() -> None:
        p = reference_problem(ACTIVE_TARGETS)
        fit, err, viol = at_x(ACTIVE_TARGETS, 0)
        assert fit <= ACTIVE_OPTIMUM + p.tolerance, \
            (f"targets {ACTIVE_TARGETS} with the constraint b >= 2c active: formula (6) at the answer is "
             f"{fit:.3g} (error {err:.3g}, constraint violation {viol:.3g}), the constrained optimum "
             f"{ACTIVE_OPTIMUM:.3g} (b = 2c) + tolerance {p.tolerance:g}: does the solver ignore constraints?")

    def r_class() -> None:
        cls = ctx.obj
        assert isinstance(cls, type) and issubclass(cls, Solver), f"entry point gives {cls!r}, not a Solver subclass"
        if ctx.by_name:
            assert cls.name == ctx.name, f"class attribute name {cls.name!r} differs from the entry-point name {ctx.name!r}"
        assert isinstance(cls.default_options, dict), "default_options must be a dict"
        json.dumps(cls.default_options, default=str)

    def r_options() -> None:
        try:
            ctx.obj(no_such_option_xyz=1)
        except ValidationError:
            return
        raise AssertionError("an unknown option was accepted")

    def r_solves() -> None:
        res = cast(SolveResult, solve((0.4, 0.75), 0))   # reference_problem()'s targets
        assert np.shape(res.x) == (3,), f"x has shape {np.shape(res.x)}, expected (3,)"
        p = reference_problem()
        assert p.space.contains(res.x).all(), f"x {res.x} outside the feature bounds"
        assert res.error <= 0.05, f"did not reach an easy reachable target: error {res.error:.3g} ({res.message})"
        assert res.constraint_violation <= 1e-3, f"constraint violated at the answer ({res.constraint_violation:.3g})"

    def r_determinism() -> None:
        a = make().solve(reference_problem(), seed=11)
        b = make().solve(reference_problem(), seed=11)
        np.testing.assert_array_equal(a.x, b.x, err_msg="the same seed gave different answers")
        T = np.array([[0.3, 0.7], [0.6, 0.8]])
        a = make().solve(reference_problem(T), seed=11)
        b = make().solve(reference_problem(T), seed=11)
        np.testing.assert_array_equal(a.x, b.x, err_msg="the same seed gave different answers for a batch of 2 targets")
        # one instance solving again (a caller keeps a solver for a session): the same
        # seed gives the same answer as the first solve, nothing carried over from it
        one = make()
        first = one.solve(reference_problem(), seed=11)
        one.solve(reference_problem((0.6, 0.8)), seed=5)
        again = one.solve(reference_problem(), seed=11)
        np.testing.assert_array_equal(first.x, again.x,
                                      err_msg=("one solver instance gave a different answer for the same problem and "
                                               "seed after solving another (state kept between solves, e.g. a warm "
                                               "start from the last answer); a seed must fix the answer"))

    def r_batch() -> None:
        T = np.array([[0.3, 0.7], [0.6, 0.8], [0.5, 0.75]])
        res = make().solve(reference_problem(T), seed=1)
        assert isinstance(res, list) and len(res) == 3, "a batch of 3 targets must give 3 results"
        assert res.x.shape == (3, 3), f"batch x shape {res.x.shape}"
        assert (res.error <= 0.05).all(), f"batch errors {res.error}"

    def r_bad_input() -> None:
        try:
            make().solve("not a problem")  # type: ignore[arg-type]
        except ValidationError:
            return
        raise AssertionError("solve() accepted something that is not a SolveProblem")

    _run_rules(ctx, [("class", r_class), ("template", r_template), ("options", r_options), ("solves", r_solves),
                     ("result", r_result), ("constraints", r_constraints), ("determinism", r_determinism),
                     ("batch", r_batch), ("bad-input", r_bad_input)],
               always=("class",), stop_after=("class",))
