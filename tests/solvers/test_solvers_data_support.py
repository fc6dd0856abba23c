"""The data-support option: solutions stay where the model's recordings were."""

import numpy as np
import pytest

import hapticsdk as hs
from hapticsdk.solvers.problems import build_problem


def test_model_carries_the_recorded_press_force_range():
    model = hs.load_model("default")
    ctx = model.metadata["constraint_context"]
    lib = hs.load_library()
    forces = [np.sqrt(2 * m.features["GS"] * m.features["W"]) for m in lib]
    # the per-sample means lie inside the per-trial range the model file records
    assert ctx["press_force_min_n"] <= min(forces) <= max(forces) <= ctx["press_force_max_n"]


def test_constraint_only_when_asked():
    plain = build_problem({"hardness": 0.3, "roughness": 0.3})
    supported = build_problem({"hardness": 0.3, "roughness": 0.3}, data_support=True)
    assert "hardness.press_force" not in [c.name for c in plain.constraints]
    assert "hardness.press_force" in [c.name for c in supported.constraints]


@pytest.mark.parametrize("name", ["S7", "S12", "S20"])
def test_supported_solution_is_plausible_and_reaches_the_target(name):
    m = hs.load_library().get(name)
    res = hs.solve(dict(m.intensities), seed=0, data_support=True)
    assert res.success, res.message
    f_max = hs.load_model("default").metadata["constraint_context"]["press_force_max_n"]
    implied = np.sqrt(2 * res.x_dict["GS"] * res.x_dict["W"])
    assert implied <= f_max * (1 + 1e-9)
    assert implied >= 3.3 * (1 - 1e-9)          # formula (4) still holds
    model = hs.load_model("default")
    pred = model.predict([[res.x_dict[n] for n in model.feature_names]])[0]
    assert abs(pred - np.array([m.intensities[d] for d in model.dimension_names])).sum() <= 0.01
