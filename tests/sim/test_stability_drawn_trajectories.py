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
