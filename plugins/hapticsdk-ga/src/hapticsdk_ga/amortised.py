"""Amortised solving: a precomputed target-grid table answered by interpolation.

Building (once per model/problem setup, then cached):

1. ``build_samples`` feature points are drawn uniformly in the searched bounds (fixed
   seed) and run through the model; feasible ones (constraints met) give a cloud of
   reachable intensities.
2. The target grid (``grid`` nodes per targeted dimension over 0..1; 101 x 101 for
   hardness x roughness by default) is solved by the batched Levenberg-Marquardt of
   :mod:`hapticsdk_ga.polish` with *continuation*: the first column (first dimension at 0)
   is swept node by node along the second dimension, each node started from its
   neighbour's answer and from the nearest sample; every further column is solved as one
   batch started from the previous column's answers and from the nearest samples, keeping
   the continued answer unless the other start is clearly better. Neighbouring nodes thus
   get neighbouring features, which is what makes interpolation meaningful (the inverse
   is not unique: 5 features for 2 intensities).
3. The table (``(grid, grid, d)`` features, per-node error and violation) is cached in
   memory and on disk (``.npz`` under ``cache_dir`` / ``$HAPTICSDK_CACHE_DIR`` /
   ``$XDG_CACHE_HOME/hapticsdk`` / ``~/.cache/hapticsdk``, subfolder ``amortised``), keyed
   by a SHA-256 of the model file's SHA-256 (models loaded from a file), the model's
   outputs on a fixed probe set, the dimensions, bounds, fixed values, the constraints'
   values on the probe set, and the table options.

Answering: bilinear interpolation of the node features at the targets
(:meth:`AmortisedTable.lookup`, microseconds, for live retargeting), then optionally
``polish_steps`` batched LM iterations on the real problem (one ``predict`` and one
``jacobian`` call each). Targets outside the reachable set get the table's nearest-feasible
answer and end ``success=False`` like with any other solver.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
import time
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from hapticsdk.errors import ValidationError
from hapticsdk.solvers import CONSTRAINT_TOL, SolveProblem, Solver, SolverOutput, Trace

from ._common import check_int, rank_key
from .polish import levenberg_marquardt

log = logging.getLogger(__name__)
_dot, _tanh, _max, _min, _square = np.dot, np.tanh, np.maximum, np.minimum, np.square

TABLE_VERSION = 2   # 2: the file records its build time
_MEMO: dict[str, "AmortisedTable"] = {}


def default_cache_dir() -> Path:
    """``$HAPTICSDK_CACHE_DIR`` or ``$XDG_CACHE_HOME/hapticsdk`` or ``~/.cache/hapticsdk``
    (:func:`hapticsdk.fileio.cache_dir`)."""
    from hapticsdk.fileio import cache_dir
    return cache_dir()


class AmortisedTable:
    """Features on a regular target grid, with interpolation.

    Attributes:
        X: ``(g1, g2, d)`` (two targeted dimensions) or ``(g1, d)`` (one) node features,
            physical units of ``feature_names``.
        node_error: per node, the sum of absolute intensity errors reached when building.
        node_violation: per node, max relative constraint violation.
        key: the cache key (hex SHA-256).
    """

    def __init__(self, X: np.ndarray, node_error: np.ndarray, node_violation: np.ndarray,
                 feature_names: tuple[str, ...], dimensions: tuple[str, ...], key: str,
                 lower: np.ndarray, upper: np.ndarray, build_time_s: float = float("nan")) -> None:
        self.X = np.ascontiguousarray(X, float)
        #: CPU seconds the table took to build (kept in the cache file; NaN if unknown)
        self.build_time_s = float(build_time_s)
        #: where this instance came from: "built", "disk cache" or "memory"
        self.source = "built"
        #: seconds spent building it or loading it from disk in this process
        self.obtain_time_s = float("nan")
        self.node_error = node_error
        self.node_violation = node_violation
        self.feature_names = tuple(feature_names)
        self.dimensions = tuple(dimensions)
        self.key = key
        self.lower, self.upper = lower, upper
        self.k = len(self.dimensions)
        self.shape = self.X.shape[:-1]
        self.shape_text = str(self.shape)   # as results' messages print it
        self._g = [n - 1 for n in self.shape]
        if self.k == 2:
            self._flat = self.X.reshape(-1, self.X.shape[-1])
            # the four corner rows of every cell side by side, (g1-1, g2-1, 4, d): a lookup
            # then reads one contiguous block and needs one small matrix product
            C = np.stack([self.X[:-1, :-1], self.X[1:, :-1], self.X[:-1, 1:], self.X[1:, 1:]], axis=2)
            self._cells = np.ascontiguousarray(C)
            self._g1f, self._g2f = float(self._g[0]), float(self._g[1])
        self._unit_cells: np.ndarray | None = None

    def lookup(self, targets: Any) -> np.ndarray:
        """Interpolated features for ``targets`` (``(m, k)`` or one ``(k,)`` row) in 0..1.

        Returns ``(m, d)`` (or ``(d,)`` for one row). No validation beyond clipping to
        0..1 (this is the live-retargeting fast path; :meth:`AmortisedSolver.solve`
        validates).
        """
        if self.k == 2:
            if isinstance(targets, (tuple, list)) and len(targets) == 2 and not hasattr(targets[0], "__len__"):
                return self._one(float(targets[0]), float(targets[1]))
            T = np.asarray(targets, float)
            if T.ndim == 1:
                return self._one(float(T[0]), float(T[1]))
            if T.shape[0] == 1:
                return self._one(float(T[0, 0]), float(T[0, 1]))[None]
            return self._many(T)
        T = np.asarray(targets, float)
        single = T.ndim == 1
        t = np.clip(T.reshape(-1), 0.0, 1.0) * self._g[0]
        i = np.minimum(t.astype(int), self._g[0] - 1)
        a = (t - i)[:, None]
        out = (1 - a) * self.X[i] + a * self.X[i + 1]
        return out[0] if single else out

    def unit_one(self, h: float, r: float) -> np.ndarray:
        """The lookup of one target ``(h, r)`` (two targeted dimensions) in unit-box
        coordinates of the table's bounds, ``(x - lower) / (upper - lower)`` (0 where a
        feature's range is empty), clipped to 0..1, with a trailing 1: ``(d + 1,)``, what
        the one-target Gauss-Newton step starts from. The same interpolation as
        :meth:`lookup` on corner rows converted once (memoised)."""
        U = self._unit_cells
        if U is None:
            span = self.upper - self.lower
            inv = np.where(span > 0, 1.0 / np.where(span > 0, span, 1.0), 0.0)
            U = np.ones(self._cells.shape[:-1] + (self._cells.shape[-1] + 1,))
            U[..., :-1] = np.clip((self._cells - self.lower) * inv, 0.0, 1.0)
            U = self._unit_cells = np.ascontiguousarray(U)
        return self._one(h, r, U)

    def _one(self, h: float, r: float, cells: np.ndarray | None = None) -> np.ndarray:
        # bilinear weights on plain floats, then one (4,) @ (4, d) product on the cell's
        # corner block (a fresh (d,) array)
        g1, g2 = self._g
        fh = (0.0 if h < 0.0 else 1.0 if h > 1.0 else h) * self._g1f
        fr = (0.0 if r < 0.0 else 1.0 if r > 1.0 else r) * self._g2f
        i = int(fh)
        j = int(fr)
        if i >= g1:
            i = g1 - 1
        if j >= g2:
            j = g2 - 1
        a = fh - i
        b = fr - j
        a1 = 1.0 - a
        b1 = 1.0 - b
        return _dot((a1 * b1, a * b1, a1 * b, a * b), (self._cells if cells is None else cells)[i, j])

    def _many(self, T: np.ndarray) -> np.ndarray:
        g1, g2 = self._g
        fh = np.clip(T[:, 0], 0.0, 1.0) * g1
        fr = np.clip(T[:, 1], 0.0, 1.0) * g2
        i = np.minimum(fh.astype(int), g1 - 1)
        j = np.minimum(fr.astype(int), g2 - 1)
        a = (fh - i)[:, None]
        b = (fr - j)[:, None]
        n2 = self.shape[1]
        base = i * n2 + j
        F = self._flat
        return (1 - a) * ((1 - b) * F[base] + b * F[base + 1]) + a * ((1 - b) * F[base + n2] + b * F[base + n2 + 1])

    def reachable_fraction(self, tolerance: float) -> float:
        """Fraction of grid nodes solved within ``tolerance`` with constraints met."""
        return float(((self.node_error <= tolerance) & (self.node_violation <= CONSTRAINT_TOL)).mean())

    def save(self, path: Path) -> None:
        """Write the table (and its build time) to ``path`` atomically."""
        from hapticsdk.fileio import atomic_savez
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_savez(path, compressed=False, X=self.X, node_error=self.node_error,
                     node_violation=self.node_violation, lower=self.lower, upper=self.upper,
                     meta=np.array(json.dumps({"feature_names": self.feature_names, "dimensions": self.dimensions,
                                               "key": self.key, "version": TABLE_VERSION,
                                               "build_time_s": self.build_time_s})))

    @classmethod
    def load(cls, path: Path) -> "AmortisedTable":
        """Read a table written by :meth:`save` (numpy archive, no pickles)."""
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            bt = meta.get("build_time_s")
            return cls(z["X"], z["node_error"], z["node_violation"], tuple(meta["feature_names"]),
                       tuple(meta["dimensions"]), meta["key"], z["lower"], z["upper"],
                       build_time_s=float(bt) if isinstance(bt, (int, float)) else float("nan"))


def problem_key(problem: SolveProblem, options: dict[str, Any]) -> str:
    """SHA-256 identifying everything a table depends on (see module doc)."""
    h = hashlib.sha256()
    h.update(f"v{TABLE_VERSION}".encode())
    h.update(json.dumps({"dims": list(problem.dimensions), "space": problem.space.to_dict(),
                         "fixed": {k: float(v) for k, v in sorted(problem.fixed.items())},
                         "model_inputs": list(problem.model.feature_names),
                         "model_outputs": list(problem.model.dimension_names),
                         "constraints": [type(c).__qualname__ + ":" + c.name for c in problem.constraints],
                         "grid": options["grid"], "samples": options["build_samples"],
                         "iter": options["build_iter"],
                         # the model file's identity where it has one (a replaced file
                         # invalidates the table even if the probe outputs below agreed)
                         "model_file_sha256": getattr(problem.model, "file_sha256", None)},
                        sort_keys=True).encode())
    rng = np.random.default_rng(20240611)
    X = problem.space.random(64, rng)
    G = problem.full_inputs(X)
    h.update(np.round(problem.model.predict(G), 10).tobytes())
    if problem.constraints:
        cols = problem.columns(G)
        for c in problem.constraints:
            h.update(np.round(c.violation(cols), 10).tobytes())
    return h.hexdigest()


def build_table(problem: SolveProblem, *, grid: int = 101, build_samples: int = 20000,
                build_iter: int = 15, key: str = "") -> AmortisedTable:
    """Solve the target grid of ``problem``'s dimensions (see module doc). Deterministic."""
    k = len(problem.dimensions)
    if k not in (1, 2):
        raise ValidationError(f"the amortised table supports 1 or 2 targeted dimensions, got {k}",
                              field="dimensions")
    rng = np.random.default_rng(12345)
    S = problem.space.random(build_samples, rng)
    G = problem.full_inputs(S)
    names = problem.model.dimension_names
    Y = problem.model.predict(G)[:, [names.index(d) for d in problem.dimensions]]
    if problem.constraints:
        cols = problem.columns(G)
        ok = np.ones(len(S), bool)
        for c in problem.constraints:
            ok &= c.violation(cols) <= CONSTRAINT_TOL
        if ok.sum() >= 16:
            S, Y = S[ok], Y[ok]
    from scipy.spatial import cKDTree
    tree = cKDTree(Y)
    axis = np.linspace(0.0, 1.0, grid)
    if k == 1:
        nodes = axis[:, None]
    else:
        hh, rr = np.meshgrid(axis, axis, indexing="ij")
        nodes = np.stack([hh.ravel(), rr.ravel()], axis=1)
    node_problem = dataclasses.replace(problem, targets=nodes, x0=None)
    near = S[tree.query(nodes)[1]]
    d = problem.n_features
    X = np.empty((len(nodes), d))
    E = np.empty(len(nodes))
    V = np.empty(len(nodes))

    def solve_rows(rows: np.ndarray, cont: np.ndarray | None) -> None:
        starts = [near[rows]] if cont is None else [cont, near[rows]]
        n_s = len(starts)
        X0 = np.stack(starts, axis=1).reshape(-1, d)
        rr = np.repeat(rows, n_s)
        Xs, es, vs, _, _ = levenberg_marquardt(node_problem, X0, rr, max_iter=build_iter, goal=1e-9)
        key_ = rank_key(es, vs).reshape(len(rows), n_s)
        pick = key_.argmin(axis=1)
        if n_s == 2:  # keep the continued answer unless the other is clearly better
            keep = key_[:, 0] <= key_[:, 1] + 1e-6
            pick = np.where(keep, 0, pick)
        idx = np.arange(len(rows)) * n_s + pick
        X[rows], E[rows], V[rows] = Xs[idx], es[idx], vs[idx]

    if k == 1:
        solve_rows(np.arange(grid), None)
    else:
        first = np.arange(grid)  # nodes (0, j)
        solve_rows(first[:1], None)
        for j in range(1, grid):
            solve_rows(first[j:j + 1], X[first[j - 1:j]])
        for i in range(1, grid):
            rows = i * grid + np.arange(grid)
            solve_rows(rows, X[rows - grid])
    shape = (grid,) * k + (d,)
    return AmortisedTable(X.reshape(shape), E.reshape(shape[:-1]), V.reshape(shape[:-1]),
                          problem.feature_names, problem.dimensions, key,
                          problem.space.lower, problem.space.upper)


class AmortisedSolver(Solver):
    """Answer targets from a precomputed grid table, then polish.

    Options: ``grid`` (101 nodes per targeted dimension), ``polish_steps`` (1 LM iteration
    after the lookup; 0 = pure lookup), ``build_samples`` (20000), ``build_iter`` (15 LM
    iterations per node when building), ``cache`` (True: read/write the disk cache),
    ``cache_dir`` (None: see :func:`default_cache_dir`).

    :meth:`table` returns the (cached) :class:`AmortisedTable`; its
    :meth:`~AmortisedTable.lookup` is the fast path for live retargeting.
    """

    name: ClassVar[str] = "amortised"
    uses_rng: ClassVar[bool] = False     # deterministic: lookup + LM steps
    privileged_options: ClassVar[dict[str, str]] = {"cache_dir": "a folder whose tables are read and written"}
    default_options: ClassVar[dict[str, Any]] = {
        "grid": 101, "polish_steps": 1, "build_samples": 20000, "build_iter": 15,
        "cache": True, "cache_dir": None,
    }

    def _table_options(self) -> tuple[dict[str, Any], tuple]:
        """The validated table options and the per-setup memo key (memoised per option
        values: a one-target call then checks nothing twice)."""
        o = self.options
        raw = (o["grid"], o["build_samples"], o["build_iter"], o["cache"], o["cache_dir"])
        key: tuple | None = (raw, tuple(map(type, raw)))     # 101.0 == 101, but only the int is valid
        try:
            found = self._checked.get(key)  # type: ignore[arg-type]
        except TypeError:   # an unhashable value: check_int raises below
            key, found = None, None
        if found is not None:
            return found
        opts = {"grid": check_int(o, "grid", 2, 2001),
                "build_samples": check_int(o, "build_samples", 16, 10_000_000),
                "build_iter": check_int(o, "build_iter", 1, 10_000)}
        if not isinstance(o["cache"], (bool, np.bool_)):
            raise ValidationError(f"must be True or False, got {o['cache']!r:.60}", field="options.cache")
        if o["cache_dir"] is not None and not isinstance(o["cache_dir"], (str, os.PathLike)):
            raise ValidationError(f"must be a directory path or None, got {type(o['cache_dir']).__name__}",
                                  field="options.cache_dir")
        mkey = ("amortised", tuple(sorted(opts.items())), bool(o["cache"]), o["cache_dir"])
        hit: tuple[dict[str, Any], tuple] = (opts, mkey)
        if key is not None:
            self._checked[key] = hit
        return hit

    def table(self, problem: SolveProblem) -> AmortisedTable:
        """The table for ``problem`` (memory cache, then disk cache, else built and stored)."""
        o = self.options
        opts, mkey = self._table_options()
        memo = getattr(problem, "_setup_cache", None)
        if memo is not None:
            tab = memo.get(mkey)
            if tab is not None:
                return tab
        t_start = time.perf_counter()
        key = problem_key(problem, opts)
        tab = _MEMO.get(key)
        if tab is not None:
            if memo is not None:
                memo[mkey] = tab
            return tab
        path = None
        if o["cache"]:
            path = Path(o["cache_dir"]) if o["cache_dir"] else default_cache_dir()
            path = path / "amortised" / f"{key[:40]}.npz"
            if path.exists():
                try:
                    tab = AmortisedTable.load(path)
                    tab.source = "disk cache"
                    if tab.key != key:
                        tab = None
                except Exception as exc:  # corrupt cache file: rebuild
                    log.warning("ignoring unreadable amortised table %s: %s", path, exc)
                    tab = None
        if tab is None:
            c0 = time.process_time()
            tab = build_table(problem, key=key, **opts)
            tab.build_time_s = time.process_time() - c0
            log.info("built amortised table %s in %.2f s CPU", tab.shape, tab.build_time_s)
            if path is not None:
                try:
                    tab.save(path)
                except OSError as exc:
                    log.warning("could not write amortised table cache %s: %s", path, exc)
        tab.obtain_time_s = time.perf_counter() - t_start
        _MEMO[key] = tab
        if memo is not None:
            memo[mkey] = tab
        return tab

    def __init__(self, **options: Any) -> None:
        super().__init__(**options)
        self._checked: dict[tuple, tuple[dict[str, Any], tuple]] = {}

    def _solve(self, problem: SolveProblem, rng: np.random.Generator, trace: Trace) -> SolverOutput:
        steps = self.options["polish_steps"]
        if type(steps) is not int or not 0 <= steps <= 10_000:
            steps = check_int(self.options, "polish_steps", 0, 10_000)
        tab = self.table(problem)
        if steps and problem.single:
            fast = self._one_target(problem, tab, steps, trace)
            if fast is not None:
                return fast
        X = tab.lookup(problem.targets)
        if steps == 0:   # the lookup alone (node features interpolated: in bounds); the core evaluates it
            return SolverOutput(x=X, nfev=0, nit=0, message=f"table {tab.shape} lookup")
        X = problem.clip(X)
        rows = np.arange(problem.n_targets)
        Xp, err, viol, it, nfev = levenberg_marquardt(
            problem, X, rows, max_iter=steps, goal=0.0, on_iter=lambda n, e, v: trace.record(n, e, v))
        return SolverOutput(x=Xp, nfev=nfev, nit=it,
                            message=f"table {tab.shape} lookup + {it} LM step(s)")

    def _one_target(self, problem: SolveProblem, tab: AmortisedTable, steps: int,
                    trace: Trace) -> SolverOutput | None:
        """One target: the lookup, then ``steps`` Gauss-Newton steps of minimum norm on
        plain 1-D arrays (the network's forward pass and Jacobian with the scaling folded
        into the weights, no batch machinery), in unit-box coordinates and clipped to the
        bounds. The answer is kept when it meets every constraint, its error (the model's) is
        within the tolerance, and it is no worse than the lookup, whose error the float64
        network gives: by the model's error, or where that is above (the float32 model
        differs from the float64 network by rounding, which can exceed the error of a
        lookup already on the target) by the float64 network's error at the answer;
        otherwise ``None`` and the caller
        runs the general batched LM (a target where a constraint binds: about 1 in 10 reachable targets of
        the default model). ``None`` also for a model without a numpy twin."""
        net = _one_row(problem)
        if net is None:
            return None
        lo, hi, span, k = net[7:11]
        Wa, W2a, P, s_l, m_l, inv_span, Psum = net[11:18]
        T = problem.targets[0].tolist()
        d = len(span)
        if k == 2:
            u = tab.unit_one(T[0], T[1])         # (u, 1): unit-box coordinates, clipped
        else:
            u = np.ones(d + 1)
            u[:d] = (tab.lookup(T) - lo) * inv_span
            _max(u, 0.0, out=u)
            _min(u, 1.0, out=u)
        err0 = -1.0
        ul: list[float] = []
        for step in range(steps + 1):
            if step == steps:
                # the answer, back in physical units (lo + span may round one unit above hi)
                x = np.array([hi_ if lo_ + v * sp > hi_ else lo_ + v * sp for v, lo_, sp, hi_ in zip(ul, *net[18:])])
                _, err, viol, _, _ = problem.evaluate_one(x)
                if not (viol <= CONSTRAINT_TOL and err <= problem.tolerance):
                    return None
                if err <= err0:
                    break         # no worse than the lookup
                # the model's (float32) error is above the lookup's by the float64 network,
                # which can be its rounding alone: judge the answer by that network too
            if step:
                u = np.array(ul + [1.0])
            # forward pass on the augmented vectors: the bias, the lower bounds and the
            # fixed inputs ride on u's trailing 1, the output bias on a saturated hidden unit
            h = _dot(Wa, u)
            _tanh(h, out=h)
            ys = _dot(W2a, h)
            ys = _tanh(ys, out=ys).tolist()
            if k == 2:
                (y0, y1), (s0, s1), (m0, m1) = ys, s_l, m_l
                r0 = (y0 + 1.0) * s0 + m0 - T[0]      # residuals
                r1 = (y1 + 1.0) * s1 + m1 - T[1]
                err_twin = abs(r0) + abs(r1)
            else:
                y0, s0, m0 = ys[0], s_l[0], m_l[0]
                r0 = (y0 + 1.0) * s0 + m0 - T[0]
                err_twin = abs(r0)
            if not step:
                err0 = err_twin   # the lookup's error
            elif step == steps:
                if err_twin > err0:
                    return None   # worse than the lookup by both
                break
            _square(h, out=h)
            # (k, d + 1) Jacobian in the unit box before the output scaling: sum_j (1 - h_j^2) P_j
            J = (Psum - _dot(h, P)).reshape(k, d + 1).tolist()
            ut = u.tolist()
            if k == 2:   # (J J^T)^-1 r by Cramer's rule on floats; a singular J gives up
                a0 = (1.0 - y0 * y0) * s0              # the output scaling: J = diag(a) Jh
                a1 = (1.0 - y1 * y1) * s1
                J0, J1 = J
                p = q = w = 0.0
                for v0, v1 in zip(J0, J1):
                    p += v0 * v0
                    q += v0 * v1
                    w += v1 * v1
                A00, A01, A11 = a0 * a0 * p, a0 * a1 * q, a1 * a1 * w
                det = A00 * A11 - A01 * A01
                if not det > 1e-12 * (A00 * A11 + 1e-300):
                    return None
                c0 = -a0 * (A11 * r0 - A01 * r1) / det
                c1 = -a1 * (A00 * r1 - A01 * r0) / det
                # du = -J^T (J J^T)^-1 r (minimum norm), clipped to the unit box
                ul = [v + c0 * g0 + c1 * g1 for v, g0, g1 in zip(ut[:d], J0, J1)]
            else:        # one targeted dimension: J J^T is a number
                a0 = (1.0 - y0 * y0) * s0
                J0 = J[0]
                n2 = a0 * a0 * sum(v * v for v in J0)
                if not n2 > 0.0:
                    return None
                c0 = -a0 * r0 / n2
                ul = [v + c0 * g0 for v, g0 in zip(ut[:d], J0)]
            ul = [0.0 if v < 0.0 else 1.0 if v > 1.0 else v for v in ul]
        trace.record(steps + 1, float(err), float(viol))
        return SolverOutput(x=x[None], nfev=steps + 2, nit=steps,
                            message=f"table {tab.shape_text} lookup + {steps} Gauss-Newton step(s), one target")


def _one_row(problem: SolveProblem) -> tuple | None:
    """The targeted outputs of the model's numpy twin with the min-max scaling folded in,
    per problem setup (memoised on the setup cache the public ``solve`` keeps):
    ``(W1, b1, W2, b2, y_scale, y_min, W1u, lower, upper, span, k, Wa, W2a, P,
    y_scale_list, y_min_list, inv_span)`` with ``h = tanh(W1 g + b1)``, ``y = (tanh(W2 h +
    b2) + 1) y_scale + y_min`` for the targeted dimensions, ``W1u`` the searched columns of
    ``W1`` per unit-box coordinate, and the augmented form the one-target step runs
    (:func:`_augmented`); ``None`` when the model has no analytic numpy form (then the
    general LM runs)."""
    memo = getattr(problem, "_setup_cache", None)
    net: Any = memo.get("amortised-one-row", False) if memo is not None else False
    if net is False:
        from hapticsdk.perception.models import MLPModel
        model = problem.model
        mlp = model if isinstance(model, MLPModel) else getattr(model, "mlp", None)
        net = None
        if isinstance(mlp, MLPModel):
            idx = [model.dimension_names.index(d) for d in problem.dimensions]
            cols = [model.feature_names.index(n) for n in problem.space.names]
            lo, hi = problem.space.lower, problem.space.upper
            W1 = mlp.W1 * mlp._xs                                  # x_s = (x - x_min) xs - 1 folded in
            b1 = mlp.b1 - W1 @ mlp.x_min - mlp.W1.sum(axis=1)
            span = hi - lo
            W1u = np.ascontiguousarray(W1[:, cols] * span)
            net = (W1, b1, mlp.W2[idx], mlp.b2[idx], mlp._ys[idx], mlp.y_min[idx],
                   W1u, lo, hi, span, len(idx)) + _augmented(problem, W1, b1, W1u, mlp.W2[idx], mlp.b2[idx]) + (
                   mlp._ys[idx].tolist(), mlp.y_min[idx].tolist(),
                   np.where(span > 0, 1.0 / np.where(span > 0, span, 1.0), 0.0))
            net += (net[13].sum(axis=0), lo.tolist(), span.tolist(), hi.tolist())
        if memo is not None:
            memo["amortised-one-row"] = net
    return net


#: a hidden unit with this pre-activation outputs exactly 1.0 in float64: 1 - tanh(z) is
#: about 2 exp(-2 z), below half a unit in the last place of 1 (2^-53) from z = 18.7 on
_SATURATED = 40.0


def _augmented(problem: SolveProblem, W1: np.ndarray, b1: np.ndarray, W1u: np.ndarray,
               W2: np.ndarray, b2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The network on augmented vectors, so that a forward pass and the Jacobian are three
    matrix products: with ``u`` the unit-box coordinates of the searched features and a
    trailing 1, ``h = tanh(Wa u)`` (``H + 1`` units: the first layer with its bias, the
    lower bounds and the fixed inputs in the last column, and one saturated unit that is
    exactly 1), ``y_s = tanh(W2a h)`` (the output bias on that unit), and the unit-box
    Jacobian before the output scaling ``Jh = ((1 - h^2) @ P).reshape(k, d + 1)``, whose
    row ``P[j]`` is the outer product of ``W2[:, j]`` and ``W1u[j]`` (the saturated unit's
    derivative is 0; the trailing column is 0, so a step never moves the 1)."""
    H, d = W1u.shape
    k = W2.shape[0]
    Wa = np.zeros((H + 1, d + 1))
    Wa[:H, :d] = W1u
    Wa[:H, d] = b1 + W1 @ problem.full_inputs(problem.space.lower)
    Wa[H, d] = _SATURATED
    W2a = np.concatenate([W2, b2[:, None]], axis=1)
    Pk = np.zeros((H + 1, k, d + 1))
    Pk[:H, :, :d] = W2.T[:, :, None] * W1u[:, None, :]
    return Wa, np.ascontiguousarray(W2a), Pk.reshape(H + 1, k * (d + 1))
