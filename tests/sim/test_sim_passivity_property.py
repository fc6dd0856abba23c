"""Property-based tests of the passivity controller (issue 23): the energy bound is the
property.

Hypothesis draws whole batches of cells (trajectory, finger, period, encoder, arm mass and
the mass declared at 0.5x-2x of it, true damping and the damping declared at 0.5x-2x of
it, wall stiffness) from the region
the controller's guarantee is stated for in docs/runtime.md, runs them through the exact
zero-order-hold plant (:mod:`hapticsdk.sim.plant`, energy from the raw state, not from the
controller) and checks, per cell:

* energy given to the finger <= ``E0 + ENERGY_SLACK_J``, where ``E0 = min(F_max Delta / 2, 0.1 mJ)`` is the
  controller's own starting allowance (computed here from the cell's declared parameters,
  not read from the controller), and ``ENERGY_SLACK_J`` = 0.1 mJ is the issue's goal: the
  room left for motion the one-tick prediction does not foresee;
* the controller's own bound ``U`` is an upper bound of the true energy on every tick
  (up to the reading's error times the held force, the bound's open tail): a bound with
  its sign flipped, or booking the wrong pairing, fails here even where it withholds;
* the wall never pulls: no negative force on a contact tick;
* no force step beyond the ramp's own ``s = F_max T / 5 ms`` plus the Colgate spring's
  change ``K_c |dq|`` (``K_c = 2 b_lo / T``; measured by the benchmark as
  ``max_step_beyond_spring_n``).

The draws are derandomised (``derandomize=True``) so CI sees the same examples every run,
and hypothesis keeps no example database (nothing is written).
"""

import numpy as np
import pytest

hyp = pytest.importorskip("hypothesis", reason="hypothesis (the test extra) is not installed")
from hypothesis import given, settings, strategies as st  # noqa: E402

from hapticsdk.benchmarks.stability_random import KINDS, SDK_LANES, run_cells  # noqa: E402

ENERGY_SLACK_J = 1e-4
#: the most energy a contact may hand the user, the SDK's specification (0.1 mJ, the
#: issue's goal; ControllerSettings.energy_allowance_j by default): E0 is capped by it
ALLOWANCE_J = 1e-4
RAMP_S = 5e-3
F_MAX = 3.3
#: the region of the stated guarantee (docs/runtime.md, "Where the bound holds (measured)")
PERIOD_S = (0.25e-3, 2.5e-3)
RESOLUTION_MM = (0.001, 0.2)


def _lu(lo, hi):
    return st.floats(np.log(lo), np.log(hi)).map(np.exp)


@st.composite
def cell(draw):
    b = draw(st.one_of(st.just(0.0), _lu(0.05, 1.0)))
    m = draw(_lu(0.02, 0.1))
    return {
        "trajectory": draw(st.sampled_from(KINDS[:5])),
        "stiffness_n_per_mm": draw(_lu(0.01, 1e4)), "period_s": draw(_lu(*PERIOD_S)),
        "resolution_mm": draw(_lu(*RESOLUTION_MM)), "arm_mass_kg": m,
        "damping_true_ns_per_m": b, "damping_declared_ns_per_m": b * draw(_lu(0.5, 2.0)),
        "finger_mass_kg": draw(_lu(0.003, 0.05)), "finger_stiffness_n_per_m": draw(_lu(50.0, 2000.0)),
        "finger_damping_ns_per_m": draw(_lu(0.1, 5.0)), "depth_mm": draw(st.floats(0.5, 4.0)),
        "speed_in_mm_s": draw(_lu(5.0, 200.0)), "speed_out_mm_s": draw(_lu(5.0, 200.0)),
        "hold_s": draw(st.floats(0.1, 0.4)), "tap_speed_mm_s": draw(_lu(100.0, 1500.0)),
        "taps": float(draw(st.integers(1, 3))), "tap_dwell_s": draw(st.floats(0.0, 0.02)),
        "tap_pause_s": draw(st.floats(0.05, 0.1)), "bump_mm": draw(st.floats(0.3, 1.0)),
        "bump_hz": draw(st.floats(5.0, 40.0)), "drift_mm": draw(st.floats(-1.0, 1.0)),
        "creep_mm_s": draw(st.floats(3.0, 5.0)),
    } | {"arm_mass_declared_kg": m * draw(_lu(0.5, 2.0))}


def _bound(c):
    s = F_MAX * min(c["period_s"] / RAMP_S, 1.0)
    return min(F_MAX * 0.5 * c["resolution_mm"] * 1e-3, ALLOWANCE_J) + ENERGY_SLACK_J, s


@settings(max_examples=3, deadline=None, derandomize=True, database=None)
@given(st.lists(cell(), min_size=10, max_size=10))
def test_energy_to_the_finger_stays_within_the_bound(cells):
    # both lanes: the damping measured hands off on the cell's arm, and the declared share
    for c, lane in ((c, lane) for c in run_cells(cells, controllers=SDK_LANES) for lane in SDK_LANES):
        r = c["results"][lane]
        bound, step = _bound(c)
        assert r["energy_to_user_j"] <= bound, (c, r)
        # the controller's own bound is an upper bound of the true energy on every tick
        # (1 nJ: float rounding of sums over up to 10^4 ticks of millijoules)
        assert r["bound_shortfall_j"] <= 1e-9, (c, r)
        assert r["min_contact_force_n"] >= 0.0, (c, r)
        assert r["max_step_beyond_spring_n"] <= step * (1 + 1e-9), (c, r)

