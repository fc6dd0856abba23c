"""What a declared damping is worth to the stiff-wall controller, and what a wrong one
costs: the randomised stability benchmark's cells (``draw_cells(N, seed)``, the
``sdk_declared`` lane: a device never calibrated, only its declaration to go on), run
with a share of the declaration credited (``declared_damping_trust``: 0, the default, and
1/2, ``DAMPING_TRUST``) on two sets of arms:

* ``right``: the cells as drawn (the declaration 0.5x-2x the true damping);
* ``wrong``: every arm declared at ``--declared`` N s/m (0.5) on a true damping of 0 (the
  issue's "0.5 declared, 0 real").

    python bench/bench_declared_damping.py [--cells 1000] [--seed 1] [--declared 0.5] [--json]

Per set and share: the cells whose energy to the user stays within 0.1 mJ, the largest
energy (mJ) and the median delivered ratio (``delivered_ratio`` of the benchmark:
force sent over ``min(K pen, 3.3 N)`` on the contact ticks). Not measured: the ``sdk``
lane (a measured damping, which these settings do not touch), a real arm. Every figure
comes from the simulated plant (generated data).
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from hapticsdk.benchmarks.stability_random import ENERGY_BOUND_J, draw_cells, run_cells
from hapticsdk.passivity import DAMPING_TRUST, DECLARED_DAMPING_TRUST, ControllerSettings


def run(cells: int, seed: int, declared: float) -> list[dict]:
    out = []
    for arms in ("right", "wrong"):
        drawn = draw_cells(cells, seed)
        if arms == "wrong":
            for c in drawn:
                c["damping_true_ns_per_m"], c["damping_declared_ns_per_m"] = 0.0, declared
        for share in (DECLARED_DAMPING_TRUST, DAMPING_TRUST):
            res = run_cells(drawn, controllers=("sdk_declared",),
                            settings=ControllerSettings(declared_damping_trust=share))
            e = np.array([c["results"]["sdk_declared"]["energy_to_user_j"] for c in res])
            d = np.array([c["results"]["sdk_declared"]["delivered_ratio"] for c in res])
            out.append({"arms": arms, "declared_damping_trust": share, "cells": len(e),
                        "cells_energy_within_bound": int((e <= ENERGY_BOUND_J).sum()),
                        "max_energy_to_user_j": float(e.max()),
                        "median_delivered_ratio": float(np.nanmedian(d))})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cells", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--declared", type=float, default=0.5, help="the wrong declaration (N s/m)")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    rows = run(a.cells, a.seed, a.declared)
    if a.json:
        print(json.dumps({"generated": True, "seed": a.seed, "rows": rows}, indent=1))
        return
    print(f"simulated plant (GENERATED data), draw_cells({a.cells}, {a.seed}), sdk_declared lane; "
          f"wrong = declared {a.declared} N s/m on a true damping of 0")
    for r in rows:
        print(f"{r['arms']:5s} share {r['declared_damping_trust']:.2f}: within {ENERGY_BOUND_J * 1e3:g} mJ "
              f"{r['cells_energy_within_bound']}/{r['cells']}, largest {r['max_energy_to_user_j'] * 1e3:.3f} mJ, "
              f"median delivered {r['median_delivered_ratio']:.3f}")


if __name__ == "__main__":
    main()
