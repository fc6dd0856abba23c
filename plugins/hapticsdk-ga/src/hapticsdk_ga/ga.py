"""The reference paper's genetic algorithm, batched over targets x population.

Table 3 of the paper: population 100, 50 generations, tournament selection of size 2,
single-point crossover fraction 0.6, uniform mutation rate 0.2, real-coded genes bounded
by each feature's range. The paper used MATLAB's ``ga`` (its network is MATLAB's
``tansig``/``trainlm``/``mapminmax``), so settings it does not state follow MATLAB's
defaults, which give these semantics:

* each generation keeps ``elite_count`` best individuals unchanged (MATLAB default
  ``ceil(0.05 * population)`` = 5 for 100; the paper does not state it, so the default
  follows the toolbox it used -- and elitism makes the best error monotone, which the
  stopping rule and the work-precision traces rely on; set ``elite_count=0`` to disable);
* of the remaining ``population - elite_count`` children, ``round(crossover_fraction * n)``
  come from single-point crossover of two tournament-selected parents (genes ``[:c]`` of
  one, ``[c:]`` of the other, cut ``c`` uniform in ``1..d-1``) and the rest from uniform
  mutation of one tournament-selected parent (each gene, with probability
  ``mutation_rate``, replaced by a uniform draw within its bounds);
* fitness is formula (6) (``problem.penalty`` chooses the paper's or the normalised form).

Every generation evaluates the children of all still-active targets in ONE model call.
A target whose best individual meets ``target_error`` (default: the problem's tolerance)
with constraints met leaves the active set; the run stops when none is active, after
``generations``, or when ``time_budget_s`` is spent. The run is deterministic for a seed.
One random stream serves the whole batch, so a target's answer depends on the seed and on
its position in the batch (not only on the target): solving a target alone or inside a
batch gives equally good but not bit-identical answers.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from hapticsdk.solvers import SolveProblem, Solver, SolverOutput, Trace

from ._common import Clock, Evaluator, check_budget, check_fraction, check_int, rank_key, solved_mask, target_error


def _tournament(fit: np.ndarray, n: int, size: int, rng: np.random.Generator) -> np.ndarray:
    """Flat indices (into ``fit.ravel()``) ``(r, n)`` of tournament winners (lowest fitness)."""
    r, p = fit.shape
    flat = fit.ravel()
    cand = rng.integers(0, p, size=(size, r, n)) + (np.arange(r) * p)[None, :, None]
    win = cand[0]
    fw = np.take(flat, win)
    for j in range(1, size):
        c = cand[j]
        fc = np.take(flat, c)
        better = fc < fw
        win = np.where(better, c, win)
        fw = np.where(better, fc, fw)
    return win


def ga_generation(pop: np.ndarray, fit: np.ndarray, lower: np.ndarray, span: np.ndarray, *,
                  elite: int, n_cross: int, tournament: int, mutation_rate: float,
                  rng: np.random.Generator) -> np.ndarray:
    """Next population ``(r, p, d)`` from ``pop`` and its fitness ``(r, p)``."""
    r, p, d = pop.shape
    out = np.empty_like(pop)
    flat_pop = pop.reshape(r * p, d)
    if elite:
        order = np.argpartition(fit, elite - 1, axis=1)[:, :elite] if elite < p else np.argsort(fit, axis=1)
        out[:, :elite] = np.take(flat_pop, order[:, :elite] + (np.arange(r) * p)[:, None], axis=0)
    n_mut = p - elite - n_cross
    winners = _tournament(fit, 2 * n_cross + n_mut, tournament, rng)
    par = np.take(flat_pop, winners, axis=0)   # (r, 2nx + nm, d); np.take: faster than fancy indexing
    if n_cross:
        a, b = par[:, :n_cross], par[:, n_cross:2 * n_cross]
        if d > 1:
            cut = rng.integers(1, d, size=(r, n_cross, 1))
            np.copyto(out[:, elite:elite + n_cross], np.where(np.arange(d) < cut, a, b))
        else:
            out[:, elite:elite + n_cross] = a
    if n_mut:
        base = par[:, 2 * n_cross:]
        u = rng.random((2, r, n_mut, d))
        np.copyto(out[:, elite + n_cross:], np.where(u[0] < mutation_rate, lower + u[1] * span, base))
    return out


class GASolver(Solver):
    """Real-coded GA of the reference paper (Table 3), vectorised over targets x population.

    Options (defaults = the paper's Table 3 where it has one):

    ``population`` (100), ``generations`` (50), ``tournament`` size (2),
    ``crossover_fraction`` (0.6), ``mutation_rate`` (0.2, per gene, uniform within bounds),
    ``elite_count`` (5 = MATLAB ``ga`` default 5 % of 100; 0 disables elitism),
    ``target_error`` (None = the problem's tolerance; 0 never stops early),
    ``time_budget_s`` (None = unlimited; wall seconds for the whole batch),
    ``init`` (``"uniform"``: uniform in bounds; ``problem.x0`` rows, when given, replace
    individual 0 of each target).
    """

    name: ClassVar[str] = "ga"
    default_options: ClassVar[dict[str, Any]] = {
        "population": 100, "generations": 50, "tournament": 2, "crossover_fraction": 0.6,
        "mutation_rate": 0.2, "elite_count": 5, "target_error": None, "time_budget_s": None,
        "init": "uniform",
    }

    def _settings(self) -> dict[str, Any]:
        o = self.options
        pop = check_int(o, "population", 2)
        s = {"population": pop, "generations": check_int(o, "generations", 0),
             "tournament": check_int(o, "tournament", 1, pop),
             "crossover_fraction": check_fraction(o, "crossover_fraction"),
             "mutation_rate": check_fraction(o, "mutation_rate"),
             "elite_count": check_int(o, "elite_count", 0, pop - 1),
             "time_budget_s": check_budget(o)}
        if o["init"] != "uniform":
            from hapticsdk.errors import ValidationError
            raise ValidationError(f"unknown init {o['init']!r}; valid: ['uniform']", field="options.init")
        return s

    def _solve(self, problem: SolveProblem, rng: np.random.Generator, trace: Trace) -> SolverOutput:
        s = self._settings()
        goal = target_error(self.options, problem)
        clock = Clock(s["time_budget_s"])
        ev = Evaluator(problem)
        m, d, p = problem.n_targets, problem.n_features, s["population"]
        elite = s["elite_count"]
        n_cross = int(round(s["crossover_fraction"] * (p - elite)))
        lower, span = ev.lower, ev.span

        pop = lower + rng.random((m, p, d)) * span
        if problem.x0 is not None:
            pop[:, 0] = problem.x0
        fit, err, viol = ev(pop)
        best_i = fit.argmin(axis=1)
        ar = np.arange(m)
        best_x = pop[ar, best_i].copy()
        best_f, best_e, best_v = fit[ar, best_i], err[ar, best_i], viol[ar, best_i]
        trace.record(ev.nfev, best_e, best_v)
        active = ~solved_mask(best_e, best_v, goal)
        pop, fit = pop[active], fit[active]
        gen = 0
        reason = "generations exhausted"
        while gen < s["generations"]:
            if not active.any():
                reason = f"all targets within target_error {goal:g}"
                break
            if clock.expired():
                reason = f"time budget {s['time_budget_s']:g} s spent"
                break
            rows = np.flatnonzero(active)
            pop = ga_generation(pop, fit, lower, span, elite=elite, n_cross=n_cross,
                                tournament=s["tournament"], mutation_rate=s["mutation_rate"], rng=rng)
            fit, err, viol = ev(pop, rows)
            gen += 1
            k = fit.argmin(axis=1)
            ra = np.arange(len(rows))
            better = fit[ra, k] < best_f[rows]
            upd = rows[better]
            best_x[upd] = pop[ra[better], k[better]]
            best_f[upd] = fit[ra[better], k[better]]
            best_e[upd] = err[ra[better], k[better]]
            best_v[upd] = viol[ra[better], k[better]]
            trace.record(ev.nfev, best_e, best_v)
            still = ~solved_mask(best_e[rows], best_v[rows], goal)
            if not still.all():
                active[rows[~still]] = False
                pop, fit = pop[still], fit[still]
        else:
            if not active.any():
                reason = f"all targets within target_error {goal:g}"
        return SolverOutput(x=best_x, nfev=ev.nfev, nit=gen,
                            message=f"{gen} generations, {reason}")


def best_of(err: np.ndarray, viol: np.ndarray) -> np.ndarray:
    """Index of the best candidate per row (feasible first, then lowest error)."""
    return rank_key(err, viol).argmin(axis=-1)
