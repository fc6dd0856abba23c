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
* ``app_call_us``: wall time of the application's calls during that run: ``state`` (its
  p99; ``state_stats`` p50 / p99 / max and count) and ``set_material`` (its max;
  ``set_material_stats``; library materials, the amortised answer, refinement off so
  that the next call is not queued behind it). With a busy application thread the wall
  time includes waiting for the interpreter lock, which is not the call's own cost:
  ``state_cpu_stats`` / ``set_material_cpu_stats`` give the calling thread's CPU time
  (``time.thread_time``) of the same calls, and ``state_cpu_back_to_back_stats`` the CPU
  time of 2000 calls made back to back at the end (warm caches: a call made every 2 ms
  on a busy machine finds its code and data evicted, and costs several times more).
* ``switch.latency_ms``: from ``set_material`` returning to the first servo tick that
  renders the new material (seen in ``state().material_switches``, published at the end
  of that tick; p50 and max over the switches).
* ``switch.max_force_step_n`` and ``switch.ramp_step_n``: largest per-tick change of the
  sent force while a kinematic probe is held 2 mm deep and the material switches from
  0.2 to 2.3 N/mm (simulated time, no encoder, so every step is the switch's), and the
  step the documented ramp itself makes (``dF T / ramp_s``).
* ``switch.energy_j``: the largest energy the arm + wall gave the finger (J, motor work
  minus kinetic energy minus the arm's damping loss) when a stiff finger holds the
  simulated Omni 5 mm into a 0.2 N/mm wall that switches to 2.3 N/mm, then releases
  (simulated time); ``energy_off_j`` the same without the passivity controller, and
  ``tolerance_j`` the 2.5 mJ the stability benchmark allows.

What it does not measure: a real device's transport, the first ``set_material`` of a
dimension set (which loads the amortised table), or anything on a machine quieter than
the one it ran on: the figures of a shared machine include the other processes.
"""

from __future__ import annotations

import contextlib
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


def _pcts(us: list[float]) -> dict[str, float]:
    if not us:
        return {"p50": float("nan"), "p99": float("nan"), "max": float("nan"), "n": 0}
    a = np.asarray(us)
    return {"p50": float(np.percentile(a, 50)), "p99": float(np.percentile(a, 99)), "max": float(a.max()),
            "n": int(a.size)}


def run_session(isolation: str = "process", app_load: str = "python-thread", seconds: float = 10.0,
                switches: int = 8, rt: dict[str, Any] | None = None) -> dict[str, Any]:
    """One live run; see the module docstring."""
    from ..runtime.session import Session
    from ..sim.finger import press_slide
    cycle = press_slide(depth_mm=2.0, press_s=0.2, hold_s=0.1, slide_s=1.5, release_s=0.2, rest_s=0.1)
    tr = cycle
    while tr.duration_s < seconds + 60.0:
        tr = tr.then(cycle, gap_s=0.01)
    stop = threading.Event()
    th = threading.Thread(target=_load, args=(app_load, stop), daemon=True)
    state_us: list[float] = []
    set_us: list[float] = []
    state_cpu_us: list[float] = []
    set_cpu_us: list[float] = []
    latency_ms: list[float] = []
    with Session(SCENE, isolation=isolation, trajectory=tr, refine=False, rt=rt) as s, _stopping(stop, th):
        s.set_material("pad", "S7")  # warm the amortised table of these dimensions
        time.sleep(0.5)
        s.events()
        th.start()
        t0 = time.monotonic()
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
                s.set_material("pad", MATERIALS[k % len(MATERIALS)])
                b = time.perf_counter()
                set_us.append((b - a) * 1e6)
                set_cpu_us.append((time.thread_time() - c) * 1e6)
                while s.state().material_switches == n0 and time.perf_counter() - b < 1.0:
                    pass
                latency_ms.append((time.perf_counter() - b) * 1e3)
                k += 1
                next_switch = time.monotonic() + (seconds - 1.5) / max(switches, 1)
            time.sleep(0.002)
        burst: list[float] = []
        for _ in range(2000):  # back to back: the call's cost with warm caches
            c = time.thread_time()
            s.state()
            burst.append((time.thread_time() - c) * 1e6)
        stop.set()
        th.join(2.0)
        summary = s.close()
    rep = summary.get("report") or {}
    jit = rep.get("jitter") or {}
    ev = rep.get("events") or {}
    return {"isolation": isolation, "app_load": app_load, "seconds": seconds,
            "jitter": {"p50_us": jit.get("p50_us"), "p99_us": jit.get("p99_us"), "max_us": jit.get("max_us"),
                       "missed_tick_rate": jit.get("missed_tick_rate"), "missed_ticks": jit.get("missed_ticks_total"),
                       "skipped_ticks": ev.get("skipped_ticks"), "periods": jit.get("periods")},
            "app_call_us": {"state": _pcts(state_us), "set_material": _pcts(set_us),
                            "state_cpu": _pcts(state_cpu_us), "set_material_cpu": _pcts(set_cpu_us),
                            "state_cpu_back_to_back": _pcts(burst)},
            "switch_latency_ms": _pcts(latency_ms),
            "servo": {"tick_median_us": rep.get("tick_median_us"), "tick_max_us": rep.get("tick_max_us"),
                      "overruns": rep.get("overruns"), "renderer_errors": ev.get("renderer_error")}}


@contextlib.contextmanager
def _stopping(stop: threading.Event, th: threading.Thread) -> Iterator[None]:
    """Stop and join the application-load thread on every exit path."""
    try:
        yield
    finally:
        stop.set()
        if th.is_alive():
            th.join(2.0)


def switch_figures(ramp_s: float = 0.05) -> dict[str, float]:
    """Force step and energy of a soft -> stiff switch while pressed (simulated time)."""
    from hapticsdk_hardness.dimension import HardnessRenderer
    from hapticsdk_hardness.omni import OmniVirtual
    from hapticsdk_hardness.voicecoil import VoiceCoilVirtual

    from ..runtime import ServoLoop
    from ..sim.finger import Trajectory
    from ..sim.probe import VirtualProbe

    # 1. force steps: kinematic probe held 2 mm deep
    probe = VirtualProbe(trajectory=Trajectory([(0.0, 0.0, 1.0), (0.1, 0.0, -2.0), (5.0, 0.0, -2.0)]))
    loop = ServoLoop(probe, [HardnessRenderer(0.2)], {"force": probe, "coil": VoiceCoilVirtual()},
                     switch_ramp_s=ramp_s)
    loop.start(1.0)
    try:
        while loop.ticks < 500:
            loop.tick()
        loop.set_renderers(0, [HardnessRenderer(2.3)])
        while loop.tick():
            pass
    finally:
        f = loop.finish().log["force_n"]   # GC and the actuators back to normal on any exit
    win = f[490:700]
    step = float(np.abs(np.diff(win)).max())
    ramp_step = abs(2.3 * 2.0 - 0.2 * 2.0) * loop.period_s / ramp_s

    # 2. energy to the user: the simulated Omni, a stiff finger 5 mm in
    def energy(passivity: bool) -> float:
        tr = Trajectory([(0, 0, 2), (0.5, 0, -5.0), (2.0, 0, -5.0), (2.5, 0, 3), (3.5, 0, 3)])
        dev = OmniVirtual(trajectory=tr, finger="stiff")
        lp = ServoLoop(dev, [HardnessRenderer(0.2)], {"force": dev, "coil": VoiceCoilVirtual()},
                       passivity=passivity, switch_ramp_s=ramp_s)
        lp.start(3.5)
        b, m = dev.arm.damping_ns_per_m, dev.arm.mass_kg
        damper = worst = 0.0
        try:
            while True:
                if lp.ticks == 1000:
                    lp.set_renderers(0, [HardnessRenderer(2.3)])
                v0 = dev.sim.v
                more = lp.tick()
                v1 = dev.sim.v
                damper += b * 0.5 * (v0 * v0 + v1 * v1) * lp.period_s
                worst = max(worst, dev.motor_work_j - 0.5 * m * v1 * v1 - damper)
                if not more:
                    break
        finally:
            lp.finish()
        return worst

    return {"max_force_step_n": step, "ramp_step_n": ramp_step, "ramp_s": ramp_s,
            "energy_j": energy(True), "energy_off_j": energy(False), "tolerance_j": 2.5e-3}


def run_live(isolation: str = "process", app_loads: tuple[str, ...] = ("python-thread",),
             seconds: float = 10.0, rt: dict[str, Any] | None = None) -> dict[str, Any] | list[dict[str, Any]]:
    """Runs for each application load; the switch figures are shared (simulated)."""
    sw = switch_figures()
    rows = []
    for load in app_loads:
        r = run_session(isolation, load, seconds, rt=rt)
        r["rt"] = dict(rt or {})
        lat = r.pop("switch_latency_ms")
        r["switch"] = {"latency_ms": lat["max"], "latency_ms_p50": lat["p50"], "switches": lat["n"],
                       "max_force_step_n": sw["max_force_step_n"], "ramp_step_n": sw["ramp_step_n"],
                       "ramp_s": sw["ramp_s"], "energy_j": sw["energy_j"], "energy_off_j": sw["energy_off_j"],
                       "tolerance_j": sw["tolerance_j"]}
        calls = r["app_call_us"]
        r["app_call_us"] = {"set_material": calls["set_material"]["max"], "state": calls["state"]["p99"],
                            "set_material_stats": calls["set_material"], "state_stats": calls["state"],
                            "state_cpu_stats": calls["state_cpu"], "set_material_cpu_stats": calls["set_material_cpu"],
                            "state_cpu_back_to_back_stats": calls["state_cpu_back_to_back"]}
        rows.append(r)
    return rows[0] if len(rows) == 1 else rows


def format_rows(rows: list[dict[str, Any]]) -> str:
    """The live benchmark's rows as a text table (jitter percentiles in us, missed-tick
    rate, material switch latency in ms, largest force step in N, energy in mJ,
    application call times in us).
    """
    head = ("isolation  app_load        jitter p50/p99/max us   missed    switch ms (max)  step N   "
            "energy mJ  state us p99 (cpu, b2b p50)   set_material us max (cpu)")
    out = [head]
    for r in rows:
        j, s, c = r["jitter"], r["switch"], r["app_call_us"]
        out.append(f"{r['isolation']:<10} {r['app_load']:<15} {j['p50_us']:7.1f}/{j['p99_us']:7.1f}/{j['max_us']:8.1f}"
                   f"  {j['missed_tick_rate'] * 100:6.2f} %  {s['latency_ms']:8.2f}        {s['max_force_step_n']:.3f}"
                   f"    {s['energy_j'] * 1e3:6.3f}    {c['state']:8.1f} ({c['state_cpu_stats']['p99']:5.1f}, "
                   f"{c['state_cpu_back_to_back_stats']['p50']:4.1f})"
                   f"   {c['set_material']:9.0f} ({c['set_material_cpu_stats']['max']:6.0f})")
    return "\n".join(out)
