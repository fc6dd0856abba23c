"""The warmth plugin in a mixed scene: composite model, solve, render, hooks."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hapticsdk.perception.models import CompositeModel
from hapticsdk.plugins import list_plugins
from hapticsdk.solvers.problems import build_problem, load_model
from hapticsdk.runtime.render import render_plan
from hapticsdk.compiler import compile_scene

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "warm-and-rough.json"


def test_plugins_are_listed_from_metadata():
    names = {(p["kind"], p["name"], p["distribution"]) for p in list_plugins()}
    assert ("dimension", "warmth", "hapticsdk-warmth") in names
    assert ("actuator", "peltier-virtual", "hapticsdk-warmth") in names
    assert ("model", "warmth", "hapticsdk-warmth") in names


def test_the_solver_works_on_the_union_of_both_models_features():
    p = build_problem({"hardness": 0.5, "roughness": 0.4, "warmth": 0.7})
    assert isinstance(p.model, CompositeModel)
    assert set(p.model.feature_names) == {"GS", "W", "Fpeak", "AFpeak", "P", "Tsurf", "Eff"}
    assert set(p.space.names) == set(p.model.feature_names)
    assert "warmth.skin-safe" in {c.name for c in p.constraints}


@pytest.fixture(scope="module")
def plan():
    return compile_scene(SCENE)


def test_mixed_scene_plan_meets_every_kept_target(plan):
    comp = CompositeModel([load_model("default"), load_model("warmth")])
    for mp in plan.materials.values():
        assert "warmth" in mp.dimensions and mp.actuators["thermal"] == "peltier-virtual"
        assert mp.actuator_options["thermal"] == {"tau_s": 0.3}
        allf = {**mp.features, **mp.pinned_features}
        pred = dict(zip(comp.dimension_names, comp.predict(np.array([[allf[n] for n in comp.feature_names]]))[0]))
        for d in mp.dimensions:
            assert abs(pred[d] - mp.targets[d]) <= 0.02, (mp.name, d, pred[d], mp.targets[d])
    dists = {p["distribution"] for p in plan.to_dict()["plugins_loaded"]}
    assert "hapticsdk-warmth" in dists


def test_render_holds_the_contact_temperature_and_calls_hooks(plan):
    from hapticsdk_warmth import hooks
    from hapticsdk_warmth.thermal import contact_temperature
    hooks.EVENTS.clear()
    name = "cold-rubber"
    rep = render_plan(plan, seconds=1.5, material=name)
    mp = plan.materials[name]
    tc = float(contact_temperature(mp.features["Tsurf"], mp.features["Eff"]))
    pel = rep.devices["peltier-virtual"]
    assert pel["target_c"] == pytest.approx(tc)
    assert abs(pel["temperature_c"] - tc) < 0.2, (pel, tc)
    assert rep.renderers["warmth"]["contact_ticks"] > 500
    assert hooks.EVENTS == [("started", name), ("finished", name)]
    assert rep.fault is None and "hapticsdk-warmth" in rep.hooks


def test_a_scene_without_warmth_never_imports_the_plugin():
    code = ("import sys, json\nfrom hapticsdk.scene import Scene\nfrom hapticsdk.compiler import compile_scene\n"
            "from hapticsdk.runtime.render import render_plan\n"
            "render_plan(compile_scene(Scene.for_material('S7')), seconds=0.2)\n"
            "print(json.dumps(sorted(m for m in sys.modules if m.startswith('hapticsdk_warmth'))))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []
