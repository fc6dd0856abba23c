"""Kit rule ``close``: a simulated actuator's own model must be at rest once closed. The
core's ``read_back()`` reports rest for any closed actuator without asking the backend, so
a backend whose ``_close`` re-sends a drive (a queue "flushed" after the stop) passed;
the kit now asks the simulated backend itself after its declared settle time."""

from __future__ import annotations

import math
from typing import Any, ClassVar

import pytest

from hapticsdk.actuators import Actuator, ActuatorLimits
from hapticsdk.dimensions import ChannelCommand
from hapticsdk.testing import check
from kit_variants import API


class _LagCoil(Actuator):
    """A simulated coil whose output follows its drive with a first-order lag it declares."""

    hapticsdk_api = API
    name: ClassVar[str] = "kit-lag-coil"
    channel: ClassVar[str] = "vibration"
    simulated: ClassVar[bool] = True
    readback_source: ClassVar[str] = "output"
    tau_s = 0.002
    limits = ActuatorLimits(frequency_range_hz=(30.0, 300.0), max_amplitude=2.0, amplitude_unit="V",
                            amplitude_resolution=0.001, frequency_resolution_hz=0.5,
                            settle_time_s=0.002 * math.log(2.0 / 0.0005))

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.drive_f = self.drive_a = self.out_a = 0.0

    def _open(self) -> None:
        self.drive_f = self.drive_a = self.out_a = 0.0

    def _command(self, cmd: ChannelCommand) -> None:
        self.drive_f = float(cmd.frequency_hz or 0.0)
        self.drive_a = float(cmd.amplitude or 0.0)

    def _stop(self) -> None:
        self.drive_a = 0.0

    def step(self, dt: float) -> None:
        self.out_a += (self.drive_a - self.out_a) * (1.0 - math.exp(-dt / self.tau_s))

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("vibration", frequency_hz=self.drive_f, amplitude=self.out_a)


class _FlushOnClose(_LagCoil):
    """Its _close re-sends the last non-zero drive after the stop."""

    name = "kit-flush-on-close"
    _last = 0.0

    def _command(self, cmd: ChannelCommand) -> None:
        super()._command(cmd)
        if self.drive_a:
            self._last = self.drive_a

    def _close(self) -> None:
        self.drive_a = self._last


class _RefusesWhenClosed(_LagCoil):
    """A backend that refuses to be read once closed: not a violation."""

    name = "kit-refuses-closed"

    def _read_back(self) -> ChannelCommand:
        if not self.is_open:
            raise OSError("port closed")
        return super()._read_back()


@pytest.mark.parametrize("cls", [_LagCoil, _RefusesWhenClosed])
def test_honest_simulated_actuators_pass(cls):
    v = check("actuator", cls)
    assert not [x for x in v if x.rule == "close"], v


def test_a_drive_resent_by_close_is_caught():
    v = [x for x in check("actuator", _FlushOnClose) if x.rule == "close"]
    assert v and "after close()" in v[0].message, v
