"""Differential evolution: batched over targets x population (``de``) and scipy per target
(``de-scipy``).

``de`` is classic DE (Storn & Price) with binomial crossover, mutation factor dithered per
generation in ``mutation`` (like scipy's default ``(0.5, 1)``), strategy ``best1bin`` or
``rand1bin``, and greedy one-to-one selection. Trial components that leave the bounds are
redrawn uniformly within them (scipy does the same). One model call per generation for all
active targets; a target leaves the active set once its best meets ``target_error``.

``de-scipy`` calls :func:`scipy.optimize.differential_evolution` once per target with
``vectorized=True`` (one model call per generation of that target), ``polish=False`` by
default (scipy's polish is a finite-difference L-BFGS-B, not batched). Degenerate features
(lower == upper) are held at their bound and not handed to scipy.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from hapticsdk.argcheck import number
from hapticsdk.checks import is_number
from hapticsdk.errors import ValidationError
from hapticsdk.solvers import SolveProblem, Solver, SolverOutput, Trace

from ._common import Clock, Evaluator, check_budget, check_fraction, check_int, solved_mask, target_error
from .ga import MAX_GENERATIONS, MAX_POPULATION


def _mutation_range(v: Any) -> tuple[float, float]:
    if is_number(v):
        lo = hi = number(v, "options.mutation")
    else:
        if isinstance(v, (str, bytes)) or not isinstance(v, (tuple, list)) or len(v) != 2:
            raise ValidationError(f"must be a number or (lo, hi), got {v!r:.60}", field="options.mutation")
        lo, hi = (number(a, f"options.mutation[{i}]") for i, a in enumerate(v))
    if not (0 <= lo <= hi <= 2):
        raise ValidationError(f"must lie in [0, 2] with lo <= hi, got {v!r}", field="options.mutation")
    return lo, hi


#: the strategies scipy's differential_evolution knows
SCIPY_STRATEGIES = ("best1bin", "best1exp", "best2bin", "best2exp", "currenttobest1bin", "currenttobest1exp",
                    "rand1bin", "rand1exp", "rand2bin", "rand2exp", "randtobest1bin", "randtobest1exp")


class DESolver(Solver):
    """Batched differential evolution.

    Options: ``population`` (50 per target), ``generations`` (100), ``mutation`` ((0.5, 1.0):
    factor F dithered per generation), ``recombination`` (CR 0.7), ``strategy``
    (``"best1bin"`` or ``"rand1bin"``), ``target_error`` (None = problem tolerance; 0 =
    never stop early), ``time_budget_s`` (None).
    """

    name: ClassVar[str] = "de"
    default_options: ClassVar[dict[str, Any]] = {
        "population": 50, "generations": 100, "mutation": (0.5, 1.0), "recombination": 0.7,
        "strategy": "best1bin", "target_error": None, "time_budget_s": None,
    }

    def _solve(self, problem: SolveProblem, rng: np.random.Generator, trace: Trace) -> SolverOutput:
        o = self.options
        p = check_int(o, "population", 4, MAX_POPULATION)
        gens = check_int(o, "generations", 0, MAX_GENERATIONS)
        f_lo, f_hi = _mutation_range(o["mutation"])
        cr = check_fraction(o, "recombination")
        if o["strategy"] not in ("best1bin", "rand1bin"):
            raise ValidationError(f"unknown strategy {o['strategy']!r}; valid: ['best1bin', 'rand1bin']",
                                  field="options.strategy")
        best_strategy = o["strategy"] == "best1bin"
        goal = target_error(o, problem)
        clock = Clock(check_budget(o))
        ev = Evaluator(problem)
        m, d = problem.n_targets, problem.n_features
        lower = problem.space.lower
        span = problem.space.upper - lower
        pop = lower + rng.random((m, p, d)) * span
        if problem.x0 is not None:
            pop[:, 0] = problem.x0
        fit, err, viol = ev(pop)
        ar = np.arange(m)
        k = fit.argmin(axis=1)
        best_x, best_f = pop[ar, k].copy(), fit[ar, k].copy()
        best_e, best_v = err[ar, k].copy(), viol[ar, k].copy()
        trace.record(ev.nfev, best_e, best_v)
        active = ~solved_mask(best_e, best_v, goal)
        gen = 0
        reason = "generations exhausted"
        while gen < gens:
            if not active.any():
                reason = f"all targets within target_error {goal:g}"
                break
            if clock.expired():
                reason = f"time budget {o['time_budget_s']:g} s spent"
                break
            rows = np.flatnonzero(active)
            P, F = pop[rows], fit[rows]
            r = len(rows)
            # three partner indices != i (uniform over the others; they may coincide)
            i = np.arange(p)[None, :, None]
            idx = rng.integers(0, p - 1, size=(r, p, 3))
            idx = idx + (idx >= i)
            rr = np.arange(r)[:, None]
            a, b, c = P[rr, idx[..., 0]], P[rr, idx[..., 1]], P[rr, idx[..., 2]]
            fac = f_lo + (f_hi - f_lo) * rng.random((r, 1, 1))
            if best_strategy:
                base = P[np.arange(r), F.argmin(axis=1)][:, None, :]
                mutant = base + fac * (a - b)
            else:
                mutant = a + fac * (b - c)
            cross = rng.random((r, p, d)) < cr
            jr = rng.integers(0, d, size=(r, p, 1))
            cross |= np.arange(d)[None, None, :] == jr
            trial = np.where(cross, mutant, P)
            out = (trial < lower) | (trial > lower + span)
            if out.any():
                trial = np.where(out, lower + rng.random((r, p, d)) * span, trial)
            tf, te, tv = ev(trial, rows)
            win = tf <= F
            P = np.where(win[..., None], trial, P)
            F = np.where(win, tf, F)
            pop[rows], fit[rows] = P, F
            gen += 1
            kk = F.argmin(axis=1)
            ra = np.arange(r)
            better = F[ra, kk] < best_f[rows]
            upd = rows[better]
            best_x[upd] = P[ra[better], kk[better]]
            best_f[upd] = F[ra[better], kk[better]]
            # error/violation of the new best: from the trial arrays (it won this generation)
            best_e[upd] = te[ra[better], kk[better]]
            best_v[upd] = tv[ra[better], kk[better]]
            trace.record(ev.nfev, best_e, best_v)
            active[rows] = ~solved_mask(best_e[rows], best_v[rows], goal)
        else:
            if not active.any():
                reason = f"all targets within target_error {goal:g}"
        return SolverOutput(x=best_x, nfev=ev.nfev, nit=gen, message=f"{gen} generations, {reason}")


class ScipyDESolver(Solver):
    """:func:`scipy.optimize.differential_evolution` per target, ``vectorized=True``.

    Options are passed to scipy: ``popsize`` (15, a multiplier of the number of searched
    features), ``maxiter`` (100), ``mutation`` ((0.5, 1)), ``recombination`` (0.7),
    ``strategy`` (``"best1bin"``), ``tol`` (0.0: stop on ``target_error`` instead),
    ``polish`` (False), plus ``target_error`` (None = problem tolerance) checked by a
    callback, and ``time_budget_s`` (None, whole batch).
    """

    name: ClassVar[str] = "de-scipy"
    default_options: ClassVar[dict[str, Any]] = {
        "popsize": 15, "maxiter": 100, "mutation": (0.5, 1.0), "recombination": 0.7,
        "strategy": "best1bin", "tol": 0.0, "polish": False, "target_error": None, "time_budget_s": None,
    }

    def _solve(self, problem: SolveProblem, rng: np.random.Generator, trace: Trace) -> SolverOutput:
        from scipy.optimize import differential_evolution

        o = self.options
        check_int(o, "popsize", 1, 10_000)
        check_int(o, "maxiter", 0, MAX_GENERATIONS)
        # every option scipy receives is checked here: scipy takes recombination=nan or
        # tol=-1 without a word, and polish="no" is true
        f_lo, f_hi = _mutation_range(o["mutation"])
        mutation: float | tuple[float, float] = f_lo if is_number(o["mutation"]) else (f_lo, f_hi)
        recombination = check_fraction(o, "recombination")
        tol = check_fraction(o, "tol", 0.0, math.inf)
        if o["strategy"] not in SCIPY_STRATEGIES:
            raise ValidationError(f"unknown strategy {o['strategy']!r:.60}; valid: {list(SCIPY_STRATEGIES)}",
                                  field="options.strategy")
        if not isinstance(o["polish"], (bool, np.bool_)):
            raise ValidationError(f"must be True or False, got {o['polish']!r:.60}", field="options.polish")
        goal = target_error(o, problem)
        clock = Clock(check_budget(o))
        ev = Evaluator(problem)
        m = problem.n_targets
        lower, upper = problem.space.lower, problem.space.upper
        free = np.flatnonzero(upper > lower)
        # current best per target, starting from the box centre (or x0) so the trace is defined
        best_x = problem.x0.copy() if problem.x0 is not None else np.tile((lower + upper) / 2, (m, 1))
        _, best_e, best_v = ev(best_x)
        best_e, best_v = best_e.copy(), best_v.copy()
        trace.record(ev.nfev, best_e, best_v)
        seeds = rng.integers(0, 2**63 - 1, size=m)
        nit = 0
        msgs = set()
        for i in range(m):
            if clock.expired():
                msgs.add("time budget spent")
                break
            row = np.array([i])
            base = best_x[i].copy()

            def fun(Z: np.ndarray, row: np.ndarray = row, base: np.ndarray = base) -> np.ndarray:
                Z = np.asarray(Z, float)
                Z = Z.T if Z.ndim == 2 else Z[None]   # scipy passes (n_free, S) when vectorized
                X = np.tile(base, (Z.shape[0], 1))
                X[:, free] = Z
                f, _, _ = ev(X[None], row)
                return f[0]

            def make_cb(i: int, base: np.ndarray) -> Any:
                def cb(intermediate_result: Any) -> bool:
                    X = base.copy()
                    X[free] = intermediate_result.x
                    _, e, v = ev(X[None, None], np.array([i]))
                    best_x[i], best_e[i], best_v[i] = X, e[0, 0], v[0, 0]
                    trace.record(ev.nfev, best_e, best_v)
                    return bool(solved_mask(e[0, 0], v[0, 0], goal)) or clock.expired()
                return cb

            if free.size == 0:
                continue
            res = differential_evolution(
                fun, bounds=list(zip(lower[free], upper[free])), popsize=o["popsize"], maxiter=o["maxiter"],
                mutation=mutation, recombination=recombination, strategy=o["strategy"],
                tol=tol, polish=bool(o["polish"]), vectorized=True, updating="deferred",
                rng=np.random.default_rng(int(seeds[i])), callback=make_cb(i, base))
            X = base.copy()
            X[free] = res.x
            _, e, v = ev(X[None, None], row)
            if e[0, 0] <= best_e[i] or v[0, 0] < best_v[i]:
                best_x[i], best_e[i], best_v[i] = X, e[0, 0], v[0, 0]
            nit = max(nit, int(res.nit))
            msgs.add(str(res.message))
        return SolverOutput(x=best_x, nfev=ev.nfev, nit=nit, message="; ".join(sorted(msgs)))
