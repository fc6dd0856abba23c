"""hapticsdk-roughness against the hapticsdk conformance kit."""

from __future__ import annotations

import pytest

from hapticsdk.testing import ActuatorConformance, DimensionConformance


class TestRoughnessDimension(DimensionConformance):
    plugin_name = "roughness"


class TestPiezoVirtual(ActuatorConformance):
    plugin_name = "piezo-virtual"


@pytest.fixture(scope="module")
def serial_bridge():
    pytest.importorskip("serial")
    from hapticsdk_roughness.emulation import SerialBridgeEmulator
    with SerialBridgeEmulator() as emu:
        yield emu


class TestPiezoSerialEmulated(ActuatorConformance):
    plugin_name = "piezo-serial"

    @pytest.fixture
    def actuator_factory(self, serial_bridge):
        from hapticsdk_roughness.hardware import PiezoSerial
        # the emulator answers from a thread of this process: a reply budget of 0.5 s, not
        # the board's 0.05 s, so that a busy machine is not taken for a silent bridge
        return lambda: PiezoSerial(port=serial_bridge.port, timeout=0.5)


class TestPiezoMCP2221Emulated(ActuatorConformance):
    plugin_name = "piezo-mcp2221"

    @pytest.fixture
    def actuator_factory(self):
        pytest.importorskip("usb")
        from hapticsdk_roughness.hardware import PiezoMCP2221
        from hapticsdk_roughness.usb_emulation import MCP2221Backend
        backend = MCP2221Backend()
        return lambda: PiezoMCP2221(backend=backend)
