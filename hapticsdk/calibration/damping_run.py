"""The hands-off damping run played on a device in real time, paced on the machine's
clock (docs/calibration.md, "A run timed by the loop's clock").

:func:`play_damping_run` plays :func:`~hapticsdk.calibration.damping.excitation` through
the device's own command path (its safety layer: clamps, ramp, staleness), one force per
tick of a loop paced by :class:`~hapticsdk.runtime.clock.MonotonicClock`, and records
each tick's timestamp on that clock. The servo period is not held exactly (nothing in a
Python loop holds it); the fit does not assume it is: each step lasts as measured
(:func:`~hapticsdk.calibration.damping.fit_damping` with ``times_s``), and what the
timestamps do not pin down, when a force reached the arm and when a reading was sampled,
is bounded by what the run measured (how long each read and each command took) and what
the device declares (``transport_latency_s``), and added to the bound. A device that
declares no latency is refused unless the caller gives one (``latency_s``): its timing
cannot be bounded, so neither can its damping.

A simulated device is stepped by the time that really passed between ticks, as the
servo loop's real-time mode steps it: its physics then runs at the loop's timestamps, so
its reads and commands take no time in its own clock (latency 0), and it drops a command
older than its safety layer's ``stale_after_s`` (it applies
:meth:`~hapticsdk.devices.safety.SafetyLayer.current`), which the fit models. A real
device may or may not drop a stale command; the bound covers both.

This is a dedicated loop, not :class:`~hapticsdk.runtime.loop.ServoLoop`: the run plays
a fixed force sequence with no renderer and no passivity controller (a controller would
change the forces the fit needs), and it records what the fit needs per tick.
"""

from __future__ import annotations

import gc
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ValidationError
from .damping import DampingFit, declared_limits, excitation, fit_damping

#: Time held at 0 N before the run beyond the safety layer's start ramp (s): the arm
#: settles, and the layer is past its gate and ramp before the first force.
SETTLE_EXTRA_S = 0.1


@dataclass
class DampingRun:
    """A hands-off run played in real time (:func:`play_damping_run`).

    Attributes:
        fit: the fit of the run (:class:`~hapticsdk.calibration.damping.DampingFit`).
        forces_n: the forces as applied (the safety layer's read-back), one per tick (N).
        readings_mm: the encoder readings along the axis, one before each force and the
            last (mm).
        times_s: each reading's timestamp on the loop's clock, from the first reading (s).
        read_s: per reading, how long after its timestamp the read returned (s; 0 on a
            simulated device).
        command_s: per force, how long after its tick's timestamp the command returned
            (s; 0 on a simulated device).
        latency_s: the transport latency the bound took (declared or given, s).
        period_s: the period the loop was paced at (s).
        late_ticks: steps longer than 1.5 periods.
        simulated: the device was simulated (generated data).
    """

    fit: DampingFit
    forces_n: np.ndarray
    readings_mm: np.ndarray
    times_s: np.ndarray
    read_s: np.ndarray
    command_s: np.ndarray
    latency_s: float
    period_s: float
    late_ticks: int
    simulated: bool


def play_damping_run(device: Any, *, period_s: float = 1e-3, axis: int = 1, role: str = "force",
                     mass_kg: float | None = None, max_force_n: float | None = None,
                     latency_s: float | None = None, clock: Any = None) -> DampingRun:
    """Play the hands-off run on ``device`` (nobody holds the stylus) in real time and fit it.

    ``period_s``: the loop's period (s); ``axis``: 0, 1, 2 (x, y, z) the one driven and
    read; ``mass_kg``, ``max_force_n``: size the run where the device declares no
    ``apparent_mass_kg`` / ``limits.max_force_n`` (refused when neither); ``latency_s``:
    the most time between a position's sample and the read returning it, and between a
    command returning and its force at the motor, where the device declares no
    ``transport_latency_s`` (a real device with neither is refused before it is opened);
    ``clock``: the pacing clock (default :class:`~hapticsdk.runtime.clock.MonotonicClock`;
    a :class:`~hapticsdk.runtime.clock.SimulatedClock` with stalls makes late ticks on
    purpose).

    The device is opened if it is not open (and then closed), held at 0 N for its safety
    layer's start ramp plus :data:`SETTLE_EXTRA_S`, driven along ``axis`` through its
    command path, and on every exit path (an error, ``KeyboardInterrupt``) sent 0 N
    (stopped if that fails). A failed fit is returned, not raised: ``fit.success`` is
    False and it credits nothing."""
    from ..argcheck import number
    from ..perception.dimensions import ChannelCommand
    from ..runtime.clock import MonotonicClock

    number(period_s, "period_s", lo=0.0, lo_open=True)
    if axis not in (0, 1, 2):
        raise ValidationError(f"must be 0, 1 or 2, got {axis!r}", field="axis")
    m, fm = declared_limits(device, mass_kg, max_force_n)
    simulated = bool(getattr(type(device), "simulated", False))
    if simulated:
        lat = 0.0   # stepped from the loop's timestamps: its clock is the loop's
    else:
        lat_d = latency_s if latency_s is not None else getattr(device, "transport_latency_s", None)
        if lat_d is None:
            raise ValidationError(f"{type(device).__name__} declares no transport_latency_s: when its forces reach "
                                  "the arm and when its readings were sampled is not bounded, so its damping cannot "
                                  "be; pass latency_s= (--latency) from the device's documentation", field="latency_s")
        lat = float(number(lat_d, "latency_s", lo=0.0))
    forces = excitation(period_s, fm, m)
    safety = getattr(device, "safety", None)
    ramp = float(getattr(getattr(safety, "settings", None), "ramp_time_s", 0.0) or 0.0)
    settle = int(math.ceil((ramp + SETTLE_EXTRA_S) / period_s))
    n = forces.size
    clock = clock if clock is not None else MonotonicClock()
    now = clock.now
    e = [0.0, 0.0, 0.0]
    applied = np.zeros(n)
    readings = np.zeros(n + 1)
    times = np.zeros(n + 1)
    read_s = np.zeros(n + 1)
    command_s = np.zeros(n)
    t_last = [0.0]

    def send(f: float, t: float) -> float:
        e[axis] = 1.0 if f >= 0.0 else -1.0
        device.command(ChannelCommand(role, force_n=abs(f), direction=(e[0], e[1], e[2])), now=t)
        back = device.read_back()
        if back is None or back.force_n is None:
            return 0.0
        # the applied force along the axis (signed), as measure_damping reads it
        return float(back.force_n) * (1.0 if back.direction is None else back.direction[axis])

    observe = getattr(safety, "observe", None)
    opened = not device.is_open
    gc_was = gc.isenabled()
    origin = now()
    t_dev = 0.0
    if opened:
        device.open()
    try:
        if safety is not None and hasattr(safety, "set_period"):
            safety.set_period(period_s)   # a command older than a period is stale, as in the servo loop
        # a simulated device's own clock (its state's t) may not start at 0 (opened and
        # stepped before): commands carry its time, so its safety layer ages them right
        t_dev = float(getattr(device.read_state(), "t", 0.0) or 0.0) if simulated else 0.0
        gc.collect()
        gc.disable()                      # no collection pauses a tick
        deadline = origin = now()
        for i in range(settle + n + 1):
            clock.wait_until(deadline)
            t = now() - origin
            if i and simulated:
                device.step(t - t_last[0])   # physics advances by the time that really passed
            t_last[0] = t
            k = i - settle
            st = device.read_state()
            if observe is not None:
                observe(st)   # the layer's speed limits see each tick's state, as in the servo loop
            if k >= 0:
                times[k] = t
                readings[k] = float(st.position_mm[axis])
                read_s[k] = 0.0 if simulated else now() - origin - t
            if k < 0:
                send(0.0, t_dev + t)
            elif k < n:
                applied[k] = send(float(forces[k]), t_dev + t)
                command_s[k] = 0.0 if simulated else now() - origin - t
            clock.work(i, 0.0)     # a simulated clock charges the tick here (a test's stalls)
            deadline += period_s
            if now() > deadline + period_s:
                deadline = now()   # behind by more than a period: on from now (the fit takes any step)
    finally:
        if gc_was:
            gc.enable()
        try:
            try:
                send(0.0, t_dev + now() - origin)
            except Exception:
                device.stop()      # the safe state when even a 0 N command fails
        finally:
            if opened:
                device.close()
    times -= times[0]
    stale = getattr(getattr(safety, "settings", None), "stale_after_s", None)
    res = float(getattr(device, "encoder_resolution_mm", 0.0) or 0.0)
    # a command older than stale_after_s is dropped to 0 N by a simulated device (it
    # applies SafetyLayer.current, the layer's contract): the fit models the drop; a real
    # device may or may not drop it: the bound covers both
    drop = None if stale is None else float(stale)
    fit = fit_damping(applied, readings, period_s, res, times_s=times, force_delay_s=command_s + lat,
                      reading_delay_s=np.maximum(read_s, lat), hold_s=drop if simulated else None,
                      may_drop_after_s=None if simulated else drop)
    late = int(np.sum(np.diff(times) > 1.5 * period_s))
    return DampingRun(fit=fit, forces_n=applied, readings_mm=readings, times_s=times, read_s=read_s,
                      command_s=command_s, latency_s=lat, period_s=float(period_s), late_ticks=late,
                      simulated=simulated)
