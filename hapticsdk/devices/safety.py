"""The core safety layer every actuator command passes through.

Every :class:`~hapticsdk.devices.actuators.Actuator` owns a :class:`SafetyLayer` (on by
default) and routes each command ``Actuator.command(cmd, now=...)`` through
:meth:`SafetyLayer.filter` before its backend sees it, so no plugin can exceed what it
declared in its :class:`~hapticsdk.devices.actuators.ActuatorLimits`, whether or not its own
code checks. What the layer enforces (see ``docs/safety.md``):

* **Declared limits** on every command: force magnitude (N), stiffness (N/mm, as
  ``|F| <= k_max * penetration + stiffness_offset_n``), a force limit that shrinks with
  probe speed above ``velocity_knee * max_velocity_mm_s`` and is zero (a fault) above
  ``max_velocity_mm_s``, drive frequency (Hz), amplitude / voltage (actuator unit, never
  negative), and the force change per tick (N). Each limit hit is counted per command.
* **Start gate**: after ``open()``, a ``stop()`` or a fault, force output is held at
  zero while the user is already pushing hard (penetration above
  ``start_max_penetration_mm`` or a commanded force above ``start_max_force_n``).
* **Ramp**: once the gate releases, force is scaled by an envelope rising linearly from
  0 to 1 over ``ramp_time_s``, so it never steps at start or after a fault: for a steady
  command ``F`` the output changes by at most ``|F| * dt / ramp_time_s`` per tick.
* **Stale commands**: :meth:`SafetyLayer.current` (what a device-side servo thread or a
  simulated device applies at time ``now``) returns the last command only while it is
  younger than ``stale_after_s`` (one servo period); after that it returns zero and the
  old command is never re-sent. A gap longer than ``restart_after_s`` between commands
  counts as a fault (gate + ramp again).

Times (``now``, s) are those the caller passes to ``Actuator.command``: simulated time
in a simulated run, ``time.monotonic()`` otherwise. The layer only compares times it
received through :meth:`filter` and :meth:`current`, so both clocks work.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from ..argcheck import flag, number
from ..perception.dimensions import ChannelCommand
from ..errors import ValidationError

#: small slack when comparing times (s): simulated clocks accumulate rounding error
_TIME_EPS = 1e-9

_new = object.__new__


@dataclass(frozen=True)
class SafetySettings:
    """Tunable behaviour of :class:`SafetyLayer` (defaults are the SDK's defaults).

    Attributes:
        ramp_time_s: duration of the force ramp at start and after a fault (s); 0 turns
            the ramp off (not recommended on hardware).
        stale_after_s: age beyond which :meth:`SafetyLayer.current` replaces the last
            command by zero (s); one servo period (1 ms at the 1 kHz servo rate).
            :meth:`SafetyLayer.set_period` sets it from the servo loop's period.
        restart_after_s: a gap between two commands longer than this (s) is treated as
            a fault: the start gate and the ramp apply again.
        start_max_penetration_mm: the start gate holds force at zero while the probe is
            deeper than this below the surface (mm); ``None``: not checked.
        start_max_force_n: ... or while the (clamped) commanded force exceeds this (N);
            ``None``: not checked.
        velocity_knee: fraction of ``max_velocity_mm_s`` above which the force limit
            shrinks linearly, reaching 0 at ``max_velocity_mm_s``.
        stiffness_offset_n: force allowed on top of ``max_stiffness * penetration`` (N),
            so constant contact forces (the paper's 1 N "no hardness" condition) pass.
        ramp_amplitude: also ramp vibration amplitude (not only force).
    """

    ramp_time_s: float = 0.2
    stale_after_s: float = 0.001
    restart_after_s: float = 0.05
    start_max_penetration_mm: float | None = 1.0
    start_max_force_n: float | None = 1.0
    velocity_knee: float = 0.5
    stiffness_offset_n: float = 1.0
    ramp_amplitude: bool = False

    def __post_init__(self) -> None:
        from ..checks import is_number
        for name in ("ramp_time_s", "stiffness_offset_n", "stale_after_s", "restart_after_s", "velocity_knee",
                     "start_max_penetration_mm", "start_max_force_n"):
            v = getattr(self, name)
            if not (v is None and name.startswith("start_")) and not is_number(v):
                raise ValidationError(f"must be a number, got {v!r}", field=f"safety.{name}")
        for name in ("ramp_time_s", "stiffness_offset_n"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValidationError(f"must be a finite number >= 0, got {v!r}", field=f"safety.{name}")
        for name in ("stale_after_s", "restart_after_s"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValidationError(f"must be a finite number > 0, got {v!r}", field=f"safety.{name}")
        for name in ("start_max_penetration_mm", "start_max_force_n"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v >= 0):
                raise ValidationError(f"must be None or a number >= 0, got {v!r}", field=f"safety.{name}")
        if not 0.0 <= self.velocity_knee < 1.0:
            raise ValidationError(f"must be in [0, 1), got {self.velocity_knee!r}", field="safety.velocity_knee")
        # a switch of a safeguard: only True or False, never a truthy string or None
        flag(self.ramp_amplitude, "safety.ramp_amplitude")

    def to_dict(self) -> dict[str, Any]:
        """The settings as a dict (every field, SI units as named)."""
        return asdict(self)


#: phases of the layer's state machine
PHASES = ("closed", "waiting", "ramping", "running")


def command_timeout_s(safety: Any, value: Any = None, *, at_most: float | None = 1.0) -> float:
    """A backend's dead-man deadline (s) from its ``command_timeout_s`` option: ``value``
    when given (a number > 0, and at most ``at_most`` unless None), else
    :func:`default_command_timeout_s` of ``safety``; a bad value is a
    :class:`~hapticsdk.errors.ValidationError` naming ``options.command_timeout_s``."""
    if value is None:
        return default_command_timeout_s(safety)
    # a finite number (never a bool: True is no deadline of 1 s)
    return number(value, "options.command_timeout_s", lo=0.0, lo_open=True, hi=at_most)


def default_command_timeout_s(safety: Any) -> float:
    """The default deadline (s) of a backend's own dead-man switch (a device-side thread
    or callback that zeroes or silences the output when the servo stops commanding): the
    ``restart_after_s`` of ``safety`` (a :class:`SafetyLayer`; its settings' default when
    it has none), at most 1 s.

    Derivation: after a gap longer than ``restart_after_s`` the safety layer gates and
    ramps the output again, so an output the dead-man switch cut comes back through the
    ramp when the servo resumes. A shorter deadline leaves a window (longer than the
    deadline, shorter than the restart gap) in which the output, cut to zero, resumes at
    its full level at once: a step. A longer one lets a stalled servo's last command play
    on after the layer itself already treats the gap as a fault."""
    settings = getattr(safety, "settings", None)
    return min(1.0, float(getattr(settings, "restart_after_s", SafetySettings.restart_after_s)))


class SafetyLayer:
    """Clamp commands to declared limits, gate and ramp force at start and after faults,
    zero stale commands; count and report each limit hit.

    Args:
        limits: the actuator's :class:`~hapticsdk.devices.actuators.ActuatorLimits`.
        settings: a :class:`SafetySettings` (default: the SDK defaults).
        **overrides: individual :class:`SafetySettings` fields, e.g. ``ramp_time_s=0.5``.

    Public attributes: ``limits``, ``settings``, ``hits`` (limit name -> count),
    ``events`` (``faults``, ``stale_zeroed``, ``start_hold_ticks``, ``ramp_ticks``),
    ``phase`` (one of :data:`PHASES`).
    """

    def __init__(self, limits: Any, settings: SafetySettings | None = None, **overrides: Any) -> None:
        #: called (no arguments) when the configuration or the phase changes: what a
        #: compiled send (:meth:`_steady_filter`) captured may be out of date
        self._watchers: tuple = ()
        self._limits = limits
        base = settings if settings is not None else SafetySettings()
        try:
            self.settings = replace(base, **overrides) if overrides else base
        except TypeError:
            valid = sorted(SafetySettings.__dataclass_fields__)
            raise ValidationError(f"unknown safety setting(s) {sorted(overrides)}; valid: {valid}",
                                  field="safety") from None
        self.hits: dict[str, int] = {}
        self.events: dict[str, int] = {"faults": 0, "stale_zeroed": 0, "start_hold_ticks": 0, "ramp_ticks": 0}
        self.last_fault: str | None = None
        self.phase = "closed"
        self._state: Any = None
        self._last: ChannelCommand | None = None
        self._t_last: float | None = None
        self._stale_counted = False
        self._ramp_t0: float | None = None
        self._prev_force = 0.0
        self._overspeed = False
        self._speed_now: float | None = None  # |v| of the observed state (mm/s), when checked

    # -- configuration -----------------------------------------------------
    @property
    def limits(self) -> Any:
        """The declared :class:`~hapticsdk.devices.actuators.ActuatorLimits` enforced (assignable)."""
        return self._limits

    @limits.setter
    def limits(self, value: Any) -> None:
        checked = declared_limits(value)    # a bad declaration is refused here, not on a tick
        self._limits = value
        self._cache(checked)

    @property
    def settings(self) -> SafetySettings:
        """The :class:`SafetySettings` in force (assignable; see also :meth:`configure`)."""
        return self._settings

    @settings.setter
    def settings(self, value: SafetySettings) -> None:
        self._settings = value
        self._cache()

    def _cache(self, checked: dict[str, Any] | None = None) -> None:
        """Copy the limits and settings the per-tick path reads into plain attributes
        (both are frozen dataclasses: replaced, never changed in place, so the copies
        stay valid until the next assignment, which refreshes them). The limits are
        validated and made floats here (:func:`declared_limits`), once per configuration:
        the per-command path compares with them as they are."""
        if not (hasattr(self, "_limits") and hasattr(self, "_settings")):
            return  # __init__ sets both before the first command
        lim = checked if checked is not None else declared_limits(self._limits)
        s = self._settings
        self._fmax = lim["max_force_n"]
        self._amax = lim["max_amplitude"]
        self._frange = lim["frequency_range_hz"]
        self._vmax = lim["max_velocity_mm_s"]
        self._kmax = lim["max_stiffness_n_per_mm"]
        self._rate = lim["max_force_rate_n_per_tick"]
        self._amin = lim["min_amplitude"]
        self._knee = s.velocity_knee
        self._k_offset = s.stiffness_offset_n
        self._ramp_amp = s.ramp_amplitude
        # the same sums the comparisons made on every call before
        self._restart_limit = s.restart_after_s + _TIME_EPS
        self._stale_limit = s.stale_after_s + _TIME_EPS
        self._changed()

    def _changed(self) -> None:
        """Tell the watchers (a servo loop's steady-state tick) that the limits, the
        settings or the phase changed."""
        for w in getattr(self, "_watchers", ()):
            w()

    def _watch(self, fn: Any) -> None:
        """Call ``fn()`` on every change of configuration or phase (once per ``fn``)."""
        w = getattr(self, "_watchers", ())
        if fn not in w:
            self._watchers = (*w, fn)

    def _unwatch(self, fn: Any) -> None:
        """Stop calling ``fn`` (no error when it was not watching)."""
        self._watchers = tuple(w for w in getattr(self, "_watchers", ()) if w != fn)

    def __getstate__(self) -> dict[str, Any]:
        # a copy or a pickle of the layer is not watched by the loop watching this one
        state = dict(self.__dict__)
        state["_watchers"] = ()
        return state

    def configure(self, **changes: Any) -> None:
        """Change settings (fields of :class:`SafetySettings`)."""
        self.settings = replace(self.settings, **changes)

    def set_period(self, period_s: float) -> None:
        """Tell the layer the servo period (s): commands older than it are stale."""
        self.configure(stale_after_s=float(period_s))

    # -- lifecycle (called by Actuator and the servo loop) ---------------------
    def reset(self, now: float) -> None:
        """Called when the actuator opens: output zero, start gate armed, then ramp.

        ``now`` may come from a different clock than later commands; it is not used to
        time the ramp (the ramp is timed from the ``now`` of the command that releases
        the gate)."""
        self._restart()

    def on_stop(self) -> None:
        """Called when the actuator is stopped (also after a backend fault): the last
        command is dropped and the next start goes through the gate and the ramp."""
        self._restart()

    def fault(self, reason: str) -> None:
        """Record a fault (e.g. a device error flag that does not stop the device):
        output drops to zero now, then gate and ramp as at start."""
        self.events["faults"] += 1
        self.last_fault = reason
        self._restart()

    def _restart(self) -> None:
        self.phase = "waiting"
        self._last = None
        self._t_last = None
        self._stale_counted = False
        self._ramp_t0 = None
        self._prev_force = 0.0
        self._changed()

    def observe(self, state: Any) -> None:
        """Called by the servo loop once per tick with the device state
        (:class:`~hapticsdk.devices.actuators.DeviceState`), before the tick's commands."""
        self._state = state
        vmax = self._vmax
        if vmax is None:
            self._speed_now = None
            return
        speed = self._speed_now = self._speed()
        over = speed > vmax
        if over:
            self._hit("max_velocity_mm_s")
            if not self._overspeed:
                self.fault("max_velocity_mm_s: probe speed above the declared limit")
        self._overspeed = over

    # -- per command -------------------------------------------------------
    def current(self, now: float) -> ChannelCommand | None:
        """The command a device-side servo thread (or a simulated device) applies at
        ``now`` (s): the last filtered command while it is at most one servo period old,
        a zero command (same role, force 0 / amplitude 0) once it is stale, ``None``
        before the first command."""
        last = self._last
        t_last = self._t_last
        if last is None or t_last is None:
            return None
        if now - t_last > self._stale_limit:
            if not self._stale_counted:
                self.events["stale_zeroed"] += 1
                self._stale_counted = True
            return _zeroed(last)
        return last

    def filter(self, cmd: ChannelCommand, now: float) -> ChannelCommand:
        """The command to actually send at ``now`` (s): clamped, gated, ramped; every
        limit that bites is counted in :attr:`hits`.

        Runs every servo tick for every actuator: it reads limits and settings from
        plain attributes (:meth:`_cache`), works on Python floats and allocates one
        :class:`~hapticsdk.perception.dimensions.ChannelCommand`."""
        if self.phase == "closed":
            self._restart()
        t_last = self._t_last
        if t_last is not None and now - t_last > self._restart_limit:
            self.fault(f"command gap of {now - t_last:.4f} s (> restart_after_s)")
        force = cmd.force_n
        if force is not None:
            # clamp to the force, speed and stiffness limits (inline: one call less a tick)
            f = float(force)
            fmax = self._fmax
            if fmax is not None and abs(f) > fmax:
                self._hit("max_force_n")
                f = math.copysign(fmax, f)
            st = self._state
            if st is not None:
                vmax = self._vmax
                if vmax is not None:
                    # observe() already measured this state's speed
                    speed = self._speed_now if self._speed_now is not None else self._speed()
                    if speed > vmax:
                        f = 0.0  # counted in observe() (once per tick)
                    elif fmax is not None:
                        knee = self._knee * vmax
                        if speed > knee:
                            cap = fmax * (vmax - speed) / (vmax - knee)
                            if abs(f) > cap:
                                self._hit("max_velocity_mm_s")
                                f = math.copysign(cap, f)
                kmax = self._kmax
                if kmax is not None:
                    pen = getattr(st, "penetration_mm", None)
                    if pen is None:
                        pen = -np.asarray(st.position_mm, float)[1]
                    pen = float(pen)
                    if pen < 0.0:  # noqa: PLR1730 -- max(pen, 0.0) without the call; NaN and -0.0 pass as before
                        pen = 0.0
                    cap = kmax * pen + self._k_offset
                    if abs(f) > cap:
                        self._hit("max_stiffness_n_per_mm")
                        f = math.copysign(cap, f)
            force = f
        amp = cmd.amplitude
        if amp is not None:
            amp = float(amp)
            if amp < 0.0:
                self._hit("negative_amplitude")
                amp = 0.0
            amax = self._amax
            if amax is not None and amp > amax:
                self._hit("max_amplitude")
                amp = amax              # a float >= 0 (declared_limits)
        freq = cmd.frequency_hz
        if freq is not None:
            frange = self._frange
            if frange is not None:
                lo, hi = frange         # floats, 0 <= lo <= hi (declared_limits)
                if not lo <= freq <= hi:
                    self._hit("frequency_range_hz")
                    freq = lo if freq < lo else hi if freq > hi else freq   # NaN stays NaN, as min/max left it

        if self._overspeed or self.phase != "running":
            gain = self._envelope(force, now)
            if force is not None:
                force = gain * force
            if amp is not None and self._ramp_amp:
                amp = gain * amp
        # running: the gain is 1.0 and 1.0 * x == x exactly, so no multiplication
        if force is not None:
            rate = self._rate
            if rate is not None:
                prev = self._prev_force
                if abs(force - prev) > rate:
                    self._hit("max_force_rate_n_per_tick")
                    force = prev + math.copysign(rate, force - prev)
            self._prev_force = force
        if amp is not None:
            amin = self._amin
            if amin is not None and amp < amin:
                self._hit("min_amplitude")
                amp = amin
        # one new command per tick (dataclasses.replace costs several us on the servo path),
        # its fields stored here as ChannelCommand.__init__ stores them, in its order: the
        # same object without the call through the class, which runs __init__ in a frame of
        # its own (~800 instructions a command; tests/safety/test_filter_output_record.py)
        out = _new(ChannelCommand)
        out.role = cmd.role
        out.force_n = force
        out.frequency_hz = freq
        out.amplitude = amp
        out.direction = cmd.direction
        self._last = out
        self._t_last = now
        self._stale_counted = False
        return out

    @staticmethod
    def _steady_observer(layers: tuple) -> Any:
        """One call doing :meth:`observe` of every layer of ``layers``, in their order,
        for a servo loop's steady-state tick, or None when some layer's ``observe`` does
        more than store the state: a speed limit is declared (the speed is computed and
        judged every tick), the class or the instance replaces :meth:`observe`, or it is
        not a :class:`SafetyLayer`. Moved to configuration time (this call): the
        ``max_velocity_mm_s is None`` test of each layer. What it captured is out of date
        when a layer's limits change: the layer tells its watchers (:meth:`_watch`), and
        the caller builds a new one."""
        for layer in layers:
            if (not isinstance(layer, SafetyLayer) or layer._vmax is not None
                    or getattr(layer.observe, "__func__", None) is not SafetyLayer.observe):
                return None

        def observe_all(state: Any) -> None:
            for layer in layers:
                layer._state = state
                layer._speed_now = None
        return observe_all

    def _steady_filter(self, force: bool) -> Any:
        """A compiled :meth:`filter` for the layer's steady state (``running``, not over
        speed), built from the limits and settings in force now, or None when this class
        replaces :meth:`filter`, :meth:`observe` or :meth:`_envelope` (a subclass's own
        rules: the servo loop then sends through :meth:`filter` every tick).

        ``force`` True: ``f(role, force_n, direction, now, pen)`` for a force command
        (``force_n`` a float; no frequency or amplitude); ``pen``: the
        ``penetration_mm`` of the state the layer observed this tick. False:
        ``f(role, frequency_hz, amplitude, now)`` for a vibration command (no force, no
        direction). Either returns the record :meth:`filter` would return for that
        command, with the same counts and state changes, or None, having changed
        nothing, when the layer is not in its steady state at ``now`` (another phase,
        over speed, no command yet, or a command gap longer than ``restart_after_s``):
        the caller then calls :meth:`filter`.

        Moved to configuration time (this call): which of the declared limits exist and
        their values, the settings the running phase reads, and the phase branches of
        :meth:`filter`. Still checked on every call: the phase, over speed, the command
        gap and every clamp of a declared limit (they depend on the command, the time or
        the observed state). What the function captured is out of date after the limits
        or the settings change: the layer's watchers (:meth:`_watch`) are told, and the
        caller builds a new one."""
        cls = type(self)
        if (cls.filter is not SafetyLayer.filter or cls.observe is not SafetyLayer.observe
                or cls._envelope is not SafetyLayer._envelope):
            return None
        layer = self
        restart = self._restart_limit
        hit = self._hit
        if force:
            fmax, vmax, kmax, rate = self._fmax, self._vmax, self._kmax, self._rate
            knee = self._knee * vmax if vmax is not None else 0.0
            koff = self._k_offset
            speed_of = self._speed

            def steady_force(role: str, f: float, direction: Any, now: float, pen: float) -> ChannelCommand | None:
                if layer._overspeed or layer.phase != "running":
                    return None
                t_last = layer._t_last
                if t_last is None or now - t_last > restart:
                    return None
                # the clamps of filter(), in its order, on the declared limits only
                if fmax is not None and abs(f) > fmax:
                    hit("max_force_n")
                    f = math.copysign(fmax, f)
                if layer._state is not None:
                    if vmax is not None:
                        sp = layer._speed_now
                        speed = sp if sp is not None else speed_of()
                        if speed > vmax:
                            f = 0.0
                        elif fmax is not None and speed > knee:
                            cap = fmax * (vmax - speed) / (vmax - knee)
                            if abs(f) > cap:
                                hit("max_velocity_mm_s")
                                f = math.copysign(cap, f)
                    if kmax is not None:
                        if pen < 0.0:  # noqa: PLR1730 -- as filter()
                            pen = 0.0
                        cap = kmax * pen + koff
                        if abs(f) > cap:
                            hit("max_stiffness_n_per_mm")
                            f = math.copysign(cap, f)
                if rate is not None:
                    prev = layer._prev_force
                    if abs(f - prev) > rate:
                        hit("max_force_rate_n_per_tick")
                        f = prev + math.copysign(rate, f - prev)
                layer._prev_force = f
                out = _new(ChannelCommand)
                out.role = role
                out.force_n = f
                out.frequency_hz = None
                out.amplitude = None
                out.direction = direction
                layer._last = out
                layer._t_last = now
                layer._stale_counted = False
                return out
            return steady_force
        amax, frange, amin = self._amax, self._frange, self._amin
        lo, hi = frange if frange is not None else (0.0, 0.0)

        def steady_vibration(role: str, freq: float | None, amp: float | None, now: float) -> ChannelCommand | None:
            if layer._overspeed or layer.phase != "running":
                return None
            t_last = layer._t_last
            if t_last is None or now - t_last > restart:
                return None
            if amp is not None:
                amp = float(amp)
                if amp < 0.0:
                    hit("negative_amplitude")
                    amp = 0.0
                if amax is not None and amp > amax:
                    hit("max_amplitude")
                    amp = amax
            if freq is not None and frange is not None and not lo <= freq <= hi:
                hit("frequency_range_hz")
                freq = lo if freq < lo else hi if freq > hi else freq
            if amp is not None and amin is not None and amp < amin:
                hit("min_amplitude")
                amp = amin
            out = _new(ChannelCommand)
            out.role = role
            out.force_n = None
            out.frequency_hz = freq
            out.amplitude = amp
            out.direction = None
            layer._last = out
            layer._t_last = now
            layer._stale_counted = False
            return out
        return steady_vibration

    def _envelope(self, force: float | None, now: float) -> float:
        """Gate and ramp gain (0..1) for this command; advances the phase machine."""
        s = self._settings
        if self._overspeed:
            self.events["start_hold_ticks"] += 1
            return 0.0
        if self.phase == "waiting":
            pen_ok = (s.start_max_penetration_mm is None or self._state is None
                      or self._penetration() <= s.start_max_penetration_mm)
            force_ok = s.start_max_force_n is None or force is None or abs(force) <= s.start_max_force_n
            if not (pen_ok and force_ok):
                self.events["start_hold_ticks"] += 1
                return 0.0
            self.phase = "ramping"
            self._ramp_t0 = now
        if self.phase == "ramping":
            if s.ramp_time_s <= 0:
                self.phase = "running"
                self._changed()
                return 1.0
            if self._ramp_t0 is None or now < self._ramp_t0:  # clock went backwards: restart the ramp from here
                self._ramp_t0 = now
            g = (now - self._ramp_t0) / s.ramp_time_s
            if g >= 1.0 - _TIME_EPS:
                self.phase = "running"
                self._changed()
                return 1.0
            self.events["ramp_ticks"] += 1
            return max(g, 0.0)
        return 1.0

    # -- helpers -----------------------------------------------------------
    def _speed(self) -> float:
        st = self._state
        speed = getattr(st, "speed_mm_s", None)   # a SensedState: from its floats
        if speed is not None:
            return speed
        return float(np.linalg.norm(np.asarray(st.velocity_mm_s, float)))

    def _penetration(self) -> float:
        st = self._state
        pen = getattr(st, "penetration_mm", None)
        return float(pen if pen is not None else -np.asarray(st.position_mm, float)[1])

    def _hit(self, key: str) -> None:
        self.hits[key] = self.hits.get(key, 0) + 1

    def clear_counts(self) -> None:
        """Zero the limit-hit and event counters."""
        self.hits.clear()
        for k in self.events:
            self.events[k] = 0

    def report(self) -> dict[str, Any]:
        """Counters and settings, JSON-ready: ``limit_hits`` (limit name -> number of
        commands it clamped), ``events``, ``phase``, ``last_fault``, ``settings``."""
        return {"limit_hits": dict(self.hits), "events": dict(self.events), "phase": self.phase,
                "last_fault": self.last_fault, "settings": self.settings.to_dict()}


#: declared limits the safety layer enforces, with the least value each may take
#: (``>=``; ``max_velocity_mm_s`` must be above 0: the speed-dependent force limit
#: divides by ``(1 - velocity_knee) max_velocity_mm_s``)
_LIMIT_FLOORS = {"max_force_n": 0.0, "max_stiffness_n_per_mm": 0.0, "max_amplitude": 0.0,
                 "max_force_rate_n_per_tick": 0.0, "max_velocity_mm_s": None}


def declared_limits(lim: Any) -> dict[str, Any]:
    """The limits the safety layer enforces, checked once when they are configured and
    returned as Python floats (``None`` where not declared): each ``max_*`` a finite
    number >= 0 (``max_velocity_mm_s`` > 0), ``frequency_range_hz`` two finite numbers
    ``0 <= lo <= hi``, ``min_amplitude`` finite and at most ``max_amplitude``. A bad
    value is a :class:`~hapticsdk.errors.ValidationError` naming ``limits.<field>``: a
    NaN bound would let every command through (a comparison with NaN is false), a
    string would fail on the first tick that reaches the limit. Objects without the
    optional fields (not an ActuatorLimits) have those limits undeclared."""
    from ..checks import is_number
    out: dict[str, Any] = {}
    for name, floor in _LIMIT_FLOORS.items():
        v = getattr(lim, name) if name in ("max_force_n", "max_amplitude") else getattr(lim, name, None)
        if v is not None:
            if not (is_number(v) and math.isfinite(v) and (v > 0 if floor is None else v >= floor)):
                raise ValidationError(f"must be None or a finite number {'> 0' if floor is None else '>= 0'}, "
                                      f"got {v!r}", field=f"limits.{name}")
            v = float(v)
        out[name] = v
    fr = lim.frequency_range_hz
    if fr is not None:
        try:
            lo, hi = fr
        except (TypeError, ValueError):
            raise ValidationError(f"must be None or (lowest, highest) in Hz, got {fr!r}",
                                  field="limits.frequency_range_hz") from None
        if not (is_number(lo) and is_number(hi) and math.isfinite(lo) and math.isfinite(hi) and 0 <= lo <= hi):
            raise ValidationError(f"must be two finite numbers 0 <= lowest <= highest (Hz), got {fr!r}",
                                  field="limits.frequency_range_hz")
        fr = (float(lo), float(hi))
    out["frequency_range_hz"] = fr
    amin = getattr(lim, "min_amplitude", None)
    if amin is not None:
        amax = out["max_amplitude"]
        if not (is_number(amin) and math.isfinite(amin) and (amax is None or amin <= amax)):
            raise ValidationError(f"must be None or a finite number <= max_amplitude ({amax!r}), got {amin!r}",
                                  field="limits.min_amplitude")
        amin = float(amin)
    out["min_amplitude"] = amin
    return out


def _zeroed(cmd: ChannelCommand) -> ChannelCommand:
    """``cmd`` with its force and amplitude set to zero (frequency kept)."""
    return replace(cmd, force_n=0.0 if cmd.force_n is not None else None,
                   amplitude=0.0 if cmd.amplitude is not None else None)
