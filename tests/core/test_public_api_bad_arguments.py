"""Every argument of the top-level entry points (``hapticsdk.render``, ``solve``,
``render_plan``, ``compile_scene``, ``load_*``, ``get_solver``, ``create_actuator``,
``Scene.for_material``), given each value of one table of bad values in turn, the others
valid: the outcome is a HapticSDKError or a clean result, never a raw TypeError /
ValueError / OverflowError (docs/safety.md, "Named errors").

Found by this table (each a raw error before): ``solve(bogus=1)`` (TypeError from
build_problem), ``solve(options={None: 1})`` ("keywords must be strings"),
``solve(..., dimensions=[[0.5, "x"]])`` (unhashable list), ``create_actuator(name,
gain=<2-D array>)`` (the plugin's own ValueError), ``load_scene("\\x00")`` and every
other file path with a NUL ("embedded null byte"), ``Scene.for_material("S7",
dimensions=<array>)`` (ambiguous truth value), ``render_plan(plan, material=[...])``
(unhashable).
"""

from __future__ import annotations

from decimal import Decimal

import numpy as np
import pytest

import hapticsdk as hs
from hapticsdk.errors import HapticSDKError

BAD = [float("nan"), float("inf"), -float("inf"), 10 ** 400, -1, 0, 1e308, True, None, "", "x" * 10000, "\x00",
       "a\x00b.json", "../../etc/passwd", [0.5], {"a": 1}, {"hardness": float("nan")}, {float("nan"): 0.5},
       {None: 0.5}, {"hardness": True}, {"hardness": 10 ** 400}, np.float32("nan"), np.array([np.nan]),
       np.array([[0.5, np.inf]]), [[0.5, "x"]], object(), b"bytes", 2 ** 63, -2 ** 63, 1j,
       # a 0-d array passes isinstance(x, Iterable) and fails to iterate; the decimal NaN
       # that raises on every comparison
       np.array(0.5), np.array("S7"), Decimal("sNaN"), Decimal("1e400")]


@pytest.fixture(scope="module")
def plan():
    return hs.compile_scene(hs.Scene.for_material("S7", solver={"method": "polish"}))


def _calls(plan):
    quick = {"method": "polish"}
    return {
        "render.material": lambda v: hs.render(v, seconds=0.01),
        "render.seconds": lambda v: hs.render("S7", seconds=v),
        "render.seed": lambda v: hs.render("S7", seconds=0.01, seed=v),
        "render.devices": lambda v: hs.render("S7", seconds=0.01, devices=v),
        "render.realtime": lambda v: hs.render("S7", seconds=0.01, realtime=v),
        "solve.targets": lambda v: hs.solve(v, **quick),
        "solve.method": lambda v: hs.solve({"hardness": 0.5}, method=v),
        "solve.seed": lambda v: hs.solve({"hardness": 0.5}, seed=v, **quick),
        "solve.options": lambda v: hs.solve({"hardness": 0.5}, options=v, **quick),
        "solve.tolerance": lambda v: hs.solve({"hardness": 0.5}, tolerance=v, **quick),
        "solve.fixed": lambda v: hs.solve({"hardness": 0.5}, fixed=v, **quick),
        "solve.dimensions": lambda v: hs.solve([0.5], dimensions=v, **quick),
        "build_problem.extra_constraints": lambda v: hs.build_problem({"hardness": 0.5}, extra_constraints=v),
        "solve.model": lambda v: hs.solve({"hardness": 0.5}, model=v, **quick),
        "solve.penalty_weight": lambda v: hs.solve({"hardness": 0.5}, penalty_weight=v, **quick),
        "solve.data_support": lambda v: hs.solve({"hardness": 0.5}, data_support=v, **quick),
        "solve.unknown_keyword": lambda v: hs.solve({"hardness": 0.5}, bogus=v, **quick),
        "load_model": hs.load_model,
        "load_dimension": hs.load_dimension,
        "get_solver": hs.get_solver,
        "get_solver.option": lambda v: hs.get_solver("polish", maxiter=v),
        "create_actuator": hs.create_actuator,
        "create_actuator.option": lambda v: hs.create_actuator("piezo-virtual", gain=v),
        "load_library": hs.load_library,
        "load_scene": hs.load_scene,
        "compile_scene": hs.compile_scene,
        "for_material.material": hs.Scene.for_material,
        "for_material.devices": lambda v: hs.Scene.for_material("S7", devices=v),
        "for_material.dimensions": lambda v: hs.Scene.for_material("S7", dimensions=v),
        "for_material.seed": lambda v: hs.Scene.for_material("S7", seed=v),
        "render_plan.plan": lambda v: hs.render_plan(v, seconds=0.01),
        "render_plan.seconds": lambda v: hs.render_plan(plan, seconds=v),
        "render_plan.material": lambda v: hs.render_plan(plan, seconds=0.01, material=v),
        "render_plan.period_s": lambda v: hs.render_plan(plan, seconds=0.01, period_s=v),
        "render_plan.actuator_options": lambda v: hs.render_plan(plan, seconds=0.01, actuator_options=v),
        "render_plan.actuator_option": lambda v: hs.render_plan(plan, seconds=0.01,
                                                                actuator_options={"vibration": {"gain": v}}),
        "render_plan.passivity": lambda v: hs.render_plan(plan, seconds=0.01, passivity=v),
        "render_plan.trajectory": lambda v: hs.render_plan(plan, seconds=0.01, trajectory=v),
        "render_plan.hooks": lambda v: hs.render_plan(plan, seconds=0.01, hooks=v),
        "render_plan.raise_on_fault": lambda v: hs.render_plan(plan, seconds=0.01, raise_on_fault=v),
    }


CALL_NAMES = list(_calls(None))


@pytest.mark.parametrize("call", CALL_NAMES)
def test_each_bad_value_is_a_named_error_or_a_clean_result(plan, call):
    fn = _calls(plan)[call]
    raw = []
    for value in BAD:
        try:
            fn(value)
        except HapticSDKError:
            pass
        except Exception as exc:   # noqa: BLE001 - the test is that none gets here
            raw.append(f"{value!r:.40}: {type(exc).__name__}: {exc}"[:200])
    assert not raw, "\n".join(raw)


@pytest.mark.parametrize("call, value, field", [
    ("solve.unknown_keyword", 1, "bogus"), ("solve.options", {None: 1}, "options"),
    ("solve.dimensions", [[0.5, "x"]], "dimensions[0]"), ("create_actuator.option", np.zeros((2, 2)), "options"),
    ("load_scene", "a\x00b.json", "scene"), ("render_plan.material", ["S7"], "material"),
    ("for_material.dimensions", np.array(["hardness"]), "scene.objects[0].dimensions")])
def test_the_cases_found_name_their_field(plan, call, value, field):
    with pytest.raises(HapticSDKError) as exc:
        _calls(plan)[call](value)
    assert getattr(exc.value, "field", None) == field
