"""Leave-out decisions judge the material (recorded features, and those solved onto the
target) with the importance model's own uncertainty, and nothing incidental enters:
solver seed, search-design size and start count."""

from __future__ import annotations

import numpy as np
import pytest

from hapticsdk.compiler import compile_scene
from hapticsdk.compiler.importance import (PaperRegressionImportance, _DRAWS, judge_material,
                                           load_importance)
from hapticsdk.plugins import registry

needs_hardness = pytest.mark.skipif("hardness" not in registry("dimension"),
                                    reason="hapticsdk-hardness not installed")

EVALUATED = ("S1", "S2", "S7", "S12", "S13", "S14", "S16", "S20")
BOTH = ["hardness", "roughness"]


def _library_scene(**settings_):
    from hapticsdk.perception.materials import load_library
    return {"name": "library", "objects": [{"name": n, "material": n} for n in load_library().names()],
            "settings": settings_}


def test_predictor_means_are_the_librarys_evaluated_samples():
    from hapticsdk.perception.materials import load_library
    lib = load_library()
    f = {k: np.mean([lib.get(s).features[k] for s in EVALUATED]) for k in ("GS", "Fpeak", "AFpeak")}
    gs, fp, af_g = PaperRegressionImportance.PREDICTOR_MEANS
    assert gs == pytest.approx(f["GS"], rel=1e-5) and fp == pytest.approx(f["Fpeak"], rel=1e-5)
    assert af_g == pytest.approx(f["AFpeak"] / 9.80665, rel=1e-5)


@pytest.mark.parametrize("dim", BOTH)
def test_bootstrap_is_the_stated_sampling_distribution_and_deterministic(dim, monkeypatch):
    """A linear function of multivariate-t coefficients is t (same df) with scale
    sqrt(x' S x); S built here from the table (slopes independent with the tabled SEs, the
    intercept through the predictor means). The draws' 10/90 % points must sit on that
    t interval within their Monte Carlo error."""
    from scipy import stats
    m = PaperRegressionImportance()
    B = np.array(m.COEFFICIENTS[dim])
    SE = np.array(m.STANDARD_ERRORS[dim])
    xbar = np.array(m.PREDICTOR_MEANS)
    S = np.zeros((4, 4))
    S[1:, 1:] = np.diag(SE[1:] ** 2)
    S[0, 1:] = S[1:, 0] = -xbar * SE[1:] ** 2
    S[0, 0] = SE[0] ** 2
    # the intercept's variance is the table's
    C = m.coefficient_draws(dim)
    df = 4
    assert np.std(C[:, 0]) == pytest.approx(SE[0] * np.sqrt(df / (df - 2)), rel=0.08)
    for gs, fp, af in [(0.1, 54.0, 0.9), (4.5, 191.0, 1.1), (1.8, 110.0, 2.3)]:
        x = np.array([1.0, gs, fp, af / 9.80665])
        draws = m.loss_draws(dim, {"GS": gs, "Fpeak": fp, "AFpeak": af}, BOTH)[:, 0]
        scale = float(np.sqrt(x @ S @ x))
        t90 = stats.t.ppf(0.9, df)
        lo, hi = np.percentile(draws, [10, 90])
        # MC error of a 10/90 % point from 4000 draws: sqrt(.09/4000)/pdf_t(1.53) ~ 0.04 scale
        assert lo == pytest.approx(x @ B - t90 * scale, abs=0.15 * scale)
        assert hi == pytest.approx(x @ B + t90 * scale, abs=0.15 * scale)
    # deterministic: recomputed from scratch, the same draws
    monkeypatch.setattr("hapticsdk.compiler.importance._DRAWS", {})
    np.testing.assert_array_equal(PaperRegressionImportance().coefficient_draws(dim), C)
    assert _DRAWS is not None


@pytest.mark.parametrize("case", range(80))
def test_judge_drops_only_below_the_whole_interval_and_is_monotone_in_the_threshold(case):
    # random cells over the features' physical ranges and thresholds (seeded per case)
    rng = np.random.default_rng(case)
    gs, fp, af = rng.uniform(0.05, 5.0), rng.uniform(20.0, 240.0), rng.uniform(0.1, 5.0)
    thr, more = rng.uniform(0.0, 60.0), rng.uniform(0.0, 30.0)
    m = load_importance("paper")
    pts = [("recorded", {"GS": gs, "Fpeak": fp, "AFpeak": af}),
           ("solved", {"GS": gs * 1.3, "Fpeak": fp * 0.8, "AFpeak": af})]
    est = judge_material(m, BOTH, pts, {}, thr)
    est2 = judge_material(m, BOTH, pts, {}, thr + more)
    rev = judge_material(m, BOTH, pts[::-1], {}, thr)
    for d, e in est.items():
        assert e.drop == (e.high_percent < thr)
        assert e.low_percent <= e.median_percent <= e.high_percent
        assert not (e.drop and not est2[d].drop)          # a higher threshold never keeps more
        assert e.straddles == (e.low_percent < thr <= e.high_percent)
        assert (rev[d].low_percent, rev[d].high_percent, rev[d].drop) == (e.low_percent, e.high_percent, e.drop)
        one = judge_material(m, BOTH, pts[:1], {}, thr)[d]
        assert one.high_percent <= e.high_percent and one.low_percent >= e.low_percent   # more points, wider


@needs_hardness
def test_library_points_do_not_read_the_solve():
    """For a library material the points are its recorded features and their projection:
    the compile's solved features (which follow the solver seed) are not read."""
    from hapticsdk.compiler.leave_out import material_points
    from hapticsdk.perception.materials import load_library
    from hapticsdk.solvers.problems import build_problem
    lib = load_library()
    mat = lib.get("S16")
    p = build_problem(np.array([[mat.intensities[d] for d in BOTH]]), dimensions=BOTH, data_support=True)
    a = material_points(p, 0, mat.features, {"GS": 1.0, "Fpeak": 190.0, "AFpeak": 1.0})
    b = material_points(p, 0, mat.features, {"GS": 4.0, "Fpeak": 40.0, "AFpeak": 4.0})
    assert a == b and [s for s, _ in a] == ["recorded", "recorded, solved onto the target"]
    # the projection reaches the target (the model, run here) and stays near the material
    model = p.model
    x = a[1][1]
    pred = model.predict(np.array([[x[n] for n in model.feature_names]]))[0]
    assert np.abs(pred - p.targets[0]).sum() <= p.tolerance
    assert abs(x["Fpeak"] - mat.features["Fpeak"]) < 30.0     # S16 at 79 Hz, not at the family's 190
    # without recorded features the solved ones are judged (what is rendered)
    c = material_points(p, 0, None, {"GS": 1.0, "Fpeak": 190.0, "AFpeak": 1.0})
    assert [s for s, _ in c] == ["solved"]


@needs_hardness
def test_library_decisions_do_not_depend_on_seed_design_size_or_starts(monkeypatch):
    """All 23 library materials: solver seeds 0-7, and the solution-set design's size
    (8k-64k) and start count (24-192), should anything use it, give the same estimates."""
    from hapticsdk.compiler import solution_set as ss
    base = compile_scene(_library_scene())
    ref = {n: mp.importance for n, mp in base.materials.items()}
    ref_drops = {n: [d.dimension for d in mp.dropped] for n, mp in base.materials.items()}
    for seed in range(1, 8):
        plan = compile_scene(_library_scene(solver={"seed": seed}))
        assert {n: mp.importance for n, mp in plan.materials.items()} == ref, seed
        assert {n: [d.dimension for d in mp.dropped] for n, mp in plan.materials.items()} == ref_drops
    orig = ss.solution_sets
    for n_design, n_start in ((8192, 24), (65536, 192)):
        monkeypatch.setattr(ss, "solution_sets",
                            lambda problem, _o=orig, _d=n_design, _s=n_start, **kw: _o(problem, n_design=_d,
                                                                                      n_start=_s))
        plan = compile_scene(_library_scene())
        assert {n: mp.importance for n, mp in plan.materials.items()} == ref, (n_design, n_start)
    # the rule does something at the default threshold: some materials lose a dimension
    assert 0 < sum(bool(v) for v in ref_drops.values()) < len(ref_drops)


@needs_hardness
def test_a_straddling_interval_keeps_the_dimension_and_the_plan_says_so():
    from hapticsdk.cli.scene import format_plan
    plan = compile_scene({"name": "s13", "objects": [{"material": "S13"}]})
    e = plan.materials["S13"].importance["roughness"]
    lo, hi = e["interval_percent"]
    assert lo < e["threshold_percent"] <= hi and e["decision"] == "keep"   # S13's roughness straddles 10 %
    assert "roughness" in plan.materials["S13"].dimensions
    text = format_plan(plan.summary())
    assert f"{lo:.1f}-{hi:.1f} %" in text and "straddles" in text


@needs_hardness
def test_a_library_material_with_changed_intensities_is_judged_at_its_solve_not_its_recording():
    """The recorded features describe the library's intensities: a scene that changes them
    judges the solved features (what renders), and the unchanged material its recording."""
    plan = compile_scene({"name": "s", "objects": [{"name": "a", "material": "S16"},
                                                   {"name": "b", "material": "S16", "intensities": {"roughness": 0.9}}]})
    (same,) = [mp for n, mp in plan.materials.items() if n == "S16"]
    (changed,) = [mp for n, mp in plan.materials.items() if n != "S16"]
    for mp, sources in ((same, ["recorded", "recorded, solved onto the target"]), (changed, ["solved"])):
        for e in mp.importance.values():
            assert [b["source"] for b in e["basis"]] == sources, mp.name
