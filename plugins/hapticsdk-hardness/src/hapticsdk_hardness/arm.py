"""What the real 3-DoF force arms (``dhd``, ``inverse3``) share.

A backend subclasses :class:`ForceArm` and implements five transport calls:
``_io_open`` (returns the model name the device reports), ``_io_read`` (position m and
velocity m/s in the device frame), ``_io_force`` (write a force vector, N, device
frame), ``_io_release`` (force output off) and ``_io_close``. The base class does the
rest, the same way for every arm:

* **Frames.** The SDK's y axis is the surface normal (index 1, y < 0 inside the
  material); ``AXES`` maps it onto the device's axes (``sdk[i] = device[AXES[i]]``), so
  the normal is the device's vertical axis. ``surface_mm`` is the height of the
  surface in the device frame. Position is reported in mm, velocity in mm/s.
* **Declared parameters.** ``MODELS`` holds, per model the device can report, the
  vendor's figures: continuous force, stiffness, position resolution, servo rate,
  apparent mass and damping (see docs/devices.md for the sources). At open the model
  the device names picks the row; ``limits`` (force, stiffness) then come from it and
  from what the device itself reports (a lower force limit read from the device
  wins). The servo loop's passivity controller reads ``apparent_mass_kg``,
  ``damping_ns_per_m`` and ``encoder_resolution_mm`` from here.
* **Capabilities** (:meth:`ForceArm.capabilities`): force limit, stiffness limit,
  force bandwidth (half the servo rate: the highest frequency a zero-order-held force
  at that rate represents), position resolution.
* **Safe state.** ``stop()`` writes zero force and turns force output off; a thread
  (:class:`hapticsdk.runtime.watchdog.CommandWatchdog`) writes zero force when no
  command came for ``command_timeout_s`` (the Python loop stalled). A transport error
  marks the device faulted, and the next command or read raises a
  :class:`~hapticsdk.errors.DeviceError` naming the device and the error.
"""

from __future__ import annotations

import threading
import time
from dataclasses import asdict, dataclass
from typing import Any, ClassVar

import numpy as np

from hapticsdk.devices.actuators import ActuatorLimits, DeviceState, HapticDevice, SensedState
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import DeviceError, ValidationError


@dataclass(frozen=True)
class ArmModel:
    """Declared figures of one arm model (vendor data sheet; ``None``: not published).

    Attributes:
        name: model name as the vendor library reports it.
        max_force_n: continuous force (N).
        max_stiffness_n_per_mm: closed-loop stiffness (N/mm).
        resolution_mm: position resolution (mm).
        servo_rate_hz: highest servo rate the device takes (Hz).
        mass_kg: apparent mass at the handle (kg), for the passivity controller.
        damping_ns_per_m: physical viscous damping (N*s/m) credited by the passivity
            observer; 0 (nothing credited) where not published.
        source: where the figures come from.
    """

    name: str
    max_force_n: float
    max_stiffness_n_per_mm: float
    resolution_mm: float
    servo_rate_hz: float
    mass_kg: float | None = None
    damping_ns_per_m: float = 0.0
    source: str = ""

    def limits(self, max_force_n: float | None = None) -> ActuatorLimits:
        """The actuator limits of this model: its continuous force (or ``max_force_n``,
        a lower limit the device reports) and its stiffness."""
        return ActuatorLimits(max_force_n=self.max_force_n if max_force_n is None else max_force_n,
                              max_stiffness_n_per_mm=self.max_stiffness_n_per_mm)


def capability_dict(model: ArmModel, limits: ActuatorLimits) -> dict[str, Any]:
    """Force limit, stiffness limit, force bandwidth and resolution of an arm."""
    return {"max_force_n": limits.max_force_n, "max_stiffness_n_per_mm": limits.max_stiffness_n_per_mm,
            "bandwidth_hz": model.servo_rate_hz / 2.0, "servo_rate_hz": model.servo_rate_hz,
            "resolution_mm": model.resolution_mm, "model": model.name, "source": model.source}


class ForceArm(HapticDevice):
    """Base of the real 3-DoF arms (see the module docstring).

    Args:
        surface_mm: height of the material surface along the device's vertical axis (mm).
        command_timeout_s: zero force when the last command is older than this (s).
            Default (None): the safety layer's ``restart_after_s`` (50 ms by default; at most
            1 s), the gap after which
            :class:`~hapticsdk.devices.safety.SafetyLayer` gates and ramps force again, so force
            the watchdog cut never returns as a step when the servo resumes; a shorter
            deadline would (a gap between the two resumes at full force at once).
        model: model name to use when the device does not report one it knows
            (``MODELS`` key); default the device's own report.
        label, safety: as for every actuator.
    """

    channel: ClassVar[str] = "force"
    accepts: ClassVar[dict[str, str]] = {"force_n": "N"}
    simulated: ClassVar[bool] = False
    #: declared figures per model; the first row is the class default (and gives the
    #: class's ``limits``, set when a subclass declares ``MODELS``)
    MODELS: ClassVar[dict[str, ArmModel]] = {}
    #: ``sdk[i] = device[AXES[i]]``: SDK axis i is the device's axis AXES[i]
    AXES: ClassVar[tuple[int, int, int]] = (0, 1, 2)

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "MODELS" in cls.__dict__ and cls.MODELS and "limits" not in cls.__dict__:
            cls.limits = cls._row(None).limits()

    @classmethod
    def _row(cls, model: str | None) -> ArmModel:
        """The declared figures of ``model`` (None: the class default, the first row)."""
        return cls.MODELS[model] if model else next(iter(cls.MODELS.values()))

    def __init__(self, *, surface_mm: float = 0.0, command_timeout_s: float | None = None, model: str | None = None,
                 label: str | None = None, safety: Any = None, **options: Any) -> None:
        super().__init__(label=label, safety=safety, **options)
        if not (isinstance(surface_mm, (int, float)) and np.isfinite(surface_mm)):
            raise ValidationError("must be a finite number of mm", field="options.surface_mm")
        from hapticsdk.devices.safety import command_timeout_s as _deadline  # default: the restart gap (see Args)
        command_timeout_s = _deadline(self.safety, command_timeout_s)
        if model is not None and model not in self.MODELS:
            raise ValidationError(f"unknown model {model!r}; one of {sorted(self.MODELS)}", field="options.model")
        self.surface_mm = float(surface_mm)
        self.command_timeout_s = command_timeout_s
        self.model_option = model
        self.model = self._row(model)
        self.limits = type(self).limits
        self.reported_model: str | None = None
        self._io = threading.RLock()
        self._force_dev = (0.0, 0.0, 0.0)
        self._enabled = False
        self._watchdog: Any = None
        self._io_error: BaseException | None = None
        self.watchdog_zeroed = 0

    # -- declared parameters (read by the servo loop's passivity controller) ----------------
    @property
    def apparent_mass_kg(self) -> float | None:
        """Apparent mass at the handle (kg) of the model in use, or None."""
        return self.model.mass_kg

    @property
    def damping_ns_per_m(self) -> float:
        """Physical damping credited by the passivity observer (N*s/m)."""
        return self.model.damping_ns_per_m

    @property
    def encoder_resolution_mm(self) -> float:
        """Position resolution of the model in use (mm)."""
        return self.model.resolution_mm

    @classmethod
    def capabilities(cls, model: str | None = None) -> dict[str, Any]:
        """Published capabilities of ``model`` (default: the class's first model)."""
        m = cls._row(model)
        return capability_dict(m, m.limits())

    # -- transport (backend) -------------------------------------------------------------------
    def _io_open(self) -> str | None:
        raise NotImplementedError

    def _io_read(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        raise NotImplementedError

    def _io_force(self, f: tuple[float, float, float]) -> None:
        raise NotImplementedError

    def _io_release(self) -> None:
        raise NotImplementedError

    def _io_close(self) -> None:
        raise NotImplementedError

    def _io_max_force_n(self) -> float | None:
        """A force limit the device reports (N), or None."""
        return None

    # -- HapticDevice backend ----------------------------------------------------------------
    def _open(self) -> None:
        from hapticsdk.runtime.watchdog import CommandWatchdog
        from hapticsdk.devices.safety import SafetyLayer
        self._io_error = None
        self._force_dev = (0.0, 0.0, 0.0)
        with self._io:
            try:
                reported = self._io_open()
            except BaseException:
                try:
                    self._io_close()
                except Exception:
                    pass
                raise
        try:
            self.reported_model = reported
            if self.model_option is None and reported in self.MODELS:
                self.model = self.MODELS[reported]
            fmax = self.model.max_force_n
            dev_max = self._io_max_force_n()
            if dev_max is not None and 0 < dev_max < fmax:
                fmax = dev_max
            self.limits = self.model.limits(fmax)
            if isinstance(self.safety, SafetyLayer):
                self.safety.limits = self.limits
            self._watchdog = CommandWatchdog(self._watchdog_zero, deadline_s=self.command_timeout_s, lock=self._io,
                                             on_error=self._failed, name=f"watchdog {self.label}").start(armed=False)
        except BaseException:
            self._release_and_close()
            raise

    def _watchdog_zero(self) -> None:
        self._force_dev = (0.0, 0.0, 0.0)
        self._io_force(self._force_dev)
        self.watchdog_zeroed += 1

    def _failed(self, exc: BaseException) -> None:
        self._io_error = self._io_error or exc

    def _check(self) -> None:
        if self._io_error is not None:
            raise DeviceError(f"{type(self._io_error).__name__}: {self._io_error}", device=self.label)

    def _command(self, cmd: ChannelCommand) -> None:
        self._check()
        f = 0.0 if cmd.force_n is None else float(cmd.force_n)
        d = cmd.direction if cmd.direction is not None else (0.0, 1.0, 0.0)
        dev = [0.0, 0.0, 0.0]
        for i, a in enumerate(self.AXES):
            dev[a] = f * float(d[i])
        with self._io:
            try:
                if not self._enabled and f != 0.0:
                    self._io_enable()
                    self._enabled = True
                self._io_force((dev[0], dev[1], dev[2]))
            except BaseException as exc:
                self._io_error = exc
                raise
            self._force_dev = (dev[0], dev[1], dev[2])
        if self._watchdog is not None:
            self._watchdog.feed()

    def _io_enable(self) -> None:
        """Turn force output on (called before the first non-zero force after open or stop)."""

    def _read_back(self) -> ChannelCommand:
        """The force last written to the device, along the SDK's normal (N)."""
        return ChannelCommand("force", force_n=float(self._force_dev[self.AXES[1]]))

    def _stop(self) -> None:
        self._force_dev = (0.0, 0.0, 0.0)
        if self._watchdog is not None:
            self._watchdog.disarm()
        with self._io:
            self._enabled = False
            try:
                self._io_force((0.0, 0.0, 0.0))
            finally:
                self._io_release()

    def _read_state(self) -> DeviceState:
        self._check()
        with self._io:
            try:
                pos, vel = self._io_read()
            except BaseException as exc:
                self._io_error = exc
                self.stop()
                raise DeviceError(f"read failed: {type(exc).__name__}: {exc}", device=self.label) from exc
        a0, a1, a2 = self.AXES
        fd = self._force_dev
        # plain floats, read every servo tick (the loop reads floats; arrays are built
        # only when a caller asks)
        return SensedState.of(time.monotonic(), float(pos[a0]) * 1e3, float(pos[a1]) * 1e3 - self.surface_mm,
                              float(pos[a2]) * 1e3, float(vel[a0]) * 1e3, float(vel[a1]) * 1e3,
                              float(vel[a2]) * 1e3, fd[a0], fd[a1], fd[a2])

    def _release_and_close(self) -> None:
        if self._watchdog is not None:
            self._watchdog.stop()
            self._watchdog = None
        with self._io:
            try:
                self._io_force((0.0, 0.0, 0.0))
                self._io_release()
            except Exception:
                pass
            finally:
                self._io_close()

    def _close(self) -> None:
        self._release_and_close()

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d.update({"model": asdict(self.model), "reported_model": self.reported_model,
                  "capabilities": capability_dict(self.model, self.limits), "surface_mm": self.surface_mm,
                  "command_timeout_s": self.command_timeout_s, "watchdog_zeroed": self.watchdog_zeroed})
        return d
