"""The inverse problem a solver minimises: :class:`SolveProblem` holds targets, a
perception model, the feature space to search, features pinned at fixed values, and the
physical constraints; its :meth:`~SolveProblem.evaluate` computes the fitness of
formula (6) for whole populations of whole batches of targets in one model call
(:class:`EvalBuffers`: the reusable working arrays).

Part of :mod:`hapticsdk.solvers`, which re-exports the public names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..perception.dimensions import Constraint, PENALTY_FORMS, _one as _first
from ..errors import ModelError, ValidationError
from ..perception.features import FeatureSpace
from ..perception.models import PerceptionModel


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
        # plain floats: a string, a bool, None or an int beyond the float range is named
        self.fixed = {n: number(v, f"fixed.{n}") for n, v in self.fixed.items()}
        self.penalty_weight = number(self.penalty_weight, "penalty_weight", lo=0.0)
        self.constraints = tuple(self.constraints)
        for i, c in enumerate(self.constraints):
            if not isinstance(c, Constraint):
                raise ValidationError(f"must be a Constraint, got {type(c).__name__} {c!r:.60}",
                                      field=f"constraints[{i}]")
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
        form = self.penalty
        pc: list[float] = []
        pen = 0.0
        if self._base_formulas:
            # the row as plain floats: each constraint's bound and value without numpy
            # (Constraint.bound_and_value_one; the same numbers as on a one-row batch)
            row = dict(zip(model.feature_names, G[0].tolist()))
            for c in self.constraints:
                b, v = c.bound_and_value_one(row)
                if v < b:     # a NaN row counts as met, as in evaluate
                    nv = (b - v) / (abs(b) or 1.0)
                    pen += nv if form == "normalised" else b * b - v * v
                else:
                    nv = 0.0
                pc.append(nv)
            viol = max(pc)
        else:
            cols = self.columns(G)
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


def _plain_predict(model: PerceptionModel) -> bool:
    """True when ``model.predict`` is :meth:`PerceptionModel.predict` (validation, then
    ``_predict``), not overridden by the class or the instance."""
    return type(model).predict is PerceptionModel.predict and "predict" not in vars(model)
