"""Issue 23 on a fast subset: the fixed grid's trajectory (press/slide/tap) and a few
drawn cells, the SDK controller beside its textbook peers on the same plant.

Goals (this file's reasoning, not the controller's constants):

* the controller's bound is sound: ``true energy <= U + (Delta/2)|F|`` on every tick
  (``bound_shortfall_j <= 0``, 1 nJ for float sums);
* no pull (normal force >= 0 on contact ticks) and no force step beyond the ramp's own
  ``F_max T / 5 ms`` plus the Colgate spring's change ``K_c |dq|``;
* the harness can fail: the plain wall gives the finger energy in the Colgate-active
  cells, and the textbook PO/PC pulls (its damper reverses the force) somewhere.
"""

import numpy as np
import pytest

from hapticsdk.benchmarks.stability import QUICK_GRID, matrix_trajectory
from hapticsdk.benchmarks.stability_random import draw_cells, grid_cells, run_cells, summarise
from hapticsdk.passivity import ControllerSettings

GRID = dict(QUICK_GRID, duration_s=3.0)


@pytest.fixture(scope="module")
def grid():
    return run_cells(grid_cells(GRID), knots=matrix_trajectory(3.0))


def _check_sdk(cells):
    for c in cells:
        r = c["results"]["sdk"]
        assert r["bound_shortfall_j"] <= 1e-9, c
        assert r["min_contact_force_n"] >= 0.0, c
        # beyond the ramp plus the spring only on ticks where the book was overdrawn and the
        # extra fell below its ramp for the energy bound (docs/runtime.md, Passivity item 3)
        assert r["max_step_beyond_spring_where_ramp_kept_n"] <= r["ramp_step_n"] * (1 + 1e-9), c
        if r["max_step_beyond_spring_n"] > r["ramp_step_n"] * (1 + 1e-9):
            assert r["below_ramp_ticks"] > 0, c


def test_grid_cells_keep_the_bound_no_pull_and_the_ramp(grid):
    _check_sdk(grid)
    # the subset reaches the wall in every cell
    assert all(c["results"]["sdk"]["contact_ticks"] > 0 for c in grid)


def test_harness_sees_active_walls_and_pulling_peers(grid):
    plain = [c["results"]["plain"]["energy_to_user_j"] for c in grid
             if c["stiffness_n_per_mm"] * 1e3 * c["period_s"] / 2 > 2 * c["damping_true_ns_per_m"]]
    assert max(plain) > 1e-3          # far above the 0.1 mJ goal
    assert min(c["results"]["popc"]["min_contact_force_n"] for c in grid) < 0.0


def test_drawn_cells_keep_the_bound_no_pull_and_the_ramp():
    cells = run_cells(draw_cells(12, seed=7))
    _check_sdk(cells)
    s = summarise(cells)
    assert s["sdk_no_pull"] == s["sdk_step_within_ramp_plus_spring_where_ramp_kept"] == 12
    assert set(s["controllers"]) == {"plain", "popc", "eb", "vc", "sdk", "sdk_declared", "eb_measured", "vc_measured"}
    assert s["peers_on_trusted_damping"]["peers"] == ["popc", "eb_measured", "vc_measured"]
    assert np.isfinite(s["controllers"]["sdk"]["median_delivered_ratio"])


def test_random_cells_are_reproducible_and_span_the_space():
    a, b = draw_cells(300, seed=1), draw_cells(300, seed=1)
    assert a == b and draw_cells(5, seed=2) != a[:5]
    T = np.array([c["period_s"] for c in a])
    res = np.array([c["resolution_mm"] for c in a])
    ratio = np.array([c["damping_declared_ns_per_m"] / c["damping_true_ns_per_m"] for c in a
                      if c["damping_true_ns_per_m"] > 0])
    assert T.min() < 0.4e-3 and T.max() > 8e-3
    assert res.min() < 0.003 and res.max() > 0.15
    assert ratio.min() < 0.6 and ratio.max() > 1.7
    assert {c["trajectory"] for c in a} == {"press_hold", "tap", "bumpy_slide", "plain_slide", "creep"}


def test_a_tap_reversing_over_many_short_ticks_is_foreseen(seed1_sdk):
    """Drawn cell 1308 of seed 1: a 1.4 m/s tap on a 0.6 N/mm wall at T = 0.46 ms, no
    damping, a 0.034 mm encoder. The hand's reversal takes ~17 ticks; per tick its second
    difference (0.06 mm) is below the two counts quantisation alone can make, so only a
    longer span sees it. Without it the held force met the outward motion: 1.35 mJ."""
    cell = draw_cells(2000, seed=1)[1308]
    assert cell["trajectory"] == "tap" and cell["damping_declared_ns_per_m"] == 0.0
    r = seed1_sdk[1308]["results"]["sdk"]
    assert r["energy_to_user_j"] <= 1e-4
    assert r["contact_ticks"] > 0


def _sdk_energy(runs, idx):
    return [runs[i]["results"]["sdk"]["energy_to_user_j"] for i in idx]


def test_a_hand_that_reversed_recently_is_expected_to_reverse_again(seed1_sdk):
    """The plan takes the largest change of motion over the reading ring's window, not
    this tick's alone: a hand that reversed within the window can reverse again, and
    between reversals a hand at a steady speed shows no change of motion.

    * Drawn cell 1694 of seed 1 (a 160 mm/s tap at T = 8.9 ms on a 0.06 mm encoder, no
      damping, a 20 g arm lighter than the declared 29 g) is what catches the window's
      removal today: 0.090 mJ with it, 0.128 mJ with this tick's estimate alone.
    * Drawn cells 259 and 1907 (taps at T = 7.8 and 4.9 ms, no damping, fine encoders)
      are the cells that found the defect (3.7 and 3.4 mJ then); the terms added since
      (the free arm's change of motion, the third difference) also cover them, so they
      stay as regression cells and no longer tell the window's removal apart."""
    cells = draw_cells(2000, seed=1)
    assert [cells[i]["trajectory"] for i in (259, 1694, 1907)] == ["tap"] * 3
    assert all(cells[i]["damping_true_ns_per_m"] == 0.0 and cells[i]["period_s"] > 4e-3 for i in (259, 1694, 1907))
    assert max(_sdk_energy(seed1_sdk, (259, 1694, 1907))) <= 1e-4


def test_a_change_of_the_change_of_motion_is_foreseen(seed1_sdk):
    """Extrapolating the reading with its velocity and acceleration misses the next tick's
    motion by the third difference (exactly, for a cubic motion); the plan adds the
    largest third difference over the window. Taps at long periods with no damping, where
    the finger and the arm ring at a few ticks per cycle, show it:

    * drawn cell 1176 of seed 2 (a 428 mm/s tap at T = 7.4 ms, 13.5 N/mm, a 0.002 mm
      encoder): 0 mJ with the term, 0.225 mJ without; drawn cell 1694 of seed 1 (above):
      0.090 and 0.147 mJ;
    * drawn cells 468, 1191 and 1919 of seed 1 (taps at T = 7.2, 4.8 and 9.0 ms) found
      the defect (0.16, 0.11 and 0.47 mJ then); other terms now cover them too, so they
      stay as regression cells."""
    cells = draw_cells(2000, seed=1)
    idx = (468, 1191, 1694, 1919)
    assert [cells[i]["trajectory"] for i in idx] == ["tap"] * 4
    assert all(cells[i]["period_s"] > 4e-3 and cells[i]["damping_true_ns_per_m"] < 0.1 for i in idx)
    assert max(_sdk_energy(seed1_sdk, idx)) <= 1e-4
    cell = draw_cells(2000, seed=2)[1176]
    assert cell["trajectory"] == "tap" and cell["damping_true_ns_per_m"] == 0.0 and cell["period_s"] > 7e-3
    r = run_cells([cell], controllers=("sdk",))[0]["results"]["sdk"]
    assert r["contact_ticks"] > 0 and r["energy_to_user_j"] <= 1e-4, r


def test_the_held_force_s_push_on_the_free_arm_is_foreseen_under_quantisation(seed1_sdk):
    """Drawn cells 516, 990 and 1137 of seed 1: presses and a bumpy slide at T = 9.3, 3.1
    and 2.9 ms with 0.06-0.08 mm encoders. At the first ticks of contact a new force
    (about 1 N on a 24-71 g arm) changes the arm's motion by up to ``dF T^2 / m`` per tick,
    while the readings' second difference shows it only within its 2-count quantisation,
    so the change the readings surely show is 0. The plan takes the largest change the
    readings allow, up to the free arm's under the force's change over the last two
    ticks; without it they gave 0.11, 0.27 and 0.14 mJ."""
    cells = draw_cells(2000, seed=1)
    idx = (516, 990, 1137)
    assert [cells[i]["trajectory"] for i in idx] == ["press_hold", "press_hold", "bumpy_slide"]
    assert all(cells[i]["period_s"] > 2.5e-3 and 0.05 < cells[i]["resolution_mm"] < 0.1 for i in idx)
    assert max(_sdk_energy(seed1_sdk, idx)) <= 1e-4


def test_a_coarse_encoder_s_allowance_is_capped_by_the_energy_a_contact_may_give(seed1_sdk):
    """Drawn cells 122 and 580 of seed 1: creeps with 0.18 mm encoders, where
    ``F_max Delta / 2`` is 0.3 mJ. The allowance is capped at ``energy_allowance_j``
    (0.1 mJ); uncapped they gave 0.21 and 0.24 mJ. A lower allowance lowers the energy."""
    cells = draw_cells(2000, seed=1)
    assert all(cells[i]["resolution_mm"] > 0.15 for i in (122, 580))
    e = _sdk_energy(seed1_sdk, (122, 580))
    assert max(e) <= 1e-4
    strict = [c["results"]["sdk"]["energy_to_user_j"] for c in run_cells(
        [seed1_sdk[i] for i in (122, 580)], controllers=("sdk",), settings=ControllerSettings(energy_allowance_j=2e-5))]
    assert all(b < a for a, b in zip(e, strict)), (e, strict)


def test_with_a_measured_damping_the_spring_keeps_half_of_it_for_the_encoder(seed1_sdk):
    """Seed 1 (2000 cells), cell 1935: a creep on a 0.18 mm encoder, 1 ms, true damping
    0.57 N*s/m, measured hands off to a bound of 0.46. A spring at Colgate's limit of that
    bound (2 b_lo / T) leaves the arm's damping little for the count crossings: arm and
    finger settle into a 50 Hz cycle across one count that gains energy on every cycle
    (0.134 mJ over the run). At half Colgate's limit of the fitted damping a crossing
    gains about the spring's energy over one count (docs/runtime.md, Passivity item 0)
    and the run stays within 0.1 mJ."""
    cell = draw_cells(2000, seed=1)[1935]
    assert cell["trajectory"] == "creep" and cell["resolution_mm"] > 0.15
    c = seed1_sdk[1935]
    assert c["damping_calibration"]["trusted_damping_ns_per_m"] <= cell["damping_true_ns_per_m"]
    assert c["results"]["sdk"]["energy_to_user_j"] <= 1e-4, c["results"]["sdk"]


def test_a_batch_gives_each_cell_what_it_gets_alone(seed1_sdk):
    """The shared batch (tests/sim/conftest.py) stands in for a run of each cell alone in
    the tests above: one of its cells (108, its shortest run) run alone gives the same
    floats, to the last bit (compared as JSON, which writes a float's shortest repr)."""
    import json
    alone = run_cells([draw_cells(2000, seed=1)[108]], controllers=("sdk",))[0]
    assert json.dumps(alone, sort_keys=True) == json.dumps(seed1_sdk[108], sort_keys=True)
