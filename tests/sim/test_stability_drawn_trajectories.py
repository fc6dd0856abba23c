"""The randomised stability benchmark's finger references are the motions the cells say
(issue 23, item 3): each drawn cell's reference, sampled every 0.1 ms over its run, starts
and ends above the surface, reaches the drawn depth (plus the bumps' amplitude for a
bumpy slide, or the drift for a plain slide) and no deeper, and moves no faster than the
drawn speeds. Without this a change in the references would change what every cell
measures while every energy check still passed.
"""

from __future__ import annotations

import numpy as np
import pytest

from hapticsdk.benchmarks.stability_random import _Ref, draw_cells

#: the sampling step (s); the slopes below are read over it, so a kink of the piecewise
#: linear references costs nothing, and a sine's extreme is found within
#: (2 pi f dt)^2 / 2 of its amplitude (40 Hz: 3e-4 relative)
DT = 1e-4


def _sampled(cell):
    ref = _Ref([cell])
    t = np.arange(0.0, float(ref.duration_s[0]) + DT, DT)
    return t, ref(t), ref


def test_each_drawn_reference_is_the_motion_its_cell_names():
    cells = draw_cells(150, 3)
    assert {c["trajectory"] for c in cells} == {"press_hold", "tap", "bumpy_slide", "plain_slide", "creep"}
    for c in cells:
        t, r, ref = _sampled(c)
        kind = c["trajectory"]
        above = 0.2 if kind == "creep" else 2.0
        assert r[0] == pytest.approx(above, abs=1e-12) and r[-1] == pytest.approx(above, abs=1e-9), c
        d = c["depth_mm"]
        speed = np.abs(np.diff(r)) / DT
        if kind == "tap":
            deepest = d
            assert speed.max() <= c["tap_speed_mm_s"] * (1 + 1e-9) and c["tap_speed_mm_s"] <= 1500.0
            # one dip to the depth per tap
            dips = np.flatnonzero((r[1:-1] < r[:-2]) & (r[1:-1] <= r[2:]) & (r[1:-1] < 0))
            assert dips.size == int(c["taps"]), c
            # a tap: down and up at the tap speed, the dwell, then the pause above
            per = 2 * (above + d) / c["tap_speed_mm_s"] + c["tap_dwell_s"] + c["tap_pause_s"]
            assert np.all(np.abs(np.diff(dips) * DT - per) <= 2 * DT), c
        elif kind == "bumpy_slide":
            deepest = d + c["bump_mm"]
        elif kind == "plain_slide":
            deepest = max(d, d + c["drift_mm"])
        else:
            deepest = d
        if kind == "creep":
            assert d <= 1.5 and speed.max() <= c["creep_mm_s"] * (1 + 1e-9) <= 5.0 * (1 + 1e-9)
        elif kind in ("press_hold", "plain_slide"):
            assert speed.max() <= max(c["speed_in_mm_s"], c["speed_out_mm_s"]) * (1 + 1e-9), c
        assert -r.min() == pytest.approx(deepest, rel=1e-3), (kind, -r.min(), deepest)
        assert -r.min() <= deepest * (1 + 1e-9), c


def test_the_cells_are_drawn_over_the_whole_space_the_issue_names():
    """Issue 23, item 3: periods 0.25-10 ms, encoders 0.001-0.2 mm, arm mass 0.02-0.1 kg,
    damping declared at 0.5x-2x the true value, taps up to 1.5 m/s, finger mass,
    stiffness and damping over their ranges, every trajectory kind. Over 4000 cells each
    range is kept and reached to within 10 % at both ends (log-uniform draws: the chance
    that 4000 draws all miss the outer 10 % of a range is (1 - ln 1.1 / ln(hi/lo))^4000,
    1e-12 for the widest, the stiffness's six decades)."""
    cells = draw_cells(4000, 11)
    ranges = {"period_s": (0.25e-3, 10e-3), "resolution_mm": (0.001, 0.2), "arm_mass_kg": (0.02, 0.1),
              "stiffness_n_per_mm": (0.01, 1e4), "tap_speed_mm_s": (100.0, 1500.0),
              "finger_mass_kg": (0.003, 0.05), "finger_stiffness_n_per_m": (50.0, 2000.0),
              "finger_damping_ns_per_m": (0.1, 5.0)}
    for key, (lo, hi) in ranges.items():
        v = np.array([c[key] for c in cells])
        assert lo <= v.min() <= lo * 1.1 and hi / 1.1 <= v.max() <= hi, (key, v.min(), v.max())
    damped = [c for c in cells if c["damping_true_ns_per_m"] > 0]
    r = np.array([c["damping_declared_ns_per_m"] / c["damping_true_ns_per_m"] for c in damped])
    assert 0.5 <= r.min() <= 0.55 and 2.0 / 1.1 <= r.max() <= 2.0
    assert any(c["damping_true_ns_per_m"] == 0 for c in cells)
    assert {c["trajectory"] for c in cells} == {"press_hold", "tap", "bumpy_slide", "plain_slide", "creep"}
