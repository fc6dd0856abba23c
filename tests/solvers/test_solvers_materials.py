"""Closed loop on the shipped setup: the default method, the default (shipped) perception
model and the installed hardness/roughness dimensions must answer every material of the
shipped library within the problem's tolerance with the constraints met.

Skipped when the default model or a dimension plugin is not installed (the other solver
tests use a seeded in-file model and need neither)."""

from __future__ import annotations

import numpy as np
import pytest

from hapticsdk.solvers import CONSTRAINT_TOL

DIMS = ("hardness", "roughness")


@pytest.fixture(scope="module")
def library_problem():
    from hapticsdk.errors import PluginError
    from hapticsdk.perception.materials import load_library
    from hapticsdk.solvers.problems import build_problem

    mats = list(load_library())
    T = np.array([[m.intensities[d] for d in DIMS] for m in mats], float)
    try:
        problem = build_problem(T, dimensions=DIMS)
    except PluginError as exc:  # default model / dimension plugins not installed
        pytest.skip(f"shipped model or dimensions not available: {exc}")
    return [m.name for m in mats], T, problem


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_default_method_meets_every_material(library_problem, seed):
    from hapticsdk.solvers.problems import DEFAULT_METHOD, get_solver

    names, T, problem = library_problem
    assert len(names) >= 20
    res = get_solver().solve(problem, seed=seed)          # the default method
    assert res.method == DEFAULT_METHOD
    # closed loop, independent of the result's own fields: run the model on the answers
    G = problem.full_inputs(res.x)
    I = problem.model.predict(G)
    out = [problem.model.dimension_names.index(d) for d in DIMS]
    err = np.abs(I[:, out] - T).sum(axis=1)
    cols = problem.columns(G)
    viol = np.max([c.violation(cols) for c in problem.constraints], axis=0)
    bad = [(n, float(e), float(v)) for n, e, v in zip(names, err, viol)
           if not (e <= problem.tolerance and v <= CONSTRAINT_TOL)]
    assert not bad, f"seed {seed}: materials missed (name, error, violation): {bad}"
    assert problem.tolerance <= 0.01
    assert np.all(res.success)
    assert np.all((res.x >= problem.space.lower) & (res.x <= problem.space.upper))


def test_polish_alone_meets_every_material_over_15_seeds(library_problem):
    """``polish`` from its default starts (nearest cloud samples + random, with the rescue
    round) meets every material, batched, for 15 seeds: from random starts only it left S4
    at 0.011 and S1 at 0.05 in some of them (a local minimum, a stall along a bound)."""
    from hapticsdk.solvers.problems import get_solver

    names, T, problem = library_problem
    S = get_solver("polish")
    missed = []
    for seed in range(15):
        res = S.solve(problem, seed=seed)
        G = problem.full_inputs(res.x)
        out = [problem.model.dimension_names.index(d) for d in DIMS]
        err = np.abs(problem.model.predict(G)[:, out] - T).sum(axis=1)
        cols = problem.columns(G)
        viol = np.max([c.violation(cols) for c in problem.constraints], axis=0)
        missed += [(names[i], seed, float(err[i])) for i in range(len(T))
                   if not (err[i] <= problem.tolerance and viol[i] <= CONSTRAINT_TOL)]
    assert not missed, missed
