"""Stability matrix script: ``python bench/bench_stability.py [--quick] [--json] [--plot PNG]``.

Pins BLAS/OpenMP to one thread, then runs ``hapticsdk bench stability``
(see hapticsdk/benchmarks/stability.py).
"""

import os
import sys

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

from hapticsdk.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["bench", "stability", *sys.argv[1:]]))
