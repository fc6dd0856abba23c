"""Driving an actuator under the kit: the command sets (normal, over the limits, at the
edges), holds of one command for the safety layer's ramp plus the declared settle time,
the read-back compared with the command in force, a sensing device's state over a run,
threads left after close, stalls, and the core's ``ServoLoop`` with stand-in parts (a still
probe, a replaying renderer) for the ``servo-loop`` rule."""

from __future__ import annotations

import math
import threading
from typing import Any, Iterator, Mapping, Sequence

import numpy as np

from ...devices.actuators import Actuator, ActuatorLimits, HapticDevice, readback_tolerance
from ...errors import ValidationError
from ...perception.dimensions import ChannelCommand, DimensionRenderer, TickInput
from .timing import KIT_PERIOD_S, _monotonic, _perf_counter, _sim_advance


def _over_limit_commands(act: Actuator) -> list[ChannelCommand]:
    lim = act.limits
    cmds = []
    role = act.channel
    if lim.max_force_n is not None:
        cmds += [ChannelCommand(role, force_n=10 * lim.max_force_n + 1),
                 ChannelCommand(role, force_n=-(10 * lim.max_force_n + 1))]
    if lim.frequency_range_hz is not None:
        lo, hi = lim.frequency_range_hz
        amp = lim.max_amplitude if lim.max_amplitude is not None else 0.5
        cmds += [ChannelCommand(role, frequency_hz=hi * 10 + 100, amplitude=amp),
                 ChannelCommand(role, frequency_hz=max(lo / 10.0, 0.0), amplitude=amp)]
    if lim.max_amplitude is not None:
        f = float(np.mean(lim.frequency_range_hz)) if lim.frequency_range_hz else 100.0
        cmds += [ChannelCommand(role, frequency_hz=f, amplitude=10 * lim.max_amplitude + 1),
                 ChannelCommand(role, frequency_hz=f, amplitude=-1.0)]
    return cmds


def _normal_commands(act: Actuator) -> list[ChannelCommand]:
    lim = act.limits
    role = act.channel
    out = []
    if lim.max_force_n is not None or act.channel == "force":
        fmax = lim.max_force_n if lim.max_force_n is not None else 1.0
        out += [ChannelCommand(role, force_n=v * fmax) for v in (0.0, 0.25, 0.5, 0.25, 0.0)]
    if lim.frequency_range_hz is not None or lim.max_amplitude is not None:
        a = lim.max_amplitude if lim.max_amplitude is not None else 1.0
        a0 = float(getattr(lim, "min_amplitude", None) or 0.0)
        if lim.frequency_range_hz is not None:
            lo, hi = lim.frequency_range_hz
            out += [ChannelCommand(role, frequency_hz=lo + (hi - lo) * u, amplitude=a0 + (a - a0) * u)
                    for u in (0.1, 0.5, 0.9, 0.5, 0.0)]
        else:
            out += [ChannelCommand(role, amplitude=a0 + (a - a0) * u) for u in (0.1, 0.5, 0.9, 0.5, 0.0)]
    if not out:
        out = [ChannelCommand(role)]
    return out


def _drive_size(c: ChannelCommand) -> float:
    """How hard ``c`` drives: its force plus its amplitude (absolute values)."""
    return abs(c.force_n or 0.0) + abs(c.amplitude or 0.0)


def _startable_commands(act: Actuator) -> list[ChannelCommand]:
    """The normal commands (:func:`_normal_commands`) the safety layer's start gate lets
    through from rest (force within ``start_max_force_n``), smallest drive first; all of
    them when none is."""
    gate = getattr(act.safety.settings, "start_max_force_n", None)
    cmds = _normal_commands(act)
    ok = [k for k in cmds if gate is None or abs(k.force_n or 0.0) <= gate] or cmds
    return sorted(ok, key=_drive_size)


def _edge_commands(act: Actuator) -> list[ChannelCommand]:
    """Commands at the edges of the declared limits, which :func:`_normal_commands` (10..90 %
    of each range) never reaches: the declared ``max_force_n``; the lowest and the highest
    declared frequency at half the amplitude range; the declared ``max_amplitude`` at
    the middle of the frequency range. A device declaring more than it does (an amplifier
    saturating short of its declared maximum, a coil that cannot reach its lowest declared
    frequency) fails ``output-follows-command`` on them."""
    lim = act.limits
    role = act.channel
    out = []
    if lim.max_force_n is not None:
        out.append(ChannelCommand(role, force_n=float(lim.max_force_n)))
    if lim.max_amplitude is not None:
        a = float(lim.max_amplitude)
        a0 = float(getattr(lim, "min_amplitude", None) or 0.0)
        if lim.frequency_range_hz is not None:
            lo, hi = (float(v) for v in lim.frequency_range_hz)
            mid = a0 + 0.5 * (a - a0)
            out += [ChannelCommand(role, frequency_hz=lo, amplitude=mid),
                    ChannelCommand(role, frequency_hz=hi, amplitude=mid),
                    ChannelCommand(role, frequency_hz=0.5 * (lo + hi), amplitude=a)]
        else:
            out.append(ChannelCommand(role, amplitude=a))
    return out


class _Spy:
    """Wraps an actuator's backend methods to see what reaches the hardware."""

    def __init__(self, act: Actuator) -> None:
        self.sent: list[ChannelCommand] = []
        self.stops = 0
        cmd, stop = act._command, act._stop

        def _command(c: ChannelCommand) -> None:
            self.sent.append(c)
            cmd(c)

        def _stop() -> None:
            self.stops += 1
            stop()
        act._command = _command  # type: ignore[method-assign, assignment]
        act._stop = _stop  # type: ignore[method-assign]


def _drive(act: Actuator, cmds: Sequence[ChannelCommand], dt: float = 0.001) -> list[Any]:
    """Send commands 1 ms apart (stepping simulated devices); return states or sent commands."""
    out: list[Any] = []
    t = 0.0
    for c in cmds:
        t += dt
        _sim_advance(dt)
        sent = act.command(c, now=t)
        if isinstance(act, HapticDevice):
            act.step(dt)
            st = act.read_state()
            out.append((np.array(st.position_mm, float).round(12).tolist(),
                        np.array(st.force_n, float).round(12).tolist()))
        else:
            out.append((sent.force_n, sent.frequency_hz, sent.amplitude))
        rb = act.read_back()
        if rb is not None:
            out.append(("read-back", rb.force_n, rb.frequency_hz, rb.amplitude))
    return out


def _full_scale(act: Actuator) -> tuple[float, float, float]:
    """(force N, frequency Hz, amplitude) scales for read-back tolerances."""
    lim = act.limits
    return (float(lim.max_force_n or 1.0), float(lim.frequency_range_hz[1] if lim.frequency_range_hz else 1.0),
            float(lim.max_amplitude or 1.0))


def _reports_output(act: Any) -> bool:
    return getattr(act, "readback_source", "drive") == "output"


#: read-back tolerance of one field (:func:`hapticsdk.devices.actuators.readback_tolerance`: the
#: rule the render's final check uses too)
_tol = readback_tolerance


def _settle_ticks(act: Actuator, *, ramp: bool = False, period: float = KIT_PERIOD_S) -> int:
    """Ticks of ``period`` (default the kit's) to hold a command before its read-back is
    judged: the actuator's declared settle time (its own ramps and lag), plus the safety
    layer's start ramp time when ``ramp``, plus two ticks (the command of the tick and the
    one that observes it)."""
    t = float(getattr(act, "settle_time_s", 0.0) or 0.0)
    if ramp:
        t += float(getattr(act.safety.settings, "ramp_time_s", 0.0) or 0.0)
    return int(math.ceil(t / period - 1e-9)) + 2


#: kit time (s) a command is held at most while the safety layer's output still changes
#: (a declared force-rate limit slewing); beyond it the read-back is judged anyway
HOLD_LIMIT_S = 5.0


def _hold(act: Actuator, cmd: ChannelCommand, t: float, period: float = KIT_PERIOD_S, *, ramp: bool = True
          ) -> tuple[ChannelCommand | None, float]:
    """Send ``cmd`` every tick of ``period`` (default the kit's), advancing simulated time,
    for the safety layer's start ramp (unless ``ramp`` is False: the layer is past it)
    plus the declared settle time (:func:`_settle_ticks`), and on while what the layer lets through has changed within the last settle time (a
    declared ``max_force_rate_n_per_tick`` still slewing; the layer is asked by its output),
    up to :data:`HOLD_LIMIT_S`. Returns the command in force and the kit time."""
    sent, _, t = _hold_both(act, cmd, None, None, t, period, ramp=ramp)
    return sent, t


def _hold_both(a: Actuator, ca: ChannelCommand, b: Actuator | None, cb: ChannelCommand | None,
               t: float, period: float = KIT_PERIOD_S, *, ramp: bool = True
               ) -> tuple[ChannelCommand | None, ChannelCommand | None, float]:
    """:func:`_hold` on two open actuators at once: ``ca`` sent to ``a`` and ``cb`` to
    ``b`` every tick (``cb`` None: ``b`` only has its time advanced; ``b`` None: ``a``
    alone), until each has been steady for its own settle time after both safety layers'
    ramps. Returns what each safety layer let through and the kit time."""
    pair = [(a, ca)] + ([(b, cb)] if b is not None else [])
    least = max(_settle_ticks(x, ramp=ramp, period=period) for x, _ in pair)
    settle = [_settle_ticks(x, period=period) for x, _ in pair]
    sent: list[ChannelCommand | None] = [None] * len(pair)
    steady = [0] * len(pair)
    for i in range(max(least, int(math.ceil(HOLD_LIMIT_S / period)))):
        t += period
        for j, (x, c) in enumerate(pair):
            now = x.command(c, now=t) if c is not None else None
            _advance(x, period)
            steady[j] = steady[j] + 1 if now == sent[j] else 1
            sent[j] = now
        if i + 1 >= least and all(n >= m for n, m in zip(steady, settle)):
            break
    return sent[0], (sent[1] if len(sent) > 1 else None), t


def _advance(act: Actuator, dt: float = KIT_PERIOD_S) -> None:
    """One kit tick of simulated time for an actuator that models it (``step(dt)``: a
    HapticDevice, a simulated plate or Peltier)."""
    _sim_advance(dt)
    step = getattr(act, "step", None)
    if callable(step):
        step(dt)


def _rest_after(act: Actuator, when: str) -> None:
    """Hold no command for the declared settle time (advancing simulated time), then the
    read-back must show rest."""
    n = _settle_ticks(act)
    for _ in range(n):
        if act.is_open:
            _advance(act)
    _assert_rest(act, act.read_back(), f"{when} and {n} ticks of {KIT_PERIOD_S * 1e3:g} ms (its declared settle "
                                       f"time {getattr(act, 'settle_time_s', 0.0):g} s)")


def _assert_rest(act: Actuator, rb: ChannelCommand | None, when: str) -> None:
    if rb is None:
        return
    lim = act.limits
    fs_f, _, fs_a = _full_scale(act)
    if rb.force_n is not None:
        tol = _tol(act, getattr(lim, "force_resolution_n", None), fs_f)
        assert abs(rb.force_n) <= tol, f"output {rb.force_n:g} N {when}, expected 0 N"
    if rb.amplitude is not None:
        rest = float(getattr(act, "rest_amplitude", 0.0))
        tol = _tol(act, lim.amplitude_resolution, fs_a)
        assert abs(rb.amplitude - rest) <= tol, \
            f"output amplitude {rb.amplitude:g} {act.limits.amplitude_unit} {when}, expected {rest:g} (rest)"


def _assert_matches(act: Actuator, sent: ChannelCommand | None, rb: ChannelCommand | None) -> None:
    """The read-back equals the command the safety layer let through."""
    if sent is None or rb is None:
        return
    lim = act.limits
    fs_f, fs_hz, fs_a = _full_scale(act)
    if sent.force_n is not None and not (isinstance(act, HapticDevice) and lim.max_force_n is None):
        got = rb.force_n if rb.force_n is not None else 0.0
        tolf = _tol(act, getattr(lim, "force_resolution_n", None), fs_f)
        assert abs(got - sent.force_n) <= tolf, \
            (f"commanded {sent.force_n:g} N (within its declared limits), the device outputs {got:g} N "
             f"(tolerance {tolf:.3g} N)")
    if sent.amplitude is not None:
        got = rb.amplitude if rb.amplitude is not None else 0.0
        tol = _tol(act, lim.amplitude_resolution, fs_a)
        assert abs(got - sent.amplitude) <= tol, \
            (f"commanded amplitude {sent.amplitude:g} {lim.amplitude_unit}, the device outputs {got:g} "
             f"(tolerance {tol:.3g})")
        if sent.frequency_hz is not None and sent.amplitude > 0:
            gf = rb.frequency_hz if rb.frequency_hz is not None else float("nan")
            tolf = _tol(act, lim.frequency_resolution_hz, fs_hz)
            assert abs(gf - sent.frequency_hz) <= tolf, \
                f"commanded {sent.frequency_hz:g} Hz, the device outputs {gf:g} Hz (tolerance {tolf:.3g} Hz)"


#: step lengths (s) of the state rule's run of a simulated device, in turn: the kit period,
#: its half and its double (the realtime loop steps by the measured period)
STATE_STEPS_S = (KIT_PERIOD_S, 0.5 * KIT_PERIOD_S, 2.0 * KIT_PERIOD_S)

def _sensed_run(a: HapticDevice, cmd: ChannelCommand, n_on: int, n_off: int,
                kept: list[tuple[int, Any, dict[str, np.ndarray]]] | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Drive an open simulated device with ``cmd`` for ``n_on`` steps, then stop it and
    step ``n_off`` more, reading the state before the first step and after each:
    ``(dt (n,), t (n+1,), position (n+1, 3), velocity (n+1, 3))``, copies of what each
    state said when it was read. ``kept``, when given, receives ``(reading, state, its
    arrays as read)`` for every reading (:func:`_stale_states` compares them later)."""
    n = n_on + n_off
    dts = np.array([STATE_STEPS_S[i % len(STATE_STEPS_S)] for i in range(n)])
    ts, xs, vs = [], [], []

    def read() -> None:
        st = a.read_state()
        ts.append(float(st.t))
        # copies: a state whose arrays the device keeps writing would otherwise show
        # every reading as the last one (and still moving as its velocity says)
        xs.append(np.array(st.position_mm, float).reshape(3))
        vs.append(np.array(st.velocity_mm_s, float).reshape(3))
        if kept is not None:
            kept.append((len(ts) - 1, st, {k: np.array(getattr(st, k), float)
                                           for k in ("position_mm", "velocity_mm_s", "force_n")}))
    read()
    t = 0.0
    for i in range(n):
        if i < n_on:
            a.command(cmd, now=t)
        elif i == n_on:
            a.stop()
        _advance(a, float(dts[i]))
        t += float(dts[i])
        read()
    return dts, np.array(ts), np.array(xs), np.array(vs)


def _second_states(make: Any, cmd: ChannelCommand, n: int, drive_first: bool) -> list[list[float]] | str:
    """Two new instances of a simulated device open at once, both stepped for ``n`` kit
    ticks, the first sent ``cmd`` every tick when ``drive_first`` (else nothing): the
    second's state (t, position, velocity) after each step, as plain floats. A text (why)
    when the second instance cannot open while the first is open (one device, one port)."""
    a, b = make(), make()
    with a:
        try:
            b.open()
        except Exception as exc:   # noqa: BLE001 - one device, one port: nothing to compare
            b.close()
            return f"{type(exc).__name__}: {exc}"
        try:
            out: list[list[float]] = []
            t = 0.0
            for _ in range(n):
                if drive_first:
                    a.command(cmd, now=t)
                _advance(a)
                step = getattr(b, "step", None)
                if callable(step):
                    step(KIT_PERIOD_S)
                t += KIT_PERIOD_S
                st = b.read_state()
                out.append([float(st.t)] + np.asarray(st.position_mm, float).tolist()
                           + np.asarray(st.velocity_mm_s, float).tolist())
            return out
        finally:
            b.close()


def _stale_states(kept: list[tuple[int, Any, dict[str, np.ndarray]]]) -> str | None:
    """The first state of ``kept`` (:func:`_sensed_run`) whose arrays no longer say what
    they said when it was read, as a message; None when every one still does."""
    for i, st, said in kept:
        for k, v in said.items():
            now = np.asarray(getattr(st, k), float)
            if not np.array_equal(now, v):
                return (f"the state read at reading {i} of {len(kept)} now says {k} {now.tolist()}, but said "
                        f"{v.tolist()} when it was read: read_state() hands out arrays the device goes on "
                        f"writing (a state is a reading at its time t: a recording, a filter or the loop's "
                        f"last reading keeps it); return copies or read-only arrays")
    return None


def _kinematics_error(dts: np.ndarray, xs: np.ndarray, vs: np.ndarray, q: float) -> str | None:
    """The first reading whose change of position since the first one disagrees with the
    velocity the device reports, or None. Between two readings the velocity is taken to
    lie between its two readings (monotone within a step: a smooth motion sampled at its
    step, a velocity that jumps once, a backward difference over the step), so the change
    of position lies between the sums of the lower and of the higher of each pair times the
    step, widened by one encoder count ``q`` (each of the two positions is off by at most
    half a count) and float rounding."""
    lo = np.cumsum(np.minimum(vs[:-1], vs[1:]) * dts[:, None], axis=0)
    hi = np.cumsum(np.maximum(vs[:-1], vs[1:]) * dts[:, None], axis=0)
    dx = xs[1:] - xs[0]
    eps = 1e-9 * (np.abs(xs[1:]) + np.abs(xs[0]) + np.cumsum(np.abs(vs[1:]) * dts[:, None], axis=0)) + 1e-12
    bad = (dx < lo - q - eps) | (dx > hi + q + eps)
    if not bad.any():
        return None
    k, j = (int(v) for v in np.argwhere(bad)[0])
    return (f"after {k + 1} steps ({float(np.sum(dts[:k + 1])):g} s) position {'xyz'[j]} moved {dx[k, j]:.6g} mm, "
            f"but the velocity it reports (mm/s) integrates to {lo[k, j]:.6g}..{hi[k, j]:.6g} mm (+- one encoder "
            f"count, {q:g} mm): the velocity is not in mm/s, or the position or the velocity is not updated")


#: writes of the lost-write part of ``output-follows-command`` (alternating between two
#: commands: a device losing every second write, or one in four, misses one of them)
ALTERNATE_WRITES = 4


def _drive_field(act: Actuator, c: ChannelCommand) -> tuple[str, float, float]:
    """(field, value, tolerance) of what drives the output of ``c``: its force, else its
    amplitude, with the read-back tolerance of that field."""
    lim = act.limits
    fs_f, _, fs_a = _full_scale(act)
    if c.force_n is not None:
        return "force_n", float(c.force_n), _tol(act, getattr(lim, "force_resolution_n", None), fs_f)
    return "amplitude", float(c.amplitude or 0.0), _tol(act, lim.amplitude_resolution, fs_a)


def _alternate_once(act: Actuator, t: float) -> None:
    """Lost writes (part of ``output-follows-command``): the kit's holds send the same
    command every tick, so a device that loses every second write still shows it. Here the
    two largest distinct normal commands alternate, each written once and then held, with
    no further write, for the declared settle time (:func:`_settle_ticks`); by then the
    output must have left the previous command (a write has an effect; a device whose
    ramp advances per write, not per second, has moved one step). The kit's own safety
    layer is told that servo period (``set_period``: a command stays in force that long) and
    a restart gap above it, for this part only."""
    cmds: list[ChannelCommand] = []
    for c in sorted(_normal_commands(act), key=_drive_size, reverse=True):
        if all(_drive_size(c) != _drive_size(k) for k in cmds):
            cmds.append(c)
    if len(cmds) < 2:
        return
    pair = cmds[:2]
    n = _settle_ticks(act)
    settings = act.safety.settings
    act.safety.configure(stale_after_s=n * KIT_PERIOD_S,
                         restart_after_s=max(settings.restart_after_s, (n + 1) * KIT_PERIOD_S))
    try:
        prev, t = _hold(act, pair[0], t)
        for i in range(ALTERNATE_WRITES):
            t += KIT_PERIOD_S
            sent = act.command(pair[(i + 1) % 2], now=t)
            _advance(act)
            for _ in range(n - 1):
                t += KIT_PERIOD_S
                _advance(act)
            rb = act.read_back()
            if prev is None or rb is None:
                return
            field, p, tol = _drive_field(act, prev)
            s = _drive_field(act, sent)[1]
            r = getattr(rb, field)
            r = 0.0 if r is None else float(r)
            assert abs(s - p) <= 2 * tol or abs(r - p) > tol, \
                (f"one write of {field} {s:g} held for {n} ticks (its declared settle time and two ticks): the "
                 f"output stayed at the previous command's {p:g} ({r:g}): a lost write (the same command written "
                 f"every tick hides it)")
            prev = sent
    finally:
        act.safety.settings = settings

#: servo period (s) at which ``output-follows-command`` holds the largest normal command
#: again, on a new simulated instance: twice the kit's (a 500 Hz loop; a scene's
#: ``servo.period_s`` may be 0.1..100 ms). A simulated output that is advanced by a fixed
#: step per ``step()`` call, not by ``dt``, settles that much slower in seconds than it
#: declares
SLOW_PERIOD_S = 2e-3


def _follows_at_period(make: Any, period: float = SLOW_PERIOD_S) -> None:
    """On a new instance, commanded and stepped every ``period`` (its safety layer told that
    period, ``set_period``): the largest normal command held through the start ramp, then
    the smallest held for the declared settle time (a step from one to the other: the
    safety layer's start ramp, which a slow output can follow, is over); the read-back
    must then match the smallest as at the kit's period (:func:`_assert_matches`). Only for
    a simulated actuator that has a ``step``: a real one moves on its own clock."""
    act = make()
    if not getattr(act, "simulated", False) or not callable(getattr(act, "step", None)):
        return
    cmds = sorted(_normal_commands(act), key=_drive_size, reverse=True)
    if len(cmds) < 2 or _drive_size(cmds[0]) == _drive_size(cmds[-1]):
        return
    with act:
        act.safety.set_period(period)
        _, t = _hold(act, cmds[0], 0.0, period)
        sent, _ = _hold(act, cmds[-1], t, period, ramp=False)
        rb = act.read_back()
        try:
            _assert_matches(act, sent, rb)
        except AssertionError as exc:
            raise AssertionError(
                f"at a {period * 1e3:g} ms servo period (commanded and stepped every {period * 1e3:g} ms; a step "
                f"from the largest to the smallest normal command held for the declared settle time of "
                f"{act.settle_time_s:g} s): {exc}. It follows "
                f"at the kit's {KIT_PERIOD_S * 1e3:g} ms: the simulation advances by a fixed step per step() call, "
                f"not by dt, so it settles slower in seconds at a longer period (a scene's servo.period_s may be "
                f"0.1..100 ms); advance it by dt") from None


#: contact normals (unit vectors, device coordinates) ``output-follows-command`` sends a
#: force along (``ChannelCommand.direction``): the underside of an object (-y) and a
#: slanted face (0.6, 0.8, 0)
DIRECTIONS = ((0.0, -1.0, 0.0), (0.6, 0.8, 0.0))


def _follows_direction(make: Any) -> None:
    """On a new instance of an actuator that takes ``force_n``: half its declared
    ``max_force_n`` (at most what the safety layer's start gate lets through) held from
    rest along each of :data:`DIRECTIONS`, and the read-back's force along
    y (its ``force_n`` times its own direction's y, +y when it gives none) must be the
    command's projection on y, ``force_n * direction[1]``, within the force tolerance of
    :func:`_assert_matches`. ``direction`` is the unit vector the force pushes along (the
    contact normal; None is +y): a device rendering along one axis applies the projection
    on its axis (the simulated Omni: y), a device rendering in 3-D the whole vector; both
    give that y component. A device that declares no ``max_force_n`` is not judged (as
    in :func:`_assert_matches`)."""
    act = make()
    lim = act.limits
    if lim.max_force_n is None or "force_n" not in act.accepted_fields():
        return
    gate = getattr(act.safety.settings, "start_max_force_n", None)
    f = 0.5 * float(lim.max_force_n) if gate is None else min(0.5 * float(lim.max_force_n), float(gate))
    with act:
        t = 0.0
        for d in DIRECTIONS:
            act.stop()   # from rest: the force the safety layer's start gate lets through
            sent, t = _hold(act, ChannelCommand(act.channel, force_n=f, direction=d), t)
            rb = act.read_back()
            if sent is None or rb is None or sent.force_n is None:
                continue
            want = sent.force_n * (sent.direction[1] if sent.direction is not None else 1.0)
            got = (rb.force_n or 0.0) * (rb.direction[1] if rb.direction is not None else 1.0)
            tolf = _tol(act, getattr(lim, "force_resolution_n", None), _full_scale(act)[0])
            assert abs(got - want) <= tolf, \
                (f"commanded {sent.force_n:g} N along direction {d} (a contact normal), the device outputs "
                 f"{got:g} N along y, expected the projection {want:g} N (tolerance {tolf:.3g} N): it ignores "
                 f"ChannelCommand.direction, so on a face whose normal is not +y it pushes the wrong way; apply "
                 f"force_n * direction (or its projection on the axis you render)")


def _sensed_force_error(make: Any) -> str | None:
    """What is wrong with the force a simulated device's state reports, as text (None:
    nothing). On a new instance the largest normal command the start gate lets through is
    held (:func:`_hold`); the state's ``force_n`` (the force currently applied, N) must
    then be the read-back's force along y (as :func:`_follows_direction` reads it) within
    two force tolerances of :func:`_assert_matches` (the read-back's resolution and the
    state's). A state that reports no force (all zero) is not judged: a device may not
    sense it. Only devices that declare ``max_force_n`` (as :func:`_assert_matches`)."""
    act = make()
    lim = act.limits
    if lim.max_force_n is None or not isinstance(act, HapticDevice):
        return None
    cmds = [c for c in _startable_commands(act) if c.force_n]
    if not cmds:
        return None
    with act:
        sent, _ = _hold(act, cmds[-1], 0.0)
        rb = act.read_back()
        st = act.read_state()
    if sent is None or rb is None:
        return None
    f = np.array(st.force_n, float).reshape(3)
    if not f.any():
        return None
    want = (rb.force_n or 0.0) * (rb.direction[1] if rb.direction is not None else 1.0)
    tolf = 2 * _tol(act, getattr(lim, "force_resolution_n", None), _full_scale(act)[0])
    if abs(f[1] - want) <= tolf:
        return None
    return (f"holding {sent.force_n:g} N (settled: the read-back gives {want:g} N along y), read_state() reports "
            f"force_n {f.tolist()} N: its y component {f[1]:g} N is not the force applied (tolerance {tolf:.3g} N); "
            f"DeviceState.force_n is the force the device applies now, in N, in device coordinates (a sign "
            f"flipped, mN, or the last command instead of the output?)")


def _reached_at_write(act: Actuator, prev: ChannelCommand | None, new: ChannelCommand | None,
                      rb: ChannelCommand | None) -> bool | None:
    """Whether the read-back ``rb``, taken the instant ``new`` was written after ``prev`` had
    settled (no simulated time between), already shows ``new`` in every field where the
    two commands differ by more than twice the read-back tolerance; None when they do
    not differ so (or nothing to compare)."""
    if prev is None or new is None or rb is None:
        return None
    lim = act.limits
    fs_f, fs_hz, fs_a = _full_scale(act)
    pairs = [("force_n", _tol(act, getattr(lim, "force_resolution_n", None), fs_f)),
             ("amplitude", _tol(act, lim.amplitude_resolution, fs_a))]
    if (new.amplitude or 0.0) > 0 and (prev.amplitude or 0.0) > 0:
        pairs.append(("frequency_hz", _tol(act, lim.frequency_resolution_hz, fs_hz)))
    reached = []
    for field, tol in pairs:
        p, n = getattr(prev, field), getattr(new, field)
        if p is None or n is None or abs(float(n) - float(p)) <= 2 * tol:
            continue
        r = getattr(rb, field)
        reached.append(r is not None and abs(float(r) - float(n)) <= tol)
    return all(reached) if reached else None


#: wall time (s) the ``close`` rule gives a thread started while the actuator was open to
#: end once ``close()`` has returned: the timing rules' sampling window
#: (:data:`TIMING_WINDOW_S`), scheduling on a loaded machine; a thread that close() told
#: to stop ends within it, one nobody told runs on
THREAD_GRACE_S = 1.0


def _threads_left(before: set[threading.Thread]) -> list[threading.Thread]:
    """Threads alive now that were not in ``before``, each given up to
    :data:`THREAD_GRACE_S` of wall time (all together) to end."""
    end = _monotonic() + THREAD_GRACE_S
    left = []
    for th in threading.enumerate():
        if th in before or th is threading.current_thread() or isinstance(th, threading._DummyThread):
            continue   # a _DummyThread stands for a foreign (native) thread: listed until exit
        th.join(max(end - _monotonic(), 0.0))
        if th.is_alive():
            left.append(th)
    return left


#: servo time (s) of the ``timing`` rule's long run: every command of one second of a
#: 1 kHz loop is timed (a stall rarer than once per this many commands may go unseen)
STALL_RUN_S = 1.0


def _command_run(act: Actuator) -> Iterator[tuple[int, float]]:
    """A run of :data:`STALL_RUN_S` of kit ticks: the normal commands in turn, simulated
    time advancing; yields (index, wall s of that ``command()``) after each command."""
    cmds = _normal_commands(act)
    t = 0.0
    for i in range(int(round(STALL_RUN_S / KIT_PERIOD_S))):
        t += KIT_PERIOD_S
        t0 = _perf_counter()
        act.command(cmds[i % len(cmds)], now=t)
        d = _perf_counter() - t0
        _advance(act)
        yield i, d


def _stalls(act: Actuator, limit_s: float) -> list[tuple[int, float]]:
    """(index, wall s) of the commands of :func:`_command_run` that took longer than
    ``limit_s``."""
    return [(i, d) for i, d in _command_run(act) if d > limit_s]


class _StillProbe(HapticDevice):
    """The servo-loop rule's sensing device: a simulated stylus held still 1 mm into the
    version-1 plane (in contact), commanding nothing itself."""
    name = "kit-still-probe"
    simulated = True
    limits = ActuatorLimits(max_force_n=1.0)

    def __init__(self) -> None:
        super().__init__()
        self.t = 0.0

    def _command(self, cmd: ChannelCommand) -> None:
        pass

    def _stop(self) -> None:
        pass

    def _read_state(self) -> Any:
        from ...devices.actuators import DeviceState
        return DeviceState(t=self.t, position_mm=np.array([0.0, -1.0, 0.0]), velocity_mm_s=np.zeros(3))

    def _step(self, dt: float) -> None:
        self.t += dt


class _Replay(DimensionRenderer):
    """Sends one command on one role every tick (the servo-loop rule's renderer)."""

    def __init__(self, cmd: ChannelCommand) -> None:
        self.roles = (cmd.role,)
        self.cmd = cmd

    def tick(self, inp: TickInput) -> list[ChannelCommand]:
        c = self.cmd
        return [ChannelCommand(c.role, force_n=c.force_n, frequency_hz=c.frequency_hz, amplitude=c.amplitude)]


class _LastSent:
    """Servo-loop recorder: what the loop's safety layer let through on ``role`` and the
    actuator's read-back, at the last tick."""

    def __init__(self, act: Actuator) -> None:
        self.act = act
        self.sent: ChannelCommand | None = None
        self.rb: ChannelCommand | None = None

    def record(self, t: float, state: Any, sent: Mapping[str, ChannelCommand]) -> None:
        self.sent = sent.get(self.act.channel)
        self.rb = self.act.read_back()

    def close(self) -> None:
        pass


def _in_servo_loop(act: Actuator, cmd: ChannelCommand) -> tuple[ChannelCommand | None, ChannelCommand | None]:
    """Drive ``act`` (closed) with ``cmd`` from the core's :class:`ServoLoop`, simulated
    time, in a worker thread of the standard library's (no kit code on its stack while the
    actuator is commanded, as in a render), for the safety layer's start ramp, the declared
    settle time and the time a declared force-rate limit takes to slew to ``cmd``. Returns
    what the loop's safety layer let through at the last tick and the read-back then."""
    from concurrent.futures import ThreadPoolExecutor
    from ...runtime.loop import ServoLoop
    n = _settle_ticks(act, ramp=True)
    rate = act.limits.max_force_rate_n_per_tick
    if rate and cmd.force_n:
        n += int(math.ceil(abs(cmd.force_n) / rate))
    rec = _LastSent(act)
    loop = ServoLoop(_StillProbe(), [_Replay(ChannelCommand(act.channel, force_n=cmd.force_n,
                                                            frequency_hz=cmd.frequency_hz, amplitude=cmd.amplitude))],
                     {act.channel: act}, period_s=KIT_PERIOD_S, passivity=False, recorder=rec, cpu_time=False)
    _sim_advance(n * KIT_PERIOD_S)
    with ThreadPoolExecutor(1, thread_name_prefix="hapticsdk-servo") as pool:
        pool.submit(loop.run, n * KIT_PERIOD_S).result()
    return rec.sent, rec.rb


def _takes_option(cls: type, key: str) -> bool:
    """Whether the constructor of actuator class ``cls`` takes the keyword option ``key``:
    named in its signature (without a ``**`` catch-all), else as the constructor answers
    when given ``key=None`` (with the class's ``conformance_options``): refused as unknown
    (a ``TypeError`` for an unexpected keyword, the core's ``ValidationError`` on
    ``options``) or not. Asking the constructor follows ``**kwargs`` forwarded to a base
    class, whatever the parameter is called; nothing is opened."""
    import inspect
    try:
        params = inspect.signature(cls).parameters   # the constructor's, without self
    except (TypeError, ValueError):
        params = None
    if params is not None:
        p = params.get(key)
        if p is not None and p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD):
            return True
        if not any(q.kind is q.VAR_KEYWORD for q in params.values()):
            return False
    base = cls.conformance_options() if hasattr(cls, "conformance_options") else {}
    try:
        cls(**{**base, key: None})
    except TypeError as exc:
        return "unexpected keyword" not in str(exc) or repr(key) not in str(exc)
    except ValidationError as exc:
        return not (exc.field == "options" and repr(key) in str(exc))
    except Exception:   # noqa: BLE001 - it read the option and disliked None: it takes it
        return True
    return True
