"""A simulated Peltier element (entry point ``peltier-virtual``).

The command's ``amplitude`` is the target surface temperature (°C). The plate follows
it as a first-order system ``dT/dt = (T_target - T) / tau`` with slew limited to
``max_rate_c_per_s`` and stays within ``[min_c, limits.max_amplitude]`` (10..42 °C).
``stop()`` returns the target to the neutral skin temperature (33 °C): no heating or
cooling.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from hapticsdk.devices.actuators import Actuator, ActuatorLimits
from hapticsdk.perception.dimensions import ChannelCommand

from .thermal import T_SKIN_C


class PeltierVirtual(Actuator):
    """Simulated Peltier plate; ``temperature_c`` is its surface temperature (°C)."""

    hapticsdk_api: ClassVar[str] = ">=1.0,<2"
    name: ClassVar[str] = "peltier-virtual"
    channel: ClassVar[str] = "thermal"
    accepts: ClassVar[dict[str, str]] = {"amplitude": "degC"}
    simulated: ClassVar[bool] = True
    limits = ActuatorLimits(max_amplitude=42.0, amplitude_unit="degC", min_amplitude=10.0)
    rest_amplitude: ClassVar[float] = T_SKIN_C

    def __init__(self, *, tau_s: float = 0.4, max_rate_c_per_s: float = 8.0, min_c: float = 10.0,
                 **options: Any) -> None:
        super().__init__(**options)
        from hapticsdk.argcheck import number
        self.tau_s = number(tau_s, "options.tau_s", lo=0.0, lo_open=True)
        self.max_rate = number(max_rate_c_per_s, "options.max_rate_c_per_s", lo=0.0, lo_open=True)
        self.min_c = number(min_c, "options.min_c")
        self.temperature_c = T_SKIN_C
        self.target_c = T_SKIN_C

    def _open(self) -> None:
        self.temperature_c = T_SKIN_C
        self.target_c = T_SKIN_C

    def _command(self, cmd: ChannelCommand) -> None:
        if cmd.amplitude is not None:
            self.target_c = float(np.clip(cmd.amplitude, self.min_c, self.limits.max_amplitude))

    def _stop(self) -> None:
        self.target_c = T_SKIN_C

    def _read_back(self) -> ChannelCommand:
        """The surface temperature set-point (°C) the controller holds."""
        return ChannelCommand("thermal", amplitude=self.target_c)

    def step(self, dt: float) -> None:
        """Advance the thermal plant by ``dt`` seconds (called by the servo loop)."""
        rate = (self.target_c - self.temperature_c) / self.tau_s
        rate = float(np.clip(rate, -self.max_rate, self.max_rate))
        self.temperature_c += rate * dt

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d.update(temperature_c=self.temperature_c, target_c=self.target_c, tau_s=self.tau_s)
        return d
