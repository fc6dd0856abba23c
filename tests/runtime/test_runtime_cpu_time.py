"""ServoLoop: per-tick on-CPU compute time of the servo thread next to the wall-clock
compute time, the preempted-tick counter, and the optional OS real-time options
(refusals reported, never raised)."""

import errno
import gc
import json
import os
import time

import numpy as np
import pytest

from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer
from hapticsdk.errors import ValidationError
from hapticsdk.runtime import ServoLoop
from hapticsdk.runtime import clock as rclock
from hapticsdk.runtime.clock import RealtimeSettings
from hapticsdk.runtime.stats import preemption_stats
from hapticsdk.sim.finger import press_slide
from hapticsdk.sim.probe import VirtualProbe

#: CPU time is read inside the wall-clock interval; the two clocks may differ by this much
CLOCK_TOL_S = 5e-6


def _spin_cpu(seconds):
    """Busy-wait until this thread has used ``seconds`` of CPU time."""
    t0 = time.thread_time_ns()
    while time.thread_time_ns() - t0 < seconds * 1e9:
        pass


class Spring(DimensionRenderer):
    roles = ("force",)

    def __init__(self, k=1.0, sleep_ticks=(), spin_ticks=(), stall_s=3e-3):
        self.k = k
        self.n = 0
        self.sleep_ticks = set(sleep_ticks)
        self.spin_ticks = set(spin_ticks)
        self.stall_s = stall_s

    def tick(self, inp):
        if self.n in self.sleep_ticks:
            time.sleep(self.stall_s)  # off the CPU: wall time only
        elif self.n in self.spin_ticks:
            _spin_cpu(self.stall_s)  # on the CPU: both clocks
        self.n += 1
        return [ChannelCommand("force", force_n=self.k * inp.penetration_mm if inp.in_contact else 0.0)]


def _slow_coil(call_no, seconds):
    """A simulated voice coil whose ``call_no``-th command busy-waits ``seconds`` of CPU."""
    from hapticsdk_hardness.voicecoil import VoiceCoilVirtual

    class SlowCoil(VoiceCoilVirtual):
        calls = 0

        def _command(self, cmd):
            if SlowCoil.calls == call_no:
                _spin_cpu(seconds)
            SlowCoil.calls += 1
            super()._command(cmd)

    return SlowCoil()


class Buzz(DimensionRenderer):
    roles = ("vib",)

    def tick(self, inp):
        return [ChannelCommand("vib", frequency_hz=100.0, amplitude=0.5 if inp.in_contact else 0.0)]


def test_cpu_compute_time_is_reported_and_never_above_wall():
    rep = ServoLoop(VirtualProbe(trajectory=press_slide()), [Spring(1.2)]).run(0.5)
    wall, cpu = rep.log["compute_s"], rep.log["compute_cpu_s"]
    assert wall.shape == cpu.shape == (500,)
    assert np.all(cpu > 0) and np.all(cpu <= wall + CLOCK_TOL_S)
    d = rep.to_dict()
    json.dumps(d)
    for key in ("compute_us", "compute_cpu_us"):
        assert {"median_us", "p99_us", "p999_us", "max_us"} <= set(d[key])
    assert d["compute_cpu_us"]["max_us"] == pytest.approx(cpu.max() * 1e6)
    assert d["compute_cpu_us"]["median_us"] == pytest.approx(np.median(cpu) * 1e6)
    assert d["compute_us"]["max_us"] == d["tick_max_us"]  # the old keys are kept, same figures
    assert rep.tick_cpu_median_us <= rep.tick_median_us + CLOCK_TOL_S * 1e6
    assert rep.preempted_ticks == int(np.sum(wall - cpu > 100e-6))
    # the two CPU-clock reads of a tick cost a few microseconds at most
    assert 0 < rep.cpu_clock_cost_us < 50


def test_busy_wait_in_a_slow_actuator_shows_in_both_clocks():
    probe = VirtualProbe(trajectory=press_slide())
    coil = _slow_coil(call_no=120, seconds=2e-3)
    rep = ServoLoop(probe, [Spring(1.0), Buzz()], {"force": probe, "vib": coil}).run(0.3)
    wall, cpu = rep.log["compute_s"], rep.log["compute_cpu_s"]
    assert cpu[120] >= 2e-3 and wall[120] >= cpu[120] - CLOCK_TOL_S
    assert rep.tick_cpu_max_us >= 2000 and rep.tick_max_us >= 2000
    assert int(np.argmax(cpu)) == 120
    assert rep.overruns >= 1  # 2 ms > T = 1 ms on the wall clock too


def test_sleep_in_a_tick_shows_in_wall_not_cpu_and_counts_as_preempted():
    r = Spring(1.0, sleep_ticks=(50, 150), spin_ticks=(100,), stall_s=3e-3)
    rep = ServoLoop(VirtualProbe(trajectory=press_slide()), [r]).run(0.3)
    wall, cpu = rep.log["compute_s"], rep.log["compute_cpu_s"]
    for k in (50, 150):
        assert wall[k] >= 3e-3  # slept 3 ms: the wall clock sees it ...
        assert cpu[k] < 1e-3  # ... the thread's CPU clock does not
        assert wall[k] - cpu[k] > 100e-6
    assert cpu[100] >= 3e-3  # the busy tick is CPU time
    assert rep.preempted_ticks >= 2 and rep.off_cpu_max_us >= 2000
    assert rep.tick_max_us >= 3000 and rep.to_dict()["preempted_ticks"] == rep.preempted_ticks


def test_preemption_stats_counts_exactly():
    wall = np.array([50, 60, 400, 70, 1000]) * 1e-6
    cpu = np.array([49, 60, 90, 70, 950]) * 1e-6
    s = preemption_stats(wall, cpu)
    assert s["preempted_ticks"] == 1 and s["off_cpu_max_us"] == pytest.approx(310)
    assert s["off_cpu_total_ms"] == pytest.approx((1 + 310 + 50) * 1e-3)
    assert preemption_stats(wall, cpu, threshold_s=40e-6)["preempted_ticks"] == 2


def test_cpu_time_can_be_switched_off():
    rep = ServoLoop(VirtualProbe(), [Spring()], cpu_time=False).run(0.05)
    assert "compute_cpu_s" not in rep.log and rep.preempted_ticks is None
    assert np.isnan(rep.tick_cpu_p99_us) and rep.tick_p99_us > 0


def _eperm(*a, **k):
    raise PermissionError(errno.EPERM, "Operation not permitted")


def test_refused_realtime_options_are_reported_not_raised(monkeypatch):
    monkeypatch.setattr(os, "sched_setscheduler", _eperm)

    class RefusingLibc:
        def mlockall(self, flags):
            import ctypes
            ctypes.set_errno(errno.EPERM)
            return -1

        def munlockall(self):  # pragma: no cover - must not be called after a refusal
            raise AssertionError("munlockall after a refused mlockall")

    monkeypatch.setattr(rclock, "_libc", lambda: RefusingLibc())
    monkeypatch.setattr(rclock, "_is_linux", lambda: True)
    rt = {"cpu": 10 ** 6, "fifo_priority": 80, "mlockall": True}
    rep = ServoLoop(VirtualProbe(), [Spring()], rt=rt).run(0.05)
    assert rep.ticks == 50 and rep.fault is None
    assert rep.rt["rt_priority"].startswith("refused: EPERM")
    assert rep.rt["cpu_affinity"].startswith("refused: cpu 1000000")
    assert rep.rt["mlockall"].startswith("refused: EPERM")
    assert rep.rt["applied"] == ["gc"]
    json.dumps(rep.to_dict()["rt"])
    # also with realtime pacing on the machine clock
    rep = ServoLoop(VirtualProbe(), [Spring()], realtime=True, rt=rt).run(0.02)
    assert rep.ticks == 20 and rep.rt["rt_priority"].startswith("refused")


def test_missing_os_calls_are_reported_unavailable(monkeypatch):
    monkeypatch.delattr(os, "sched_setaffinity", raising=False)
    monkeypatch.delattr(os, "sched_setscheduler", raising=False)
    monkeypatch.setattr(rclock, "_is_linux", lambda: False)
    rep = ServoLoop(VirtualProbe(), [Spring()], rt=RealtimeSettings(cpu=0, fifo_priority=10, mlockall=True)).run(0.02)
    assert all(rep.rt[k].startswith("unavailable") for k in ("cpu_affinity", "rt_priority", "mlockall"))


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this platform")
def test_applied_options_are_undone_after_the_run(monkeypatch):
    before = os.sched_getaffinity(0)
    cpu = min(before)
    calls = []
    pol0, par0 = os.sched_getscheduler(0), os.sched_getparam(0)
    # record the scheduler calls instead of really running the test at SCHED_FIFO
    monkeypatch.setattr(os, "sched_setscheduler", lambda pid, pol, par: calls.append((pid, pol, par)))

    seen = []

    class Probe(Spring):
        def tick(self, inp):
            seen.append((os.sched_getaffinity(0), gc.isenabled()))
            return super().tick(inp)

    rep = ServoLoop(VirtualProbe(), [Probe()], rt={"cpu": cpu, "fifo_priority": 10, "gc_freeze": False}).run(0.02)
    assert rep.rt["cpu_affinity"].startswith(f"applied: cpu {cpu}")
    assert rep.rt["rt_priority"] == "applied: SCHED_FIFO 10"
    assert "freeze off" in rep.rt["gc"] and rep.rt["mlockall"] == "off"
    assert rep.rt["applied"] == ["cpu_affinity", "gc", "rt_priority"]
    assert all(a == {cpu} and not g for a, g in seen)  # pinned and GC off inside the loop
    assert os.sched_getaffinity(0) == before  # restored
    assert calls[0][1] == os.SCHED_FIFO and calls[0][2].sched_priority == 10
    assert calls[-1][1:] == (pol0, par0)  # scheduler restored


def test_realtime_settings_are_validated_outside_the_loop():
    with pytest.raises(ValidationError):
        RealtimeSettings(fifo_priority=0)
    with pytest.raises(ValidationError):
        RealtimeSettings(cpu=-1)
    with pytest.raises(ValidationError):
        ServoLoop(VirtualProbe(), [Spring()], rt={"priority": 50})
    assert RealtimeSettings.coerce(None) == RealtimeSettings() and not RealtimeSettings().requested


def test_timing_benchmark_judges_goal13_on_cpu_time_and_prints_both_tables():
    from hapticsdk.benchmarks.timing import format_table, run_timing
    d = run_timing(0.3, rt={"cpu": 10 ** 6})
    json.dumps(d)
    c = d["compute_cpu_us"]
    assert d["tick_limits_met_cpu"] == (c["p99_us"] < 200 and c["max_us"] < 500)
    assert d["tick_limits_met_wall"] == (d["tick_p99_us"] < 200 and d["tick_max_us"] < 500)
    assert d["rt"]["cpu_affinity"].startswith("refused") and d["jitter_limits_met"] is None
    text = format_table([d])
    assert "CPU compute" in text and "wall compute" in text and "refused" in text


class _Calls(list):
    attempts: list


def _record_scheduler(monkeypatch, refuse_above=None):
    """Replace os.sched_setscheduler by a recorder that refuses FIFO priorities above
    ``refuse_above`` (None: refuse nothing) as an unprivileged process is refused."""
    calls = _Calls()

    def fake(pid, pol, par):
        calls.attempts.append(par.sched_priority)
        if pol == os.SCHED_FIFO and refuse_above is not None and par.sched_priority > refuse_above:
            raise PermissionError(errno.EPERM, "Operation not permitted")
        calls.append((pol, par.sched_priority))

    monkeypatch.setattr(os, "sched_setscheduler", fake)
    calls.attempts = []  # every priority asked for, refused or not
    return calls


@pytest.mark.skipif(not hasattr(os, "SCHED_FIFO"), reason="no SCHED_FIFO on this platform")
def test_auto_fifo_priority_takes_the_auto_priority_where_allowed(monkeypatch):
    calls = _record_scheduler(monkeypatch)
    status, restore = rclock.apply_realtime(RealtimeSettings(fifo_priority="auto"))
    assert calls[0] == (os.SCHED_FIFO, rclock.AUTO_FIFO_PRIORITY)
    assert status["rt_priority"] == f"applied: SCHED_FIFO {rclock.AUTO_FIFO_PRIORITY} (auto)"
    restore()
    assert calls[-1][0] == os.sched_getscheduler(0)  # put back


@pytest.mark.skipif(not hasattr(os, "SCHED_FIFO"), reason="no SCHED_FIFO on this platform")
def test_auto_fifo_priority_falls_back_to_the_rtprio_limit(monkeypatch):
    # an unprivileged user whose RLIMIT_RTPRIO is 7: auto asks for 40, is refused, takes 7
    calls = _record_scheduler(monkeypatch, refuse_above=7)
    monkeypatch.setattr(rclock, "_rtprio_limit", lambda: 7)
    status, restore = rclock.apply_realtime(RealtimeSettings(fifo_priority="auto"))
    assert calls[0] == (os.SCHED_FIFO, 7)
    assert status["rt_priority"] == "applied: SCHED_FIFO 7 (auto)"
    restore()
    # an explicit priority above the limit is refused, not lowered
    calls.clear()
    status, restore = rclock.apply_realtime(RealtimeSettings(fifo_priority=30))
    assert calls == [] and status["rt_priority"].startswith("refused: EPERM")
    restore()


@pytest.mark.skipif(not hasattr(os, "SCHED_FIFO"), reason="no SCHED_FIFO on this platform")
def test_auto_fifo_priority_without_a_limit_runs_at_normal_priority(monkeypatch):
    calls = _record_scheduler(monkeypatch, refuse_above=0)
    monkeypatch.setattr(rclock, "_rtprio_limit", lambda: 0)
    rep = ServoLoop(VirtualProbe(), [Spring()], rt={"fifo_priority": "auto"}).run(0.02)
    assert rep.ticks == 20 and rep.fault is None and calls == []
    assert rep.rt["rt_priority"].startswith("refused: EPERM") and "normal priority" in rep.rt["rt_priority"]
    assert "rt_priority" not in rep.rt["applied"]
    # refused for another reason (a container's zero real-time budget refuses even
    # root): a limit above the auto priority must not be tried instead
    calls = _record_scheduler(monkeypatch, refuse_above=0)
    monkeypatch.setattr(rclock, "_rtprio_limit", lambda: 99)
    status, restore = rclock.apply_realtime(RealtimeSettings(fifo_priority="auto"))
    restore()
    assert calls == [] and max(calls.attempts) == rclock.AUTO_FIFO_PRIORITY
    assert status["rt_priority"].startswith("refused: EPERM")


def test_auto_is_the_only_word_fifo_priority_takes():
    assert RealtimeSettings(fifo_priority="auto").requested
    with pytest.raises(ValidationError):
        RealtimeSettings(fifo_priority="high")


def test_a_servo_process_asks_for_auto_fifo_unless_told_otherwise():
    from hapticsdk.runtime.session.app import _default_rt
    assert _default_rt(None, "process") == {"fifo_priority": "auto"}
    assert _default_rt({"cpu": 1}, "process") == {"cpu": 1, "fifo_priority": "auto"}
    assert _default_rt({"fifo_priority": None}, "process") == {"fifo_priority": None}
    assert _default_rt({"fifo_priority": 20}, "process") == {"fifo_priority": 20}
    assert _default_rt(None, "thread") is None  # not in the application's interpreter
    assert _default_rt({"cpu": 0}, "thread") == {"cpu": 0}
    assert RealtimeSettings.coerce(_default_rt(RealtimeSettings(cpu=0), "process")) == RealtimeSettings(cpu=0)


def test_a_fifo_servo_thread_in_the_application_is_warned_about(caplog, monkeypatch):
    import logging
    _record_scheduler(monkeypatch)  # never really run this process's thread at SCHED_FIFO

    import hapticsdk as hs
    scene = {"schema_version": 1, "name": "w", "devices": {"force": "probe-virtual"},
             "objects": [{"name": "pad", "material": {"intensities": {"hardness": 0.5}}}]}
    with caplog.at_level(logging.WARNING, logger="hapticsdk.runtime.session"):
        with hs.Session(scene, isolation="thread", realtime=False, rt={"fifo_priority": None}) as s:
            s.state()
        assert not [r for r in caplog.records if "SCHED_FIFO" in r.getMessage()]
        with hs.Session(scene, isolation="thread", realtime=False, rt={"fifo_priority": "auto"}) as s:
            s.state()
    assert [r for r in caplog.records if "SCHED_FIFO servo thread" in r.getMessage()]
