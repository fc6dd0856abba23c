"""The hands-off damping calibration over the stability benchmark's space of arms: how
often its lower bound exceeds the true damping (the property the controller relies on),
and how much of the true damping it credits, beside the declared share.

    python bench/bench_damping_calibration.py [--arms 2000] [--seed 11] [--space benchmark]
        [--patterns 6] [--force-share 0.25] [--min-segment-ticks 10] [--travel-mm 5] [--json]

``--space`` draws the arms elsewhere than the benchmark's space (``heavy``: 0.1-0.5 kg with
1-5 N s/m; ``fast-periods``: 0.05-0.25 ms; ``slow-periods``: 10-50 ms; ``coarse``:
0.2-1 mm encoders; ``light-damping``: 0.001-0.05 N s/m), and the excitation's options
replace its design choices (:data:`hapticsdk.calibration.damping.PATTERNS`,
``FORCE_SHARE``, ``MIN_SEGMENT_TICKS``, ``TRAVEL_M``), to see that the bound does not
hinge on either.

Arms drawn log-uniform as in ``hapticsdk bench stability --random``: period 0.25-10 ms,
encoder 0.001-0.2 mm, mass 0.02-0.1 kg, true damping 0 (a quarter) or 0.05-1 N s/m; the
mass that sizes the excitation is declared at 0.5x-2x the true one, the damping declared
at 0.5x-2x the true one for the declared share (``damping_trust`` x declared). Each arm
runs :func:`hapticsdk.calibration.damping.excitation` on the simulated arm
(:func:`hapticsdk.sim.arm.free_arm_readings_mm`, exact, no hand, no Coulomb friction) and
:func:`~hapticsdk.calibration.damping.fit_damping` fits it. Reported: arms whose bound is
above the truth (worst case and, for comparison, a 3.09-standard-error bound of the same
fit), the bound over the truth (median and 10th percentile, arms with damping), the
declared share over the truth, and the fit's wall time per arm (median, ``perf_counter``).
Not measured: a real arm (friction, cables, a hand resting on the stylus), drift of the
servo period. Every figure comes from simulated arms (generated data).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


#: Log-uniform ranges per space: period (s), encoder (mm), mass (kg), damping when not 0 (N s/m).
SPACES = {
    "benchmark": ((0.25e-3, 10e-3), (0.001, 0.2), (0.02, 0.1), (0.05, 1.0)),
    "heavy": ((0.25e-3, 10e-3), (0.001, 0.2), (0.1, 0.5), (1.0, 5.0)),
    "fast-periods": ((0.05e-3, 0.25e-3), (0.001, 0.2), (0.02, 0.1), (0.05, 1.0)),
    "slow-periods": ((10e-3, 50e-3), (0.001, 0.2), (0.02, 0.1), (0.05, 1.0)),
    "coarse": ((0.25e-3, 10e-3), (0.2, 1.0), (0.02, 0.1), (0.05, 1.0)),
    "light-damping": ((0.25e-3, 10e-3), (0.001, 0.2), (0.02, 0.1), (0.001, 0.05)),
}


def main() -> int:
    import hapticsdk.calibration.damping as damping
    from hapticsdk.calibration.damping import excitation, fit_damping
    from hapticsdk.passivity.settings import DAMPING_TRUST
    from hapticsdk.sim.arm import ArmParams, free_arm_readings_mm

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--arms", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--space", choices=sorted(SPACES), default="benchmark")
    ap.add_argument("--patterns", type=int, default=damping.PATTERNS)
    ap.add_argument("--force-share", type=float, default=damping.FORCE_SHARE)
    ap.add_argument("--min-segment-ticks", type=int, default=damping.MIN_SEGMENT_TICKS)
    ap.add_argument("--travel-mm", type=float, default=damping.TRAVEL_M * 1e3)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    damping.PATTERNS, damping.FORCE_SHARE, damping.MIN_SEGMENT_TICKS = a.patterns, a.force_share, a.min_segment_ticks
    (t_r, q_r, m_r, b_r) = SPACES[a.space]
    rng = np.random.default_rng(a.seed)

    def lu(lo: float, hi: float) -> float:
        return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))

    rows = []
    for _ in range(a.arms):
        T, q, m = lu(*t_r), lu(*q_r), lu(*m_r)
        b = 0.0 if rng.random() < 0.25 else lu(*b_r)
        m_decl, b_decl = m * lu(0.5, 2.0), b * lu(0.5, 2.0)
        f = excitation(T, 3.3, m_decl, travel_m=a.travel_mm * 1e-3)
        y = free_arm_readings_mm(T, ArmParams(mass_kg=m, damping_ns_per_m=b, encoder_resolution_mm=q), f)
        t0 = time.perf_counter()
        fit = fit_damping(f, y, T, q)
        dt = time.perf_counter() - t0
        rows.append((b, fit.trusted_damping_ns_per_m, fit.damping_ns_per_m - 3.09 * fit.damping_se_ns_per_m,
                     DAMPING_TRUST * b_decl, fit.success, dt, fit.readings))
    r = np.array(rows, float)
    pos = r[:, 0] > 0
    out = {"arms": a.arms, "seed": a.seed, "space": a.space, "generated": True,
           "excitation": {"patterns": a.patterns, "force_share": a.force_share,
                          "min_segment_ticks": a.min_segment_ticks, "travel_mm": a.travel_mm},
           "failed_fits": int((r[:, 4] == 0).sum()),
           "bound_above_truth": int((r[:, 1] > r[:, 0]).sum()),
           "se_bound_3_09_above_truth": int((r[:, 2] > r[:, 0]).sum()),
           "median_bound_over_truth": float(np.median(r[pos, 1] / r[pos, 0])),
           "p10_bound_over_truth": float(np.quantile(r[pos, 1] / r[pos, 0], 0.1)),
           "median_declared_share_over_truth": float(np.median(r[pos, 3] / r[pos, 0])),
           "median_fit_time_s": float(np.median(r[:, 5])), "clock": "time.perf_counter, wall time of fit_damping",
           "median_readings": float(np.median(r[:, 6]))}
    if a.json:
        print(json.dumps(out, indent=1))
    else:
        print(f"{a.arms} simulated arms (seed {a.seed}, space {a.space}, excitation {out['excitation']}, "
              f"GENERATED): fits failed {out['failed_fits']}; worst-case bound "
              f"above the true damping in {out['bound_above_truth']} (a 3.09-standard-error bound of the same fits: "
              f"{out['se_bound_3_09_above_truth']}); bound / truth median {out['median_bound_over_truth']:.3f}, "
              f"10th percentile {out['p10_bound_over_truth']:.3f} (declared share / truth median "
              f"{out['median_declared_share_over_truth']:.3f}); fit {out['median_fit_time_s'] * 1e3:.1f} ms median "
              f"over {out['median_readings']:.0f} readings")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
