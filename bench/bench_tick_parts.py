"""Per-part CPU cost of the servo tick (hardness + roughness on the simulated devices of
``hapticsdk bench timing``).

``python bench/bench_tick_parts.py [--ticks 60000] [--mode outer|inner|none] [--json]``

What it measures: the on-CPU time (``time.thread_time_ns``) of each call the servo loop
makes into the device, the safety layers, the renderers and the actuators, wrapped on
the instances and run for ``--ticks`` ticks in simulated time (GC off while it runs).
``outer``: the calls the loop makes (``_read_state``, ``observe``, ``tick``,
``command``, the simulated ``step``); ``inner``: what ``command`` calls
(``SafetyLayer.filter``, the backend ``_command``), ``SafetyLayer.current`` and
``PassivityController.step`` (called by the loop before ``command``);
``none``: nothing wrapped, only the loop's own per-tick CPU time. The median cost of an
empty ``thread_time_ns`` pair is subtracted from every sample.

What it does not measure: the wrapper itself adds a Python call per wrapped call
(roughly 0.1-0.2 us), so the parts of ``outer``/``inner`` are a little high and the
whole tick of a wrapped run is not the unwrapped one (use ``none`` for that); the loop's
own bookkeeping is the whole tick minus the parts. ``PassivityController`` has
``__slots__``: its ``step`` is wrapped on the class, in this process only. CPU time
includes interrupt handling charged to the thread; on a shared machine repeat and
compare medians.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import time

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import numpy as np  # noqa: E402

from hapticsdk.benchmarks.timing import build_scene  # noqa: E402
from hapticsdk.runtime import ServoLoop  # noqa: E402

WRAPPED = {"outer": ("_read_state", "step", "command", "observe", "tick"),
           "inner": ("filter", "_command", "current", "pc.step"), "none": ()}


def run(ticks: int, mode: str) -> dict:
    tt = time.thread_time_ns
    samples: dict[str, list[int]] = {}
    names = WRAPPED[mode]

    def wrap(obj, attr: str, key: str, kind: str = "") -> None:
        if (kind or attr) not in names:
            return
        f = getattr(obj, attr)
        app = samples.setdefault(key, []).append

        def timed(*a, **k):
            t0 = tt()
            r = f(*a, **k)
            app(tt() - t0)
            return r
        try:
            setattr(obj, attr, timed)
        except AttributeError:  # __slots__ class: wrap the method on the class (this process only)
            g = getattr(type(obj), attr)

            def timed_cls(*a, **k):
                t0 = tt()
                r = g(*a, **k)
                app(tt() - t0)
                return r
            setattr(type(obj), attr, timed_cls)

    pair = []
    for _ in range(100_000):
        t0 = tt()
        pair.append(tt() - t0)
    pair_ns = float(np.median(pair))

    dev, renderers, acts = build_scene(ticks / 1000 + 1)
    loop = ServoLoop(dev, renderers, acts, period_s=0.001, realtime=False)
    wrap(dev, "_read_state", "device._read_state")
    for a in {id(a): a for a in acts.values()}.values():
        wrap(a, "step", f"{a.name}.step (simulation, outside the tick)")
        wrap(a.safety, "observe", f"safety.observe [{a.name}]")
    for role, a in acts.items():
        wrap(a, "command", f"Actuator.command [{role}]")
        wrap(a.safety, "filter", f"SafetyLayer.filter [{role}]")
        wrap(a, "_command", f"{a.name}._command")
    wrap(dev.safety, "current", "SafetyLayer.current [force]")
    for r in renderers:
        wrap(r, "tick", f"{type(r).__name__}.tick")
    loop.start(ticks / 1000)
    for s in loop._slots:  # the passivity controllers exist once the loop has started
        if s.pc is not None:
            wrap(s.pc, "step", f"PassivityController.step [{s.role}]", "pc.step")
    gc.disable()
    try:
        while loop.tick():
            pass
    finally:
        gc.enable()
    loop.finish()
    out: dict = {"ticks": ticks, "mode": mode, "thread_time_pair_ns": pair_ns, "parts_us": {}}
    for k, v in samples.items():
        a = (np.asarray(v[100:], float) - pair_ns) / 1000.0  # the first 100 calls warm up
        if a.size:
            out["parts_us"][k] = {"calls": len(v), "median": round(float(np.median(a)), 2),
                                  "p99": round(float(np.percentile(a, 99)), 2), "max": round(float(a.max()), 1)}
    cpu = loop._log[100:min(ticks, loop._cap), loop._ncol - 2] * 1e6   # the per-tick CPU column of the ring
    out["whole_tick_cpu_us"] = {"median": round(float(np.median(cpu)), 2), "p99": round(float(np.percentile(cpu, 99)), 2),
                                "max": round(float(cpu.max()), 1)}
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ticks", type=int, default=60_000)
    ap.add_argument("--mode", choices=sorted(WRAPPED), default="outer")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    d = run(a.ticks, a.mode)
    if a.json:
        print(json.dumps(d, indent=1))
        return 0
    print(f"{d['ticks']} ticks, mode {d['mode']}; on-CPU us per call (median / p99 / max), "
          f"empty thread_time_ns pair {d['thread_time_pair_ns']:.0f} ns subtracted")
    for k, v in d["parts_us"].items():
        print(f"  {k:52s} {v['median']:6.2f} / {v['p99']:6.2f} / {v['max']:7.1f}")
    w = d["whole_tick_cpu_us"]
    print(f"  {'whole tick (loop clock, wrapped run)':52s} {w['median']:6.2f} / {w['p99']:6.2f} / {w['max']:7.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
