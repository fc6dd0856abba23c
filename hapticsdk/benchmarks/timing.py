"""Servo-loop timing (``hapticsdk bench timing``; ``bench/bench_timing.py``).

Runs a hardness + roughness material (roughness when the ``hapticsdk-roughness`` plugin
is installed) on simulated devices (``omni-virtual``, ``voicecoil-virtual``,
``piezo-virtual``) and reports per-tick compute time (median/p99/p99.9/max, overruns)
and, in realtime mode, the period jitter (|period - T| p50/p99/p99.9/max and the
missed-tick rate), optionally with a second CPU-bound process running (``load=True``;
the process is started here and ended by its pid).

Goal 13 (tick compute p99 < 200 us, max < 500 us over >= 60 s, GC disabled in the loop)
and goal 14 (jitter, reported: pass/fail only on a declared real-time machine).
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from typing import Any

from ..plugins import registry
from ..runtime import ServoLoop
from ..runtime.clock import MonotonicClock

GOAL_P99_US = 200.0
GOAL_MAX_US = 500.0
MATERIAL = {"GS": 3.0, "Fpeak": 150.0, "AFpeak": 5.0}


def build_scene(seconds: float, period_s: float = 0.001) -> tuple[Any, list, dict]:
    """Device, renderers and actuators of the timing material (simulated)."""
    from ..sim.finger import press_slide
    dims = registry("dimension")
    acts = registry("actuator")
    cycle = press_slide(depth_mm=3.0, press_s=0.3, hold_s=0.1, slide_s=1.0, release_s=0.3, rest_s=0.2)
    tr = cycle
    while tr.duration_s < seconds:
        tr = tr.then(cycle, gap_s=0.01)
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
               period_s: float = 0.001) -> dict[str, Any]:
    """One timing run; returns a JSON-ready dict with the goals' verdicts."""
    dev, renderers, actuators = build_scene(seconds, period_s)
    hog = _cpu_hog() if load else None
    try:
        loop = ServoLoop(dev, renderers, actuators, period_s=period_s, realtime=realtime,
                         clock=MonotonicClock() if realtime else None)
        rep = loop.run(seconds)
    finally:
        if hog is not None:
            hog.kill()
            hog.wait()
        for a in {id(a): a for a in [dev, *actuators.values()]}.values():
            a.close()
    d = rep.to_dict()
    d.update({"seconds": seconds, "load": load, "dimensions": [type(r).__name__ for r in renderers],
              "goal13_pass": bool(rep.tick_p99_us < GOAL_P99_US and rep.tick_max_us < GOAL_MAX_US),
              "goal13": {"p99_us_lt": GOAL_P99_US, "max_us_lt": GOAL_MAX_US},
              "machine": {"python": platform.python_version(), "platform": platform.platform(),
                          "cpus": os.cpu_count()}})
    return d
