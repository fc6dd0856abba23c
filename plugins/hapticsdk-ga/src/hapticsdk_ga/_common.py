"""Helpers shared by the solvers: subset evaluation, option checks, constraint residuals.

All arrays are in physical units of the searched features (``problem.space``) unless a
name says ``u`` (unit coordinates, ``u = (x - lower) / span``, 0 for a degenerate feature).
"""

from __future__ import annotations

import math
import time
from typing import Any, Literal, overload

import numpy as np

from hapticsdk.argcheck import number
from hapticsdk.checks import is_number
from hapticsdk.errors import ValidationError
from hapticsdk.solvers import CONSTRAINT_TOL, EvalBuffers, SolveProblem

__all__ = ["Evaluator", "check_int", "check_fraction", "check_budget", "Clock", "CONSTRAINT_TOL"]


class Evaluator:
    """Formula (6) for any subset of the problem's targets, counting model rows.

    A thin adapter over :meth:`SolveProblem.evaluate` (its ``rows`` argument scores a subset
    of targets: solvers that drop solved targets, ``ga`` and ``de``, or solve them one by
    one, ``de-scipy``) that returns ``(fitness, error, violation)`` and counts ``nfev``.
    """

    def __init__(self, problem: SolveProblem, *, finite: bool = False) -> None:
        self.problem = problem
        self.nfev = 0
        #: the candidates are generated inside the bounds (finite): the model's NaN check is skipped
        self.finite = finite
        self._work: EvalBuffers | None = None

    def __call__(self, X: np.ndarray, rows: np.ndarray | None = None, *,
                 reuse: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return ``(fitness, error, violation)`` for ``X`` ``(r, p, d)`` (or ``(r, d)``),
        where ``r`` targets are ``problem.targets[rows]`` (all targets when ``rows`` is None).

        ``reuse=True`` (a solver's loop): the arithmetic runs in buffers kept from the
        previous call of the same shape (:class:`~hapticsdk.solvers.EvalBuffers`), so the
        three arrays returned are only valid until the next ``reuse`` call: copy what you keep."""
        if reuse:
            f, e, v = self._into(X, rows, False)
            assert v is not None
            return f, e, v
        d = self.problem.evaluate(X, details=True, rows=rows, finite=self.finite)
        self.nfev += d["fitness"].size
        return d["fitness"], d["error"], d["violation"]

    def lazy(self, X: np.ndarray, rows: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """As ``self(X, rows, reuse=True)``, but the violation may be left out (None; paper
        penalty form): :meth:`violation_at` then gives it for the rows the caller needs,
        before the next call (a GA reads it only where a child becomes the best)."""
        work = self._work
        if work is None or work.lead != X.shape[:-1] or not self.finite:
            return self._into(X, rows, True)
        work.lazy = True
        f, e, v = self.problem.evaluate_into(work, X, rows)
        self.nfev += f.size
        return f, e, v

    def _into(self, X: np.ndarray, rows: np.ndarray | None, lazy: bool
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        work = self._work
        if work is None or work.lead != X.shape[:-1]:
            work = self._work = self.problem.eval_buffers(X.shape[:-1])
        work.lazy = lazy
        if self.finite:
            f, e, v = self.problem.evaluate_into(work, X, rows)
        else:
            d = self.problem.evaluate(X, details=True, rows=rows, work=work)
            f, e, v = d["fitness"], d["error"], d["violation"]
        self.nfev += f.size
        return f, e, v

    def violation_at(self, idx: Any) -> Any:
        """Violation of rows ``idx`` (flat indices into ``X.reshape(-1, d)``) of the last
        ``reuse`` call (:meth:`~hapticsdk.solvers.EvalBuffers.violation_at`)."""
        assert self._work is not None
        return self._work.violation_at(idx)


def constraint_shortfalls(problem: SolveProblem, G: np.ndarray) -> np.ndarray:
    """Relative constraint shortfalls ``(n, c)``: ``(bound - value) / |bound|`` (``|bound|``
    replaced by 1 where it is 0); positive = violated. ``max(0, .)`` of a column is the
    constraint's ``violation`` (the base :class:`~hapticsdk.perception.dimensions.Constraint` formula);
    one ``bound_and_value`` call per constraint."""
    cons = problem.constraints
    n = G.shape[0]
    out = np.empty((n, len(cons)))
    if not cons:
        return out
    cols = problem.columns(G)
    for j, c in enumerate(cons):
        bound, value = c.bound_and_value(cols)
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
    if all(type(c).uses_base_formulas() for c in problem.constraints):
        v = np.where(S <= 0, 0.0, S)   # NaN (infinite bound) stays NaN = not feasible
        return v.max(axis=1)
    cols = problem.columns(G)
    v = np.zeros(n)
    for c in problem.constraints:
        np.maximum(v, c.violation(cols), out=v)
    return v


@overload
def check_int(opts: dict, key: str, lo: int, hi: int | None = None, *, allow_none: Literal[False] = False) -> int: ...
@overload
def check_int(opts: dict, key: str, lo: int, hi: int | None = None, *, allow_none: bool) -> int | None: ...
def check_int(opts: dict, key: str, lo: int, hi: int | None = None, *, allow_none: bool = False) -> int | None:
    v = opts[key]
    if v is None and allow_none:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo or (hi is not None and v > hi):
        rng = f">= {lo}" if hi is None else f"in {lo}..{hi}"
        raise ValidationError(f"must be an integer {rng}, got {v!r}", field=f"options.{key}")
    return int(v)


def check_fraction(opts: dict, key: str, lo: float = 0.0, hi: float = 1.0) -> float:
    """Option ``key``: a finite number in ``lo..hi`` (a string or a bool is not one)."""
    return number(opts[key], f"options.{key}", lo=lo, hi=hi)


def check_budget(opts: dict, key: str = "time_budget_s") -> float | None:
    """Option ``key``: seconds > 0 (infinite: no budget) or None."""
    v = opts.get(key)
    if v is None:
        return None
    if not is_number(v):
        raise ValidationError(f"must be a number of seconds or None, got {v!r:.60}", field=f"options.{key}")
    try:
        f = float(v)
    except OverflowError:   # an int beyond the float range: as long as infinity
        f = math.inf
    if not (f > 0):
        raise ValidationError(f"must be > 0 s, got {v!r}", field=f"options.{key}")
    return f


def target_error(opts: dict, problem: SolveProblem) -> float:
    """Stopping threshold on the error: option ``target_error`` (None -> the problem's
    tolerance; 0 -> never stop early)."""
    v = opts.get("target_error")
    if v is None:
        return float(problem.tolerance)
    return check_target_error(v)


def check_target_error(v: Any) -> float:
    """A ``target_error`` option: a finite number >= 0."""
    if not is_number(v):
        raise ValidationError(f"must be a number or None, got {v!r:.60}", field="options.target_error")
    return number(v, "options.target_error", lo=0.0)


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



# ---------------------------------------------------------------------------
# a cached cloud of feasible samples: nearest-sample starts for the local solvers

#: samples drawn uniformly in the searched bounds for the cloud (fixed seed)
CLOUD_SAMPLES = 4096
CLOUD_SEED = 20240611
_CLOUDS: dict[tuple, tuple[Any, "SampleCloud"]] = {}


def setup_key(problem: SolveProblem) -> tuple:
    """What a problem's answers depend on besides its targets (model object, dimensions,
    bounds, pinned values, penalty and the constraints' classes and parameters): the key
    of in-memory caches shared by problems that differ only in their targets."""
    memo = getattr(problem, "_setup_cache", None)
    if memo is not None and "setup_key" in memo:
        return memo["setup_key"]
    cons = tuple((type(c).__module__, type(c).__qualname__, c.name,
                  repr(sorted((k, v) for k, v in vars(c).items() if not k.startswith("_"))))
                 for c in problem.constraints)
    key = (id(problem.model), tuple(problem.dimensions), tuple(problem.space.names),
           problem.space.lower.tobytes(), problem.space.upper.tobytes(),
           tuple(sorted((k, float(v)) for k, v in problem.fixed.items())), cons)
    if memo is not None:
        memo["setup_key"] = key
    return key


class SampleCloud:
    """Feasible feature samples (``X``, physical units) and their targeted intensities
    (``Y``), for nearest-sample starts: :meth:`nearest` returns, per target, the samples
    whose intensities are closest to it (Euclidean in intensity space)."""

    def __init__(self, X: np.ndarray, Y: np.ndarray) -> None:
        self.X = np.ascontiguousarray(X)
        self.Y = np.ascontiguousarray(Y)
        self._y2 = np.einsum("ij,ij->i", self.Y, self.Y)
        self._m2yt = np.ascontiguousarray(-2.0 * self.Y.T)
        self._last: tuple[np.ndarray, int, np.ndarray] | None = None

    def nearest(self, T: np.ndarray, k: int, *, block: int = 1024) -> np.ndarray:
        """``(m, k, d)``: the ``k`` samples nearest to each target row of ``T``, nearest
        first; targets are handled ``block`` at a time (``block x samples`` floats)."""
        m, n = T.shape[0], self.Y.shape[0]
        k = min(k, n)
        last = self._last
        if last is not None and last[0] is T and last[1] >= k:   # same targets again (GA, then LM starts)
            return last[2][:, :k].copy()
        out = np.empty((m, k, self.X.shape[1]))
        for a in range(0, m, block):
            Tb = T[a:a + block]
            D = Tb @ self._m2yt
            D += self._y2
            ar = np.arange(len(Tb))
            for j in range(k):   # k argmin passes (k is small; argpartition is far slower here)
                i = D.argmin(axis=1)
                out[a:a + block, j] = self.X[i]
                D[ar, i] = np.inf
        self._last = (T, k, out)
        return out


def sample_cloud(problem: SolveProblem) -> SampleCloud:
    """The problem setup's :class:`SampleCloud` (built once per setup, kept in memory;
    ~2-4 ms for the default model): :data:`CLOUD_SAMPLES` samples (seed
    :data:`CLOUD_SEED`), half uniform in the bounds and half with each feature on its lower
    or upper bound with probability 1/4 each (the rest uniform), one model call, the ones
    meeting every constraint kept (all of them if fewer than 16 do). Independent of the
    solve's seed, so it adds no randomness to the answers."""
    import weakref
    memo = getattr(problem, "_setup_cache", None)
    if memo is not None and "cloud" in memo:
        return memo["cloud"]
    key = setup_key(problem)
    hit = _CLOUDS.get(key)
    if hit is not None and hit[0]() is problem.model:
        if memo is not None:
            memo["cloud"] = hit[1]
        return hit[1]
    rng = np.random.default_rng(CLOUD_SEED)
    X = problem.space.random(CLOUD_SAMPLES, rng)
    # half of the samples have some features on a bound (each feature at its lower or
    # upper bound with probability 1/4 each): optima on a face or corner of the box (the
    # extremes of the data a model was trained on) then have a start on the same face
    half = CLOUD_SAMPLES // 2
    side = rng.random((half, X.shape[1]))
    lo, hi = problem.space.lower, problem.space.upper
    Xh = X[half:]
    np.copyto(Xh, np.broadcast_to(lo, Xh.shape), where=side < 0.25)
    np.copyto(Xh, np.broadcast_to(hi, Xh.shape), where=side > 0.75)
    G = problem.full_inputs(X)
    I = problem.model.predict(G)[:, problem._out_idx]
    if problem.constraints:
        ok = violation_from(problem, constraint_shortfalls(problem, G), G) <= CONSTRAINT_TOL
        if ok.sum() >= 16:
            X, I = X[ok], I[ok]
    cloud = SampleCloud(X, I)
    if len(_CLOUDS) > 32:
        _CLOUDS.clear()
    _CLOUDS[key] = (weakref.ref(problem.model), cloud)
    if memo is not None:
        memo["cloud"] = cloud
    return cloud
