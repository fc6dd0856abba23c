"""The stiff-wall controller on hand motions the stability benchmark does not draw, through
the independent simulator (``tests/independent_plant.py``: exact zero-order hold, its own
energy sums). Simulated arms and fingers: generated data.

    python bench/bench_hand_motions.py [--cells 500] [--seed 11] [--kinds tremor,walk,yank,pump,inside]
                                       [--json out.json]

Each cell draws the device from the benchmark's space (``hapticsdk bench stability
--random``: stiffness 0.01-10^4 N/mm, period 0.25-10 ms, encoder 0.001-0.2 mm, arm
0.02-0.1 kg declared at 0.5x-2x, damping none in a quarter of the cells or 0.05-1 N s/m,
the finger's mass, spring and damper), its arm's damping measured hands off as the
benchmark's ``sdk`` lane does, and one hand motion, the kinds taken in turn:

* ``tremor``: a press (2 mm above to 0.5-6 mm in at 5-500 mm/s), held 0.5-1.5 s with a
  4-12 Hz tremor of 0.05-0.5 mm plus a 30-300 Hz one of 0.005-0.1 mm, released at
  5-1500 mm/s;
* ``walk``: the same press, held with a random walk of the hand (an Ornstein-Uhlenbeck
  path, 1-50 mm/sqrt(s), mean reversion 2-50 /s);
* ``yank``: the hand's reference jumps from 2 mm above the surface to 0.5-6 mm in and
  back, 2-6 times, within one tick each time (the finger's spring and damper carry the
  stylus: a hand pulled away at metres a second);
* ``pump``: the press held while the hand pumps across 0.3-3 counts at 1-300 Hz;
* ``inside``: the stylus resting 0.5-6 mm inside the wall when the controller starts
  (a wall that appears around it), held, then drawn out.

What it reports per kind: the cells whose energy to the finger (device side, largest over
the run) exceeds 0.1 mJ, the largest energy, the median delivered ratio (the benchmark's
definition) and the cells whose force ever fell below the controller's ramp
(``below_ramp_ticks``) and the cells in which the bound was ever spent (``spent_ticks``:
the force above the Colgate spring held back; the controller's own warning, one per
controller, is not printed per cell). What it does not measure: the peers, the servo loop's own timing,
motion the readings cannot resolve by construction (a pump or tremor above half the
servo's rate is in the draw and is reported with the rest, not apart).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import independent_plant as ip  # noqa: E402

from hapticsdk.benchmarks.stability_random import ENERGY_BOUND_J, measure_cell_damping  # noqa: E402
from hapticsdk.fileio import atomic_write_text  # noqa: E402
from hapticsdk.passivity import PassivityController  # noqa: E402

KINDS = ("tremor", "walk", "yank", "pump", "inside")
ABOVE_MM = 2.0
REST_S = 0.3


def _lu(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def draw(rng: np.random.Generator, kind: str) -> dict:
    """One cell: the device and finger as the benchmark draws them, and this kind's motion."""
    b = 0.0 if rng.random() < 0.25 else _lu(rng, 0.05, 1.0)
    m = _lu(rng, 0.02, 0.1)
    return dict(kind=kind, stiffness_n_per_mm=_lu(rng, 0.01, 1e4), period_s=_lu(rng, 0.25e-3, 10e-3),
                resolution_mm=_lu(rng, 0.001, 0.2), arm_mass_kg=m, arm_mass_declared_kg=m * _lu(rng, 0.5, 2.0),
                damping_true_ns_per_m=b, damping_declared_ns_per_m=b * _lu(rng, 0.5, 2.0),
                finger_mass_kg=_lu(rng, 0.003, 0.05), finger_stiffness_n_per_m=_lu(rng, 50, 2000),
                finger_damping_ns_per_m=_lu(rng, 0.1, 5.0), depth_mm=rng.uniform(0.5, 6), v_in=_lu(rng, 5, 500),
                hold_s=rng.uniform(0.5, 1.5), v_out=_lu(rng, 5, 1500), tremor_mm=rng.uniform(0.05, 0.5),
                tremor_hz=rng.uniform(4, 12), buzz_mm=_lu(rng, 0.005, 0.1), buzz_hz=_lu(rng, 30, 300),
                walk_mm_per_sqrt_s=_lu(rng, 1, 50), walk_return_per_s=_lu(rng, 2, 50),
                yanks=int(rng.integers(2, 7)), yank_hold_s=rng.uniform(0.01, 0.2),
                pump_counts=rng.uniform(0.3, 3.0), pump_hz=_lu(rng, 1, 300), walk_seed=int(rng.integers(1 << 30)))


def reference(c: dict):
    """The hand's reference ``r(t)`` (mm, the surface at 0, inside below) and the run's length (s)."""
    a, d, kind = ABOVE_MM, c["depth_mm"], c["kind"]
    if kind == "yank":
        per = 2 * c["yank_hold_s"]

        def yank(t: float) -> float:
            j = int(t // per)
            return a if j >= c["yanks"] or (t - j * per) < c["yank_hold_s"] else -d
        return yank, c["yanks"] * per + REST_S
    if kind == "inside":
        hold, out = c["yank_hold_s"], 0.05

        def inside(t: float) -> float:
            return -d if t < hold else (-d + (a + d) * min((t - hold) / out, 1.0))
        return inside, hold + out + REST_S
    t_in, hold, t_out = (a + d) / c["v_in"], c["hold_s"], (a + d) / c["v_out"]
    if kind == "walk":
        rng = np.random.default_rng(c["walk_seed"])
        dt = 1e-4
        z = np.zeros(int(hold / dt) + 2)
        s, th = c["walk_mm_per_sqrt_s"], c["walk_return_per_s"]
        for i in range(1, z.size):
            z[i] = z[i - 1] - th * z[i - 1] * dt + s * math.sqrt(dt) * rng.standard_normal()

        def mod(t: float) -> float:
            return float(z[min(int(t / dt), z.size - 1)])
    elif kind == "tremor":
        def mod(t: float) -> float:
            return (c["tremor_mm"] * math.sin(2 * math.pi * c["tremor_hz"] * t)
                    + c["buzz_mm"] * math.sin(2 * math.pi * c["buzz_hz"] * t))
    else:
        amp = c["pump_counts"] * c["resolution_mm"]

        def mod(t: float) -> float:
            return amp * math.sin(2 * math.pi * c["pump_hz"] * t)

    def press(t: float) -> float:
        if t < t_in:
            return a - (a + d) * t / t_in
        if t < t_in + hold:
            return -d + mod(t - t_in)
        return min(-d + mod(hold) + (a + d) * (t - t_in - hold) / t_out, a)
    return press, t_in + hold + t_out + REST_S


def run(c: dict) -> dict:
    """The cell through the independent plant with the ``sdk`` lane's scalar controller."""
    c = dict(c, damping_calibration=measure_cell_damping(c))
    ref, dur = reference(c)
    ctl = PassivityController(ip.sdk_settings(c, "sdk"))
    out = ip.drive(c, ref, dur, lambda x, fw: ctl.step(x, c["period_s"], fw), ctl.commit)
    rep = ctl.report()
    return {"energy_to_user_j": out["energy_to_user_j"], "delivered_ratio": out["delivered_ratio"],
            "below_ramp_ticks": rep.get("below_ramp_ticks", 0), "spent_ticks": rep["spent_ticks"],
            "overdrawn_j": rep["overdrawn_j"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cells", type=int, default=500)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--json")
    a = ap.parse_args(argv)
    kinds = a.kinds.split(",")
    unknown = set(kinds) - set(KINDS)
    if unknown:
        ap.error(f"unknown kinds {sorted(unknown)}; choose from {', '.join(KINDS)}")
    # the spent-bound warning is for a live loop's user; here it is counted per cell
    logging.getLogger("hapticsdk.passivity.controller").setLevel(logging.ERROR)
    rng = np.random.default_rng(a.seed)
    rows = []
    for i in range(a.cells):
        c = draw(rng, kinds[i % len(kinds)])
        rows.append({"cell": i, **c, **run(c)})
    print(f"GENERATED (simulated arms and fingers), seed {a.seed}, {a.cells} cells, sdk lane (damping measured "
          f"hands off), independent plant; energy to the finger, largest over the run")
    print(f"{'kind':<8} {'cells':>5} {'> 0.1 mJ':>9} {'max E (mJ)':>11} {'median F/Kx':>12} {'below ramp':>11} {'bound spent':>12}")
    for kind in kinds:
        rs = [r for r in rows if r["kind"] == kind]
        e = np.array([r["energy_to_user_j"] for r in rs])
        dr = np.array([r["delivered_ratio"] for r in rs])
        print(f"{kind:<8} {len(rs):>5} {int((e > ENERGY_BOUND_J).sum()):>9} {e.max() * 1e3:>11.4f} "
              f"{np.nanmedian(dr):>12.3f} {sum(r['below_ramp_ticks'] > 0 for r in rs):>11} "
              f"{sum(r['spent_ticks'] > 0 for r in rs):>12}")
    for r in rows:
        if r["energy_to_user_j"] > ENERGY_BOUND_J:
            print(f"  over: cell {r['cell']} {r['kind']}: {r['energy_to_user_j'] * 1e3:.3f} mJ, T "
                  f"{r['period_s'] * 1e3:.2f} ms, encoder {r['resolution_mm']:.3f} mm, damping "
                  f"{r['damping_true_ns_per_m']:.2f} N s/m, K {r['stiffness_n_per_mm']:.3g} N/mm")
    if a.json:
        atomic_write_text(a.json, json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
