"""The rules of the ``actuator`` and ``device`` kinds (``RULES['actuator']``, plus ``state`` for a
device): class and template, declared limits and options, lifecycle and close, bad input,
limits enforced, safe stop, read-back, output following the command, reopen, instances,
the servo loop, determinism and timing."""

from __future__ import annotations

import json
import math
import numbers
import threading
from typing import Any, Callable, cast

import numpy as np

from ...devices.actuators import CHANNELS, Actuator, ActuatorLimits, HapticDevice
from ...errors import DeviceError, PluginError, ValidationError
from ...perception.dimensions import ChannelCommand
from .actuator_drive import (STALL_RUN_S, THREAD_GRACE_S, _Spy, _advance, _alternate_once, _assert_matches,
                             _command_run, _follows_at_period, _follows_direction,
                             _assert_rest, _drive, _drive_size, _edge_commands, _full_scale, _hold, _hold_both,
                             _in_servo_loop, _kinematics_error, _normal_commands, _over_limit_commands,
                             _reached_at_write, _reports_output, _rest_after, _sensed_force_error, _sensed_run, _settle_ticks,
                             _second_states, _stale_states, _stalls, _startable_commands, _takes_option,
                             _threads_left, _tol)
from .runner import _Ctx, _run_rules
from .timing import COMMAND_BUDGET, KIT_PERIOD_S, TIMING_CALLS, _fastest, _sim_advance
from .values import _finite, _refuses


#: the safety settings a plugin may not loosen, and which way is looser: a shorter ramp, a
#: later stale or restart gap, a start gate that lets more through (or none: None), a later
#: knee of the speed-dependent force limit, more force on top of the stiffness limit
_LOOSER = {"ramp_time_s": "lower", "stale_after_s": "higher", "restart_after_s": "higher",
           "start_max_penetration_mm": "higher", "start_max_force_n": "higher", "velocity_knee": "higher",
           "stiffness_offset_n": "higher"}


def _safety_loosened(cls: Any) -> str | None:
    """Which safety setting an instance built without a ``safety`` argument (its
    ``conformance_options()`` only) has looser than :class:`SafetySettings`' defaults, after
    construction and, for a simulated actuator, after ``open()``, as text (None: none). The
    settings are the application's (a scene's, the user's, the defaults); a plugin may
    tighten them, never loosen them: a ramp of 0 s or no start gate lets a full force step
    reach the hardware at start."""
    from ...devices.safety import SafetySettings
    if not isinstance(cls, type):
        return None
    default = SafetySettings()
    try:
        a = cls(**(cls.conformance_options() if hasattr(cls, "conformance_options") else {}))
    except Exception:   # noqa: BLE001 - needs options only the application has (a port): the other rules build it
        return None

    def looser(when: str) -> str | None:
        s = a.safety.settings
        for k, way in _LOOSER.items():
            v, d = getattr(s, k), getattr(default, k)
            if v == d:
                continue
            if (v is None and d is not None) or (d is not None and v is not None and
                                                 (v < d if way == "lower" else v > d)):
                return (f"its safety layer's {k} is {v!r} {when}, looser than the default {d!r}: the safety "
                        f"settings are the application's (a scene, the user, SafetySettings' defaults); a plugin "
                        f"may tighten them, never loosen them")
        return None
    why = looser("after construction")
    if why is None and getattr(cls, "simulated", False):
        with a:
            why = looser("after open()")
    return why


def _capability_error(cls: Any) -> str | None:
    """What is wrong with ``cls.capability_for(conformance options)`` against the class's
    declared limits, as text (None: nothing). The compiler solves a dimension's features
    within it (``device_constraints``); the safety layer clamps every command to the limits,
    so a capability beyond them is something the actuator cannot output: its channel must
    be the actuator's, its band within ``frequency_range_hz``, its ``max_drive`` at most
    ``max_amplitude`` (compared in one unit where ``drive_unit`` and ``amplitude_unit``
    parse as units of one quantity: a drive in mV against limits in V is converted; units
    of two quantities fail). Only what both declare is compared."""
    from ...devices.actuators import DriveCapability
    from ...units import parse_unit
    opts = cls.conformance_options() if hasattr(cls, "conformance_options") else {}
    cap = cls.capability_for(opts)
    if cap is None:
        return None
    if not isinstance(cap, DriveCapability):
        return f"capability_for() returned {type(cap).__name__}, not a DriveCapability (or None)"
    lim = cls.limits
    if cap.channel != cls.channel:
        return f"capability_for() describes channel {cap.channel!r}; the actuator's channel is {cls.channel!r}"
    band, declared = cap.frequency_range_hz, lim.frequency_range_hz
    if band is not None and declared is not None:
        lo, hi = (float(v) for v in band)
        dlo, dhi = (float(v) for v in declared)
        if not (lo >= dlo - 1e-9 * dhi and hi <= dhi * (1 + 1e-9)):
            return (f"capability_for() gives the band {lo:g}..{hi:g} Hz, beyond the declared frequency_range_hz "
                    f"{dlo:g}..{dhi:g} Hz the safety layer clamps to: the compiler would solve for frequencies "
                    f"it cannot play")
    if cap.max_drive is not None and lim.max_amplitude is not None:
        pc, pl = parse_unit(cap.drive_unit or lim.amplitude_unit), parse_unit(lim.amplitude_unit)
        if isinstance(pc, tuple) and isinstance(pl, tuple):
            if pc[1] != pl[1]:
                return (f"capability_for() gives max_drive in {cap.drive_unit!r}, not a unit of the amplitude "
                        f"({lim.amplitude_unit!r}, limits.amplitude_unit)")
            drive = float(cap.max_drive) * pc[0] / pl[0]
            if drive > float(lim.max_amplitude) * (1 + 1e-9):
                return (f"capability_for() gives max_drive {cap.max_drive:g} {cap.drive_unit} ({drive:g} "
                        f"{lim.amplitude_unit}), above the declared max_amplitude {lim.max_amplitude:g} "
                        f"{lim.amplitude_unit} the safety layer clamps to: the compiler would solve for "
                        f"amplitudes it cannot output")
    return None


def _actuator_rules(ctx: _Ctx, device: bool) -> None:
    cls = ctx.obj

    def r_class() -> None:
        assert isinstance(cls, type) and issubclass(cls, Actuator), \
            f"entry point gives {cls!r}, not an Actuator subclass"
        if device:
            assert issubclass(cls, HapticDevice), "a device must subclass HapticDevice (it senses)"
        assert cls.name, "class attribute 'name' is empty"
        if ctx.by_name:
            assert cls.name == ctx.name, \
                f"class attribute name {cls.name!r} differs from the entry-point name {ctx.name!r}"
        assert cls.channel in CHANNELS, f"channel {cls.channel!r} not one of {CHANNELS}"
        src = getattr(cls, "readback_source", "drive")
        assert src in ("drive", "output"), f"readback_source {src!r} is neither 'drive' nor 'output'"
        assert isinstance(cls.limits, ActuatorLimits), "limits must be an ActuatorLimits"
        ok, why = cls.check_available()
        assert isinstance(ok, bool) and isinstance(why, str), "check_available() must return (bool, str)"
        for k in ("_command", "_stop"):
            assert not getattr(getattr(cls, k), "__isabstractmethod__", False), f"{k} not implemented"

    def r_limits() -> None:
        lim = cls.limits
        for k in ("max_force_n", "max_stiffness_n_per_mm", "max_amplitude", "max_velocity_mm_s",
                  "max_force_rate_n_per_tick"):
            v = getattr(lim, k)
            assert _finite(v) and (v is None or v > 0), f"limit {k}={v!r} must be a finite number > 0 or None"
        if lim.frequency_range_hz is not None:
            lo, hi = lim.frequency_range_hz
            assert _finite(lo) and _finite(hi) and 0 <= lo < hi, f"frequency_range_hz {lim.frequency_range_hz} invalid"
        if cls.channel == "force" and not (device and not _commands_force(cls)):
            assert lim.max_force_n is not None, "a force actuator must declare max_force_n"
        if cls.channel == "vibration":
            assert lim.frequency_range_hz is not None and lim.max_amplitude is not None, \
                "a vibration actuator must declare frequency_range_hz and max_amplitude"
            assert lim.amplitude_unit, "a vibration actuator must name its amplitude_unit"
        if cls.channel in ("thermal", "friction", "other"):
            assert lim.max_amplitude is not None and lim.amplitude_unit, \
                f"a {cls.channel} actuator must declare max_amplitude and amplitude_unit (the safety layer " \
                f"has nothing else to clamp)"
        for k in ("frequency_resolution_hz", "amplitude_resolution", "force_resolution_n", "settle_time_s"):
            v = getattr(lim, k, None)
            assert _finite(v) and (v is None or v > 0 or (k == "settle_time_s" and v == 0)), \
                f"limit {k}={v!r} must be a finite number > 0 or None"
        # the units it accepts are the units of its limits (a clean unit clash otherwise)
        from ...perception.features import same_unit
        acc = cls.accepted_fields()
        if "force_n" in acc:
            assert same_unit(acc["force_n"], "N"), f"accepts force_n in {acc['force_n']!r}; force_n is in newtons"
        if "frequency_hz" in acc:
            assert same_unit(acc["frequency_hz"], "Hz"), \
                f"accepts frequency_hz in {acc['frequency_hz']!r}; frequency_hz is in hertz"
        if "amplitude" in acc and lim.amplitude_unit:
            assert same_unit(acc["amplitude"], lim.amplitude_unit), \
                (f"accepts amplitude in {acc['amplitude']!r} but declares its limits in {lim.amplitude_unit!r} "
                 f"(limits.amplitude_unit): one of them is wrong")
        # what it says it can produce (device-aware solving) is within what the safety
        # layer lets it output
        why = _capability_error(cls)
        assert why is None, why

    def r_options() -> None:
        base = cls.conformance_options() if hasattr(cls, "conformance_options") else {}
        try:
            cls(**base, no_such_option_xyz=1)
        except ValidationError:
            return
        except TypeError as exc:
            raise AssertionError(f"an unknown option raised TypeError ({exc}), expected ValidationError") from None
        raise AssertionError("an unknown option was accepted silently")

    def r_lifecycle() -> None:
        a = ctx.make()
        assert not a.is_open, "a new actuator must not be open before open()"
        a.stop()  # stop on a closed actuator must not raise
        assert _refuses(DeviceError, lambda: a.command(_normal_commands(a)[0])), \
            "command() on a closed actuator did not raise DeviceError"
        with a:
            assert a.is_open
            a.open()  # idempotent
            _drive(a, _normal_commands(a))
        assert not a.is_open, "the context manager did not close the actuator"
        a.close()  # twice: no error
        a.open()
        _drive(a, _normal_commands(a)[:2])
        a.close()
        json.dumps(a.describe(), default=str)

    def r_bad_input() -> None:
        a = ctx.make()
        with a:
            for attr in ("force_n", "frequency_hz", "amplitude"):
                for bad in (float("nan"), float("inf")):
                    cmd = cast("dict[str, Any]", {attr: bad})
                    assert _refuses(ValidationError, lambda: a.command(ChannelCommand(a.channel, **cmd))), \
                        f"{attr}={bad} was accepted"
            if isinstance(a, HapticDevice):
                for bad in (0.0, -1.0, float("nan")):
                    assert _refuses(ValidationError, lambda: a.step(bad)), f"step({bad}) was accepted"

    def r_limits_enforced() -> None:
        a = ctx.make()
        spy = _Spy(a)
        lim = a.limits
        if _reports_output(a):   # the output itself, held until settled, within the declared limits
            with a:
                t = 0.0
                for c in _over_limit_commands(a):
                    _, t = _hold(a, c, t)
                    rb = a.read_back()
                    if rb is None:
                        break
                    fs_f, _, fs_a = _full_scale(a)
                    if rb.force_n is not None and lim.max_force_n is not None:
                        tol = _tol(a, getattr(lim, "force_resolution_n", None), fs_f)
                        assert abs(rb.force_n) <= lim.max_force_n + tol, \
                            f"outputs {rb.force_n:g} N, above its declared max_force_n {lim.max_force_n:g} N"
                    if rb.amplitude is not None and lim.max_amplitude is not None:
                        tol = _tol(a, lim.amplitude_resolution, fs_a)
                        assert rb.amplitude <= lim.max_amplitude + tol, \
                            (f"outputs amplitude {rb.amplitude:g} {lim.amplitude_unit}, above its declared "
                             f"max_amplitude {lim.max_amplitude:g}")
        with a:
            for c in _over_limit_commands(a):
                a.command(c, now=0.0)
                if isinstance(a, HapticDevice):
                    a.step(0.001)
                    st = a.read_state()
                    if lim.max_force_n is not None:
                        fn = float(np.linalg.norm(np.asarray(st.force_n, float)))
                        assert fn <= lim.max_force_n * (1 + 1e-6) + 1e-9, \
                            f"device reports force {fn:g} N above max_force_n {lim.max_force_n:g} N"
        for c in spy.sent:
            if c.force_n is not None and lim.max_force_n is not None:
                assert abs(c.force_n) <= lim.max_force_n * (1 + 1e-9), \
                    f"backend received force {c.force_n:g} N above max_force_n {lim.max_force_n:g} N"
            if c.frequency_hz is not None and lim.frequency_range_hz is not None:
                lo, hi = lim.frequency_range_hz
                assert lo - 1e-9 <= c.frequency_hz <= hi + 1e-9, \
                    f"backend received {c.frequency_hz:g} Hz outside frequency_range_hz {lim.frequency_range_hz}"
            if c.amplitude is not None:
                assert c.amplitude >= 0, f"backend received a negative amplitude {c.amplitude:g}"
                if lim.max_amplitude is not None:
                    assert c.amplitude <= lim.max_amplitude * (1 + 1e-9), \
                        f"backend received amplitude {c.amplitude:g} {lim.amplitude_unit} above " \
                        f"max_amplitude {lim.max_amplitude:g}"
        assert spy.sent or not _over_limit_commands(a), "no command reached the backend"

    def r_safe_stop() -> None:
        a = ctx.make()
        spy = _Spy(a)
        with a:
            _drive(a, _normal_commands(a)[:3])
            assert a.stop() is True, "stop() returned False (backend stop failed)"
            assert spy.stops >= 1, "stop() did not call the backend _stop"
            if isinstance(a, HapticDevice):
                a.step(0.001)
                f = float(np.linalg.norm(np.asarray(a.read_state().force_n, float)))
                assert f <= 1e-6, f"force {f:g} N still applied after stop()"
        n = spy.stops
        # the output itself: full drive held until settled, then stop(): at rest within the declared time
        c = ctx.make()
        with c:
            top = _normal_commands(c)
            big = max(top, key=_drive_size)
            _hold(c, big, 0.0)
            assert c.stop() is True, "stop() returned False (backend stop failed)"
            _rest_after(c, "after stop()")
        assert n >= 2, "close() did not stop the backend"
        # a failing backend is stopped by the core and reported as DeviceError
        b = ctx.make()
        with b:
            def broken(c: ChannelCommand) -> None:
                raise OSError("simulated transport failure")
            b._command = broken  # type: ignore[method-assign]
            assert _refuses(DeviceError, lambda: b.command(_normal_commands(b)[0])), \
                "a failing backend command was not reported as DeviceError"

    def r_determinism() -> None:
        runs = []
        for _ in range(2):
            a = ctx.make()
            with a:
                runs.append(_drive(a, _normal_commands(a) + _over_limit_commands(a)))
        assert runs[0] == runs[1], "the same command sequence gave different outputs on two instances"

    def r_state() -> None:
        a = ctx.make()
        # the encoder count it declares sizes the loop's speed step (TickInput.speed_step_mm_s,
        # a renderer's gate hysteresis) and the kit's own kinematics bounds: a position
        # quantum, a finite number of mm >= 0 (0 or None: an exact position). A NaN turns
        # both into NaN, and every comparison with them passes
        q_said = getattr(a, "encoder_resolution_mm", None)
        assert q_said is None or (isinstance(q_said, numbers.Real) and not isinstance(q_said, bool)
                                  and math.isfinite(q_said) and float(q_said) >= 0.0), \
            (f"declares encoder_resolution_mm {q_said!r}: a position quantum is a finite number of mm >= 0 (0 "
             f"or None for an exact position); the servo loop sizes its speed step from it")
        with a:
            st = a.read_state()
            for k in ("position_mm", "velocity_mm_s", "force_n"):
                v = np.asarray(getattr(st, k), float)
                assert v.shape == (3,), f"state.{k} has shape {v.shape}, expected (3,)"
                assert np.isfinite(v).all(), f"state.{k} is not finite"
            assert math.isfinite(st.t), "state.t is not finite"
            t0 = st.t
            for _ in range(10):
                a.step(0.001)
            assert a.read_state().t >= t0, "device time went backwards"
        assert _refuses(DeviceError, a.read_state), "read_state() on a closed device did not raise DeviceError"
        if not getattr(cls, "simulated", False):
            return   # a real device moves and keeps time on its own: nothing the kit steps
        # a simulated device: its clock advances by the steps it is given, and its position
        # changes as its velocity (mm/s) says, under a held force and coasting after stop()
        b = ctx.make()
        with b:
            big = _startable_commands(b)[-1]
            n_on = _settle_ticks(b, ramp=True) + 100
            kept: list[tuple[int, Any, dict[str, np.ndarray]]] = []
            dts, ts, xs, vs = _sensed_run(b, big, n_on, n_on, kept)
            q = float(getattr(b, "encoder_resolution_mm", 0.0) or 0.0)
        stale = _stale_states(kept)
        assert stale is None, stale
        assert (np.diff(ts) >= 0).all(), "device time went backwards while stepped"
        assert ts[-1] > ts[0], (f"device time stayed at {ts[0]:g} s over {len(dts)} steps of "
                                f"{float(np.sum(dts)):g} s in all (step(dt) advances simulated time)")
        why = _kinematics_error(np.diff(ts), xs, vs, q)
        assert why is None, why
        # the force it reports is the force it applies (N, device coordinates)
        why = _sensed_force_error(ctx.make)
        assert why is None, why
        # two simulated devices open at once keep separate physics: what the second senses
        # does not change when the first is driven (compared with two runs where the first
        # is left alone, which must agree with each other: a simulation that is not
        # reproducible cannot be compared, and is noted)
        idle = [_second_states(ctx.make, big, n_on, False) for _ in range(2)]
        if any(isinstance(r, str) for r in idle):
            ctx.note("state", f"a second instance could not open while the first was open "
                     f"({next(r for r in idle if isinstance(r, str))}); the states of two instances were not compared")
            return
        if idle[0] != idle[1]:
            ctx.note("state", "the sensed state of a second instance differs between two identical runs (a "
                     "simulation that is not reproducible); the states of two instances were not compared")
            return
        driven = _second_states(ctx.make, big, n_on, True)
        alone = cast(list, idle[0])
        if isinstance(driven, list) and driven != alone:
            at = next(i for i, (x, y) in enumerate(zip(driven, alone)) if x != y)
            raise AssertionError(
                f"a second instance senses the first's motion: stepped beside a first instance that was driven with "
                f"{big}, its state after step {at + 1} is {driven[at]} (t, position, velocity), beside an idle one "
                f"{alone[at]}: the two share their physics (a class attribute or module global); keep the "
                f"simulated state on the instance")

    def r_template() -> None:
        over = [m for m in ("open", "close", "command", "stop", "read_back")
                if getattr(cls, m) is not getattr(Actuator, m)]
        if device:
            over += [m for m in ("read_state", "step") if getattr(cls, m) is not getattr(HapticDevice, m)
                     and not getattr(cls, "simulated", False)]
        assert not over, (f"overrides the public method(s) {over}: implement the backend's _{over[0]} instead, "
                          f"so the core's checks and safety layer run")
        # nor loosens its safety layer: the settings are the application's
        why = _safety_loosened(cls)
        assert why is None, why

    def r_close() -> None:
        a = ctx.make()
        a.open()
        _drive(a, _normal_commands(a)[:2])
        try:
            a.close()
        except Exception as exc:
            raise AssertionError(f"close() raised {type(exc).__name__}: {exc} (it must never raise)") from None
        assert not a.is_open, "close() left the actuator open"
        if getattr(a, "simulated", False):
            # a simulated backend can still be asked what its model outputs once closed
            # (the core's read_back() reports rest for any closed actuator without asking):
            # after its declared settle time it must be at rest, not driving what a
            # "flush" in _close re-sent after the stop
            for _ in range(_settle_ticks(a)):
                _advance(a)
            try:
                rb = a._read_back()
            except Exception:  # noqa: BLE001 - a closed backend may refuse to answer
                rb = None
            if isinstance(rb, ChannelCommand):
                _assert_rest(a, rb, "after close() (the simulated backend's own read-back)")
        err = getattr(a, "close_error", None)
        assert err is None, (f"the backend failed while closing: {type(err).__name__}: {err} (kept in "
                             f"close_error; close() stopped and released what it could)")
        # what open() took, close() gives back: no thread started while it was open runs on
        # (the open and close above started what a library starts once per process)
        before = set(threading.enumerate())
        for _ in range(2):
            c = ctx.make()
            c.open()
            _drive(c, _normal_commands(c)[:2])
            c.close()
        left = _threads_left(before)
        assert not left, (f"{len(left)} thread(s) started while it was open still run {THREAD_GRACE_S:g} s after "
                          f"close() ({', '.join(repr(th.name) for th in left)}; two opens and closes): close() "
                          f"must stop and join what open() started, or every reopen leaves one more behind")
        b = ctx.make()
        b.open()
        stops = _Spy(b)

        def broken() -> None:
            raise OSError("simulated close failure")
        b._close = broken  # type: ignore[method-assign]
        import logging
        quiet = logging.getLogger("hapticsdk.actuators")
        level = quiet.level
        quiet.setLevel(logging.CRITICAL)   # the kit's own injected failure: not news in the log
        try:
            b.close()
        except Exception as exc:
            raise AssertionError(f"close() raised {type(exc).__name__} when the backend's _close failed") from None
        finally:
            quiet.setLevel(level)
            # the failure was the kit's own: release what the backend holds (its port, its
            # threads), or it outlives the rule and shares the device with the next one
            del b._close
            try:
                b._close()
            except Exception:  # noqa: BLE001 - best effort: the check below is the rule
                pass
        assert stops.stops >= 1, "close() did not stop the backend before releasing it"
        assert isinstance(getattr(b, "close_error", None), OSError), \
            "a failing backend _close was not reported (close_error is not set): nobody can see it"

    def r_privileged() -> None:
        from ...devices.device_options import privileged_options
        try:
            priv = privileged_options(cls)
        except PluginError as exc:
            raise AssertionError(f"the core cannot read its privileged_options: {exc}") from None
        unknown = sorted(k for k in priv if not _takes_option(cls, k))
        assert not unknown, (f"privileged_options names {unknown}, which the constructor does not take "
                             f"(it refuses them as unknown options): a misspelt name protects nothing, and "
                             f"the option it meant stays settable from scene and plan files")

    def r_read_back() -> None:
        a = ctx.make()
        with a:
            rb = a.read_back()
            assert rb is not None, ("read_back() gives None: implement _read_back (what the device outputs, "
                                    "or the backend's record of its last write)")
            _assert_rest(a, rb, "right after open()")
            _drive(a, _normal_commands(a)[:3])
            a.stop()
            _assert_rest(a, a.read_back(), "after stop()")
        _assert_rest(a, a.read_back(), "after close()")
        # read back after every command of a long run (as a servo that checks its output
        # does): a read-back that goes bad only after many reads (a counter, a buffer that
        # fills) raises in the servo loop; here it is named. The core refuses a non-finite
        # or failed read-back (DeviceError)
        a = ctx.make()
        with a:
            for i, _ in _command_run(a):
                try:
                    a.read_back()
                except DeviceError as exc:
                    raise AssertionError(f"read_back() failed after {i + 1} commands of a run, each read back: "
                                         f"{exc}") from None

    def r_follows() -> None:
        a = ctx.make()
        if not _reports_output(a):
            ctx.note("output-follows-command", "the actuator reports its drive record (readback_source 'drive'): "
                     "the kit compared what the backend wrote, not the physical output; declare "
                     "readback_source = 'output' where read_back measures or models the output")
        # a modelled output that takes time to settle cannot show a new command the
        # instant it is written (no simulated time passed)
        lags = _reports_output(a) and bool(getattr(a, "simulated", False)) and \
            float(getattr(a, "settle_time_s", 0.0) or 0.0) > 0
        instant: list[bool] = []
        with a:
            if a.read_back() is None:
                return   # reported by read-back
            t = 0.0
            sent = None
            for c in _normal_commands(a) + _edge_commands(a):
                if lags and sent is not None:
                    t += KIT_PERIOD_S
                    now = a.command(c, now=t)
                    seen = _reached_at_write(a, sent, now, a.read_back())
                    if seen is not None:
                        instant.append(seen)
                    _advance(a)
                # held until the safety layer's output has been steady for the declared
                # settle time (simulated time advances)
                sent, t = _hold(a, c, t)
                _assert_matches(a, sent, a.read_back())
            assert not (instant and all(instant)), \
                (f"the read-back showed each of {len(instant)} new commands the instant it was written, before any "
                 f"simulated time passed, though the actuator declares readback_source 'output' and a settle time "
                 f"of {a.settle_time_s:g} s: an output cannot reach a command in no time, so it reports the command "
                 f"(its drive record), not the output; report the modelled output (advanced by step(dt)) or declare "
                 f"readback_source = 'drive'")
            _alternate_once(a, t)
        # the same at a longer servo period, on a new instance: the declared settle time is in
        # seconds, whatever the period the simulation is stepped at
        _follows_at_period(ctx.make)
        # a force along a contact normal other than +y: the device renders its projection
        _follows_direction(ctx.make)

    def r_reopen() -> None:
        # one instance opened, driven, stopped and closed twice: its second life keeps
        # the contracts of the first (no stale output, stop() stops, close() does not
        # fail), so a latch or handle that open() does not reset is seen
        a = ctx.make()
        for life in ("first", "second"):
            a.open()
            try:
                if life == "second":
                    _rest_after(a, "after close() and open() again (stale output)")
                _drive(a, _normal_commands(a)[:4])
                _hold(a, max(_normal_commands(a), key=_drive_size), 0.0)
                assert a.stop() is True, f"stop() returned False in the {life} open of one instance"
                _rest_after(a, f"after stop() in the {life} open of one instance (close() and open() "
                               f"must leave stop() working)")
            finally:
                a.close()
            err = getattr(a, "close_error", None)
            assert err is None, (f"the backend failed while closing after the {life} open of one instance: "
                                 f"{type(err).__name__}: {err} (an instance must close again after open())")

    def r_instances() -> None:
        a, b = ctx.make(), ctx.make()
        with a:
            try:
                b.open()
            except Exception as exc:   # noqa: BLE001 - one device, one port: nothing to compare
                b.close()
                ctx.note("instances", f"a second instance could not open while the first was open "
                         f"({type(exc).__name__}: {exc}); the rule needs two and was skipped")
                return
            try:
                if a.read_back() is None or b.read_back() is None:
                    return   # reported by read-back
                start = [c for c in _startable_commands(a) if _drive_size(c) > 0]
                if not start:
                    return
                top = max(_normal_commands(a), key=_drive_size)   # allowed once running (past the start gate)
                # a driven, b left alone (its time advances too): b stays at rest
                t = 0.0
                sent_a, _, t = _hold_both(a, start[-1], b, None, t)
                _assert_rest(b, b.read_back(), "on a second instance while the first was driven (the two share "
                                               "their output state)")
                _assert_matches(a, sent_a, a.read_back())
                # both driven with different commands: each follows its own
                sent_a, sent_b, t = _hold_both(a, top, b, start[0], t)
                _assert_matches(b, sent_b, b.read_back())
                _assert_matches(a, sent_a, a.read_back())
                # one closed: the other goes on following its own commands (a new one)
                a.close()
                sent_b, t = _hold(b, top, t)
                _assert_matches(b, sent_b, b.read_back())
            finally:
                b.close()

    def r_timing() -> None:
        a = ctx.make()
        with a:
            cmds = _normal_commands(a)
            state: dict[str, Any] = {"t": 0.0, "i": 0}

            def one() -> None:
                state["t"] += KIT_PERIOD_S
                _sim_advance(KIT_PERIOD_S)
                a.command(cmds[state["i"] % len(cmds)], now=state["t"])
                state["i"] += 1
            best = _fastest(one, budget_s=COMMAND_BUDGET * KIT_PERIOD_S)
        assert best <= COMMAND_BUDGET * KIT_PERIOD_S, \
            (f"command() takes at least {best * 1e3:.3f} ms (fastest of {TIMING_CALLS} or more calls); a {KIT_PERIOD_S * 1e3:g} ms "
             f"servo period allows {COMMAND_BUDGET * KIT_PERIOD_S * 1e3:.3f} ms per actuator")
        # the worst call: one that blocks longer than the safety layer's restart gap makes
        # the next command a restart (a fault, the output ramped from zero); seen in two
        # runs on new instances (a preempted call does not recur at the same place)
        runs = []
        for _ in range(2):
            b = ctx.make()
            limit = float(b.safety.settings.restart_after_s)
            with b:
                runs.append(_stalls(b, limit))
            if not runs[-1]:
                return
        i = runs[0][0][0]
        d = max(w for _, w in runs[0])
        raise AssertionError(f"command() blocked for up to {d * 1e3:.0f} ms (first at call {i + 1} of a run of "
                             f"{STALL_RUN_S / KIT_PERIOD_S:.0f}; {len(runs[0])} and {len(runs[1])} calls over the limit "
                             f"in two runs), longer than the safety layer's restart_after_s {limit * 1e3:g} ms: the "
                             f"servo loop misses that many periods and the next command restarts the output from "
                             f"zero; never block in _command (a write timeout below the servo period, or a queue)")

    def r_servo_loop() -> None:
        a = ctx.make()
        if a.check_available()[0] is False:
            return
        cmd = max(_startable_commands(a), key=_drive_size)
        try:
            sent, rb = _in_servo_loop(a, cmd)
        finally:
            a.close()
        if rb is None:
            return   # reported by read-back
        try:
            _assert_matches(a, sent, rb)
        except AssertionError as exc:
            raise AssertionError(f"driven by the core's ServoLoop (as a render drives it, from a thread of its "
                                 f"own): {exc}; the kit's own holds saw it follow: it behaves differently in "
                                 f"the loop") from None

    rules: list[tuple[str, Callable[[], None]]] = [
        ("class", r_class), ("template", r_template), ("limits-declared", r_limits), ("options", r_options),
        ("privileged-options", r_privileged),
        ("lifecycle", r_lifecycle), ("close", r_close), ("bad-input", r_bad_input),
        ("limits-enforced", r_limits_enforced), ("safe-stop", r_safe_stop), ("read-back", r_read_back),
        ("output-follows-command", r_follows), ("reopen", r_reopen), ("instances", r_instances),
        ("servo-loop", r_servo_loop), ("determinism", r_determinism), ("timing", r_timing)]
    if device:
        rules.append(("state", r_state))
    _run_rules(ctx, rules, stop_after=("class",))


def _commands_force(cls: type) -> bool:
    return getattr(cls, "limits", ActuatorLimits()).max_force_n is not None
