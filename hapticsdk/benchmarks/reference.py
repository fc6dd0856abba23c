"""Bare references and machine facts for benchmark figures.

A figure in microseconds means little on another machine, or on this one under another
load. Every runtime benchmark therefore reports, next to its figures, the same clock and
statistic applied in the same run to two bare references, and the ratios to them:

* ``empty_call_us``: one call of a Python function that does nothing, the clock read
  before and after (what the cheapest possible "tick" costs with this clock);
* ``bare_loop_us``: one iteration of a ``for`` loop over a range that does nothing,
  timed as a block of ``BLOCK`` iterations (the interpreter's speed, without clock reads).

and :func:`machine` says where and when: CPU model, cores, load average before and after,
Python and platform. A ratio ``tick / empty_call`` taken in the same run moves much less
with the machine and its load than the microseconds do; it is no substitute for
measuring on the target machine.
"""

from __future__ import annotations

import os
import platform
import time
from typing import Any, Callable

from ..quantiles import median

#: iterations of the bare loop timed as one sample
BLOCK = 1000

#: the clocks a figure can be taken with: name -> (reader in ns, description)
CLOCKS: dict[str, tuple[Callable[[], int], str]] = {
    "thread_cpu": (time.thread_time_ns, "time.thread_time_ns: on-CPU time of the calling thread"),
    "wall": (time.perf_counter_ns, "time.perf_counter_ns: monotonic wall clock"),
}


def _nothing() -> None:
    return None


def bare_reference(clock: str = "thread_cpu", samples: int = 2001) -> dict[str, Any]:
    """Median cost of an empty call (clock read around it, as a tick is timed) and of one
    bare-loop iteration, with ``clock`` (a key of :data:`CLOCKS`), in microseconds."""
    if clock not in CLOCKS:
        raise ValueError(f"clock must be one of {sorted(CLOCKS)}, got {clock!r}")
    read, what = CLOCKS[clock]
    f = _nothing
    calls = []
    for _ in range(samples):
        q0 = read()
        f()
        calls.append(read() - q0)
    loops = []
    rng = range(BLOCK)
    for _ in range(max(1, samples // 20)):
        q0 = read()
        for _ in rng:
            pass
        loops.append((read() - q0) / BLOCK)
    return {"clock": clock, "clock_description": what, "statistic": "median",
            "empty_call_us": median(calls) * 1e-3, "bare_loop_us": median(loops) * 1e-3, "samples": samples}


def ratios(figures_us: dict[str, float], ref: dict[str, Any]) -> dict[str, float]:
    """Each figure (us) over the empty call and over the bare-loop iteration of ``ref``."""
    out = {}
    for name, v in figures_us.items():
        for key in ("empty_call_us", "bare_loop_us"):
            r = ref.get(key)
            out[f"{name}/{key[:-3]}"] = v / r if r else float("nan")
    return out


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def machine() -> dict[str, Any]:
    """Where a figure was taken: CPU model, logical CPUs, 1-min load average, Python,
    platform."""
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = float("nan")
    return {"cpu_model": _cpu_model(), "cpus": os.cpu_count(), "load_1min": load,
            "python": platform.python_version(), "implementation": platform.python_implementation(),
            "platform": platform.platform()}


def describe(ref: dict[str, Any], before: dict[str, Any], after: dict[str, Any]) -> str:
    """One line for a text report: the machine, its load before/after, the references."""
    return (f"machine: {before['cpu_model']}, {before['cpus']} CPUs, load {before['load_1min']:.2f} -> "
            f"{after['load_1min']:.2f}, Python {before['python']}; bare references ({ref['clock']} clock, "
            f"{ref['statistic']}): empty call {ref['empty_call_us']:.3f} us, bare loop iteration "
            f"{ref['bare_loop_us'] * 1e3:.1f} ns")


def with_reference(d: dict[str, Any], before: dict[str, Any]) -> dict[str, Any]:
    """Add ``reference`` to a servo report's dict ``d`` (``LoopReport.to_dict`` keys):
    the bare references with both clocks the tick figures use, the machine before
    (``before``) and now, and each tick figure's ratio to the references of its own clock
    (``compute_cpu_us`` with ``thread_cpu``, ``compute_us`` with ``wall``)."""
    refs = {"thread_cpu": bare_reference("thread_cpu"), "wall": bare_reference("wall")}
    out: dict[str, Any] = {"machine_before": before, "machine_after": machine(), **refs}
    for key, clock in (("compute_cpu_us", "thread_cpu"), ("compute_us", "wall")):
        c = d.get(key) or {}
        figs = {k: c[k] for k in ("median_us", "p99_us") if isinstance(c.get(k), (int, float))}
        out[f"ratios_{key}"] = ratios(figs, refs[clock])
    d["reference"] = out
    return d


def reference_lines(runs: list[dict[str, Any]]) -> list[str]:
    """Text lines for the reports of ``runs`` that carry ``reference``: the machine and
    references of each, and the CPU tick median as a multiple of the empty call."""
    lines = []
    for d in runs:
        r = d.get("reference")
        if not r:
            continue
        ref = r["thread_cpu"]
        lines.append(describe(ref, r["machine_before"], r["machine_after"]))
        rc = r.get("ratios_compute_cpu_us", {})
        if "median_us/empty_call" in rc:
            lines.append(f"tick CPU compute = {rc['median_us/empty_call']:.1f} empty calls (median), "
                         f"{rc.get('p99_us/empty_call', float('nan')):.1f} (p99), same clock and run")
    return lines
