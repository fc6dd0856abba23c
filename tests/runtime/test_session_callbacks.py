"""Live sessions, round 2 (issue 27): callbacks on an SDK thread, acknowledged material
switches, servo death seen by every call and by the callbacks, the servo reaped at once,
clamp events that name the actuator, the limit and the value."""

import os
import signal
import threading

import pytest

import hapticsdk as hs
from hapticsdk.devices.actuators import ActuatorLimits
from hapticsdk.errors import ServoProcessDied, SessionError, ValidationError
from hapticsdk.devices.safety import SafetyLayer
from hapticsdk.sim.finger import Trajectory

PAD = {"schema_version": 1, "name": "pad",
       "objects": [{"name": "pad", "material": {"intensities": {"hardness": 0.5}}}],
       "devices": {"force": "probe-virtual"},  # kinematic: the probe follows the finger exactly
       "settings": {"solver": {"seed": 0}}}
#: press 3 mm into the pad and stay
PRESS = Trajectory([(0.0, 0.0, 2.0), (0.3, 0.0, -3.0), (600.0, 0.0, -3.0)])



def _proc_state(pid):
    """The kernel's state letter of ``pid`` (``Z`` zombie), None when it is gone."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):  # gone before the open, or between open and read
        return None


def test_callbacks_run_on_the_sdk_thread_and_the_switch_is_acknowledged(wait):
    got = []
    with hs.Session(PAD, trajectory=PRESS) as s:
        s.on_event("contact_enter", lambda e: got.append((threading.current_thread().name, e)))
        s.on_event("*", lambda e: 1 / 0)  # a raising callback is counted, never fatal
        assert wait(lambda: any(e.kind == "contact_enter" for _, e in got))
        name, ev = got[0]
        assert name == "hapticsdk-events" and ev.object == "pad"
        assert s._dispatcher.errors >= 1
        before = s.state().ticks
        r = s.set_material("pad", {"hardness": 0.9}, refine=False)
        assert r.wait(10.0)
        st = s.state()
        # the tick the servo says rendered it first is the one whose publication
        # state().switched_at dates (the same slot write), and it is after the call
        assert r.switch.monotonic == st.switched_at and r.switch.monotonic >= r.switch.sent_at
        assert before <= r.tick < st.ticks and r.t > 0
        assert r.switch.latency_s >= 0
        # a second switch gets its own, later tick
        r2 = s.set_material("pad", {"hardness": 0.2}, refine=False)
        assert r2.wait(10.0) and r2.tick > r.tick
    with pytest.raises(SessionError):
        s.on_event("clamp", print)


def test_on_event_rejects_unknown_kinds():
    with hs.Session(PAD, trajectory=PRESS, isolation="thread", realtime=False) as s:
        with pytest.raises(ValidationError):
            s.on_event("contact_entr", print)
        with pytest.raises(ValidationError):
            s.on_event("clamp", 3)


def test_servo_death_raises_from_events_reaches_callbacks_and_is_reaped_at_once(wait):
    died = []
    with hs.Session(PAD, trajectory=PRESS) as s:
        s.on_event("servo_died", died.append)
        assert wait(lambda: s.state().ticks > 20)
        pid = s.servo_pid
        os.kill(pid, signal.SIGKILL)
        # no call on the session: the supervisor reaps the servo, it never stays a zombie
        assert wait(lambda: _proc_state(pid) is None, 5.0), f"servo {pid} state {_proc_state(pid)}"
        assert wait(lambda: bool(died), 5.0)
        assert "SIGKILL" in died[0].message and died[0].value == -signal.SIGKILL
        with pytest.raises(ServoProcessDied):
            s.events()
        with pytest.raises(ServoProcessDied):
            s.set_material("pad", {"hardness": 0.9}, refine=False)


def test_clamp_events_name_the_actuator_the_limit_and_the_value(wait):
    """A limit that keeps biting: reported at once, then at most once per CLAMP_REPORT_S,
    then a last time at the end; every clamped tick is counted in exactly one event, and
    the last report, written at the stop, is still returned by events() after close().
    (One event per 10 ticks filled the 1024-event ring in seconds, and a slow events()
    reader lost its contact events.)"""
    from hapticsdk.runtime.session import CLAMP_REPORT_S
    limit = 0.5  # N, far below the 3 mm press on this pad (several N)
    opts = {"force": {"safety": SafetyLayer(ActuatorLimits(max_force_n=limit))}}
    with hs.Session(PAD, trajectory=PRESS, actuator_options=opts) as s:
        # past the safety layer's 0.2 s start ramp, which scales the clamped force down,
        # and past two report periods of continued clamping
        assert wait(lambda: s.state().clamps > 0, 10.0)
        t_first = s.state().t
        assert wait(lambda: s.state().t > t_first + 2.5 * CLAMP_REPORT_S, 20.0)
        ev = [e for e in s.events() if e.kind == "clamp"]
        t_read = s.state().t
    ev += [e for e in s.events() if e.kind == "clamp"]   # the last report, written at the stop
    total = s._summary["report"]["events"]["clamp"]
    assert ev and all((e.actuator, e.field) == ("force", "max_force_n") for e in ev)
    # the value is the force actually sent: never above the limit. It is the last
    # command's at the report, so it can be 0 where the safety layer's envelope was at 0
    # then (a servo that stalled past restart_after_s on a loaded machine restarts its
    # ramp from 0: seen once under two CPU-bound processes); the largest is the limit
    assert all(0 <= e.value <= limit + 1e-12 for e in ev), [e.value for e in ev]
    assert max(e.value for e in ev) == pytest.approx(limit)  # once the start ramp is over
    # every clamped tick once
    assert sum(e.count for e in ev) == total
    # the onset at once (the servo compares the counters every 10 ticks), then no more
    # than one report per period while it bites, plus the last one
    ts = [e.t for e in ev]
    assert ts[0] <= t_first + 0.02
    assert all(b - a >= CLAMP_REPORT_S - 0.011 for a, b in zip(ts[1:-1], ts[2:-1]))
    assert 2 <= len(ev) <= 2 + (t_read - ts[0]) / CLAMP_REPORT_S + 2


def test_the_acknowledged_tick_is_the_first_that_renders_the_new_material(wait):
    """Simulated time, a probe held 3 mm deep, a switch without a ramp from a soft pad
    (the arm alone) to a hard one (arm plus voice coil): the voice coil's logged
    amplitude steps exactly at the acknowledged tick (silent on the tick before, driven
    on it), and the acknowledged servo time is that tick's. (The force does not step:
    a switch while pressed keeps the force continuous, docs/runtime.md.)"""
    with hs.Session(PAD, trajectory=PRESS, isolation="thread", realtime=False, ramp_s=0.0) as s:
        assert wait(lambda: s.state().t > 1.0)
        r = s.set_material("pad", {"hardness": 0.95}, refine=False)
        assert r.wait(10.0)
        loop = s._servo_holder[0].loop
        assert wait(lambda: loop.ticks > r.tick + 5)
        coil = next(sl for sl in loop._slots if sl.role == "coil")
        a = coil.log_a
        cap = a.size
        assert r.t == pytest.approx(r.tick * loop.period_s)
        assert a[(r.tick - 1) % cap] == 0.0 and a[(r.tick - 2) % cap] == 0.0
        assert a[r.tick % cap] > 0.0 and a[(r.tick + 1) % cap] > 0.0


def test_a_killed_servo_is_reaped_without_any_call_or_callback(wait):
    with hs.Session(PAD, trajectory=PRESS) as s:
        assert wait(lambda: s.state().ticks > 20)
        pid = s.servo_pid
        os.kill(pid, signal.SIGKILL)
        assert wait(lambda: _proc_state(pid) is None, 2.0), f"servo {pid} state {_proc_state(pid)}"
