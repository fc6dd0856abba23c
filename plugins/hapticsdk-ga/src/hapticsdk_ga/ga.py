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

Every generation evaluates the children of all still-active targets in ONE model call
(the elites are copied unchanged, so their fitness is reused, not recomputed). Tournament
selection is sampled through the fitness ranks (see :func:`_rank_select`: the same
selection law as drawing ``tournament`` individuals and keeping the best, with one random
number per selected parent instead of ``tournament``).
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

from ._common import (CONSTRAINT_TOL, Clock, Evaluator, check_budget, check_fraction, check_int, sample_cloud,
                      solved_mask, target_error)

#: upper limits of the size options (a run of the paper's size is 100 x 50; these bound a
#: mistyped value, e.g. ``generations: 1e9``, instead of running for days)
MAX_POPULATION = 100_000
MAX_GENERATIONS = 1_000_000
#: individuals of ``init="nearest"`` taken from the sample cloud
NEAREST_INIT = 8


def _rank_select(order_flat: np.ndarray, u: np.ndarray, size: int) -> np.ndarray:
    """Flat indices ``(r, n)`` of tournament winners from uniforms ``u`` ``(r, n)`` (overwritten).

    A tournament of ``size`` individuals drawn uniformly with replacement, won by the lowest
    fitness, selects the individual of rank ``K = min`` of ``size`` i.i.d. uniform ranks in
    ``0..p-1``. Since ``floor(p * min(U_i)) = min(floor(p * U_i))`` and ``min`` of ``size``
    i.i.d. U(0, 1) has the law of ``1 - V ** (1 / size)`` (V uniform), ``K = floor(p * (1 -
    V ** (1 / size)))`` has exactly the tournament's distribution (ties in fitness aside,
    which pick among equal-fitness individuals either way). ``order_flat`` ``(r, p)`` holds
    the flat indices (into ``pop.reshape(r * p, d)``) of each row's individuals sorted best
    first. One random number per winner instead of ``size``, and no fitness gathers.
    """
    r, p = order_flat.shape
    if size == 2:
        np.sqrt(u, out=u)
    elif size != 1:
        np.power(u, 1.0 / size, out=u)
    u *= -p
    u += p                                    # p * (1 - V^(1/size)) in [0, p]
    k = u.astype(np.intp)
    np.minimum(k, p - 1, out=k)
    if r > 1:   # row offsets (0 for one row)
        k += _offsets(r, p)
    return order_flat.take(k)


_CACHE: dict[tuple, np.ndarray] = {}


def _offsets(r: int, p: int) -> np.ndarray:
    """``(r, 1)`` row offsets ``i * p`` into a flattened ``(r, p)`` array (cached)."""
    key = ("off", r, p)
    o = _CACHE.get(key)
    if o is None:
        if len(_CACHE) > 256:
            _CACHE.clear()
        o = _CACHE[key] = (np.arange(r) * p)[:, None]
    return o


def _arange(r: int) -> np.ndarray:
    """``np.arange(r)`` (cached; read-only use)."""
    key = ("ar", r)
    o = _CACHE.get(key)
    if o is None:
        if len(_CACHE) > 256:
            _CACHE.clear()
        o = _CACHE[key] = np.arange(r)
    return o


def _cut_masks(d: int) -> np.ndarray:
    """``(d - 1, d)`` bool table, row ``j`` = genes ``[:j + 1]`` (single-point crossover
    with cut ``c = j + 1`` in ``1..d-1`` takes them from the first parent)."""
    key = ("cut", d)
    t = _CACHE.get(key)
    if t is None:
        t = _CACHE[key] = np.arange(d)[None, :] < np.arange(1, d)[:, None]
    return t


def _cut_masks_inv(d: int) -> np.ndarray:
    """``~_cut_masks(d)``: row ``j`` = the genes ``[j + 1:]`` a crossover child takes from
    its second parent (cached)."""
    key = ("cutinv", d)
    t = _CACHE.get(key)
    if t is None:
        t = _CACHE[key] = ~_cut_masks(d)
    return t


class GAWorkspace:
    """Preallocated buffers for :func:`ga_generation` (population double buffer, uniforms,
    crossover parents, mutation children), sized for ``m`` rows: a generation then writes
    into memory that is already mapped and cached instead of allocating ~1 MB of fresh
    temporaries (which the allocator returns to the system and faults in again every
    generation). A batch of ``r <= m`` active rows uses the leading ``r`` rows."""

    def __init__(self, m: int, p: int, d: int, elite: int, n_cross: int) -> None:
        n_mut = p - elite - n_cross
        self.n_u = 2 * n_cross + n_mut + (n_cross if d > 1 else 0) + n_mut * d
        self.pops = [np.empty((m, p, d)), np.empty((m, p, d))]
        self.turn = 0
        self.u = np.empty((m, self.n_u))
        self.a = np.empty((m, n_cross, d))
        self.b = np.empty((m, n_cross, d))
        self.child = np.empty((m, n_mut, d))
        #: ``(lower, span, lower tiled, span tiled)`` over the ``n_mut * d`` genes of one
        #: row's mutation children (:func:`ga_generation` with one row; set on first use)
        self.tiles: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._one: dict[tuple, tuple[Any, ...]] = {}

    def one_views(self, k: int, elite: int, n_cross: int, n_sel: int) -> tuple[Any, ...]:
        """Views for a one-row generation written into population buffer ``k`` (cached):
        that buffer's first row ``(1, p, d)``, its elite, crossover and mutation slices
        (and the latter flat), the uniforms' row and its selection, cut and mutation parts,
        and the second crossover parents; then the children ``out[:, elite:]`` and the
        crossover's second-parent masks (:func:`_cut_masks_inv`)."""
        key = (k, elite, n_cross, n_sel)
        v = self._one.get(key)
        if v is None:
            out = self.pops[k][:1]
            row = out[0]
            u = self.u[0]
            n_cut = self.n_u - n_sel - (row.shape[0] - elite - n_cross) * row.shape[1]
            child = row[elite + n_cross:]
            v = self._one[key] = (out, row[:elite], row[elite:elite + n_cross], child, child.reshape(-1),
                                  self.u[:1], u[:n_sel], u[n_sel:n_sel + n_cut], u[n_sel + n_cut:], self.b[0],
                                  out[:, elite:], _cut_masks_inv(row.shape[1]))
        return v

    def next_pop(self, r: int, current: np.ndarray) -> np.ndarray:
        """The buffer not holding ``current``, first ``r`` rows."""
        owner = current if current.base is None else current.base
        for buf in self.pops:
            if buf is not owner:
                return buf[:r]
        return np.empty((r,) + self.pops[0].shape[1:])  # pragma: no cover - defensive


def ga_generation(pop: np.ndarray, fit: np.ndarray, lower: np.ndarray, span: np.ndarray, *,
                  elite: int, n_cross: int, tournament: int, mutation_rate: float,
                  rng: np.random.Generator, order: np.ndarray | None = None,
                  work: GAWorkspace | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Next population ``(r, p, d)`` from ``pop`` and its fitness ``(r, p)``.

    Returns ``(new_pop, elite_src)``: ``new_pop[:, :elite]`` are the ``elite`` best of
    ``pop`` (best first), copied unchanged, and ``elite_src`` ``(r, elite)`` their flat
    indices into ``fit.ravel()`` (so the caller reuses their fitness instead of evaluating
    them again). ``order`` (optional) = ``np.argsort(fit, axis=1)``. With ``work`` (a
    :class:`GAWorkspace` of at least ``r`` rows) no large array is allocated and
    ``new_pop`` is a view of one of its buffers (valid until the next-but-one call).

    Random numbers per row, from ONE ``rng.random`` call: one per selected parent, one per
    crossover cut (``c = 1 + floor((d - 1) u)``, uniform in ``1..d-1``), one per gene of
    the mutation children (mutated when ``< mutation_rate``); a second call draws the new
    values of the mutated genes only (uniform within the gene's bounds).
    """
    r, p, d = pop.shape
    if order is None:
        order = fit.argsort(axis=1)
    if r == 1 and work is not None:
        return _generation_one(pop, order, lower, span, elite, n_cross, tournament, mutation_rate, rng, work)[:2]
    order_flat = order if r == 1 else order + _offsets(r, p)
    flat_pop = pop.reshape(r * p, d)
    n_mut = p - elite - n_cross
    n_sel = 2 * n_cross + n_mut
    n_cut = n_cross if d > 1 else 0
    n_u = n_sel + n_cut + n_mut * d
    if work is not None:
        out = work.next_pop(r, pop)
        u = rng.random((r, n_u), out=work.u[:r])
        bufs = (work.a[:r], work.b[:r], work.child[:r])
    else:
        out = np.empty_like(pop)
        u = rng.random((r, n_u))
        bufs = (None, None, None)  # type: ignore[assignment]  # fresh arrays per call
    if elite:
        flat_pop.take(order_flat[:, :elite], axis=0, out=out[:, :elite], mode="clip")
    winners = _rank_select(order_flat, u[:, :n_sel], tournament)
    if n_cross:
        a = flat_pop.take(winners[:, :n_cross], axis=0, out=bufs[0], mode="clip")       # (r, n_cross, d)
        if d > 1:
            b = flat_pop.take(winners[:, n_cross:2 * n_cross], axis=0, out=bufs[1], mode="clip")
            uc = u[:, n_sel:n_sel + n_cut]
            uc *= d - 1
            # genes [:cut] from a, the rest from b (np.where: half the time of a masked copy)
            a = np.where(_cut_masks(d).take(uc.astype(np.intp), axis=0), a, b)
        out[:, elite:elite + n_cross] = a
    if n_mut:
        child = flat_pop.take(winners[:, 2 * n_cross:], axis=0, out=bufs[2], mode="clip")  # (r, n_mut, d)
        hit = (u[:, n_sel + n_cut:] < mutation_rate).ravel().nonzero()[0]    # row-major = child's order
        if hit.size:
            g = hit % d
            child.reshape(-1)[hit] = lower[g] + rng.random(hit.size) * span[g]
        out[:, elite + n_cross:] = child
    return out, order_flat[:, :elite]


def _generation_one(pop: np.ndarray, order: np.ndarray, lower: np.ndarray, span: np.ndarray, elite: int,
                    n_cross: int, tournament: int, mutation_rate: float, rng: np.random.Generator,
                    work: GAWorkspace) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`ga_generation` for one row (a one-target solve), with the same random draws
    and the same individuals: the row's slices of the new population are contiguous, so
    the parents are gathered straight into them and the crossover copies the second
    parent's genes in place (no temporaries), and the mutated genes' bounds come from
    tables tiled once per run instead of ``gene % d`` gathers. A test compares it with
    the general path. Returns ``ga_generation``'s pair and the children ``new_pop[:, elite:]``."""
    _, p, d = pop.shape
    flat_pop = pop[0]
    n_mut = p - elite - n_cross
    n_sel = 2 * n_cross + n_mut
    owner = pop if pop.base is None else pop.base
    k = 1 if owner is work.pops[0] else 0       # the buffer not holding pop (as next_pop)
    out, row_e, a, child, child_flat, u1, us, uc, um, b, children, inv = work.one_views(k, elite, n_cross, n_sel)
    rng.random((1, work.n_u), out=u1)
    o = order[0]
    if elite:
        flat_pop.take(o[:elite], axis=0, out=row_e, mode="clip")
    # _rank_select on one row; take's mode="clip" is its np.minimum(k, p - 1)
    if tournament == 2:
        np.sqrt(us, out=us)
    elif tournament != 1:
        np.power(us, 1.0 / tournament, out=us)
    np.multiply(us, -p, out=us)      # (ufunc calls: the in-place operators cost ~0.25 us more each)
    np.add(us, p, out=us)
    winners = o.take(us.astype(np.intp), mode="clip")
    if n_cross:
        flat_pop.take(winners[:n_cross], axis=0, out=a, mode="clip")
        if d > 1:
            flat_pop.take(winners[n_cross:2 * n_cross], axis=0, out=b, mode="clip")
            np.multiply(uc, d - 1, out=uc)
            # genes [cut:] from b (the general path's np.where(mask, a, b), in place)
            np.copyto(a, b, where=inv.take(uc.astype(np.intp), axis=0))
    if n_mut:
        flat_pop.take(winners[2 * n_cross:], axis=0, out=child, mode="clip")
        hit = np.less(um, mutation_rate).nonzero()[0]    # row-major = child's order
        if hit.size:
            t = work.tiles
            if t is None or t[0] is not lower or t[1] is not span:
                lt, st = np.empty((n_mut, d)), np.empty((n_mut, d))
                lt[:] = lower
                st[:] = span
                t = work.tiles = (lower, span, lt.reshape(-1), st.reshape(-1))
            child_flat.put(hit, t[2].take(hit) + rng.random(hit.size) * t[3].take(hit))
    return out, order[:, :elite], children


class GASolver(Solver):
    """Real-coded GA of the reference paper (Table 3), vectorised over targets x population.

    Options (defaults = the paper's Table 3 where it has one):

    ``population`` (100), ``generations`` (50), ``tournament`` size (2),
    ``crossover_fraction`` (0.6), ``mutation_rate`` (0.2, per gene, uniform within bounds),
    ``elite_count`` (5 = MATLAB ``ga`` default 5 % of 100; 0 disables elitism),
    ``target_error`` (None = the problem's tolerance; 0 never stops early),
    ``time_budget_s`` (None = unlimited; wall seconds for the whole batch),
    ``init`` (``"uniform"``: uniform in bounds; ``"nearest"``: the first ``min(8,
    population)`` individuals of each target are the feasible samples of a fixed cached
    cloud whose intensities are nearest the target (:func:`~hapticsdk_ga._common.sample_cloud`),
    the rest uniform; with either, ``problem.x0`` rows, when given, replace individual 0),
    ``stall_generations`` (None = never: a target whose best fitness has not fallen by more
    than 0.1 % in that many generations leaves the batch, like MATLAB's
    ``MaxStallGenerations``).
    """

    name: ClassVar[str] = "ga"
    default_options: ClassVar[dict[str, Any]] = {
        "population": 100, "generations": 50, "tournament": 2, "crossover_fraction": 0.6,
        "mutation_rate": 0.2, "elite_count": 5, "target_error": None, "time_budget_s": None,
        "init": "uniform", "stall_generations": None,
    }

    def _settings(self) -> dict[str, Any]:
        o = self.options
        pop = check_int(o, "population", 2, MAX_POPULATION)
        s = {"population": pop, "generations": check_int(o, "generations", 0, MAX_GENERATIONS),
             "tournament": check_int(o, "tournament", 1, pop),
             "crossover_fraction": check_fraction(o, "crossover_fraction"),
             "mutation_rate": check_fraction(o, "mutation_rate"),
             "elite_count": check_int(o, "elite_count", 0, pop - 1),
             "time_budget_s": check_budget(o),
             "stall_generations": check_int(o, "stall_generations", 1, MAX_GENERATIONS, allow_none=True)}
        if o["init"] not in ("uniform", "nearest"):
            from hapticsdk.errors import ValidationError
            raise ValidationError(f"unknown init {o['init']!r}; valid: ['uniform', 'nearest']",
                                  field="options.init")
        return s

    def _solve(self, problem: SolveProblem, rng: np.random.Generator, trace: Trace) -> SolverOutput:
        s = self._settings()
        goal = target_error(self.options, problem)
        clock = Clock(s["time_budget_s"])
        ev = Evaluator(problem, finite=True)    # every individual is drawn inside the bounds
        m, d, p = problem.n_targets, problem.n_features, s["population"]
        elite = s["elite_count"]
        n_cross = int(round(s["crossover_fraction"] * (p - elite)))
        lower = problem.space.lower
        span = problem.space.upper - lower

        work = GAWorkspace(m, p, d, elite, n_cross)
        pop = work.pops[0]
        rng.random((m, p, d), out=pop)
        pop *= span
        pop += lower
        k0 = 0
        if self.options["init"] == "nearest":
            k0 = min(NEAREST_INIT, p)
            pop[:, :k0] = sample_cloud(problem).nearest(problem.targets, k0)
        if problem.x0 is not None:
            pop[:, 0] = problem.x0
        if k0:
            # the nearest samples first: a target one of them already meets leaves at once,
            # and only the others' uniform individuals are evaluated
            f0, e0, v0 = ev(pop[:, :k0])
            j0 = f0.argmin(axis=1)
            ar = np.arange(m)
            done = solved_mask(e0[ar, j0], v0[ar, j0], goal)
            fit, err, viol = (np.full((m, p), np.inf), np.full((m, p), np.inf), np.full((m, p), np.inf))
            fit[:, :k0], err[:, :k0], viol[:, :k0] = f0, e0, v0
            todo = np.flatnonzero(~done)
            if todo.size:
                fit[todo, k0:], err[todo, k0:], viol[todo, k0:] = ev(pop[todo, k0:], todo)
        else:
            fit, err, viol = ev(pop)
        best_i = fit.argmin(axis=1)
        ar = np.arange(m)
        best_x = pop[ar, best_i].copy()
        best_f, best_e, best_v = fit[ar, best_i], err[ar, best_i], viol[ar, best_i]
        trace.record(ev.nfev, best_e, best_v)
        active = ~solved_mask(best_e, best_v, goal)
        if not active.all():
            k = int(active.sum())
            pop[:k] = pop[active]
            pop, fit = pop[:k], fit[active]
        gen = 0
        reason = "generations exhausted"
        tour, mrate = s["tournament"], s["mutation_rate"]
        kw = dict(elite=elite, n_cross=n_cross, tournament=tour, mutation_rate=mrate)
        rows = np.flatnonzero(active)
        stall_n = s["stall_generations"]
        if stall_n is not None:
            ref_f = best_f.copy()           # best fitness when it last fell by > 0.1 %
            since = np.zeros(m, int)        # generations since then
        n_stalled = 0
        fbufs: tuple[np.ndarray, np.ndarray] | None = None    # fitness double buffer (as the population's)
        n_gen, budget = s["generations"], s["time_budget_s"] is not None
        fi = 0
        while gen < n_gen:
            if not rows.size:
                reason = f"all targets within target_error {goal:g}"
                break
            if budget and clock.expired():
                reason = f"time budget {s['time_budget_s']:g} s spent"
                break
            r = rows.size
            if fbufs is None:
                fbufs = (np.empty((m, p)), np.empty((m, p)))
                f_one = [(f[:1], f[:1, :elite], f[:1, elite:]) for f in fbufs]    # their views for one row
            if r == 1:   # one row: its own path (same draws, same individuals)
                pop, esrc, children = _generation_one(pop, fit.argsort(axis=1), lower, span, elite, n_cross,
                                                      tour, mrate, rng, work)
                nf, nf_e, nf_c = f_one[fi]
            else:
                pop, esrc = ga_generation(pop, fit, lower, span, rng=rng, work=work, **kw)
                children = pop[:, elite:]
                nf = fbufs[fi][:r]
                nf_e, nf_c = nf[:, :elite], nf[:, elite:]
            fi ^= 1      # nf is not fit's buffer: fit is the other one or a fresh array
            # the elites are copied unchanged: their fitness is reused, only the children are
            # evaluated. An elite never beats best_f (elite 0 is the previous best), so the
            # best-so-far update only looks at the children.
            # (fc, ec, vc: views of buffers reused every generation; read or copied below)
            # (vc None: the violation only where a child becomes the best, from ev.violation_at)
            fc, ec, vc = ev.lazy(children, rows if r < m else None)   # rows: sorted, all when r == m
            if elite:
                fit.take(esrc, out=nf_e)
            np.copyto(nf_c, fc)
            fit = nf
            gen += 1
            if r == 1:   # one active target: the same bookkeeping on scalars (fewer numpy calls)
                kk = int(fc.argmin())     # fc is (1, c)
                i0 = int(rows[0])
                fk0 = fc[0, kk]
                if fk0 < best_f[i0]:
                    best_x[i0] = pop[0, kk + elite]
                    best_f[i0], best_e[i0] = fk0, ec[0, kk]
                    best_v[i0] = ev.violation_at(kk) if vc is None else vc[0, kk]
                    trace.record(ev.nfev, best_e, best_v)
                    if best_e[i0] <= goal and best_v[i0] <= CONSTRAINT_TOL:    # solved_mask
                        rows = rows[:0]
                        pop, fit = pop[:0], fit[:0]
                else:
                    trace.repeat(ev.nfev)      # best_e, best_v unchanged since the last record
            else:
                k = fc.argmin(axis=1)
                ra = _arange(r)
                fk = fc[ra, k]
                better = fk < (best_f if r == m else best_f[rows])
                if better.any():
                    upd, kb, rb = rows[better], k[better], ra[better]
                    best_x[upd] = pop[rb, kb + elite]
                    best_f[upd] = fk[better]
                    best_e[upd] = ec[rb, kb]
                    best_v[upd] = ev.violation_at(rb * (p - elite) + kb) if vc is None else vc[rb, kb]
                    trace.record(ev.nfev, best_e, best_v)
                    still = ~solved_mask(best_e[rows], best_v[rows], goal)
                    if not still.all():
                        rows = rows[still]
                        k = rows.size
                        pop[:k] = pop[still]          # compact in place (leading rows of the buffer)
                        pop, fit = pop[:k], fit[still]
                else:
                    trace.repeat(ev.nfev)
            if stall_n is not None and rows.size:
                fell = best_f[rows] < ref_f[rows] - 1e-3 * np.abs(ref_f[rows])
                ref_f[rows[fell]] = best_f[rows[fell]]
                since[rows] = np.where(fell, 0, since[rows] + 1)
                still = since[rows] < stall_n
                if not still.all():
                    n_stalled += int((~still).sum())
                    rows = rows[still]
                    k = rows.size
                    pop[:k] = pop[still]
                    pop, fit = pop[:k], fit[still]
        else:
            if not rows.size:
                reason = f"all targets within target_error {goal:g}"
        if n_stalled:
            reason += f"; {n_stalled} target(s) stalled for {stall_n} generations"
        return SolverOutput(x=best_x, nfev=ev.nfev, nit=gen,
                            message=f"{gen} generations, {reason}")

