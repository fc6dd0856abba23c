"""Live sessions (issue 12): the application side never blocks, the servo renders
several objects, switches materials with a ramp, reports events; every failure path
leaves the actuators stopped, the servo reaped and no shared memory behind."""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import hapticsdk as hs
from hapticsdk.dimensions import DimensionRenderer
from hapticsdk.errors import HapticSDKError, ServoProcessDied, SessionError
from hapticsdk.runtime.session import Session
from hapticsdk.sim.finger import Trajectory

HERE = Path(__file__).parent

PAD = {"schema_version": 1, "name": "pad",
       "objects": [{"name": "pad", "material": {"intensities": {"hardness": 0.5}}}],
       "settings": {"solver": {"seed": 0}}}

TWO = {"schema_version": 2, "name": "two",
       "objects": [
           {"name": "left", "material": {"intensities": {"hardness": 0.2}},
            "geometry": {"shape": "box", "half_size_mm": [20, 10, 20]}, "pose": {"position_mm": [-30, -10, 0]}},
           {"name": "right", "material": {"intensities": {"hardness": 0.8}},
            "geometry": {"shape": "box", "half_size_mm": [20, 10, 20]}, "pose": {"position_mm": [30, -10, 0]}}],
       "devices": {"force": "probe-virtual"},  # kinematic: the probe follows the finger exactly
       "settings": {"solver": {"seed": 0}}}

#: press 1.5 mm into the left box, slide onto the right one, hold, lift
SLIDE = Trajectory([(0.0, -30.0, 3.0), (0.2, -30.0, -1.5), (0.5, -30.0, -1.5), (1.1, 30.0, -1.5),
                    (3.0, 30.0, -1.5), (3.3, 30.0, 3.0), (600.0, 30.0, 3.0)])
#: the same slide, then held on the right box: a servo in simulated time runs the 2 s on
#: the right box in ~0.1 s of wall time, which a loaded machine's polling can miss
SLIDE_AND_HOLD = Trajectory([(0.0, -30.0, 3.0), (0.2, -30.0, -1.5), (0.5, -30.0, -1.5), (1.1, 30.0, -1.5),
                             (600.0, 30.0, -1.5)])


def _shm():
    return set(os.listdir("/dev/shm")) if os.path.isdir("/dev/shm") else set()


def _wait(pred, timeout=20.0):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if pred():
            return True
        time.sleep(0.01)
    return False


def test_thread_session_contacts_state_events_and_switch():
    """Two boxes, the finger slides from one to the other: contact events name the
    objects in order, state() follows the probe, set_material switches the material in
    contact (counted by the servo), close() stops every actuator."""
    # simulated time: a thread servo shares the interpreter lock with this test, and a
    # command gap > 50 ms would (rightly) re-arm the safety layer's start gate
    with hs.session(TWO, isolation="thread", trajectory=SLIDE_AND_HOLD, realtime=False) as s:
        assert _wait(lambda: s.state().object == "right" and s.state().position_mm[0] > 25.0, 20.0)
        st = s.state()
        # pressed 1.5 mm into the right box's top: penetration along +y, a spring force
        assert st.penetration_mm == pytest.approx(1.5) and st.position_mm[1] == pytest.approx(-1.5)
        assert st.force_n > 1.0 and st.ticks > 0
        r = s.set_material("right", {"hardness": 0.95}, refine=False)
        assert r.source == "amortised" and set(r.features) == {"hardness"}
        assert _wait(lambda: s.state().material_switches >= 1, 5.0)
        s.pause()
        assert _wait(lambda: s.state().paused and s.state().force_n == 0.0, 5.0)
        s.resume()
        assert _wait(lambda: not s.state().paused, 5.0)
        ev = s.events()
        summary = s.close()
    kinds = [(e.kind, e.object) for e in ev if e.kind.startswith("contact")]
    assert kinds[:3] == [("contact_enter", "left"), ("contact_leave", "left"), ("contact_enter", "right")]
    assert any(e.kind == "material_switched" and e.object == "right" for e in ev)
    assert any(e.kind == "paused" for e in ev) and any(e.kind == "resumed" for e in ev)
    assert set(summary["stopped"]) >= {"probe-virtual", "voicecoil-virtual"}
    with pytest.raises(SessionError):
        s.state()


class Raises(DimensionRenderer):
    roles = ("force",)

    def tick(self, inp):
        raise RuntimeError("renderer bug")


def test_renderer_error_is_counted_not_fatal():
    with Session(PAD, isolation="thread", trajectory=SLIDE, realtime=False) as s:
        # thread isolation: the servo's loop is in this process; give it a renderer that raises
        s._servo_holder[0].loop.set_renderers(0, [Raises()], 0.0)
        assert _wait(lambda: s.state().renderer_errors > 10, 10.0)
        assert any(e.kind == "renderer_error" for e in s.events())
        assert s.state().ticks > 0  # still running


def test_add_move_remove_objects_live():
    kinematic = dict(PAD, devices={"force": "probe-virtual"})  # the probe follows the finger exactly
    with Session(kinematic, isolation="thread", trajectory=Trajectory([(0, 100.0, -1.0), (600, 100.0, -1.0)]),
                 realtime=False) as s:
        # the finger rests at x = 100 mm, 1 mm below y = 0: inside the (infinite) pad plane
        assert _wait(lambda: s.state().object == "pad")
        s.remove_object("pad")
        assert _wait(lambda: s.state().object is None)
        s.add_object("ball", {"hardness": 0.6}, {"shape": "sphere", "radius_mm": 10.0},
                     {"position_mm": [0.0, 0.0, 0.0]})
        time.sleep(0.05)
        assert s.state().object is None  # the ball is 100 mm away
        s.move_object("ball", {"position_mm": [100.0, 5.0, 0.0]})
        assert _wait(lambda: s.state().object == "ball")
        assert s.state().penetration_mm == pytest.approx(4.0, abs=1e-9)
        with pytest.raises(HapticSDKError):
            s.set_material("nothing", "S1")


# -- process isolation and failure semantics ----------------------------------------
def test_process_session_close_reaps_and_unlinks():
    before = _shm()
    s = Session(PAD, trajectory=SLIDE)
    name = s._buf.name.lstrip("/")
    assert name in _shm() and s.servo_pid != os.getpid()
    assert _wait(lambda: s.state().ticks > 50)
    proc = s._process
    summary = s.close()
    assert proc._popen is None or proc.exitcode is not None  # reaped
    assert name not in _shm() and _shm() <= before | (_shm() - {name})
    assert set(summary["stopped"]) >= {"omni-virtual", "voicecoil-virtual"}
    assert summary["reason"] == "close"
    s.close()  # idempotent


def test_servo_killed_next_call_raises():
    with Session(PAD, trajectory=SLIDE) as s:
        name = s._buf.name.lstrip("/")
        os.kill(s.servo_pid, signal.SIGKILL)
        with pytest.raises(ServoProcessDied) as ei:
            assert _wait(lambda: s.state() is None, 10.0)
        assert "SIGKILL" in str(ei.value) and ei.value.exitcode == -signal.SIGKILL
    assert name not in _shm()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_stop_signals_to_the_servo_stop_safely(sig):
    with Session(PAD, trajectory=SLIDE) as s:
        assert _wait(lambda: s.state().ticks > 20)
        os.kill(s.servo_pid, sig)
        with pytest.raises(ServoProcessDied) as ei:
            assert _wait(lambda: s.state() is None, 10.0)
        assert signal.Signals(sig).name in str(ei.value)
        assert ei.value.exitcode == 128 + sig
        summary = s._summary
        assert set(summary["stopped"]) >= {"omni-virtual", "voicecoil-virtual"}


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_application_death_stops_the_servo(sig):
    """The application dies without closing its session (SIGKILL; SIGTERM and SIGHUP
    with their default action): the servo notices (parent check every tick, heartbeat),
    stops every actuator and exits; the resource tracker removes the shared memory.
    SIGINT raises KeyboardInterrupt in the application, whose ``with`` exit closes the
    session: every actuator stopped, the servo reaped, the memory unlinked."""
    p = subprocess.Popen([sys.executable, str(HERE / "_session_app.py")], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        line = p.stdout.readline()
        assert line.startswith("servo"), p.stderr.read()
        pid, shm = int(line.split()[1]), line.split()[3].lstrip("/")
        time.sleep(0.3)
        t_kill = time.monotonic()
        os.kill(p.pid, sig)
        p.wait(10)
        assert _wait(lambda: not os.path.exists(f"/proc/{pid}"), 10.0), "servo still running"
        if sig == signal.SIGINT:
            out = p.stdout.read()
            assert "closed:" in out and "omni-virtual" in out and "voicecoil-virtual" in out
            assert shm not in _shm()
            return
        err = p.stderr.read()
        assert "every actuator stopped" in err and "omni-virtual" in err
        # monotonic clocks are system-wide: the servo says when it noticed (the parent
        # check, not the heartbeat timeout). The goal is 50 ms, measured in
        # docs/runtime.md; here a bound that holds on a busy shared machine
        noticed = float(re.search(r"noticed at monotonic ([0-9.]+) s", err).group(1))
        assert 0.0 <= noticed - t_kill < 1.0
        assert _wait(lambda: shm not in _shm(), 10.0)
    finally:
        if p.poll() is None:
            p.kill()


def test_hung_application_heartbeat_timeout_stops_the_servo():
    """An application that is alive but hung (its heartbeat thread no longer runs):
    after heartbeat_timeout_s the servo stops every actuator and exits; the next call
    says why."""
    with Session(PAD, trajectory=SLIDE, heartbeat_timeout_s=0.1) as s:
        assert _wait(lambda: s.state().ticks > 20)
        s._hb_stop.set()  # the heartbeat thread ends: as if the application hung
        with pytest.raises(ServoProcessDied) as ei:
            assert _wait(lambda: s.state() is None, 10.0)
        assert "no heartbeat" in str(ei.value)
        assert set(s._summary["stopped"]) >= {"omni-virtual", "voicecoil-virtual"}


def test_state_is_never_torn():
    """state() returns the fields of one tick: a kinematic probe's x is the finger's x
    at that tick's time, for every read, while the servo process writes in parallel."""
    with Session(TWO, trajectory=SLIDE) as s:
        assert _wait(lambda: s.state().ticks > 10)
        bad = 0
        n = 0
        t_end = time.monotonic() + 2.0
        while time.monotonic() < t_end:
            st = s.state()
            n += 1
            if abs(st.position_mm[0] - SLIDE.at(st.t)[0]) > 1e-6:
                bad += 1
        assert n > 1000 and bad == 0, f"{bad} torn reads of {n}"
