"""A backend's own dead-man deadline defaults to the safety layer's restart gap, so an
output the switch cut comes back through the start gate and ramp, never as a step."""

import pytest

from hapticsdk.devices.safety import SafetyLayer, SafetySettings, default_command_timeout_s


def _backends():
    out = []
    try:
        from hapticsdk_hardness.audio import VoiceCoilAudio
        out.append(VoiceCoilAudio)
    except ImportError:
        pass
    try:
        from hapticsdk_hardness.openhaptics import OmniOpenHaptics
        out.append(OmniOpenHaptics)
    except ImportError:
        pass
    try:
        from hapticsdk_hardness.dhd import DhdDevice
        out.append(DhdDevice)
    except ImportError:
        pass
    return out


@pytest.mark.parametrize("gap", [0.02, 0.05, 0.3, 5.0])
def test_the_default_is_the_layers_restart_gap(gap):
    from hapticsdk.devices.actuators import ActuatorLimits
    layer = SafetyLayer(ActuatorLimits(max_force_n=1.0), settings=SafetySettings(restart_after_s=gap))
    assert default_command_timeout_s(layer) == min(gap, 1.0)
    assert default_command_timeout_s(None) == SafetySettings.restart_after_s


@pytest.mark.parametrize("cls", _backends(), ids=lambda c: c.name)
@pytest.mark.parametrize("gap", [0.02, 0.3])
def test_backends_take_it_and_an_explicit_value_wins(cls, gap):
    layer = SafetyLayer(cls.limits, settings=SafetySettings(restart_after_s=gap))
    assert cls(safety=layer).command_timeout_s == pytest.approx(gap)
    assert cls(safety=SafetyLayer(cls.limits), command_timeout_s=0.01).command_timeout_s == 0.01


@pytest.mark.parametrize("at_most", [1.0, 0.25])
def test_an_explicit_deadline_up_to_and_at_the_cap_is_taken(at_most):
    """An explicit ``command_timeout_s`` is any number in ``(0, at_most]`` (the cap itself
    included); 0, a negative value, one above the cap or one that is not a number is named."""
    from hapticsdk.devices.actuators import ActuatorLimits
    from hapticsdk.devices.safety import command_timeout_s
    from hapticsdk.errors import ValidationError
    layer = SafetyLayer(ActuatorLimits(max_force_n=1.0))
    assert command_timeout_s(layer, at_most, at_most=at_most) == at_most
    assert command_timeout_s(layer, at_most / 2, at_most=at_most) == at_most / 2
    assert command_timeout_s(layer, 5.0, at_most=None) == 5.0
    for bad in (0.0, -0.1, at_most * 1.5, "0.5", [0.5], True, float("nan")):
        with pytest.raises(ValidationError) as ei:
            command_timeout_s(layer, bad, at_most=at_most)
        assert ei.value.field == "options.command_timeout_s"
    for bad in (True, float("nan"), float("inf")):   # without a cap too: True is no 1 s deadline
        with pytest.raises(ValidationError):
            command_timeout_s(layer, bad, at_most=None)
