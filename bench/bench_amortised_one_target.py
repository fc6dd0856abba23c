"""CPU time and error of the public one-target amortised call, lookup only and default.

    OMP_NUM_THREADS=1 python bench/bench_amortised_one_target.py [--baseline REF [--rounds N]]

Targets: 500 reachable intensity pairs (the model's outputs at feasible feature points,
fixed seed, away from the 0/1 edges). Per call: ``time.process_time`` around
``hapticsdk.solve(target, method="amortised")``, 5 rounds; median and mean over calls; the
error median and 90th percentile over the targets; the same clock around an empty call
(median of 2001) as the bare reference of the run.

``--baseline REF``: the same measurement on the files of git ref ``REF`` and on this
code, ``--rounds`` times each, alternating, each in a fresh child process of this
interpreter (:mod:`hapticsdk.benchmarks.baseline`: the ref's tree exported with ``git
archive``, imported from there); prints both, each call's median over its own empty
call, and this code / baseline paired by round.
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np


def measure() -> dict:
    import hapticsdk as hs
    import hapticsdk_ga.amortised as am
    from hapticsdk.benchmarks.solvers import feasible_samples
    from hapticsdk.solvers.problems import build_problem

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

    def nothing() -> None:
        return None
    ref = []
    for _ in range(2001):
        c0 = pt()
        nothing()
        ref.append(pt() - c0)
    out["empty_call_us"] = statistics.median(ref) * 1e6
    return out


def side_by_side(ref: str, rounds: int) -> None:
    from hapticsdk.benchmarks.baseline import PRELUDE, exported_tree, repository_of, resolve, run_code
    from hapticsdk.benchmarks.reference import machine
    script = str(Path(__file__).resolve())
    code = PRELUDE + f"import runpy, sys\nsys.argv = [{script!r}, '--child']\nrunpy.run_path({script!r}, run_name='__main__')\n"
    repo = repository_of(Path(script).parent)
    commit = resolve(repo, ref)
    before = machine()
    runs: dict[str, list] = {"baseline": [], "this": []}
    with exported_tree(repo, commit) as tree:
        for r in range(rounds):
            order = [("baseline", tree), ("this", None)] if r % 2 == 0 else [("this", None), ("baseline", tree)]
            for name, t in order:
                d = run_code(t, code, [])
                if t is not None and not str(Path(d["module"]).resolve()).startswith(str(tree.resolve())):
                    raise RuntimeError(f"the baseline child imported {d['module']}")
                runs[name].append(d)
    after = machine()
    print(f"one-target hs.solve(..., method='amortised'), {runs['this'][0]['targets']} reachable targets x 5, "
          f"CPU time per call (time.process_time), median over calls, then median over {rounds} interleaved rounds")
    print(f"baseline {ref} ({commit[:10]}) vs this code; machine {before['cpu_model']}, {before['cpus']} CPUs, "
          f"load {before['load_1min']:.2f} -> {after['load_1min']:.2f}, Python {before['python']}")
    med = statistics.median
    for call in ("lookup only", "default"):
        for name in ("baseline", "this"):
            rs = runs[name]
            us = med([d[call]["cpu_us_median"] for d in rs])
            e0 = med([d["empty_call_us"] for d in rs])
            print(f"  {call:11} {name:8}: {us:7.1f} us (mean {med([d[call]['cpu_us_mean'] for d in rs]):6.1f}) "
                  f"= {us / e0:5.0f} empty calls ({e0:.3f} us); error median {rs[0][call]['error_median']:.2g}, "
                  f"p90 {rs[0][call]['error_p90']:.2g}")
        ratios = [n[call]["cpu_us_median"] / o[call]["cpu_us_median"] for o, n in zip(runs["baseline"], runs["this"])]
        print(f"  {call:11} this / baseline, paired by round: {med(ratios):.3f} ({', '.join(f'{x:.3f}' for x in ratios)})")


def main() -> None:
    args = sys.argv[1:]
    if args == ["--child"]:
        print(json.dumps(measure()))
    elif args[:1] == ["--baseline"] and len(args) in (2, 4):
        rounds = int(args[3]) if len(args) == 4 and args[2] == "--rounds" else 2
        side_by_side(args[1], rounds)
    elif not args:
        print(json.dumps(measure(), indent=1))
    else:
        sys.exit("usage: bench_amortised_one_target.py [--baseline REF [--rounds N]]")


if __name__ == "__main__":
    main()
