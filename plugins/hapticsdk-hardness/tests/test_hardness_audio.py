"""``voicecoil-audio`` against a real audio server started here: JACK (Debian jackd2) on
its dummy driver, 48 kHz, 128-frame periods, the output captured back through a loopback
port (:mod:`hapticsdk_hardness.audio_loopback`).

Tolerances, from the measurement itself: the frequency comes from ~100 interpolated
zero crossings of float32 samples (error well under 0.01 Hz when the phase is
continuous), so the issue's 0.5 Hz goal is the bound; the amplitude is float32
end to end through JACK (bit-exact), so 2 % (the goal) only leaves room for the RMS
estimate over whole cycles. Timing goals (command-to-sound within 10 ms, stop-to-silence
within 20 ms) are not tested here: they are figures of how soon this machine schedules
the audio processes, which another CPU-bound job changes (two suites run at once failed
them once); ``bench/bench_voicecoil_audio.py`` measures them, by hand. The tests check
instead what holds however late a process runs, counted in samples where they can be
(see :func:`hapticsdk_hardness.audio_loopback.measure`)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import DeviceError, DeviceNotFoundError
from hapticsdk.testing import ActuatorConformance


@pytest.fixture(scope="module")
def jack(missing):
    from hapticsdk_hardness.audio_loopback import JackServer
    why = JackServer.available()
    if why:
        missing(why)
    with JackServer(rate=48000, period=128) as srv:
        yield srv


@pytest.fixture
def loop(jack):
    from hapticsdk_hardness.audio_loopback import LoopbackCapture
    with LoopbackCapture(jack) as cap:
        yield cap


def _coil(**kw):
    from hapticsdk.devices.safety import SafetyLayer
    from hapticsdk_hardness.audio import VoiceCoilAudio
    return VoiceCoilAudio(safety=SafetyLayer(VoiceCoilAudio.limits, ramp_time_s=0.0), **kw)


@pytest.mark.parametrize("isolation", ["thread", "process"])
def test_missing_sounddevice_is_named(monkeypatch, tmp_path, isolation):
    """sounddevice or PortAudio missing where the stream would run: in this process
    (the import fails here), or in the audio process (a ``sounddevice`` on its path that
    fails to load, as sounddevice does without the PortAudio library)."""
    from hapticsdk_hardness import audio
    def fail(name):
        raise OSError("PortAudio library not found")
    monkeypatch.setattr(audio.importlib, "import_module", fail)
    (tmp_path / "sounddevice.py").write_text("raise OSError('PortAudio library not found')\n")
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    with pytest.raises(DeviceNotFoundError) as ei:
        audio.VoiceCoilAudio(isolation=isolation).open()
    assert "libportaudio2" in str(ei.value) and "hapticsdk-hardness[audio]" in str(ei.value)
    assert "PortAudio library not found" in str(ei.value)
    ok, why = audio.VoiceCoilAudio.check_available()
    assert not ok and "sounddevice" in why


def test_unknown_device_lists_outputs(jack):
    with pytest.raises(DeviceNotFoundError) as ei:
        _coil(device="no such card").open()
    assert "no such card" in str(ei.value) and "system" in str(ei.value)


def _measured_right(m, period):
    """The checks of a measure() result (see the loopback test below)."""
    assert m["frequency_error_hz"] <= 0.5, m
    assert m["amplitude_rel_error"] <= 0.02, m
    assert m["samples_before_command"] > 0 and m["sound_before_command"] == 0, m
    assert m["samples_checked_after_stop"] >= 4 * period and m["samples_after_stop"] == 0, m
    assert np.isfinite(m["latency_dac_ms"]) and np.isfinite(m["stop_dac_ms"]), m


@pytest.mark.parametrize("isolation", ["process", "thread"])
@pytest.mark.parametrize("freq,amp", [(250.0, 0.5), (61.3, 0.8), (997.0, 0.2)])
def test_frequency_amplitude_start_stop_through_the_loopback(jack, loop, freq, amp, isolation):
    """Frequency and amplitude (tolerances: the module doc); the sound starts after the
    command: the samples captured before the first command (rendered before it, however
    late anything ran) are silent; the sound stops: past the blocks that can be in
    flight when ``stop()`` returns (at most two periods, one more per server xrun), at
    least four periods more are captured and every one is silent; and the start and stop
    times are finite, i.e. there was a sound to time. How soon it starts and stops (the
    10 ms and 20 ms goals) is bench/bench_voicecoil_audio.py's, see the module doc."""
    from hapticsdk_hardness.audio_loopback import measure
    coil = _coil(device="system", full_scale=0.9, isolation=isolation)
    with coil:
        loop.route()
        m = measure(coil, loop, frequency_hz=freq, amplitude=amp, seconds=0.6)
    _measured_right(m, jack.period)


@pytest.mark.parametrize("isolation", ["process", "thread"])
def test_measure_holds_through_a_servo_stall(jack, loop, isolation):
    """The thread that commands the coil stalls right after its first sounding command,
    for longer than the whole measurement (0.6 s + 0.1 s), as on a busy machine (a test
    process at nice 19 next to five CPU-bound ones slept 1 ms and woke 0.64 s later):
    the coil's dead-man's switch silences it after command_timeout_s (its safety rule,
    counted in ``timeouts``), and measure() holds on until 0.6 s of sound are captured,
    so the same checks as the loopback test above hold. A hold timed on the wall clock
    captured one 50 ms burst here: too few cycles at 61.3 Hz for a frequency (NaN)."""
    from hapticsdk_hardness.audio_loopback import measure
    coil = _coil(device="system", full_scale=0.9, isolation=isolation)
    seconds = 0.6
    with coil:
        loop.route()
        command = coil.command
        stalled = []

        def stalling(cmd, *a, **kw):
            out = command(cmd, *a, **kw)
            if cmd.amplitude and not stalled:
                stalled.append(cmd)
                time.sleep(seconds + 0.1)
            return out
        coil.command = stalling
        m = measure(coil, loop, frequency_hz=61.3, amplitude=0.8, seconds=seconds)
        assert stalled and coil.timeouts >= 1, coil.timeouts
    _measured_right(m, jack.period)


@pytest.mark.parametrize("isolation", ["process", "thread"])
def test_phase_continuous_across_frequency_changes(jack, loop, isolation):
    """A sweep of frequency steps every 20 ms: no sample-to-sample jump beyond what a
    continuous sine of the highest frequency can do (2 pi f A / fs)."""
    coil = _coil(device="system", isolation=isolation)
    fs, amp = 48000.0, 0.7
    with coil:
        loop.route()
        from hapticsdk_hardness.audio_loopback import hold
        hold(coil, 0.1, frequency_hz=100.0, amplitude=amp)
        loop.clear()
        for f in (100.0, 173.0, 412.0, 90.0, 650.0, 233.0):
            hold(coil, 0.02, frequency_hz=f, amplitude=amp)
        coil.stop()
        time.sleep(0.05)
    _, y = loop.signal()
    loud = np.nonzero(np.abs(y) > 1e-4)[0]
    seg = y[loud[0]:loud[-1]]
    bound = 2 * np.pi * 650.0 * amp / fs
    assert np.abs(np.diff(seg)).max() <= bound * 1.01 + 1e-6


@pytest.mark.parametrize("isolation", ["process", "thread"])
def test_dead_servo_goes_silent(jack, loop, isolation):
    """No command for longer than command_timeout_s (30 ms): the callback itself goes
    silent, and says so (``timeouts``). A coil without the switch would sound to the end
    of the capture, so the end of the capture is checked, in samples: once at least
    0.2 s of audio has been captured after the last command, the last four periods
    captured are silent. How soon after the timeout the silence comes depends on how
    soon the audio process runs: not checked here (it was once, at 10 ms of allowance)."""
    coil = _coil(device="system", command_timeout_s=0.03, isolation=isolation)
    with coil:
        loop.route()
        from hapticsdk_hardness.audio_loopback import hold
        hold(coil, 0.2, frequency_hz=200.0, amplitude=0.5)
        n_last = loop.count()
        time.sleep(0.2)                                  # the servo stalls, nobody calls stop()
        assert loop.wait_for(n_last + int(0.2 * jack.rate)), "the capture stopped"
        assert coil.timeouts >= 1
        t, y = loop.signal()
        loud = np.nonzero(np.abs(y) > 1e-4)[0]
        assert loud.size, "the coil was never heard"
        assert not (np.abs(y[-4 * jack.period:]) > 1e-4).any(), (y.size, loud[-1])
        with coil:
            pass


GONE = """
import os, sys, time
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import DeviceError
from hapticsdk_hardness.audio import VoiceCoilAudio
from hapticsdk_hardness.audio_loopback import JackServer
with JackServer(rate=48000, period=256) as srv:
    coil = VoiceCoilAudio().open()
    coil.command(ChannelCommand("vibration", frequency_hz=100.0, amplitude=0.1))
    srv.stop()
    deadline = time.monotonic() + 5
    try:
        while time.monotonic() < deadline:
            coil.command(ChannelCommand("vibration", frequency_hz=100.0, amplitude=0.1))
            time.sleep(0.01)
        print("no error")
    except DeviceError as exc:
        coil.close()
        print("device error;", exc, "; closed", not coil.is_open, coil.abandoned)
    sys.stdout.flush()
    os._exit(0)   # PortAudio's exit handler would touch the dead stream (see the module doc)
"""


def test_server_gone_is_a_device_error(missing):
    """The JACK server dies under a playing stream (in a child process: see GONE)."""
    from hapticsdk_hardness.audio_loopback import JackServer
    why = JackServer.available()
    if why:
        missing(why)
    r = subprocess.run([sys.executable, "-c", GONE], capture_output=True, text=True, timeout=60)
    assert "device error;" in r.stdout and "stream stopped" in r.stdout, r.stdout + r.stderr[-2000:]
    assert r.stdout.strip().endswith("closed True True")


def test_underruns_are_counted(jack):
    """A callback that overruns its period (here: made to take 3 periods) is reported in
    ``underruns``; the goal (none in 10 minutes with a busy application thread) is
    measured by bench/bench_voicecoil_audio.py, not here (a timing figure of a loaded
    machine is not a unit test)."""
    from hapticsdk_hardness.audio_loopback import hold
    coil = _coil(device="system", isolation="thread")
    with coil:
        hold(coil, 0.2, frequency_hz=150.0, amplitude=0.3)
        quiet = coil.underruns
        render = coil.osc.render

        def slow(*a):
            time.sleep(3 * 128 / 48000)
            return render(*a)
        coil.osc.render = slow
        # each overrunning callback is one; how many run in a given time is this machine's
        # scheduling: hold until five are counted (10 s: a stuck test, not a measurement)
        deadline = time.monotonic() + 10.0
        while coil.underruns - quiet < 5 and time.monotonic() < deadline:
            hold(coil, 0.05, frequency_hz=150.0, amplitude=0.3)
        assert coil.underruns - quiet >= 5
        # the stream still runs (and still overruns) while we read: describe() reports the
        # counter as it was between two reads of it, which only grows
        before = coil.underruns
        reported = coil.describe()["underruns"]
        assert before <= reported <= coil.underruns


def _render_cli(jack, loop, tmp_path, *args):
    cfg = tmp_path / "devices.json"
    cfg.write_text(json.dumps({"voicecoil-audio": {"device": "system"}}))
    os.chmod(cfg, 0o600)
    env = dict(os.environ, HAPTICSDK_DEVICE_CONFIG=str(cfg), JACK_DEFAULT_SERVER=jack.name)
    loop.clear()
    proc = subprocess.Popen([sys.executable, "-m", "hapticsdk", "render", *args, "--device", "coil=voicecoil-audio",
                             "--seconds", "2", "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)
    deadline = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline:
        loop.route()
        time.sleep(0.02)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode in (0, 1), err[-2000:]
    rep = json.loads(out)
    desc = [d for d in rep["devices"].values() if d.get("name") == "voicecoil-audio"]
    assert desc and desc[0]["device_name"] == "system" and desc[0]["callbacks"] > 0
    t, y = loop.signal()
    return rep, t, y


def test_render_cli_plays_through_the_server(jack, loop, tmp_path):
    """`hapticsdk render ... --device coil=voicecoil-audio` in a child process, the card
    chosen by name in the user device configuration (privileged). S7's hardness (GS
    0.16 N/mm) is below the arm's 2.3 N/mm, so the hardness renderer leaves the coil
    silent: the stream runs on the server and the capture is silence. Hardness 1.0 (GS
    above 2.3 N/mm) drives the coil at the formula (7) frequency the render reports:
    the capture shows that frequency while the probe is in contact."""
    from hapticsdk_hardness.audio_loopback import sine_fit
    rep, t, y = _render_cli(jack, loop, tmp_path, "S7")
    assert rep["renderers"]["hardness"]["coil_frequency_hz"] is None
    assert t.size > 48000 and np.abs(y).max() == 0.0
    rep, t, y = _render_cli(jack, loop, tmp_path, "--hardness", "1.0")
    f_coil = rep["renderers"]["hardness"]["coil_frequency_hz"]
    loud = np.nonzero(np.abs(y) > 1e-4)[0]
    assert loud.size > 0.2 * 48000, "the coil was not heard"
    # the frequency on the sample clock, as measure() does: the capture blocks' times
    # carry the capture callback's scheduling delay (on a busy machine it moved the fit
    # to 111.2 Hz against 109.9 once); a dropout changes a cycle by a whole JACK period
    # (128 samples, about 30 % of a cycle here), and sine_fit leaves such cycles out
    ys = y[loud[0]:loud[-1]]
    f, a = sine_fit(np.arange(ys.size) / float(jack.rate), ys)
    assert f == pytest.approx(f_coil, abs=0.5)


class TestVoiceCoilAudioConformance(ActuatorConformance):
    plugin_name = "voicecoil-audio"

    @pytest.fixture
    def actuator_factory(self, jack):
        from hapticsdk_hardness.audio import VoiceCoilAudio
        return lambda: VoiceCoilAudio(device="system")


def test_loud_since_counts_what_a_full_count_counts():
    """LoopbackCapture.loud_since reads only new blocks when asked again: its counts
    equal a count over everything captured, as blocks arrive, for another start or
    level, and after clear() (no audio server: blocks put in as the callback does)."""
    import threading
    from hapticsdk_hardness.audio_loopback import LoopbackCapture
    cap = object.__new__(LoopbackCapture)
    cap.blocks, cap._lock, cap._cleared, cap._loud = [], threading.Lock(), 0, ((), 0, 0, 0)
    rng = np.random.default_rng(0)

    def full(start, level):
        y = np.concatenate([b for _, b in cap.blocks]) if cap.blocks else np.zeros(0)
        return int(np.count_nonzero(np.abs(y[start:]) > level))
    for start, level in ((0, 0.5), (137, 0.5), (137, 1.5)):
        for step in range(40):                    # as measure() asks: the same question
            cap.blocks.append((0.0, rng.normal(size=int(rng.integers(1, 200))).astype(np.float32)))
            assert cap.loud_since(start, level) == full(start, level)
            if step == 20:
                cap.clear()
                assert cap.loud_since(start, level) == 0
        assert cap.loud_since(0, 0.5) == full(0, 0.5)          # another question
        assert cap.loud_since(start, level) == full(start, level)


def test_wait_for_follows_a_goal_that_moves():
    """LoopbackCapture.wait_for with a callable goal asks for it on every look (measure()'s
    wait after stop(): the samples in flight grow with each xrun the server reports), and
    returns once the capture has reached the goal as last asked (no audio server: a
    capture that grows by 100 samples a look, a goal that grows by 50)."""
    from hapticsdk_hardness.audio_loopback import LoopbackCapture
    cap = object.__new__(LoopbackCapture)
    captured = [0]

    def count():
        captured[0] += 100
        return captured[0]
    cap.count = count
    asked = []

    def goal():
        asked.append(300 + 50 * len(asked))
        return asked[-1]
    assert cap.wait_for(goal, 5.0)
    assert len(asked) == 5 and captured[0] == 500 == asked[-1]
    assert cap.wait_for(700, 5.0) and captured[0] == 700     # a plain count as before


@pytest.mark.parametrize("f0", [109.889, 997.0])
def test_sine_fit_on_silence_gaps_and_exact_zeros(f0):
    """The estimator of these measurements: exact for a sine with gaps of silence (a
    dropout; the coil's own silence when its commands stop coming, 40 ms of it seen once
    on a busy machine, which took 3.5 % off an RMS over every cycle) and with samples
    that are exactly 0 (no division by zero). The gaps here are 8 % of the samples: an
    RMS that counted them would be 4 % low. Tolerances: the frequency of whole cycles of
    interpolated crossings, well under 0.01 Hz; the RMS of a sampled sine over whole
    cycles, within 1e-3 (cycles of 48000 / f0 samples, a fraction of a sample each)."""
    from hapticsdk_hardness.audio_loopback import sine_fit
    fs = 48000.0
    t = np.arange(int(fs)) / fs
    y = 0.5 * np.sin(2 * np.pi * f0 * t)
    for g0 in (5000, 20000, 33000):
        y[g0:g0 + 1280] = 0.0
        y[g0:g0 + 1280:2] = -0.0     # signed zeros, as a float32 silence can carry
    f, a = sine_fit(t, y)
    assert f == pytest.approx(f0, abs=0.01) and a == pytest.approx(0.5, rel=1e-3)
    assert np.isnan(sine_fit(t, np.zeros_like(t))[0])


def test_thread_callback_keeps_a_command_that_lands_during_it(monkeypatch):
    """Thread isolation: the audio callback renders a block from a target older than
    command_timeout_s (silence: the dead-man's switch), and the servo's next command
    lands while the callback still runs (the coil lowers the switch interval to 0.1 ms,
    so the servo thread can take the interpreter lock between any two bytecodes of the
    callback). That fresh command is read back and the next block sounds: the callback
    writes nothing the servo writes (it once set the silence flag after the render,
    over the command's own write, which silenced the command and its read-back until the
    next command came). Clock and interleaving made here, no audio server needed."""
    from hapticsdk_hardness import audio
    clock = [100.0]
    monkeypatch.setattr(audio, "time", type("T", (), {"monotonic": staticmethod(lambda: clock[0])}))
    coil = audio.VoiceCoilAudio(isolation="thread", command_timeout_s=0.05)
    coil._renderer = renderer = coil._new_renderer(48000.0)
    c = ChannelCommand("vibration", frequency_hz=200.0, amplitude=0.5)
    out = np.zeros((128, 1), np.float32)
    status = type("S", (), {"output_underflow": False})()
    coil._command(c)
    coil._callback(out, 128, None, status)
    assert np.abs(out).max() > 0.1                      # a fresh command sounds
    clock[0] += 0.2                                      # the servo stalls past the timeout

    class ServoRunsDuring:                               # the next command lands mid-callback
        timed_out, error = property(lambda s: renderer.timed_out), property(lambda s: renderer.error)

        def __call__(self, *a):
            renderer(*a)
            coil._command(c)
    coil._renderer = ServoRunsDuring()
    coil._callback(out, 128, None, status)
    assert not np.abs(out).any() and renderer.timeouts == 1   # the stale target: silence
    coil._renderer = renderer
    assert coil._read_back().amplitude == 0.5           # the fresh command is the target
    coil._callback(out, 128, None, status)
    assert np.abs(out).max() > 0.1                      # and the next block plays it
    clock[0] += 0.2                                      # stalled again, no command meanwhile
    assert coil._read_back().amplitude == 0.0           # the switch's rule, on the same clock
    coil._callback(out, 128, None, status)
    assert not np.abs(out).any() and renderer.timeouts == 2


# -- the audio process (isolation="process", the default) ------------------------------
def test_seqlock_keeps_the_previous_target_during_a_write():
    """The callback's read of the shared target (two mappings of one file, as the two
    processes have): a write in progress (odd sequence number, half the values written)
    is never rendered; the previous target is, until the write completes."""
    from hapticsdk_hardness.audio_process import AMP, FREQ, SEQ, SharedTarget, new_shared_file
    fd = new_shared_file()
    try:
        w, r = SharedTarget(fd), SharedTarget(fd)
        w.write(100.0, 0.5, 1.0, False)
        assert r.read() == (100.0, 0.5, 1.0, 0.0)
        s = w.mv[SEQ]
        w.mv[SEQ] = s + 1.0          # the writer has begun ...
        w.mv[FREQ] = 999.0           # ... and written one value of two
        assert r.read() == (100.0, 0.5, 1.0, 0.0)
        w.mv[AMP] = 0.9
        w.mv[SEQ] = s + 2.0          # done
        assert r.read() == (999.0, 0.9, 1.0, 0.0)
        w.write(50.0, 0.0, 2.0, True)
        assert r.read() == (50.0, 0.0, 2.0, 1.0)
        w.close()
        r.close()
    finally:
        os.close(fd)


def test_process_isolation_leaves_the_application_interpreter_alone(jack):
    """The stream runs in another process: this process's switch interval is untouched
    and no PortAudio stream is opened here."""
    before = sys.getswitchinterval()
    coil = _coil(device="system")
    with coil:
        assert coil.isolation == "process" and coil.stream is None
        assert coil.audio_pid is not None and coil.audio_pid != os.getpid()
        assert sys.getswitchinterval() == before


def _alive(pid):
    """Whether ``pid`` runs (a zombie, dead but not reaped, does not)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except OSError:
        return False


def _until_heard(loop, seconds=10.0):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        loop.route()
        time.sleep(0.1)
        _, y = loop.signal()
        if y.size and np.abs(y[-4800:]).max() > 0.1:
            return
    pytest.fail("the coil was never heard")


def _silent_then_gone(loop, t_kill, audio_pid):
    """After a kill at ``t_kill`` (capture clock): the last sound within 0.25 s (a quarter
    of the coil's 1 s dead-man's switch, which the tests set: silence before that is not
    the switch's doing), and the audio process gone within 10 s."""
    time.sleep(1.3)                                   # past the dead-man's switch
    t, y = loop.signal()
    loud = t[np.abs(y) > 1e-4]
    assert loud.size and loud[-1] - t_kill <= 0.25, (loud[-1] - t_kill if loud.size else None)
    deadline = time.monotonic() + 10
    while _alive(audio_pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(audio_pid), "the audio process outlived its owner"


OWNER = """
import os, sys, time
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.devices.safety import SafetyLayer
from hapticsdk_hardness.audio import VoiceCoilAudio
coil = VoiceCoilAudio(device="system", command_timeout_s=1.0,
                      safety=SafetyLayer(VoiceCoilAudio.limits, ramp_time_s=0.0)).open()
other = 0
if sys.argv[1] == "fork":
    other = os.fork()       # this copy holds the control pipe's write end on
    if other == 0:
        time.sleep(60)
        os._exit(0)
print(coil.audio_pid, other, flush=True)
c = ChannelCommand("vibration", frequency_hz=200.0, amplitude=0.5)
while True:
    coil.command(c)
    time.sleep(0.001)
"""


@pytest.mark.parametrize("variant", ["plain", "fork"])
def test_owner_dying_silences_the_audio_process(jack, loop, variant):
    """The process that opened the coil (an application; a live session's servo process
    is the same case) is killed while it plays: the audio process goes silent and exits.

    The coil's own dead-man's switch is set to its longest, 1 s, so silence well before
    that is the parent check's doing, not the switch's: bound 0.25 s (a quarter of it).
    ``fork``: a forked copy of the owner still holds the control pipe open, so no end of
    file comes; the audio process must notice that its parent changed."""
    app = subprocess.Popen([sys.executable, "-c", OWNER, variant], stdout=subprocess.PIPE, text=True)
    pids = []
    try:
        pids = [int(x) for x in app.stdout.readline().split()]
        assert pids and _alive(pids[0])
        _until_heard(loop)
        t_kill = loop.now()
        app.kill()
        app.wait(10)
        _silent_then_gone(loop, t_kill, pids[0])
    finally:
        app.kill()
        for pid in pids:
            if pid and _alive(pid):
                os.kill(pid, signal.SIGKILL)


def test_audio_process_dying_is_a_named_error(jack, loop):
    """The audio process is killed under a playing coil: the capture goes silent, the
    next command raises AudioProcessDied (a DeviceError) naming the signal, the read-back
    is silence, and close() returns at once (the process is already gone: nothing to
    wait for; bound 1 s, a fifth of the EXIT_WAIT_S a close() that waited for it would take)."""
    from hapticsdk_hardness.audio import AudioProcessDied
    from hapticsdk_hardness.audio_loopback import hold
    coil = _coil(device="system", command_timeout_s=1.0)
    coil.open()
    try:
        loop.route()
        hold(coil, 0.3, frequency_hz=200.0, amplitude=0.5)
        pid = coil.audio_pid
        n_kill = loop.count()
        os.kill(pid, signal.SIGKILL)
        c = ChannelCommand("vibration", frequency_hz=200.0, amplitude=0.5)
        deadline = time.monotonic() + 2.0
        with pytest.raises(AudioProcessDied) as ei:
            while time.monotonic() < deadline:
                coil.command(c)
                time.sleep(0.001)
        assert isinstance(ei.value, DeviceError)
        assert ei.value.exitcode == -signal.SIGKILL and ei.value.reason == "killed by SIGKILL"
        assert str(pid) in str(ei.value) and "voicecoil-audio" in str(ei.value)
        assert coil.read_back().amplitude == 0.0
        with pytest.raises(DeviceError):
            coil.command(c)
        # the killed client leaves the graph: once 0.2 s of audio is captured after the
        # kill, its last four periods are silent (a process still playing would sound to
        # the end; how soon the silence comes is a figure of this machine's scheduling)
        assert loop.wait_for(n_kill + int(0.2 * jack.rate)), "the capture stopped"
        t, y = loop.signal()
        loud = np.nonzero(np.abs(y) > 1e-4)[0]
        assert loud.size and not (np.abs(y[-4 * jack.period:]) > 1e-4).any(), (y.size, loud[-1:])
    finally:
        t0 = time.monotonic()
        coil.close()
        assert time.monotonic() - t0 <= 1.0
    assert not coil.is_open


def test_underruns_in_the_audio_process_are_counted(jack):
    """The audio process is stopped (SIGSTOP) for 20 ms, several periods, five times:
    the JACK server reports the late client, PortAudio flags the next callback with an
    output underflow, and ``underruns`` (the audio process's shared counter) shows it."""
    from hapticsdk_hardness.audio_loopback import hold
    coil = _coil(device="system")
    with coil:
        hold(coil, 0.2, frequency_hz=150.0, amplitude=0.3)
        quiet, calls = coil.underruns, coil.callbacks
        for _ in range(5):
            os.kill(coil.audio_pid, signal.SIGSTOP)
            time.sleep(0.02)
            os.kill(coil.audio_pid, signal.SIGCONT)
            hold(coil, 0.05, frequency_hz=150.0, amplitude=0.3)
        assert coil.callbacks > calls
        assert coil.underruns - quiet >= 1
        before = coil.underruns   # the stream runs on: the counter can grow between reads
        reported = coil.describe()["underruns"]
        assert before <= reported <= coil.underruns
    assert coil.underruns >= quiet + 1          # kept after close


SESSION_APP = """
import time
import hapticsdk as hs
from hapticsdk.sim.finger import Trajectory
scene = {"schema_version": 2, "name": "pad",
         "objects": [{"name": "pad", "material": {"intensities": {"hardness": 1.0}},
                      "geometry": {"shape": "box", "half_size_mm": [20, 10, 20]}, "pose": {"position_mm": [0, -10, 0]}}],
         "devices": {"force": "probe-virtual", "coil": "voicecoil-audio"},
         "settings": {"solver": {"seed": 0}}}
tr = Trajectory([(0.0, 0.0, 3.0), (0.3, 0.0, -1.5), (600.0, 0.0, -1.5)])
with hs.Session(scene, trajectory=tr,
                actuator_options={"coil": {"device": "system", "command_timeout_s": 1.0}}) as s:
    print(s.servo_pid, flush=True)
    while True:
        time.sleep(0.05)
"""


def _cmdline(pid):
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            return fh.read()
    except OSError:
        return b""


def _children(pid):
    out = []
    try:
        for tid in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{tid}/children") as fh:
                out += [int(x) for x in fh.read().split()]
    except OSError:
        pass
    return out


@pytest.mark.parametrize("who", ["servo", "application"])
def test_live_session_death_silences_the_coil(jack, loop, who):
    """A live session (servo in its own process) plays hardness 1.0 on the coil; the
    servo process, or the application, is killed. The coil's audio process is the
    servo's child: it goes silent and exits (the servo killed: its owner is gone; the
    application killed: the servo notices, stops and closes its devices). Bound as for
    the owner test: 0.25 s, a quarter of the coil's 1 s dead-man's switch."""
    app = subprocess.Popen([sys.executable, "-c", SESSION_APP], stdout=subprocess.PIPE, text=True)
    audio = []
    try:
        servo = int(app.stdout.readline())
        deadline = time.monotonic() + 60
        while not audio and time.monotonic() < deadline:
            audio = [p for p in _children(servo) if b"audio_process" in _cmdline(p)]
            time.sleep(0.1)
        assert audio, "no audio process under the servo"
        _until_heard(loop, 60.0)
        t_kill = loop.now()
        os.kill(servo if who == "servo" else app.pid, signal.SIGKILL)
        _silent_then_gone(loop, t_kill, audio[0])
    finally:
        app.kill()
        app.wait(10)
        for pid in audio:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)


def test_read_back_of_a_fresh_command_after_an_idle_spell(jack):
    """An opened coil left without commands longer than its dead-man timeout (its audio
    process then marks its blocks timed out), then commanded: the read-back right after
    the command shows it, before the audio process has run another block. The timed-out
    state is the callback's rule on the command's age, judged on the same clock; the
    process's flag describes a block that predates the command (on a busy machine the
    conformance kit's holds finish within one audio period and read that stale flag)."""
    coil = _coil(device="system", command_timeout_s=0.05)
    coil.open()
    try:
        time.sleep(0.3)   # several timeouts' worth of blocks without a command
        c = ChannelCommand("vibration", frequency_hz=200.0, amplitude=0.4)
        for _ in range(20):   # each at once after its command: no audio block in between
            coil.command(c)
            assert coil.read_back().amplitude == pytest.approx(0.4)
            time.sleep(0.12)  # idle past the timeout again
            assert coil.read_back().amplitude == 0.0
    finally:
        coil.close()
