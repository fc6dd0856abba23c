"""Servo-loop timing script (tick compute time and jitter limits): runs with and without a second CPU-bound
process, in simulated time (tick compute: wall clock and the servo thread's on-CPU
time) and realtime (period jitter), optionally with OS real-time options.

``python bench/bench_timing.py [--seconds 60] [--pin-cpu N] [--fifo-priority P]
[--mlockall] [--rt-sim] [--json]``

The OS options (CPU pinning, SCHED_FIFO, mlockall) are applied to the realtime (paced)
runs; ``--rt-sim`` applies them to the simulated-time runs too (a SCHED_FIFO thread that
never sleeps holds its CPU for the whole run: avoid on a shared machine). A refused
option is reported, not raised.
"""

import argparse
import json
import os
import sys

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

from hapticsdk.benchmarks.timing import format_table, run_timing  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--pin-cpu", type=int, default=None, metavar="N", help="pin the servo thread to CPU N")
    ap.add_argument("--fifo-priority", type=int, default=None, metavar="P", help="request SCHED_FIFO priority P")
    ap.add_argument("--mlockall", action="store_true", help="lock the process's memory (Linux)")
    ap.add_argument("--rt-sim", action="store_true", help="apply the OS options to the simulated-time runs too")
    ap.add_argument("--declared-rt-machine", action="store_true", help="judge the jitter limits (pass/fail)")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    rt = {"cpu": a.pin_cpu, "fifo_priority": a.fifo_priority, "mlockall": a.mlockall}
    runs = []
    for realtime in (False, True):
        for load in (False, True):
            d = run_timing(a.seconds, realtime=realtime, load=load, rt=rt if (realtime or a.rt_sim) else None,
                           declared_rt_machine=a.declared_rt_machine)
            runs.append(d)
            if not a.json:
                print(f"done: realtime={realtime} load={load}", file=sys.stderr, flush=True)
    if a.json:
        keys = ("realtime", "load", "ticks", "tick_median_us", "tick_p99_us", "tick_p999_us", "tick_max_us",
                "compute_us", "compute_cpu_us", "preempted_ticks", "preempt_threshold_us", "off_cpu_max_us",
                "cpu_clock_cost_us", "overruns", "tick_limits_met_cpu", "tick_limits_met_wall", "tick_limits", "jitter",
                "jitter_limits", "jitter_limits_met", "rt", "rt_requested", "dimensions", "machine")
        print(json.dumps([{k: d.get(k) for k in keys} for d in runs], indent=2))
    else:
        print(format_table(runs))
    return 0


if __name__ == "__main__":
    sys.exit(main())
