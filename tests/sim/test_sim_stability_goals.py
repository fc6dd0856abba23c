"""Issue 15 (b) on a fast subset of the stability matrix: with the passivity controller
on, a wall stiffer than the device renders passively is rendered as the stiffest spring
it can render, not withheld, and gives the finger no energy.

Goals and their tolerances are this file's (from the issue), not the benchmark's or the
controller's constants:

* energy given to the finger over the run <= 0.1 mJ;
* over the contact ticks, the applied force >= 90 % of min(K, K_pass) x penetration
  (each target capped at the arm's 3.3 N), K_pass = the stiffest wall the same cell keeps
  stable with the controller off (measured here with the benchmark's search);
* on every tick deeper than 1 mm, applied force >= min(0.5 N, 0.9 K x penetration) (the
  felt floor). The cells marked for it (all b = 0 cells here, including three at 4 ms
  that missed it before the entry boost, and the 4 ms cells with b = 0.25 / 0.5 that
  missed it before the felt floor) must actually go deeper than 1 mm, so the check cannot
  pass by not applying.

Each cell is a 3 s press/slide/tap run of the benchmark's simulation (exact ZOH arm,
0.055 mm encoder, 3.3 N saturation), and one 10 s run at 2 ms (the cell that needs the
pre-paid budget). Each mutation of the controller below must fail at least one goal in
at least one cell, so the goals can fail. At T = 4 ms with no device damping the felt
floor is paid for on the way in (the entry boost,
``test_entry_boost_pays_for_the_floor_at_4ms_without_damping``).
"""

import numpy as np
import pytest

from hapticsdk.benchmarks.stability import passive_stiffness, run_period
from hapticsdk.passivity import ControllerSettings

ENERGY_J = 1e-4          # 0.1 mJ
DELIVERED = 0.9          # of min(K, K_pass) x penetration
FELT_N = 0.5             # ... or 0.9 K x penetration, deeper than 1 mm
DURATION_S = 3.0

#: (period s, duration s) -> cells (K N/mm, b N*s/m, finger, felt floor must apply); all
#: far above or above 2b/T but one
CELLS = {
    (1e-3, DURATION_S): [(100.0, 0.5, "stiff", False), (10000.0, 0.5, "medium", False),
                         (2.3, 0.25, "medium", False), (10000.0, 0.25, "stiff", False),
                         # no device damping: the dampers took the force to -0.2 N on withdrawal
                         (10.0, 0.0, "medium", True), (0.1, 0.0, "stiff", True), (0.7, 0.0, "medium", True)],
    (4e-3, DURATION_S): [(100.0, 0.5, "medium", False), (10000.0, 0.5, "stiff", False),
                         # K_pass x 1 mm < 0.5 N here; the damper took the force to 0.02-0.37 N
                         (2.3, 0.25, "stiff", True), (10.0, 0.25, "medium", True), (0.7, 0.25, "medium", True),
                         (0.7, 0.5, "medium", True),
                         # no device damping: a tap moves 1-1.5 mm per tick; before the entry
                         # boost the floor yielded there (down to 0 N / 0.34 / 0.69 of the floor)
                         (10.0, 0.0, "medium", True), (10.0, 0.0, "stiff", True), (0.7, 0.0, "medium", True),
                         (0.1, 0.0, "stiff", True)],
    (0.25e-3, DURATION_S): [(10000.0, 0.25, "medium", False), (10000.0, 0.5, "soft", False)],
    # 10 s (five press/slide/tap cycles): without the pre-paid budget 0.41 N on withdrawal
    (2e-3, 10.0): [(0.7, 0.0, "medium", True)],
}

_KPASS: dict = {}


def _kpass(key):
    if key not in _KPASS:
        cl = CELLS[key]
        _KPASS[key] = passive_stiffness(key[0], [c[1] for c in cl], [c[2] for c in cl], key[1])
    return _KPASS[key]


def _run(key, settings, cells=None):
    T, dur = key
    cl = cells or CELLS[key]
    return run_period(T, np.array([c[0] for c in cl]), np.array([c[1] for c in cl]), [c[2] for c in cl],
                      np.ones(len(cl), bool), dur, settings=settings, k_pass=_kpass(key) if cells is None else None)


def _failures(key, settings):
    """Goals missed, one string per (cell, goal)."""
    cl = CELLS[key]
    r = _run(key, settings)
    out = []
    for i, c in enumerate(cl):
        name = f"T={key[0] * 1e3:g} ms K={c[0]:g} b={c[1]:g} {c[2]}"
        if not r["energy_to_user_j"][i] <= ENERGY_J:
            out.append(f"{name}: energy {r['energy_to_user_j'][i]:.3g} J")
        if not r["delivered_vs_passive_ratio"][i] >= DELIVERED:
            out.append(f"{name}: delivered {r['delivered_vs_passive_ratio'][i]:.3f} of min(K, K_pass) x pen")
        felt = r["felt_force_ratio_min"][i]
        if c[3] and felt != felt:
            out.append(f"{name}: never deeper than 1 mm (the felt floor was not checked)")
        if felt == felt and felt < 1.0:
            out.append(f"{name}: felt force ratio {felt:.2f}")
    return out


@pytest.mark.parametrize("key", sorted(CELLS))
def test_controller_renders_the_stiffest_passive_spring(key):
    kp = _kpass(key)
    # the cells are beyond what the device renders passively: K > K_pass > 0
    assert np.all(kp > 0) and all(c[0] > k for c, k in zip(CELLS[key], kp))
    assert _failures(key, None) == []


def test_felt_floor_on_every_deep_tick():
    """The felt floor checked here directly on the force trace, with this file's
    tolerance (not the benchmark's ``felt_force_ratio_min``): at 1 ms with b = 0 every
    tick whose reading is deeper than 1 mm gets >= min(0.5 N, 0.9 K pen), and there are
    withdrawal ticks among them (reading moving out)."""
    from hapticsdk.benchmarks.stability import matrix_trajectory
    from hapticsdk.passivity import controller_commit_batch, controller_state_batch, controller_step_batch
    from hapticsdk.sim.arm import ArmBatch, ArmParams
    from hapticsdk.sim.finger import FINGERS
    T, cells = 1e-3, [(10.0, "medium"), (0.7, "stiff"), (0.1, "stiff")]
    arms = [ArmParams(damping_ns_per_m=0.0)] * len(cells)
    n = int(round(DURATION_S / T))
    _, r = matrix_trajectory(DURATION_S).position(np.arange(n + 1) * T)
    bt = ArmBatch(T, arms, [FINGERS[c[1]] for c in cells], y0_mm=float(r[0]))
    st = controller_state_batch(len(cells))
    K = np.array([c[0] for c in cells])
    deep_ticks = np.zeros(len(cells), int)
    out_ticks = np.zeros(len(cells), int)
    y_prev = bt.measured_mm()
    for k in range(n):
        y = bt.measured_mm()
        pen = -y
        fw = np.where(pen > 0, K * pen, 0.0)
        f = bt.step(controller_step_batch(st, y, T, fw, np.ones(len(cells), bool), damping_ns_per_m=0.0,
                                          resolution_mm=bt.res_mm), r[k], (r[k + 1] - r[k]) / T)
        controller_commit_batch(st, f)
        deep = pen > 1.0
        need = np.minimum(FELT_N, 0.9 * K * pen)
        assert np.all(f[deep] >= need[deep] - 1e-12), (k, f, need, pen)
        deep_ticks += deep
        out_ticks += deep & (y > y_prev)
        y_prev = y
    assert np.all(deep_ticks > 100) and np.all(out_ticks > 10)


def test_entry_boost_pays_for_the_floor_at_4ms_without_damping():
    """T = 4 ms, b = 0: a tap leaves the wall at 1-1.5 mm per tick, so a 0.5 N floor held
    through the tick it leaves hands the finger 0.5-0.75 mJ, 5-7 x the energy goal. With
    the entry boost (the damper pays that on the way in, beyond its 5 N*s/m bound and the
    0.8 N slew limit) the floor holds and the finger gets no energy; without the boost
    the floor either yields (felt goal missed) or, held regardless, hands the finger more
    than the energy goal."""
    key = (4e-3, DURATION_S)
    cells = [(10.0, 0.0, "medium", True), (10.0, 0.0, "stiff", True)]
    r = _run(key, None, cells)
    assert np.all(r["energy_to_user_j"] <= ENERGY_J)
    assert np.all(r["felt_force_ratio_min"] >= 1.0)
    before = dict(entry_force_limit_n=None, felt_uses_reserve=False, prepay_budget_j=1e-3)
    r = _run(key, ControllerSettings(**before), cells)
    assert np.all(r["energy_to_user_j"] <= ENERGY_J) and np.any(r["felt_force_ratio_min"] < 1.0)
    r = _run(key, ControllerSettings(felt_tick_energy_j=np.inf, **before), cells)
    assert np.any(r["energy_to_user_j"] > ENERGY_J)


def test_scalar_controller_equals_batch_through_the_entry_boost():
    """The scalar and the batch controller give the same force on every tick of fast taps
    at 4 ms without device damping (where the entry boost acts: the boost changes the
    output, so this comparison goes through it)."""
    from hapticsdk.passivity import (PassivityController, controller_commit_batch, controller_state_batch,
                                     controller_step_batch)
    t = np.arange(1500)
    rng = np.random.default_rng(1)
    x = np.round((2.0 - 6.0 * np.abs(np.sin(t * 2 * np.pi / 16.0)) + rng.normal(0, 0.1, t.size)) / 0.055) * 0.055
    fw = np.maximum(-x, 0.0) * 10.0

    def run(s):
        pc, st, outs = PassivityController(s), controller_state_batch(1), []
        for k in range(x.size):
            a = pc.step(float(x[k]), 4e-3, float(fw[k]))
            b = controller_step_batch(st, x[k:k + 1], 4e-3, fw[k:k + 1], np.array([True]), s)[0]
            assert a == pytest.approx(b, rel=1e-12, abs=1e-12), k
            fa = float(np.clip(a, -3.3, 3.3))
            pc.commit(fa)
            controller_commit_batch(st, np.array([fa]))
            outs.append(a)
        assert pc.reserve_j == pytest.approx(st["reserve"][0], rel=1e-9, abs=1e-15)
        return np.array(outs)

    kw = dict(device_damping_ns_per_m=0.0, position_resolution_mm=0.055)
    with_boost = run(ControllerSettings(**kw))
    without = run(ControllerSettings(entry_force_limit_n=None, **kw))
    assert np.any(np.abs(with_boost - without) > 0.1)


def test_kpass_is_the_stability_boundary_without_the_controller():
    """The reference the transparency goal uses: at 1 ms the same cells are stable with the
    controller off at K_pass and unstable (energy or residual force) at 1.5 x K_pass."""
    from hapticsdk.benchmarks.stability import _is_stable
    T = 1e-3
    key = (T, DURATION_S)
    cl = [c for c in CELLS[key] if c[1] > 0]
    kp = _kpass(key)[[i for i, c in enumerate(CELLS[key]) if c[1] > 0]]
    K = np.concatenate([kp, 1.5 * kp])
    b = np.array([c[1] for c in cl] * 2)
    fg = [c[2] for c in cl] * 2
    r = run_period(T, K, b, fg, np.zeros(K.size, bool), DURATION_S)
    ok = _is_stable(r)
    n = len(cl)
    assert ok[:n].all() and not ok[n:].any()


#: mutations of the controller, each of which must miss a goal in the cells of its period
_1MS, _4MS, _025MS, _2MS10 = (1e-3, DURATION_S), (4e-3, DURATION_S), (0.25e-3, DURATION_S), (2e-3, 10.0)
MUTATIONS = {
    # the controller before the stiffness cap: no cap, 1 mJ bound tolerance
    # (withholds walls far above 2b/T, hands the finger up to 0.4 mJ)
    "controller before the cap": (ControllerSettings(stiffness_cap=False, bound_tolerance_j=1e-3), _1MS),
    # no stiffness cap: a 10 kN/mm wall is a relay that the energy bound withholds
    "no stiffness cap": (ControllerSettings(stiffness_cap=False), _1MS),
    # cap at Colgate's 2b/T only (no use of the damper's margin): walls rendered too soft
    "cap at 2b/T": (ControllerSettings(cap_colgate_multiple=1.0, cap_damping_share=0.0), _1MS),
    # the energy bound's tolerance back at 1 mJ: energy reaches the finger
    "bound tolerance 1 mJ": (ControllerSettings(bound_tolerance_j=1e-3), _1MS),
    # no per-count limit of the cap: at 0.25 ms a count is worth 0.8 N and the
    # quantised wall feeds the finger
    "no count limit": (ControllerSettings(cap_count_force_n=None), _025MS),
    # the controller before the felt floor (no floor, no pre-payment): with b = 0 the
    # dampers take the force to -0.13 N on withdrawal
    "controller before the felt floor": (ControllerSettings(felt_floor_fraction=None, prepay_factor=0.0), _1MS),
    # no felt floor (pre-payment kept): at 4 ms, b = 0.25 the force drops to 0.37 N
    "no felt floor": (ControllerSettings(felt_floor_fraction=None), _4MS),
    # floor at half the wall's force: a soft wall (0.1 N/mm) gets 0.56 of 0.9 K pen
    "floor at half the wall": (ControllerSettings(felt_floor_fraction=0.5), _1MS),
    # floor not capped at 0.6 N (95 % of a stiff wall): the damper cannot work and the
    # finger gets 2 mJ (4 ms, b = 0.25)
    "floor without its cap": (ControllerSettings(felt_force_n=None), _4MS),
    # affordability without the device damping's share (on the controller before the
    # entry boost, which otherwise pays for those withdrawals too): at 4 ms, b = 0.25
    # the floor yields on fast withdrawals it could afford (0.38 N)
    "floor gate without damping": (ControllerSettings(felt_damping_multiple=0.0, entry_force_limit_n=None,
                                                      felt_uses_reserve=False, prepay_budget_j=1e-3), _4MS),
    # no pre-paid budget: the 10 s, 2 ms, b = 0 cell gets 0.41 N on a withdrawal
    "no pre-payment": (ControllerSettings(prepay_factor=0.0), _2MS10),
    # the controller before the entry boost (damper held to 5 N*s/m and 0.8 N per tick,
    # floor gate without the reserve, 1 mJ reserve): at 4 ms, b = 0 the floor yields (0 N)
    "controller before the entry boost": (ControllerSettings(entry_force_limit_n=None, felt_uses_reserve=False,
                                                             prepay_budget_j=1e-3), _4MS),
    # no entry boost, the gate still counting the reserve: the reserve is booked but not
    # paid and the floor hands the finger 0.25-0.31 mJ
    "no entry boost": (ControllerSettings(entry_force_limit_n=None), _4MS),
    # the floor's gate without the reserve: at 4 ms, b = 0 it yields on a withdrawal (0.79)
    "floor gate without the reserve": (ControllerSettings(felt_uses_reserve=False), _4MS),
    # a 1 mJ reserve: the withdrawal outruns it (0.9 of the floor at 4 ms, b = 0)
    "reserve of 1 mJ": (ControllerSettings(prepay_budget_j=1e-3), _4MS),
    # the boost held to the ordinary slew limit: it cannot pay what it books (0.45 mJ)
    "entry boost at the slew limit": (ControllerSettings(entry_force_step_n=0.8), _4MS),
}


@pytest.mark.parametrize("name", sorted(MUTATIONS))
def test_each_mutation_misses_a_goal(name):
    s, key = MUTATIONS[name]
    assert _failures(key, s), f"mutation {name!r} met every goal"
