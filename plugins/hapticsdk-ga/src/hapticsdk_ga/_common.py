"""Helpers shared by the solvers: subset evaluation, option checks, constraint residuals.

All arrays are in physical units of the searched features (``problem.space``) unless a
name says ``u`` (unit coordinates, ``u = (x - lower) / span``, 0 for a degenerate feature).
"""

from __future__ import annotations

import time
from typing import Any, Sequence

import numpy as np

from hapticsdk.errors import ValidationError
from hapticsdk.solvers import CONSTRAINT_TOL, SolveProblem

__all__ = ["Evaluator", "check_int", "check_fraction", "check_budget", "Clock", "CONSTRAINT_TOL"]


class Evaluator:
    """Formula (6) for any subset of the problem's targets, one model call per call.

    :meth:`SolveProblem.evaluate` needs all ``m`` targets; solvers that drop targets once
    they are solved (``ga``, ``de``) or solve targets one by one (``de-scipy``) need the same
    fitness on a subset of rows. The arithmetic is the one of ``SolveProblem.evaluate``
    (checked against it by the tests).
    """

    def __init__(self, problem: SolveProblem, penalty: str | None = None) -> None:
        self.problem = problem
        self.penalty = penalty or problem.penalty
        names = problem.model.dimension_names
        self.out_idx = np.array([names.index(d) for d in problem.dimensions], dtype=int)
        self.lower = problem.space.lower
        self.upper = problem.space.upper
        self.span = self.upper - self.lower
        self.nfev = 0
        model_in = list(problem.model.feature_names)
        self._identity = (tuple(problem.space.names) == tuple(model_in))
        # constraints whose penalty/violation are the base class's formulas: one
        # _bound_and_value call gives both forms
        from hapticsdk.dimensions import Constraint
        self._fast_c = all(type(c).penalty is Constraint.penalty and type(c).violation is Constraint.violation
                           for c in problem.constraints)
        self.penalty_weight_is_one = float(problem.penalty_weight) == 1.0
        self._all_out = np.array_equal(self.out_idx, np.arange(len(names)))

    def __call__(self, X: np.ndarray, rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return ``(fitness, error, violation)`` for ``X`` ``(r, p, d)`` (or ``(r, d)``),
        where ``r`` targets are ``problem.targets[rows]`` (all targets when ``rows`` is None)."""
        p = self.problem
        T = p.targets if rows is None else p.targets[rows]
        lead = X.shape[:-1]
        X2 = X.reshape(-1, X.shape[-1])
        G = X2 if self._identity else p.full_inputs(X2)
        I = p.model.predict(G)
        n = G.shape[0]
        self.nfev += n
        # sum_j |I_j - T_j|: one subtraction, |.| in place, then the columns added (a
        # reduction over a length-2 axis costs more than the additions)
        I3 = I.reshape(T.shape[0], -1, I.shape[-1])
        if not self._all_out:
            I3 = I3[:, :, self.out_idx]
        D = np.subtract(I3, T[:, None, :])
        np.abs(D, out=D)
        if D.shape[-1] == 2:
            err = np.add(D[..., 0], D[..., 1])
        else:
            err = D.sum(axis=-1)
        err = err.reshape(lead)
        if not p.constraints:
            return err, err, np.zeros(lead)
        cols = p.columns(G)
        if self._fast_c:
            # same values as Constraint.penalty (paper: b^2 - v^2; normalised:
            # (b - v)/|b|, where v < b), one _bound_and_value call per constraint, all
            # constraints stacked so that each operation runs once
            nc = len(p.constraints)
            B = np.empty((nc, n))
            V = np.empty((nc, n))
            for j, c in enumerate(p.constraints):
                B[j], V[j] = c._bound_and_value(cols)
            short = V < B
            scale = np.abs(B)
            scale[scale == 0] = 1.0
            nvs = np.subtract(B, V)
            nvs /= scale
            nvs[~short] = 0.0
            viol = nvs.max(axis=0) if nc > 1 else nvs[0]
            if self.penalty == "normalised":
                pen = nvs.sum(axis=0) if nc > 1 else nvs[0].copy()
            else:
                B *= B
                V *= V
                B -= V
                B[~short] = 0.0
                pen = B.sum(axis=0) if nc > 1 else B[0]
        else:
            pen = np.zeros(n)
            viol = np.zeros(n)
            for c in p.constraints:
                pen += c.penalty(cols, self.penalty)
                np.maximum(viol, c.violation(cols), out=viol)
        if self.penalty_weight_is_one:
            pen += err.reshape(-1)
            fit = pen.reshape(lead)
        else:
            fit = err + p.penalty_weight * pen.reshape(lead)
        return fit, err, viol.reshape(lead)


def constraint_shortfalls(problem: SolveProblem, G: np.ndarray) -> np.ndarray:
    """Relative constraint shortfalls ``(n, c)``: ``(bound - value) / |bound|`` (``|bound|``
    replaced by 1 where it is 0); positive = violated. ``max(0, .)`` of a column is the
    constraint's ``violation`` (the base :class:`~hapticsdk.dimensions.Constraint` formula);
    one ``_bound_and_value`` call per constraint."""
    cons = problem.constraints
    n = G.shape[0]
    out = np.empty((n, len(cons)))
    if not cons:
        return out
    cols = problem.columns(G)
    for j, c in enumerate(cons):
        bound, value = c._bound_and_value(cols)
        bound = np.asarray(bound, float)
        col = out[:, j]
        np.subtract(bound, value, out=col)
        scale = np.abs(bound)
        if scale.ndim:
            scale[scale == 0] = 1.0
        elif scale == 0:
            scale = 1.0
        col /= scale
    return out


def violation_from(problem: SolveProblem, S: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Max relative violation per row from :func:`constraint_shortfalls` ``S`` (exactly
    ``Constraint.violation`` when no constraint overrides it; otherwise that method)."""
    n = S.shape[0]
    if not problem.constraints:
        return np.zeros(n)
    from hapticsdk.dimensions import Constraint
    if all(type(c).violation is Constraint.violation and type(c).penalty is Constraint.penalty
           for c in problem.constraints):
        v = np.where(S <= 0, 0.0, S)   # NaN (infinite bound) stays NaN = not feasible
        return v.max(axis=1)
    cols = problem.columns(G)
    v = np.zeros(n)
    for c in problem.constraints:
        np.maximum(v, c.violation(cols), out=v)
    return v


def constraint_terms(problem: SolveProblem, G: np.ndarray, margin: float) -> np.ndarray:
    """Signed constraint shortfalls ``(n, c)`` shifted by a margin: ``(bound - value)/|bound|
    + margin`` (positive = violated, or within the margin of the bound).

    The margin makes a Gauss-Newton iterate that converges onto the constraint land on the
    feasible side (the base class counts a violation above ``CONSTRAINT_TOL`` as failure).
    """
    S = constraint_shortfalls(problem, G)
    if margin:
        S += margin
    return S


def check_int(opts: dict, key: str, lo: int, hi: int | None = None, *, allow_none: bool = False) -> int | None:
    v = opts[key]
    if v is None and allow_none:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo or (hi is not None and v > hi):
        rng = f">= {lo}" if hi is None else f"in {lo}..{hi}"
        raise ValidationError(f"must be an integer {rng}, got {v!r}", field=f"options.{key}")
    return int(v)


def check_fraction(opts: dict, key: str, lo: float = 0.0, hi: float = 1.0) -> float:
    v = opts[key]
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValidationError(f"must be a number, got {v!r}", field=f"options.{key}") from None
    if not (np.isfinite(f) and lo <= f <= hi):
        raise ValidationError(f"must be in [{lo:g}, {hi:g}], got {v!r}", field=f"options.{key}")
    return f


def check_budget(opts: dict, key: str = "time_budget_s") -> float | None:
    v = opts.get(key)
    if v is None:
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValidationError(f"must be a number of seconds or None, got {v!r}", field=f"options.{key}") from None
    if not (f > 0):
        raise ValidationError(f"must be > 0 s, got {v!r}", field=f"options.{key}")
    return f


def target_error(opts: dict, problem: SolveProblem) -> float:
    """Stopping threshold on the error: option ``target_error`` (None -> the problem's
    tolerance; 0 -> never stop early)."""
    v = opts.get("target_error")
    if v is None:
        return float(problem.tolerance)
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValidationError(f"must be a number or None, got {v!r}", field="options.target_error") from None
    if not (np.isfinite(f) and f >= 0):
        raise ValidationError(f"must be >= 0, got {v!r}", field="options.target_error")
    return f


class Clock:
    """Wall-clock budget (``None`` = unlimited)."""

    def __init__(self, budget_s: float | None) -> None:
        self.budget = budget_s
        self.t0 = time.perf_counter()

    def expired(self) -> bool:
        return self.budget is not None and time.perf_counter() - self.t0 >= self.budget


def merge_options(defaults: dict[str, Any], given: dict[str, Any] | None, field: str) -> dict[str, Any]:
    """Defaults updated with ``given``; unknown keys raise naming the valid ones."""
    given = dict(given or {})
    unknown = [k for k in given if k not in defaults]
    if unknown:
        raise ValidationError(f"unknown option(s) {unknown}; valid: {sorted(defaults)}", field=field)
    return {**defaults, **given}


def solved_mask(err: np.ndarray, viol: np.ndarray, goal: float) -> np.ndarray:
    return (err <= goal) & (viol <= CONSTRAINT_TOL)


def rank_key(err: np.ndarray, viol: np.ndarray) -> np.ndarray:
    """Ordering for 'best answer': feasible first, then smaller error."""
    return np.where(viol <= CONSTRAINT_TOL, err, 1e6 + viol + err)


def as_rows(seq: Sequence[int] | np.ndarray) -> np.ndarray:
    return np.asarray(seq, dtype=int)
