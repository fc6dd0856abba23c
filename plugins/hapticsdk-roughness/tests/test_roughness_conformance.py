"""hapticsdk-roughness against the hapticsdk conformance kit."""

from __future__ import annotations

from hapticsdk.testing import ActuatorConformance, DimensionConformance, check


class TestRoughnessDimension(DimensionConformance):
    plugin_name = "roughness"


class TestPiezoVirtual(ActuatorConformance):
    plugin_name = "piezo-virtual"


def test_hardware_backends_declare_limits_and_reject_unknown_options():
    # real backends need a port / USB device: check what can be checked without hardware
    for name in ("piezo-serial", "piezo-mcp2221"):
        assert check("actuator", name, rules=["limits-declared", "options"]) == []
