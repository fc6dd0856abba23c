"""The core safety layer every actuator command passes through.

:class:`SafetyLayer` clamps each command to the actuator's declared
:class:`~hapticsdk.actuators.ActuatorLimits` and counts every limit hit, so that no
plugin can exceed what it declared, whether or not its own code checks.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from .dimensions import ChannelCommand


class SafetyLayer:
    """Clamp commands to declared limits; count and report each limit hit."""

    def __init__(self, limits: Any) -> None:
        self.limits = limits
        self.hits: dict[str, int] = {}
        self._last: ChannelCommand | None = None

    def reset(self, now: float) -> None:
        """Called when the actuator opens."""

    def on_stop(self) -> None:
        """Called when the actuator is stopped."""

    def observe(self, state: Any) -> None:
        """Called by the servo loop once per tick with the device state, before commands."""

    def current(self, now: float) -> ChannelCommand | None:
        """The command a device-side servo thread should apply at ``now`` (the last one sent)."""
        return self._last

    def _hit(self, key: str) -> None:
        self.hits[key] = self.hits.get(key, 0) + 1

    def filter(self, cmd: ChannelCommand, now: float) -> ChannelCommand:
        lim = self.limits
        out = cmd
        if cmd.force_n is not None and lim.max_force_n is not None and abs(cmd.force_n) > lim.max_force_n:
            self._hit("max_force_n")
            out = replace(out, force_n=float(np.clip(cmd.force_n, -lim.max_force_n, lim.max_force_n)))
        if cmd.frequency_hz is not None and lim.frequency_range_hz is not None:
            lo, hi = lim.frequency_range_hz
            if not lo <= cmd.frequency_hz <= hi:
                self._hit("frequency_range_hz")
                out = replace(out, frequency_hz=float(np.clip(cmd.frequency_hz, lo, hi)))
        if cmd.amplitude is not None:
            a = cmd.amplitude
            if a < 0:
                self._hit("negative_amplitude")
                a = 0.0
            if lim.max_amplitude is not None and a > lim.max_amplitude:
                self._hit("max_amplitude")
                a = lim.max_amplitude
            if a != cmd.amplitude:
                out = replace(out, amplitude=float(a))
        self._last = out
        return out

    def report(self) -> dict[str, Any]:
        return {"limit_hits": dict(self.hits)}
