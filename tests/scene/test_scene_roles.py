"""Typed roles: a renderer declares the channel and the fields/units it commands on each
role, an actuator what it accepts; the compiler refuses a mismatch by name."""

from typing import ClassVar

import pytest

from hapticsdk.devices.actuators import Actuator, ActuatorLimits
from hapticsdk.compiler import compile_scene
from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer, PerceptionDimension, RoleSpec
from hapticsdk.errors import PluginError, ValidationError
from hapticsdk.perception.features import Feature
from hapticsdk.plugins import registry

pytest.importorskip("hapticsdk_hardness")
pytest.importorskip("hapticsdk_roughness")


class PlateVirtual(Actuator):
    """An electro-adhesion plate: friction channel, drive amplitude in V."""
    name = "plate-test"
    channel: ClassVar[str] = "friction"
    limits = ActuatorLimits(max_amplitude=200.0, amplitude_unit="V")
    simulated = True

    def _command(self, cmd):
        pass

    def _stop(self):
        pass


class LraVirtual(Actuator):
    """A narrow-band LRA: vibration channel, frequency in Hz, amplitude in V."""
    name = "lra-test"
    channel: ClassVar[str] = "vibration"
    accepts: ClassVar[dict[str, str]] = {"frequency_hz": "Hz", "amplitude": "V"}
    limits = ActuatorLimits(frequency_range_hz=(140.0, 260.0), max_amplitude=2.5, amplitude_unit="V")
    simulated = True

    def _command(self, cmd):
        pass

    def _stop(self):
        pass


class _StickyRenderer(DimensionRenderer):
    roles = ("friction",)

    def __init__(self, role="friction"):
        self.roles = (role,)
        self.role = role

    def tick(self, inp):
        return [ChannelCommand(self.role, amplitude=50.0 if inp.in_contact else 0.0)]


class Stickiness(PerceptionDimension):
    name = "stickiness-test"
    features = (Feature("stickiness-test.mu", "1", 0.0, 2.0),)
    default_actuators: ClassVar[dict[str, str]] = {"friction": "plate-test"}
    roles: ClassVar[dict[str, RoleSpec]] = {"friction": RoleSpec("friction", {"amplitude": "V"})}
    default_model = "stickiness-test"

    def renderer(self, features, **options):
        return _StickyRenderer(options.get("role", "friction"))


@pytest.fixture
def extra_plugins():
    acts, dims = registry("actuator"), registry("dimension")
    acts.register("plate-test", PlateVirtual)
    acts.register("lra-test", LraVirtual)
    dims.register("stickiness-test", Stickiness)
    yield
    acts.unregister("plate-test")
    acts.unregister("lra-test")
    dims.unregister("stickiness-test")


def _scene(material, devices):
    return {"name": "roles", "objects": [{"name": "o", "material": material}], "devices": devices,
            "settings": {"importance": {"enabled": False}}}


def test_roughness_on_the_plate_is_refused(extra_plugins):
    with pytest.raises(ValidationError) as ei:
        compile_scene(_scene({"name": "m", "intensities": {"roughness": 0.5}}, {"vibration": "plate-test"}))
    msg = str(ei.value)
    assert "'roughness'" in msg and "plate-test" in msg and "friction channel" in msg
    assert ei.value.field == "scene.devices.vibration"


def test_hardness_force_on_the_plate_is_refused(extra_plugins):
    with pytest.raises(ValidationError, match="force_n"):
        compile_scene(_scene({"name": "m", "intensities": {"hardness": 0.5}}, {"force": "plate-test"}))


def test_roughness_amplitude_in_volts_on_a_normalised_voice_coil_is_refused(extra_plugins):
    with pytest.raises(ValidationError, match=r"amplitude in '1', not 'V'"):
        compile_scene(_scene({"name": "m", "intensities": {"roughness": 0.5}}, {"vibration": "voicecoil-virtual"}))


def test_roughness_on_an_lra_in_volts_compiles_and_the_plan_shows_the_contract(extra_plugins):
    plan = compile_scene(_scene({"name": "m", "intensities": {"roughness": 0.5}}, {"vibration": "lra-test"}))
    c = plan.material("m").role_contracts["vibration"]
    assert c["actuator"] == "lra-test" and c["accepts"] == {"frequency_hz": "Hz", "amplitude": "V"}
    assert c["commanded_by"]["roughness"]["fields"] == {"frequency_hz": "Hz", "amplitude": "V"}


def test_stickiness_on_the_piezo_is_refused():
    # the test dimension has no perception model to solve with, so the contract check
    # compile_scene runs for every mapped role is called directly
    from hapticsdk.compiler.compile import _check_role
    with pytest.raises(ValidationError) as ei:
        _check_role("stickiness-test", "friction", Stickiness.roles["friction"], "piezo-virtual", {})
    assert "vibration channel" in str(ei.value) and "stickiness-test" in str(ei.value)
    contracts = {}
    registry("actuator").register("plate-test", PlateVirtual)
    try:
        _check_role("stickiness-test", "friction", Stickiness.roles["friction"], "plate-test", contracts)
    finally:
        registry("actuator").unregister("plate-test")
    assert contracts["friction"]["accepts"] == {"amplitude": "V"}   # derived from channel + limits


def test_a_renderer_commanding_an_undeclared_role_is_a_plugin_error(extra_plugins, monkeypatch):
    from hapticsdk_roughness.dimension import RoughnessDimension
    monkeypatch.setattr(RoughnessDimension, "roles", {"other": RoleSpec("vibration", {"amplitude": "V"})})
    with pytest.raises(PluginError, match="does not declare"):
        compile_scene(_scene({"name": "m", "intensities": {"roughness": 0.5}}, {}))


def test_role_spec_validates():
    with pytest.raises(ValidationError):
        RoleSpec("smell", {"amplitude": "1"})
    with pytest.raises(ValidationError):
        RoleSpec("force", {"torque": "N*m"})
    with pytest.raises(ValidationError):
        RoleSpec("force", {})


def test_first_party_dimensions_declare_every_role_their_renderers_use():
    from hapticsdk_hardness.dimension import HardnessDimension
    from hapticsdk_roughness.dimension import RoughnessDimension
    for dim, feats in ((HardnessDimension(), {"GS": 3.0, "W": 10.0}),
                       (RoughnessDimension(), {"Fpeak": 100.0, "AFpeak": 2.0, "P": 3.0})):
        r = dim.renderer(feats)
        assert set(r.roles) <= set(dim.roles), dim.name


def test_an_unsatisfiable_constraint_is_a_compile_error(monkeypatch):
    from hapticsdk_roughness.dimension import RoughnessDimension
    from kit_variants import never
    Never = never("roughness.never", "P")
    orig = RoughnessDimension.constraints
    monkeypatch.setattr(RoughnessDimension, "constraints", lambda self, **c: orig(self, **c) + [Never()])
    with pytest.raises(PluginError, match="roughness.never"):
        compile_scene(_scene({"name": "m", "intensities": {"roughness": 0.5}}, {}))
