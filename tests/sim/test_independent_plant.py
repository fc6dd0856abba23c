"""The stability benchmark's plant and energy integral (``run_cells``) against an independent
simulator (``tests/independent_plant.py``: its own exact zero-order-hold step, Gauss-Legendre
energy integrals, its own trajectories and figures; nothing of ``hapticsdk.sim`` imported),
both driving the same controller, cell by cell.

The tolerance is derived, not fitted (``independent_plant.energy_tolerance_j``): two exact
integrations of one linear model differ by rounding only, at most ``EPS`` = 2^-40 of each
tick's propagated sums, carried forward by at most the free plant's largest transition
power; the propagator's own error is measured here against an extended-precision
reference (``test_the_propagator_is_within_the_budget_s_share``). With the same forces
(the vectorised controller called as the benchmark calls it, on one lane) and the same
counts read (checked: every reading further than the carried error from a count's edge),
the delivered ratio, the largest step and the most negative force are the same numbers.

What it checks: the benchmark's plant model (arm, damping, finger, reference within a
tick, clamp), its encoder, and its energy to the user (motor work on the true positions,
the arm's kinetic energy, the arm damper's loss), the per-cell figures. What it does not:
a model both share (one axis, a rigid finger mass, a reference linear within each tick,
no friction or delay) or the controller itself (the same code on both sides).
"""

from __future__ import annotations

import numpy as np
import pytest

import independent_plant as ip
from hapticsdk.benchmarks.stability_random import draw_cells, run_cells

#: (seed, index into draw_cells(300, seed)): taps, presses, slides and creeps, with and
#: without arm damping, where the plain wall and the SDK lanes put energy into the hand
#: (so a wrong kinetic or damper term shows), 55-312 ticks each
CELLS = ((1, 293), (77, 228), (77, 219), (1, 243), (1, 57), (1, 81), (77, 29))
LANES = ("plain", "sdk_declared", "sdk")


@pytest.fixture(scope="module")
def compared():
    drawn = {s: draw_cells(300, s) for s in {s for s, _ in CELLS}}
    cells = run_cells([drawn[s][i] for s, i in CELLS], controllers=LANES)
    return [(c, lane, ip.run_cell(c, lane, controller="batch")) for c in cells for lane in LANES]


def test_energy_to_the_user_agrees_within_the_derived_bound(compared):
    for c, lane, mine in compared:
        bench = c["results"][lane]
        assert mine["count_margin_mm"] > 0.0, (c["trajectory"], lane)   # the derivation's premise
        # the independent simulator's two energy identities (device side, finger side) agree
        assert mine["energy_sides_gap_j"] <= mine["tolerance_j"]
        assert abs(bench["energy_to_user_j"] - mine["energy_to_user_j"]) <= mine["tolerance_j"], \
            (c["trajectory"], lane, bench["energy_to_user_j"], mine["energy_to_user_j"], mine["tolerance_j"])


def test_the_force_figures_are_the_same_numbers(compared):
    for c, lane, mine in compared:
        bench = c["results"][lane]
        for k in ("max_force_step_n", "min_contact_force_n", "contact_ticks"):
            assert bench[k] == mine[k], (c["trajectory"], lane, k)
        assert bench["delivered_ratio"] == mine["delivered_ratio"] or \
            (np.isnan(bench["delivered_ratio"]) and np.isnan(mine["delivered_ratio"]))


def test_the_cells_make_the_energy_terms_matter(compared):
    """Each term of the energy is far above the tolerance in some compared cell: a benchmark
    that dropped the kinetic energy or counted the damper twice would be caught."""
    tol = max(m["tolerance_j"] for _, _, m in compared)
    assert max(m["energy_to_user_j"] for _, _, m in compared) > 1e6 * tol
    damped = [c for c, _, _ in compared if c["damping_true_ns_per_m"] > 0]
    assert damped and max(c["results"]["plain"]["energy_to_user_j"] for c in damped) > 1e4 * tol


def _expm_extended(a: np.ndarray) -> np.ndarray:
    """exp(a) in extended precision (numpy longdouble): scaling and squaring of a Taylor
    series to 40 terms (the reference for scipy's expm's error)."""
    a = a.astype(np.longdouble)
    s = max(0, int(np.ceil(np.log2(max(float(np.abs(a).sum(axis=1).max()), 1e-30) / 0.25))))
    b = a / np.longdouble(2.0) ** s
    term = np.eye(a.shape[0], dtype=np.longdouble)
    out = term.copy()
    for k in range(1, 40):
        term = term @ b / k
        out = out + term
    for _ in range(s):
        out = out @ out
    return out


def test_the_propagator_is_within_the_budget_s_share():
    """The budget's EPS = 2^-40 per tick allows each of the two integrations 2^-41, the sum's
    rounding (5 u) included; scipy's expm of these systems is within 2^-46 of the
    extended-precision propagator, row scale by row scale, at every Gauss node and the tick's
    end (a 32-fold margin). Where longdouble is plain double the check is void."""
    if np.finfo(np.longdouble).eps >= np.finfo(float).eps:
        pytest.skip("no extended precision here")
    drawn = {s: draw_cells(300, s) for s in {s for s, _ in CELLS}}
    for s, i in CELLS:
        c = drawn[s][i]
        p = ip.CellPlant(c["period_s"], c["arm_mass_kg"], c["damping_true_ns_per_m"], c["finger_mass_kg"],
                         c["finger_stiffness_n_per_m"], c["finger_damping_ns_per_m"])
        M = c["arm_mass_kg"] + c["finger_mass_kg"]
        k, bh = c["finger_stiffness_n_per_m"], c["finger_damping_ns_per_m"]
        A = np.zeros((5, 5))
        A[0, 1] = 1.0
        A[1, :] = [-k / M, -(c["damping_true_ns_per_m"] + bh) / M, k / M, bh / M, 1.0 / M]
        A[2, 3] = 1.0
        T = c["period_s"]
        taus = 0.5 * T * (ip._GL_X + 1.0)
        for got, tau in [(p._E, T)] + [(p._N[2 * j:2 * j + 2], t) for j, t in enumerate(taus)]:
            ref = _expm_extended(A * tau)[:2]
            # error of each row's sum for any state, relative to that row's scale sum |P_ij z_j|
            rel = np.abs(got.astype(np.longdouble) - ref) / np.maximum(np.abs(ref), 1e-300)
            assert float(rel.max()) <= 2.0 ** -46, (s, i, tau)
