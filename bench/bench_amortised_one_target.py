"""CPU time and error of the public one-target amortised call, lookup only and default.

    OMP_NUM_THREADS=1 python bench/bench_amortised_one_target.py

Targets: 500 reachable intensity pairs (the model's outputs at feasible feature points,
fixed seed, away from the 0/1 edges). Per call: ``time.process_time`` around
``hapticsdk.solve(target, method="amortised")``, 5 rounds; median and mean over calls; the
error median and 90th percentile over the targets. To compare with other code, run it
again with that code's ``hapticsdk_ga`` first on ``PYTHONPATH`` (the output names the
module file it used), alternating old and new in one session.
"""

from __future__ import annotations

import json
import statistics
import time

import numpy as np


def main() -> None:
    import hapticsdk as hs
    import hapticsdk_ga.amortised as am
    from hapticsdk.benchmarks.solvers import feasible_samples
    from hapticsdk.problems import build_problem

    p = build_problem({"hardness": 0.5, "roughness": 0.5})
    _, Y = feasible_samples(p, 4000, seed=7)
    Y = Y[(Y.min(1) > 0.02) & (Y.max(1) < 0.98)][:500]
    T = [{"hardness": float(a), "roughness": float(b)} for a, b in Y]
    pt = time.process_time
    out: dict = {"module": am.__file__, "targets": len(T), "clock": "time.process_time per call"}
    for name, opts in (("lookup only", {"polish_steps": 0}), ("default", {})):
        hs.solve(T[0], method="amortised", options=opts)
        per = []
        for _ in range(5):
            for t in T:
                c0 = pt()
                hs.solve(t, method="amortised", options=opts)
                per.append(pt() - c0)
        res = [hs.solve(t, method="amortised", options=opts) for t in T]
        errs = [r.error for r in res]
        out[name] = {"cpu_us_median": round(statistics.median(per) * 1e6, 1),
                     "cpu_us_mean": round(statistics.mean(per) * 1e6, 1),
                     "error_median": float(statistics.median(errs)), "error_p90": float(np.percentile(errs, 90)),
                     "gauss_newton_share": sum("Gauss-Newton" in r.message for r in res) / len(res)}
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
