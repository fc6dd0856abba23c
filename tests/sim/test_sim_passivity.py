"""Passivity: the Colgate margin against an eigenvalue computation (goal 1), the harness
detects an active wall (goal 3), the ZOH-paired observer and the controller (goal 4),
delay accounting (goal 5), no hidden passivity claim at GS_max (goal 6)."""

import itertools

import numpy as np
import pytest

from hapticsdk.passivity import (PASSIVE, STABLE_BY_ASSUMPTION, ControllerSettings, PassivityController,
                                 classify_wall, controller_commit_batch, controller_state_batch,
                                 controller_step_batch, critical_stiffness, critical_stiffness_eig,
                                 naive_observer_energy, passivity_margin, spectral_radius,
                                 zoh_observer_energy)
from hapticsdk.sim.arm import ArmBatch, ArmParams, quantise
from hapticsdk.sim.finger import FingerParams, Trajectory


def test_margin_formula():
    # b - (K T (1/2 + d) + |B|), K in N/mm
    assert passivity_margin(2.3, 0.0, 0.5, 1e-3, 0) == pytest.approx(0.5 - 1.15)
    assert passivity_margin(1.0, -0.2, 2.0, 2e-3, 1) == pytest.approx(2.0 - (1000 * 2e-3 * 1.5 + 0.2))
    assert critical_stiffness(0.5, 1e-3) == pytest.approx(1.0)
    arr = passivity_margin(np.array([0.1, 1.0]), 0.0, 0.5, 1e-3)
    assert arr.shape == (2,)


@pytest.mark.parametrize("m, b, T, d", list(itertools.product((0.045, 0.2), (0.2, 0.5, 1.15, 2.0),
                                                              (0.5e-3, 1e-3, 2e-3), (0, 1, 2))))
def test_margin_predicts_eigenvalue_stability_limit(m, b, T, d):
    """Goal 1: K_crit within 2 % of the ZOH eigenvalue limit in all 72 cells with the
    device's apparent mass given (measured worst 0.004 %).

    The plain formula (no mass: b - K T (1/2 + d) - |B|, the goal's expression) is the
    first-order term in delta = b*T/m of the exact limit: 69 of the 72 cells within 2 %;
    for the light arm (m = 0.045 kg) at T = 2 ms with b >= 1.15 N*s/m and d >= 1
    (delta >= 0.05) it is 2.1-3.5 % low (conservative side). Those three cells are held to
    4 % and listed in docs/runtime.md."""
    k_eig = critical_stiffness_eig(m, b, T, d)
    k_mass = critical_stiffness(b, T, d, mass_kg=m)
    assert k_mass == pytest.approx(k_eig, rel=0.02)
    k_pred = critical_stiffness(b, T, d)
    heavy_damping = b * T / m >= 0.05 and d >= 1
    assert k_pred == pytest.approx(k_eig, rel=0.04 if heavy_damping else 0.02)
    assert k_pred <= k_mass * (1 + 1e-12) and k_pred <= k_eig * 1.02  # never optimistic
    # and the eigenvalue check really separates the two sides
    assert spectral_radius(0.9 * k_eig, m, b, T, d) < 1.0 < spectral_radius(1.1 * k_eig, m, b, T, d)


def test_eigenvalue_limit_matches_time_domain_simulation():
    """The eigenvalue model (exact ZOH, d whole ticks of lag on the sampled position) is
    what the simulated arm does: worst goal-1 cell (m = 0.045 kg, b = 2, T = 2 ms, d = 2),
    linear spring, free decay from 1 mm: 0.98 x K_eig decays, 1.02 x K_eig grows, and
    the margin's (3.5 % lower) K_crit decays."""
    m, b, T, d = 0.045, 2.0, 2e-3, 2
    ke = critical_stiffness_eig(m, b, T, d)
    K = np.array([critical_stiffness(b, T, d), 0.98 * ke, 1.02 * ke])
    arm = ArmParams(mass_kg=m, damping_ns_per_m=b, encoder_resolution_mm=0.0)
    bt = ArmBatch(T, [arm] * 3, [FingerParams(0.0, 0.0, 0.0)] * 3, y0_mm=-1.0)
    hist = [bt.measured_mm()] * (d + 1)
    for _ in range(5000):
        hist.append(bt.measured_mm())
        bt.step(-K * hist[-1 - d], np.zeros(3), np.zeros(3))
    late = []
    for _ in range(200):
        hist.append(bt.measured_mm())
        bt.step(-K * hist[-1 - d], np.zeros(3), np.zeros(3))
        late.append(np.abs(bt.y) * 1e3)
    amp = np.max(late, axis=0)
    assert amp[0] < 0.1 and amp[1] < 1.0 < amp[2]


def test_delay_of_one_tick_divides_passive_stiffness_by_three():
    """Goal 5: with d = 1 the stable K drops to 1/3 (+-2 %)."""
    for m, b, T in ((0.045, 0.5, 1e-3), (0.2, 1.15, 2e-3)):
        ratio = critical_stiffness_eig(m, b, T, 1) / critical_stiffness_eig(m, b, T, 0)
        assert ratio == pytest.approx(1 / 3, rel=0.02)


def test_no_hidden_passivity_claim_at_gs_max():
    """Goal 6: 2.3 N/mm at 1 kHz with b below 1.15 N*s/m is not labelled passive."""
    from hapticsdk_hardness.omni import OmniVirtual
    dev = OmniVirtual()
    rep = dev.passivity()
    assert rep["stiffness_n_per_mm"] == 2.3 and rep["device_damping_ns_per_m"] < 1.15
    assert rep["label"] == STABLE_BY_ASSUMPTION and rep["margin_ns_per_m"] < 0
    assert OmniVirtual(damping_ns_per_m=1.3).passivity()["label"] == PASSIVE
    # CHAI3D's 0.7 N/mm is passive with the default damping; both figures are carried with sources
    assert dev.passivity(0.7)["label"] == PASSIVE
    d = dev.describe()
    assert "CHAI3D" in d["sources"]["rated_stable_stiffness_n_per_mm"]
    assert "paper" in d["sources"]["max_stiffness_n_per_mm"]
    assert classify_wall(0.99, 0.5, 1e-3)["label"] == PASSIVE


def _press_cells(K, on, *, b=0.5, T=1e-3, res=0.0, dur=3.0, settings=None):
    """Device m=0.05 kg pulled 3 mm into a wall by a 200 N/m, 0.2 N*s/m hand (the reference's
    V-sim setting), one cell per entry of ``on`` (run together). Returns per cell
    (energy-to-user max, x at each tick (mm), applied forces)."""
    on = np.asarray(on, bool)
    c = on.size
    arm = ArmParams(mass_kg=0.05, damping_ns_per_m=b, encoder_resolution_mm=res)
    tr = Trajectory([(0, 0, 1.0), (0.5, 0, -3.0), (dur, 0, -3.0)])
    n = int(round(dur / T))
    _, r = tr.position(np.arange(n + 1) * T)
    bt = ArmBatch(T, [arm] * c, [FingerParams(0.0, 200.0, 0.2)] * c, y0_mm=1.0, track_energy=True)
    st = controller_state_batch(c)
    xs, fs = np.empty((n, c)), np.empty((n, c))
    e = np.full(c, -np.inf)
    for k in range(n):
        y = bt.measured_mm()
        fw = np.where(-y > 0, K * -y, 0.0)
        f = controller_step_batch(st, y, T, fw, on, settings, damping_ns_per_m=b, resolution_mm=res)
        xs[k] = bt.y * 1e3
        f = bt.step(f, np.full(c, r[k]), np.full(c, (r[k + 1] - r[k]) / T))
        controller_commit_batch(st, f)
        fs[k] = f
        np.maximum(e, bt.energy_to_user_j(), out=e)
    return [(e[i], xs[:, i], fs[:, i]) for i in range(c)]


def _press(K, *, on, **kw):
    return _press_cells(K, [on], **kw)[0]


def test_harness_detects_an_active_wall():
    """Goal 3: K = 1.5 * 2b/T without controller gives energy to the hand; 0.5 * 2b/T does not."""
    e_active, _, _ = _press(1.5, on=False)
    e_passive, _, _ = _press(0.5, on=False)
    assert e_active > 1e-5
    assert e_passive < 1e-9


def test_zoh_paired_observer_fires_where_naive_one_does_not():
    """Goal 4 (unit): on an active ZOH spring the ZOH-paired PO goes negative, f(n)v(n) never."""
    _, x, f = _press(1.5, on=False)
    assert zoh_observer_energy(x, f).min() < -1e-4
    assert naive_observer_energy(x, f, 1e-3).min() >= 0.0


@pytest.mark.parametrize("K", [1.5, 2.3])
def test_controller_keeps_wall_passive_without_spikes(K):
    """Goal 4: PO/PC on, K = 1.5 and 2.3 x 2b/T, quantised encoder: min W_d >= -1e-6 J,
    |F| <= 3.3 N every tick, |dF| <= 1 N per tick, position settles (std < 0.05 mm)."""
    e_off, x_off, _ = _press(K, on=False, res=0.055)
    e_on, x, f = _press(K, on=True, res=0.055)
    assert e_off > 1e-4  # active without the controller (the test can fail)
    assert e_on <= 1e-6
    assert np.abs(f).max() <= 3.3 + 1e-12
    assert np.abs(np.diff(f)).max() <= 1.0
    assert x[-500:].std() < 0.05
    assert x_off[-500:].std() > x[-500:].std()
    # transparency: the wall is rendered, not withheld (mean force = spring law at the mean depth)
    assert f[-500:].mean() == pytest.approx(K * -x[-500:].mean(), rel=0.05)


@pytest.mark.parametrize("K", [3.0, 3.5, 4.0])
def test_controller_has_no_force_spikes_up_to_four_times_critical_stiffness(K):
    """Goal 4 spike criterion at K = 3 ... 4 x 2b/T (quantised encoder): |dF| <= 1 N per
    tick and |F| <= 3.3 N on every tick, energy to the hand <= 1e-6 J (goal 4's W_d bound).
    The controller before the predictive ramp cut the force in one tick here (|dF| up
    to 3.2-3.25 N), so this test fails on that behaviour. (The tolerances are the
    goal's; the energy bound was the controller's own 1 mJ tolerance before issue 15.)"""
    e_off, _, _ = _press(K, on=False, res=0.055)
    e_on, x, f = _press(K, on=True, res=0.055)
    assert e_off > 1e-3
    assert e_on <= 1e-6
    assert np.abs(f).max() <= 3.3 + 1e-12
    assert np.abs(np.diff(f)).max() <= 1.0


#: the controller before the generation observer and the half-count play (energy
#: observer, bounded damper and energy bound only; no stiffness cap, 1 mJ bound tolerance)
OLD = {"generation_observer": False, "count_play_ratio": 0.0, "stiffness_cap": False, "bound_tolerance_j": 1e-3,
       "felt_floor_fraction": None, "prepay_factor": 0.0}


def test_spike_criterion_fails_without_the_slew_limit():
    """The K = 4 x 2b/T press with the old controller (energy observer only, no slew
    limit) cuts the force in one tick, so the spike assertion above can fail."""
    old = ControllerSettings(max_force_step_n=None, **OLD)
    _, _, f = _press(4.0, on=True, res=0.055, settings=old)
    assert np.abs(np.diff(f)).max() > 1.0


GOAL4 = [(b, T, res, mult) for b, T in ((0.5, 1e-3), (0.2, 1e-3), (1.15, 1e-3), (0.5, 0.5e-3), (0.5, 2e-3))
         for res in (0.0, 0.055) for mult in (1.5, 3.0, 4.0)
         if res * mult * 2.0 * b / T / 1000.0 <= 0.35]  # quantised: one count worth <= 0.35 N


@pytest.mark.parametrize("b, T, res, mult", GOAL4)
def test_goal4_passive_settled_and_transparent_up_to_four_times_critical_stiffness(b, T, res, mult):
    """Goal 4 in full, K = 1.5 ... 4 x 2b/T, exact and quantised (0.055 mm) encoder:
    min W_d >= -1e-6 J, std of the position over the last 0.5 s < 0.05 mm, |F| <= 3.3 N,
    |dF| <= 1 N per tick; and the wall is still rendered (mean force = spring law at the
    mean depth within 12 %: a controller that withholds the wall would pass the other
    criteria). Not claimed: quantised encoder with b = 1.15 at 3-4x (K = 6.9-9.2 N/mm,
    one count = 0.38-0.51 N) nor at 0.5 ms, 4x (8 N/mm, 0.44 N per count): the cells
    whose count is worth more than 0.35 N (docs/runtime.md). Transparency is judged
    against the spring of the *reading* the wall is computed from."""
    K = mult * 2.0 * b / T / 1000.0
    (e_off, _, _), (e_on, x, f) = _press_cells(K, [False, True], res=res, b=b, T=T)
    n = int(round(0.5 / T))
    if mult >= 3.0:
        assert e_off > 1e-6  # the wall is active without the controller
    assert e_on <= 1e-6
    assert x[-n:].std() < 0.05
    assert np.abs(f).max() <= 3.3 + 1e-12
    assert np.abs(np.diff(f)).max() <= 1.0
    assert f[-n:].mean() == pytest.approx(K * -quantise(x[-n:], res).mean(), rel=0.12)


@pytest.mark.parametrize("K", [3.0, 4.0])
def test_goal4_fails_without_the_generation_observer(K):
    """The energy observer alone (the controller before the generation observer) lets
    the 45-50 Hz oscillation at K = 3-4 x 2b/T grow until the wall's stored energy is
    spent: settling or energy fails, so the goal-4 test above can fail."""
    old = ControllerSettings(**OLD)
    e_on, x, _ = _press(K, on=True, res=0.0, settings=old)
    assert e_on > 1e-6 or x[-500:].std() >= 0.05


@pytest.mark.parametrize("K", [1.5, 4.0])
def test_wall_is_not_withheld_in_a_long_quantised_hold(K):
    """8 s press and hold on the 0.055 mm encoder: the count-level dither of the reading
    must not drain the energy observer until the energy bound withholds the wall (the
    controller before the half-count play did so after about 4 s at 1.5 x 2b/T)."""
    e_on, x, f = _press(K, on=True, res=0.055, dur=8.0)
    assert e_on <= 1e-6
    assert f[-500:].mean() == pytest.approx(K * -x[-500:].mean(), rel=0.12)
    old = ControllerSettings(**OLD)
    _, x0, f0 = _press(1.5, on=True, res=0.055, dur=8.0, settings=old)
    assert abs(f0[-500:].mean()) < 0.1 * 1.5 * abs(x0[-500:].mean())  # the old one withheld it


def test_generation_observer_books_the_hold_at_once():
    """One tick of motion dx into a spring K with exact positions: the generation
    observer falls by K dx^2 / 2 - b dx^2 / dt (the hold's excess over the credited
    damping) in that very tick, while the energy observer still holds the spring's
    stored energy (positive). Moving in, the pre-payment books ``prepay_factor`` times
    that excess more as debt and the same amount as reserve (their sum is the excess)."""
    K, b, dt = 2000.0, 0.5, 1e-3  # N/m
    p = 1.5
    pc = PassivityController(ControllerSettings(device_damping_ns_per_m=b, generation_budget_j=1.0,
                                                prepay_factor=p))
    x0, x1, x2 = -0.5, -0.6, -0.65  # mm, moving into the wall
    pc.step(x0, dt, K * 1e-3 * -x0)
    pc.commit(K * 1e-3 * -x0)
    pc.step(x1, dt, K * 1e-3 * -x1)
    g1 = pc.generation_j
    dx = (x1 - x0) * 1e-3
    excess = 0.5 * K * dx * dx - b * dx * dx / dt
    assert g1 == pytest.approx(-(1.0 + p) * excess, rel=1e-9)
    assert pc.reserve_j == pytest.approx(p * excess, rel=1e-9)
    assert pc.energy_j > 0
    # the next command carries the damper (opposes the inward motion: pushes outward more)
    out = pc.step(x2, dt, K * 1e-3 * -x2)
    assert out > K * 1e-3 * -x2


def test_no_damper_out_of_contact():
    """In free space (wall force 0) the generation observer is reset and adds no force."""
    pc = PassivityController(ControllerSettings(device_damping_ns_per_m=0.0))
    xs = [-0.5, -0.8, -1.1, -0.7, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5]
    outs = []
    for x in xs:
        fw = 0.5 * -x if x < 0 else 0.0
        o = pc.step(x, 1e-3, fw)
        pc.commit(o)
        outs.append(o)
    assert outs[-3:] == [0.0, 0.0, 0.0]
    assert pc.generation_j == 0.0


def test_scalar_controller_equals_batch():
    rng = np.random.default_rng(3)
    s = ControllerSettings(device_damping_ns_per_m=0.3, position_resolution_mm=0.055)
    pc = PassivityController(s)
    st = controller_state_batch(1)
    x = np.cumsum(rng.normal(0, 0.05, 3000)) - 1.0
    fw = np.maximum(-x, 0) * 3.0
    for k in range(x.size):
        a = pc.step(float(x[k]), 1e-3, float(fw[k]))
        bb = controller_step_batch(st, x[k:k + 1], 1e-3, fw[k:k + 1], np.array([True]), s)[0]
        assert a == pytest.approx(bb, rel=1e-12, abs=1e-12)
        fa = float(np.clip(a, -3.3, 3.3))
        pc.commit(fa)
        controller_commit_batch(st, np.array([fa]))
    assert pc.energy_j == pytest.approx(st["energy"][0], rel=1e-9, abs=1e-15)
    assert pc.active_ticks > 0


@pytest.mark.parametrize("T", [1e-3, 4e-3])
def test_goal4_in_the_stability_matrix_cycles(T):
    """Goal 4 on the stability matrix's press / slide / tap cycles (10 s, quantised
    encoder, soft / medium / stiff finger): every cell with b > 0 and K <= 4 x 2b/T gives
    the finger no energy (<= 1e-6 J) with the controller on, and its largest force step
    is the wall's own (the same cells without the controller give the finger energy)."""
    from hapticsdk.benchmarks.stability import run_period
    cells = [(K, b, fg) for K in (0.1, 0.7, 2.3) for b in (0.25, 0.5) for fg in ("soft", "medium", "stiff")
             if K * 1000.0 <= 4 * 2 * b / T]
    K = np.array([c[0] for c in cells] * 2)
    b = np.array([c[1] for c in cells] * 2)
    fg = [c[2] for c in cells] * 2
    on = np.array([True] * len(cells) + [False] * len(cells))
    r = run_period(T, K, b, fg, on, 10.0)
    n = len(cells)
    assert np.all(r["energy_to_user_j"][:n] <= 1e-6)
    assert np.all(r["max_force_step_n"][:n] <= np.maximum(r["max_force_step_n"][n:], 0.8) + 1e-9)
    assert np.all(r["peak_force_n"][:n] <= 3.3 + 1e-12)
    active = K[:n] * 1000.0 > 2 * b[:n] / T
    if active.any():
        assert r["energy_to_user_j"][n:][active].max() > 1e-4


@pytest.mark.parametrize("K", [0.5, 0.95])
def test_controller_leaves_a_passive_quantised_wall_alone(K):
    """Below 2b/T (quantised encoder) the device damping covers the hold: a one-count
    change is credited whole when the wall's step across it is within Colgate's bound,
    so the controller commands exactly the wall's force on every tick of the press (no
    dither pulses). With the count credited only by its strict lower bound (zero; the
    controller of the previous commit) the same presses got 0.19 / 0.27 N pulses."""
    (_, _, f_off), (_, _, f_on) = _press_cells(K, [False, True], res=0.055)
    assert np.array_equal(f_on, f_off)
