"""Servo-loop timing (``hapticsdk bench timing``; ``bench/bench_timing.py``).

Runs a hardness + roughness material (roughness when the ``hapticsdk-roughness`` plugin
is installed) on simulated devices (``omni-virtual``, ``voicecoil-virtual``,
``piezo-virtual``) and reports per-tick compute time (median/p99/p99.9/max, overruns)
and, in realtime mode, the period jitter (|period - T| p50/p99/p99.9/max and the
missed-tick rate), optionally with a second CPU-bound process running (``load=True``;
the process is started here and ended by its pid).

The tick limits (compute p99 < 200 us, max < 500 us over >= 60 s, GC disabled in the
loop; ``tick_limits``) are judged on the servo thread's **on-CPU** compute time (``compute_cpu_us``: what the
tick code costs); the wall-clock figures (``compute_us`` / ``tick_*_us``, which include
preemption by other processes on a shared machine) and their verdict
(``tick_limits_met_wall``) are reported next to it, with ``preempted_ticks``. The jitter
limits (``jitter_limits``) are reported: pass/fail only on a declared real-time machine
(``declared_rt_machine=True``). Optional OS options (``rt``: CPU pinning,
``SCHED_FIFO``, ``mlockall``) are applied to the servo thread and their outcome is in
``rt``.
"""

from __future__ import annotations

import math
import subprocess
import sys
from typing import Any

from ..plugins import registry
from ..runtime import ServoLoop
from ..runtime.clock import MonotonicClock, RealtimeSettings
from .reference import machine as machine_now
from .reference import reference_lines, with_reference

TICK_P99_US_LIMIT = 200.0
TICK_MAX_US_LIMIT = 500.0
JITTER_LIMITS = {"p99_us_lt": 50.0, "p999_us_lt": 250.0, "missed_tick_rate_lt": 0.001}
MATERIAL = {"GS": 3.0, "Fpeak": 150.0, "AFpeak": 5.0}


def build_scene(seconds: float, period_s: float = 0.001) -> tuple[Any, list, dict]:
    """Device, renderers and actuators of the timing material (simulated)."""
    from ..sim.finger import press_slide
    dims = registry("dimension")
    acts = registry("actuator")
    cycle = press_slide(depth_mm=3.0, press_s=0.3, hold_s=0.1, slide_s=1.0, release_s=0.3, rest_s=0.2)
    tr = cycle.repeated(lambda d: d < seconds, gap_s=0.01)
    dev = acts.load("omni-virtual")(trajectory=tr, finger="stiff")
    renderers = [dims.load("hardness")().renderer({"GS": MATERIAL["GS"]})]
    actuators: dict[str, Any] = {"force": dev, "coil": acts.load("voicecoil-virtual")()}
    if "roughness" in dims and "piezo-virtual" in acts:
        renderers.append(dims.load("roughness")().renderer({"Fpeak": MATERIAL["Fpeak"], "AFpeak": MATERIAL["AFpeak"]}))
        actuators["vibration"] = acts.load("piezo-virtual")(period_s=period_s)
    return dev, renderers, actuators


def _cpu_hog() -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", "while True: pass"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)


def run_timing(seconds: float = 60.0, *, realtime: bool = False, load: bool = False,
               period_s: float = 0.001, rt: RealtimeSettings | dict | None = None,
               declared_rt_machine: bool = False) -> dict[str, Any]:
    """One timing run; returns a JSON-ready dict with the limits' verdicts.

    Args:
        seconds: run length (s).
        realtime: pace on the machine clock (jitter figures) instead of simulated time.
        load: run a second CPU-bound process meanwhile.
        period_s: servo period (s).
        rt: OS options of the servo thread (:class:`RealtimeSettings` or its fields).
        declared_rt_machine: judge the jitter limits (otherwise ``jitter_limits_met`` is None).
    """
    from ..scene.limits import check_seconds
    check_seconds(seconds, "seconds")   # before building a trajectory that long
    rt_settings = RealtimeSettings.coerce(rt)
    before = machine_now()
    dev, renderers, actuators = build_scene(seconds, period_s)
    hog = _cpu_hog() if load else None
    try:
        loop = ServoLoop(dev, renderers, actuators, period_s=period_s, realtime=realtime,
                         clock=MonotonicClock() if realtime else None, rt=rt_settings)
        rep = loop.run(seconds)
    finally:
        if hog is not None:
            hog.kill()
            hog.wait()
        for a in {id(a): a for a in [dev, *actuators.values()]}.values():
            a.close()
    d = rep.to_dict()
    j = rep.jitter
    jitter_met = None
    if declared_rt_machine and j:
        jitter_met = bool(j["p99_us"] < JITTER_LIMITS["p99_us_lt"] and j["p999_us"] < JITTER_LIMITS["p999_us_lt"]
                      and j["missed_tick_rate"] < JITTER_LIMITS["missed_tick_rate_lt"])
    d.update({"seconds": seconds, "load": load, "dimensions": [type(r).__name__ for r in renderers],
              "tick_limits_met_cpu": bool(rep.tick_cpu_p99_us < TICK_P99_US_LIMIT and rep.tick_cpu_max_us < TICK_MAX_US_LIMIT),
              "tick_limits_met_wall": bool(rep.tick_p99_us < TICK_P99_US_LIMIT and rep.tick_max_us < TICK_MAX_US_LIMIT),
              "tick_limits": {"p99_us_lt": TICK_P99_US_LIMIT, "max_us_lt": TICK_MAX_US_LIMIT, "judged_on": "compute_cpu_us"},
              "jitter_limits": dict(JITTER_LIMITS, judged=bool(declared_rt_machine and j)),
              "jitter_limits_met": jitter_met,
              "rt_requested": {"cpu": rt_settings.cpu, "fifo_priority": rt_settings.fifo_priority,
                               "gc_freeze": rt_settings.gc_freeze, "mlockall": rt_settings.mlockall},
              "machine": before})   # reference.machine(): Python, platform, CPUs, model, load
    return with_reference(d, before)


def _f(x: Any, fmt: str = ".1f") -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, fmt)


def format_table(runs: list[dict[str, Any]]) -> str:
    """Text tables of :func:`run_timing` results: wall and CPU compute time side by side
    (median / p99 / p99.9 / max, us), preempted ticks, the tick limits' verdicts, the period
    jitter and the OS options' outcome of each run."""
    head = ("mode        load  ticks  | wall compute med / p99 / p99.9 / max (us)  | "
            f"CPU compute med / p99 / p99.9 / max (us)   | preempted | p99 < {TICK_P99_US_LIMIT:.0f} and max < "
            f"{TICK_MAX_US_LIMIT:.0f} us: CPU / wall")
    lines = [head, "-" * len(head)]
    for d in runs:
        w, c = d["compute_us"], d["compute_cpu_us"]
        mode = "realtime" if d["realtime"] else "simulated"
        lines.append(
            f"{mode:10}  {'yes' if d['load'] else 'no':4}  {d['ticks']:5d}  | "
            f"{_f(w['median_us']):>6} / {_f(w['p99_us']):>6} / {_f(w['p999_us']):>6} / {_f(w['max_us']):>7}"
            f"{'':11}| {_f(c['median_us']):>6} / {_f(c['p99_us']):>6} / {_f(c['p999_us']):>6} / "
            f"{_f(c['max_us']):>7}{'':11}| {d['preempted_ticks'] if d['preempted_ticks'] is not None else '-':>9} | "
            f"{'pass' if d['tick_limits_met_cpu'] else 'FAIL'} / {'pass' if d['tick_limits_met_wall'] else 'FAIL'}")
    jit = [d for d in runs if d.get("jitter")]
    if jit:
        lines.append("")
        lines.append(f"jitter |period - T| (us)   load  p50 / p99 / p99.9 / max            missed ticks  "
                     f"p99 < {JITTER_LIMITS['p99_us_lt']:.0f}, p99.9 < {JITTER_LIMITS['p999_us_lt']:.0f} us, "
                     f"missed < {JITTER_LIMITS['missed_tick_rate_lt']:.1%}")
        for d in jit:
            j = d["jitter"]
            verdict = ("reported only (no declared RT machine)" if d.get("jitter_limits_met") is None
                       else "pass" if d["jitter_limits_met"] else "FAIL")
            lines.append(f"realtime                   {'yes' if d['load'] else 'no':4}  {_f(j['p50_us'])} / "
                         f"{_f(j['p99_us'])} / {_f(j['p999_us'])} / {_f(j['max_us'])}"
                         f"{'':8}{j['missed_tick_rate']:.4%}       {verdict}")
    lines.append("")
    for d in runs:
        rt = d.get("rt") or {}
        mode = "realtime" if d["realtime"] else "simulated"
        lines.append(f"rt options ({mode}, load={'yes' if d['load'] else 'no'}): "
                     + "; ".join(f"{k} = {rt[k]}" for k in ("cpu_affinity", "rt_priority", "mlockall", "gc")
                                 if k in rt))
    lines.extend(reference_lines(runs))
    if runs:
        lines.append(f"CPU-clock cost per tick: {_f(runs[0].get('cpu_clock_cost_us'), '.2f')} us; preempted = "
                     f"wall - CPU compute > {_f(runs[0].get('preempt_threshold_us'), '.0f')} us. The tick limits are "
                     f"judged on CPU compute (p99 < {TICK_P99_US_LIMIT:.0f} us, max < {TICK_MAX_US_LIMIT:.0f} us); wall max "
                     f"includes preemption by other processes.")
    return "\n".join(lines)


_RENAMED = {"GOAL_P99_US": "TICK_P99_US_LIMIT", "GOAL_MAX_US": "TICK_MAX_US_LIMIT", "GOAL14": "JITTER_LIMITS"}


def __getattr__(name: str) -> Any:
    """The limits' former names, kept for one minor version with a DeprecationWarning."""
    if name in _RENAMED:
        import warnings
        warnings.warn(f"hapticsdk.benchmarks.timing.{name} is now {_RENAMED[name]}", DeprecationWarning,
                      stacklevel=2)
        return globals()[_RENAMED[name]]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
