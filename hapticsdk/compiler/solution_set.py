"""The set of feature vectors that reach a target: a seed-independent basis for
decisions that read features.

The inverse of a perception model has many solutions: for a target ``(hardness,
roughness)`` a whole 3-dimensional family of ``G = [GS, W, Fpeak, AFpeak, P]`` predicts
the same intensities. A decision that reads features (the importance model's leave-out
rule, which reads GS, Fpeak and AFpeak) would flip with whichever member a randomised
solver happened to return. Here the decision reads the *distribution* over the family
instead:

1. a fixed, deterministic quasi-random design (a Halton sequence, no random seed) of
   ``n_design`` points covers the searched feature box; the model and the constraints are
   evaluated on it once per problem;
2. for each target the ``n_start`` feasible design points nearest to it in intensity
   space (L1) are moved onto the target by a few damped Gauss-Newton steps of the
   minimum-norm form ``du = -J^T (J J^T + mu I)^-1 r`` in unit-box coordinates (the
   model's Jacobian), clipped to the box;
3. the points whose error is within the problem's tolerance and that satisfy every
   constraint form the target's :class:`SolutionSet`.

The same problem gives the same set on every run and for every solver seed. The set is
a sample of the solution family, weighted by where the design put points, not a
probability distribution of anything physical: its percentiles say how much a
feature-reading prediction varies across equally good solutions.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..solvers import SolveProblem

__all__ = ["SolutionSet", "halton", "solution_sets"]

_PRIMES = (2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47)


def halton(n: int, d: int) -> np.ndarray:
    """The first ``n`` points (skipping the origin) of the ``d``-dimensional Halton
    sequence in ``[0, 1)^d``; deterministic."""
    if d > len(_PRIMES):
        raise ValueError(f"halton: at most {len(_PRIMES)} dimensions")
    idx = np.arange(1, n + 1, dtype=np.int64)
    out = np.empty((n, d))
    for j in range(d):
        b = _PRIMES[j]
        f = 1.0 / b
        i = idx.copy()
        v = np.zeros(n)
        while i.any():
            v += f * (i % b)
            i //= b
            f /= b
        out[:, j] = v
    return out


@dataclass
class SolutionSet:
    """Feature vectors (physical units, searched features only) that reach one target.

    Attributes:
        X: ``(n, d)`` solutions, columns ``names``.
        names: the searched feature names.
        error: ``(n,)`` sum of absolute intensity errors of each solution.
        radius: the largest design-point distance (L1, intensity) the starts came from.
        n_starts: how many design points were moved onto the target.
        reached: False when no feasible point reaches the target within the tolerance
            (the target is outside what the model predicts under the constraints); then
            ``X`` holds the ``min_size`` feasible design points nearest to the target
            instead, and ``error`` says how far they are.
    """

    X: np.ndarray
    names: tuple[str, ...]
    error: np.ndarray
    radius: float
    n_starts: int
    reached: bool = True

    def __len__(self) -> int:
        return int(self.X.shape[0])

    def columns(self, fixed: dict[str, float] | None = None) -> dict[str, np.ndarray]:
        """Name -> ``(n,)`` column, with ``fixed`` features broadcast."""
        cols = {n: self.X[:, i] for i, n in enumerate(self.names)}
        for k, v in (fixed or {}).items():
            cols.setdefault(k, np.full(len(self), float(v)))
        return cols


_CACHE: dict[Any, tuple[Any, np.ndarray, np.ndarray, np.ndarray]] = {}


def _design(problem: SolveProblem, n_design: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit-box design points, their intensities (targeted columns) and feasibility."""
    # constraints by what they are (class and parameters, ``describe()``), not by name: two
    # device bands share a name but not a feasible set
    cons = tuple((type(c).__qualname__, json.dumps(c.describe(), sort_keys=True, default=repr))
                 for c in problem.constraints)
    key = (id(problem.model), problem.dimensions, problem.space.names, tuple(problem.space.lower),
           tuple(problem.space.upper), tuple(sorted(problem.fixed.items())), cons, n_design)
    hit = _CACHE.get(key)
    # the entry holds its model, so the id in the key cannot be reused by another model
    # while the entry lives; the identity check makes that explicit
    if hit is not None and hit[0] is problem.model:
        return hit[1:]
    U = halton(n_design, problem.n_features)
    X = problem.space.from_unit(U)
    det = problem.evaluate(X[None], rows=np.array([0]), details=True)
    I = np.asarray(det["intensities"])[0]
    idx = [problem.model.dimension_names.index(d) for d in problem.dimensions]
    I = I[:, idx]
    feasible = np.asarray(det["violation"])[0] <= 0.0
    if len(_CACHE) > 16:
        _CACHE.clear()
    _CACHE[key] = (problem.model, U, I, feasible)
    return U, I, feasible


def _project(problem: SolveProblem, U: np.ndarray, target: np.ndarray, steps: int) -> np.ndarray:
    """Damped minimum-norm Gauss-Newton steps moving unit-box points onto ``target``."""
    lo, span = problem.space.lower, problem.space.upper - problem.space.lower
    idx = [problem.model.dimension_names.index(d) for d in problem.dimensions]
    cols = np.array([problem.model.feature_names.index(n) for n in problem.space.names])
    for _ in range(steps):
        G = problem.full_inputs(lo + U * span)
        r = problem.model.predict(G)[:, idx] - target            # (n, k)
        J = problem.model.jacobian(G)[:, idx][:, :, cols] * span  # (n, k, d), per unit coordinate
        JJt = J @ np.swapaxes(J, 1, 2)
        mu = 1e-6 * (np.trace(JJt, axis1=1, axis2=2)[:, None, None] + 1e-12)
        k = JJt.shape[1]
        y = np.linalg.solve(JJt + mu * np.eye(k), r[..., None])
        U = np.clip(U - (np.swapaxes(J, 1, 2) @ y)[..., 0], 0.0, 1.0)
    return U


def solution_sets(problem: SolveProblem, *, n_design: int = 16384, n_start: int = 48,
                  steps: int = 4, min_size: int = 8) -> list[SolutionSet]:
    """One :class:`SolutionSet` per target of ``problem`` (see the module docstring).

    Args:
        problem: targets, model, searched space and constraints.
        n_design: size of the deterministic design.
        n_start: design points moved onto each target.
        steps: Gauss-Newton steps per start.
        min_size: a target whose set is smaller is tried again with four times the
            starts and twice the steps (hard-to-reach targets near the edge of what the
            model predicts).

    A target no start reaches within the problem's tolerance gets the nearest feasible
    design points instead, with ``reached=False``.
    """
    U, I, feasible = _design(problem, n_design)
    Uf, If = U[feasible], I[feasible]
    out: list[SolutionSet] = []
    names = problem.space.names
    lo, span = problem.space.lower, problem.space.upper - problem.space.lower
    for i in range(problem.n_targets):
        T = problem.targets[i]
        if len(Uf) == 0:
            out.append(SolutionSet(np.zeros((0, len(names))), names, np.zeros(0), float("inf"), 0,
                                   reached=False))
            continue
        dist = np.abs(If - T).sum(axis=1)
        for starts, n_steps in ((n_start, steps), (4 * n_start, 2 * steps)):
            k = min(starts, len(dist))
            near = np.argpartition(dist, k - 1)[:k]
            radius = float(dist[near].max())
            Up = _project(problem, Uf[near], T, n_steps)
            Xp = lo + Up * span
            det = problem.evaluate(Xp, rows=np.full(len(Xp), i), details=True)
            err = np.asarray(det["error"])
            ok = (err <= problem.tolerance) & (np.asarray(det["violation"]) <= 0.0)
            if int(ok.sum()) >= min_size:
                break
        if not ok.any():
            near = np.argsort(dist, kind="stable")[:min_size]
            out.append(SolutionSet(lo + Uf[near] * span, names, dist[near], float(dist[near].max()), 0,
                                   reached=False))
            continue
        order = np.argsort(err[ok], kind="stable")
        out.append(SolutionSet(Xp[ok][order], names, err[ok][order], radius, k))
    return out
