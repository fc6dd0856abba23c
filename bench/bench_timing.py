"""Servo-loop timing script (goals 13-15): 60 s runs with and without a second CPU-bound
process, in simulated time (tick compute) and realtime (period jitter).

``python bench/bench_timing.py [--seconds 60] [--json]``
"""

import argparse
import json
import os
import sys

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

from hapticsdk.benchmarks.timing import run_timing  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    rows = []
    for realtime in (False, True):
        for load in (False, True):
            d = run_timing(a.seconds, realtime=realtime, load=load)
            row = {"realtime": realtime, "load": load, "ticks": d["ticks"], "tick_median_us": d["tick_median_us"],
                   "tick_p99_us": d["tick_p99_us"], "tick_p999_us": d["tick_p999_us"], "tick_max_us": d["tick_max_us"],
                   "overruns": d["overruns"], "goal13_pass": d["goal13_pass"], "jitter": d["jitter"],
                   "dimensions": d["dimensions"]}
            rows.append(row)
            if not a.json:
                j = d["jitter"] or {}
                print(f"realtime={realtime!s:5} load={load!s:5} ticks={d['ticks']} compute median "
                      f"{d['tick_median_us']:.1f} p99 {d['tick_p99_us']:.1f} max {d['tick_max_us']:.1f} us"
                      + (f" | jitter p50 {j['p50_us']:.1f} p99 {j['p99_us']:.1f} p99.9 {j['p999_us']:.1f} "
                         f"max {j['max_us']:.1f} us missed {j['missed_tick_rate']:.4%}" if j else ""))
    if a.json:
        print(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
