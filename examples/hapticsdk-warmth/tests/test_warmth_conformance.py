"""The example plugin passes the hapticsdk conformance kit."""

from __future__ import annotations

from hapticsdk.testing import ActuatorConformance, DimensionConformance, ModelConformance


class TestWarmthDimension(DimensionConformance):
    plugin_name = "warmth"


class TestPeltierVirtual(ActuatorConformance):
    plugin_name = "peltier-virtual"


class TestWarmthModel(ModelConformance):
    plugin_name = "warmth"
