"""Batches solved in chunks, the lazy batch result, bounded solver options, one-target
public calls through cached problems, the sample cloud's nearest starts, the GA's stall
rule and nearest-sample initialisation. Nothing here times anything."""

from __future__ import annotations

import numpy as np
import pytest

import hapticsdk.solvers.base as core
from hapticsdk.errors import ValidationError
from hapticsdk.solvers import BatchSolveResult, SolveResult
from hapticsdk_ga._common import SampleCloud, sample_cloud
from hapticsdk_ga.amortised import AmortisedSolver
from hapticsdk_ga.de import DESolver, ScipyDESolver
from hapticsdk_ga.ga import GASolver
from hapticsdk_ga.polish import GAPolishSolver, PolishSolver


def _mixed_targets(fx, model, n=9):
    """Reachable targets plus corners of the intensity square (unreachable for the fixture
    model), so that the polish rescue round runs too."""
    T = fx.reachable_targets(model, n, seed=21)
    return np.vstack([T[:4], [[0.0, 0.0]], T[4:], [[1.0, 1.0]]])


@pytest.mark.parametrize("solver", [PolishSolver(), PolishSolver(start="random", starts=2),
                                    AmortisedSolver(grid=15, build_samples=1500, build_iter=6, cache=False,
                                                    polish_steps=2)],
                         ids=["polish", "polish-random", "amortised"])
def test_chunked_equals_unchunked(fx, model, solver):
    p = fx.make_problem(_mixed_targets(fx, model), model=model)
    whole = solver.solve(p, seed=5)
    if solver.name == "polish":   # the rescue round ran: a chunk boundary would show
        assert "retried" in whole[0].message
    for chunk in (1, 3, 4):
        part = solver.solve(p, seed=5, chunk_size=chunk)
        # the same answers up to rounding: the model's matrix products on a batch of another
        # size may round differently in the last bits (different starts would differ by far more)
        assert np.allclose(part.x, whole.x, rtol=1e-9, atol=1e-12), chunk
        assert np.allclose(part.error, whole.error, rtol=1e-6, atol=1e-12)
        assert np.array_equal(part.success, whole.success)
        assert [r.message.split(" [")[0] for r in part] == [r.message.split(" [")[0] for r in whole]


def test_chunks_bound_the_batch_a_solver_sees(fx, model, monkeypatch):
    seen = []
    orig = GASolver._solve

    def spy(self, problem, rng, trace):
        seen.append(problem.n_targets)
        return orig(self, problem, rng, trace)

    monkeypatch.setattr(GASolver, "_solve", spy)
    p = fx.make_problem(n=10, model=model)
    res = GASolver(generations=5).solve(p, seed=1, chunk_size=4)
    assert seen == [4, 4, 2] and len(res) == 10
    # every target still gets an honest result, and the population solver's answers are
    # as good chunked as whole (not identical: one random stream runs through the chunks)
    err, _ = fx.closed_loop(p, res.x)
    assert np.allclose(err, res.error)
    a = GASolver(generations=5).solve(p, seed=1, chunk_size=4)
    assert np.array_equal(a.x, res.x)                       # deterministic per seed and chunk size
    # the batch trace runs through the chunks: evaluations keep counting up
    nfev = [row["nfev"] for row in res.trace]
    assert np.all(np.diff(nfev) > 0) and nfev[-1] == res.nfev


@pytest.mark.parametrize("bad", [0, -3, True, 2.5, "8", 10 ** 9])
def test_chunk_size_is_validated(fx, model, bad):
    p = fx.make_problem(n=3, model=model)
    with pytest.raises(ValidationError) as ei:
        GASolver(generations=1).solve(p, seed=0, chunk_size=bad)
    assert ei.value.field == "chunk_size"


def test_batch_result_is_a_lazy_list(fx, model):
    p = fx.make_problem(n=6, model=model)
    res = PolishSolver().solve(p, seed=2)
    assert isinstance(res, list) and isinstance(res, BatchSolveResult) and len(res) == 6 and res
    items = list(res)
    assert all(isinstance(r, SolveResult) for r in items)
    assert np.array_equal(res.x, np.array([r.x for r in items]))
    assert np.array_equal(res.error, np.array([r.error for r in items]))
    assert np.array_equal(res.success, np.array([r.success for r in items]))
    assert res[-1].x_dict == items[5].x_dict and res[-6].targets == items[0].targets
    assert [r.error for r in res[1:4]] == [r.error for r in items[1:4]]
    assert [r.error for r in reversed(res)] == [r.error for r in items[::-1]]
    with pytest.raises(IndexError):
        res[6]
    # the per-target fields are those of the target (not of its neighbours)
    for i, r in enumerate(items):
        assert r.targets == dict(zip(p.dimensions, p.targets[i].tolist()))
        err, _ = fx.closed_loop(p.with_targets(p.targets[i]), r.x)
        assert err[0] == pytest.approx(r.error, abs=1e-12)
        assert len(r.trace) >= 1 and r.trace[-1]["best_error"] == pytest.approx(r.error, rel=1e-9, abs=1e-12)


def test_large_batches_keep_no_per_target_trace(fx, model, monkeypatch):
    monkeypatch.setattr(core, "PER_TARGET_TRACE_MAX", 4)
    res = PolishSolver().solve(fx.make_problem(n=5, model=model), seed=0)
    assert res[0].trace == [] and res.trace            # the batch trace stays
    small = PolishSolver().solve(fx.make_problem(n=4, model=model), seed=0)
    assert small[0].trace


@pytest.mark.parametrize("cls,opts,field", [
    (GASolver, {"generations": 10 ** 9}, "options.generations"),
    (GASolver, {"population": 10 ** 9}, "options.population"),
    (GASolver, {"stall_generations": 0}, "options.stall_generations"),
    (DESolver, {"generations": 10 ** 9}, "options.generations"),
    (DESolver, {"population": 10 ** 9}, "options.population"),
    (ScipyDESolver, {"maxiter": 10 ** 9}, "options.maxiter"),
    (PolishSolver, {"max_iter": 10 ** 9}, "options.max_iter"),
    (PolishSolver, {"starts": 10 ** 9}, "options.starts"),
    (PolishSolver, {"rescue_starts": -1}, "options.rescue_starts"),
    (GAPolishSolver, {"ga_options": {"generations": 10 ** 9}}, "options.generations"),
    (AmortisedSolver, {"polish_steps": 10 ** 9, "cache": False, "grid": 5, "build_samples": 200}, "options.polish_steps"),
    (AmortisedSolver, {"build_samples": 10 ** 12, "cache": False}, "options.build_samples"),
])
def test_size_options_have_upper_limits(fx, model, cls, opts, field):
    # with a 0.2 s budget where the solver has one: a missing limit fails the test instead
    # of running for ever
    if "time_budget_s" in cls.default_options:
        opts = {**opts, "time_budget_s": 0.2}
    with pytest.raises(ValidationError) as ei:
        cls(**opts).solve(fx.make_problem(n=2, model=model), seed=0)
    assert ei.value.field == field


def test_public_call_reuses_the_setup_but_not_the_targets(monkeypatch):
    from hapticsdk.errors import PluginError
    from hapticsdk.solvers import problems

    # an empty cache: other tests leave setups with the same dimensions behind
    monkeypatch.setattr(problems, "_PROBLEMS", {})
    monkeypatch.setattr(problems, "_SOLVERS", {})
    try:
        a = problems.solve({"hardness": 0.4, "roughness": 0.6}, method="amortised", seed=0,
                           options={"polish_steps": 0})
    except PluginError as exc:   # shipped model / dimensions not installed
        pytest.skip(str(exc))
    b = problems.solve({"hardness": 0.7, "roughness": 0.2}, method="amortised", seed=0,
                       options={"polish_steps": 0})
    key = next(k for k, v in problems._PROBLEMS.items() if v.dimensions == ("hardness", "roughness"))
    assert problems._PROBLEMS[key].targets.tolist() == [[0.4, 0.6]]   # b came from the cached setup
    c = problems.solve({"roughness": 0.2, "hardness": 0.7}, method="amortised", seed=0,
                       options={"polish_steps": 0})
    assert a.targets == {"hardness": 0.4, "roughness": 0.6}
    assert b.targets == {"hardness": 0.7, "roughness": 0.2} and list(c.targets) == ["roughness", "hardness"]
    # the same answer as a problem built from scratch, and an honest error
    fresh = problems.get_solver("amortised", polish_steps=0).solve(
        problems.build_problem({"hardness": 0.7, "roughness": 0.2}), seed=0)
    assert np.array_equal(fresh.x, b.x) and fresh.error == b.error
    # the other column order is another setup (its own table): equal to its own fresh solve
    fresh_c = problems.get_solver("amortised", polish_steps=0).solve(
        problems.build_problem({"roughness": 0.2, "hardness": 0.7}), seed=0)
    assert np.array_equal(fresh_c.x, c.x) and fresh_c.error == c.error
    with pytest.raises(ValidationError):
        problems.solve({"hardness": 1.5, "roughness": 0.2}, method="amortised")


def test_sample_cloud_nearest_is_exact():
    rng = np.random.default_rng(3)
    X = rng.random((300, 4))
    Y = rng.random((300, 2))
    cloud = SampleCloud(X, Y)
    T = rng.random((7, 2))
    got = cloud.nearest(T, 5, block=3)     # several blocks
    order = np.argsort(((Y[None] - T[:, None]) ** 2).sum(-1), axis=1)[:, :5]
    assert np.array_equal(got, X[order])
    assert cloud.nearest(T, 500).shape == (7, 300, 4)   # k capped at the cloud size


def test_sample_cloud_is_feasible_cached_and_seed_free(fx, model):
    p = fx.make_problem(n=3, model=model)
    cloud = sample_cloud(p)
    assert sample_cloud(fx.make_problem(n=5, model=model, seed=9)) is cloud   # same setup
    _, viol = fx.closed_loop(p.with_targets(cloud.Y), cloud.X)
    assert np.all(viol <= core.CONSTRAINT_TOL)
    assert np.allclose(model.predict(cloud.X), cloud.Y)
    # face / corner samples are in it, on lower and on upper bounds
    assert (cloud.X == fx.LOWER).any(axis=1).mean() > 0.1
    assert (cloud.X == fx.UPPER).any(axis=1).mean() > 0.1


def test_ga_nearest_init_starts_from_the_cloud(fx, model):
    p = fx.make_problem(n=5, model=model)
    res = GASolver(init="nearest", generations=0, target_error=0).solve(p, seed=0)
    near = sample_cloud(p).nearest(p.targets, 8)
    best = np.array([np.abs(model.predict(near[i]) - p.targets[i]).sum(1).min() for i in range(5)])
    # generation 0 already holds the nearest samples: its best is at least as good
    assert np.all(res.error <= best + 1e-12)
    with pytest.raises(ValidationError):
        GASolver(init="sobol").solve(p, seed=0)


def test_ga_stall_rule_ends_hopeless_targets(fx):
    from hapticsdk.perception.models import MLPModel
    base = fx.make_model()
    w = dict(base.weights, y_min=np.full(2, 0.1), y_max=np.full(2, 0.9))
    model = MLPModel(w, base.feature_names, base.dimension_names, feature_space=base.feature_space)
    p = fx.make_problem(np.array([[0.0, 0.0], [1.0, 1.0]]), model=model)   # unreachable
    full = GASolver(generations=60).solve(p, seed=0)
    stalled = GASolver(generations=60, stall_generations=4).solve(p, seed=0)
    assert full.nit == 60
    assert stalled.nit < 60 and "stalled for 4 generations" in stalled[0].message
    assert not stalled.success.any()


def test_polish_rescue_retries_missed_targets(fx, model):
    """One short random start per target leaves several targets outside the tolerance; the
    rescue round (new starts for those only) reaches more of them. (The first-round starts
    differ between the two runs: every random number of a target is drawn up front.)"""
    p = fx.make_problem(n=12, model=model, seed=4)
    kw = dict(start="random", starts=1, max_iter=2, target_error=0)
    first = PolishSolver(rescue_starts=0, **kw).solve(p, seed=3)
    rescued = PolishSolver(rescue_starts=8, **kw).solve(p, seed=3)
    missed = ~first.success
    assert missed.sum() >= 2
    assert rescued.success.sum() >= first.success.sum() + 2
    assert "retried from 8 new starts" in rescued[0].message


def test_polish_starts_include_the_nearest_samples(fx, model):
    p = fx.make_problem(n=8, model=model, seed=12)
    res = PolishSolver(starts=2, max_iter=0, rescue_starts=0, target_error=0).solve(p, seed=0)
    near = sample_cloud(p).nearest(p.targets, 1)[:, 0]
    err_near = np.array([fx.closed_loop(p.with_targets(p.targets[i]), near[i])[0][0] for i in range(8)])
    assert np.all(res.error <= err_near + 1e-12)      # no step taken: the best start is kept


def test_lookup_is_bilinear_interpolation(fx, model):
    S = AmortisedSolver(grid=9, build_samples=800, build_iter=4, cache=False)
    tab = S.table(fx.make_problem(n=2, model=model))
    X, g = tab.X, 8

    def bilinear(h, r):   # written out: the four corners of the cell, weights by distance
        fh, fr = min(max(h, 0.0), 1.0) * g, min(max(r, 0.0), 1.0) * g
        i, j = min(int(fh), g - 1), min(int(fr), g - 1)
        a, b = fh - i, fr - j
        return ((1 - a) * (1 - b) * X[i, j] + a * (1 - b) * X[i + 1, j]
                + (1 - a) * b * X[i, j + 1] + a * b * X[i + 1, j + 1])

    pts = [(0.0, 0.0), (1.0, 1.0), (1.0, 0.0), (0.0, 1.0), (-0.5, 2.0), (0.37, 0.81), (0.5, 0.125)]
    pts += [tuple(v) for v in np.random.default_rng(1).random((40, 2))]
    for h, r in pts:
        want = bilinear(h, r)
        assert np.allclose(tab.lookup((h, r)), want, rtol=1e-12, atol=1e-12)
        assert np.allclose(tab.lookup(np.array([h, r])), want, rtol=1e-12, atol=1e-12)
        assert np.allclose(tab.lookup(np.array([[h, r]]))[0], want, rtol=1e-12, atol=1e-12)
    many = tab.lookup(np.array(pts))
    assert np.allclose(many, [bilinear(*q) for q in pts], rtol=1e-12, atol=1e-12)
