"""Live-session benchmark (``hapticsdk bench live``).

What it measures, per run:

* ``jitter``: period jitter of the servo of a :class:`~hapticsdk.runtime.session.Session`
  (``|period - T|`` p50 / p99 / max in us, ``missed_tick_rate`` = fraction of periods
  longer than 1.5 T, ``missed_ticks`` and ``skipped_ticks`` counts) while the application
  does its own work in a thread (``app_load``: ``none``, ``python-thread`` = a pure-Python
  busy loop, ``numpy-thread`` = repeated 200 x 200 matrix products), with the servo in
  its own process (``isolation="process"``) or in a thread of the application
  (``"thread"``). Scene: S7 (hardness + roughness: simulated Omni, voice coil, piezo)
  on the version-1 plane, the finger pressing and sliding repeatedly.
* ``reference`` (``run_live(reference=True)``, the default): right after each session
  run, the same statistics of a paced loop doing nothing else (the servo's own clock
  and deadline grid) in a process started the same way, with the same OS options
  (``rt``: scheduling policy, CPU; ``reference.rt`` their outcome), under the same
  application load for the same time: what this machine gives a 1 kHz loop in that
  minute. On a shared machine the session's jitter means something only next to it.
* ``servo.rt``: what the OS granted the servo (``rt_priority``: ``applied: SCHED_FIFO
  40 (auto)`` or ``refused: ...``, ``cpu_affinity``, ``mlockall``); ``rt`` the options
  asked for (``{}``: the session's defaults, ``fifo_priority="auto"`` for a process).
* ``app_call_us``: wall time of the application's calls during that run: ``state`` (its
  median, the typical call; ``state_p99`` its p99, which with a busy application thread
  is mostly the wait for the interpreter lock; ``state_stats`` p50 / p99 / max and count) and ``set_material`` (its max;
  ``set_material_stats``; library materials, the amortised answer, refinement off so
  that the next call is not queued behind it). With a busy application thread the wall
  time includes waiting for the interpreter lock, which is not the call's own cost:
  ``state_cpu_stats`` / ``set_material_cpu_stats`` give the calling thread's CPU time
  (``time.thread_time``) of the same calls, and ``state_cpu_back_to_back_stats`` the CPU
  time of 2000 calls made back to back at the end (warm caches: a call made every 2 ms
  on a busy machine finds its code and data evicted, and costs several times more);
  ``trivial_cpu_after_sleep_stats`` the CPU time of a function that only builds a pair,
  called after the same 2 ms sleep 500 times at the end: what any call costs cold here.
* ``switch.latency_ms``: from ``set_material`` returning (``time.monotonic()`` in the
  application right after the call) to the servo publishing the first tick that renders
  the new material (``state().switched_at``, the servo's own ``time.monotonic()`` at the
  end of that tick; the machine's clock, the same in both processes); p50 and max over
  the switches. The application waits for that state with 0.5 ms sleeps, so its own
  polling neither delays the servo (a busy-polling application thread would take the
  second CPU of a 2-CPU machine from the servo) nor adds its polling period to the
  figure. ``switch.builds``: the servo's command statistics (slices of renderer
  building done in the slack of a period, how many had to run without fitting, the
  longest one).
* ``switch.max_force_step_n``: largest per-tick change of the sent force while a
  kinematic probe is held 2 mm deep and the material switches (``HardnessRenderer``,
  simulated time, no encoder, so every step is the switch's), the larger of
  ``soft_to_stiff_step_n`` (0.2 -> 2.3 N/mm: the force is held, so ~0) and
  ``stiff_to_soft_step_n`` (2.3 -> 0.2 N/mm: the documented ramp), next to
  ``ramp_step_n``, the step of the ramp itself (``|dF| T / ramp_s``, 4.2 N x 1 ms / 50 ms,
  at most the loop's ``switch_max_step_n``, 0.1 N);
  ``*_force_after_n`` the force 200 ms after each switch.
* ``switch.energy_j``: the largest energy the arm + wall gave the finger over the run (J,
  motor work minus kinetic energy minus the arm's damping loss, exact under the hold; 0
  when it never gave any) when a stiff finger holds the simulated Omni 5 mm into a
  0.2 N/mm wall that switches to 2.3 N/mm, then releases (simulated time, passivity
  controller on); ``energy_off_j`` the same without the controller (the switch rule
  alone); ``energy_cross_fade_j`` / ``energy_cross_fade_off_j`` the same with the linear
  cross-fade of every force (``switch_rule="cross-fade"``, the rule before the passive
  one) with / without the controller; ``energy_stiff_to_soft_j`` the reverse switch;
  ``energy_put_in_j`` the work the finger did pressing before the switch and
  ``energy_back_after_switch_j`` (``_off_j``, ``energy_back_after_cross_fade_j``) the most
  the wall handed back after it; ``tolerance_j`` the benchmark's own 0.1 mJ
  (:data:`SWITCH_ENERGY_TOLERANCE_J`, argued there).

* ``switch_handle_ms``: from sending the switch to the servo's publication of the tick
  that rendered it, as the handle ``set_material`` returns says (its ``latency_s``);
  ``switch_handle_wait_ms``: from ``set_material`` returning to ``Retarget.wait()``
  returning True (what an application waiting on the handle sees; ``wait`` polls every
  0.2 ms).
* ``recording``: the run records every tick (``Session(record=...)``, a temporary file
  removed afterwards; ``--record npz|h5|none``, ``format``); ``servo_rss_kb_first`` / ``_last`` and the slope of a straight
  line through about 20 samples of the servo process's resident set size (kB per
  minute, ``/proc/<pid>/status``), and the file's size. A slope measured over seconds
  says little about an hour: run ``--seconds 600`` for that.
* ``view_frames_per_s``: the live view is served (``Session(view=True)``) and a client
  thread in this process reads its stream during the run: frames received per second.
  The view's cost lands on the application (one ``state()`` per frame), never on the
  servo.

The session runs with the application heartbeat off (``heartbeat_timeout_s=None``; the
servo still stops when the application process dies): on a loaded machine an application
that misses the 250 ms heartbeat stops the servo, and the run would end instead of being
measured. What it does not measure: the heartbeat thread's own cost; a real device's transport, the first ``set_material`` of a
dimension set (which loads the amortised table), or anything on a machine quieter than
the one it ran on: the figures of a shared machine include the other processes.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import threading
import time
from typing import Any, Iterator

import numpy as np

APP_LOADS = ("none", "python-thread", "numpy-thread")
SCENE = {"schema_version": 1, "name": "bench-live", "objects": [{"name": "pad", "material": "S7"}],
         "settings": {"importance": {"enabled": False}, "solver": {"seed": 0}}}
MATERIALS = ("S12", "S3", "S8", "S1")


def _load(kind: str, stop: threading.Event) -> None:
    if kind == "python-thread":
        while not stop.is_set():
            x = 0
            for i in range(20000):
                x += i * i
    elif kind == "numpy-thread":
        a = np.random.default_rng(0).random((200, 200))
        while not stop.is_set():
            a = a @ a
            a /= np.abs(a).max()


def _trivial() -> tuple[float, float]:
    """The reference call of ``trivial_cpu_after_sleep``: a function that builds a pair."""
    return (1.0, 2.0)


def _reference_loop(seconds: float, period_s: float, conn: Any, rt: dict[str, Any] | None = None) -> None:
    """The reference: a paced loop doing nothing else, in a spawned process. It waits on
    the servo's own clock (:class:`~hapticsdk.runtime.clock.MonotonicClock`: sleep,
    then spin the last 200 us) against the same deadline grid, with the servo's OS
    options ``rt`` (scheduling policy, CPU), and re-anchors after the same 5 ticks
    behind; it sends its start-to-start periods (s) and the options' outcome."""
    from ..runtime.clock import MonotonicClock, RealtimeSettings, apply_realtime
    status, restore = apply_realtime(RealtimeSettings.coerce(rt))
    clock = MonotonicClock()
    n = max(2, int(seconds / period_s))
    starts = []
    deadline = clock.now()
    for _ in range(n):
        clock.wait_until(deadline)
        starts.append(clock.now())
        deadline += period_s
        behind = (clock.now() - deadline) / period_s
        if behind > 5:
            deadline += int(behind) * period_s
    restore()
    conn.send(([b - a for a, b in itertools.pairwise(starts)], status))
    conn.close()


def run_reference(app_load: str = "python-thread", seconds: float = 5.0, period_s: float = 1e-3,
                  rt: dict[str, Any] | None = None) -> dict[str, Any]:
    """What this machine gives a 1 kHz loop right now, under the same application load:
    :func:`_reference_loop` in a process started like a session's servo (``spawn``,
    the same OS options ``rt``) while this process runs the ``app_load`` thread and its
    main thread wakes every 2 ms, as :func:`run_session`'s does. Same statistics as the
    session's ``jitter``, and ``rt``: the options' outcome."""
    import multiprocessing as mp

    from ..runtime.stats import jitter_stats
    from ..scene.limits import check_seconds
    check_seconds(seconds, "seconds")
    ctx = mp.get_context("spawn")
    rx, tx = ctx.Pipe(duplex=False)
    stop = threading.Event()
    th = threading.Thread(target=_load, args=(app_load, stop), daemon=True)
    proc = ctx.Process(target=_reference_loop, args=(seconds, period_s, tx, rt), name="hapticsdk-reference",
                       daemon=True)
    periods: list[float] = []
    status: dict[str, Any] = {}
    with _stopping(stop, th):
        th.start()
        proc.start()
        tx.close()
        try:
            deadline = time.monotonic() + seconds + 60.0
            while not rx.poll(0) and proc.is_alive() and time.monotonic() < deadline:
                time.sleep(0.002)
            if rx.poll(0.5):
                periods, status = rx.recv()
        finally:
            proc.join(5.0)
            if proc.is_alive():
                proc.kill()
                proc.join(2.0)
            rx.close()
    return {**jitter_stats(np.asarray(periods), period_s), "rt": status}


def _pcts(us: list[float]) -> dict[str, float]:
    if not us:
        return {"p50": float("nan"), "p99": float("nan"), "max": float("nan"), "n": 0}
    a = np.asarray(us)
    return {"p50": float(np.percentile(a, 50)), "p99": float(np.percentile(a, 99)), "max": float(a.max()),
            "n": int(a.size)}


def _rss_kb(pid: int | None) -> int | None:
    """Resident set size of process ``pid`` (kB, Linux), None elsewhere."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as fh:
            for ln in fh:
                if ln.startswith("VmRSS:"):
                    return int(ln.split()[1])
    except (OSError, ValueError, TypeError):
        pass
    return None


def _count_frames(url: str, stop: threading.Event, out: list[float]) -> None:
    """A client of the live view's stream in this process: the monotonic time of every
    frame it receives, until ``stop``."""
    import urllib.request
    try:
        with urllib.request.urlopen(url + "stream", timeout=5.0) as r:
            while not stop.is_set():
                ln = r.readline()
                if not ln:
                    return
                if ln.startswith(b"data: "):
                    out.append(time.monotonic())
    except OSError:
        return


def run_session(isolation: str = "process", app_load: str = "python-thread", seconds: float = 10.0,
                switches: int = 8, rt: dict[str, Any] | None = None, record: "bool | str" = True,
                view: bool = True, period_s: float | None = None) -> dict[str, Any]:
    """One live run; see the module docstring. ``record``: True or ``"npz"``, ``"h5"``
    (needs h5py), False or ``"none"``."""
    import tempfile
    from pathlib import Path
    from ..runtime.session import Session
    from ..scene.limits import check_seconds
    from ..sim.finger import press_slide
    check_seconds(seconds, "seconds")   # before building a trajectory that long
    cycle = press_slide(depth_mm=2.0, press_s=0.2, hold_s=0.1, slide_s=1.5, release_s=0.2, rest_s=0.1)
    tr = cycle.repeated(lambda d: d < seconds + 60.0, gap_s=0.01)
    stop = threading.Event()
    th = threading.Thread(target=_load, args=(app_load, stop), daemon=True)
    state_us: list[float] = []
    set_us: list[float] = []
    state_cpu_us: list[float] = []
    set_cpu_us: list[float] = []
    latency_ms: list[float] = []
    handle_ms: list[float] = []
    handle_wait_ms: list[float] = []
    lost_switches = 0
    tmp = Path(tempfile.mkdtemp(prefix="hapticsdk-bench-live-"))
    fmt = None if record is False or record == "none" else ("npz" if record is True else str(record))
    rec_path = tmp / f"run.{fmt}" if fmt else None
    frames: list[float] = []
    stop_view = threading.Event()
    rss: list[tuple[float, int | None]] = []
    # the application's heartbeat is off (the servo's check that the application process
    # lives stays): on a loaded machine an application that misses 250 ms stops the servo,
    # which ends the measurement instead of measuring it (module docstring)
    with Session(SCENE, isolation=isolation, trajectory=tr, refine=False, rt=rt, record=rec_path,
                 view=bool(view), period_s=period_s, heartbeat_timeout_s=None) as s, _stopping(stop, th):
        s.set_material("pad", "S7")  # warm the amortised table of these dimensions
        time.sleep(0.5)
        s.events()
        viewer = None
        if view:
            viewer = threading.Thread(target=_count_frames, args=(s.view.url, stop_view, frames), daemon=True)
            viewer.start()
        th.start()
        t0 = time.monotonic()
        next_rss = t0
        pid = s.servo_pid
        next_switch = t0 + 1.0
        k = 0
        while time.monotonic() - t0 < seconds:
            c = time.thread_time()
            a = time.perf_counter()
            st = s.state()
            state_us.append((time.perf_counter() - a) * 1e6)
            state_cpu_us.append((time.thread_time() - c) * 1e6)
            if k < switches and time.monotonic() >= next_switch:
                n0 = st.material_switches
                c = time.thread_time()
                a = time.perf_counter()
                r = s.set_material("pad", MATERIALS[k % len(MATERIALS)])
                returned = time.monotonic()
                b = time.perf_counter()
                set_us.append((b - a) * 1e6)
                set_cpu_us.append((time.thread_time() - c) * 1e6)
                if r.wait(1.0):
                    handle_wait_ms.append((time.monotonic() - returned) * 1e3)
                    handle_ms.append(r.switch.latency_s * 1e3)
                st = s.state()
                while st.material_switches == n0 and time.perf_counter() - b < 1.0:
                    time.sleep(0.0005)
                    st = s.state()
                if st.material_switches != n0:
                    latency_ms.append((st.switched_at - returned) * 1e3)
                else:
                    lost_switches += 1
                k += 1
                next_switch = time.monotonic() + (seconds - 1.5) / max(switches, 1)
            if pid is not None and time.monotonic() >= next_rss:
                rss.append((time.monotonic() - t0, _rss_kb(pid)))
                next_rss += max(seconds / 20.0, 0.5)
            time.sleep(0.002)
        stop_view.set()
        if viewer is not None:
            viewer.join(2.0)
        burst: list[float] = []
        for _ in range(2000):  # back to back: the call's cost with warm caches
            c = time.thread_time()
            s.state()
            burst.append((time.thread_time() - c) * 1e6)
        cold: list[float] = []
        for _ in range(500):  # any call after the same 2 ms sleep: what cold caches cost here
            time.sleep(0.002)
            c = time.thread_time()
            _trivial()
            cold.append((time.thread_time() - c) * 1e6)
        stop.set()
        th.join(2.0)
        summary = s.close()
    rep = summary.get("report") or {}
    jit = rep.get("jitter") or {}
    ev = rep.get("events") or {}
    recording: dict[str, Any] = {"on": rec_path is not None, "format": fmt}
    pts = [(t, kb) for t, kb in rss if kb is not None]
    if len(pts) >= 3:
        tt, kk = np.array(pts, float).T
        recording.update({"servo_rss_kb_first": int(kk[0]), "servo_rss_kb_last": int(kk[-1]),
                          "servo_rss_slope_kb_per_min": float(np.polyfit(tt, kk, 1)[0] * 60.0),
                          "rss_samples": len(pts)})
    if rec_path is not None and rec_path.exists():
        recording["file_bytes"] = rec_path.stat().st_size
    import shutil
    shutil.rmtree(tmp, ignore_errors=True)
    view_rate = None
    if len(frames) >= 2:
        view_rate = (len(frames) - 1) / (frames[-1] - frames[0])
    return {"isolation": isolation, "app_load": app_load, "seconds": seconds,
            "jitter": {"p50_us": jit.get("p50_us"), "p99_us": jit.get("p99_us"), "max_us": jit.get("max_us"),
                       "missed_tick_rate": jit.get("missed_tick_rate"), "missed_ticks": jit.get("missed_ticks_total"),
                       "skipped_ticks": ev.get("skipped_ticks"), "periods": jit.get("periods")},
            "app_call_us": {"state": _pcts(state_us), "set_material": _pcts(set_us),
                            "state_cpu": _pcts(state_cpu_us), "set_material_cpu": _pcts(set_cpu_us),
                            "state_cpu_back_to_back": _pcts(burst), "trivial_cpu_after_sleep": _pcts(cold)},
            "switch_latency_ms": _pcts(latency_ms), "switches_not_seen_within_1s": lost_switches,
            "switch_handle_ms": _pcts(handle_ms), "switch_handle_wait_ms": _pcts(handle_wait_ms),
            "recording": recording, "view_frames_per_s": view_rate,
            "servo": {"tick_median_us": rep.get("tick_median_us"), "tick_max_us": rep.get("tick_max_us"),
                      "overruns": rep.get("overruns"), "renderer_errors": ev.get("renderer_error"),
                      "rt": rep.get("rt"),
                      "commands": summary.get("commands"), "thread_pools": summary.get("thread_pools")}}


@contextlib.contextmanager
def _stopping(stop: threading.Event, th: threading.Thread) -> Iterator[None]:
    """Stop and join the application-load thread on every exit path."""
    try:
        yield
    finally:
        stop.set()
        if th.is_alive():
            th.join(2.0)


#: Energy a material switch may hand the finger over a whole press (J). A passive switch
#: hands out nothing (<= 0); what is left is this harness's bookkeeping (motor work exact
#: under the hold, the arm damper's loss by the trapezoid of b v^2 per tick) and the
#: zero-order hold of a 2.3 N/mm wall, which the arm's own damping does not cover
#: (Colgate: K T / 2 = 1.15 > b = 0.5 N s/m). 0.1 mJ: the stability matrix's bound
#: (issue 15), about 1/18 of the ~1.8 mJ the finger puts in pressing the soft wall here
#: and 1/70 of what a linear cross-fade of the same switch hands out without a controller.
SWITCH_ENERGY_TOLERANCE_J = 1.0e-4


def switch_figures(ramp_s: float = 0.05) -> dict[str, Any]:
    """Force steps and energy of material switches while pressed (simulated time; see the
    module docstring)."""
    from hapticsdk_hardness.dimension import HardnessRenderer
    from hapticsdk_hardness.omni import OmniVirtual
    from hapticsdk_hardness.voicecoil import VoiceCoilVirtual

    from ..runtime import ServoLoop
    from ..runtime.loop import DEFAULT_SWITCH_MAX_STEP_N
    from ..sim.finger import Trajectory
    from ..sim.probe import VirtualProbe

    # 1. force steps: kinematic probe held 2 mm deep, switched at 0.5 s
    def step(k1: float, k2: float) -> tuple[float, float]:
        probe = VirtualProbe(trajectory=Trajectory([(0.0, 0.0, 1.0), (0.1, 0.0, -2.0), (5.0, 0.0, -2.0)]))
        loop = ServoLoop(probe, [HardnessRenderer(k1)], {"force": probe, "coil": VoiceCoilVirtual()},
                         switch_ramp_s=ramp_s)
        loop.start(1.0)
        try:
            while loop.ticks < 500:
                loop.tick()
            loop.set_renderers(0, [HardnessRenderer(k2)])
            while loop.tick():
                pass
        finally:
            f = loop.finish().log["force_n"]   # GC and the actuators back to normal on any exit
        return float(np.abs(np.diff(f[490:700])).max()), float(f[699])

    up, f_up = step(0.2, 2.3)
    down, f_down = step(2.3, 0.2)
    # the documented ramp's own step: dF T / ramp_s, at most switch_max_step_n
    ramp_step = min(abs(2.3 * 2.0 - 0.2 * 2.0) * 1e-3 / ramp_s, DEFAULT_SWITCH_MAX_STEP_N)

    # 2. energy to the user: the simulated Omni, a stiff finger 5 mm in, switched at 1 s
    def energy(k1: float, k2: float, passivity: bool, rule: str = "passive") -> tuple[float, float, float]:
        tr = Trajectory([(0, 0, 2), (0.5, 0, -5.0), (2.0, 0, -5.0), (2.5, 0, 3), (3.5, 0, 3)])
        dev = OmniVirtual(trajectory=tr, finger="stiff")
        lp = ServoLoop(dev, [HardnessRenderer(k1)], {"force": dev, "coil": VoiceCoilVirtual()},
                       passivity=passivity, switch_ramp_s=ramp_s, switch_rule=rule)
        lp.start(3.5)
        worst = 0.0
        at_switch = after = -math.inf
        try:
            while True:
                if lp.ticks == 1000:
                    lp.set_renderers(0, [HardnessRenderer(k2)])
                more = lp.tick()
                e = dev.energy_to_user_j()
                worst = max(worst, e)
                if lp.ticks == 1000:
                    at_switch = e
                elif lp.ticks > 1000:
                    after = max(after, e - at_switch)
                if not more:
                    break
        finally:
            lp.finish()
        return worst, -at_switch, after

    on, put_in, back = energy(0.2, 2.3, True)
    off, _, back_off = energy(0.2, 2.3, False)
    xf_on, _, back_xf = energy(0.2, 2.3, True, "cross-fade")
    xf_off, _, _ = energy(0.2, 2.3, False, "cross-fade")
    down_on, _, _ = energy(2.3, 0.2, True)
    return {"rule": "passive", "max_force_step_n": max(up, down), "soft_to_stiff_step_n": up,
            "stiff_to_soft_step_n": down, "ramp_step_n": ramp_step, "ramp_s": ramp_s,
            "soft_to_stiff_force_after_n": f_up, "stiff_to_soft_force_after_n": f_down,
            "energy_j": on, "energy_off_j": off, "energy_cross_fade_j": xf_on, "energy_cross_fade_off_j": xf_off,
            "energy_stiff_to_soft_j": down_on, "energy_put_in_j": put_in, "energy_back_after_switch_j": back,
            "energy_back_after_switch_off_j": back_off, "energy_back_after_cross_fade_j": back_xf,
            "tolerance_j": SWITCH_ENERGY_TOLERANCE_J}


def run_live(isolation: str = "process", app_loads: tuple[str, ...] = ("python-thread",),
             seconds: float = 10.0, rt: dict[str, Any] | None = None,
             reference: bool = True, period_s: float | None = None,
             record: "bool | str" = True) -> dict[str, Any] | list[dict[str, Any]]:
    """Runs for each application load; the switch figures are shared (simulated).
    ``reference``: after each session run, :func:`run_reference` under the same load
    for the same time (key ``reference``): the session's jitter next to what a loop
    doing nothing else gets from this machine in the same minute. ``period_s``: the
    servo period (default the scene's, 1 ms); the reference loop runs at the same period."""
    from ..runtime.session.app import _default_rt
    sw = switch_figures()
    rows = []
    for load in app_loads:
        r = run_session(isolation, load, seconds, rt=rt, period_s=period_s, record=record)
        if reference:
            r["reference"] = run_reference(load, seconds, period_s=period_s or 1e-3, rt=_default_rt(rt, isolation))
        r["rt"] = dict(rt or {})
        r["period_s"] = float(period_s or 1e-3)
        lat = r.pop("switch_latency_ms")
        r["switch"] = {"latency_ms": lat["max"], "latency_ms_p50": lat["p50"], "switches": lat["n"],
                       "not_seen_within_1s": r.pop("switches_not_seen_within_1s"),
                       "builds": (r["servo"].get("commands") or {}),
                       "max_force_step_n": sw["max_force_step_n"], "ramp_step_n": sw["ramp_step_n"],
                       "ramp_s": sw["ramp_s"], "energy_j": sw["energy_j"], "energy_off_j": sw["energy_off_j"],
                       "tolerance_j": sw["tolerance_j"],
                       **{k: v for k, v in sw.items() if k not in ("max_force_step_n", "ramp_step_n", "ramp_s",
                                                                    "energy_j", "energy_off_j", "tolerance_j")}}
        calls = r["app_call_us"]
        r["app_call_us"] = {"set_material": calls["set_material"]["max"], "state": calls["state"]["p50"],
                            "state_p99": calls["state"]["p99"],
                            "set_material_stats": calls["set_material"], "state_stats": calls["state"],
                            "state_cpu_stats": calls["state_cpu"], "set_material_cpu_stats": calls["set_material_cpu"],
                            "state_cpu_back_to_back_stats": calls["state_cpu_back_to_back"],
                            "trivial_cpu_after_sleep_stats": calls["trivial_cpu_after_sleep"]}
        rows.append(r)
    return rows[0] if len(rows) == 1 else rows


def format_rows(rows: list[dict[str, Any]]) -> str:
    """The live benchmark's rows as a text table (jitter percentiles in us, missed-tick
    rate, material switch latency in ms, largest force step in N, energy in mJ,
    application call times in us).
    """
    head = ("isolation  app_load        jitter p50/p99/max us   missed    switch ms (max)  step N   "
            "energy mJ  state us p50/p99 (cpu p50, b2b p50)   set_material us max (cpu)")
    out = [head]
    periods = sorted({r.get("period_s", 1e-3) for r in rows})
    out.insert(0, "servo period " + ", ".join(f"{p * 1e3:g} ms ({1e-3 / p:g} kHz)" for p in periods))
    for r in rows:
        j, s, c = r["jitter"], r["switch"], r["app_call_us"]
        out.append(f"{r['isolation']:<10} {r['app_load']:<15} {j['p50_us']:7.1f}/{j['p99_us']:7.1f}/{j['max_us']:8.1f}"
                   f"  {j['missed_tick_rate'] * 100:6.2f} %  {s['latency_ms']:8.2f}        {s['max_force_step_n']:.3f}"
                   f"    {s['energy_j'] * 1e3:6.3f}    {c['state']:5.1f}/{c['state_p99']:6.1f} "
                   f"({c['state_cpu_stats']['p50']:5.1f}, {c['state_cpu_back_to_back_stats']['p50']:4.1f})"
                   f"   {c['set_material']:9.0f} ({c['set_material_cpu_stats']['max']:6.0f})")
        ref = r.get("reference")
        if ref:
            out.append(f"{'reference':<10} {r['app_load']:<15} {ref['p50_us']:7.1f}/{ref['p99_us']:7.1f}/"
                       f"{ref['max_us']:8.1f}  {ref['missed_tick_rate'] * 100:6.2f} %  (a loop doing nothing else, "
                       f"same load, right after)")
    for r in rows:
        h, rec = r.get("switch_handle_ms"), r.get("recording") or {}
        w: Any = r.get("switch_handle_wait_ms")
        parts = []
        if h and h.get("n"):
            parts.append(f"switch handle {h['p50']:.2f}/{h['max']:.2f} ms p50/max (wait returns after "
                         f"{w['p50']:.2f}/{w['max']:.2f} ms)")
        if "servo_rss_slope_kb_per_min" in rec:
            parts.append(f"recording ({rec.get('format')}): servo RSS {rec['servo_rss_kb_first']}->"
                         f"{rec['servo_rss_kb_last']} kB "
                         f"({rec['servo_rss_slope_kb_per_min']:+.0f} kB/min over this run; the simulated "
                         f"actuators' 60 s waveform windows fill first: bench/bench_live_rss.py for an hour)")
        if r.get("view_frames_per_s"):
            parts.append(f"view {r['view_frames_per_s']:.1f} frames/s")
        if parts:
            out.append(f"{r['isolation']:<10} {r['app_load']:<15} " + "; ".join(parts))
    seen = []
    for r in rows:
        st = (r.get("servo") or {}).get("rt") or {}
        line = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in st.items()
                         if k in ("rt_priority", "cpu_affinity") and v != "off")
        if line and line not in seen:
            seen.append(line)
    out.extend(f"servo process: {line}" for line in seen)
    cold = [r["app_call_us"].get("trivial_cpu_after_sleep_stats", {}).get("p50") for r in rows]
    cold = [c for c in cold if c is not None and math.isfinite(c)]
    if cold:
        out.append(f"a trivial Python call after the same 2 ms sleep costs {min(cold):.1f}-{max(cold):.1f} us "
                   f"of CPU (p50) on this machine: the cold-cache part of the state() figures")
    return "\n".join(out)
