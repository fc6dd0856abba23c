"""Inverse problem: find features G whose predicted intensities match targets.

:class:`SolveProblem` holds targets, a perception model, the feature space to search,
features pinned at fixed values, and the physical constraints; its :meth:`evaluate`
computes the fitness of formula (6) for whole populations of whole batches of targets in
one model call. :class:`Solver` is the template every solver plugin follows (public
``solve`` validates, times and re-evaluates; the backend implements ``_solve``), and
:class:`SolveResult` follows ``scipy.optimize.OptimizeResult``.

The result's error is always recomputed by the base class from the model at the
returned ``x``: a solver cannot report an error it did not reach.
"""

from __future__ import annotations

import math
import operator
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar, Iterator, Sequence

import numpy as np

from ..checks import MAX_SEED, check_seed
from ..dimensions import PENALTY_FORMS, Constraint
from ..errors import ModelError, SolverError, ValidationError
from ..features import FeatureSpace
from ..models import PerceptionModel

#: Violation (relative, normalised form) below which a constraint counts as met.
CONSTRAINT_TOL = 1e-9
#: Targets solved per chunk by :meth:`Solver.solve` (bounds the working memory of a batch:
#: a solver holds at most one chunk's populations/starts at a time).
DEFAULT_CHUNK_SIZE = 4096
MAX_CHUNK_SIZE = 1_000_000
#: Batches larger than this keep no per-target trace (``result.trace == []``; the
#: batch-level ``trace`` stays): per-target traces cost ~1 kB per target.
PER_TARGET_TRACE_MAX = 20000


class SolveResult(dict):
    """Result of one target, with attribute access (like scipy's ``OptimizeResult``).

    Keys: ``x`` (solved features, physical units, ``(d,)`` over ``feature_names``),
    ``x_dict`` (every model input by name, including pinned ones), ``fun`` (objective
    value, formula (6) in the chosen penalty form), ``success``, ``message``, ``nfev``,
    ``nit``, ``error`` (sum of absolute intensity errors), ``error_per_dimension``,
    ``intensities`` (model prediction per output dimension), ``targets``,
    ``constraint_violation`` (max relative violation, 0 when met),
    ``constraint_violations`` (per constraint), ``time_s`` (wall time of the solve),
    ``trace`` (list of ``{time_s, nfev, best_error, constraint_violation}``), ``method``.
    """

    def __getattr__(self, name: str) -> Any:
        try:
            return self[name]
        except KeyError:
            raise AttributeError(name) from None

    __setattr__ = dict.__setitem__  # type: ignore[assignment]

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (``x`` as feature name -> value)."""
        return {"success": bool(self.success), "message": self.message,
                "x": dict(self.x_dict), "intensities": dict(self.intensities),
                "targets": dict(self.targets), "error": float(self.error),
                "error_per_dimension": dict(self.error_per_dimension),
                "constraint_violation": float(self.constraint_violation),
                "constraint_violations": dict(self.constraint_violations),
                "fun": float(self.fun), "time_s": float(self.time_s),
                "nfev": int(self.nfev), "nit": int(self.nit), "method": self.method,
                **({"model": dict(self["model"])} if "model" in self else {})}

    def __repr__(self) -> str:
        return (f"SolveResult(success={self.success}, error={self.error:.3g}, "
                f"violation={self.constraint_violation:.3g}, nfev={self.nfev}, "
                f"time_s={self.time_s:.4g}, method={self.method!r})")


class BatchSolveResult(list):  # type: ignore[type-arg]
    """Results of a batch of targets solved in one call: a list of :class:`SolveResult`
    (a ``list`` subclass whose items are built on access: the batch itself holds arrays, so
    a million targets take ~150 MB, not one dict per target; ``len``, indexing, slicing and
    iteration work as on a list) with batch-level ``x`` ``(m, d)``, ``error`` ``(m,)``,
    ``success`` ``(m,)``, ``fun`` ``(m,)``, ``constraint_violation`` ``(m,)``,
    ``time_s`` (wall time of the whole batch, s), ``nfev`` (model rows evaluated),
    ``nit``, ``trace`` (per iteration: ``time_s``, ``nfev``, ``best_error`` = max over
    targets, ``best_error_median``) and ``method``."""

    time_s: float
    nfev: int
    nit: int
    trace: list[dict[str, Any]]
    method: str
    model: dict[str, Any]      # provenance of the model, set by hapticsdk.solvers.problems.solve

    def __init__(self, results: Sequence[SolveResult] | None = None, *, data: "_BatchData | None" = None,
                 **attrs: Any) -> None:
        super().__init__()
        self._list = None if results is None else list(results)
        self._data = data
        self.__dict__.update(attrs)

    def __bool__(self) -> bool:
        return len(self) > 0

    def __contains__(self, item: object) -> bool:
        return any(r is item or r == item for r in self)

    def __reversed__(self) -> Iterator[SolveResult]:
        for k in range(len(self) - 1, -1, -1):
            yield self[k]

    def __eq__(self, other: object) -> bool:
        if isinstance(other, (list, tuple)):
            return len(self) == len(other) and all(a == b for a, b in zip(self, other))
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]

    def __len__(self) -> int:
        return len(self._list) if self._list is not None else self._data.m  # type: ignore[union-attr]

    def __getitem__(self, i: Any) -> Any:
        if self._list is not None:
            return self._list[i]
        if isinstance(i, slice):
            return [self._data.result(k) for k in range(*i.indices(len(self)))]  # type: ignore[union-attr]
        k = operator.index(i)
        m = len(self)
        if k < 0:
            k += m
        if not 0 <= k < m:
            raise IndexError("BatchSolveResult index out of range")
        return self._data.result(k)  # type: ignore[union-attr]

    def __iter__(self) -> Iterator[SolveResult]:
        for k in range(len(self)):
            yield self[k]

    def _column(self, name: str) -> np.ndarray:
        if self._list is not None:
            return np.array([r[name] for r in self._list])
        return getattr(self._data, name).copy()

    @property
    def x(self) -> np.ndarray:
        """Solved features of every target, ``(m, d)``, physical units."""
        return self._column("x")

    @property
    def error(self) -> np.ndarray:
        """Sum of absolute intensity errors of every target, ``(m,)``."""
        return self._column("error")

    @property
    def success(self) -> np.ndarray:
        """Whether each target was reached, ``(m,)``."""
        return self._column("success")

    @property
    def fun(self) -> np.ndarray:
        """Objective value (formula (6)) of every target, ``(m,)``."""
        return self._column("fun")

    @property
    def constraint_violation(self) -> np.ndarray:
        """Largest relative constraint violation of every target, ``(m,)`` (0 when met)."""
        return self._column("constraint_violation")

    def __repr__(self) -> str:
        e = self.error
        return (f"BatchSolveResult(targets={len(self)}, success={int(self.success.sum())}/{len(self)}, "
                f"max_error={float(e.max()) if e.size else float('nan'):.3g}, "
                f"time_s={self.__dict__.get('time_s', float('nan')):.4g}, method={self.__dict__.get('method')!r})")


def _row_medians(a: np.ndarray) -> np.ndarray:
    """``np.median(a, axis=1)`` for a 2-D float array, by partition (np.median
    imports ``numpy.ma``, ~10 ms of every command's start-up)."""
    if np.isnan(a).any():
        return np.median(a, axis=1)
    n = a.shape[1]
    k = n // 2
    if n % 2:
        return np.partition(a, k, axis=1)[:, k]
    p = np.partition(a, (k - 1, k), axis=1)
    return 0.5 * (p[:, k - 1] + p[:, k])


_F64 = np.dtype(np.float64)
_np_array = np.array


class Trace:
    """Per-iteration record of (wall time, evaluations, best error, violation) for a batch."""

    def __init__(self, n_targets: int) -> None:
        self.n_targets = n_targets
        self.t0 = time.perf_counter()
        self.times: list[float] = []
        self.nfev: list[int] = []
        self.best_error: list[np.ndarray] = []
        self.violation: list[np.ndarray] = []

    def record(self, nfev: int, best_error: np.ndarray | float, violation: np.ndarray | float | None = None) -> None:
        """Record one iteration: evaluations so far, best error per target ``(m,)`` and its
        constraint violation (zeros when not given); the time is taken now. A trace of one
        target also takes both as plain floats.
        """
        self.times.append(time.perf_counter() - self.t0)
        self.nfev.append(int(nfev))
        n = self.n_targets
        if n == 1 and type(best_error) is float and type(violation) is float:   # one target, plain floats
            self.best_error.append(_np_array((best_error,)))
            self.violation.append(_np_array((violation,)))
            return
        # a copy (the solver keeps updating its arrays); float (n,) arrays copy directly
        self.best_error.append(best_error.copy() if type(best_error) is np.ndarray and best_error.shape == (n,)
                               and best_error.dtype is _F64 else np.array(best_error, float).reshape(n))
        self.violation.append(np.zeros(n) if violation is None else
                              violation.copy() if type(violation) is np.ndarray and violation.shape == (n,)
                              and violation.dtype is _F64 else np.array(violation, float).reshape(n))

    def repeat(self, nfev: int) -> None:
        """Record one iteration that changed neither the best errors nor the violations
        since the last :meth:`record` (the time is taken now; the previous row's arrays are
        shared, not copied: the stored arrays are read, never written)."""
        if not self.best_error:
            raise ValueError("Trace.repeat before any record")
        self.times.append(time.perf_counter() - self.t0)
        self.nfev.append(int(nfev))
        self.best_error.append(self.best_error[-1])
        self.violation.append(self.violation[-1])

    def rows(self, i: int | None = None) -> list[dict[str, Any]]:
        """Rows for target ``i`` (scalars), or for the batch (max over targets)."""
        if i is not None:
            return self.per_target()[i]
        if not self.times:
            return []
        E = np.array(self.best_error)          # (iterations, m): one reduction per statistic
        V = np.array(self.violation)
        emax, emed, vmax = E.max(axis=1).tolist(), _row_medians(E).tolist(), V.max(axis=1).tolist()
        return [{"time_s": t, "nfev": n, "best_error": e, "best_error_median": md, "constraint_violation": v}
                for t, n, e, md, v in zip(self.times, self.nfev, emax, emed, vmax)]

    def per_target(self) -> list[list[dict[str, Any]]]:
        """Rows of every target, built in one pass (``per_target()[i] == rows(i)``)."""
        if not self.times:
            return [[] for _ in range(self.n_targets)]
        E = np.array(self.best_error).T.tolist()     # (m, iterations)
        V = np.array(self.violation).T.tolist()
        tn = list(zip(self.times, self.nfev))
        return [[{"time_s": t, "nfev": n, "best_error": e, "constraint_violation": v}
                 for (t, n), e, v in zip(tn, Ei, Vi)] for Ei, Vi in zip(E, V)]


def _check_targets(T: np.ndarray, dimensions: tuple[str, ...], given_shape: tuple[int, ...]) -> None:
    """Raise unless ``T`` is ``(m >= 1, k)`` with every value finite in 0..1."""
    if T.ndim != 2 or T.shape[1] != len(dimensions) or T.shape[0] == 0:
        raise ValidationError(f"targets must have shape (m, {len(dimensions)}) for "
                              f"{list(dimensions)}, got {given_shape}", field="targets")
    if T.size <= 16:   # plain floats: NaN fails both comparisons
        if all(0.0 <= v <= 1.0 for v in T.ravel().tolist()):
            return
    elif np.isfinite(T).all() and (T >= 0).all() and (T <= 1).all():
        return
    for j, dname in enumerate(dimensions):
        col = T[:, j]
        if not np.isfinite(col).all():
            raise ValidationError("NaN or infinite target", field=f"targets.{dname}")
        if (col < 0).any() or (col > 1).any():
            bad = col[(col < 0) | (col > 1)][0]
            raise ValidationError(f"target {bad:g} outside 0..1", field=f"targets.{dname}")


def _answer_key(x: np.ndarray) -> tuple[str, tuple[int, ...], bytes]:
    """Identity of an answer array for :meth:`SolveProblem.evaluate_one`'s memo: equal
    keys, equal evaluations."""
    return x.dtype.char, x.shape, x.tobytes()


@dataclass
class SolveProblem:
    """Targets + model + feature space + constraints.

    Attributes:
        targets: ``(m, k)`` target intensities in 0..1, columns ``dimensions``.
        dimensions: names of the targeted model outputs.
        model: the perception model.
        space: features searched (a subset of the model's inputs), with bounds.
        fixed: model inputs not searched, pinned at a value (physical units).
        constraints: physical constraints on the full feature vector.
        penalty: ``"paper"`` (formula (6), squared physical units) or ``"normalised"``.
        tolerance: success threshold on the sum of absolute intensity errors.
        x0: optional ``(m, d)`` starting points (for polishing chains).
        penalty_weight: multiplier of the penalty term (1 for the paper's form).
    """

    targets: np.ndarray
    dimensions: tuple[str, ...]
    model: PerceptionModel
    space: FeatureSpace
    fixed: dict[str, float] = field(default_factory=dict)
    constraints: tuple[Constraint, ...] = ()
    penalty: str = "paper"
    tolerance: float = 0.01
    x0: np.ndarray | None = None
    penalty_weight: float = 1.0

    def __post_init__(self) -> None:
        self.dimensions = tuple(self.dimensions)
        from ..argcheck import number_array
        T = number_array(self.targets, "targets", finite=False)  # a string is named by its index
        #: True when targets were given as one 1-D row: ``Solver.solve`` returns one result.
        self.single = T.ndim == 1
        if T.ndim == 1:
            T = T[None, :]
        _check_targets(T, self.dimensions, np.shape(self.targets))
        self.targets = T
        missing = [d for d in self.dimensions if d not in self.model.dimension_names]
        if missing:
            raise ValidationError(f"model {self.model.name!r} does not predict {missing}; "
                                  f"it covers {list(self.model.dimension_names)}", field="dimensions")
        if self.penalty not in PENALTY_FORMS:
            raise ValidationError(f"unknown penalty {self.penalty!r}; valid: {list(PENALTY_FORMS)}",
                                  field="penalty")
        from ..argcheck import number
        self.tolerance = number(self.tolerance, "tolerance", lo=0.0, lo_open=True)
        model_in = list(self.model.feature_names)
        for n in self.space.names:
            if n not in model_in:
                raise ValidationError(f"feature {n!r} is not an input of model {self.model.name!r} "
                                      f"(inputs {model_in})", field="space")
        unset = [n for n in model_in if n not in self.space and n not in self.fixed]
        if unset:
            raise ValidationError(f"model inputs {unset} are neither searched nor fixed", field="fixed")
        for n, v in self.fixed.items():
            if not np.isfinite(v):
                raise ValidationError("fixed value is NaN or infinite", field=f"fixed.{n}")
        self.constraints = tuple(self.constraints)
        for c in self.constraints:
            absent = [f for f in c.features if f not in model_in]
            if absent:
                raise ValidationError(f"constraint {c.name!r} reads features {absent} that the model "
                                      f"does not take", field="constraints")
        self._out_idx = np.array([self.model.dimension_names.index(d) for d in self.dimensions], dtype=int)
        self._n_feat = len(self.space)
        self._all_out = np.array_equal(self._out_idx, np.arange(self.model.n_outputs))
        self._identity = tuple(self.space.names) == tuple(model_in)   # X rows are model inputs
        self._base_formulas = all(type(c).uses_base_formulas() for c in self.constraints)
        self._space_cols = np.array([model_in.index(n) for n in self.space.names], dtype=int)
        # plain-float copies for the one-target path (evaluate_one, results)
        self._out_list = self._out_idx.tolist()
        self._cnames = [c.name for c in self.constraints]
        self._bounds_list = (self.space.lower.tolist(), self.space.upper.tolist())
        #: per-setup memo (search caches: sample clouds, lookup tables, keys) shared by the
        #: problems :meth:`with_targets` derives, which differ only in their targets
        self._setup_cache: dict[Any, Any] = {}
        #: ``[self, (key, result)]`` while a one-target ``Solver.solve`` runs on this very
        #: problem: the last :meth:`evaluate_one` of the backend (see there); else ``None``
        self._one_memo: list[Any] | None = None
        self._lo, self._hi = self.space.lower, self.space.upper
        self._fixed_row = np.zeros(len(model_in))
        for n, v in self.fixed.items():
            if n in model_in:
                self._fixed_row[model_in.index(n)] = v
        if self.x0 is not None:
            x0 = np.asarray(self.x0, float)
            if x0.ndim == 1:
                x0 = np.broadcast_to(x0, (self.n_targets, len(self.space))).copy()
            self.x0 = self.space.clip(self.space.validate(x0, field="x0"))
            if self.x0.shape[0] != self.n_targets:
                raise ValidationError("x0 must have one row per target", field="x0")

    def clip(self, X: np.ndarray) -> np.ndarray:
        """``X`` clipped to the searched features' bounds (a new array)."""
        return np.minimum(np.maximum(X, self._lo), self._hi)

    def with_targets(self, targets: Any, x0: np.ndarray | None = None, *, validate: bool = True) -> "SolveProblem":
        """The same problem (model, space, constraints, settings) for other targets: a
        shallow copy, so nothing but the targets is validated or derived again (a one-target
        public call and the chunks of a batch use this). ``targets`` as in the constructor;
        ``x0`` optional ``(m, d)`` starts (already in bounds)."""
        T = np.asarray(targets, dtype=float)
        single = T.ndim == 1
        if single:
            T = T[None, :]
        if validate:
            _check_targets(T, self.dimensions, np.shape(targets))
        new = object.__new__(type(self))      # a shallow copy (copy.copy costs ~3 us more)
        new.__dict__.update(self.__dict__)
        new.targets = T
        new.single = single
        new.x0 = x0
        return new

    def target_chunk(self, start: int, stop: int) -> "SolveProblem":
        """Targets ``start:stop`` as a batch problem (``x0`` rows sliced with them)."""
        new = self.with_targets(self.targets[start:stop],
                                None if self.x0 is None else self.x0[start:stop], validate=False)
        new.single = False
        return new

    # -- sizes -------------------------------------------------------------
    @property
    def n_targets(self) -> int:
        """Number of targets ``m``."""
        return int(self.targets.shape[0])

    @property
    def n_features(self) -> int:
        """Number of searched features ``d``."""
        return len(self.space)

    @property
    def feature_names(self) -> tuple[str, ...]:
        """Names of the searched features, in column order."""
        return self.space.names

    def full_inputs(self, X: np.ndarray) -> np.ndarray:
        """Model input rows ``(n, d_model)`` from searched-feature rows ``(n, d)``."""
        X = np.asarray(X, float)
        G = np.broadcast_to(self._fixed_row, X.shape[:-1] + self._fixed_row.shape).copy()
        G[..., self._space_cols] = X
        return G

    def columns(self, G: np.ndarray) -> dict[str, np.ndarray]:
        """Model inputs ``G`` (``(..., n_inputs)``, physical units) as ``{feature name:
        column}`` for the constraints. For more than 64 rows the columns are rows of one
        transposed copy (contiguous: the constraints' arithmetic on them runs ~1.5x faster
        than on strided views, well above the cost of the copy)."""
        if G.ndim == 2:   # the rows of the transpose are the columns (views, or of one copy)
            return dict(zip(self.model.feature_names, G.T.copy() if G.shape[0] > 64 else G.T))
        return {n: G[..., i] for i, n in enumerate(self.model.feature_names)}

    # -- evaluation --------------------------------------------------------
    def eval_buffers(self, shape: tuple[int, ...], penalty: str | None = None) -> "EvalBuffers":
        """Buffers for :meth:`evaluate` of candidates of leading shape ``shape`` (``X.shape[:-1]``)
        that a solver reuses across the iterations of one run (see :class:`EvalBuffers`)."""
        return EvalBuffers(self, shape, penalty or self.penalty)

    def evaluate(self, X: np.ndarray, *, penalty: str | None = None, details: bool = False,
                 rows: np.ndarray | None = None, per_constraint: bool = False,
                 finite: bool = False, work: "EvalBuffers | None" = None) -> Any:
        """Fitness of formula (6) for ``X`` of shape ``(m, p, d)`` (p candidates per target)
        or ``(m, d)``; ONE model call for all rows. ``rows`` (optional index array) scores
        ``X`` against ``targets[rows]`` instead of all ``m`` targets (solvers that drop solved
        targets). Returns fitness with the leading shape of ``X``; with ``details``, a dict
        with ``fitness``, ``error``, ``violation``, ``intensities`` and, with
        ``per_constraint``, ``violations`` (each constraint's, last axis in the order of
        ``constraints``). ``finite=True`` (solvers, for candidates they generated inside the
        bounds) skips the model's input check for NaN/inf rows.

        ``work`` (optional, from :meth:`eval_buffers` for this ``X.shape[:-1]`` and penalty
        form; ignored otherwise): the arithmetic writes into its buffers instead of fresh
        arrays, so the returned fitness, error and violation are views of them, valid until
        the next call with the same ``work`` (a solver's loop copies what it keeps). The
        numbers are the same with or without it: it is the same code."""
        X = np.asarray(X, float)
        lead = X.shape[:-1]
        T = self.targets if rows is None else self.targets[rows]
        d = self._n_feat
        if X.shape[-1] != d or not lead or lead[0] != T.shape[0]:
            raise ValidationError(f"candidates must have shape (m={T.shape[0]}, [p,] "
                                  f"{d}), got {X.shape}", field="X")
        form = penalty or self.penalty
        if work is not None and (work.lead != lead or work.form != form or work.problem_id != id(self._setup_cache)):
            work = None
        fitness, err, viol, I, per_c = self._formula6(X.reshape(-1, d), T, lead, form, finite, per_constraint, work)
        if not details:
            return fitness
        out = {"fitness": fitness, "error": err, "violation": viol, "intensities": I.reshape(lead + (I.shape[-1],))}
        if per_constraint:
            out["violations"] = (np.zeros(lead + (0,)) if per_c is None
                                 else np.moveaxis(per_c, 0, -1).reshape(lead + (len(self.constraints),)))
        return out

    def evaluate_into(self, work: "EvalBuffers", X: np.ndarray, rows: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``(fitness, error, violation)`` of :meth:`evaluate` (``details``, ``finite=True``)
        into ``work``'s buffers, for a solver's inner loop: ``X`` must be a float array of
        shape ``work.lead + (d,)`` of finite candidates (the solver drew them inside the
        bounds); nothing else is checked. The same code as :meth:`evaluate`; the arrays
        returned are views of ``work`` valid until its next use (``violation`` is None with
        ``work.lazy``: see :meth:`EvalBuffers.violation_at`)."""
        if X.shape[:-1] != work.lead or work.problem_id != id(self._setup_cache):
            raise ValidationError(f"candidates of shape {X.shape} do not fit buffers for {work.lead}", field="X")
        T = self.targets if rows is None else self.targets[rows]
        fitness, err, viol, _, _ = self._formula6(X.reshape(-1, self._n_feat), T, work.lead, work.form, True,
                                                  False, work)
        return fitness, err, viol

    def _formula6(self, X2: np.ndarray, T: np.ndarray, lead: tuple[int, ...], form: str, finite: bool,
                  per_constraint: bool, work: "EvalBuffers | None"
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray, np.ndarray | None]:
        """Formula (6) for candidate rows ``X2`` ``(n, d)`` (leading shape ``lead``) against
        targets ``T``: ``(fitness, error, violation, intensities, per-constraint violations)``
        (the one implementation behind :meth:`evaluate` and :meth:`evaluate_into`)."""
        G = X2 if self._identity else self.full_inputs(X2)
        model = self.model
        if finite and (work.plain if work is not None else _plain_predict(model)):
            I = np.asarray(model._predict(G), dtype=float)
            if I.shape != (work.I_shape if work is not None else (G.shape[0], model.n_outputs)):
                raise ModelError(f"model {model.name!r} returned shape {I.shape}, "
                                 f"expected {(G.shape[0], model.n_outputs)}")
        else:
            I = model.predict(G)
        n = G.shape[0]
        # sum_j |I_j - T_j|: one subtraction, |.| in place, then the columns added (a
        # reduction over a length-2 axis costs more than the additions)
        I3 = I.reshape(T.shape[0], -1, I.shape[-1])
        if not self._all_out:
            I3 = I3[:, :, self._out_idx]
        if work is None or work.T3 is None or work.T_src is not T:
            # the targets' (r, 1, k) view (buffers keep it until the targets change)
            T3 = T[:, None, :] if work is None else work.set_targets(T)
        else:
            T3 = work.T3
        D = np.subtract(I3, T3, out=None if work is None else work.D)
        np.abs(D, out=D)
        if D.shape[-1] == 2:
            err = (np.add(D[..., 0], D[..., 1]) if work is None
                   else np.add(work.D0, work.D1, out=work.err)).reshape(lead)
        else:   # = D.sum(axis=-1) (its reduction), into work's error buffer when given
            err = np.add.reduce(D, axis=-1, out=None if work is None else work.err).reshape(lead)
        per_c = None
        viol: np.ndarray | None
        if not self.constraints:
            fitness, viol = err, np.zeros(lead)
        else:
            if work is not None and work.GT is not None:
                np.copyto(work.GT, G.T)      # the contiguous columns of :meth:`columns`
                cols = work.cols
            else:
                cols = self.columns(G)
            pen, viol, per_c = self._penalty_violation(cols, form, n, per=per_constraint, work=work)
            if self.penalty_weight == 1.0:
                if work is not None and pen is work.pen:   # (views made once)
                    np.add(pen, work.err_flat, out=pen)
                    fitness = work.pen_lead
                else:
                    np.add(pen, err.reshape(-1), out=pen)
                    fitness = pen.reshape(lead)
            else:
                fitness = err + self.penalty_weight * pen.reshape(lead)
            if viol is not None:
                viol = viol.reshape(lead)
        if work is not None:
            work.last_viol = viol
        return fitness, err, viol, I, per_c

    def evaluate_one(self, x: np.ndarray) -> tuple[float, float, float, list[float], list[float]]:
        """Formula (6) at one answer ``x`` ``(d,)`` of the first target, on plain floats:
        ``(fitness, error, violation, intensities, violations)`` with every model output's
        intensity and each constraint's violation as lists; the same numbers as
        :meth:`evaluate` with ``details`` and ``per_constraint`` on a batch of one.

        While a one-target :meth:`Solver.solve` runs on this problem, the last answer its
        backend evaluated here is remembered: a backend that judges its answer with this
        method (to keep it or fall back) and the core's evaluation of the same answer for
        the result then cost one evaluation, not two. Nothing is remembered across calls or
        for derived problems; the lists returned are the caller's own."""
        memo = self._one_memo
        if memo is None or memo[0] is not self or type(x) is not np.ndarray:
            return self._evaluate_one(x)
        key = _answer_key(x)
        pair = memo[1]
        if pair is None or pair[0] != key:
            # key and numbers replaced in one assignment: never a mixed pair, whatever the threads
            pair = (key, self._evaluate_one(x))
            memo[1] = pair
        fit, err, viol, I, pc = pair[1]
        return fit, err, viol, list(I), list(pc)

    def _evaluate_one(self, x: np.ndarray) -> tuple[float, float, float, list[float], list[float]]:
        G = (x if self._identity else self.full_inputs(x))[None, :]
        model = self.model
        if _plain_predict(model):
            # a validated, finite row of the right width: the backend directly
            Y = np.asarray(model._predict(G), dtype=float)
            if Y.shape != (1, model.n_outputs):
                raise ModelError(f"model {model.name!r} returned shape {Y.shape}, expected {(1, model.n_outputs)}")
        else:
            Y = model.predict(G)
        I = Y[0].tolist()
        T = self.targets[0].tolist()
        err = 0.0
        for j, o in enumerate(self._out_list):
            err += abs(I[o] - T[j])
        if not self.constraints:
            return err, err, 0.0, I, []
        cols = self.columns(G)
        form = self.penalty
        pc: list[float] = []
        pen = 0.0
        if self._base_formulas:
            for c in self.constraints:
                bnd, val = c.bound_and_value(cols)
                # the first (only) value, as _first, for the usual (1,) arrays without a call
                b = float(bnd[0]) if type(bnd) is np.ndarray and bnd.shape == (1,) else _first(bnd)
                v = float(val[0]) if type(val) is np.ndarray and val.shape == (1,) else _first(val)
                if v < b:     # a NaN row counts as met, as in evaluate
                    nv = (b - v) / (abs(b) or 1.0)
                    pen += nv if form == "normalised" else b * b - v * v
                else:
                    nv = 0.0
                pc.append(nv)
            viol = max(pc)
        else:
            for c in self.constraints:
                pen += _first(c.penalty(cols, form))
                pc.append(_first(c.violation(cols)))
            viol = max(0.0, *pc)
        if viol == viol and any(v != v for v in pc):   # NaN propagates, as numpy's max
            viol = float("nan")
        fit = err + pen if self.penalty_weight == 1.0 else err + self.penalty_weight * pen
        return fit, err, viol, I, pc

    def _penalty_violation(self, cols: dict[str, np.ndarray], form: str, n: int, per: bool = False,
                           work: "EvalBuffers | None" = None
                           ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Summed penalty (``form``) and max violation of all constraints, ``(n,)`` each,
        and (with ``per``) each constraint's violation ``(c, n)``; into ``work``'s buffers
        when given (the same operations either way; no violation with ``work.lazy``)."""
        if form not in PENALTY_FORMS:   # the message of Constraint.penalty
            raise ValidationError(f"unknown penalty form {form!r}; valid: {list(PENALTY_FORMS)}",
                                  field="penalty")
        if not self._base_formulas:
            pen = np.zeros(n)
            viol = np.zeros(n)
            P = np.empty((len(self.constraints), n))
            for j, c in enumerate(self.constraints):
                pen += c.penalty(cols, form)
                P[j] = c.violation(cols)
                np.maximum(viol, P[j], out=viol)
            return pen, viol, (P if per else None)
        # the values of Constraint.penalty (paper: b^2 - v^2; normalised: (b - v)/|b|,
        # where v < b) from one bound_and_value call per constraint, all constraints
        # stacked so that each operation runs once; into work's arrays when given
        nc = len(self.constraints)
        w = work
        B = np.empty((nc, n)) if w is None else w.B
        V = np.empty((nc, n)) if w is None else w.V
        for j, c in enumerate(self.constraints):
            B[j], V[j] = c.bound_and_value(cols)
        short = np.less(V, B, out=None if w is None else w.short)   # not met (a NaN row counts as met)
        # work.lazy: the violation is left to EvalBuffers.violation_at (a solver that reads
        # it only at a few rows); B and V stay as they are for it
        lazy = w is not None and w.lazy and form == "paper" and not per
        nvs: np.ndarray | None = None
        vmax: np.ndarray | None = None
        if not lazy:
            nvs, vmax = _violations(B, V, short, w)
        if form == "normalised":
            assert nvs is not None
            pen = np.add.reduce(nvs, axis=0, out=None if w is None else w.pen) if nc > 1 else nvs[0].copy()
            return pen, vmax, (nvs if per else None)
        B2 = np.multiply(B, B, out=w.B2 if w is not None and lazy else B)
        V2 = np.multiply(V, V, out=w.V2 if w is not None and lazy else V)
        np.subtract(B2, V2, out=B2)
        P = np.where(short, B2, 0.0)
        if nc == 2:    # = np.add.reduce(P, axis=0)
            pen = np.add(P[0], P[1], out=None if w is None else w.pen)
        else:
            pen = np.add.reduce(P, axis=0, out=None if w is None else w.pen) if nc > 1 else P[0]
        return pen, vmax, (nvs if per else None)


def _violations(B: np.ndarray, V: np.ndarray, short: np.ndarray, w: "_PenaltyBuffers | None" = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """Each constraint's relative violation ``(c, k)`` (the ``normalised`` penalty: ``(b -
    v) / |b|`` where ``v < b``, ``|b| = 0`` read as 1) and their max ``(k,)``, from stacked
    bounds ``B`` and values ``V`` ``(c, k)`` and ``short = V < B`` (into ``w``'s arrays
    when given)."""
    nvs = np.subtract(B, V, out=None if w is None else w.nvs)
    scale = np.abs(B, out=None if w is None else w.scale)
    np.divide(nvs, scale, out=nvs, where=np.not_equal(scale, 0.0, out=None if w is None else w.nz))
    nvs = np.where(short, nvs, 0.0)
    # ufunc calls directly (ndarray.max goes through a Python wrapper: ~1 us)
    if nvs.shape[0] == 2:   # = np.maximum.reduce(nvs, axis=0)
        viol = np.maximum(nvs[0], nvs[1], out=None if w is None else w.viol)
    else:
        viol = np.maximum.reduce(nvs, axis=0, out=None if w is None else w.viol) if nvs.shape[0] > 1 \
            else nvs[0].copy()
    return nvs, viol


class _PenaltyBuffers:
    """The ``(c, n)`` and ``(n,)`` arrays of :meth:`SolveProblem._penalty_violation`."""

    def __init__(self, nc: int, n: int) -> None:
        self.B, self.V, self.nvs, self.scale, self.B2, self.V2 = np.empty((6, nc, n))   # (one allocation each)
        self.short, self.nz = np.empty((2, nc, n), bool)
        self.viol, self.pen = np.empty((2, n))


class EvalBuffers(_PenaltyBuffers):
    """Work arrays of :meth:`SolveProblem.evaluate` for candidates of one leading shape
    ``lead`` (``X.shape[:-1]``) and penalty form, reused by a solver across the iterations
    of one run (:meth:`SolveProblem.eval_buffers`): the same arithmetic then writes into
    memory that is already there instead of ~20 fresh arrays per call, and the per-setup
    facts it needs (whether the model's ``predict`` is the base one, the contiguous column
    views for the constraints) are looked up once. Not thread-safe; one run at a time.

    ``lazy`` (set it to True; paper penalty form, base-formula constraints): ``evaluate``
    then returns ``violation=None`` and the violation of the rows a solver needs comes from
    :meth:`violation_at` (after the same call, before the next): a GA reads it only where
    a child beats the best so far, a few times per run."""

    lazy = False
    last_viol: "np.ndarray | None" = None

    def __init__(self, problem: "SolveProblem", lead: tuple[int, ...], form: str) -> None:
        lead = tuple(map(int, lead))
        n = math.prod(lead)
        super().__init__(len(problem.constraints), n)
        self.lead, self.form = lead, form
        self.problem_id = id(problem._setup_cache)      # problems of one setup share it
        self.plain = _plain_predict(problem.model)
        k = len(problem.dimensions)
        self.D = np.empty((lead[0], n // lead[0] if lead[0] else 0, k))
        self.err = np.empty(self.D.shape[:2])
        self.D0, self.D1 = (self.D[..., 0], self.D[..., 1]) if k == 2 else (self.D, self.D)
        self.err_flat = self.err.reshape(-1)
        self.pen_lead = self.pen.reshape(lead)
        self.T_src: np.ndarray | None = None
        self.T3: np.ndarray | None = None
        self.I_shape = (n, problem.model.n_outputs)
        # the columns of SolveProblem.columns for more than 64 rows: rows of one contiguous
        # (inputs, n) copy, whose views are made once here
        self.GT: np.ndarray | None = None
        self.cols: dict[str, np.ndarray] = {}
        if n > 64:
            names = problem.model.feature_names
            self.GT = np.empty((len(names), n))
            self.cols = {nm: self.GT[i] for i, nm in enumerate(names)}

    def set_targets(self, T: np.ndarray) -> np.ndarray:
        """Remember ``T``'s ``(r, 1, k)`` view for the next calls with the same targets."""
        self.T_src, self.T3 = T, T[:, None, :]
        return self.T3

    def violation_at(self, idx: Any) -> Any:
        """Max relative violation of rows ``idx`` (flat indices into ``X.reshape(-1, d)``
        of the last :meth:`SolveProblem.evaluate` call with these buffers): the same
        numbers as its ``violation`` array (:func:`_violations` on those rows)."""
        if self.last_viol is not None:
            return self.last_viol.reshape(-1)[idx]
        return _violations(self.B[:, idx], self.V[:, idx], self.short[:, idx])[1]


def _first(a: Any) -> float:
    """The first (only) value of a one-row constraint result (array, numpy or Python scalar)."""
    return float(a[0]) if getattr(a, "ndim", 0) else float(a)


def _plain_predict(model: PerceptionModel) -> bool:
    """True when ``model.predict`` is :meth:`PerceptionModel.predict` (validation, then
    ``_predict``), not overridden by the class or the instance."""
    return type(model).predict is PerceptionModel.predict and "predict" not in vars(model)


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
