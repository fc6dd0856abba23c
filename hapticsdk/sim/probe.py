"""A kinematic virtual probe: a stylus that follows a scripted trajectory exactly.

It senses (position, velocity; all three axes of a 3-D trajectory such as
:func:`hapticsdk.sim.finger.walk_over`) but has no motors: forces commanded to it are accepted
and ignored, so it exercises renderers and the servo loop without any physics
(entry point ``probe-virtual``). For a probe pushed back by the rendered force use the
simulated Omni of the hardness plugin (``omni-virtual``).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ..devices.actuators import ActuatorLimits, DeviceState, HapticDevice
from ..perception.dimensions import ChannelCommand
from ..errors import ValidationError
from .finger import Trajectory, press_slide


class VirtualProbe(HapticDevice):
    """Kinematic probe on a scripted trajectory (default: press 2 mm, slide at 80 mm/s,
    release; see :func:`hapticsdk.sim.finger.press_slide`).

    Args:
        trajectory: a :class:`~hapticsdk.sim.finger.Trajectory`.
        loop: restart the trajectory when it ends (default False: hold the last point).
        label, safety: as for every actuator.
    """

    name: ClassVar[str] = "probe-virtual"
    channel: ClassVar[str] = "force"
    simulated: ClassVar[bool] = True
    limits = ActuatorLimits()

    def __init__(self, *, trajectory: Trajectory | None = None, loop: bool = False,
                 label: str | None = None, safety: Any = None, **options: Any) -> None:
        super().__init__(label=label, safety=safety, **options)
        if trajectory is not None and not isinstance(trajectory, Trajectory):
            raise ValidationError("trajectory must be a hapticsdk.sim.finger.Trajectory", field="trajectory")
        self.trajectory = trajectory or press_slide()
        self.loop = bool(loop)
        self.t = 0.0
        self.ignored_force_n = 0.0

    def _time(self) -> float:
        if self.loop and self.trajectory.duration_s > 0:
            return self.t % self.trajectory.duration_s
        return self.t

    def _read_state(self) -> DeviceState:
        x, y, z, vx, vy, vz = self.trajectory.at3(self._time())
        return DeviceState(t=self.t, position_mm=np.array([x, y, z]),
                           velocity_mm_s=np.array([vx, vy, vz]))

    def _step(self, dt: float) -> None:
        self.t += dt

    def _command(self, cmd: ChannelCommand) -> None:
        if cmd.force_n is not None:
            self.ignored_force_n = float(cmd.force_n)

    def _stop(self) -> None:
        self.ignored_force_n = 0.0

    def _read_back(self) -> ChannelCommand:
        """A kinematic probe applies no force (``max_force_n`` is None: it only senses)."""
        return ChannelCommand("force", force_n=0.0)

    def _open(self) -> None:
        self.t = 0.0
