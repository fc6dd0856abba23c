"""Actuators and haptic devices: the output side of the SDK.

:class:`Actuator` is the one interface every output plugin implements (like
python-can's ``BusABC``). Public methods validate and then call the backend's
``_open``/``_command``/``_stop``/``_close``; every command passes through the core
safety layer (:mod:`hapticsdk.devices.safety`) first, so every plugin gets the same limits for
free. :class:`HapticDevice` is an actuator that also senses (a force arm reports its
stylus position and velocity).

Actuator plugins are published under the entry-point group ``hapticsdk.actuators`` and
created by name with :func:`create_actuator` (``"omni-virtual"``, ``"piezo-serial"``).
"""

from __future__ import annotations

import atexit
import logging
import math
import struct
import time
import weakref
from collections import deque
from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar, Mapping, NoReturn, TypeVar

import numpy as np

from ..perception.channels import CHANNELS  # the channel kinds an actuator can serve (also hapticsdk.devices.actuators.CHANNELS)
from ..perception.dimensions import ChannelCommand
from ..errors import DeviceError, HapticSDKError, PluginError, ValidationError

log = logging.getLogger("hapticsdk.actuators")  # the 0.1 name: users configure logging by it

_isfinite = math.isfinite  # bound once: Actuator.command checks three fields every servo tick

#: relative tolerance of a read-back against its command or its rest, of full scale, where
#: the actuator declares no resolution (float rounding of a unit conversion, not a drift)
READBACK_RTOL = 1e-6


def readback_tolerance(act: Any, step: float | None, full_scale: float) -> float:
    """How far a read-back of one field may lie from the command in force (or from rest):
    half the declared ``step`` for a drive record (the quantisation of a write), one step
    for a measured or modelled output (``readback_source = "output"``: that of the write
    plus that of the reading); :data:`READBACK_RTOL` of ``full_scale`` where no step is
    declared. One rule for the conformance kit and :meth:`Actuator.still_driving`."""
    share = 1.0 if getattr(act, "readback_source", "drive") == "output" else 0.5
    return max(READBACK_RTOL * full_scale, share * (step or 0.0)) + 1e-9


#: every actuator currently open in this process; stopped at interpreter exit
_OPEN_ACTUATORS: "weakref.WeakSet[Actuator]" = weakref.WeakSet()


#: the last stops of this process: (label, time.monotonic(), success); see stops_since
_STOPS: "deque[tuple[str, float, bool]]" = deque(maxlen=256)


def stop_all() -> list[str]:
    """Put every open actuator of this process in its safe state; return their labels.

    Every actuator is stopped even when one backend breaks the never-raise contract of
    :meth:`Actuator.stop` with a ``BaseException`` (e.g. a second Ctrl-C inside its
    ``_stop``): the others are stopped first, then the first such exception is raised."""
    labels = []
    first: BaseException | None = None
    for act in list(_OPEN_ACTUATORS):
        try:
            act.stop()
            labels.append(act.label)
        except BaseException as exc:  # noqa: BLE001 - stop the others first
            log.error("stopping %s raised %s: %s", act.label, type(exc).__name__, exc)
            if first is None:
                first = exc
    if first is not None:
        raise first
    return labels


def stops_since(t0: float) -> list[tuple[str, float, bool]]:
    """Stops done at or after ``t0`` (``time.monotonic()`` seconds), oldest first, as
    ``(label, t, success)``: what a stop path (signal, exception) really stopped, also
    for actuators that were closed since (and so are no longer open for :func:`stop_all`)."""
    return [s for s in list(_STOPS) if s[1] >= t0]


atexit.register(stop_all)


@dataclass(frozen=True)
class ActuatorLimits:
    """Declared limits of an actuator (``None``: no such limit / not applicable).

    Attributes:
        max_force_n: largest force magnitude (N).
        max_stiffness_n_per_mm: stiffest spring it renders (N/mm).
        frequency_range_hz: (lowest, highest) drive frequency (Hz).
        max_amplitude: largest drive amplitude, in ``amplitude_unit``.
        amplitude_unit: ``"V"`` (piezo), ``"1"`` (normalised drive), ...
        max_velocity_mm_s: speed above which force output is not trusted (mm/s).
        max_force_rate_n_per_tick: largest force change per servo tick (N).
        frequency_resolution_hz: step of the frequencies the hardware can produce (Hz;
            e.g. 7.8125 Hz for the DRV2667's synthesiser); ``None``: continuous.
        amplitude_resolution: step of the amplitudes it can produce (``amplitude_unit``);
            ``None``: continuous.
        min_amplitude: smallest amplitude it can produce, for actuators whose amplitude
            is a set-point rather than an on/off level (a Peltier's coolest surface
            temperature, ``amplitude_unit``); ``None``: 0.
        settle_time_s: longest time the output takes to reach a new command within its
            resolution, from rest to full scale or back (its own ramps, slew and lag; s).
            ``None``: within one servo tick. (Plugin API 1.2.)
        force_resolution_n: step of the forces it can produce or measure (N); ``None``:
            continuous. (Plugin API 1.2.)

    The conformance kit compares what an actuator reports it outputs
    (:meth:`Actuator.read_back`) with the command in force once ``settle_time_s`` has
    passed: a drive record (:attr:`Actuator.readback_source` ``"drive"``) within half
    these steps, a measured or modelled output (``"output"``) within one step.
    """

    max_force_n: float | None = None
    max_stiffness_n_per_mm: float | None = None
    frequency_range_hz: tuple[float, float] | None = None
    max_amplitude: float | None = None
    amplitude_unit: str = ""
    max_velocity_mm_s: float | None = None
    max_force_rate_n_per_tick: float | None = None
    frequency_resolution_hz: float | None = None
    amplitude_resolution: float | None = None
    min_amplitude: float | None = None
    settle_time_s: float | None = None
    force_resolution_n: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The limits as a JSON-ready dict (tuples as lists; ``None`` where a limit does not
        apply).
        """
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}


@dataclass(frozen=True)
class DriveCapability:
    """What an actuator can produce, for solving features it can render (device-aware
    solving, :meth:`Actuator.capability_for`).

    Attributes:
        channel: its channel.
        frequency_range_hz: the band it plays (Hz), or None.
        max_drive: the largest drive amplitude it takes (``drive_unit``), or None.
        drive_unit: unit of the drive amplitude (``"V"``).
        table: optional drive table of the actuator itself (an object with
            ``acceleration_at(f_hz, drive)`` and ``voltage_for(f_hz, accel)``, e.g. a
            :class:`hapticsdk.calibration.PiezoTable`): the output per drive over
            frequency. None: the dimension's own (calibrated) table applies.
        source: where the figures come from (model, datasheet, calibration file).
    """

    channel: str
    frequency_range_hz: tuple[float, float] | None = None
    max_drive: float | None = None
    drive_unit: str = ""
    table: Any = field(default=None, compare=False)
    source: str = ""

    def summary(self) -> dict[str, Any]:
        """JSON-ready figures (the table by its source)."""
        return {"channel": self.channel,
                "frequency_range_hz": list(self.frequency_range_hz) if self.frequency_range_hz else None,
                "max_drive": self.max_drive, "drive_unit": self.drive_unit,
                "table": getattr(self.table, "source", None) if self.table is not None else None,
                "table_generated": getattr(self.table, "generated", None) if self.table is not None else None,
                "source": self.source}


@dataclass
class DeviceState:
    """Sensed state of a haptic device.

    Attributes:
        t: device time (s).
        position_mm: probe position (3,), (mm); y (index 1) is the surface normal, the
            material surface at y = 0 and inside it at y < 0.
        velocity_mm_s: probe velocity (3,), (mm/s).
        force_n: force currently applied by the device (3,), (N).
        buttons: button bit mask.
    """

    t: float
    position_mm: np.ndarray
    velocity_mm_s: np.ndarray
    force_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    buttons: int = 0

    @property
    def penetration_mm(self) -> float:
        """Depth below the surface y = 0 (mm); negative outside."""
        return float(-self.position_mm[1])


_PACK3 = struct.Struct("3d").pack


def _frozen3(a: float, b: float, c: float) -> np.ndarray:
    """A read-only (3,) float array of ``a, b, c``: a view of immutable bytes (0.15 us,
    against 0.25 us for ``np.array((a, b, c))`` and 0.6 us with ``flags.writeable = False``
    set on it; timeit, one run)."""
    return np.frombuffer(_PACK3(a, b, c))


def _vec3_field(names: tuple[str, str, str], cache: str, doc: str) -> property:
    """A :class:`SensedState` array field: three float slots ``names`` shown as a (3,)
    read-only array, built on first access and kept in slot ``cache``; assigning a
    sequence sets the floats and drops the kept array."""
    a, b, c = names

    def get(self: Any) -> np.ndarray:
        v = getattr(self, cache)
        if v is None:
            v = _frozen3(getattr(self, a), getattr(self, b), getattr(self, c))
            setattr(self, cache, v)
        return v

    def put(self: Any, v: Any) -> None:
        setattr(self, a, float(v[0]))
        setattr(self, b, float(v[1]))
        setattr(self, c, float(v[2]))
        setattr(self, cache, None)

    get.__doc__ = doc
    return property(get, put, doc=doc)


_SensedT = TypeVar("_SensedT", bound="SensedState")


class SensedState(DeviceState):
    """A :class:`DeviceState` held as plain floats: what a backend's ``_read_state``
    returns when it reads every servo tick (building three numpy arrays per read costs
    more than the rest of the read).

    Floats: ``t``, ``px, py, pz`` (mm), ``vx, vy, vz`` (mm/s), ``fx, fy, fz`` (N),
    ``buttons``. The :class:`DeviceState` fields ``position_mm``, ``velocity_mm_s`` and
    ``force_n`` are (3,) arrays built on first access and kept (read-only: a state is a
    reading; assign a whole field to change it, which sets the floats). Code written for
    :class:`DeviceState` (``st.position_mm[1]``, ``st.penetration_mm``, ``isinstance``)
    keeps working.

    ``SensedState(t, position_mm, velocity_mm_s, force_n=None, buttons=0)`` takes
    :class:`DeviceState`'s arguments (sequences or arrays);
    :meth:`of` takes the floats (the fast path); :meth:`from_state` converts any
    :class:`DeviceState`.
    """

    __slots__ = ("t", "buttons", "px", "py", "pz", "vx", "vy", "vz", "fx", "fy", "fz", "_pos", "_vel", "_frc")
    px: float
    py: float
    pz: float
    vx: float
    vy: float
    vz: float
    fx: float
    fy: float
    fz: float
    _pos: np.ndarray | None
    _vel: np.ndarray | None
    _frc: np.ndarray | None

    def __init__(self, t: float, position_mm: Any, velocity_mm_s: Any, force_n: Any = None,
                 buttons: int = 0) -> None:
        self.t = t
        self.position_mm = position_mm
        self.velocity_mm_s = velocity_mm_s
        self.force_n = (0.0, 0.0, 0.0) if force_n is None else force_n
        self.buttons = buttons

    @classmethod
    def of(cls: "type[_SensedT]", t: float, px: float, py: float, pz: float, vx: float, vy: float, vz: float,
           fx: float = 0.0, fy: float = 0.0, fz: float = 0.0, buttons: int = 0) -> "_SensedT":
        """A state from plain floats (no array is built until a field is read)."""
        st = cls.__new__(cls)
        st.t = t
        st.px = px
        st.py = py
        st.pz = pz
        st.vx = vx
        st.vy = vy
        st.vz = vz
        st.fx = fx
        st.fy = fy
        st.fz = fz
        st.buttons = buttons
        st._pos = st._vel = st._frc = None
        return st

    @classmethod
    def from_state(cls, st: Any) -> "SensedState":
        """``st`` (a :class:`DeviceState` or anything with its fields) as floats; a
        :class:`SensedState` is returned as it is."""
        if type(st) is cls:
            return st
        return cls(st.t, st.position_mm, st.velocity_mm_s, getattr(st, "force_n", None), getattr(st, "buttons", 0))

    position_mm = _vec3_field(("px", "py", "pz"), "_pos",  # type: ignore[assignment]
                              "Probe position (3,) (mm), a read-only array built from ``px, py, pz``.")
    velocity_mm_s = _vec3_field(("vx", "vy", "vz"), "_vel",  # type: ignore[assignment]
                                "Probe velocity (3,) (mm/s), a read-only array built from ``vx, vy, vz``.")
    force_n = _vec3_field(("fx", "fy", "fz"), "_frc",  # type: ignore[assignment]
                          "Applied force (3,) (N), a read-only array built from ``fx, fy, fz``.")

    @property
    def penetration_mm(self) -> float:
        """Depth below the surface y = 0 (mm); negative outside."""
        return -self.py

    @property
    def speed_mm_s(self) -> float:
        """|velocity| (mm/s)."""
        return math.hypot(self.vx, self.vy, self.vz)

    def __repr__(self) -> str:
        return (f"SensedState(t={self.t!r}, position_mm=({self.px!r}, {self.py!r}, {self.pz!r}), "
                f"velocity_mm_s=({self.vx!r}, {self.vy!r}, {self.vz!r}), "
                f"force_n=({self.fx!r}, {self.fy!r}, {self.fz!r}), buttons={self.buttons!r})")


class Actuator(ABC):
    """Base class of every actuator plugin.

    Class attributes a backend sets: ``name`` (its entry-point name), ``channel`` (one of
    :data:`CHANNELS`), ``limits`` (:class:`ActuatorLimits`), ``simulated``,
    ``privileged_options``.

    Public API (do not override): :meth:`open`, :meth:`close`, :meth:`command`,
    :meth:`stop`, :meth:`read_back`, context manager. Backend API: ``_open``,
    ``_command``, ``_stop``, ``_close``, ``_read_back`` (all but ``_command`` and
    ``_stop`` optional; a backend without ``_read_back`` fails the conformance kit's
    ``read-back`` rule, so every first-party backend has one).
    """

    name: ClassVar[str] = ""
    channel: ClassVar[str] = "other"
    #: command fields this actuator acts on, each with its unit (``{"force_n": "N"}``,
    #: ``{"frequency_hz": "Hz", "amplitude": "V"}``); empty: derived from ``channel`` and
    #: ``limits.amplitude_unit`` (:meth:`accepted_fields`)
    accepts: ClassVar[dict[str, str]] = {}
    limits: ActuatorLimits = ActuatorLimits()
    simulated: ClassVar[bool] = False
    #: options that name native code to load or files to write (option -> what it names,
    #: e.g. ``{"library": "native library", "sink": "output file"}``): never taken from
    #: scene or plan files, only from code, CLI flags, the environment or the user's device
    #: configuration (:mod:`hapticsdk.devices.device_options`). Merged over base classes.
    privileged_options: ClassVar[dict[str, str]] = {}
    #: amplitude the output rests at in its safe state (``stop()``): 0 for vibration and
    #: friction; a thermal actuator rests at a neutral temperature (its ``amplitude_unit``)
    rest_amplitude: ClassVar[float] = 0.0
    #: what :meth:`read_back` reports (plugin API 1.2): ``"drive"``, the backend's own
    #: record of what it last wrote to the hardware; ``"output"``, the physical output,
    #: measured (a sensor, a status register) or modelled (a simulated plant). The
    #: conformance kit checks the output itself only for ``"output"`` and says so in its
    #: report for ``"drive"``.
    readback_source: ClassVar[str] = "drive"
    #: the SDK axes (0 x, 1 y, 2 z) along which a force command's ``direction`` is
    #: rendered: ``(0, 1, 2)``, the whole vector (a 3-D arm); ``(1,)``, the projection on
    #: y alone (a device with one physical axis, the simulated Omni). The servo loop's
    #: stiff-wall controller books the work of the force on the motion along these axes
    #: (docs/runtime.md, Passivity, "A force rendered along one axis")
    force_axes: ClassVar[tuple[int, ...]] = (0, 1, 2)

    @classmethod
    def capability_for(cls, options: Mapping[str, Any] | None = None) -> DriveCapability | None:
        """What this actuator, created with ``options`` (gain, band, ...), can produce, so
        that the scene compiler solves for features it can render. Called on the class:
        nothing is created, opened or loaded. Default: the band and largest amplitude of
        the class's :attr:`limits`; None for a force channel. Backends whose limits depend
        on options override it; backends with a drive table of their own (an LRA's
        response) return it in ``table``."""
        if cls.channel == "force":
            return None
        lim = cls.limits if isinstance(cls.limits, ActuatorLimits) else ActuatorLimits()
        return DriveCapability(channel=cls.channel, frequency_range_hz=lim.frequency_range_hz,
                               max_drive=lim.max_amplitude, drive_unit=lim.amplitude_unit,
                               source=f"declared limits of {cls.name or cls.__name__}")

    @classmethod
    def conformance_options(cls) -> dict[str, Any]:
        """Keyword options the conformance kit creates a test instance with (default
        none). A backend that cannot be built without arguments (a playback device needs
        a run) returns what a self-contained test instance needs."""
        return {}

    def __init__(self, *, label: str | None = None, safety: Any = None, **options: Any) -> None:
        if options:
            raise ValidationError(f"unknown option(s) {sorted(options)} for actuator {self.name!r}",
                                  field="options")
        self.label = label or self.name or type(self).__name__
        self._is_open = False
        self.fault: BaseException | None = None
        #: the backend error of the last :meth:`close` (its ``_stop`` or ``_close``), or None
        self.close_error: BaseException | None = None
        self.last_command: ChannelCommand | None = None
        from .safety import SafetyLayer
        if safety is None:
            safety = SafetyLayer(self.limits)
        elif not isinstance(safety, SafetyLayer):
            # e.g. a scene file's device options {"safety": "off"}: the safety layer is not
            # an option a file can set or switch off
            raise ValidationError(f"safety must be a hapticsdk.devices.safety.SafetyLayer built in code, got "
                                  f"{type(safety).__name__} {safety!r}; the safety layer cannot be set or "
                                  "turned off from a scene or plan file", field="options.safety")
        self.safety = safety

    # -- lifecycle ---------------------------------------------------------
    @property
    def is_open(self) -> bool:
        """Whether :meth:`open` succeeded and :meth:`close` has not run yet."""
        return self._is_open

    def open(self) -> "Actuator":
        """Open the device (idempotent). Raises :class:`DeviceError` naming what was tried."""
        if self._is_open:
            return self
        try:
            self._open()
        except HapticSDKError:
            raise
        except Exception as exc:
            raise DeviceError(f"open failed: {type(exc).__name__}: {exc}", device=self.label) from exc
        self._is_open = True
        self.fault = None
        self.safety.reset(time.monotonic())
        _OPEN_ACTUATORS.add(self)
        return self

    def close(self) -> None:
        """Stop (safe state) and release the device. Never raises an :class:`Exception`
        (it may run while another error propagates): ``_close`` runs even when the stop
        failed, and a backend error of either is logged and kept in :attr:`close_error`
        (None after a clean close), where callers and the conformance kit see it."""
        if not self._is_open:
            return
        self.close_error = None
        if not self.stop():
            self.close_error = self.fault or DeviceError("stop failed during close()", device=self.label)
        try:
            self._close()
        except Exception as exc:  # closing must not mask the caller's error
            log.error("%s: close failed: %s: %s", self.label, type(exc).__name__, exc)
            self.close_error = self.close_error or exc
        self._is_open = False
        _OPEN_ACTUATORS.discard(self)

    def __enter__(self) -> "Actuator":
        return self.open()

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- per tick ----------------------------------------------------------
    def command(self, cmd: ChannelCommand, *, now: float | None = None) -> ChannelCommand:
        """Send one tick's command. It is validated and passed through the safety layer
        (clamped to the declared limits, ramped, counted); the command actually sent is
        returned. A non-finite value raises :class:`ValidationError`; a device that fails
        is put in its safe state and the error re-raised as :class:`DeviceError`."""
        return self._servo_command(cmd, time.monotonic() if now is None else now)

    def _servo_command(self, cmd: ChannelCommand, now: float) -> ChannelCommand:
        """:meth:`command` with the time given (what the servo loop calls every tick, as a
        method bound once per run; see :func:`servo_sender`): every check of
        :meth:`command`, the same safety layer (looked up on each call: ``safety`` may be
        replaced), the same backend ``_command``. Not for backends to override."""
        if not self._is_open:
            raise DeviceError("command on a closed actuator; call open() first", device=self.label)
        if self.fault is not None:
            raise DeviceError(f"actuator is faulted ({self.fault}); stop() and open() again",
                              device=self.label)
        # unrolled (no getattr by name): this runs every servo tick for every actuator
        v = cmd.force_n
        if v is not None and not _isfinite(v):
            raise ValidationError("force_n is NaN or infinite", field=f"{self.label}.force_n")
        v = cmd.frequency_hz
        if v is not None and not _isfinite(v):
            raise ValidationError("frequency_hz is NaN or infinite", field=f"{self.label}.frequency_hz")
        v = cmd.amplitude
        if v is not None and not _isfinite(v):
            raise ValidationError("amplitude is NaN or infinite", field=f"{self.label}.amplitude")
        safe = self.safety.filter(cmd, now)
        try:
            self._command(safe)
        except Exception as exc:
            self._command_failed(exc)
        self.last_command = safe
        return safe

    def _command_failed(self, exc: Exception) -> NoReturn:
        """The backend's ``_command`` raised ``exc``: keep it as :attr:`fault`, put the
        device in its safe state and raise it as a :class:`DeviceError`."""
        self.fault = exc
        self.stop()
        if isinstance(exc, DeviceError):
            raise exc
        raise DeviceError(f"command failed: {type(exc).__name__}: {exc}", device=self.label) from exc

    def _steady_sender(self, force: bool) -> Any:
        """A send for a servo loop's steady-state tick, compiled now from this actuator
        and the safety layer it has now, or None when this actuator does not offer one
        (its class or the instance replaces :meth:`command` or :meth:`_servo_command`,
        or its safety layer offers no :meth:`~hapticsdk.devices.safety.SafetyLayer._steady_filter`).

        ``force`` True: ``send(role, force_n, direction, now, pen)`` (``pen``: the
        penetration of the state the safety layer observed this tick); False:
        ``send(role, frequency_hz, amplitude, now)``. Either does what
        :meth:`_servo_command` does with the command of those fields (the other fields
        None), the same checks, filter, backend call and :attr:`last_command`, and
        returns what was sent; or returns None, having changed nothing, when the
        command would not take the steady path: the actuator is closed, faulted or has
        another safety layer than when the send was built, a value is not finite, or the
        layer is not in its steady state. The caller then sends through
        :meth:`_servo_command`, which raises or takes the general path as always. The
        backend's ``_command`` is looked up on every call (as :meth:`_servo_command`
        does)."""
        if (type(self)._servo_command is not Actuator._servo_command
                or getattr(self.command, "__func__", None) is not Actuator.command
                or type(self)._command_failed is not Actuator._command_failed):
            return None
        layer = self.safety
        steady = getattr(layer, "_steady_filter", None)
        filt = steady(force) if steady is not None else None
        if filt is None:
            return None
        act = self
        failed = self._command_failed

        if force:
            def send_force(role: str, f: float, direction: Any, now: float, pen: float) -> ChannelCommand | None:
                if not act._is_open or act.fault is not None or act.safety is not layer or not _isfinite(f):
                    return None
                safe = filt(role, f, direction, now, pen)
                if safe is None:
                    return None
                try:
                    act._command(safe)
                except Exception as exc:
                    failed(exc)
                act.last_command = safe
                return safe   # type: ignore[no-any-return]
            return send_force

        def send_vibration(role: str, fr: float | None, am: float | None, now: float) -> ChannelCommand | None:
            if (not act._is_open or act.fault is not None or act.safety is not layer
                    or (fr is not None and not _isfinite(fr)) or (am is not None and not _isfinite(am))):
                return None
            safe = filt(role, fr, am, now)
            if safe is None:
                return None
            try:
                act._command(safe)
            except Exception as exc:
                failed(exc)
            act.last_command = safe
            return safe   # type: ignore[no-any-return]
        return send_vibration

    def stop(self) -> bool:
        """Put the hardware in its safe state (zero force, vibration off). Never raises
        an :class:`Exception` (the stop paths of the servo loop and the CLI rely on it):
        the backend's ``_stop`` runs even when the safety layer's ``on_stop`` fails.
        Returns False when either failed (logged, kept in :attr:`fault`). Each call is
        noted in :func:`stops_since` (label, ``time.monotonic()``, success)."""
        ok = True
        try:
            self.safety.on_stop()
        except Exception as exc:
            log.error("%s: safety.on_stop failed: %s", self.label, exc)
            ok = False
        try:
            self._stop()
        except Exception as exc:
            log.error("%s: stop failed: %s", self.label, exc)
            self.fault = self.fault or exc
            ok = False
        _STOPS.append((self.label, time.monotonic(), ok))
        return ok

    @classmethod
    def accepted_fields(cls) -> dict[str, str]:
        """Command fields this actuator acts on, with their units: ``accepts`` when the
        class declares it; otherwise ``force_n`` in N for a force channel and
        ``frequency_hz`` in Hz plus ``amplitude`` in ``limits.amplitude_unit`` for the
        others (the amplitude alone when no frequency range is declared)."""
        if cls.accepts:
            return dict(cls.accepts)
        if cls.channel == "force":
            return {"force_n": "N"}
        lim = cls.limits if isinstance(cls.limits, ActuatorLimits) else ActuatorLimits()
        out = {"frequency_hz": "Hz"} if lim.frequency_range_hz is not None else {}
        out["amplitude"] = lim.amplitude_unit or "1"
        return out

    def read_back(self) -> ChannelCommand | None:
        """What the hardware outputs now, as a command of this actuator's channel (role =
        its ``channel``): from the device where it can report it (a register, a sensor),
        else from the backend's own record of what it last wrote to the hardware (after
        every conversion and quantisation of its own). A closed actuator outputs nothing:
        a zero force, or its ``rest_amplitude``. ``None``: the backend offers no read-back.

        Raises :class:`DeviceError` when the read fails or reports a non-finite value."""
        if not self._is_open:
            return ChannelCommand(self.channel, force_n=0.0 if self.channel == "force" else None,
                                  amplitude=None if self.channel == "force" else float(self.rest_amplitude))
        try:
            rb = self._read_back()
        except HapticSDKError:
            raise
        except Exception as exc:
            raise DeviceError(f"read-back failed: {type(exc).__name__}: {exc}", device=self.label) from exc
        if rb is not None:
            for attr in ("force_n", "frequency_hz", "amplitude"):
                v = getattr(rb, attr)
                if v is not None and not math.isfinite(v):
                    raise DeviceError(f"read-back reported {attr}={v!r}", device=self.label)
        return rb

    def _read_back(self) -> ChannelCommand | None:
        """Backend: the output now (see :meth:`read_back`); default: not available."""
        return None

    @property
    def settle_time_s(self) -> float:
        """How long the output takes to reach a command (s): ``limits.settle_time_s``;
        where that is undeclared, the backend's amplitude ramp time ``ramp_s`` (the option
        of the first-party vibration backends and of plugins written after them: full
        scale per ``ramp_s``); else 0. Backends whose settling depends on options override
        it."""
        v = getattr(self.limits, "settle_time_s", None)
        if v is None:
            r = getattr(self, "ramp_s", None)
            if isinstance(r, (int, float)) and not isinstance(r, bool) and math.isfinite(r) and r >= 0:
                return float(r)
        return float(v) if v is not None else 0.0

    def still_driving(self) -> str | None:
        """What this actuator still outputs when it should rest, per :meth:`read_back`
        (``"amplitude 148 V"``), or None at rest (within :func:`readback_tolerance`: half
        its declared resolution for a drive record, one step for a reported output, as the
        conformance kit judges it) or when it cannot tell (no read-back). For the render
        report after the final stop."""
        try:
            rb = self.read_back()
        except Exception as exc:  # noqa: BLE001 - a failing read is reported, not raised
            return f"read-back failed after stop ({type(exc).__name__}: {exc})"
        if rb is None:
            return None
        lim = self.limits
        f = rb.force_n or 0.0
        ftol = readback_tolerance(self, getattr(lim, "force_resolution_n", None), float(lim.max_force_n or 1.0))
        if abs(f) > ftol:
            return f"force {f:g} N"
        if rb.amplitude is not None:
            atol = readback_tolerance(self, lim.amplitude_resolution, float(lim.max_amplitude or 1.0))
            if abs(rb.amplitude - float(self.rest_amplitude)) > atol:
                return f"amplitude {rb.amplitude:g} {lim.amplitude_unit} (rest {float(self.rest_amplitude):g})"
        return None

    # -- discovery (used by `hapticsdk doctor`) -----------------------------
    @classmethod
    def check_available(cls) -> tuple[bool, str]:
        """Whether this backend can run here (libraries present), and why not.
        Backends needing a library or driver override it; it must not open devices."""
        return True, "no external library needed"

    @classmethod
    def discover(cls) -> list[dict[str, Any]]:
        """Devices of this backend found on this machine (name, serial, port ...)."""
        return []

    # -- backend API -------------------------------------------------------
    def _open(self) -> None:
        """Acquire the device."""

    def _close(self) -> None:
        """Release the device."""

    @abstractmethod
    def _command(self, cmd: ChannelCommand) -> None:
        """Apply an already validated and limited command."""

    @abstractmethod
    def _stop(self) -> None:
        """Zero force / vibration off, as directly as the hardware allows."""

    # -- reporting ---------------------------------------------------------
    def describe(self) -> dict[str, Any]:
        """Facts about this actuator for reports and ``hapticsdk doctor``: name, label,
        channel, accepted command fields, simulated or not, limits and the safety layer's
        report.
        """
        return {"name": self.name, "label": self.label, "channel": self.channel,
                "accepts": self.accepted_fields(), "simulated": self.simulated, "limits": self.limits.to_dict(),
                "safety": self.safety.report()}


class HapticDevice(Actuator):
    """An actuator that also senses the user's probe (e.g. a force-feedback arm).

    Backends implement ``_read_state``; simulated backends also implement ``_step`` to
    advance their physics by ``dt`` seconds under the last commanded force.
    """

    channel: ClassVar[str] = "force"

    def read_state(self) -> DeviceState:
        """Current state; non-finite readings raise :class:`DeviceError` naming the device."""
        if not self._is_open:
            raise DeviceError("read on a closed device; call open() first", device=self.label)
        st = self._read_state()
        if type(st) is SensedState:
            ok = (_isfinite(st.px) and _isfinite(st.py) and _isfinite(st.pz) and _isfinite(st.vx)
                  and _isfinite(st.vy) and _isfinite(st.vz))
        else:
            ok = np.isfinite(st.position_mm).all() and np.isfinite(st.velocity_mm_s).all()
        if not ok:
            raise DeviceError("device reported a non-finite position or velocity", device=self.label)
        return st

    @abstractmethod
    def _read_state(self) -> DeviceState:
        """Backend read."""

    def step(self, dt: float) -> None:
        """Advance simulated physics by ``dt`` (s); real devices move on their own."""
        if dt <= 0 or not math.isfinite(dt):  # math: a numpy call costs ~1 us every tick
            raise ValidationError(f"dt must be a positive number of seconds, got {dt!r}", field="dt")
        self._step(dt)

    def _step(self, dt: float) -> None:
        """Simulated devices integrate here; real ones ignore it."""


def force_axes_of(act: Any) -> tuple[int, ...]:
    """The SDK axes ``act`` renders a force's direction along (``Actuator.force_axes``),
    checked: distinct axes of 0 (x), 1 (y), 2 (z), at least one, in increasing order.

    Raises:
        PluginError: anything else (a name such as ``"y"``, an axis 3, a repeated axis, an
            empty tuple), naming the actuator: the servo loop reads it on every tick of a
            spatial contact and books the stiff-wall controller's work on it.
    """
    axes = getattr(act, "force_axes", (0, 1, 2))
    try:
        out = tuple(axes)
    except TypeError:
        out = ()
    if (not out or len(set(out)) != len(out)
            or not all(type(a) is int and 0 <= a <= 2 for a in out) or list(out) != sorted(out)):
        raise PluginError(f"{type(act).__name__}.force_axes must be distinct SDK axes 0, 1, 2 in increasing order "
                          f"(e.g. (0, 1, 2) or (1,)), got {axes!r}", plugin=type(act).__name__, kind="actuators")
    return out


def servo_sender(act: Actuator) -> Any:
    """What a servo loop calls to send ``act`` one tick's command, ``send(cmd, now)``:
    the bound :meth:`Actuator._servo_command` (bound once per run, no keyword handling,
    no clock read) when the actuator's class and instance keep the base class's
    :meth:`Actuator.command`; otherwise a call of its own ``command(cmd, now=now)``, so a
    class or an instance that replaces ``command`` (a wrapper, a test double) is called
    as before."""
    command = act.command
    # (not ``vars(act)``: reading an instance's __dict__ makes CPython 3.11 keep it as a
    # dict, and every attribute access on that actuator slower, each tick)
    if getattr(command, "__func__", None) is Actuator.command and getattr(command, "__self__", None) is act:
        return act._servo_command
    return lambda cmd, now: command(cmd, now=now)


def create_actuator(name: str, **options: Any) -> Actuator:
    """Instantiate the actuator plugin registered as ``name`` (lazy import). An option the
    class does not take, or one whose value it fails on with ``TypeError`` / ``ValueError``
    (a plugin that does not check it), raises :class:`ValidationError` naming the option
    (:func:`hapticsdk.argcheck.call_with_options`)."""
    from ..argcheck import call_with_options
    from ..plugins import registry
    cls = registry("actuator").load(name)
    return call_with_options(cls, options=options, field="options")  # type: ignore[no-any-return]
