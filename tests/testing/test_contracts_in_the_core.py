"""The contracts of plugin API 1.2 where the core (not the kit) enforces them: the render
report faults an actuator left driving, a 1.0-style dimension's roles are typed from its
default actuators, a renderer's fields are checked at compile time, device constraints are
reported as binding within a tolerance stated in the result, unit strings are parsed."""

from __future__ import annotations

from types import SimpleNamespace
from typing import ClassVar

import numpy as np
import pytest

from hapticsdk.perception.dimensions import ChannelCommand, Constraint, RoleSpec, declared_roles
from hapticsdk.errors import PluginError, ValidationError
from hapticsdk.plugins import registry
from hapticsdk.units import is_force_unit, parse_unit, same_unit

needs_roughness = pytest.mark.skipif("piezo-virtual" not in registry("actuator"),
                                     reason="hapticsdk-roughness not installed")


# -- render: an actuator left driving is a fault -------------------------------------

@pytest.fixture
def stuck_piezo():
    from hapticsdk_roughness.virtual import PiezoVirtual

    class StuckPiezo(PiezoVirtual):
        """stop() does nothing: the chip keeps its last drive."""
        name: ClassVar[str] = "kit-stuck-piezo"

        def _stop(self) -> None:
            pass
    registry("actuator").register("kit-stuck-piezo", StuckPiezo)
    yield "kit-stuck-piezo"
    registry("actuator").unregister("kit-stuck-piezo")


@needs_roughness
def test_a_piezo_whose_stop_does_nothing_ends_the_render_with_a_fault(stuck_piezo):
    from hapticsdk.compiler import compile_scene
    from hapticsdk.runtime.render import render_plan
    from hapticsdk.scene import Scene
    # the default trajectory presses, slides and releases: end the run mid-slide
    plan = compile_scene(Scene.for_material({"roughness": 0.8}, devices={"vibration": stuck_piezo}))
    rep = render_plan(plan, seconds=1.0)
    assert rep.fault is not None, "an actuator left driving must be reported"
    assert rep.fault["device"] == stuck_piezo and "left driving" in rep.fault["message"]
    assert " V" in rep.fault["message"]
    good = render_plan(compile_scene(Scene.for_material({"roughness": 0.8})), seconds=1.0)
    assert good.fault is None


@needs_roughness
def test_a_reported_output_within_one_step_of_rest_passes_the_kit_and_ends_the_render_clean():
    """The kit and the render's final check judge rest by one rule: a measured output may
    lie one declared step off (the write's and the reading's quantisation). A reading
    0.7 step above rest conforms, so it must not end every render with a fault."""
    from hapticsdk.compiler import compile_scene
    from hapticsdk.runtime.render import render_plan
    from hapticsdk.scene import Scene
    from hapticsdk.testing import check_actuator
    from hapticsdk_roughness.virtual import PiezoVirtual, piezo_limits

    class ReadingPiezo(PiezoVirtual):
        """Reports its measured output: the synthesised amplitude (ramped, advanced by
        step()), read 0.7 of its declared step high."""
        hapticsdk_api = ">=1.2,<2"
        name: ClassVar[str] = "kit-reading-piezo"
        readback_source: ClassVar[str] = "output"

        def __init__(self, **kw):
            super().__init__(**kw)
            self.limits = piezo_limits(self.gain, None, quantised=True)

        def _read_back(self):
            rb = super()._read_back()
            return ChannelCommand("vibration", frequency_hz=rb.frequency_hz,
                                  amplitude=self.osc.amplitude + 0.7 * self.limits.amplitude_resolution)
    registry("actuator").register("kit-reading-piezo", ReadingPiezo)
    try:
        assert check_actuator(ReadingPiezo) == []
        rep = render_plan(compile_scene(Scene.for_material({"roughness": 0.8},
                                                           devices={"vibration": "kit-reading-piezo"})),
                          seconds=0.5)
        assert rep.fault is None, rep.fault
    finally:
        registry("actuator").unregister("kit-reading-piezo")


# -- typed roles for every dimension --------------------------------------------------

@needs_roughness
def test_a_1_0_style_dimension_gets_typed_roles_from_its_default_actuator(monkeypatch):
    from hapticsdk_roughness.dimension import RoughnessDimension
    monkeypatch.setattr(RoughnessDimension, "roles", {})
    roles = declared_roles(RoughnessDimension())
    assert {r: (s.channel, s.fields) for r, s in roles.items()} == \
        {"vibration": ("vibration", {"frequency_hz": "Hz", "amplitude": "V"})}
    assert "piezo-virtual" in roles["vibration"].description


@needs_roughness
def test_a_1_0_style_dimension_on_an_actuator_of_another_unit_is_refused(monkeypatch):
    if "voicecoil-virtual" not in registry("actuator"):
        pytest.skip("hapticsdk-hardness not installed")
    from hapticsdk.compiler import compile_scene
    from hapticsdk.scene import Scene
    from hapticsdk_roughness.dimension import RoughnessDimension
    monkeypatch.setattr(RoughnessDimension, "roles", {})
    with pytest.raises(ValidationError, match="amplitude"):
        compile_scene(Scene.for_material({"roughness": 0.5}, devices={"vibration": "voicecoil-virtual"}))
    compile_scene(Scene.for_material({"roughness": 0.5}))      # its own default still compiles


@needs_roughness
def test_a_renderer_sending_an_undeclared_field_is_refused_at_compile_time(monkeypatch):
    from hapticsdk.compiler import compile_scene
    from hapticsdk.scene import Scene
    from hapticsdk_roughness.dimension import RoughnessRenderer
    tick = RoughnessRenderer.tick

    def with_force(self, inp):
        return [ChannelCommand(c.role, force_n=1.0, frequency_hz=c.frequency_hz, amplitude=c.amplitude)
                for c in tick(self, inp)]
    monkeypatch.setattr(RoughnessRenderer, "tick", with_force)
    with pytest.raises(PluginError, match="force_n"):
        compile_scene(Scene.for_material({"roughness": 0.5}))


# -- binding within a stated tolerance -------------------------------------------------

class _Plate(Constraint):
    """The plate's largest friction force bounds the feature: 0.45 N >= F."""
    name = "plate.max-force"
    features = ("F",)

    def _bound_and_value(self, cols):
        f = np.asarray(cols["F"], float)
        return f, np.full_like(f, 0.45)     # 0.45 >= F


def _summary(F, target, pred, tolerance=0.01):
    from hapticsdk.compiler.compile import _device_summary
    r = SimpleNamespace(x_dict={"F": F}, intensities={"stick": pred})
    return _device_summary(r, {"stick": target}, ["stick"], {}, {}, {"stick": [_Plate()]}, tolerance=tolerance)


def test_a_bound_1_percent_away_binds_and_the_tolerance_is_stated():
    s = _summary(0.45 / 1.01, target=0.8, pred=0.8)           # 1 % slack, target met
    assert s["binding"] == ["plate.max-force"] and s["binding_rtol"] == 0.01
    assert _summary(0.40, target=0.8, pred=0.8)["binding"] == []           # 12 % slack, met
    # the target is missed: the device constraint with the least slack held the answer back
    assert _summary(0.45 / 1.03, target=0.8, pred=0.7)["binding"] == ["plate.max-force"]
    assert _summary(0.45 / 1.03, target=0.8, pred=0.7, tolerance=0.02)["binding_rtol"] == 0.02


def test_plan_text_shows_a_plate_limit_without_a_band():
    from hapticsdk.cli.scene import _limits_text
    assert _limits_text({"frequency_range_hz": None, "max_drive": 0.45, "drive_unit": "N"}) == "drive up to 0.45 N"
    assert _limits_text({"frequency_range_hz": [10.0, 400.0], "max_drive": 50.0, "drive_unit": "V"}) == \
        "10-400 Hz, drive up to 50 V"
    assert _limits_text({"frequency_range_hz": None, "max_drive": None}) == ""


# -- units ------------------------------------------------------------------------------

@pytest.mark.parametrize("a, b, same", [
    ("newton", "N", True), ("N / mm", "N/mm", True), ("N/mm", "N/m", False), ("N/mm", "kN/m", True),
    ("newtons per millimetre", "N/mm", True), ("m/s^2", "m s**-2", True), ("m/s2", "m/s^2", True),
    ("Hz", "1/s", True), ("ms", "s", False), ("degC", "°C", True), ("degC", "K", False), ("", "1", True),
    ("dimensionless", "1", True), ("V", "1", False), ("mm", "millimeter", True), ("furlong", "furlong", True),
    ("furlong", "N", False),
])
def test_unit_strings_are_parsed(a, b, same):
    assert same_unit(a, b) is same and same_unit(b, a) is same


@pytest.mark.parametrize("a, b, same", [
    ("kN^999", "N", False), ("kN^999", "kN^999", True), ("mm^999", "um^999", False),
    ("m^99999999999999999999", "m", False), ("mm^-200", "m^-200", False),
])
def test_extreme_powers_are_a_stable_answer_not_an_overflow(a, b, same):
    # a unit string comes from a plugin or a model file: a power no float can scale is
    # compared as text (kN^999 overflowed; mm^999 and um^999 both became scale 0)
    assert same_unit(a, b) is same and same_unit(b, a) is same


def test_force_units():
    assert is_force_unit("N") and is_force_unit("newton") and is_force_unit("mN") and is_force_unit("kg m/s^2")
    assert not is_force_unit("N/mm") and not is_force_unit("V") and parse_unit("zorg") is None
