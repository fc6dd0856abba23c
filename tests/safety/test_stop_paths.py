"""Every stop path leaves every actuator at zero (issue 13, items 2 and 3).

ServoLoop.run: any exception that leaves the loop -- KeyboardInterrupt, SystemExit, the
SafeStop of SIGTERM/SIGHUP, an OSError from a sink or a device step, anything from a
renderer, recorder or actuator -- stops every actuator first and propagates unchanged.
Exceptions the loop handles by design (an ``Exception`` from a renderer or recorder is
counted; one from a device read or command becomes a DeviceError fault) still end with
every actuator stopped.
"""

from __future__ import annotations

import errno
import signal

import numpy as np
import pytest

from hapticsdk.devices.actuators import Actuator, ActuatorLimits, stops_since
from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer
from hapticsdk.errors import DeviceError
from hapticsdk.runtime import ServoLoop, SimulatedClock
from hapticsdk.runtime.signals import SafeStop
from hapticsdk.sim.finger import press_slide
from hapticsdk.sim.probe import VirtualProbe


class Boom(BaseException):
    """An exception type nobody catches on purpose (not an Exception)."""


def _enospc() -> OSError:
    return OSError(errno.ENOSPC, "No space left on device")


#: (id, factory): every kind of exception the stop paths must survive
KINDS = [
    ("KeyboardInterrupt", lambda: KeyboardInterrupt()),
    ("SystemExit", lambda: SystemExit(3)),
    ("SafeStop-SIGTERM", lambda: SafeStop(signal.SIGTERM)),
    ("OSError-ENOSPC", _enospc),
    ("RuntimeError", lambda: RuntimeError("bug")),
    ("MemoryError", lambda: MemoryError()),
    ("BaseException", lambda: Boom("custom")),
]
BASE_ONLY = [k for k in KINDS if not isinstance(k[1](), Exception)]
EXC_ONLY = [k for k in KINDS if isinstance(k[1](), Exception)]


class Out(Actuator):
    """An output whose 'hardware' value is readable: force (N) or amplitude."""

    name = "test-out"
    simulated = True

    def __init__(self, channel: str, **kw):
        self.channel = channel
        if channel == "force":
            self.limits = ActuatorLimits(max_force_n=5.0)
        else:
            self.limits = ActuatorLimits(frequency_range_hz=(10.0, 500.0), max_amplitude=1.0)
        super().__init__(**kw)
        self.output = 0.0
        self.stops = 0
        self.raise_in_command: BaseException | None = None
        self.commands = 0

    def _command(self, cmd: ChannelCommand) -> None:
        self.commands += 1
        if self.raise_in_command is not None and self.commands >= 400:
            raise self.raise_in_command
        self.output = float(cmd.force_n if self.channel == "force" else (cmd.amplitude or 0.0))

    def _stop(self) -> None:
        self.stops += 1
        self.output = 0.0


class Probe(VirtualProbe):
    """Kinematic probe that can raise from its read or its step at tick 400."""

    def __init__(self, **kw):
        super().__init__(trajectory=press_slide(), **kw)
        self.raise_in_read: BaseException | None = None
        self.raise_in_step: BaseException | None = None
        self.reads = 0
        self.steps = 0
        self.stops = 0

    def _read_state(self):
        self.reads += 1
        if self.raise_in_read is not None and self.reads >= 400:
            raise self.raise_in_read
        return super()._read_state()

    def _step(self, dt):
        self.steps += 1
        if self.raise_in_step is not None and self.steps >= 400:
            raise self.raise_in_step
        super()._step(dt)

    def _stop(self):
        self.stops += 1
        super()._stop()


class Both(DimensionRenderer):
    """A constant force and a vibration whenever in contact; can raise at tick 400."""

    roles = ("force", "vib")

    def __init__(self):
        self.n = 0
        self.exc: BaseException | None = None

    def tick(self, inp):
        self.n += 1
        if self.exc is not None and self.n >= 400:
            raise self.exc
        on = inp.in_contact
        return [ChannelCommand("force", force_n=2.0 if on else 0.0),
                ChannelCommand("vib", frequency_hz=200.0, amplitude=0.8 if on else 0.0)]


class Rec:
    def __init__(self):
        self.n = 0
        self.exc: BaseException | None = None

    def record(self, t, st, sent):
        self.n += 1
        if self.exc is not None and self.n >= 400:
            raise self.exc


def _rig(realtime=False, clock=None):
    probe = Probe()
    force, vib = Out("force", label="force-out"), Out("vibration", label="vib-out")
    r = Both()
    rec = Rec()
    loop = ServoLoop(probe, [r], {"force": force, "vib": vib}, passivity=False, recorder=rec,
                     realtime=realtime, clock=clock)
    return loop, probe, force, vib, r, rec


def _outputs_were_live(force, vib):
    # at tick 400 (0.4 s) the press_slide probe is in contact: both outputs non-zero
    # unless stopped; checked on a run without any exception
    loop, probe, f, v, r, rec = _rig()
    loop.run(0.399)
    return f.output, v.output


def test_outputs_are_live_at_tick_400_without_a_stop():
    """The premise of every test below: at tick 400 both outputs are non-zero, so a zero
    output after the exception is the stop's doing."""
    f, v = _outputs_were_live(None, None)
    assert f > 0.5 and v > 0.2


def _assert_all_stopped(probe, force, vib):
    assert force.stops >= 1 and vib.stops >= 1 and probe.stops >= 1
    assert force.output == 0.0 and vib.output == 0.0 and probe.ignored_force_n == 0.0


@pytest.mark.parametrize("where", ["renderer", "recorder", "command", "read", "step"])
@pytest.mark.parametrize("kind,make", BASE_ONLY, ids=[k for k, _ in BASE_ONLY])
def test_base_exceptions_stop_everything_and_propagate_unchanged(where, kind, make):
    loop, probe, force, vib, r, rec = _rig()
    exc = make()
    if where == "renderer":
        r.exc = exc
    elif where == "recorder":
        rec.exc = exc
    elif where == "command":
        vib.raise_in_command = exc
    elif where == "read":
        probe.raise_in_read = exc
    else:
        probe.raise_in_step = exc
    with pytest.raises(type(exc)) as info:
        loop.run(2.0)
    assert info.value is exc            # the same object, not wrapped
    _assert_all_stopped(probe, force, vib)


@pytest.mark.parametrize("kind,make", KINDS, ids=[k for k, _ in KINDS])
def test_any_exception_from_a_device_step_stops_and_propagates(kind, make):
    """Before the fix only a DeviceError from step() stopped the actuators."""
    loop, probe, force, vib, r, rec = _rig()
    exc = make()
    probe.raise_in_step = exc
    with pytest.raises(type(exc)) as info:
        loop.run(2.0)
    assert info.value is exc
    _assert_all_stopped(probe, force, vib)


@pytest.mark.parametrize("kind,make", EXC_ONLY, ids=[k for k, _ in EXC_ONLY])
def test_exception_from_a_sink_is_a_fault_that_stops_everything(kind, make):
    """An Exception from a backend's _command (ENOSPC from a WAV sink) is a device
    fault: every actuator stopped, DeviceError raised with the original as its cause."""
    loop, probe, force, vib, r, rec = _rig()
    exc = make()
    vib.raise_in_command = exc
    with pytest.raises(DeviceError) as info:
        loop.run(2.0)
    assert info.value.__cause__ is exc
    _assert_all_stopped(probe, force, vib)
    assert loop.report.fault["device"] == "vib-out"


@pytest.mark.parametrize("where", ["renderer", "recorder"])
def test_exception_from_renderer_or_recorder_is_counted_and_the_run_ends_normally(where):
    loop, probe, force, vib, r, rec = _rig()
    if where == "renderer":
        r.exc = _enospc()
    else:
        rec.exc = _enospc()
    rep = loop.run(1.0)
    assert rep.events["renderer_error"] == 601 and rep.fault is None


def test_realtime_interrupt_while_waiting_for_the_deadline():
    class InterruptingClock(SimulatedClock):
        def wait_until(self, deadline):
            if deadline > 0.4:
                raise KeyboardInterrupt
            super().wait_until(deadline)

    loop, probe, force, vib, r, rec = _rig(realtime=True, clock=InterruptingClock())
    with pytest.raises(KeyboardInterrupt):
        loop.run(2.0)
    _assert_all_stopped(probe, force, vib)


def test_one_actuator_whose_stop_raises_does_not_keep_the_others_running():
    """A backend breaking the never-raise contract of stop() (here: a KeyboardInterrupt
    while stopping, which Actuator.stop does not catch) must not leave the others on;
    the original exception still wins."""
    loop, probe, force, vib, r, rec = _rig()

    def bad_stop():
        force.stops += 1
        raise KeyboardInterrupt("second Ctrl-C during stop")

    good_stop = force._stop
    force._stop = bad_stop
    r.exc = SystemExit(4)
    try:
        with pytest.raises(SystemExit) as info:
            loop.run(2.0)
        assert info.value.code == 4
        assert vib.stops >= 1 and vib.output == 0.0 and probe.stops >= 1
    finally:  # leave no actuator whose stop raises in the process-wide open registry
        force._stop = good_stop
        for a in (probe, force, vib):
            a.close()


def test_stop_all_stops_every_actuator_when_one_stop_raises(monkeypatch):
    """The process-wide stop (signals, interpreter exit) reaches every open actuator even
    when one backend's stop raises a BaseException; that exception comes out afterwards."""
    from hapticsdk.devices import actuators as A

    bad, good = Out("vib-a"), Out("vib-b")
    for a in (bad, good):
        a.open()
        a.command(ChannelCommand("vib", frequency_hz=100.0, amplitude=0.5), now=0.0)
        a.output = 0.7
    plain = bad._stop

    def raising():
        plain()
        raise KeyboardInterrupt("second Ctrl-C during stop")

    bad._stop = raising
    try:
        monkeypatch.setattr(A, "_OPEN_ACTUATORS", [bad, good])  # the raising one first
        with pytest.raises(KeyboardInterrupt):
            A.stop_all()
        assert good.output == 0.0 and good.stops >= 1
    finally:
        bad._stop = plain
        monkeypatch.undo()
        for a in (bad, good):
            a.close()


def test_actuator_stop_never_raises_even_when_the_safety_layer_fails():
    act = Out("vibration")
    act.open()
    act.command(ChannelCommand("vib", frequency_hz=100.0, amplitude=0.5), now=0.0)
    act.output = 0.7

    def broken():
        raise RuntimeError("safety bug")

    act.safety.on_stop = broken
    assert act.stop() is False          # reported ...
    assert act.output == 0.0 and act.stops == 1   # ... and the hardware still stopped
    act.close()


def test_stops_are_noted_for_the_interrupt_message():
    import time
    t0 = time.monotonic()
    loop, probe, force, vib, r, rec = _rig()
    r.exc = KeyboardInterrupt()
    with pytest.raises(KeyboardInterrupt):
        loop.run(2.0)
    labels = {label for label, t, ok in stops_since(t0) if ok}
    assert {"force-out", "vib-out", probe.label} <= labels


def test_render_plan_closes_every_actuator_on_an_interrupt(monkeypatch):
    """render_plan: the interrupt reaches the caller and every actuator of the plan is
    stopped and closed (the ExitStack), none left in the open-actuator registry."""
    from hapticsdk.devices import actuators as A
    from hapticsdk.compiler import compile_scene
    from hapticsdk.runtime.render import render_plan
    from hapticsdk.scene import Scene

    plan = compile_scene(Scene.for_material("S7", seed=0))
    seen = []
    from hapticsdk.runtime import loop as loop_mod
    orig = loop_mod.ServoLoop.run

    def run(self, seconds):
        seen.extend(a for a in {id(a): a for a in [self.device, *self.actuators.values()]}.values())
        for rr in self.renderers:
            rr_tick = rr.tick

            def tick(inp, _t=rr_tick):
                if inp.t > 0.3:
                    raise SafeStop(signal.SIGHUP)
                return _t(inp)
            rr.tick = tick
        return orig(self, seconds)

    monkeypatch.setattr(loop_mod.ServoLoop, "run", run)
    import time
    t0 = time.monotonic()
    with pytest.raises(SafeStop):
        render_plan(plan, seconds=2.0, hooks=False)
    assert len(seen) >= 2
    stopped = {label for label, t, ok in stops_since(t0) if ok}
    for a in seen:
        assert not a.is_open and a not in set(A._OPEN_ACTUATORS)
        assert a.label in stopped
