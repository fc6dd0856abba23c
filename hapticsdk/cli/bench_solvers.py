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
    """Add ``bench solvers`` under ``hapticsdk bench``."""
    p = bench_sub.add_parser("solvers", help="solver work-precision, runtime-to-target, peers (pygad, DEAP, pymoo)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    from .argtypes import bounded_int, figure_file
    # the figure's format is checked when the arguments are parsed, before minutes of benchmark
    p.add_argument("--plot", metavar="FILE", type=figure_file,
                   help="write the work-precision plot (PNG, or another format by its suffix; needs matplotlib)")
    p.add_argument("--quick", action="store_true", help="3 seeds and fewer settings (about a minute)")
    p.add_argument("--seeds", type=bounded_int(1, 1000), default=None,
                   help="seeds per setting, 1..1000 (default 15, --quick 3)")
    p.add_argument("--output", metavar="FILE", help="also write the JSON report to FILE")
    p.set_defaults(func=cmd_bench_solvers)


def cmd_bench_solvers(args: Any) -> int:
    """Run the solver benchmark; print its summary (or JSON), optionally write the JSON
    report and the work-precision plot. Returns the exit status.
    """
    from ..benchmarks import solvers as bench

    from ..fileio import check_output_path
    # output paths are checked before the benchmark runs (minutes), not after it
    if args.output:
        check_output_path(args.output, field="--output")
    if args.plot:
        check_output_path(args.plot, field="--plot")
    from ..progress import Progress
    # progress lines go above a bar on a terminal's stderr; nothing in a pipe or with --json
    with Progress("bench solvers", quiet=args.json) as progress:
        report = bench.run(quick=bool(args.quick), seeds=args.seeds,
                           log=progress.note if progress.enabled else None)
    if args.output:
        from ..fileio import atomic_write_text
        atomic_write_text(args.output, json.dumps(report, indent=2, default=_default) + "\n", field="--output")
    if args.plot:
        try:
            bench.plot(report, args.plot)
        except ImportError as exc:
            from ..install_hints import pip_hint
            print(f"hapticsdk: --plot needs matplotlib ({pip_hint('hapticsdk', 'plot')}): {exc}", file=sys.stderr)
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
