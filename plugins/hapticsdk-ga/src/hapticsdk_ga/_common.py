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

    def __call__(self, X: np.ndarray, rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return ``(fitness, error, violation)`` for ``X`` ``(r, p, d)`` (or ``(r, d)``),
        where ``r`` targets are ``problem.targets[rows]`` (all targets when ``rows`` is None)."""
        p = self.problem
        T = p.targets if rows is None else p.targets[rows]
        lead = X.shape[:-1]
        X2 = X.reshape(-1, X.shape[-1])
        G = X2 if self._identity else p.full_inputs(X2)
        I = p.model.predict(G)
        self.nfev += G.shape[0]
        I = I[:, self.out_idx].reshape(lead + (len(self.out_idx),))
        Tb = T.reshape((T.shape[0],) + (1,) * (len(lead) - 1) + (T.shape[1],))
        err = np.abs(I - Tb).sum(axis=-1)
        if p.constraints:
            cols = p.columns(G)
            pen = np.zeros(G.shape[0])
            viol = np.zeros(G.shape[0])
            for c in p.constraints:
                if self._fast_c:
                    # same formulas as Constraint.penalty (paper: b^2 - v^2; normalised:
                    # (b - v)/|b|, where v < b), computed from one _bound_and_value call
                    b, v = c._bound_and_value(cols)
                    short = v < b
                    scale = np.where(np.abs(b) > 0, np.abs(b), 1.0)
                    nv = np.where(short, (b - v) / scale, 0.0)
                    pen += nv if self.penalty == "normalised" else np.where(short, b * b - v * v, 0.0)
                    viol = np.maximum(viol, nv)
                else:
                    pen += c.penalty(cols, self.penalty)
                    viol = np.maximum(viol, c.violation(cols))
            fit = err + p.penalty_weight * pen.reshape(lead)
            return fit, err, viol.reshape(lead)
        return err, err, np.zeros(lead)


def constraint_terms(problem: SolveProblem, G: np.ndarray, margin: float) -> np.ndarray:
    """Signed constraint shortfalls ``(n, c)``: ``(bound + margin|bound| - value)/|bound|``
    (positive = violated, or within the margin of the bound).

    The margin makes a Gauss-Newton iterate that converges onto the constraint land on the
    feasible side (the base class counts a violation above ``CONSTRAINT_TOL`` as failure).
    """
    cons = problem.constraints
    if not cons:
        return np.zeros((G.shape[0], 0))
    cols = problem.columns(G)
    out = np.empty((G.shape[0], len(cons)))
    for j, c in enumerate(cons):
        bv = getattr(c, "_bound_and_value", None)
        if bv is None:  # pragma: no cover - every Constraint has it (abstract method)
            out[:, j] = c.violation(cols)
            continue
        bound, value = bv(cols)
        bound = np.broadcast_to(np.asarray(bound, float), (G.shape[0],))
        value = np.broadcast_to(np.asarray(value, float), (G.shape[0],))
        scale = np.where(np.abs(bound) > 0, np.abs(bound), 1.0)
        out[:, j] = (bound + margin * scale - value) / scale
    return out


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
