"""Time and memory per input byte of the SDK's JSON reader (``hapticsdk.schemas_io.read_json``)
for the costliest shapes of JSON (docs/safety.md, "Budgets"). Run by hand:

    python bench/bench_json_budget.py [--n 200000]

Prints, per shape, the file size, the traced peak memory per input byte (``tracemalloc``)
and the wall time per input byte (``time.perf_counter``, one read per shape: a figure on
the machine it runs on, not a test)."""

from __future__ import annotations

import argparse
import tempfile
import time
import tracemalloc
from pathlib import Path

from hapticsdk.schemas_io import read_json


def shapes(n: int) -> dict[str, str]:
    return {"empty lists": "[" + ",".join(["[]"] * n) + "]",
            "empty objects": "[" + ",".join(["{}"] * n) + "]",
            "nested lists": "[" + ",".join(["[[[[[[[[[[]]]]]]]]]]"] * (n // 10)) + "]",
            "small ints": "[" + ",".join(["1"] * n) + "]",
            "floats": "[" + ",".join(["0.5"] * n) + "]",
            "strings": "[" + ",".join(['"a"'] * n) + "]",
            "keys": "{" + ",".join(f'"{i}":0' for i in range(n)) + "}"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200_000, help="values per file")
    n = ap.parse_args().n
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "f.json"
        print(f"{'shape':14s} {'bytes':>9s} {'peak B/B':>9s} {'ns/B':>7s}")
        for name, text in shapes(n).items():
            p.write_text(text)
            size = p.stat().st_size
            tracemalloc.start()
            read_json(p, field="x")
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
            t0 = time.perf_counter()
            read_json(p, field="x")
            dt = time.perf_counter() - t0
            print(f"{name:14s} {size:9d} {peak / size:9.1f} {dt / size * 1e9:7.1f}")


if __name__ == "__main__":
    main()
