"""hapticsdk-hardness against the hapticsdk conformance kit."""

from __future__ import annotations

from hapticsdk.testing import ActuatorConformance, DeviceConformance, DimensionConformance


class TestHardnessDimension(DimensionConformance):
    plugin_name = "hardness"


class TestOmniVirtual(DeviceConformance):
    plugin_name = "omni-virtual"


class TestVoiceCoilVirtual(ActuatorConformance):
    plugin_name = "voicecoil-virtual"


class TestOmni3Virtual(DeviceConformance):
    plugin_name = "omni3-virtual"
