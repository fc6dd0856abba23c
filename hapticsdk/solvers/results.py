"""Result objects of a solve, like ``scipy.optimize.OptimizeResult``: one target's
:class:`SolveResult` (``x``, ``fun``, ``success``, ``message``, ``nfev``, the error and
the run time), a batch's :class:`BatchSolveResult` (a list of them, built lazily from
arrays), and the convergence :class:`Trace`.

Part of :mod:`hapticsdk.solvers`, which re-exports the public names.
"""

from __future__ import annotations

import operator
import time
from typing import TYPE_CHECKING, Any, Iterator, Sequence

import numpy as np

if TYPE_CHECKING:
    from .base import _BatchData  # a batch's arrays, built by the Solver base


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
