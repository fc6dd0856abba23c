"""Device-aware solving: the same roughness target solved per mapped actuator, within
what that actuator can produce, with the remaining perceptual residual in the plan."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("hapticsdk_roughness")

from hapticsdk.compiler import compile_scene  # noqa: E402
from hapticsdk.plugins import registry  # noqa: E402
from hapticsdk.solvers.problems import load_model  # noqa: E402
from hapticsdk.runtime.render import render_plan  # noqa: E402

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "lra_device_aware.py"


@pytest.fixture(scope="module")
def lra():
    spec = importlib.util.spec_from_file_location("lra_device_aware", EXAMPLE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    registry("actuator").register("lra-virtual", mod.LraVirtual)
    yield mod
    registry("actuator").unregister("lra-virtual")


def _plan(actuator, r, **devopts):
    dev = {"actuator": actuator, "options": devopts} if devopts else actuator
    return compile_scene({"name": "x", "objects": [{"name": "o", "material": {"name": "m",
                                                                              "intensities": {"roughness": r}}}],
                          "devices": {"vibration": dev}, "settings": {"importance": {"enabled": False}}})


def _predicted(mp):
    m = load_model("default")
    G = np.array([[{**mp.features, **mp.pinned_features}[n] for n in m.feature_names]])
    return float(m.predict(G)[0, list(m.dimension_names).index("roughness")])


#: a roughness the piezo reaches and the LRA (140..260 Hz, 2.5 V) does not, with the
#: default model: it needs a coarse texture (low Fpeak), below the LRA's band
TARGET = 0.75


def test_the_lra_solve_stays_in_its_band_and_states_the_residual(lra):
    mp = _plan("lra-virtual", TARGET).material()
    lo, hi = lra.BAND_HZ
    assert lo - 1e-6 <= mp.features["Fpeak"] <= hi + 1e-6
    # what the LRA reaches at Fpeak with 2.5 V, from its own table
    assert mp.features["AFpeak"] <= lra.lra_table().acceleration_at(mp.features["Fpeak"], lra.MAX_V) * (1 + 1e-6)
    pred = _predicted(mp)   # the model's prediction of what will be rendered, recomputed here
    assert mp.device["predicted"]["roughness"] == pytest.approx(pred, abs=1e-9)
    assert mp.device["residual"]["roughness"] == pytest.approx(TARGET - pred, abs=1e-9)
    assert mp.device["residual"]["roughness"] > 0.01            # the LRA cannot reach TARGET
    assert mp.device["binding"]


def test_the_piezo_reaches_the_same_target_with_other_features(lra):
    piezo, lra_mp = _plan("piezo-virtual", TARGET).material(), _plan("lra-virtual", TARGET).material()
    assert abs(piezo.device["residual"]["roughness"]) <= 0.01
    assert abs(piezo.features["Fpeak"] - lra_mp.features["Fpeak"]) > 10.0


def test_a_smaller_piezo_gain_binds_the_amplitude(lra):
    from hapticsdk_roughness.table import resolve_table
    mp = _plan("piezo-virtual", 0.8, gain=0).material()       # 25 V full scale
    a_max = resolve_table(None).acceleration_at(mp.features["Fpeak"], 25.0)
    assert mp.features["AFpeak"] <= a_max * (1 + 1e-6)
    assert "roughness.device-amplitude" in mp.device["binding"]
    assert mp.device["capabilities"]["roughness"]["vibration"]["max_drive"] == 25.0


def test_each_described_device_constraint_is_met_with_its_value_above_its_bound(lra):
    """``device["constraints"]``: every device constraint the solved features meet reads
    ``value >= bound`` (the constraint's own direction), with the relative slack of that
    pair; one that does not bind has a clear margin (bound and value swapped would read as
    violated)."""
    mp = _plan("lra-virtual", TARGET).material()
    described = [c for c in mp.device["constraints"] if "bound" in c]
    assert described
    for c in described:
        assert c["value"] >= c["bound"] - 1e-9 * max(abs(c["bound"]), 1.0), c
        assert c["relative_slack"] == pytest.approx(
            (c["value"] - c["bound"]) / max(abs(c["bound"]), abs(c["value"]), 1e-12), rel=1e-12, abs=1e-15)
    assert max(c["relative_slack"] for c in described) > 0.01


def test_rendering_on_the_lra_uses_its_own_table_and_band(lra):
    plan = _plan("lra-virtual", TARGET)
    mp = plan.material()
    rep = render_plan(plan, seconds=1.0)
    r = rep.renderers["roughness"]
    v_expected, _ = lra.lra_table().voltage_for(mp.features["Fpeak"], mp.features["AFpeak"])
    assert r["v_out_v"] == pytest.approx(v_expected, rel=1e-6)
    assert "LRA" in r["table_source"]
    f = rep.loop.log["vibration.frequency_hz"]
    a = rep.loop.log["vibration.amplitude"]
    played = f[a > 0]
    assert played.size and played.min() >= lra.BAND_HZ[0] - 1e-9 and played.max() <= lra.BAND_HZ[1] + 1e-9


def test_the_example_runs(capsys, lra):
    assert lra.main(["--roughness", str(TARGET), "--seconds", "0.3"]) == 0
    out = capsys.readouterr().out
    assert "piezo-virtual" in out and "lra-virtual" in out and "residual" in out and "GENERATED" in out


def test_the_solution_family_follows_the_device_band_not_the_constraints_name():
    """Two problems whose device bands differ only in their bound: each family respects
    its own band (the design's feasibility is cached per constraint parameters)."""
    from hapticsdk.compiler.solution_set import solution_sets
    from hapticsdk.solvers.problems import build_problem
    from hapticsdk_roughness.dimension import DeviceBandConstraint
    for lo in (60.0, 150.0, 60.0, 150.0):
        # reachable targets and an unreachable one (whose set is the nearest feasible design points)
        p = build_problem(np.array([[0.3, 0.3], [0.05, 0.98]]), dimensions=["hardness", "roughness"],
                          data_support=True, extra_constraints=(DeviceBandConstraint(lo, "low", "test"),))
        for s in solution_sets(p):
            assert len(s) and s.X[:, list(s.names).index("Fpeak")].min() >= lo - 1e-6, (lo, s.reached)

