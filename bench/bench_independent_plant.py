"""Cross-check of the stability benchmark's plant and energy integral against an independent
simulator (``tests/independent_plant.py``: its own exact ZOH step, Gauss-Legendre energy
integrals, the energy counted on the device side and on the finger side), both driving the
SDK's controller (scalar ``PassivityController`` here, the vectorised one in ``run_cells``)
and the plain wall, cell by cell.

    python bench/bench_independent_plant.py --cells 300 --seeds 1 77 [--controller scalar|batch]
                                            [--json out.json] [--ivp 5]

Prints, per lane, the largest absolute and relative differences of energy, delivered ratio,
largest force step and most negative contact force, and every cell where one side puts more
than 0.1 mJ into the hand and the other does not. ``--ivp N`` also replays the forces of N
cells per seed through ``scipy.integrate.solve_ivp`` (Radau, rtol 1e-11) tick by tick, as a
check of the independent simulator's integrator. With ``--controller batch`` the SDK lanes
run the vectorised controller on one lane, called as the benchmark calls it, so both sides
send the same forces wherever they read the same counts; then each cell's energy difference
is also held to the derived bound ``tolerance_j`` (``tests/independent_plant.py``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import independent_plant as ip  # noqa: E402

from hapticsdk.benchmarks.stability_random import ENERGY_BOUND_J, draw_cells, run_cells  # noqa: E402
from hapticsdk.fileio import atomic_write_text  # noqa: E402

LANES = ("plain", "sdk", "sdk_declared")
KEYS = ("energy_to_user_j", "delivered_ratio", "max_force_step_n", "min_contact_force_n")


def ivp_replay(cell: dict, forces: list[float], refs: list[float]) -> float:
    """Largest device-side energy over the ticks of the logged forces replayed through
    solve_ivp (Radau, rtol 1e-11, atol 1e-15 m), the damper's loss as an extra state."""
    from scipy.integrate import solve_ivp
    T = cell["period_s"]
    m, b = cell["arm_mass_kg"], cell["damping_true_ns_per_m"]
    mh, kh, bh = cell["finger_mass_kg"], cell["finger_stiffness_n_per_m"], cell["finger_damping_ns_per_m"]
    M = m + mh
    y, v = refs[0] * 1e-3, 0.0
    work = damp = 0.0
    emax = 0.0
    for k, f in enumerate(forces):
        r0, rd = refs[k] * 1e-3, (refs[k + 1] - refs[k]) * 1e-3 / T

        def rhs(t: float, s: np.ndarray) -> list[float]:
            yy, vv, _ = s
            return [vv, (f - b * vv + kh * (r0 + rd * t - yy) + bh * (rd - vv)) / M, b * vv * vv]
        sol = solve_ivp(rhs, (0.0, T), [y, v, 0.0], method="Radau", rtol=1e-11, atol=[1e-15, 1e-13, 1e-18])
        y1, v, d = sol.y[:, -1]
        work += f * (y1 - y)
        damp += d
        y = y1
        emax = max(emax, work - 0.5 * m * v * v - damp)
    return emax


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cells", type=int, default=300)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 77])
    ap.add_argument("--ivp", type=int, default=0)
    ap.add_argument("--controller", choices=("scalar", "batch"), default="scalar")
    ap.add_argument("--json")
    a = ap.parse_args(argv)
    rows = []
    for seed in a.seeds:
        t0 = time.perf_counter()
        cells = run_cells(draw_cells(a.cells, seed), controllers=LANES)
        t1 = time.perf_counter()
        n_ivp = 0
        for i, c in enumerate(cells):
            for lane in LANES:
                mine = ip.run_cell(c, lane, log=a.ivp > 0, controller=a.controller)
                row = {"seed": seed, "cell": i, "lane": lane, "trajectory": c["trajectory"],
                       "period_s": c["period_s"], "stiffness_n_per_mm": c["stiffness_n_per_mm"],
                       "resolution_mm": c["resolution_mm"], "gap_j": mine["energy_sides_gap_j"],
                       "ticks": mine["ticks"], "tolerance_j": mine["tolerance_j"],
                       "count_margin_mm": mine["count_margin_mm"]}
                for k in KEYS:
                    row["ind_" + k] = mine[k]
                    row["bench_" + k] = c["results"][lane][k]
                if a.ivp and lane == "sdk" and n_ivp < a.ivp and mine["ticks"] <= 4000:
                    row["ivp_energy_to_user_j"] = ivp_replay(c, mine["forces_n"], mine["refs_mm"])
                    n_ivp += 1
                rows.append(row)
        print(f"seed {seed}: {len(cells)} cells, run_cells {t1 - t0:.0f} s, independent "
              f"{time.perf_counter() - t1:.0f} s", flush=True)
    report(rows)
    if a.json:
        atomic_write_text(a.json, json.dumps(rows, indent=1))
    return 0


def report(rows: list[dict]) -> None:
    for lane in LANES:
        rs = [r for r in rows if r["lane"] == lane]
        print(f"\n{lane}: {len(rs)} cells")
        for k in KEYS:
            x = np.array([r["ind_" + k] for r in rs])
            y = np.array([r["bench_" + k] for r in rs])
            ok = np.isfinite(x) & np.isfinite(y)
            nan_mismatch = int((np.isfinite(x) != np.isfinite(y)).sum())
            d = np.abs(x[ok] - y[ok])
            rel = d / np.maximum(np.maximum(np.abs(x[ok]), np.abs(y[ok])), 1e-300)
            rel = np.where(d == 0, 0.0, rel)
            print(f"  {k:22s} max |diff| {d.max():.3e}  max rel {rel.max():.3e}  "
                  f"cells differing by >1e-9 rel: {(rel > 1e-9).sum()}  nan mismatch {nan_mismatch}")
        sure = [r for r in rs if r["count_margin_mm"] > 0]
        over_tol = [r for r in sure if abs(r["ind_energy_to_user_j"] - r["bench_energy_to_user_j"]) > r["tolerance_j"]]
        print(f"  cells read the same counts for sure (margin > 0): {len(sure)}; energy difference beyond the "
              f"derived bound among them: {len(over_tol)}; largest diff/bound "
              f"{max((abs(r['ind_energy_to_user_j'] - r['bench_energy_to_user_j']) / r['tolerance_j'] for r in sure), default=0):.2e}")
        g = max(r["gap_j"] for r in rs)
        print(f"  independent device-side vs finger-side energy: largest gap {g:.3e} J")
        flip = [r for r in rs if (r["ind_energy_to_user_j"] > ENERGY_BOUND_J) != (r["bench_energy_to_user_j"] > ENERGY_BOUND_J)]
        print(f"  cells over 0.1 mJ on one side only: {len(flip)}")
        for r in flip:
            print(f"    seed {r['seed']} cell {r['cell']} {r['trajectory']} T {r['period_s']*1e3:.2f} ms "
                  f"K {r['stiffness_n_per_mm']:.3g} N/mm: independent {r['ind_energy_to_user_j']:.4e} J, "
                  f"benchmark {r['bench_energy_to_user_j']:.4e} J")
        over = sum(r["ind_energy_to_user_j"] > ENERGY_BOUND_J for r in rs)
        print(f"  cells over 0.1 mJ: independent {over}, benchmark "
              f"{sum(r['bench_energy_to_user_j'] > ENERGY_BOUND_J for r in rs)}")
    iv = [r for r in rows if "ivp_energy_to_user_j" in r]
    if iv:
        d = max(abs(r["ivp_energy_to_user_j"] - r["ind_energy_to_user_j"]) for r in iv)
        print(f"\nsolve_ivp replay of {len(iv)} sdk cells: largest |energy diff| {d:.3e} J")
        mx = max(abs(r["ivp_energy_to_user_j"]) for r in iv)
        print(f"  (largest energy among them {mx:.3e} J)")


if __name__ == "__main__":
    sys.exit(main())
