"""Solver benchmark script: ``python bench/bench_solvers.py [--quick] [--json] [--plot FILE]``.

Pins BLAS/OpenMP to one thread before numpy is imported, then runs
``hapticsdk bench solvers`` (see hapticsdk/benchmarks/solvers.py).
"""

import os
import sys

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

from hapticsdk.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["bench", "solvers", *sys.argv[1:]]))
