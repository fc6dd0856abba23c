"""The generic base of every solver: :class:`Solver`, the template each solver plugin
follows (public ``solve`` validates the problem and the options, times the run, solves
a batch chunk by chunk and re-evaluates; the backend implements ``_solve`` and returns a
:class:`SolverOutput`).

The result's error is always recomputed by the base class from the model at the
returned ``x``: a solver cannot report an error it did not reach. The problem it solves
is :mod:`.objective`'s :class:`~hapticsdk.solvers.objective.SolveProblem`; the results
are :mod:`.results`'.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..checks import MAX_SEED, check_seed
from ..errors import SolverError, ValidationError
from .objective import SolveProblem, _answer_key
from .results import BatchSolveResult, SolveResult, Trace

#: Violation (relative, normalised form) below which a constraint counts as met.
CONSTRAINT_TOL = 1e-9
#: Targets solved per chunk by :meth:`Solver.solve` (bounds the working memory of a batch:
#: a solver holds at most one chunk's populations/starts at a time).
DEFAULT_CHUNK_SIZE = 4096
MAX_CHUNK_SIZE = 1_000_000
#: Batches larger than this keep no per-target trace (``result.trace == []``; the
#: batch-level ``trace`` stays): per-target traces cost ~1 kB per target.
PER_TARGET_TRACE_MAX = 20000


@dataclass
class SolverOutput:
    """What a backend's ``_solve`` returns: best ``x`` per target ``(m, d)`` and counters."""

    x: np.ndarray
    nfev: int
    nit: int
    message: str = ""


class Solver(ABC):
    """Template for solver plugins.

    Subclasses set ``name`` and ``default_options`` (every setting, with the paper's
    values where the paper has one) and implement :meth:`_solve`. Unknown options raise
    :class:`~hapticsdk.errors.ValidationError` listing the valid ones.
    """

    name: ClassVar[str] = ""
    default_options: ClassVar[dict[str, Any]] = {}
    #: False for solvers that draw no random numbers: ``solve`` then skips seeding a
    #: generator (~8-40 us, a large part of a one-target lookup call) and hands ``_solve``
    #: a shared, unused one
    uses_rng: ClassVar[bool] = True
    #: options that name a file or folder to read or write (option -> what it names): a
    #: scene refuses them in ``settings.solver.options`` (a file somebody hands you chooses
    #: no file; :func:`hapticsdk.compiler.compile_scene`); code passes them to ``hs.solve``
    privileged_options: ClassVar[dict[str, str]] = {}

    def __init__(self, **options: Any) -> None:
        unknown = [k for k in options if k not in self.default_options]
        if unknown:
            raise ValidationError(f"unknown option(s) {unknown} for solver {self.name!r}; "
                                  f"valid: {sorted(self.default_options)}", field="options")
        self.options: dict[str, Any] = {**self.default_options, **options}

    def solve(self, problem: SolveProblem, *, seed: int | None = None,
              chunk_size: int | None = None) -> SolveResult | BatchSolveResult:
        """Solve; a 1-target problem returns a :class:`SolveResult`, a batch a
        :class:`BatchSolveResult`. The error is recomputed from the model at ``x``.

        The targets are solved ``chunk_size`` at a time (default :data:`DEFAULT_CHUNK_SIZE`)
        with one random stream running through the chunks, so the working memory is that of
        one chunk whatever the batch. Solvers whose random draws per target are fixed in
        number and order (``polish``, ``amortised``) give the same answers for any chunk
        size; population solvers (``ga``, ``de``) give equally good ones that depend on the
        chunk size, as they depend on a target's position in the batch."""
        if not isinstance(problem, SolveProblem):
            raise ValidationError("problem must be a SolveProblem", field="problem")
        if not (seed is None or (type(seed) is int and 0 <= seed <= MAX_SEED)):
            seed = check_seed(seed)
        rng = np.random.default_rng(seed) if self.uses_rng else _NO_RNG
        chunk = DEFAULT_CHUNK_SIZE if chunk_size is None else chunk_size
        if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or not 1 <= chunk <= MAX_CHUNK_SIZE:
            raise ValidationError(f"must be an integer in 1..{MAX_CHUNK_SIZE}, got {chunk_size!r}",
                                  field="chunk_size")
        m = problem.n_targets
        if problem.single:
            return self._solve_single(problem, rng)
        keep_traces = m <= PER_TARGET_TRACE_MAX
        data = _BatchData(problem, self.name, keep_traces)
        t0 = time.perf_counter()
        for a in range(0, m, int(chunk)):
            sub = problem if m <= chunk else problem.target_chunk(a, min(m, a + int(chunk)))
            trace = Trace(sub.n_targets)
            out = self._call_backend(sub, rng, trace)
            x = np.asarray(out.x, float)
            if x.shape != (sub.n_targets, sub.n_features) or not np.isfinite(x).all():
                raise SolverError(f"solver {self.name!r} returned x of shape {x.shape} "
                                  f"(expected {(sub.n_targets, sub.n_features)}) or non-finite values")
            data.add(sub, sub.clip(x), out, trace, trace.t0 - t0)
        data.finish(time.perf_counter() - t0)
        if problem.single:
            return data.result(0)
        return BatchSolveResult(data=data, time_s=data.elapsed, nfev=data.nfev, nit=data.nit,
                                trace=data.batch_trace, method=self.name)

    def _call_backend(self, problem: SolveProblem, rng: np.random.Generator, trace: "Trace") -> Any:
        """The backend's :meth:`_solve`; an exception other than the SDK's own becomes a
        :class:`~hapticsdk.errors.SolverError` naming the solver."""
        try:
            return self._solve(problem, rng, trace)
        except (ValidationError, SolverError):
            raise
        except Exception as exc:
            raise SolverError(f"solver {self.name!r} failed: {type(exc).__name__}: {exc}") from exc

    def _solve_single(self, problem: SolveProblem, rng: np.random.Generator) -> SolveResult:
        """One target (``problem.single``): the backend's search (the same as for a batch of
        one unless the backend has its own one-target path, like ``amortised``'s
        Gauss-Newton step), with the answer re-evaluated on plain floats (:meth:`SolveProblem.evaluate_one`)
        instead of through the batch arrays."""
        t0 = time.perf_counter()
        trace = Trace(1)
        memo: list[Any] = [problem, None]     # what the backend's evaluate_one computed last
        problem._one_memo = memo
        try:
            out = self._call_backend(problem, rng, trace)
        finally:
            problem._one_memo = None
        x = np.asarray(out.x, float)
        d = problem.n_features
        row = x[0].tolist() if x.shape == (1, d) else None
        if row is None or not all(v - v == 0.0 for v in row):    # v - v is NaN for NaN and +-inf
            raise SolverError(f"solver {self.name!r} returned x of shape {x.shape} "
                              f"(expected {(1, d)}) or non-finite values")
        lo, hi = problem._bounds_list      # clipped to the bounds as problem.clip does, on floats
        x = np.array([h if v > h else (l if v < l else v) for v, l, h in zip(row, lo, hi)])
        pair = memo[1]
        if pair is not None and pair[0] == _answer_key(x):   # the backend judged this very answer
            fun, error, viol, I, pc = pair[1]
        else:
            fun, error, viol, I, pc = problem.evaluate_one(x)
        elapsed = time.perf_counter() - t0
        rows: list[dict[str, Any]] = []
        if trace.times:   # as a batch's per-target trace: times from the solver's start
            E = [a.item() for a in trace.best_error]     # (1,) arrays: a trace of one target
            V = [a.item() for a in trace.violation]
            rows = [{"time_s": t, "nfev": n, "best_error": e, "constraint_violation": v}
                    for t, n, e, v in zip(trace.times, trace.nfev, E, V)]
        return _make_result(problem, 0, x, I, error, fun, viol, pc, out.message, rows,
                            int(out.nfev), int(out.nit), elapsed, self.name)

    @abstractmethod
    def _solve(self, problem: SolveProblem, rng: np.random.Generator, trace: Trace) -> SolverOutput:
        """Search; call ``trace.record`` once per iteration."""


_NO_RNG = np.random.default_rng(0)


class _BatchData:
    """The arrays of a solved batch, filled chunk by chunk (:meth:`add`), from which
    :class:`SolveResult` objects are built on access (:meth:`result`). Everything a result
    reports is recomputed here from the model at the returned ``x``."""

    def __init__(self, problem: SolveProblem, method: str, keep_traces: bool) -> None:
        self.problem, self.method, self.keep_traces = problem, method, keep_traces
        self.m = problem.n_targets
        self._parts: list[dict[str, Any]] = []
        self._cols: dict[str, np.ndarray] = {}
        self._filled = 0
        self.nfev = 0
        self.nit = 0
        self.batch_trace: list[dict[str, Any]] = []
        self.elapsed = 0.0

    def add(self, sub: SolveProblem, x: np.ndarray, out: SolverOutput, trace: Trace, t_offset: float) -> None:
        ev = sub.evaluate(x, details=True, per_constraint=True)
        per_c = ev["violations"]
        cols = {"x": x, "fun": ev["fitness"], "error": ev["error"], "violation": ev["violation"],
                "intensities": ev["intensities"], "per_c": per_c}
        # the answers go straight into arrays for the whole batch (allocated at the first
        # chunk): no chunk is kept, and none is copied again at the end, so the memory of
        # a batch is its answers plus one chunk's working set
        if not self._parts:
            self._cols = {k: np.empty((self.m, *np.shape(v)[1:]), np.asarray(v).dtype) for k, v in cols.items()}
        a = self._filled
        for k, v in cols.items():
            self._cols[k][a:a + len(x)] = v
        self._filled = a + len(x)
        part = {"message": out.message, "n": len(x), "traces": None}
        if self.keep_traces and trace.times:
            part["traces"] = (np.array(trace.times), np.array(trace.nfev), np.array(trace.best_error).T,
                              np.array(trace.violation).T)
        self._parts.append(part)
        nfev0 = self.nfev
        for row in trace.rows():
            row["time_s"] += t_offset
            row["nfev"] += nfev0
            self.batch_trace.append(row)
        self.nfev += int(out.nfev)
        self.nit = max(self.nit, int(out.nit))

    def finish(self, elapsed: float) -> None:
        self.elapsed = float(elapsed)
        parts = self._parts
        one = len(parts) == 1
        c = self._cols
        self.x, self.fun, self.error = c["x"], c["fun"], c["error"]
        self.constraint_violation, self.intensities, self.per_c = c["violation"], c["intensities"], c["per_c"]
        self.success = (self.error <= self.problem.tolerance) & (self.constraint_violation <= CONSTRAINT_TOL)
        self._part_of = None if one else np.repeat(np.arange(len(parts)), [q["n"] for q in parts])
        self._start = [0] if one else np.cumsum([0] + [q["n"] for q in parts]).tolist()

    def result(self, i: int) -> SolveResult:
        k = 0 if self._part_of is None else int(self._part_of[i])
        part = self._parts[k]
        trace: list[dict[str, Any]] = []
        if part["traces"] is not None:
            times, nfev, E, V = part["traces"]
            j = i - int(self._start[k])
            trace = [{"time_s": t, "nfev": n, "best_error": e, "constraint_violation": v}
                     for t, n, e, v in zip(times.tolist(), nfev.tolist(), E[j].tolist(), V[j].tolist())]
        return _make_result(self.problem, i, self.x[i].copy(), self.intensities[i].tolist(),
                            float(self.error[i]), float(self.fun[i]), float(self.constraint_violation[i]),
                            self.per_c[i].tolist(), part["message"], trace, self.nfev, self.nit,
                            self.elapsed, self.method)


def _make_result(problem: SolveProblem, i: int, x: np.ndarray, I: list[float], error: float, fun: float,
                 viol: float, pc: list[float], solver_message: str, trace: list[dict[str, Any]],
                 nfev: int, nit: int, elapsed: float, method: str) -> SolveResult:
    """The :class:`SolveResult` of target ``i`` from its evaluated answer: ``x`` (searched
    features), ``I`` (every model output), error, fitness, max violation and each
    constraint's violation ``pc``, as plain floats."""
    dims = problem.dimensions
    out_idx = problem._out_list
    Ti = problem.targets[i].tolist()
    err_dims = {d: abs(I[out_idx[j]] - Ti[j]) for j, d in enumerate(dims)}
    ok = error <= problem.tolerance and viol <= CONSTRAINT_TOL
    names = problem.model.dimension_names
    preds = dict(zip(names, I))
    cnames = problem._cnames
    if ok:
        msg = f"target reached: error {error:.3g} <= tolerance {problem.tolerance:g}, constraints met"
    else:
        parts = []
        if error > problem.tolerance:
            parts.append(f"error {error:.3g} > tolerance {problem.tolerance:g}; residual per "
                         f"dimension {{{', '.join(f'{a}: {v:.3g}' for a, v in err_dims.items())}}}; "
                         f"nearest intensities found {{{', '.join(f'{a}: {preds[a]:.3g}' for a in dims)}}}")
        if viol > CONSTRAINT_TOL:
            bad = [n for n, v in zip(cnames, pc) if v > CONSTRAINT_TOL]
            parts.append(f"constraints violated: {bad} (max relative violation {viol:.3g})")
        msg = "target not reached: " + "; ".join(parts)
    if solver_message:
        msg += f" [{method}: {solver_message}]"
    G = x if problem._identity else problem.full_inputs(x[None])[0]
    return SolveResult(
        x=x, x_dict=dict(zip(problem.model.feature_names, G.tolist())),
        feature_names=problem.feature_names, fun=fun, success=ok,
        message=msg, nfev=nfev, nit=nit, error=error,
        error_per_dimension=err_dims, intensities=preds,
        targets=dict(zip(dims, Ti)),
        constraint_violation=viol, constraint_violations=dict(zip(cnames, pc)),
        time_s=elapsed, trace=trace, method=method)
