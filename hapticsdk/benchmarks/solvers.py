"""Solver benchmark: work-precision, runtime-to-target, peers, penalty forms, call costs.

Run with ``hapticsdk bench solvers [--json] [--plot FILE] [--quick]`` (or
``python bench/bench_solvers.py``), on one core: set ``OMP_NUM_THREADS=1`` before the
process starts (the ONNX model already runs onnxruntime with one intra-op thread).

Targets (:func:`bench_targets`):

* the material library (``hapticsdk/data/materials.json``, its intensities),
* reachable extremes: the feasible model outputs (20000 uniform feature samples, seed 0,
  constraints met) that are extreme along h, r, h+r and h-r,
* candidate unreachable targets: the corners and edge midpoints of the intensity square.

Every target gets a *reference* answer: the best of a 16-start, 100-iteration LM polish
and a 200-generation GA. A target is *reachable* when the reference error is <= 1e-6
(the model output can be met exactly), *boundary* when it is above that but within the
tolerance, *unreachable* beyond the tolerance (those must end ``success=False`` for every
solver; checked and reported).

Work-precision: for each solver, a list of settings (generations, LM iterations, ...);
each setting solves the whole reachable batch once per seed with ``target_error=0`` (no
early stop); per run, ``time_s`` = wall time of the batched call / number of targets and
``error`` = the 90th percentile over the targets of the sum of absolute intensity errors;
a point is the median over seeds of both, with the 10th and 90th percentiles over seeds
of the error as spread. Runtime-to-target (COCO style, fixed targets 1e-1, 1e-2, 1e-3):
from the per-iteration traces of the largest setting, the first wall time (per target)
at which the 90th percentile of the best errors over the targets reaches the threshold;
median over seeds, ``null`` when fewer than half of the seeds reach it. Next to every p90
the benchmark gives the worst error over all runs (``error_max``) and the number of solves
that ended outside the problem's tolerance or with a violated constraint (``failures`` of
``solves``): a p90 alone hides a solver that misses a few targets.

Times: ``time_s`` is wall time (the machine may be shared), ``cpu_s`` the process CPU
time of the same call (what to compare on a loaded machine). Public calls
(:func:`public_calls`) time :func:`hapticsdk.solvers.problems.solve` itself, one target per call,
next to the solver-internal ``time_s`` the result reports; the amortised table's build
time is reported separately (:func:`amortised_stats`). Not measured: start-up (imports,
plugin and model loading; see docs/runtime.md), and any machine but the one it runs on.
"""

from __future__ import annotations

import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import ValidationError
from ..solvers.problems import get_solver as _solver
from ..solvers import CONSTRAINT_TOL, SolveProblem

THRESHOLDS = (1e-1, 1e-2, 1e-3)
DIMS = ("hardness", "roughness")


# ---------------------------------------------------------------------------
# problem and targets

def load_material_targets(path: str | Path | None = None) -> tuple[list[str], np.ndarray]:
    """Names and ``(m, 2)`` (hardness, roughness) intensities of the material library."""
    from ..perception.materials import load_library
    mats = list(load_library(path))
    return [m.name for m in mats], np.array([[m.intensities[d] for d in DIMS] for m in mats], float)


def make_problem_factory() -> tuple[Callable[..., SolveProblem], str]:
    """``factory(targets, penalty=...) -> SolveProblem`` on the default model, and its
    description. Raises when the default model or the dimensions are not installed."""
    from ..solvers.problems import build_problem

    probe = build_problem(np.array([[0.5, 0.5]]), dimensions=DIMS)
    mdl = probe.model
    sha = getattr(mdl, "file_sha256", None) or getattr(mdl, "_sha256", None)
    runtime = getattr(mdl, "runtime", None)   # OnnxModel: "numpy" (dense chain) or "onnxruntime"
    desc = f"{type(mdl).__name__} {mdl.name!r} (default model" + (f", file sha256 {sha[:12]}" if sha else "") + \
           (f", evaluated with {runtime}" if runtime else "") + f"), space {list(probe.space.names)}, " \
           f"constraints {[c.name for c in probe.constraints]}"

    def factory(T: np.ndarray, penalty: str = "paper", **kw: Any) -> SolveProblem:
        return build_problem(np.asarray(T, float), dimensions=DIMS, penalty=penalty, **kw)

    return factory, desc


def feasible_samples(problem: SolveProblem, n: int = 20000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random feature vectors of ``problem``'s space that meet every constraint, and
    the model's predicted intensities for them (the reachable intensity set).
    """
    X = problem.space.random(n, np.random.default_rng(seed))
    G = problem.full_inputs(X)
    names = problem.model.dimension_names
    Y = problem.model.predict(G)[:, [names.index(d) for d in problem.dimensions]]
    ok = np.ones(n, bool)
    cols = problem.columns(G)
    for c in problem.constraints:
        ok &= c.violation(cols) <= CONSTRAINT_TOL
    return X[ok], Y[ok]


def bench_targets(factory: Callable[..., SolveProblem], material_path: str | None = None
                  ) -> dict[str, Any]:
    """The benchmark's targets: the material library's intensities plus extreme points of
    the reachable intensity set (min/max of each dimension and of their sum and
    difference).
    """
    names, TM = load_material_targets(material_path)
    probe = factory(np.array([[0.5, 0.5]]))
    _, Y = feasible_samples(probe)
    ext_idx, ext_names = [], []
    for lab, v in (("min h", Y[:, 0]), ("max h", -Y[:, 0]), ("min r", Y[:, 1]), ("max r", -Y[:, 1]),
                   ("min h+r", Y.sum(1)), ("max h+r", -Y.sum(1)), ("min h-r", Y[:, 0] - Y[:, 1]),
                   ("max h-r", Y[:, 1] - Y[:, 0])):
        k = int(np.argmin(v))
        if k not in ext_idx:
            ext_idx.append(k)
            ext_names.append(f"extreme {lab}")
    TE = Y[ext_idx]
    TU = np.array([[0, 0], [1, 1], [0, 1], [1, 0], [0.5, 0], [0.5, 1], [0, 0.5], [1, 0.5]], float)
    T = np.concatenate([TM, TE, TU])
    labels = names + ext_names + [f"square ({a:g}, {b:g})" for a, b in TU]
    kinds = ["material"] * len(TM) + ["extreme"] * len(TE) + ["candidate-unreachable"] * len(TU)
    return {"targets": T, "labels": labels, "kinds": kinds}


def reference_errors(factory: Callable[..., SolveProblem], T: np.ndarray) -> np.ndarray:
    """Best error per target reached by a long polish and a long GA run (the reference a
    solver's error is compared with; ``inf`` where neither meets the constraints).
    """
    from hapticsdk_ga.ga import GASolver
    from hapticsdk_ga.polish import PolishSolver

    p = factory(T)
    a = PolishSolver(starts=16, max_iter=100, target_error=1e-10).solve(p, seed=12345)
    b = GASolver(generations=200, target_error=0).solve(p, seed=12345)
    ea = np.where([r.constraint_violation <= CONSTRAINT_TOL for r in a], a.error, np.inf)
    eb = np.where([r.constraint_violation <= CONSTRAINT_TOL for r in b], b.error, np.inf)
    return np.minimum(ea, eb)


# ---------------------------------------------------------------------------
# runs

def _p(v: Any, q: float) -> float:
    return float(np.percentile(np.asarray(v, float), q))


def _trace_p90(res: Any) -> tuple[np.ndarray, np.ndarray]:
    """(time_s per iteration, p90 over targets of best error per iteration)."""
    n = min(len(r.trace) for r in res)
    times = np.array([res[0].trace[i]["time_s"] for i in range(n)])
    E = np.array([[r.trace[i]["best_error"] for r in res] for i in range(n)])
    return times, np.percentile(E, 90, axis=1)


def work_precision(factory: Callable[..., SolveProblem], T: np.ndarray, name: str,
                   settings: list[dict[str, Any]], seeds: list[int], *, penalty: str = "paper",
                   prepare: Callable[[SolveProblem, Any], None] | None = None) -> dict[str, Any]:
    """Run solver ``name`` with each option set in ``settings`` and each seed on targets
    ``T``; returns its work-precision points (time per target vs error) and its times to
    reach each error threshold.
    """
    p = factory(T, penalty=penalty)
    m = len(T)
    points = []
    ttt: dict[str, list[float | None]] = {f"{t:g}": [] for t in THRESHOLDS}
    for k, opts in enumerate(settings):
        S = _solver(name, **opts)
        if prepare:
            prepare(p, S)
        else:
            S.solve(factory(T[:1], penalty=penalty), seed=0)  # warm-up
        times, cpus, errs, succ, emax, fails = [], [], [], [], [], 0
        every: list[float] = []
        for s in seeds:
            c0 = time.process_time()
            t0 = time.perf_counter()
            res = S.solve(p, seed=s)
            dt = time.perf_counter() - t0
            cpus.append((time.process_time() - c0) / m)
            times.append(dt / m)
            every.extend(float(e) for e in res.error)
            errs.append(_p(res.error, 90))
            emax.append(float(np.max(res.error)))
            succ.append(float(np.mean(res.success)))
            fails += int(np.sum(~res.success))
            if k == len(settings) - 1:
                tt, e90 = _trace_p90(res)
                for thr in THRESHOLDS:
                    hit = np.flatnonzero(e90 <= thr)
                    ttt[f"{thr:g}"].append(float(tt[hit[0]]) / m if hit.size else None)
        points.append({"setting": opts, "time_s": statistics.median(times), "cpu_s": statistics.median(cpus),
                       "error": statistics.median(errs), "error_p10": _p(errs, 10), "error_p90": _p(errs, 90),
                       "error_max": max(emax), "failures": fails, "solves": m * len(seeds),
                       "success_rate": statistics.median(succ), "runs": len(seeds),
                       # the statistic the figures use in both calling patterns: over every solve
                       "solve_error_p10": _p(every, 10), "solve_error_p50": _p(every, 50),
                       "solve_error_p90": _p(every, 90)})
    out_ttt = {}
    for key, vals in ttt.items():
        got = [v for v in vals if v is not None]
        out_ttt[key] = statistics.median(got) if len(got) * 2 >= max(len(vals), 1) else None
    return {"points": points, "time_to_error": out_ttt}


# ---------------------------------------------------------------------------
# peers: same fitness (one target row of formula (6)), population 100, 50 generations

def _peer_fitness(p: SolveProblem, i: int) -> Callable[[np.ndarray], np.ndarray]:
    """Formula (6) of target ``i`` for candidate rows ``(n, d)``."""
    rows = np.array([i])

    def f(X: np.ndarray) -> np.ndarray:
        return p.evaluate(np.asarray(X, float)[None], rows=rows)[0]
    return f


def peer_pygad(p: SolveProblem, i: int, seed: int, pop: int = 100, gens: int = 50) -> np.ndarray:
    """Solve target ``i`` of ``p`` with pygad's GA (population ``pop``, ``gens``
    generations); returns the best feature vector (physical units).
    """
    import pygad
    f = _peer_fitness(p, i)
    lo, hi = p.space.lower, p.space.upper

    def fit(ga: Any, sols: Any, idx: Any) -> Any:
        return -f(np.atleast_2d(sols))

    ga = pygad.GA(num_generations=gens, sol_per_pop=pop, num_parents_mating=pop // 2, num_genes=len(lo),
                  fitness_func=fit, fitness_batch_size=pop, gene_space=[{"low": a, "high": b} for a, b in zip(lo, hi)],
                  init_range_low=0, init_range_high=1, parent_selection_type="tournament", K_tournament=2,
                  crossover_type="single_point", crossover_probability=0.6, mutation_type="random",
                  mutation_probability=0.2, keep_elitism=5, random_seed=seed, suppress_warnings=True,
                  save_solutions=False)
    ga.run()
    return np.asarray(ga.best_solution(pop_fitness=ga.last_generation_fitness)[0], float)


def peer_deap(p: SolveProblem, i: int, seed: int, pop: int = 100, gens: int = 50) -> np.ndarray:
    """Solve target ``i`` of ``p`` with DEAP's simple GA (population ``pop``, ``gens``
    generations); returns the best feature vector (physical units).
    """
    import random
    from deap import algorithms, base, creator, tools
    f = _peer_fitness(p, i)
    lo, hi = p.space.lower, p.space.upper
    if not hasattr(creator, "HsdkFitMin"):
        creator.create("HsdkFitMin", base.Fitness, weights=(-1.0,))
        creator.create("HsdkInd", list, fitness=creator.HsdkFitMin)
    rnd = random.Random(seed)
    tb = base.Toolbox()
    tb.register("individual", lambda: creator.HsdkInd([rnd.uniform(a, b) for a, b in zip(lo, hi)]))
    tb.register("population", tools.initRepeat, list, tb.individual)

    def batched_map(func: Any, inds: Any) -> list:
        inds = list(inds)
        if not inds:
            return []
        vals = f(np.array(inds, float))
        return [(float(v),) for v in vals]

    def mutate(ind: Any) -> tuple:
        for j, (a, b) in enumerate(zip(lo, hi)):
            if rnd.random() < 0.2:
                ind[j] = rnd.uniform(a, b)
        return (ind,)

    def mate(a: Any, b: Any) -> tuple:
        if len(a) > 1:
            c = rnd.randint(1, len(a) - 1)
            a[c:], b[c:] = b[c:], a[c:]
        return a, b

    tb.register("evaluate", lambda ind: (0.0,))
    tb.register("map", batched_map)
    tb.register("mate", mate)
    tb.register("mutate", mutate)
    tb.register("select", tools.selTournament, tournsize=2)
    random.seed(seed)
    population = tb.population(n=pop)
    hof = tools.HallOfFame(1)
    algorithms.eaSimple(population, tb, cxpb=0.6, mutpb=0.2, ngen=gens, halloffame=hof, verbose=False)
    return np.asarray(hof[0], float)


def peer_pymoo(p: SolveProblem, i: int, seed: int, pop: int = 100, gens: int = 50) -> np.ndarray:
    """Solve target ``i`` of ``p`` with pymoo's GA (population ``pop``, ``gens``
    generations); returns the best feature vector (physical units).
    """
    from pymoo.algorithms.soo.nonconvex.ga import GA
    from pymoo.core.problem import Problem
    from pymoo.optimize import minimize
    f = _peer_fitness(p, i)
    lo, hi = p.space.lower, p.space.upper
    free = hi > lo

    class P(Problem):
        def __init__(self) -> None:
            super().__init__(n_var=int(free.sum()), n_obj=1, xl=lo[free], xu=hi[free])

        def _evaluate(self, Z: Any, out: Any, *a: Any, **k: Any) -> None:
            X = np.tile(lo, (len(Z), 1))
            X[:, free] = Z
            out["F"] = f(X)

    res = minimize(P(), GA(pop_size=pop, eliminate_duplicates=False), ("n_gen", gens), seed=seed, verbose=False)
    x = lo.copy()
    x[free] = np.asarray(res.X, float).reshape(-1)
    return x


def peer_numpy_ga(p: SolveProblem, i: int, seed: int, pop: int = 100, gens: int = 50) -> np.ndarray:
    """A plain vectorised numpy GA, as a user would write it: the paper's operators
    (tournament 2, single-point crossover 0.6, uniform mutation 0.2 per gene, 5 elites),
    the whole population evaluated in one call per generation."""
    f = _peer_fitness(p, i)
    lo, hi = p.space.lower, p.space.upper
    rng = np.random.default_rng(seed)
    d = len(lo)
    P = lo + rng.random((pop, d)) * (hi - lo)
    F = f(P)
    n_el = 5
    for _ in range(gens):
        order = np.argsort(F)
        elite = P[order[:n_el]]
        n = pop - n_el

        def tour(k: int) -> np.ndarray:
            a, b = rng.integers(0, pop, k), rng.integers(0, pop, k)
            return P[np.where(F[a] <= F[b], a, b)]
        n_x = int(round(0.6 * n))
        pa, pb = tour(n_x), tour(n_x)
        cut = rng.integers(1, d, n_x) if d > 1 else np.zeros(n_x, int)
        kids = np.where(np.arange(d)[None, :] < cut[:, None], pa, pb)
        mut = tour(n - n_x)
        mask = rng.random(mut.shape) < 0.2
        mut = np.where(mask, lo + rng.random(mut.shape) * (hi - lo), mut)
        P = np.concatenate([elite, kids, mut])
        F = np.concatenate([F[order[:n_el]], f(P[n_el:])])
    return P[int(np.argmin(F))]


def peer_scipy_de(p: SolveProblem, i: int, seed: int, pop: int = 100, gens: int = 50) -> np.ndarray:
    """``scipy.optimize.differential_evolution`` with ``vectorized=True`` (one call per
    generation), population about ``pop`` (popsize = pop / features), ``gens`` generations,
    no final polish (scipy's polish is an unbatched L-BFGS-B), tol 0 (the full budget)."""
    from scipy.optimize import differential_evolution
    f = _peer_fitness(p, i)
    lo, hi = p.space.lower, p.space.upper
    free = hi > lo

    def fun(Z: np.ndarray) -> np.ndarray:
        Z = np.atleast_2d(np.asarray(Z, float).T)
        X = np.tile(lo, (len(Z), 1))
        X[:, free] = Z
        return f(X)

    res = differential_evolution(fun, list(zip(lo[free], hi[free])), popsize=max(1, pop // int(free.sum())),
                                 maxiter=gens, tol=0.0, polish=False, vectorized=True, updating="deferred",
                                 rng=np.random.default_rng(seed))
    x = lo.copy()
    x[free] = res.x
    return x


def peer_lbfgsb(p: SolveProblem, i: int, seed: int, starts: int = 8, gens: int | None = None,
                **_: Any) -> np.ndarray:
    """Multi-start ``scipy.optimize.minimize(method="L-BFGS-B")`` on formula (6), features
    scaled to the unit box (``x = lower + u * span``, bounds 0..1: in physical units the
    gradient is so small along Hz or mJ that scipy's default ``gtol`` stops at once),
    scipy's finite-difference gradient with a step of 3e-4 (about the square root of a
    float32 model's resolution; scipy's default 1e-8 is below it and gives a gradient of
    rounding noise), ``starts`` uniform starts, the best answer kept (``gens``: iteration
    limit per start, default scipy's)."""
    from scipy.optimize import minimize
    f = _peer_fitness(p, i)
    lo, hi = p.space.lower, p.space.upper
    span = hi - lo
    rng = np.random.default_rng(seed)
    best, best_f = None, np.inf
    for _start in range(starts):
        u0 = rng.random(len(lo))
        r = minimize(lambda u: float(f((lo + u * span)[None])[0]), u0, method="L-BFGS-B",
                     bounds=[(0.0, 1.0)] * len(lo),
                     options={"eps": 3e-4, **({} if gens is None else {"maxiter": gens})})
        if r.fun < best_f:
            best, best_f = lo + r.x * span, r.fun
    return np.asarray(best, float)


#: peers, one target per call, same fitness (formula (6)); the first three are what a user
#: would write or pick in numpy/scipy, the last three are GA libraries
PEERS: dict[str, Callable[..., np.ndarray]] = {"numpy-ga": peer_numpy_ga, "scipy-de": peer_scipy_de, "lbfgsb-multistart": peer_lbfgsb,
         "pygad": peer_pygad, "deap": peer_deap, "pymoo": peer_pymoo}


def _err_stats(errs: list[float], fails: int) -> dict[str, Any]:
    return {"error": _p(errs, 50), "error_p10": _p(errs, 10), "error_p90": _p(errs, 90),
            "error_max": float(np.max(errs)), "failures": int(fails), "solves": len(errs),
            "solve_error_p10": _p(errs, 10), "solve_error_p50": _p(errs, 50), "solve_error_p90": _p(errs, 90)}


def run_peers(factory: Callable[..., SolveProblem], T: np.ndarray, seeds: list[int]) -> dict[str, Any]:
    """Each peer and our solvers solve each target one by one (population 100 and 50
    generations where there is a population); CPU time per target (median), error
    p50/p90/max over targets x seeds, failures (error above the tolerance or a violated
    constraint)."""
    from hapticsdk_ga.amortised import AmortisedSolver
    from hapticsdk_ga.ga import GASolver
    from hapticsdk_ga.polish import GAPolishSolver, PolishSolver
    p = factory(T)
    tol = p.tolerance
    out: dict[str, Any] = {}
    ours: dict[str, Any] = {"ga (ours, one target per call)": GASolver(target_error=0),
                            "ga-polish (ours, one target per call)": GAPolishSolver(),
                            "polish (ours, one target per call)": PolishSolver(),
                            "amortised (ours, one target per call)": AmortisedSolver()}
    t_ours: float | None = None
    for label, S in ours.items():
        S.solve(p.with_targets(T[0]), seed=0)   # warm-up (the amortised table is built or loaded here)
        times, errs, fails = [], [], 0
        for s in seeds:
            for i in range(len(T)):
                # the same problem setup, one target (as hapticsdk.solvers.problems.solve keeps it per
                # setup); the peers get that setup too
                pi = p.with_targets(T[i])     # a 1-D target: the one-target call of the public API
                c0 = time.process_time()
                r = S.solve(pi, seed=s)
                times.append(time.process_time() - c0)
                errs.append(float(r.error))
                fails += int(not r.success)
        t = statistics.median(times)
        if t_ours is None:
            t_ours = t
        out[label] = {"points": [{"time_s": t, "cpu_s": t, **_err_stats(errs, fails)}], "time_to_error": None,
                      "time_ratio_vs_ours": t / t_ours}
    for name, fn in PEERS.items():
        try:
            fn(p, 0, 0, pop=10, gens=2)  # import + warm-up
        except Exception as exc:  # peer not installed or API changed: report, don't fail
            out[name] = {"error": f"{type(exc).__name__}: {exc}"}
            continue
        times, errs, fails = [], [], 0
        for s in seeds:
            for i in range(len(T)):
                c0 = time.process_time()
                x = fn(p, i, s)
                times.append(time.process_time() - c0)
                ev = p.evaluate(p.space.clip(x)[None], details=True, rows=np.array([i]))
                e, v = float(ev["error"][0]), float(ev["violation"][0])
                errs.append(e)
                fails += int(not (e <= tol and v <= CONSTRAINT_TOL))
        t = statistics.median(times)
        out[name] = {"points": [{"time_s": t, "cpu_s": t, **_err_stats(errs, fails)}],
                     "time_to_error": None, "time_ratio_vs_ours": t / (t_ours or t)}
    return out


def public_calls(targets: np.ndarray, n: int = 200) -> dict[str, Any]:
    """CPU time of :func:`hapticsdk.solvers.problems.solve` itself, one target per call (a dict of
    intensities, the default model), after a warm-up call of the same setup: the cost an
    application pays per call, next to the solver-internal ``time_s`` of the results.
    Median over ``n`` calls (fewer for the slow methods), targets cycled from ``targets``."""
    from ..solvers.problems import solve as public_solve
    cases = [("amortised", {"polish_steps": 0}), ("amortised", {}), ("polish", {}), ("ga-polish", {}),
             ("ga", {}), ("ga", {"target_error": 0})]
    out = {}
    rows = [{d: float(v) for d, v in zip(DIMS, t)} for t in targets]
    for method, opts in cases:
        public_solve(rows[0], method=method, options=opts, seed=0)
        k = n if method == "amortised" else max(20, n // 10)
        cpu, internal, errs, fails = [], [], [], 0
        for j in range(k):
            c0 = time.process_time()
            r = public_solve(rows[j % len(rows)], method=method, options=opts, seed=j)
            cpu.append(time.process_time() - c0)
            internal.append(r.time_s)
            errs.append(r.error)
            fails += int(not r.success)
        label = method + ("" if not opts else " " + ",".join(f"{a}={b}" for a, b in opts.items()))
        out[label] = {"calls": k, "public_call_cpu_us": statistics.median(cpu) * 1e6,
                      "public_call_cpu_us_p90": _p(cpu, 90) * 1e6,
                      "internal_time_s_us": statistics.median(internal) * 1e6, **_err_stats(errs, fails)}
    return out


# ---------------------------------------------------------------------------
# profile, amortised table, one batched call

def profile_ga(factory: Callable[..., SolveProblem], T: np.ndarray) -> dict[str, Any]:
    """Share of the GA's wall time spent inside ``model.predict`` (paper settings, no early stop)."""
    from hapticsdk_ga.ga import GASolver
    p = factory(T)
    model = p.model
    orig = model.predict
    spent = [0.0, 0]

    def timed(G: Any) -> Any:
        t0 = time.perf_counter()
        y = orig(G)
        spent[0] += time.perf_counter() - t0
        spent[1] += len(G)
        return y

    model.predict = timed  # type: ignore[method-assign]
    try:
        t0 = time.perf_counter()
        GASolver(target_error=0).solve(p, seed=0)
        total = time.perf_counter() - t0
    finally:
        del model.predict
    return {"targets": len(T), "total_ms": total * 1e3, "model_predict_ms": spent[0] * 1e3,
            "model_share": spent[0] / total, "rows": spent[1], "ns_per_row_in_model": spent[0] / spent[1] * 1e9}


def amortised_stats(factory: Callable[..., SolveProblem], T: np.ndarray, ref_ga_error: np.ndarray,
                    n_lookup: int = 20000) -> dict[str, Any]:
    """Build the amortised solver's table for ``factory``'s problem and report its build
    time (s), lookup time per target (us) and its errors next to the GA's
    ``ref_ga_error``.
    """
    from hapticsdk_ga.amortised import AmortisedSolver
    p = factory(T)
    S = AmortisedSolver()
    t0 = time.perf_counter()
    tab = S.table(p)
    t_table = time.perf_counter() - t0
    build_s, source = tab.build_time_s, tab.source   # recorded when built, kept in the cache file
    rng = np.random.default_rng(0)
    Q = rng.random((n_lookup, 2))
    lk = tab.lookup
    per = []
    for q in Q:
        t0 = time.perf_counter()
        lk(q)
        per.append(time.perf_counter() - t0)
    Qt = [(float(a), float(b)) for a, b in Q]
    cpu_rounds = []
    for _ in range(5):
        c0 = time.process_time()
        for q in Qt:
            lk(q)
        cpu_rounds.append((time.process_time() - c0) / len(Qt))
    t0 = time.perf_counter()
    lk(Q)
    batch_us = (time.perf_counter() - t0) / n_lookup * 1e6
    out: dict[str, Any] = {"median_us": statistics.median(per) * 1e6, "p90_us": _p(per, 90) * 1e6,
                           "cpu_us_per_lookup": statistics.median(cpu_rounds) * 1e6,
                           "batch_us_per_target": batch_us, "table_shape": list(tab.X.shape),
                           "table_build_cpu_s": build_s, "table_source": source,
                           "table_obtain_s": t_table,
                           "reachable_node_fraction": tab.reachable_fraction(p.tolerance)}
    errs = {}
    for steps in (0, 1, 2):
        r = AmortisedSolver(polish_steps=steps).solve(p, seed=0)
        errs[f"polish_steps={steps}"] = {"error_p50": _p(r.error, 50), "error_p90": _p(r.error, 90),
                                         "error_max": float(np.max(r.error)),
                                         "success_rate": float(np.mean(r.success)),
                                         "ms_per_target": r.time_s / len(T) * 1e3}
    out["error_vs_full_solve"] = {"full_ga_error_p50": _p(ref_ga_error, 50), "full_ga_error_p90": _p(ref_ga_error, 90),
                                  **errs}
    return out


def batch_call_times(factory: Callable[..., SolveProblem], T: np.ndarray, seeds: list[int]) -> dict[str, Any]:
    """ONE batched call on the material targets, per method (median over seeds): CPU and
    wall time of the solver call, and of the public ``hapticsdk.solvers.problems.solve`` call with
    the same targets; error p90 (median over seeds) and max, failures over all seeds."""
    from ..solvers.problems import solve as public_solve
    p = factory(T)
    out = {}
    for name, opts in (("ga-polish", {}), ("polish", {}), ("ga", {}), ("amortised", {}), ("amortised", {"polish_steps": 5})):
        S = _solver(name, **opts)
        S.solve(p, seed=0)
        public_solve(T, dimensions=DIMS, method=name, options=opts, seed=0)
        ts, cpus, pub, errs, emax, fails = [], [], [], [], [], 0
        for s in seeds:
            c0 = time.process_time()
            r = S.solve(p, seed=s)
            cpus.append(time.process_time() - c0)
            ts.append(r.time_s)
            errs.append(_p(r.error, 90))
            emax.append(float(np.max(r.error)))
            fails += int(np.sum(~r.success))
            c0 = time.process_time()
            public_solve(T, dimensions=DIMS, method=name, options=opts, seed=s)
            pub.append(time.process_time() - c0)
        label = name + ("" if not opts else " " + ",".join(f"{a}={b}" for a, b in opts.items()))
        out[label] = {"ms": statistics.median(ts) * 1e3, "cpu_ms": statistics.median(cpus) * 1e3,
                      "public_call_cpu_ms": statistics.median(pub) * 1e3,
                      "error_p90": statistics.median(errs), "error_max": max(emax), "failures": fails,
                      "solves": len(T) * len(seeds)}
    return out


def machine_info() -> dict[str, Any]:
    """The machine and library versions the benchmark ran on (CPU, cores, Python, numpy,
    scipy, onnxruntime, OMP_NUM_THREADS).
    """
    import scipy
    info = {"machine": platform.machine(), "processor": platform.processor() or _cpu_name(),
            "cpus": os.cpu_count(), "python": sys.version.split()[0], "numpy": np.__version__,
            "scipy": scipy.__version__, "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS"),
            "platform": platform.platform()}
    try:
        import onnxruntime
        info["onnxruntime"] = onnxruntime.__version__
    except ImportError:
        pass
    return info


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return ""


# ---------------------------------------------------------------------------
# the whole benchmark

def run(*, quick: bool = False, seeds: int | None = None, log: Callable[[str], None] | None = None
        ) -> dict[str, Any]:
    """Run the benchmark; returns the JSON-ready report (see module doc)."""
    say = log or (lambda s: None)
    n_seeds = seeds or (3 if quick else 15)
    if n_seeds < 1:
        raise ValidationError("need at least one seed", field="seeds")
    seed_list = list(range(n_seeds))
    factory, model_desc = make_problem_factory()
    say(f"model: {model_desc}")
    tg = bench_targets(factory)
    T, labels, kinds = tg["targets"], tg["labels"], np.array(tg["kinds"])
    say(f"{len(T)} targets; computing reference answers")
    ref = reference_errors(factory, T)
    tol = factory(T[:1]).tolerance
    cls = np.where(ref <= 1e-6, "reachable", np.where(ref <= tol, "boundary", "unreachable"))
    reach = cls == "reachable"
    TR = T[reach]
    report: dict[str, Any] = {
        "meta": {**machine_info(), "model": model_desc, "quick": quick, "seeds": n_seeds,
                 "error": "sum over dimensions of |predicted - target| intensity; per run the 90th percentile over "
                          "reachable targets (error), and over every solve of every seed (solve_error_p10/p50/p90, "
                          "what the figure shows)",
                 "time": "wall seconds of one batched call / number of targets (time_s); process CPU seconds of "
                         "the same call / number of targets (cpu_s, what the figure shows)"},
        "targets": [{"label": l, "kind": k, "target": [float(a), float(b)], "class": str(c), "reference_error": float(r)}
                    for l, k, (a, b), c, r in zip(labels, kinds, T, cls, ref)],
    }
    report["targets_summary"] = {c: int((cls == c).sum()) for c in ("reachable", "boundary", "unreachable")}

    if quick:
        cfg = {
            "ga": [{"generations": g, "target_error": 0} for g in (5, 20, 50)],
            "de": [{"generations": g, "target_error": 0} for g in (10, 50)],
            "polish": [{"max_iter": k, "target_error": 0} for k in (4, 30)],
            "ga-polish": [{"max_iter": k, "target_error": 0} for k in (2, 8)],
            "amortised": [{"polish_steps": k} for k in (0, 1, 3)],
        }
    else:
        cfg = {
            "ga": [{"generations": g, "target_error": 0} for g in (5, 10, 20, 50, 100, 200)],
            "de": [{"generations": g, "target_error": 0} for g in (10, 25, 50, 100, 200)],
            "de-scipy": [{"maxiter": k, "target_error": 0} for k in (10, 30, 100)],
            "polish": [{"max_iter": k, "target_error": 0} for k in (2, 4, 8, 16, 30)],
            "ga-polish": [{"max_iter": k, "target_error": 0} for k in (1, 2, 4, 8, 16)],
            "amortised": [{"polish_steps": k} for k in (0, 1, 2, 3, 5)],
        }

    def prep_amortised(p: SolveProblem, S: Any) -> None:
        S.table(p)           # build or load once; not timed
        S.solve(p, seed=0)   # warm-up

    report["solvers"] = {}
    for name, settings in cfg.items():
        say(f"work-precision: {name} ({len(settings)} settings x {n_seeds} seeds)")
        sd = seed_list if name != "de-scipy" else seed_list[:max(3, n_seeds // 5)]
        report["solvers"][name] = work_precision(factory, TR, name, settings, sd,
                                                 prepare=prep_amortised if name == "amortised" else None)

    # unreachable targets must fail with every solver (default settings)
    unre = T[cls == "unreachable"]
    checks = {}
    if len(unre):
        pu = factory(unre)
        for name in cfg:
            r = _solver(name).solve(pu, seed=0)
            checks[name] = {"all_success_false": bool(not np.any(r.success)), "min_error": float(np.min(r.error))}
    report["unreachable_check"] = checks

    say("peers (numpy GA, scipy DE, L-BFGS-B multi-start, pygad, DEAP, pymoo), one target per call")
    peer_T = TR[:5] if quick else TR[:8]
    peer_seeds = list(range(2 if quick else 3))
    report["peers"] = run_peers(factory, peer_T, peer_seeds)
    report["peers_setup"] = {"targets": len(peer_T), "seeds": len(peer_seeds), "solves": len(peer_T) * len(peer_seeds)}
    report["peers_note"] = ("each peer and our solvers solve one target per call (population 100 and 50 "
                            f"generations where there is one; {len(peer_T)} reachable targets x {len(peer_seeds)} "
                            "seeds); time_s = CPU seconds per target (median); failures = solves outside the "
                            "tolerance or with a violated constraint; time_ratio_vs_ours = time / our GA's time; "
                            "same fitness function (formula (6)).")

    say("penalty forms")
    pen = {}
    for form in ("paper", "normalised"):
        wp = work_precision(factory, TR, "ga", [{"target_error": 0}], seed_list, penalty=form)
        pen[form] = wp["points"][0]
    better = min(pen, key=lambda k: pen[k]["error"])
    report["penalty_forms"] = {**pen, "lower_error": better,
                               "note": "GA at the paper's settings (same generations, so about equal time)"}

    say("one batched call, public calls, amortised table, GA profile")
    mats = T[kinds == "material"]
    ga_full = _solver("ga", target_error=0).solve(factory(TR), seed=0)
    report["amortised"] = amortised_stats(factory, TR, ga_full.error)
    report["batch_23_materials"] = batch_call_times(factory, mats, seed_list[: max(3, min(n_seeds, 7))])
    report["profile_ga"] = profile_ga(factory, TR)
    report["public_calls"] = public_calls(TR, n=50 if quick else 300)
    return report


# ---------------------------------------------------------------------------
# plot

def _solve_err(pt: dict[str, Any]) -> tuple[float, float, float]:
    """(p10, p50, p90) of the error over every solve of a point (older reports: the
    per-run figures)."""
    if "solve_error_p50" in pt:
        return pt["solve_error_p10"], pt["solve_error_p50"], pt["solve_error_p90"]
    return pt["error_p10"], pt["error"], pt["error_p90"]


def _wp_point(ax: Any, t_ms: Any, pts: list[dict[str, Any]], floor: float, **kw: Any) -> None:
    st = np.array([_solve_err(p) for p in pts], float)
    lo, e, hi = (np.maximum(st[:, k], floor) for k in range(3))
    ax.errorbar(t_ms, e, yerr=[e - lo, hi - e], capsize=3, **kw)


def plot(report: dict[str, Any], path: str | Path) -> None:
    """One work-precision panel per calling pattern, each with one clock and one error
    statistic for every point: process CPU time per target (ms) against the median error
    over every solve (bars: 10th-90th percentile over every solve).

    * batched: each SDK solver's settings, all reachable targets in one call per seed;
    * one target per call: our solvers and the peers (DEAP, pymoo, pygad, numpy GA,
      scipy DE, L-BFGS-B multi-start), one solve per target and seed;
    * the amortised solver's table build, paid once per model and constraints, as its
      own bar, with the number of one-target calls after which it has paid for itself
      against ga-polish.

    Legends sit below the panels, off the data. The panel titles say how many targets and
    seeds each used.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax1, ax2) = plt.subplots(1, 3, figsize=(16, 6.2), gridspec_kw={"width_ratios": [3, 3, 1.3]})
    floor = 1e-12
    markers = "ovs^Dph*<>"
    # one colour per solver in both panels (ours by name, then the peers)
    ours_names = list(report["solvers"])
    peer_names = [k for k, v in report.get("peers", {}).items() if "points" in v and "(ours" not in k]
    names = ours_names + [n for n in peer_names if n not in ours_names]
    # 20 distinct colours (tab20: the dark shades first, then the light ones): no two solvers share one
    tab = getattr(plt.get_cmap("tab20"), "colors")   # a ListedColormap
    palette = list(tab[0::2]) + list(tab[1::2])
    colour = {n: palette[i % len(palette)] for i, n in enumerate(names)}
    for k, (name, s) in enumerate(report["solvers"].items()):
        pts = s["points"]
        t = np.array([p.get("cpu_s", p["time_s"]) for p in pts]) * 1e3
        _wp_point(ax, t, pts, floor, marker=markers[k % len(markers)], label=name, color=colour[name])
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("CPU time per target (ms): one batched call / targets")
    ax.set_ylabel("error sum |I - T|: median over every solve\n(bars: p10-p90; below 1e-12 drawn at 1e-12)")
    ax.grid(True, which="both", alpha=0.3)
    m = report["meta"]
    n_reach = report["targets_summary"]["reachable"]
    ax.set_title(f"batched: {n_reach} reachable targets in one call x {m['seeds']} seeds\n"
                 "(a point per setting: generations / iterations / polish steps;\n"
                 "amortised: without its table build, right)", fontsize=9)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(0.0, -0.13), ncol=3, frameon=False)

    peers = {k: v for k, v in report.get("peers", {}).items() if "points" in v}
    for k, (name, s) in enumerate(peers.items()):
        pt = s["points"][0]
        ours = "(ours" in name
        base = name.split(" (ours")[0]
        label = base + " (ours)" if ours else base
        _wp_point(ax1, [pt.get("cpu_s", pt["time_s"]) * 1e3], [pt], floor, linestyle="none",
                  marker=markers[ours_names.index(base) % len(markers)] if base in ours_names else "s",
                  markerfacecolor=None if ours else "white", label=label,
                  color=colour.get(base, "0.3"))
    not_run = [k for k, v in report.get("peers", {}).items() if "points" not in v]
    ax1.set_xscale("log")
    ax1.set_yscale("log")
    ax1.set_xlabel("CPU time per target (ms): one solve per call")
    ax1.grid(True, which="both", alpha=0.3)
    ps = report.get("peers_setup") or {}
    ax1.set_title(f"one target per call: {ps.get('targets', '?')} reachable targets x {ps.get('seeds', '?')} seeds "
                  f"each\n(filled: hapticsdk; open squares: peers; GAs and DE: population 100 x 50 "
                  f"generations, L-BFGS-B: 8 starts)"
                  + (f"; not installed: {', '.join(not_run)}" if not_run else ""), fontsize=9)
    ax1.legend(fontsize=7, loc="upper left", bbox_to_anchor=(0.0, -0.13), ncol=3, frameon=False)
    ax1.sharey(ax)

    a = report.get("amortised") or {}
    build = a.get("table_build_cpu_s")
    ax2.set_title("paid once per model\nand constraints", fontsize=9)
    if build is not None:
        ax2.bar([0], [build], color="C4", width=0.6)
        ax2.set_xticks([0])
        ax2.set_xticklabels(["amortised\ntable build"], fontsize=8)
        ax2.set_ylabel("CPU time (s)")
        am = (peers.get("amortised (ours, one target per call)") or {}).get("points", [{}])[0]
        gp = (peers.get("ga-polish (ours, one target per call)") or {}).get("points", [{}])[0]
        note = f"{build:.2f} s CPU\n(table {'x'.join(str(v) for v in a.get('table_shape', []))})"
        if a.get("table_source", "built") != "built":   # not this process's CPU time: say so
            note += f"\nmeasured when built;\nthis run read it from\nthe {a['table_source']}"
        if am.get("cpu_s") and gp.get("cpu_s") and gp["cpu_s"] > am["cpu_s"]:
            n_even = build / (gp["cpu_s"] - am["cpu_s"])
            note += f"\npays for itself after\n{n_even:,.0f} one-target calls\n(vs ga-polish)"
        ax2.text(0, build, note, ha="center", va="bottom", fontsize=7)
        ax2.set_ylim(0, build * 1.9)
        ax2.set_xlim(-0.8, 0.8)
    else:
        ax2.axis("off")
    model_short = m["model"].split(", space")[0]   # e.g. "OnnxModel 'default' (default model)"
    fig.suptitle(f"hapticsdk solvers, work-precision per calling pattern ({'quick run' if m.get('quick') else 'full run'}) "
                 f"- {model_short} - {m.get('processor', '')}, Python {m['python']}, numpy {m['numpy']}, "
                 f"onnxruntime {m.get('onnxruntime', '-')}, OMP_NUM_THREADS={m.get('OMP_NUM_THREADS')}\n"
                 "targets: the GENERATED material library's intensities and extremes of the model's reachable set; "
                 "CPU time of this process (the machine may be shared)", fontsize=8)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 0.93))
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    from ..plotting import save_figure
    save_figure(fig, path, dpi=110)  # temp file + rename: a failed write keeps the old figure


def summary_text(rep: dict[str, Any]) -> str:
    """A human-readable table of the report (results only)."""
    lines = [f"model: {rep['meta']['model']}", f"targets: {rep['targets_summary']}",
             "times: wall ms per target of one batched call (CPU ms in brackets); errors: sum |I - T|", "",
             f"{'solver':<12}{'setting':<30}{'ms/target':>16}{'p90 err':>10}{'max err':>10}{'failed':>10}"]
    for name, s in rep["solvers"].items():
        for pt in s["points"]:
            st = ",".join(f"{k}={v}" for k, v in pt["setting"].items() if k != "target_error")
            t = f"{pt['time_s'] * 1e3:.3f} ({pt.get('cpu_s', float('nan')) * 1e3:.3f})"
            lines.append(f"{name:<12}{st:<30}{t:>16}{pt['error']:>10.2e}{pt.get('error_max', float('nan')):>10.2e}"
                         f"{str(pt.get('failures', '-')) + '/' + str(pt.get('solves', '-')):>10}")
        tt = s["time_to_error"]
        lines.append(f"{'':<12}time to error (ms/target): " + ", ".join(
            f"{k}: {'null' if v is None else f'{v * 1e3:.3f}'}" for k, v in tt.items()))
    lines.append("")
    ps = rep.get("peers_setup") or {}
    lines.append(f"one target per call, {ps.get('targets', '?')} targets x {ps.get('seeds', '?')} seeds "
                 "(CPU ms per target; error median / p90 / max; failed solves):")
    for name, s in rep["peers"].items():
        if "points" in s:
            pt = s["points"][0]
            lines.append(f"  {name:<40} {pt['time_s'] * 1e3:9.2f} ms  {pt['error']:.1e} / {pt['error_p90']:.1e} / "
                         f"{pt.get('error_max', float('nan')):.1e}  failed {pt.get('failures', '-')}/{pt.get('solves', '-')}"
                         f"  x{s['time_ratio_vs_ours']:.2f} our GA's time")
        else:
            lines.append(f"  {name}: not run ({s['error']})")
    pf = rep["penalty_forms"]
    lines.append(f"penalty paper: p90 err {pf['paper']['error']:.2e}; normalised: {pf['normalised']['error']:.2e} "
                 f"-> lower error: {pf['lower_error']}")
    a = rep["amortised"]
    lines.append(f"amortised lookup: {a.get('cpu_us_per_lookup', float('nan')):.2f} us CPU per single lookup "
                 f"(wall median {a['median_us']:.2f} us), batch {a['batch_us_per_target']:.3f} us/target; "
                 f"table {a['table_shape']} built in {a.get('table_build_cpu_s', float('nan')):.2f} s CPU "
                 f"(this run: {a.get('table_source', '?')}, {a.get('table_obtain_s', float('nan')):.3f} s)")
    b = rep.get("batch_23_materials", {})
    if b:
        lines.append("materials in one call (ms; CPU ms; public call CPU ms; p90 / max error; failed):")
        for k, v in b.items():
            lines.append(f"  {k:<26} {v['ms']:7.2f}  {v.get('cpu_ms', float('nan')):7.2f}  "
                         f"{v.get('public_call_cpu_ms', float('nan')):7.2f}  {v['error_p90']:.1e} / "
                         f"{v.get('error_max', float('nan')):.1e}  {v.get('failures', '-')}/{v.get('solves', '-')}")
    pc = rep.get("public_calls", {})
    if pc:
        lines.append("public hapticsdk.solvers.problems.solve, one target per call (CPU us median / p90; solver time_s us; max error; failed):")
        for k, v in pc.items():
            lines.append(f"  {k:<26} {v['public_call_cpu_us']:9.1f} / {v['public_call_cpu_us_p90']:9.1f}  "
                         f"{v['internal_time_s_us']:9.1f}  {v['error_max']:.1e}  {v['failures']}/{v['solves']}")
    pg = rep.get("profile_ga")
    if pg:
        lines.append(f"GA profile: {pg['total_ms']:.1f} ms for {pg['targets']} targets, model.predict "
                     f"{pg['model_share'] * 100:.0f} % ({pg['ns_per_row_in_model']:.0f} ns per row)")
    return "\n".join(lines)
