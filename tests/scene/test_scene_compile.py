"""Scene -> plan compilation: solving, leaving things out, serialisation, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.compiler.importance import PaperRegressionImportance, decide_drops, load_importance
from hapticsdk.plan import RenderPlan, validate_plan_dict
from hapticsdk.plugin_api import api_compatible, check_plugin_api
from hapticsdk.plugins import registry
from hapticsdk.compiler import compile_scene
from hapticsdk.scene import Scene

needs_hardness = pytest.mark.skipif("hardness" not in registry("dimension"),
                                    reason="hapticsdk-hardness not installed")


def _model():
    from hapticsdk.solvers.problems import load_model
    return load_model("default")


def _predict(plan_mat):
    """Run the perception model on the plan's solved + pinned features."""
    m = _model()
    allf = {**plan_mat.features, **plan_mat.pinned_features}
    G = np.array([[allf[n] for n in m.feature_names]])
    return dict(zip(m.dimension_names, m.predict(G)[0]))


def test_roughness_only_scene_solves_and_pins_unread_features():
    plan = compile_scene(Scene.for_material({"roughness": 0.45}))
    mp = plan.material()
    assert mp.dimensions == ["roughness"]
    assert set(mp.features) == {"Fpeak", "AFpeak", "P"}
    # (c) features no remaining dimension reads are not solved, they are pinned at defaults
    defaults = _model().metadata["feature_defaults"]
    assert set(mp.pinned_features) == {"GS", "W"}
    for k, v in mp.pinned_features.items():
        assert v == pytest.approx(defaults[k])
    # closed loop: the model at the planned features meets the target
    pred = _predict(mp)
    assert abs(pred["roughness"] - 0.45) <= plan.settings["solver"]["tolerance"] + 1e-9
    assert mp.solve["success"] is True
    assert mp.actuators == {"vibration": "piezo-virtual"}


def test_plan_round_trips_through_json_and_schema(tmp_path):
    plan = compile_scene(Scene.for_material({"roughness": 0.3}, seed=3))
    d = json.loads(plan.to_json())
    validate_plan_dict(d)
    path = plan.save(tmp_path / "plan.json")
    again = RenderPlan.load(path)
    assert again.to_dict() == plan.to_dict()
    assert again.settings["solver"]["seed"] == 3


def test_plan_schema_rejects_a_broken_plan():
    plan = compile_scene(Scene.for_material({"roughness": 0.3}))
    d = plan.to_dict()
    d["materials"][next(iter(d["materials"]))]["targets"]["roughness"] = 1.7
    with pytest.raises(ValidationError) as ei:
        RenderPlan.from_dict(d)
    assert "targets" in str(ei.value.field)
    d = plan.to_dict()
    d["plugin_api_version"] = "2.0"
    with pytest.raises(ValidationError, match="plugin API"):
        RenderPlan.from_dict(d)


def test_compile_is_deterministic_for_a_seed():
    a = compile_scene(Scene.for_material({"roughness": 0.6}, seed=7)).material().features
    b = compile_scene(Scene.for_material({"roughness": 0.6}, seed=7)).material().features
    assert a == b


@pytest.mark.parametrize("scene, field", [
    ({"objects": []}, "scene.objects"),
    ({"objects": [{"material": {"intensities": {"roughness": 1.5}}}]}, "scene.objects"),
    ({"objects": [{"material": "NO-SUCH-MATERIAL"}]}, "scene.objects[0].material"),
    ({"objects": [{"material": {"intensities": {"warmthiness": 0.5}}}]}, "materials"),
    ({"objects": [{"material": {"intensities": {"roughness": 0.5}}}],
      "devices": {"vibration": "no-such-actuator"}}, "scene.devices.vibration"),
    ({"objects": [{"name": "a", "material": {"intensities": {"roughness": 0.5}}},
                  {"name": "a", "material": {"intensities": {"roughness": 0.2}}}]}, "scene.objects"),
    ({"objects": [{"material": {"intensities": {"roughness": 0.5}}}],
      "settings": {"servo": {"period_s": 0}}}, "scene.settings.servo"),
])
def test_bad_scenes_raise_validation_errors_naming_the_field(scene, field):
    with pytest.raises(ValidationError) as ei:
        compile_scene(scene)
    assert str(ei.value.field).startswith(field), ei.value.field


def test_scene_file_round_trip(tmp_path):
    sc = Scene.for_material({"roughness": 0.5}, devices={"vibration": {"actuator": "piezo-virtual"}})
    p = tmp_path / "s.json"
    p.write_text(json.dumps(sc.to_dict()))
    again = Scene.load(p)
    assert again.to_dict() == sc.to_dict()
    assert again.devices["vibration"].actuator == "piezo-virtual"


# -- importance ------------------------------------------------------------------

def test_paper_regressions_match_tables_5_and_6():
    m = load_importance("paper")
    assert isinstance(m, PaperRegressionImportance)
    f = {"GS": np.array([0.1, 2.0, 4.5]), "Fpeak": np.array([200.0, 50.0, 120.0]),
         "AFpeak": np.array([0.5, 3.0, 2.0])}
    both = ["hardness", "roughness"]
    r = m.predict_loss("roughness", f, both)
    h = m.predict_loss("hardness", f, both)
    a_g = f["AFpeak"] / 9.80665  # the regressions take AFpeak in g (see the class docstring)
    np.testing.assert_allclose(r, 35.009 - 0.075 * f["GS"] - 0.232 * f["Fpeak"] + 15.966 * a_g)
    np.testing.assert_allclose(h, 3.804 + 8.168 * f["GS"] + 0.060 * f["Fpeak"] - 9.138 * a_g)
    # a smooth sample (high Fpeak, low AFpeak) needs roughness less than a rough one
    assert r[0] < r[1]
    # the regressions refer to hardness+roughness renderings only
    assert not m.judges("roughness", ["roughness"])
    assert m.replacement("hardness")["force_n"] == 1.0
    assert m.replacement("roughness") is None


def test_importance_rejects_bad_input():
    m = load_importance("paper")
    with pytest.raises(ValidationError, match="GS"):
        m.predict_loss("roughness", {"Fpeak": 1.0, "AFpeak": 1.0}, ["hardness", "roughness"])
    with pytest.raises(ValidationError):
        m.predict_loss("roughness", {"GS": np.nan, "Fpeak": 1.0, "AFpeak": 1.0}, ["hardness", "roughness"])
    with pytest.raises(ValidationError):
        m.predict_loss("roughness", {"GS": 1, "Fpeak": 1.0, "AFpeak": 1.0}, ["roughness"])


def test_decide_drops_is_the_threshold_rule():
    m = load_importance("paper")
    rng = np.random.default_rng(0)
    n = 200
    f = {"GS": rng.uniform(0.1, 4.5, n), "Fpeak": rng.uniform(20, 240, n), "AFpeak": rng.uniform(0, 4, n)}
    dims = ["hardness", "roughness"]
    thr = 15.0
    decided = decide_drops(m, dims, f, {}, thr)
    r = m.predict_loss("roughness", f, dims)
    h = m.predict_loss("hardness", f, dims)
    both_below = 0
    for i, drops in enumerate(decided):
        names = {d for d, _, _ in drops}
        assert len(names) <= 1  # the paper's regressions are single removals
        if r[i] < thr and h[i] < thr:  # both below: the one with the lower loss goes
            both_below += 1
            assert names == {"roughness" if r[i] < h[i] else "hardness"}
        else:
            assert ("roughness" in names) == (r[i] < thr)
            assert ("hardness" in names) == (h[i] < thr)
    assert both_below > 0  # the sample exercises the rule
    # per-dimension thresholds override the default
    decided = decide_drops(m, dims, f, {"roughness": -1e9}, thr)
    assert not any(d == "roughness" for drops in decided for d, _, _ in drops)


def test_plugin_api_versions():
    assert api_compatible(">=1.0,<2")
    assert not api_compatible(">=1.1", "1.0")
    assert api_compatible("==1.0", "1.0.0")
    assert not api_compatible("<1", "1.0")

    class Old:
        name = "old"
        hapticsdk_api = "<1"
    from hapticsdk.errors import PluginError
    with pytest.raises(PluginError, match="old"):
        check_plugin_api(Old)
    with pytest.raises(ValidationError):
        api_compatible("~1.0")
    assert api_compatible("~=1.0") and not api_compatible("==1.0")


# -- library materials (hardness + roughness) --------------------------------------

@needs_hardness
def test_library_plan_drops_exactly_when_the_whole_interval_is_below_the_threshold():
    from hapticsdk.perception.materials import load_library
    lib = load_library()
    names = lib.names()
    thr = 20.0
    scene = {"name": "library", "objects": [{"name": n, "material": n} for n in names],
             "settings": {"importance": {"threshold_percent": thr}}}
    plan = compile_scene(scene)
    n_r = n_h = n_straddle = 0
    for n in names:
        mp = plan.materials[n]
        rec = lib.get(n).features
        for dim in ("hardness", "roughness"):
            e = mp.importance[dim]
            basis = e["basis"]
            # judged on the material: its recorded features, and those moved onto its target
            assert [b["source"] for b in basis] == ["recorded", "recorded, solved onto the target"]
            assert basis[0]["features"] == {k: pytest.approx(rec[k]) for k in ("GS", "Fpeak", "AFpeak")}
            # the interval spans every point's interval; the decision is "whole interval below"
            lo = min(b["interval_percent"][0] for b in basis)
            hi = max(b["interval_percent"][1] for b in basis)
            assert e["interval_percent"] == [pytest.approx(lo), pytest.approx(hi)]
            assert (e["decision"] == "drop") == (hi < thr), (n, dim, hi)
            n_straddle += lo < thr <= hi
        dropped = {d.dimension: d for d in mp.dropped}
        drop_r = mp.importance["roughness"]["decision"] == "drop"
        drop_h = mp.importance["hardness"]["decision"] == "drop"
        if drop_r and drop_h:  # single removals only: the lower predicted loss is dropped
            lower = min(("roughness", "hardness"), key=lambda d: mp.importance[d]["median_percent"])
            assert set(dropped) == {lower}
        else:
            assert ("roughness" in dropped) == drop_r and ("hardness" in dropped) == drop_h
        assert mp.dimensions, n  # something is always rendered
        if "roughness" in dropped:
            n_r += 1
            d = dropped["roughness"]
            assert d.loss_interval_percent[1] < thr and "wholly below" in d.reason
            assert d.replacement is None
            assert "roughness" not in mp.dimensions and "vibration" not in mp.actuators
            assert not {"Fpeak", "AFpeak", "P"} & set(mp.features)
        if "hardness" in dropped:
            n_h += 1
            assert dropped["hardness"].replacement["force_n"] == 1.0
            assert mp.actuators.get("force")
            assert not {"GS", "W"} & set(mp.features)
        # what is kept is solved: the model meets the kept targets
        pred = _predict(mp)
        for d in mp.dimensions:
            assert abs(pred[d] - mp.targets[d]) <= 0.05, (n, d, pred[d], mp.targets[d])
    # the library spans every case at this threshold (else the test proves little)
    assert 0 < n_h < len(names) and 0 < n_r < len(names) and n_straddle > 0
    summary = plan.summary()
    for n in names:
        for d in summary["materials"][n]["dropped"]:
            assert set(d) >= {"dimension", "reason", "predicted_loss_percent"}


@needs_hardness
def test_solution_set_members_reach_the_target_and_satisfy_the_constraints():
    from hapticsdk.compiler.solution_set import solution_sets
    from hapticsdk.solvers.problems import build_problem
    T = np.array([[0.3, 0.3], [0.7, 0.5], [0.15, 0.45]])
    problem = build_problem(T, dimensions=["hardness", "roughness"], data_support=True)
    sets = solution_sets(problem)
    for i, sset in enumerate(sets):
        assert sset.reached and len(sset) >= 8
        G = problem.full_inputs(sset.X)
        pred = problem.model.predict(G)
        # the model's own prediction, recomputed here, is within the tolerance of the target
        assert np.all(np.abs(pred - T[i]).sum(axis=1) <= problem.tolerance + 1e-12)
        cols = problem.columns(G)
        for c in problem.constraints:
            assert np.all(c.violation(cols) <= 0.0), c.name
        # a family of solutions, not one point: the set spreads over the searched box
        spread = (sset.X.max(axis=0) - sset.X.min(axis=0)) / (problem.space.upper - problem.space.lower)
        assert spread.max() > 0.1


def test_negative_predicted_losses_are_clamped_and_flagged():
    from hapticsdk.compiler.importance import LossEstimate, decide_from_estimates, estimate_losses
    from hapticsdk.compiler.solution_set import SolutionSet

    class Linear(load_importance("paper").__class__):
        COEFFICIENTS = {"roughness": (0.0, 0.0, 1.0, 0.0), "hardness": (0.0, 1.0, 0.0, 0.0)}

    names = ("GS", "W", "Fpeak", "AFpeak", "P")
    X = np.zeros((5, 5))
    X[:, 2] = [-4.0, -2.0, 1.0, 3.0, 30.0]   # roughness loss = Fpeak (-4 .. 30 %)
    X[:, 0] = [5.0, 12.0, 15.0, 20.0, 25.0]  # hardness loss = GS: median 15 % above 10 %, p10 below
    sset = SolutionSet(X, names, np.zeros(5), 0.0, 5)
    (est,) = estimate_losses(Linear(), ["hardness", "roughness"], [sset], {}, 10.0)
    e = est["roughness"]
    assert e.median_percent == 1.0 and e.low_percent == 0.0      # -4 and -2 count as 0
    assert e.extrapolated_fraction == pytest.approx(0.4)
    assert e.p_below == pytest.approx(0.8) and e.drop and e.confidence == pytest.approx(0.8)
    h = est["hardness"]
    assert h.median_percent == 15.0 and h.low_percent < 10.0 and not h.drop   # the median decides
    assert h.confidence == pytest.approx(0.8)
    (drops,) = decide_from_estimates(Linear(), ["hardness", "roughness"], [est])
    assert [d.dimension for d in drops] == ["roughness"]
    assert isinstance(drops[0], LossEstimate)


def test_left_out_features_pinned_at_the_full_solve_when_the_defaults_miss_the_target():
    """S12 (hardest in the library) drops roughness; with the texture features at the
    model's medians its hardness target is out of reach, so the compiler pins them at the
    full solve's values. The kept target must then be reached, checked here by running the
    model on the plan's features ourselves."""
    from hapticsdk.compiler import compile_scene
    from hapticsdk.perception.materials import load_library
    from hapticsdk.solvers.problems import load_model

    plan = compile_scene({"schema_version": 1, "name": "s12", "objects": [{"name": "pad", "material": "S12"}],
                          "settings": {"solver": {"seed": 0}}})
    m = plan.materials["S12"]
    assert m.dimensions == ["hardness"] and [d.dimension for d in m.dropped] == ["roughness"]
    assert m.solve["success"] and m.solve.get("pinned_from") == "full solve"
    model = load_model("default")
    x = {**m.features, **m.pinned_features}
    pred = model.predict([[x[n] for n in model.feature_names]])[0]
    target = load_library().get("S12").intensities["hardness"]
    tol = 0.01  # the scene's default solve tolerance (schema default), in intensity units
    assert abs(pred[model.dimension_names.index("hardness")] - target) <= tol
    # the defaults alone do not reach it (else this test would not exercise the fallback)
    defaults = dict(model.metadata["feature_defaults"])
    assert any(abs(m.pinned_features[k] - defaults[k]) > 1e-9 for k in m.pinned_features)
