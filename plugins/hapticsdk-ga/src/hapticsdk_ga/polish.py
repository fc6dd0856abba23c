"""Bounded Levenberg-Marquardt polish and the GA + polish chain.

The residual vector of one candidate is ``[I_j(x) - T_j for each targeted dimension] +
[w * s_c for each constraint]`` with ``s_c = (bound - value) / |bound| + margin``:
intensity errors (signed, so the sum of squares is smooth) and the constraints of formula
(6) as extra residuals in their normalised (relative) form, shifted by a small ``margin``
so that an iterate converging onto a constraint ends on its feasible side. A constraint
counts as ``max(0, s_c)`` until the iterate first violates it; from then on it is kept
as the signed equality residual ``s_c`` ("sticky" active set): the hinge ``max(0, .)``
makes Gauss-Newton zig-zag along an active constraint, the equality converges
quadratically, and with 5 features for 2 intensities the system stays solvable on the
constraint surface. Steps are taken in unit
coordinates (``u = (x - lower) / span``) with the model's Jacobian
(``problem.model.jacobian``, analytic for :class:`~hapticsdk.perception.models.MLPModel`; constraint
columns by central differences, which need no model call), damped (``(J^T J + lambda I)
step = -J^T r``, features on a bound whose descent direction leaves the box held there),
projected onto the bounds, and accepted only when the sum of squares falls (``lambda`` /3
on success, *4 on failure). Everything is batched over targets x starts: one ``predict``
and one ``jacobian`` call per iteration for the rows still running (see
:func:`levenberg_marquardt` for the stopping rules).

Degenerate bounds (lower == upper) give a zero Jacobian column and a zero step: the
feature stays at its bound.
"""

from __future__ import annotations

from typing import Any, Callable, ClassVar

from collections.abc import Mapping

import numpy as np

from hapticsdk.errors import ValidationError
from hapticsdk.solvers import CONSTRAINT_TOL, SolveProblem, Solver, SolverOutput, Trace

from ._common import (Clock, check_budget, check_fraction, check_int, check_target_error, constraint_shortfalls,
                      merge_options, rank_key, sample_cloud, solved_mask, violation_from)

#: upper limits of the size options (they bound a mistyped value, not a sensible one)
MAX_ITER = 100_000
MAX_STARTS = 10_000


class _Residuals:
    """Residuals and Jacobians of a problem for candidate rows belonging to target ``rows``.

    Every evaluation also returns the raw constraint shortfalls ``S`` (``(n, c)``,
    :func:`~hapticsdk_ga._common.constraint_shortfalls`): the constraint residuals, the
    sticky-set update, the stopping test and the violation all derive from that one array.
    """

    def __init__(self, problem: SolveProblem, margin: float, weight: float) -> None:
        self.p = problem
        names = problem.model.dimension_names
        self.out_idx = np.array([names.index(d) for d in problem.dimensions], dtype=int)
        model_in = list(problem.model.feature_names)
        self.cols = np.array([model_in.index(n) for n in problem.space.names], dtype=int)
        self._all_out = np.array_equal(self.out_idx, np.arange(len(names)))
        self._all_cols = np.array_equal(self.cols, np.arange(len(model_in)))
        self._identity = tuple(problem.space.names) == tuple(model_in)
        self.lower = problem.space.lower
        self.span = problem.space.upper - problem.space.lower
        self.margin = margin
        self.weight = weight
        self.nc = len(problem.constraints)
        self.nfev = 0
        d = len(self.span)
        self.h = 1e-6
        self._E = np.concatenate([np.eye(d) * self.h, np.eye(d) * -self.h])   # (2d, d): +h then -h

    def x(self, U: np.ndarray) -> np.ndarray:
        X = U * self.span
        X += self.lower
        return X

    def inputs(self, U: np.ndarray) -> np.ndarray:
        X = self.x(U)
        return X if self._identity else self.p.full_inputs(X)

    def shortfalls(self, G: np.ndarray) -> np.ndarray:
        return constraint_shortfalls(self.p, G)

    def cterms(self, S: np.ndarray, sticky: np.ndarray) -> np.ndarray:
        """Constraint residuals from shortfalls: ``w * (S + margin)``, hinged where not sticky."""
        s = S + self.margin
        np.copyto(s, 0.0, where=~sticky & (s < 0))
        if self.weight != 1.0:
            s *= self.weight
        return s

    def residual(self, U: np.ndarray, T: np.ndarray, sticky: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(r (n, k+c), G (n, d_model), abs error (n,), shortfalls S (n, c))``."""
        G = self.inputs(U)
        I = self.p.model.predict(G)
        if not self._all_out:
            I = I[:, self.out_idx]
        self.nfev += G.shape[0]
        k = I.shape[1]
        r = np.empty((G.shape[0], k + self.nc))
        rI = r[:, :k]
        np.subtract(I, T, out=rI)
        err = np.abs(rI).sum(axis=1)
        if self.nc:
            S = self.shortfalls(G)
            r[:, k:] = self.cterms(S, sticky)
        else:
            S = np.empty((G.shape[0], 0))
        return r, G, err, S

    def jacobian(self, U: np.ndarray, G: np.ndarray, sticky: np.ndarray) -> np.ndarray:
        """``(n, k+c, d)`` in unit coordinates."""
        J = self.p.model.jacobian(G)
        if not self._all_out:
            J = J[:, self.out_idx]
        if not self._all_cols:
            J = J[:, :, self.cols]
        self.nfev += G.shape[0]
        n, d = U.shape
        k = J.shape[1]
        out = np.empty((n, k + self.nc, d))
        np.multiply(J, self.span, out=out[:, :k])
        if self.nc:
            Upm = (U[:, None, :] + self._E).reshape(-1, d)                 # one constraint call
            S = self.shortfalls(self.inputs(Upm))
            c = self.cterms(S, np.repeat(sticky, 2 * d, axis=0)).reshape(n, 2, d, self.nc)
            dc = c[:, 0] - c[:, 1]
            dc /= 2 * self.h
            out[:, k:] = np.transpose(dc, (0, 2, 1))
        return out

    def violation(self, S: np.ndarray, G: np.ndarray) -> np.ndarray:
        return violation_from(self.p, S, G)


def _member(values: np.ndarray, of: np.ndarray) -> np.ndarray:
    """``np.isin(values, of)`` for small non-negative integers (target indices): a
    boolean table instead of a sort (``isin`` costs ~40 us even on a handful of rows)."""
    if values.size == 0:
        return np.zeros(0, bool)
    table = np.zeros(int(max(values.max(), of.max() if of.size else 0)) + 1, bool)
    table[of] = True
    return table[values]


def levenberg_marquardt(problem: SolveProblem, X0: np.ndarray, rows: np.ndarray, *, max_iter: int,
                        goal: float, damping: float = 1e-2, margin: float = 1e-6, weight: float = 1.0,
                        clock: Clock | None = None,
                        on_iter: Callable[[int, np.ndarray, np.ndarray], None] | None = None,
                        ftol: float = 0.0, patience: int = 5, per_target: bool = False,
                        settle: float | None = None,
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
    """Batched bounded LM from ``X0`` ``(n, d)``; row ``i`` aims at ``problem.targets[rows[i]]``.

    A row stops when its error is <= ``goal`` with constraints met; when ``lambda`` exceeds
    1e10; after an accepted step that lowered its sum of squares by at most ``ftol`` times
    it, ``patience`` iterations in a row without more progress than that (rejected steps
    included): converged to a
    stationary point, e.g. the closest point of a target that cannot be met exactly (with
    a float32 model the sum of squares there fluctuates by ~1e-5 relative, so ``ftol``
    must sit above that; 0 = never); or, with ``per_target``, as soon as another row
    aiming at the same target (another start) is at the goal or, with ``settle``, has
    converged with constraints met and an error <= ``settle`` (the problem's tolerance: a
    target that cannot be met to ``goal`` is settled by its first converged acceptable
    start; rows of such a target that still violate a constraint are not repaired, they
    cannot be picked). The loop ends when no row is left.

    Features on a bound whose descent direction points out of the box are held there for
    the step (their Jacobian column zeroed), so the damped step is solved for the free
    features instead of being projected afterwards (a projected step stalls along a bound).
    The rows still running are kept in compact arrays (written back when they stop), so
    an iteration costs the same few dozen array operations whatever the batch.
    Returns ``(X, error, violation, iterations, nfev)``; ``on_iter(nfev, error, violation)``
    is called after the start evaluation and after every iteration.
    """
    R = _Residuals(problem, margin, weight)
    span = R.span
    free = span > 0
    U = np.where(free, (np.asarray(X0, float) - R.lower) / np.where(free, span, 1.0), 0.0)
    U = np.clip(U, 0.0, 1.0)
    rows = np.asarray(rows)
    T = problem.targets[rows]
    nc = R.nc
    sticky = np.zeros((U.shape[0], nc), bool)
    r, G, err, S = R.residual(U, T, sticky)
    if nc:
        sticky = S > 0
        r[:, -nc:] = R.cterms(S, sticky)
    f = np.einsum("ij,ij->i", r, r)
    n, d = U.shape
    lam = np.full(n, float(damping))
    viol = R.violation(S, G)
    if on_iter:
        on_iter(R.nfev, err, viol)
    eye = np.eye(d)
    it = 0

    def at_goal(e: np.ndarray, s: np.ndarray) -> np.ndarray:
        return (e <= goal) & (s <= 0).all(axis=1) if nc else e <= goal

    ok = at_goal(err, S)
    stop = ok | (lam >= 1e10)
    if per_target and ok.any():
        stop |= _member(rows, rows[ok])
    # compact working set: a = indices of the running rows; *a arrays = their state
    a = np.flatnonzero(~stop)
    Ua, Ga, ra, fa, ea, Sa, sta, la, Ta = U[a], G[a], r[a], f[a], err[a], S[a], sticky[a], lam[a], T[a]
    stall = np.zeros(a.size, int)
    while it < max_iter and a.size and not (clock and clock.expired()):
        Ja = R.jacobian(Ua, Ga, sta)
        g = np.einsum("nkd,nk->nd", Ja, ra)          # gradient of 0.5 |r|^2
        # features on a bound whose descent direction leaves the box are held there (their
        # Jacobian column zeroed): the damped step is then computed for the free features
        # only, instead of being projected (which stalls the iteration along a bound)
        held = ((Ua <= 0.0) & (g > 0)) | ((Ua >= 1.0) & (g < 0))
        if held.any():
            Ja = Ja * ~held[:, None, :]
            g[held] = 0.0
        JT = np.transpose(Ja, (0, 2, 1))
        A = JT @ Ja
        A += la[:, None, None] * eye
        step = np.linalg.solve(A, -g[..., None])[..., 0]
        step += Ua
        Un = np.clip(step, 0.0, 1.0, out=step)
        rn, Gn, en, Sn = R.residual(Un, Ta, sta)
        fn = np.einsum("ij,ij->i", rn, rn)
        acc = fn < fa
        it += 1
        conv = None
        if ftol > 0:
            # an accepted step lowering f by <= ftol*f starts (or extends) a stall; once
            # stalled, rejected steps extend it too (before that they are the normal damping
            # search of LM); an accepted step with real progress ends it
            tiny = acc & (fa - fn <= ftol * fa)
            stall = np.where(tiny | (~acc & (stall > 0)), stall + 1, np.where(acc, 0, stall))
            conv = stall >= patience
        if acc.any():
            c1 = acc[:, None]
            np.copyto(Ua, Un, where=c1)
            np.copyto(Ga, Gn, where=c1)
            np.copyto(ra, rn, where=c1)
            np.copyto(fa, fn, where=acc)
            np.copyto(ea, en, where=acc)
            if nc:
                np.copyto(Sa, Sn, where=c1)
                newly = (Sn > 0) & ~sta & c1
                if newly.any():
                    sta |= newly
                    nr = newly.any(axis=1)
                    ra[nr, -nc:] = R.cterms(Sa[nr], sta[nr])
                    fa[nr] = np.einsum("ij,ij->i", ra[nr], ra[nr])
            la = np.where(acc, np.maximum(la / 3.0, 1e-12), la * 4.0)
        else:
            la = la * 4.0
        if on_iter:
            err[a] = ea
            if acc.any():
                ia = a[acc]
                viol[ia] = R.violation(Sn[acc], Gn[acc])
            on_iter(R.nfev, err, viol)
        oka = at_goal(ea, Sa)
        sa = oka | (la >= 1e10)
        if conv is not None:
            sa |= conv
        if per_target:
            ends = oka
            if settle is not None and conv is not None:
                ends = oka | (conv & (ea <= settle) & ((Sa <= 0).all(axis=1) if nc else True))
            if ends.any():
                sa |= _member(rows[a], rows[a[ends]])
        if sa.any():   # write the stopped rows back, shrink the working set
            i = a[sa]
            U[i], G[i], r[i], f[i], err[i], S[i], sticky[i], lam[i] = (
                Ua[sa], Ga[sa], ra[sa], fa[sa], ea[sa], Sa[sa], sta[sa], la[sa])
            keep = ~sa
            a = a[keep]
            Ua, Ga, ra, fa, ea, Sa, sta, la, Ta = (Ua[keep], Ga[keep], ra[keep], fa[keep], ea[keep],
                                                   Sa[keep], sta[keep], la[keep], Ta[keep])
            stall = stall[keep]
    if a.size:
        U[a], G[a], r[a], f[a], err[a], S[a], sticky[a], lam[a] = Ua, Ga, ra, fa, ea, Sa, sta, la
    if nc:
        skip = None
        if per_target:
            feas = (S <= 0).all(axis=1)
            skip = ~feas & _member(rows, rows[feas])   # a sibling start is feasible
        U, G, err, S = _repair(R, U, G, err, S, T, skip=skip)
    viol = R.violation(S, G)
    return R.x(U), err, viol, it, R.nfev


def _repair(R: _Residuals, U: np.ndarray, G: np.ndarray, err: np.ndarray, S: np.ndarray, T: np.ndarray,
            iters: int = 4, skip: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Project rows that still violate a constraint onto it: minimum-norm Gauss-Newton
    steps on the violated constraints' shortfalls only (no intensity terms; constraint
    Jacobians by central differences, no model call), then one model call for the moved
    rows. Needed where the least-squares compromise between a large intensity residual
    (unreachable target) and a constraint leaves a small violation."""
    touched = np.zeros(U.shape[0], bool)
    for _ in range(iters):
        viol_rows = (S > 0).any(axis=1)
        if skip is not None:
            viol_rows &= ~skip
        bad = np.flatnonzero(viol_rows)
        if bad.size == 0:
            break
        Ub, sb = U[bad], S[bad] + R.margin
        n, d = Ub.shape
        spm = (R.shortfalls(R.inputs((Ub[:, None, :] + R._E).reshape(-1, d))) + R.margin
               ).reshape(n, 2, d, -1)
        J = np.transpose((spm[:, 0] - spm[:, 1]) / (2 * R.h), (0, 2, 1))  # (n, c, d)
        act = sb > 0
        J = J * act[:, :, None]
        r = np.where(act, sb, 0.0)
        JJt = J @ np.transpose(J, (0, 2, 1)) + 1e-12 * np.eye(J.shape[1])
        step = -(np.transpose(J, (0, 2, 1)) @ np.linalg.solve(JJt, r[..., None]))[..., 0]
        U[bad] = np.clip(Ub + step, 0.0, 1.0)
        G[bad] = R.inputs(U[bad])
        S[bad] = R.shortfalls(G[bad])
        touched[bad] = True
    t = np.flatnonzero(touched)
    if t.size:
        _, G[t], err[t], S[t] = R.residual(U[t], T[t], np.zeros((t.size, R.nc), bool))
    return U, G, err, S


def pick_best(X: np.ndarray, err: np.ndarray, viol: np.ndarray, m: int, starts: int
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Best of ``starts`` consecutive rows per target (rows ordered target-major)."""
    key = rank_key(err, viol).reshape(m, starts)
    k = key.argmin(axis=1)
    idx = np.arange(m) * starts + k
    return X[idx], err[idx], viol[idx]


class _BestTrace:
    """Adapter: per-row (target x start) errors -> per-target best into a :class:`Trace`."""

    def __init__(self, trace: Trace, m: int, starts: int, nfev0: int = 0) -> None:
        self.trace, self.m, self.starts, self.nfev0 = trace, m, starts, nfev0

    def __call__(self, nfev: int, err: np.ndarray, viol: np.ndarray) -> None:
        key = rank_key(err, viol).reshape(self.m, self.starts)
        k = key.argmin(axis=1)
        idx = np.arange(self.m) * self.starts + k
        self.trace.record(self.nfev0 + nfev, err[idx], viol[idx])


class PolishSolver(Solver):
    """Bounded Levenberg-Marquardt (damped Gauss-Newton) from several starts per target.

    Options: ``max_iter`` (30), ``starts`` (4 per target), ``start`` (``"auto"``: the row
    of ``problem.x0`` when given, then the feasible samples of a cached sample cloud whose
    intensities are nearest the target (about half of the starts, see
    :func:`~hapticsdk_ga._common.sample_cloud`), the rest random; ``"x0"``: only
    ``problem.x0``; ``"random"``: random starts only; ``"ga"``: a short GA's best, then
    nearest samples and random starts),
    ``ga_options`` (GA settings for ``start="ga"``), ``target_error`` (1e-6: stop a
    target once one of its starts has an error below this with its constraints met; its
    other starts stop too), ``ftol`` (1e-4: a start also stops after ``patience`` iterations in a row,
    the first an accepted step, that did not lower its sum of squared residuals by more
    than this fraction: converged to a stationary point, typically the closest point of a
    target that cannot be met exactly; a start converged there with constraints met and an
    error within the problem's tolerance ends its target's other starts too; 0 = never),
    ``damping`` (initial lambda, 1e-2), ``constraint_margin`` (1e-6, relative),
    ``constraint_weight`` (1.0), ``time_budget_s`` (None), ``patience`` (3, the iterations
    of the ``ftol`` rule), ``rescue_starts`` (8: a target none of whose starts ended within
    the problem's tolerance is solved again from this many new starts, its next-nearest
    cloud samples and random points, and the better answer kept; 0 = no rescue).
    Every random number of a target is drawn up front in target order, so a batch solved
    in chunks gets the same answers as in one piece.
    """

    name: ClassVar[str] = "polish"
    default_options: ClassVar[dict[str, Any]] = {
        "max_iter": 30, "starts": 4, "start": "auto", "ga_options": None, "target_error": 1e-6,
        "ftol": 1e-4, "damping": 1e-2, "constraint_margin": 1e-6, "constraint_weight": 1.0, "time_budget_s": None,
        "rescue_starts": 8, "patience": 3,
    }
    _ga_defaults: ClassVar[dict[str, Any]] = {"population": 30, "generations": 10}
    #: GA stage goal (``start="ga"``) = this x the problem's tolerance (None: the GA's own)
    _ga_goal_factor: ClassVar[float | None] = None

    def _starts(self, problem: SolveProblem, rng: np.random.Generator, trace: Trace, n_starts: int,
                start: str, uniforms: np.ndarray) -> tuple[np.ndarray, int]:
        """``(m * n_starts, d)`` start rows (target-major) and the model rows spent on them.

        Row 0 of a target: ``problem.x0`` (``"auto"``/``"x0"``, when given) or the GA's best
        (``"ga"``); then, except for ``"random"``, the feasible samples of the cached cloud
        nearest the target (about half of the starts); the rest uniform in bounds, from
        ``uniforms`` ``(m, n_starts, d)``."""
        m, d = problem.n_targets, problem.n_features
        lower, span = problem.space.lower, problem.space.upper - problem.space.lower
        X = lower + uniforms * span
        nfev = 0
        first = 0
        if start in ("auto", "x0"):
            if problem.x0 is not None:
                X[:, 0] = problem.x0
                first = 1
            elif start == "x0":
                raise ValidationError("start='x0' needs problem.x0", field="options.start")
        elif start == "ga":
            from .ga import GASolver
            given = dict(self.options.get("ga_options") or {})
            ga_opts = merge_options(GASolver.default_options, {**self._ga_defaults, **given}, "options.ga_options")
            if "target_error" not in given and self._ga_goal_factor is not None:
                # the GA only has to bring a target near; the LM meets it
                ga_opts["target_error"] = self._ga_goal_factor * float(problem.tolerance)
            out = GASolver(**ga_opts)._solve(problem, rng, trace)
            X[:, 0] = out.x
            nfev = out.nfev
            first = 1
        elif start != "random":
            raise ValidationError(f"unknown start {start!r}; valid: ['auto', 'x0', 'random', 'ga']",
                                  field="options.start")
        if start != "random" and n_starts > first:
            k = max(1, (n_starts - first + 1) // 2)
            X[:, first:first + k] = sample_cloud(problem).nearest(problem.targets, k)
        return X.reshape(m * n_starts, d), nfev

    def _run(self, problem: SolveProblem, rng: np.random.Generator, trace: Trace, *, start: str,
             n_starts: int) -> SolverOutput:
        o = self.options
        max_iter = check_int(o, "max_iter", 0, MAX_ITER)
        goal = check_target_error(o["target_error"])
        if o["ga_options"] is not None and not isinstance(o["ga_options"], Mapping):
            raise ValidationError(f"must be an object of GA options or None, got {o['ga_options']!r:.60}",
                                  field="options.ga_options")
        damping = check_fraction(o, "damping", 1e-12, 1e6)   # the floor the updates keep: 0 leaves a held feature singular
        ftol = check_fraction(o, "ftol", 0.0, 1.0)
        margin = check_fraction(o, "constraint_margin", 0.0, 1.0)
        weight = check_fraction(o, "constraint_weight", 1e-12, 1e12)
        rescue = check_int(o, "rescue_starts", 0, MAX_STARTS)
        clock = Clock(check_budget(o))
        m = problem.n_targets
        if start == "x0" and problem.x0 is not None:
            n_starts = 1
        # every random start of a target, rescue included, is drawn here: a fixed number per
        # target in target order, so a batch solved in chunks gets the same answers
        uni = rng.random((m, n_starts + rescue, problem.n_features))
        X0, nfev0 = self._starts(problem, rng, trace, n_starts, start, uni[:, :n_starts])
        rows = np.repeat(np.arange(m), n_starts)
        lm: dict[str, Any] = dict(max_iter=max_iter, goal=goal, damping=damping, margin=margin, weight=weight, clock=clock,
                  ftol=ftol, patience=check_int(o, "patience", 1, MAX_ITER), per_target=True,
                  settle=float(problem.tolerance))
        X, err, viol, it, nfev = levenberg_marquardt(
            problem, X0, rows, on_iter=_BestTrace(trace, m, n_starts, nfev0), **lm)
        xb, eb, vb = pick_best(X, err, viol, m, n_starts)
        note = ""
        # rescue: a target none of whose starts got within the tolerance (a local minimum or
        # a stall) gets ``rescue_starts`` fresh starts: its next-nearest cloud samples and
        # random points, solved the same way; kept only where better
        miss = np.flatnonzero(~solved_mask(eb, vb, float(problem.tolerance)))
        if rescue and miss.size and not clock.expired():
            k_near = (rescue + 1) // 2
            near = sample_cloud(problem).nearest(problem.targets[miss], n_starts + k_near)[:, -k_near:]
            lower, span = problem.space.lower, problem.space.upper - problem.space.lower
            XR = lower + uni[miss, n_starts:] * span
            XR[:, :k_near] = near
            Xr, er, vr, it2, nfev2 = levenberg_marquardt(
                problem, XR.reshape(-1, problem.n_features), np.repeat(miss, rescue), **lm)
            nfev += nfev2
            it += it2
            xr, err_r, viol_r = pick_best(Xr, er, vr, miss.size, rescue)
            better = rank_key(err_r, viol_r) < rank_key(eb[miss], vb[miss])
            xb[miss[better]], eb[miss[better]], vb[miss[better]] = xr[better], err_r[better], viol_r[better]
            trace.record(nfev0 + nfev, eb, vb)
            note = f"; {miss.size} target(s) not within tolerance retried from {rescue} new starts"
        ok = int(((eb <= goal) & (vb <= CONSTRAINT_TOL)).sum())
        return SolverOutput(x=xb, nfev=nfev0 + nfev, nit=it,
                            message=f"LM {it} iterations x {n_starts} starts{note}; {ok}/{m} at error <= {goal:g}")

    def _solve(self, problem: SolveProblem, rng: np.random.Generator, trace: Trace) -> SolverOutput:
        return self._run(problem, rng, trace, start=self.options["start"],
                         n_starts=check_int(self.options, "starts", 1, MAX_STARTS))


class GAPolishSolver(PolishSolver):
    """A short GA whose best individual per target starts the LM polish, next to the
    nearest cloud samples and random starts (``starts=4`` in all). The GA stage
    (``ga_options``; default population 100 as in the paper, at most 20 generations,
    ``init="nearest"``: 8 of its individuals are the cloud samples nearest the target)
    only has to bring a target near: a target leaves it once its best is within 5 x the
    problem's tolerance with constraints met, or after 3 generations without progress
    (``stall_generations``), and the LM meets it. This is the SDK's default solver; see
    docs/solvers.md for its quality and time on the material library."""

    name: ClassVar[str] = "ga-polish"
    default_options: ClassVar[dict[str, Any]] = {**PolishSolver.default_options, "start": "ga", "starts": 4}
    _ga_defaults: ClassVar[dict[str, Any]] = {"population": 100, "generations": 20, "init": "nearest",
                                              "stall_generations": 3}
    _ga_goal_factor: ClassVar[float | None] = 5.0
