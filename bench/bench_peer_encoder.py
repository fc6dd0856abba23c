"""Why a virtual-coupling peer of the stability benchmark gives more than 0.1 mJ: the cells
of a ``hapticsdk bench stability --random N --seed S --json`` output where the lane (``vc``
or ``vc_measured``) is over the bound, run again with the encoder as drawn, ten times finer
and ideal (1e-9 mm), everything else the cell's (docs/runtime.md, Benchmarks, "The
virtual coupling over the bound").

    python bench/bench_peer_encoder.py OUT.json [--lane vc_measured]

Per cell: the coupling's stiffness in series with the wall (``K K_c / (K + K_c)``, ``K_c =
2 b / T`` of the damping the lane is sized on), Colgate's margin on the true damping ``b -
K T / 2`` (> 0: passive for exact positions), the force of one count, item 0's bound on
the gain of one crossing of a count, ``G = (K Delta)^2 T / (4 (b - K T / 2))``, and the
energy to the user (J) of the benchmark's own run (``run_cells``, that lane alone) at each
encoder; with the encoder as drawn also the energy of the independent simulator
(``tests/independent_plant.py``: its own plant, energy integral and coupling) and the
number of ticks whose reading changed. Generated data (simulated arm and finger).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import independent_plant as ip  # noqa: E402

from hapticsdk.benchmarks.stability_random import ENERGY_BOUND_J, run_cells  # noqa: E402

#: an encoder far finer than any motion of the run (mm): the readings are the positions
IDEAL_MM = 1e-9


def coupling_n_per_m(cell: dict, lane: str) -> float:
    """The stiffness the lane renders (N/m): Colgate's spring ``2 b / T`` on the damping the
    lane is sized on (the declaration for ``vc``, the calibration's lower bound for
    ``vc_measured``) in series with the wall."""
    b = (cell["damping_calibration"]["trusted_damping_ns_per_m"] if lane == "vc_measured"
         else cell["damping_declared_ns_per_m"])
    kc = 2.0 * b / cell["period_s"]
    k = cell["stiffness_n_per_mm"] * 1e3
    return k * kc / (k + kc) if k + kc > 0 else 0.0


def independent(cell: dict, k_n_per_m: float) -> tuple[float, int]:
    """The coupling ``k x penetration`` of the reading on the independent plant: the largest
    energy to the user (J) and the ticks whose reading changed."""
    readings: list[float] = []

    def send(x: float, fw: float) -> float:
        readings.append(x)
        return k_n_per_m * 1e-3 * max(-x, 0.0)

    ref, dur = ip.reference(cell)
    got = ip.drive(cell, ref, dur, send, lambda f: None)
    return got["energy_to_user_j"], sum(a != b for a, b in zip(readings, readings[1:]))


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results")
    ap.add_argument("--lane", choices=["vc", "vc_measured"], default="vc_measured")
    a = ap.parse_args(argv)
    cells = json.loads(Path(a.results).read_text())["cells"]
    over = [(i, c) for i, c in enumerate(cells) if c["results"][a.lane]["energy_to_user_j"] > ENERGY_BOUND_J]
    print(f"{a.lane}: {len(over)} of {len(cells)} cells over {ENERGY_BOUND_J * 1e3:.1f} mJ (generated data)")
    for i, c in over:
        k = coupling_n_per_m(c, a.lane)
        T, b, q = c["period_s"], c["damping_true_ns_per_m"], c["resolution_mm"] * 1e-3
        margin = b - k * T / 2.0
        gain = (k * q) ** 2 * T / (4.0 * margin) if margin > 0 else math.inf
        bare = {kk: v for kk, v in c.items() if kk != "results"}
        runs = {}
        for name, res in (("as drawn", c["resolution_mm"]), ("1/10", c["resolution_mm"] / 10), ("ideal", IDEAL_MM)):
            cc = dict(bare, resolution_mm=res)
            runs[name] = run_cells([cc], controllers=(a.lane,))[0]["results"][a.lane]["energy_to_user_j"]
        e_ind, changes = independent(bare, k)
        print(f"cell {i}: {c['trajectory']}, T {T * 1e3:.3f} ms, encoder {c['resolution_mm']:.4f} mm, true damping "
              f"{b:.4f} N s/m; coupling {k / 1e3:.4f} N/mm, b - K T/2 = {margin:.4f} N s/m, one count {k * q:.4f} N, "
              f"G {gain * 1e6:.2f} uJ per crossing; energy (uJ): as drawn {runs['as drawn'] * 1e6:.3f} "
              f"(independent {e_ind * 1e6:.3f}, {changes} reading changes), encoder / 10 {runs['1/10'] * 1e6:.3f}, "
              f"ideal {runs['ideal'] * 1e6:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
