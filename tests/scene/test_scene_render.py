"""render_plan: renderers from the plan, actuators opened/closed, hooks, lazy imports."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from typing import ClassVar

import numpy as np
import pytest

from hapticsdk.devices.actuators import Actuator, ActuatorLimits
from hapticsdk.errors import DeviceError, ValidationError
from hapticsdk.plugins import registry
from hapticsdk.runtime.render import render_plan
from hapticsdk.runtime.replacements import ConstantForceRenderer
from hapticsdk.compiler import compile_scene
from hapticsdk.scene import Scene
from hapticsdk.schemas_io import read_json
from hapticsdk.perception.dimensions import TickInput

needs_hardness = pytest.mark.skipif("hardness" not in registry("dimension"),
                                    reason="hapticsdk-hardness not installed")


def test_roughness_render_follows_formula_9():
    plan = compile_scene(Scene.for_material({"roughness": 0.5}))
    rep = render_plan(plan, seconds=1.2)
    assert rep.sensor == "probe-virtual"
    assert rep.actuators == {"vibration": "piezo-virtual"}
    assert rep.fault is None and rep.ticks == 1200
    log = rep.loop.log
    vx = np.abs(log["velocity_mm_s"][:, 0])
    amp = log["vibration.amplitude"]
    freq = log["vibration.frequency_hz"]
    active = (vx >= 20.0) & (log["penetration_mm"] > 0)
    assert active.sum() > 100
    fpeak = plan.material().features["Fpeak"]
    # frequency follows the sliding speed; amplitude is on only while sliding in contact
    np.testing.assert_allclose(freq[active], fpeak * vx[active] / 80.0, rtol=1e-9)
    assert np.all(amp[active] > 0) and np.all(amp[~active] == 0)
    d = rep.to_dict()
    json.dumps(d)
    assert d["tick"]["ticks"] == 1200 and d["material"] == "roughness 0.5"


def test_render_from_saved_plan_needs_no_solver(tmp_path, monkeypatch):
    plan = compile_scene(Scene.for_material({"roughness": 0.5}))
    path = plan.save(tmp_path / "p.json")
    import hapticsdk.solvers.problems as problems

    def boom(*a, **k):
        raise AssertionError("render must not solve")
    monkeypatch.setattr(problems, "solve", boom)
    monkeypatch.setattr(problems, "build_problem", boom)
    rep = render_plan(read_json(path, field="plan"), seconds=0.2)
    assert rep.features == plan.material().features


def test_constant_force_replacement():
    r = ConstantForceRenderer(1.0, replaces="hardness")
    on = TickInput(t=0, dt=1e-3, penetration_mm=0.5, velocity_mm_s=np.zeros(3), in_contact=True)
    off = TickInput(t=0, dt=1e-3, penetration_mm=-0.5, velocity_mm_s=np.zeros(3), in_contact=False)
    assert r.tick(on)[0].force_n == 1.0 and r.tick(off)[0].force_n == 0.0
    with pytest.raises(ValidationError):
        ConstantForceRenderer(float("nan"))


class _Failing(Actuator):
    """A vibration actuator whose transport fails after some commands."""

    name: ClassVar[str] = "failing-test"
    channel: ClassVar[str] = "vibration"
    limits = ActuatorLimits(frequency_range_hz=(1.0, 1000.0), max_amplitude=100.0, amplitude_unit="V")
    simulated: ClassVar[bool] = True
    instances: ClassVar[list] = []

    def __init__(self, *, fail_after: int = 50, **kw):
        super().__init__(**kw)
        self.fail_after = fail_after
        self.n = 0
        self.stopped = 0
        _Failing.instances.append(self)

    def _command(self, cmd):
        self.n += 1
        if self.n > self.fail_after:
            raise OSError("link lost")

    def _stop(self):
        self.stopped += 1


def test_every_actuator_is_stopped_and_closed_on_a_fault():
    reg = registry("actuator")
    reg.register("failing-test", _Failing)
    try:
        _Failing.instances.clear()
        scene = Scene.for_material({"roughness": 0.5},
                                   devices={"vibration": {"actuator": "failing-test",
                                                          "options": {"fail_after": 30}}})
        plan = compile_scene(scene)
        opened = []
        from hapticsdk.sim.probe import VirtualProbe
        orig = VirtualProbe.__enter__

        def spy(self):
            opened.append(self)
            return orig(self)
        VirtualProbe.__enter__ = spy
        from hapticsdk.hookspecs import hookimpl
        from hapticsdk.plugins import manager

        faults = []

        class Listener:
            @hookimpl
            def hapticsdk_device_fault(self, device, error):
                faults.append((device, str(error)))

        manager().register(Listener(), name="test-fault-listener")
        try:
            with pytest.raises(DeviceError, match="failing-test"):
                render_plan(plan, seconds=0.5)
        finally:
            VirtualProbe.__enter__ = orig
            manager().pm.unregister(name="test-fault-listener")
        assert len(faults) == 1 and "failing-test" in faults[0][0] + faults[0][1]
        assert "link lost" in faults[0][1]
        (act,) = _Failing.instances
        assert not act.is_open and act.stopped >= 1
        assert opened and not opened[0].is_open
    finally:
        reg.unregister("failing-test")


def test_render_rejects_bad_arguments():
    plan = compile_scene(Scene.for_material({"roughness": 0.5}))
    for bad in (0, -1, float("nan"), "x"):
        with pytest.raises(ValidationError):
            render_plan(plan, seconds=bad)
    with pytest.raises(ValidationError, match="no material"):
        render_plan(plan, seconds=0.1, material="nope")


SNIPPET = """
import json, sys
from hapticsdk.compiler import compile_scene
from hapticsdk.scene import Scene
from hapticsdk.runtime.render import render_plan
plan = compile_scene(Scene.for_material({TARGETS}))
after_compile = sorted(m for m in sys.modules if m.split('.')[0] in ('hapticsdk_roughness', 'hapticsdk_hardness', 'hapticsdk_warmth', 'serial', 'usb'))
rep = render_plan(plan, seconds=0.3)
after_render = sorted(m for m in sys.modules if m.split('.')[0] in ('hapticsdk_roughness', 'hapticsdk_hardness', 'hapticsdk_warmth', 'serial', 'usb'))
print(json.dumps({{"compile": after_compile, "render": after_render, "actuators": rep.actuators,
                   "plugins": [p["distribution"] for p in plan.to_dict()["plugins_loaded"]]}}))
"""


def _run(targets: str) -> dict:
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(SNIPPET.format(TARGETS=targets))],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@needs_hardness
def test_hardness_only_scene_imports_no_roughness_serial_or_usb():
    res = _run("{'hardness': 0.6}")
    for stage in ("compile", "render"):
        mods = res[stage]
        assert not [m for m in mods if m.split(".")[0] in ("hapticsdk_roughness", "hapticsdk_warmth", "serial", "usb")], (stage, mods)
    assert any(m.startswith("hapticsdk_hardness") for m in res["render"])
    assert "hapticsdk-roughness" not in res["plugins"]


def test_roughness_only_scene_imports_no_hardness_serial_or_usb():
    res = _run("{'roughness': 0.6}")
    for stage in ("compile", "render"):
        assert not [m for m in res[stage] if m.split(".")[0] in ("hapticsdk_hardness", "hapticsdk_warmth", "serial", "usb")], res
    assert res["actuators"] == {"vibration": "piezo-virtual"}
