"""``hapticsdk bench solvers``: work-precision and runtime-to-target of the inverse solvers.

See :mod:`hapticsdk.benchmarks.solvers` for what is measured. Run on one core:
``OMP_NUM_THREADS=1 hapticsdk bench solvers --plot docs/img/solvers-work-precision.png``.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any


def register_bench(bench_sub: argparse._SubParsersAction) -> None:
    p = bench_sub.add_parser("solvers", help="solver work-precision, runtime-to-target, peers (pygad, DEAP, pymoo)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--plot", metavar="FILE", help="write the work-precision plot (PNG; needs matplotlib)")
    p.add_argument("--quick", action="store_true", help="3 seeds and fewer settings (about a minute)")
    p.add_argument("--seeds", type=int, default=None, help="seeds per setting (default 15, --quick 3)")
    p.add_argument("--output", metavar="FILE", help="also write the JSON report to FILE")
    p.set_defaults(func=cmd_bench_solvers)


def cmd_bench_solvers(args: Any) -> int:
    from ..benchmarks import solvers as bench

    log = (lambda s: print(f"[bench solvers] {s}", file=sys.stderr)) if not args.json else None
    report = bench.run(quick=bool(args.quick), seeds=args.seeds, log=log)
    if args.output:
        with open(args.output, "w") as fh:
            json.dump(report, fh, indent=2, default=_default)
    if args.plot:
        try:
            bench.plot(report, args.plot)
        except ImportError as exc:
            print(f"hapticsdk: --plot needs matplotlib (pip install 'hapticsdk[plot]'): {exc}", file=sys.stderr)
            return 2
        report.setdefault("meta", {})["plot"] = args.plot
    if args.json:
        print(json.dumps(report, indent=2, default=_default))
    else:
        print(bench.summary_text(report))
    return 0


def _default(o: Any) -> Any:
    import numpy as np
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    return str(o)
