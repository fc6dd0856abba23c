"""Live sessions (issue 12): the application side never blocks, the servo renders
several objects, switches materials with a ramp, reports events; every failure path
leaves the actuators stopped, the servo reaped and no shared memory behind."""

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

import hapticsdk as hs
from hapticsdk.perception.dimensions import DimensionRenderer
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



_BAD_SESSION_ARGS = [
    ("period_s", "0.001"), ("period_s", True), ("period_s", float("nan")), ("period_s", 0.0), ("period_s", 5.0),
    ("period_s", [0.001]),
    ("ramp_s", "0.1"), ("ramp_s", True), ("ramp_s", -0.1), ("ramp_s", 6.0),
    ("heartbeat_timeout_s", "1"), ("heartbeat_timeout_s", True), ("heartbeat_timeout_s", float("inf")),
    ("heartbeat_timeout_s", 0.0),
    ("log_seconds", "1"), ("log_seconds", True), ("log_seconds", 0.0), ("log_seconds", float("nan")),
    ("start_timeout_s", "1"), ("start_timeout_s", True), ("start_timeout_s", float("nan")), ("start_timeout_s", 0.0),
    ("realtime", "no"), ("realtime", 0), ("realtime", None),
    ("refine", "no"), ("refine", 1),
    ("view", "yes"), ("view", -1), ("view", 70000), ("view", 2.5),
    ("actuator_options", "x"), ("actuator_options", {"force": 3}), ("actuator_options", {"nosuch": {}}),
]


@pytest.mark.parametrize("name,value", _BAD_SESSION_ARGS, ids=lambda v: repr(v)[:20])
def test_session_arguments_are_checked_before_a_servo_starts(name, value, monkeypatch):
    """Every argument of ``Session`` is checked before the servo starts, a bad one a
    ValidationError naming it: a string that reads as a number, a bool for a number, a
    switch given as ``"no"`` (true by its truth value: a realtime servo the caller turned
    off), a port out of range, options for a role the scene does not have (a typo's
    options were dropped in silence). Before, several opened a session or raised
    TypeError/ValueError from inside."""
    from hapticsdk.errors import ValidationError
    from hapticsdk.runtime.session import app

    started = []
    monkeypatch.setattr(app.threading.Thread, "start", lambda self: started.append(self.name))
    with pytest.raises(ValidationError) as ei:
        Session(PAD, isolation="thread", **{name: value})
    assert ei.value.field == name, ei.value
    assert "hapticsdk-servo" not in started


def test_live_calls_check_their_arguments(wait):
    """``set_material``'s ``ramp_s`` and ``refine`` and ``pause``'s switch: the same checks
    as the constructor's, on a running session (which carries on)."""
    from hapticsdk.errors import ValidationError
    with Session(PAD, isolation="thread", realtime=False) as s:
        for kw in ({"ramp_s": "0.1"}, {"ramp_s": True}, {"ramp_s": 9.0}, {"refine": "no"}):
            with pytest.raises(ValidationError) as ei:
                s.set_material("pad", {"hardness": 0.7}, **kw)
            assert ei.value.field == next(iter(kw))
        for v in ("no", 1, None):
            with pytest.raises(ValidationError) as ei:
                s.pause(v)
            assert ei.value.field == "on"
        assert s.set_material("pad", {"hardness": 0.7}, ramp_s=0.1, refine=False).success
        s.pause(True)
        s.pause(False)


def test_thread_session_contacts_state_events_and_switch(wait):
    """Two boxes, the finger slides from one to the other: contact events name the
    objects in order, state() follows the probe, set_material switches the material in
    contact (counted by the servo), close() stops every actuator."""
    # simulated time: a thread servo shares the interpreter lock with this test, and a
    # command gap > 50 ms would (rightly) re-arm the safety layer's start gate
    with hs.session(TWO, isolation="thread", trajectory=SLIDE_AND_HOLD, realtime=False) as s:
        assert wait(lambda: s.state().object == "right" and s.state().position_mm[0] > 25.0, 20.0)
        st = s.state()
        # pressed 1.5 mm into the right box's top: penetration along +y, a spring force
        assert st.penetration_mm == pytest.approx(1.5) and st.position_mm[1] == pytest.approx(-1.5)
        assert st.force_n > 1.0 and st.ticks > 0
        assert s.state().switched_at == 0.0
        t_call = time.monotonic()
        r = s.set_material("right", {"hardness": 0.95}, refine=False)
        assert r.source == "amortised" and set(r.features) == {"hardness"}
        assert wait(lambda: s.state().material_switches >= 1, 5.0)
        assert s.state().switched_at > t_call  # when the servo rendered it first
        # built in the application and only unpickled by the servo
        assert "<unpickle>" in s._servo_holder[0]._build_s
        s.pause()
        assert wait(lambda: s.state().paused and s.state().force_n == 0.0, 5.0)
        s.resume()
        assert wait(lambda: not s.state().paused, 5.0)
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


def test_renderer_error_is_counted_not_fatal(wait):
    # held pressed: a servo on simulated time runs SLIDE's 3 s of contact in a fraction
    # of a second of wall time, which this thread's set_renderers could arrive after
    with Session(PAD, isolation="thread", trajectory=SLIDE_AND_HOLD, realtime=False) as s:
        # thread isolation: the servo's loop is in this process; give it a renderer that raises
        s._servo_holder[0].loop.set_renderers(0, [Raises()], 0.0)
        # the servo publishes its events after its state: wait for both, as asserted
        seen: list = []

        def counted_and_reported():
            seen.extend(s.events())
            return s.state().renderer_errors > 10 and any(e.kind == "renderer_error" for e in seen)
        assert wait(counted_and_reported, 10.0)
        assert s.state().ticks > 0  # still running


def test_add_move_remove_objects_live(wait):
    kinematic = dict(PAD, devices={"force": "probe-virtual"})  # the probe follows the finger exactly
    with Session(kinematic, isolation="thread", trajectory=Trajectory([(0, 100.0, -1.0), (600, 100.0, -1.0)]),
                 realtime=False) as s:
        # the finger rests at x = 100 mm, 1 mm below y = 0: inside the (infinite) pad plane
        assert wait(lambda: s.state().object == "pad")
        s.remove_object("pad")
        assert wait(lambda: s.state().object is None)
        s.add_object("ball", {"hardness": 0.6}, {"shape": "sphere", "radius_mm": 10.0},
                     {"position_mm": [0.0, 0.0, 0.0]})
        time.sleep(0.05)
        assert s.state().object is None  # the ball is 100 mm away
        s.move_object("ball", {"position_mm": [100.0, 5.0, 0.0]})
        assert wait(lambda: s.state().object == "ball")
        assert s.state().penetration_mm == pytest.approx(4.0, abs=1e-9)
        with pytest.raises(HapticSDKError):
            s.set_material("nothing", "S1")


# -- process isolation and failure semantics ----------------------------------------
def test_process_session_close_reaps_and_unlinks(wait):
    before = _shm()
    s = Session(PAD, trajectory=SLIDE)
    name = s._buf.name.lstrip("/")
    assert name in _shm() and s.servo_pid != os.getpid()
    assert wait(lambda: s.state().ticks > 50)
    t_call = time.monotonic()
    s.set_material("pad", {"hardness": 0.9}, refine=False)  # built and switched in the servo's slack
    assert wait(lambda: s.state().material_switches == 1, 10.0)
    assert s.state().switched_at > t_call
    proc = s._process
    summary = s.close()
    assert summary["commands"]["received"] == 1 and summary["commands"]["done"] == 1
    assert proc._popen is None or proc.exitcode is not None  # reaped
    assert name not in _shm() and _shm() <= before | (_shm() - {name})
    assert set(summary["stopped"]) >= {"omni-virtual", "voicecoil-virtual"}
    assert summary["reason"] == "close"
    s.close()  # idempotent


def test_servo_killed_next_call_raises(wait):
    with Session(PAD, trajectory=SLIDE) as s:
        name = s._buf.name.lstrip("/")
        os.kill(s.servo_pid, signal.SIGKILL)
        with pytest.raises(ServoProcessDied) as ei:
            assert wait(lambda: s.state() is None, 10.0)
        assert "SIGKILL" in str(ei.value) and ei.value.exitcode == -signal.SIGKILL
    assert name not in _shm()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_stop_signals_to_the_servo_stop_safely(sig, wait):
    with Session(PAD, trajectory=SLIDE) as s:
        assert wait(lambda: s.state().ticks > 20)
        os.kill(s.servo_pid, sig)
        with pytest.raises(ServoProcessDied) as ei:
            assert wait(lambda: s.state() is None, 10.0)
        assert signal.Signals(sig).name in str(ei.value)
        assert ei.value.exitcode == 128 + sig
        summary = s._summary
        assert set(summary["stopped"]) >= {"omni-virtual", "voicecoil-virtual"}


def _default_signals() -> None:
    """In the application under test: the default actions of SIGHUP, SIGINT and SIGTERM,
    whatever the test runner inherited (``nohup`` ignores SIGHUP, a background job of a
    non-interactive shell may ignore SIGINT; an ignored signal is inherited and would let
    the application survive the very signal the test sends)."""
    for s in (signal.SIGHUP, signal.SIGINT, signal.SIGTERM):
        signal.signal(s, signal.SIG_DFL)


def _exited(pid: int) -> bool:
    """The process has ended: gone, or a zombie that its new parent (init, which reaps
    orphans on its own schedule: about 1 s on some container inits) has not reaped yet."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except (FileNotFoundError, ProcessLookupError):
        return True


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_application_death_stops_the_servo(sig, wait):
    """The application dies without closing its session (SIGKILL; SIGTERM and SIGHUP
    with their default action): the servo notices (parent check every tick, heartbeat),
    stops every actuator and exits; the resource tracker removes the shared memory.
    SIGINT raises KeyboardInterrupt in the application, whose ``with`` exit closes the
    session: every actuator stopped, the servo reaped, the memory unlinked."""
    p = subprocess.Popen([sys.executable, str(HERE / "_session_app.py")], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, preexec_fn=_default_signals)
    try:
        line = p.stdout.readline()
        assert line.startswith("servo"), p.stderr.read()
        pid, shm = int(line.split()[1]), line.split()[3].lstrip("/")
        time.sleep(0.3)
        t_kill = time.monotonic()
        os.kill(p.pid, sig)
        p.wait(10)
        assert wait(lambda: _exited(pid), 10.0), "servo still running"
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
        assert wait(lambda: shm not in _shm(), 10.0)
    finally:
        if p.poll() is None:
            p.kill()


def _hang(s) -> ServoProcessDied:
    """The application hangs: its heartbeat thread ends and nothing calls the API (a
    call is a heartbeat too). Waits for the servo to stop, reading the status slot only,
    and returns the error the next call raises."""
    from hapticsdk.runtime.session.protocol import _RUNNING, _STATUS
    s._hb_stop.set()
    deadline = time.monotonic() + 10.0
    while s._mv[_STATUS] == _RUNNING and time.monotonic() < deadline:
        time.sleep(0.05)
    with pytest.raises(ServoProcessDied) as ei:
        s.state()
    return ei.value


def test_hung_application_heartbeat_timeout_stops_the_servo(wait):
    """An application that is alive but hung (its heartbeat thread no longer runs, no
    call of the API): after heartbeat_timeout_s the servo stops every actuator and
    exits; the next call says why."""
    with Session(PAD, trajectory=SLIDE, heartbeat_timeout_s=0.1) as s:
        assert wait(lambda: s.state().ticks > 20)
        assert "no heartbeat" in str(_hang(s))
        assert set(s._summary["stopped"]) >= {"omni-virtual", "voicecoil-virtual"}


def test_a_start_up_that_starves_the_heartbeat_does_not_stop_the_servo(monkeypatch, wait):
    """The session's own start-up work in the application (the warm-up's table build,
    while the servo process starts) can hold the interpreter lock: on a busy machine it
    starved the heartbeat thread for 254 ms and the servo, already running, stopped for
    want of a heartbeat (examples/live_session.py under load). Here the heartbeat thread
    writes nothing while the warm-up runs, three times the timeout: the servo watches the
    heartbeat only once ``Session()`` has returned, and then does (a hang stops it)."""
    from hapticsdk.runtime.session.protocol import _HEARTBEAT, _RUNNING, _STATUS, HEARTBEAT_PERIOD_S
    warming = threading.Event()
    real_warm = Session._warm

    def slow_warm(self):
        warming.set()
        real_warm(self)
        deadline = time.monotonic() + 60.0
        while self._mv[_STATUS] != _RUNNING and time.monotonic() < deadline:   # the servo is up
            time.sleep(0.005)
        time.sleep(0.3)     # and runs, three heartbeat timeouts without a heartbeat
        warming.clear()

    def starved_heartbeat(self):   # Session._heartbeat, writing nothing while the warm-up runs
        while not self._hb_stop.wait(HEARTBEAT_PERIOD_S):
            if not warming.is_set():
                try:
                    self._mv[_HEARTBEAT] = time.monotonic()
                except (ValueError, TypeError):
                    return

    monkeypatch.setattr(Session, "_warm", slow_warm)
    monkeypatch.setattr(Session, "_heartbeat", starved_heartbeat)
    with Session(PAD, trajectory=SLIDE, heartbeat_timeout_s=0.1) as s:
        ticks = s.state().ticks
        assert wait(lambda: s.state().ticks > ticks + 20)
        assert "no heartbeat" in str(_hang(s))   # then a hang: the servo stops


def test_a_busy_application_thread_calling_the_api_is_alive(monkeypatch):
    """A call of the session's API is a heartbeat: an application thread that calls
    ``state()`` in a tight loop can starve the heartbeat thread for longer than the timeout
    on a loaded machine (258 ms under two CPU-bound processes, which stopped the servo in
    ``test_state_alloc``). Here the heartbeat thread writes nothing at all once the session
    has started; calling ``state()`` for ten timeouts keeps the servo running, and stopping
    the calls is a hang that stops it."""
    from hapticsdk.runtime.session.protocol import _RUNNING, _STATUS, HEARTBEAT_PERIOD_S
    started = threading.Event()

    def silent_heartbeat(self):   # Session._heartbeat, silent after the start
        while not self._hb_stop.wait(HEARTBEAT_PERIOD_S):
            if started.is_set():
                continue
            try:
                self._mv[_HEARTBEAT] = time.monotonic()
            except (ValueError, TypeError):
                return

    from hapticsdk.runtime.session.protocol import _HEARTBEAT
    monkeypatch.setattr(Session, "_heartbeat", silent_heartbeat)
    with Session(PAD, trajectory=SLIDE, heartbeat_timeout_s=0.1) as s:
        started.set()
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            s.state()
            time.sleep(0.001)
        assert s._mv[_STATUS] == _RUNNING and s.state().ticks > 0
        assert "no heartbeat" in str(_hang(s))   # no calls: a hang


def test_state_is_never_torn(wait):
    """state() returns the fields of one tick: a kinematic probe's x is the finger's x
    at that tick's time, for every read, while the servo process writes in parallel."""
    with Session(TWO, trajectory=SLIDE) as s:
        assert wait(lambda: s.state().ticks > 10)
        bad = 0
        n = 0
        t_end = time.monotonic() + 2.0
        while time.monotonic() < t_end:
            st = s.state()
            n += 1
            if abs(st.position_mm[0] - SLIDE.at(st.t)[0]) > 1e-6:
                bad += 1
        assert n > 1000 and bad == 0, f"{bad} torn reads of {n}"


# -- the servo process: one thread of its own, commands never block it ----------------
def _thread_cpu_ticks(pid):
    out = {}
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{tid}/stat") as fh:
                st = fh.read()
        except OSError:
            continue
        f = st[st.rindex(")") + 2:].split()
        out[int(tid)] = int(f[11]) + int(f[12])  # utime + stime, clock ticks
    return out


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="per-thread CPU times from /proc (Linux)")
def test_servo_process_has_no_busy_helper_thread(wait):
    """Only the servo thread may use CPU in the servo process. A BLAS pool's worker
    thread, woken by the simulated arm's matrix exponential every tick, busy-waits for
    the next job and never sleeps: it kept a whole CPU busy, which on a 2-CPU machine
    with a busy application thread took the CPU from the servo. An idle helper thread
    uses ~0 % of a CPU; a spinning one close to 100 % (less on a loaded machine, but far
    above the 10 % allowed here)."""
    s7 = {"schema_version": 1, "name": "s7", "objects": [{"name": "pad", "material": "S7"}],
          "settings": {"importance": {"enabled": False}, "solver": {"seed": 0}}}  # force + vibration
    with Session(s7, trajectory=SLIDE, refine=False) as s:
        assert wait(lambda: s.state().ticks > 200)
        pid = s.servo_pid
        hz = os.sysconf("SC_CLK_TCK")
        a = _thread_cpu_ticks(pid)
        t0 = time.monotonic()
        time.sleep(1.5)
        b = _thread_cpu_ticks(pid)
        wall = time.monotonic() - t0
        assert s.state().ticks > 500
        summary = s.close()
    helpers = {tid: (b[tid] - a.get(tid, 0)) / hz / wall for tid in b if tid != pid}
    assert all(share < 0.10 for share in helpers.values()), f"busy helper threads (share of a CPU): {helpers}"
    assert "set_num_threads" in summary["thread_pools"]  # numpy/scipy's OpenBLAS pools limited


_POOL_PROBE = r"""
import os, sys, threading, time
import numpy as np
import scipy.linalg as sl
from hapticsdk.threadpools import one_thread
if sys.argv[1] == "limit":
    print(one_thread(), file=sys.stderr)
def cpu():
    out = {}
    for t in os.listdir("/proc/self/task"):
        st = open(f"/proc/self/task/{t}/stat").read()
        f = st[st.rindex(")") + 2:].split()
        out[t] = int(f[11]) + int(f[12])
    return out
a = np.random.default_rng(0).random((5, 5))
t0 = time.monotonic()
while time.monotonic() - t0 < 0.5:   # warm-up, not measured (test docstring)
    sl.expm(a * 1e-3)
    time.sleep(0.0008)
c0 = cpu()
t0 = time.monotonic()
while time.monotonic() - t0 < 1.0:   # a servo-like caller: one small expm per millisecond
    sl.expm(a * 1e-3)
    time.sleep(0.0008)
c1 = cpu()
me = str(threading.get_native_id())
print(c1[me] - c0[me], sum(c1[t] - c0.get(t, 0) for t in c1 if t != me), len(c1) - 1)
"""


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="per-thread CPU times from /proc (Linux)")
@pytest.mark.parametrize("mode", ["limit", "as-is"])
def test_one_pool_thread_stops_a_spinning_blas_worker(mode):
    """What the servo process does to its BLAS pools: scipy's OpenBLAS, fed one small
    matrix exponential per millisecond, keeps a worker thread busy-waiting between the
    calls (it used about as much CPU as the calling thread, or more); after
    hapticsdk.threadpools.one_thread() the calls run in the calling thread and the helpers stay idle.
    ``as-is`` checks that this machine shows the hazard at all (else the test could
    not fail); both runs take 1 s, after 0.5 s of the same calls that are not measured.

    The warm-up: an OpenBLAS worker busy-waits for ``THREAD_TIMEOUT`` (2^28 cycles by
    default: 0.1 s at 2.7 GHz, 0.27 s at 1 GHz) after its creation or its last job before
    it sleeps. Under ``limit`` the workers get no job after ``one_thread()``, so what
    they spend after being created at import is not the hazard; it fell inside the
    measured second where the import was fast (the oldest allowed numpy 1.24.2 and scipy
    1.15.0 load two OpenBLAS pools: helpers 4-7 clock ticks against the caller's 2-5 in 4
    of 8 runs on an idle machine, failing the bound once in CI; 0 in 8 of 8 with the
    warm-up). Under ``as-is`` the workers get a job every millisecond, so they spin
    through the warm-up and the measured second alike."""
    out = subprocess.run([sys.executable, "-c", _POOL_PROBE, mode], capture_output=True, text=True, timeout=120,
                         check=False)
    assert out.returncode == 0, out.stderr
    main, helpers, n_helpers = map(int, out.stdout.split())
    # The hazard is a helper that spins between calls: it then uses at least as much CPU
    # as the caller (on an idle machine about the whole second, 100 ticks, against the
    # caller's 3-5). CPU time is charged in whole clock ticks, and a thread that ran at
    # all can be charged one, so each helper thread may show one tick of rounding. On a
    # busy machine a helper's wake-up and teardown also cost a tick or two (CI saw 3
    # ticks against the caller's 5), which stays below the caller's own time.
    bound = main + n_helpers
    if mode == "limit":
        assert "set_num_threads(1)" in out.stderr, out.stderr
        assert helpers <= bound, (main, helpers, n_helpers)
    else:
        if helpers <= bound:
            pytest.skip("this BLAS does not busy-wait between small calls here")
        assert helpers > bound


def test_partly_written_command_never_blocks_the_servo(wait):
    """A command the application has only partly written (a message larger than the
    pipe's atomic write, or an application descheduled in the middle of it) leaves the
    servo ticking; the command applies once the rest arrives."""
    import pickle
    with Session(PAD, isolation="thread", trajectory=SLIDE, realtime=False) as s:
        assert wait(lambda: s.state().ticks > 10)
        feats = s._answer({"hardness": 0.9})[0]
        payload = pickle.dumps(("material", 0, feats, 0.0))
        frame = len(payload).to_bytes(4, "big") + payload
        fd = s._cmd.fileno()
        half = len(frame) // 2
        assert os.write(fd, frame[:half]) == half
        n0 = s.state().ticks
        assert wait(lambda: s.state().ticks > n0 + 100, 5.0), "the servo stopped ticking"
        assert s.state().material_switches == 0
        t_sent = time.monotonic()
        assert os.write(fd, frame[half:]) == len(frame) - half
        assert wait(lambda: s.state().material_switches == 1, 5.0)
        st = s.state()
        assert st.switched_at >= t_sent  # published by the tick that rendered it first
        assert any(e.kind == "material_switched" and e.object == "pad" for e in s.events())


def test_closed_command_pipe_means_the_application_is_gone(wait):
    """Every writer of the command pipe closed (the application exited, however it
    died): the servo stops every actuator and exits; the next call says why."""
    with Session(PAD, trajectory=SLIDE) as s:
        assert wait(lambda: s.state().ticks > 20)
        s._cmd.close()
        with pytest.raises(ServoProcessDied) as ei:
            assert wait(lambda: s.state() is None, 10.0)
        assert "closed its command pipe" in str(ei.value)
        assert set(s._summary["stopped"]) >= {"omni-virtual", "voicecoil-virtual"}


class _StubClock:
    def __init__(self):
        self.t = 0.0

    def now(self):
        return self.t


class _StubLoop:
    realtime = True
    period_s = 1e-3
    last_compute_s = 40e-6

    def __init__(self):
        self.clock = _StubClock()
        self._deadline = 1e-3


class _StubReader:
    eof = False

    def __init__(self, msgs):
        self.msgs = list(msgs)

    def read(self):
        out, self.msgs = self.msgs, []
        return out


def test_command_work_waits_for_slack_then_is_forced():
    """serve() runs a command's slice only when its estimated cost fits before the next
    deadline; otherwise it waits for a later period, at most _MAX_WAIT_TICKS ticks,
    then runs it anyway; a slice longer than any period's slack runs at once."""
    from collections import deque

    from hapticsdk.runtime.session import servo as sm
    from hapticsdk.runtime.session.protocol import _NSLOTS
    srv = sm._Servo({}, memoryview(bytearray(_NSLOTS * 8)).cast("d"), None, True)
    loop = srv.loop = _StubLoop()
    ran = []

    def command(msg):
        yield msg[1]  # estimated cost of the one slice
        ran.append(msg[0])

    srv._command = command
    srv._queue = deque()
    # 300 us of work, 800 us left before the deadline (minus the 100 us margin): at once
    loop.clock.t = loop._deadline - 800e-6
    srv._reader = _StubReader([("fits", 300e-6)])
    srv.serve()
    assert ran == ["fits"]
    # 500 us of work, 300 us left: waits while later periods could hold it ...
    loop.clock.t = loop._deadline - 300e-6
    srv._reader = _StubReader([("waits", 500e-6)])
    for _ in range(sm._MAX_WAIT_TICKS):
        srv.serve()
        srv.serve()  # called again in the same period (the clock serves before each sleep)
        assert ran == ["fits"]
        loop._deadline += 1e-3  # the next period, again 300 us left
        loop.clock.t += 1e-3
    srv.serve()  # ... then runs anyway
    assert ran == ["fits", "waits"] and srv.cmd_stats["forced_slices"] == 1
    # 5 ms of work never fits in a 1 ms period: no waiting; but a second forced slice
    # waits for the next tick
    srv._reader = _StubReader([("never fits", 5e-3), ("never fits either", 5e-3)])
    srv.serve()
    assert ran == ["fits", "waits", "never fits"] and srv.cmd_stats["forced_slices"] == 2
    srv.serve()
    assert ran == ["fits", "waits", "never fits", "never fits either"] and srv.cmd_stats["forced_slices"] == 3
    assert srv.cmd_stats["done"] == 4 and srv.cmd_stats["received"] == 4


def test_benchmark_reference_loop_is_paced():
    """``hapticsdk bench live``'s reference row: a loop paced on the servo's clock and
    grid. It never starts a tick before its deadline, so its mean period cannot be
    shorter than T (less the first tick's few-microsecond lateness spread over 299
    periods); it reports the session's jitter keys."""
    from hapticsdk.benchmarks.live import run_reference
    ref = run_reference("none", 0.3)
    assert ref["periods"] == 299
    assert ref["mean_period_us"] >= 999.0
    assert {"p50_us", "p99_us", "max_us", "missed_tick_rate"} <= set(ref)


@pytest.mark.parametrize("kind", ["python-thread", "numpy-thread"])
def test_benchmark_application_load_keeps_a_cpu_busy_until_stopped(kind):
    """``hapticsdk bench live --app-load``'s application loads (the CLI test in
    test_bench_baseline.py runs with ``none``): the thread takes CPU time while it runs and
    returns once told to stop. The 30 s are only how long a broken load may hang the test."""
    import threading

    from hapticsdk.benchmarks.live import _load
    if not hasattr(time, "pthread_getcpuclockid"):
        pytest.skip("needs a thread's CPU clock (POSIX)")
    stop = threading.Event()
    th = threading.Thread(target=_load, args=(kind, stop), daemon=True)
    th.start()
    clock = time.pthread_getcpuclockid(th.ident)
    give_up = time.monotonic() + 30.0
    while th.is_alive() and time.clock_gettime(clock) < 0.02 and time.monotonic() < give_up:
        time.sleep(0.005)
    assert th.is_alive() and time.clock_gettime(clock) >= 0.02   # the thread's own CPU time
    stop.set()
    th.join(30.0)
    assert not th.is_alive()


def test_serving_clock_serves_commands_in_the_sleep_and_keeps_the_deadline():
    """The servo's clock calls serve() before it sleeps (so a command is taken up
    while the servo would otherwise sleep), never returns before the deadline, and
    returns at once when serve() used up the time."""
    from hapticsdk.runtime.clock import MonotonicClock
    calls = []
    clock = MonotonicClock(serve=lambda: calls.append(time.perf_counter()))
    deadline = time.perf_counter() + 5e-3
    clock.wait_until(deadline)
    assert time.perf_counter() >= deadline
    assert calls and all(c < deadline - clock.spin_s for c in calls)

    def slow():
        calls.append(time.perf_counter())
        while time.perf_counter() < deadline2 + 1e-3:
            pass
    clock = MonotonicClock(serve=slow)
    calls.clear()
    deadline2 = time.perf_counter() + 3e-3
    clock.wait_until(deadline2)
    assert len(calls) == 1  # no second serve and no sleep once past the deadline


class _Unpicklable:
    def renderers_for(self, feats):
        class Local:  # a class defined in a function cannot be pickled
            pass
        return [Local()]


def test_renderers_that_cannot_be_pickled_are_built_by_the_servo(wait):
    """set_material builds the renderers in the application and sends them pickled;
    when that fails (a plugin's renderer that does not pickle) it sends the features
    and the servo builds them itself."""
    with Session(PAD, isolation="thread", trajectory=SLIDE_AND_HOLD, realtime=False) as s:
        assert wait(lambda: s.state().ticks > 10)
        s._builder = _Unpicklable()
        s.set_material("pad", {"hardness": 0.9}, refine=False)
        assert wait(lambda: s.state().material_switches == 1, 5.0)
        servo = s._servo_holder[0]
        assert "<unpickle>" not in servo._build_s and servo.cmd_stats["failed"] == 0


def test_calibration_tables_cross_the_pipe_once(wait):
    """set_material sends the renderers pickled with references to the calibration
    tables they hold (the piezo's drive table, the same for every material): the first
    switch sends each table in a "tables" command before the renderers that refer to
    it; later switches send only the renderers (kilobytes, not the table's ~300 kB),
    and the servo's new renderers use the table it kept."""
    import pickle

    from hapticsdk.calibration.piezo import PiezoTable
    from hapticsdk.runtime.session import shipping as sm
    scene = {"schema_version": 1, "name": "s7", "objects": [{"name": "pad", "material": "S7"}],
             "settings": {"importance": {"enabled": False}, "solver": {"seed": 0}}}
    with Session(scene, isolation="thread", trajectory=SLIDE_AND_HOLD, realtime=False, refine=False) as s:
        sent = []
        send = s._send
        s._send = lambda msg: (sent.append(msg), send(msg))[1]
        assert wait(lambda: s.state().ticks > 10)
        s.set_material("pad", "S12")
        assert wait(lambda: s.state().material_switches == 1, 10.0)
        assert [m[0] for m in sent] == ["tables", "renderers"]
        (key, blob), = sent[0][1].items()
        table = pickle.loads(blob)
        assert isinstance(table, PiezoTable)
        # the table alone is most of a plain pickle of the renderers
        servo = s._servo_holder[0]
        assert len(blob) > 0.5 * len(pickle.dumps(servo.loop._objs[0].renderers))
        s.set_material("pad", "S3")
        assert wait(lambda: s.state().material_switches == 2, 10.0)
        assert [m[0] for m in sent] == ["tables", "renderers", "renderers"]
        # the second switch carries no table: under a tenth of the table's size
        assert len(sent[2][2]) < 0.1 * len(blob)
        assert servo.cmd_stats["failed"] == 0 and set(servo._tables) == {key}
        kept = servo._tables[key]
        with_table = [r for r in servo.loop._objs[0].renderers if isinstance(getattr(r, "table", None), PiezoTable)]
        assert with_table and all(r.table is kept for r in with_table)
        # a reference to a table the servo never received is refused, not guessed
        with pytest.raises(pickle.UnpicklingError):
            sm._load_renderers(sent[2][2], {})


def test_state_fields_come_from_the_slots_the_servo_writes():
    """state() reads the slots with one struct call and builds the tuple by position:
    every field must come from the slot the servo publishes it in (distinct values in
    every slot, each field checked against its named slot)."""
    import hapticsdk.runtime.session.protocol as ss
    slots = [0.0] + [float(100 + i) for i in range(1, 24)] + [0.0]  # slot i holds 100 + i
    slots[ss._OBJ], slots[ss._NEAR] = 3.0, 7.0
    slots[ss._PAUSED_S] = 1.0
    names = {3: "cube", 7: "ball"}
    buf = bytearray(ss._NSLOTS * 8)
    memoryview(buf).cast("d")[:25] = memoryview(bytearray(__import__("struct").pack("25d", *slots))).cast("d")
    before = time.monotonic()
    st = ss._state_from(ss._read_state(buf), names)
    v = lambda k: float(100 + k)  # noqa: E731
    assert st.t == v(ss._T) and st.force_n == v(ss._F) and st.penetration_mm == v(ss._PEN)
    assert st.position_mm == (v(ss._PX), v(ss._PY), v(ss._PZ))
    assert st.velocity_mm_s == (v(ss._VX), v(ss._VY), v(ss._VZ))
    assert (st.object, st.near, st.paused) == ("cube", "ball", True)
    assert (st.ticks, st.overruns, st.skipped_ticks, st.renderer_errors, st.clamps, st.missed_ticks,
            st.material_switches) == tuple(int(v(k)) for k in (ss._TICKS, ss._OVERRUNS, ss._SKIPPED, ss._RERR,
                                                                ss._CLAMPS, ss._MISSED, ss._SWITCHES))
    assert (st.tick_us, st.tick_max_us, st.switched_at) == (v(ss._TICK_US), v(ss._TICK_MAX_US), v(ss._SWITCHED_AT))
    assert before - v(ss._PUB) <= st.age_s <= time.monotonic() - v(ss._PUB)
    assert all(isinstance(getattr(st, f), int) for f in ("ticks", "overruns", "clamps"))
    slots[ss._OBJ] = slots[ss._NEAR] = -1.0  # nothing in contact, nothing near
    st = ss._state_from(slots, names)
    assert st.object is None and st.near is None


def test_live_benchmark_rows_say_what_scheduling_the_servo_got():
    """The text table names the scheduling the servo was granted (or refused) and the
    cold-call reference next to the state() figures; the CLI's option reaches the run."""
    from hapticsdk.benchmarks.live import format_rows
    from hapticsdk.cli.bench_runtime import _fifo_priority
    pct = {"p50": 1.0, "p99": 2.0, "max": 3.0, "n": 5}
    row = {"isolation": "process", "app_load": "none",
           "jitter": {"p50_us": 0.1, "p99_us": 1.0, "max_us": 5.0, "missed_tick_rate": 0.0},
           "switch": {"latency_ms": 1.2, "max_force_step_n": 0.08, "energy_j": 0.0},
           "app_call_us": {"state": 2.0, "state_p99": 2.5, "set_material": 900.0, "state_stats": pct, "state_cpu_stats": pct,
                           "state_cpu_back_to_back_stats": pct, "set_material_cpu_stats": pct,
                           "trivial_cpu_after_sleep_stats": {**pct, "p50": 1.7}},
           "servo": {"rt": {"rt_priority": "refused: EPERM (x); the servo runs at normal priority",
                            "cpu_affinity": "off", "mlockall": "off"}}}
    text = format_rows([row, {**row, "app_load": "python-thread"}])
    assert text.count("servo process: rt priority refused: EPERM") == 1  # once for equal rows
    assert "cpu affinity" not in text  # "off" is not news
    assert "costs 1.7-1.7 us" in text
    assert (_fifo_priority("auto"), _fifo_priority("off"), _fifo_priority("7")) == ("auto", None, 7)


@pytest.mark.parametrize("isolation, servo_running", [("thread", False), ("process", None)])
def test_the_warm_up_runs_once_and_in_a_thread_session_before_its_servo(monkeypatch, isolation, servo_running):
    """The session's warm-up (the amortised tables, the application's renderer builder)
    runs once. In a thread session it runs before the servo thread starts: the two share
    one interpreter lock, and beside a simulated-time servo, which runs flat out, a cold
    table build went from about 1 s to over 3 minutes (each numpy call waited for the
    lock). A process session warms up while its servo process starts."""
    import threading

    calls = []
    real = Session._warm

    def spy(self):
        calls.append(any(t.name == "hapticsdk-servo" for t in threading.enumerate()))
        return real(self)
    monkeypatch.setattr(Session, "_warm", spy)
    with Session(PAD, isolation=isolation, realtime=False, refine=False):
        pass
    assert len(calls) == 1
    if servo_running is not None:
        assert calls == [servo_running]
