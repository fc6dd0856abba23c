"""Passivity: the Colgate margin against an eigenvalue computation (goal 1), the harness
detects an active wall (goal 3), the ZOH-paired observer and the controller (goal 4),
delay accounting (goal 5), no hidden passivity claim at GS_max (goal 6)."""

import itertools

import numpy as np
from hypothesis import example, given
from hypothesis import settings as hsettings
from hypothesis import strategies as st
import pytest

from hapticsdk.passivity import (DAMPING_TRUST, DECLARED_DAMPING_TRUST, PASSIVE, STABLE_BY_ASSUMPTION, ControllerSettings, PassivityController,
                                 classify_wall, controller_commit_batch, controller_state_batch,
                                 controller_step_batch, critical_stiffness, critical_stiffness_eig,
                                 colgate_stiffness_n_per_mm, naive_observer_energy, passivity_margin, spectral_radius,
                                 zoh_observer_energy)
from hapticsdk.sim.arm import ArmBatch, ArmParams
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


@pytest.fixture(scope="module")
def active_press_off():
    """``_press(1.5, on=False)``, which the two tests below read (run once; its arrays are
    made read-only so that neither can change what the other sees)."""
    e, x, f = _press(1.5, on=False)
    x.flags.writeable = False
    f.flags.writeable = False
    return e, x, f


def test_harness_detects_an_active_wall(active_press_off):
    """Goal 3: K = 1.5 * 2b/T without controller gives energy to the hand; 0.5 * 2b/T does not."""
    e_active, _, _ = active_press_off
    e_passive, _, _ = _press(0.5, on=False)
    assert e_active > 1e-5
    assert e_passive < 1e-9


def test_zoh_paired_observer_fires_where_naive_one_does_not(active_press_off):
    """Goal 4 (unit): on an active ZOH spring the ZOH-paired PO goes negative, f(n)v(n) never."""
    _, x, f = active_press_off
    assert zoh_observer_energy(x, f).min() < -1e-4
    assert naive_observer_energy(x, f, 1e-3).min() >= 0.0


SET = dict(device_mass_kg=0.05, max_force_n=3.3)


@pytest.mark.parametrize("K", [1.5, 2.3, 4.0, 100.0])
def test_controller_keeps_an_active_wall_passive_without_steps(K):
    """Walls 1.5-100 x 2b/T on the reference's press (exact encoder): energy to the hand
    within the controller's allowance (0 here: E0 = s Delta / 2 = 0 without quantisation;
    1 nJ for float sums), no pull, no step beyond the extra's ramp (3.3 N x 1 ms / 5 ms)
    plus the Colgate spring's own change, K_c |dx| with K_c = 2 b_lo / T."""
    st = ControllerSettings(device_damping_ns_per_m=0.5, declared_damping_trust=DAMPING_TRUST, **SET)
    e, x, f = _press(K, on=True, settings=st)
    assert e <= 1e-9
    assert f.min() >= 0.0
    kc = 2.0 * st.damping_trust * st.device_damping_ns_per_m / 1e-3
    allowed = st.ramp_step_n(1e-3) + kc * np.abs(np.diff(x)) * 1e-3
    assert (np.abs(np.diff(f)) <= allowed * (1 + 1e-12)).all()


def test_active_wall_gives_energy_without_the_bound():
    """The same 2.3 x 2b/T press with the energy bound removed (ramp only) gives energy."""
    st = ControllerSettings(device_damping_ns_per_m=0.5, declared_damping_trust=DAMPING_TRUST, energy_bound=False,
                            **SET)
    e, _, _ = _press(2.3, on=True, settings=st)
    assert e > 1e-5


def test_passive_wall_is_rendered_through_the_controller():
    """0.5 x 2b/T (passive by Colgate with the trusted half of b = 1): after the ramp the
    held force equals the wall's own force on the reading (the bound never binds)."""
    st = ControllerSettings(device_damping_ns_per_m=1.0, declared_damping_trust=DAMPING_TRUST, **SET)
    _, x, f = _press(1.0, on=True, b=1.0, settings=st)
    tail = slice(-500, None)
    np.testing.assert_allclose(f[tail], np.maximum(-x[tail], 0.0) * 1.0, rtol=0.02, atol=1e-3)


def test_ramp_sum_is_an_upper_bound():
    from hapticsdk.passivity import _ramp_sum
    for s in (0.1, 0.66, 3.3):
        for a in np.linspace(0.0, 3.3, 67):
            true = sum(max(a - j * s, 0.0) for j in range(200))
            assert _ramp_sum(a, s) >= true - 1e-12


def test_free_arm_work_of_the_plan_is_exact():
    """The plan's cost without the encoder term equals the work of the ramp's forces on a
    free mass (integrated here tick by tick under the hold)."""
    from hapticsdk.passivity import plan_cost_j
    m, T, s, v0 = 0.045, 1e-3, 0.5, 0.02
    forces = [2.0 - j * s for j in range(5) if 2.0 - j * s > 0]
    x, v, w = 0.0, v0, 0.0
    for F in forces:
        dx = v * T + F * T * T / (2 * m)
        w += F * dx
        x += dx
        v += F * T / m
    exact_sum = sum(forces)
    cost = plan_cost_j(2.0, 0.0, v0 * T, T * T / (2 * m), s, 0.0)
    # S(a) bound >= the true sum, so the cost bounds the work from above, tightly
    assert cost >= w - 1e-15
    assert cost <= w * (1 + 2 * (0.125 * s) / exact_sum + 0.1)


def test_affordable_force_is_the_largest_within_budget():
    from hapticsdk.passivity import _affordable_scalar, affordable_force, plan_cost_j
    rng = np.random.default_rng(3)
    for _ in range(300):
        A = rng.uniform(-1e-4, 1e-3)
        p = rng.uniform(0, 3)
        s = rng.uniform(0.05, 3.3)
        lo, hi = max(p - s, 0.0), p + s
        d = rng.uniform(-1e-4, 1e-4)
        cm = rng.uniform(0, 1e-3)
        c = rng.uniform(0, 1e-4)
        a = affordable_force(A, lo, hi, p, d, cm, s, c)
        assert a == pytest.approx(_affordable_scalar(A, lo, hi, p, d, cm, s, c), abs=1e-6)
        grid = np.linspace(lo, hi, 2001)
        ok = grid[plan_cost_j(grid, p, d, cm, s, c) <= A]
        if ok.size:
            assert a >= ok.max() - (hi - lo) / 1000 and plan_cost_j(a, p, d, cm, s, c) <= A + 1e-12
        else:
            assert lo <= a <= hi


@pytest.mark.parametrize("trust", [DECLARED_DAMPING_TRUST, DAMPING_TRUST], ids=["default", "credited"])
def test_scalar_controller_equals_batch(trust):
    """The loop's scalar controller and the benchmark's batch run the same law, with the
    declaration credited (a spring) or not (the default: the extra alone)."""
    st = ControllerSettings(device_damping_ns_per_m=0.3, position_resolution_mm=0.055, declared_damping_trust=trust,
                            **SET)
    rng = np.random.default_rng(1)
    xs = np.round(np.cumsum(rng.normal(-0.01, 0.05, 2000)) / 0.055) * 0.055
    pc = PassivityController(st)
    bs = controller_state_batch(1)
    for x in xs:
        fw = 2.3 * max(-x, 0.0)
        a = pc.step(float(x), 1e-3, fw)
        b = controller_step_batch(bs, np.array([x]), 1e-3, np.array([fw]), True, st)[0]
        assert a == pytest.approx(b, abs=1e-6)
        fa = min(a, 3.3)
        pc.commit(fa)
        controller_commit_batch(bs, np.array([fa]))
    assert pc.report()["energy_bound_j"] == pytest.approx(bs["energy"][0], abs=1e-9)


@pytest.mark.parametrize("fmax", [3.3, None])
def test_a_wall_or_applied_force_that_is_not_a_number_is_taken_as_0_n_by_both_forms(fmax):
    """The batch runs the scalar controller's law tick by tick (module docstring of
    ``hapticsdk.passivity.batch``), also on a wall force or an applied force that is NaN,
    +inf or -inf, which the scalar one takes as 0 N: the same outputs and the same book
    on a press whose wall and device report such values now and then."""
    st = ControllerSettings(device_damping_ns_per_m=0.3, position_resolution_mm=0.055, device_mass_kg=0.05,
                            max_force_n=fmax, declared_damping_trust=DAMPING_TRUST)
    rng = np.random.default_rng(2)
    xs = np.round(np.cumsum(rng.normal(-0.01, 0.05, 400)) / 0.055) * 0.055
    bad = (np.nan, np.inf, -np.inf)
    pc = PassivityController(st)
    bs = controller_state_batch(1)
    for k, x in enumerate(xs):
        fw = 2.3 * max(-x, 0.0) if k % 5 else bad[(k // 5) % 3]
        a = pc.step(float(x), 1e-3, fw)
        b = controller_step_batch(bs, np.array([x]), 1e-3, np.array([fw]), True, st)[0]
        assert a == pytest.approx(b, abs=1e-9), k
        fa = min(a, 3.3) if k % 7 else bad[(k // 7) % 3]
        pc.commit(fa)
        controller_commit_batch(bs, np.array([fa]))
    assert pc.report()["energy_bound_j"] == pytest.approx(bs["energy"][0], abs=1e-12)


@pytest.mark.parametrize("batch", [False, True])
def test_release_without_a_declared_force_limit_reaches_zero(batch):
    """With no force limit declared, a wall that goes to 0 (a pause, a release) is ramped
    down linearly and reaches exactly 0 within F / s ticks (s the ramp step of the largest
    force seen); a step relative to the current output would shrink with it (geometric
    decay, never 0)."""
    st = ControllerSettings()   # no limit, no damping, exact encoder
    f_hold, dt = 3.45, 1e-3
    n_ramp = int(np.ceil(st.ramp_time_s / dt))   # ticks of a full-scale ramp
    if batch:
        state = controller_state_batch(1)
        step = lambda fw: float(controller_step_batch(state, np.array([-1.5]), dt, np.array([fw]), True, st)[0])  # noqa: E731
        commit = lambda f: controller_commit_batch(state, np.array([f]))  # noqa: E731
    else:
        pc = PassivityController(st)
        step = lambda fw: pc.step(-1.5, dt, fw)  # noqa: E731
        commit = pc.commit
    out = []
    for k in range(40):
        f = step(f_hold if k < 20 else 0.0)
        commit(f)
        out.append(f)
    assert out[19] == pytest.approx(f_hold)
    assert out[20 + n_ramp] == 0.0


def test_old_controller_settings_warn_and_are_ignored():
    """The 0.1 controller's tuned settings still construct (one minor version), with a
    DeprecationWarning naming them, and change nothing; cap_stiffness_n_per_mm warns and
    returns the Colgate spring's stiffness, 2 b_lo / T (N/mm)."""
    from hapticsdk.passivity import cap_stiffness_n_per_mm, colgate_stiffness_n_per_mm
    with pytest.warns(DeprecationWarning, match="felt_force_n, stiffness_cap"):
        old = ControllerSettings(stiffness_cap=False, felt_force_n=0.6, declared_damping_trust=DAMPING_TRUST, device_damping_ns_per_m=0.5)
    assert old == ControllerSettings(declared_damping_trust=DAMPING_TRUST, device_damping_ns_per_m=0.5)
    with pytest.warns(DeprecationWarning, match="no stiffness cap"):
        k = cap_stiffness_n_per_mm(old, 1e-3)
    assert k == colgate_stiffness_n_per_mm(old, 1e-3) == pytest.approx(2 * 0.25 / 1e-3 / 1000)


@pytest.mark.parametrize("mass", [0.0, -0.045, float("nan"), float("inf")])
def test_a_mass_that_would_make_held_force_free_is_refused(mass):
    """The plan's free-arm terms (``T^2 / 2m`` and ``dF T^2 / m``) divide by the declared
    mass: 0, a negative, NaN or infinite mass is a ValidationError naming the field."""
    from hapticsdk.errors import ValidationError

    with pytest.raises(ValidationError) as err:
        ControllerSettings(device_mass_kg=mass)
    assert err.value.field == "device_mass_kg"
    assert ControllerSettings(device_mass_kg=None).device_mass_kg is None


_SETTING_FIELDS = {   # field: (what it accepts besides a finite number, its lower end, open, upper end)
    "device_damping_ns_per_m": (False, 0.0, False, None),
    "damping_trust": (False, 0.0, False, 1.0),
    "declared_damping_trust": (False, 0.0, False, 1.0),
    "position_resolution_mm": (False, 0.0, False, None),
    "measured_damping_ns_per_m": (True, 0.0, False, None),
    "max_force_n": (True, 0.0, True, None),
    "ramp_time_s": (False, 0.0, True, None),
    "device_mass_kg": (True, 0.0, True, None),
    "mass_trust": (False, 0.0, True, 1.0),
    "energy_allowance_j": (False, 0.0, False, None),
    "period_s": (True, 0.0, True, None),
}


@pytest.mark.parametrize("field", sorted(_SETTING_FIELDS))
@pytest.mark.parametrize("how", ["init", "assign", "replace"])
def test_every_settings_field_refuses_what_the_tick_cannot_use(field, how):
    """The tick reads the settings with no checks of its own, so each field is checked
    where it is set: at construction, by ``dataclasses.replace`` and by an assignment
    (which takes effect mid-run). A string (even one that reads as a number), a bool, a
    NaN, an infinity, a complex number, a list, a number beyond a float, or a value
    outside the field's range is a ValidationError naming the field, and the settings
    keep their old value; a numpy scalar is stored as a plain float."""
    import dataclasses
    from hapticsdk.errors import ValidationError

    none_ok, lo, lo_open, hi = _SETTING_FIELDS[field]
    bad = ["0.5", True, False, float("nan"), float("inf"), -float("inf"), 1 + 0j, [0.5], 10 ** 400, lo - 1.0]
    if lo_open:
        bad.append(lo)
    if hi is not None:
        bad.append(hi + 0.5)
    if not none_ok:
        bad.append(None)
    base = ControllerSettings(max_force_n=3.3, device_mass_kg=0.05, period_s=1e-3, measured_damping_ns_per_m=0.2)
    for value in bad:
        s = dataclasses.replace(base)
        with pytest.raises(ValidationError) as err:
            if how == "init":
                ControllerSettings(**{field: value})
            elif how == "assign":
                setattr(s, field, value)
            else:
                dataclasses.replace(s, **{field: value})
        assert err.value.field == field, value
        assert s == base
    good = np.float32(0.5)
    s = dataclasses.replace(base)
    if how == "init":
        s = ControllerSettings(**{field: good})
    elif how == "assign":
        setattr(s, field, good)
    else:
        s = dataclasses.replace(s, **{field: good})
    assert type(getattr(s, field)) is float and getattr(s, field) == 0.5


@pytest.mark.parametrize("value", [1, "yes", None, 1.0, np.float64(1.0)])
def test_the_energy_bound_switch_takes_only_a_bool(value):
    """``energy_bound`` switches the extra's bound off: only True or False (or a numpy
    bool) do that, never a 1, a string or None that a caller meant as something else."""
    import dataclasses
    from hapticsdk.errors import ValidationError

    with pytest.raises(ValidationError) as err:
        ControllerSettings(energy_bound=value)
    assert err.value.field == "energy_bound"
    s = ControllerSettings()
    with pytest.raises(ValidationError):
        s.energy_bound = value
    assert s.energy_bound is True
    assert dataclasses.replace(s, energy_bound=np.bool_(False)).energy_bound is False


@hsettings(max_examples=100, deadline=None, derandomize=True, database=None)
@given(b=st.floats(0.05, 3.0), T=st.floats(2.5e-4, 1e-2), res=st.floats(1e-3, 0.2), fmax=st.floats(0.5, 12.0),
       depth=st.floats(0.05, 5.0), jitter=st.lists(st.floats(0.5, 3.0), min_size=1, max_size=8))
def test_with_a_declared_period_the_spring_keeps_its_stiffness_through_jitter(b, T, res, fmax, depth, jitter):
    """With the servo's period declared (``period_s``), the Colgate spring of a press held
    at one reading is ``min(2 b_s / T, s(T) / Delta) x depth`` (``s(T)`` the ramp step at
    the declared period) before, during and after intervals of any measured length: a
    spring sized on each measured interval changes its stiffness while compressed (a rise
    stores energy no motion paid for), and one that may only fall would ratchet down
    after an early tick. The wall equals the spring here (``F_wall`` = that force), so the
    force sent is the spring's alone. The press comes in one count a tick at the declared
    period: the spring then rises by at most one ramp step a tick (its cap), so its anchor
    stays at the surface."""
    cs = ControllerSettings(declared_damping_trust=DAMPING_TRUST, device_damping_ns_per_m=b, position_resolution_mm=res, max_force_n=fmax,
                            period_s=T)
    b_s = cs.damping_trust * b
    k = min(2 * b_s / T, fmax * min(T / cs.ramp_time_s, 1.0) / (res * 1e-3))
    f_spring = min(k * depth * 1e-3, fmax)
    pc = PassivityController(cs)
    pc.step(0.0, T, 0.0)
    pc.commit(0.0)
    for n in range(1, int(depth / res) + 1):
        pc.commit(pc.step(-n * res, T, min(k * n * res * 1e-3, fmax)))
    for dt in [T] + [dt_ * T for dt_ in jitter] + [T, T]:
        f = pc.step(-depth, dt, f_spring)
        pc.commit(f)
        assert f == pytest.approx(f_spring, rel=1e-12, abs=1e-15), dt / T


def test_without_a_declared_limit_the_spring_does_not_stiffen_while_compressed():
    """Without a declared force limit the full scale is the largest force so far, and the
    spring's cap (one ramp step per count) follows it. With the servo's period declared,
    the spring of a press does not stiffen while it is compressed: a press that deepens
    the wall's force (and so the full scale) keeps the stiffness it had, and after the
    release the next press starts from the grown full scale."""
    T, res, b, K = 2.5e-4, 0.17, 1.0, 1.0          # K: a 1 N/mm wall; the cap binds (2 b_s / T = 4 N/mm)
    cs = ControllerSettings(declared_damping_trust=DAMPING_TRUST, device_damping_ns_per_m=b, position_resolution_mm=res, period_s=T, energy_bound=False)
    pc = PassivityController(cs)
    pc.step(0.0, T, 0.0)
    pc.commit(0.0)

    def spring_at(depth, f_wall=None):   # the force sent on a press into a wall of K N/mm (or f_wall)
        f = pc.step(-depth, T, K * depth if f_wall is None else f_wall)
        pc.commit(f)
        return f
    # (the stiffness K_c is read from the controller: a press of several counts in one tick
    # raises the spring by one ramp step, its anchor moving in, so the force alone does not
    # show the stiffness)
    f0 = spring_at(0.4)                               # contact: full scale 0.4 N
    k0 = 0.4 * min(T / cs.ramp_time_s, 1.0) / (res * 1e-3)   # its cap, N/m
    assert pc._kc == pytest.approx(k0, rel=1e-12) and 0.0 < f0 <= 0.4
    spring_at(10.0)                                   # the wall's force, and the full scale, to 10 N
    assert pc._kc == pytest.approx(k0, rel=1e-12)     # the stiffness of the contact's start
    for _ in range(40):                               # release; out of the wall
        pc.step(1.0, T, 0.0)
        pc.commit(0.0)
    spring_at(0.4, 10.0)                              # a press into a 10 N wall
    k1 = 10.0 * min(T / cs.ramp_time_s, 1.0) / (res * 1e-3)  # the next press: the grown full scale's cap
    assert pc._kc == pytest.approx(min(k1, 2 * 0.5 * b / T), rel=1e-12)


def _hold_at(pc, dts, depth_mm=-0.5, f_wall=50.0):
    out = []
    for dt in dts:
        f = pc.step(depth_mm, dt, f_wall)
        pc.commit(f)
        out.append(f)
    return out


def test_a_settings_field_assigned_mid_run_takes_effect():
    """Assigning a field of the settings (or replacing them) mid-run takes effect at the
    next tick: the output obeys the new force limit, and equals that of a controller
    given the new settings object at the same tick (a controller that kept constants
    derived at construction would fail this)."""
    a_set = ControllerSettings(declared_damping_trust=DAMPING_TRUST, device_damping_ns_per_m=0.4, position_resolution_mm=0.01, max_force_n=3.3,
                               device_mass_kg=0.05, energy_bound=False)
    a = PassivityController(a_set)
    b = PassivityController(ControllerSettings(declared_damping_trust=DAMPING_TRUST, device_damping_ns_per_m=0.4, position_resolution_mm=0.01,
                                               max_force_n=3.3, device_mass_kg=0.05, energy_bound=False))
    assert _hold_at(a, [1e-3] * 30) == _hold_at(b, [1e-3] * 30)
    assert a.step(-0.5, 1e-3, 50.0) == pytest.approx(3.3)   # held at the limit
    a.commit(3.3)
    b.step(-0.5, 1e-3, 50.0)
    b.commit(3.3)
    a_set.max_force_n = 1.0
    b.settings = ControllerSettings(declared_damping_trust=DAMPING_TRUST, device_damping_ns_per_m=0.4, position_resolution_mm=0.01, max_force_n=1.0,
                                    device_mass_kg=0.05, energy_bound=False)
    fa, fb = _hold_at(a, [1e-3] * 30), _hold_at(b, [1e-3] * 30)
    assert fa == fb
    assert max(fa[-10:]) <= 1.0 + 1e-12   # ramped down to the new limit, and kept there
    assert fa[0] < 3.3   # the ramp down starts at once


@hsettings(max_examples=200, deadline=None)
@given(dt1=st.floats(1e-4, 1e-2), dt2=st.floats(1e-4, 1e-2), depth=st.floats(1e-3, 5.0))
def test_the_spring_and_the_ramp_follow_a_changing_period(dt1, dt2, depth):
    """With a measured period that changes from tick to tick (realtime mode), the Colgate
    spring is ``2 b_lo / dt`` of that tick and the ramp step ``F_max dt / ramp`` of that
    tick: from rest, two ticks at depth d into a wall far above both (bound off) give the
    spring ``K(dt) d`` plus an extra one ramp step ``s(dt)`` above the last, less what the
    spring rose by (the whole force rises by at most ``s``), never below the last extra
    less ``s`` nor below 0, and the sum at most F_max."""
    b, fm = 0.3, 1000.0
    pc = PassivityController(ControllerSettings(declared_damping_trust=DAMPING_TRUST, device_damping_ns_per_m=b, max_force_n=fm, energy_bound=False))
    pc.step(0.0, dt1, 0.0)   # the first call takes the position
    pc.commit(0.0)
    blo = b * pc.settings.damping_trust
    d = depth * 1e-3

    def ramp(dt):
        return fm * min(dt / pc.settings.ramp_time_s, 1.0)
    k1, k2 = 2 * blo / dt1 * d, 2 * blo / dt2 * d   # both far below F_max here

    def extra(p, s, rise, room):   # one ramp step up, less the spring's rise; not below p - s, 0
        return max(min(p + s - max(rise, 0.0), room), max(p - s, 0.0))
    f1 = pc.step(-depth, dt1, 1e6)
    assert f1 == pytest.approx(k1 + extra(0.0, ramp(dt1), k1, fm - k1), rel=1e-12, abs=1e-15)
    pc.commit(f1)
    f2 = pc.step(-depth, dt2, 1e6)
    assert f2 == pytest.approx(k2 + extra(f1 - k1, ramp(dt2), k2 - k1, fm - k2), rel=1e-12, abs=1e-15)


@hsettings(max_examples=300, deadline=None)
@given(b=st.floats(0.01, 3.0), dt=st.floats(2.5e-4, 1e-2), res=st.floats(1e-3, 0.2), fmax=st.floats(0.5, 12.0),
       depth=st.floats(1e-3, 5.0))
def test_one_count_of_the_colgate_spring_is_within_one_ramp_step(b, dt, res, fmax, depth):
    """The Colgate spring ``K_c = 2 b_lo / T`` is capped at one ramp step per encoder count,
    ``s / Delta``: a hand crossing one count moves the spring by at most the ramp's own
    step, and the spring's gain per crossing, ``(K_c Delta)^2 T / 4b``, is at most
    ``s^2 T / 4b``. With no allowance and the hand at rest the extra stays 0 and the
    output is the spring alone; the scalar controller, the batch and
    ``colgate_stiffness_n_per_mm`` agree. The hand takes its first reading at the surface and
    crosses one count inward: the spring is ``K_c Delta``. A wall that appears around a
    stylus resting at ``depth``, or moving out by a count, stores nothing: no inward motion
    paid for it, so the spring stays 0 (item 0, "a spring born compressed")."""
    cs = ControllerSettings(declared_damping_trust=DAMPING_TRUST, device_damping_ns_per_m=b, position_resolution_mm=res, max_force_n=fmax,
                            energy_allowance_j=0.0)
    s = fmax * min(dt / cs.ramp_time_s, 1.0)
    kc = min(2 * cs.damping_trust * b / dt, s / (res * 1e-3))   # N/m, from the derivation
    assert kc * res * 1e-3 <= s * (1 + 1e-12)
    assert colgate_stiffness_n_per_mm(cs, dt) * 1000 == pytest.approx(kc, rel=1e-12)
    for xs, want in (((0.0, -res), min(kc * res * 1e-3, fmax, s)), ((-depth, -depth), 0.0),
                     ((-depth - res, -depth), 0.0)):   # nor one that moves out
        pc = PassivityController(cs)
        bs = controller_state_batch(1)
        for x in xs:   # the first call takes the position
            a = pc.step(x, dt, 1e6)
            pc.commit(a)
            f = controller_step_batch(bs, np.array([x]), dt, np.array([1e6]), True, cs)[0]
            controller_commit_batch(bs, np.array([f]))
            assert a == f
        assert a == pytest.approx(want, rel=1e-12)


@hsettings(max_examples=50, deadline=None)
@given(b=st.floats(0.05, 3.0), dt=st.floats(2.5e-4, 1e-2), res=st.floats(1e-3, 0.2), fmax=st.floats(0.5, 12.0),
       k=st.floats(0.05, 50.0), seed=st.integers(0, 2**31 - 1), inward=st.floats(0.3, 0.9))
def test_the_whole_force_rises_by_at_most_one_ramp_step(b, dt, res, fmax, k, seed, inward):
    """The extra gives way to the spring's rise, so while the reading moves by at most one
    count per tick (the spring's cap then keeps its own rise within ``s``) the force sent
    rises by at most one ramp step ``s`` per tick, the spring included (item 3). Presses
    into walls from 0.05 to 50 N/mm, the energy bound on; the batch sends the same."""
    cs = ControllerSettings(declared_damping_trust=DAMPING_TRUST, device_damping_ns_per_m=b, position_resolution_mm=res, max_force_n=fmax,
                            device_mass_kg=0.05)
    s = fmax * min(dt / cs.ramp_time_s, 1.0)
    rng = np.random.default_rng(seed)
    moves = rng.choice([-1, 0, 1], size=400, p=[inward * 0.6, 0.4, 0.6 * (1 - inward)])
    xs = res * (3 + np.minimum(np.cumsum(moves), 3))   # from 3 counts outside, never above
    pc = PassivityController(cs)
    bs = controller_state_batch(1)
    last = 0.0
    for x in xs:
        fw = k * max(-x, 0.0)
        f = pc.step(float(x), dt, fw)
        g = controller_step_batch(bs, np.array([x]), dt, np.array([fw]), True, cs)[0]
        assert f == pytest.approx(g, abs=1e-6)
        assert f - last <= s * (1 + 1e-9) + 1e-12
        pc.commit(f)
        controller_commit_batch(bs, np.array([f]))
        last = f


def _press_hold_release(res: float, depth_counts: int, hold: int, out_counts: int = 1) -> np.ndarray:
    """Readings (mm): in by one count a tick to ``depth_counts``, held ``hold`` ticks, out
    by ``out_counts`` counts a tick to 3 counts outside."""
    down = -res * np.arange(0, depth_counts + 1)
    up = -res * np.arange(depth_counts, -4, -out_counts)
    return np.concatenate([res * np.arange(3, 0, -1), down, np.full(hold, down[-1]), up, np.full(5, 3 * res)])


@hsettings(max_examples=60, deadline=None)
@given(b=st.floats(0.05, 3.0), dt=st.floats(2.5e-4, 1e-2), res=st.floats(1e-3, 0.2), fmax=st.floats(0.5, 12.0),
       k=st.floats(0.05, 200.0), depth=st.integers(1, 60), hold=st.integers(0, 50), out=st.integers(1, 6))
def test_where_the_extra_is_not_bounded_the_whole_force_falls_by_at_most_one_ramp_step(b, dt, res, fmax, k,
                                                                                        depth, hold, out):
    """On a release the extra takes up what the spring gave up in the same tick, never
    above what it held (item 7). So while the reading moves out by one count a tick (the
    spring's fall then is at most ``s``, its cap) the force sent falls by at most one ramp
    step a tick, the spring included, even where the wall's law falls faster; and on a
    faster release the extra rises above what it held only within the wall's law. With the energy bound off, so that the interval
    alone decides; the batch sends the same."""
    cs = ControllerSettings(declared_damping_trust=DAMPING_TRUST, device_damping_ns_per_m=b, position_resolution_mm=res, max_force_n=fmax,
                            device_mass_kg=0.05, energy_bound=False)
    s = fmax * min(dt / cs.ramp_time_s, 1.0)
    pc = PassivityController(cs)
    bs = controller_state_batch(1)
    last, spring, extra = 0.0, 0.0, 0.0
    for x in _press_hold_release(res, depth, hold, out):
        fw = k * max(-x, 0.0)
        f = pc.step(float(x), dt, fw)
        g = controller_step_batch(bs, np.array([x]), dt, np.array([fw]), True, cs)[0]
        assert f == pytest.approx(g, abs=1e-9)
        assert 0.0 <= f
        if out == 1:
            assert last - f <= s * (1 + 1e-9) + 1e-12
        if pc._spring < spring:
            # the spring fell: the extra rises only within the wall's law (capped at the limit)
            assert f - pc._spring <= max(extra, min(fw, fmax) - pc._spring) * (1 + 1e-12) + 1e-12
        pc.commit(f)
        controller_commit_batch(bs, np.array([f]))
        last, spring, extra = f, pc._spring, f - pc._spring


@pytest.mark.parametrize("depth", [1, 3])
def test_a_count_crossed_after_a_rest_keeps_the_fall_within_one_ramp_step(depth):
    """A creep out of a press (docs/runtime.md, Passivity item 3, "The count crossing"): the
    reading rests 10 ticks at each count (0.3 ms, a 0.05 mm encoder, 3.3 N, half of 0.43 N
    s/m credited). At rest the plan's speed estimate shrinks and the extra climbs to the
    edge of what it affords; one count out books the held extra times a count and raises
    the estimate, so not even the ramp down fits. The ramp is taken anyway, and the extra's
    take-up of the spring's fall is priced at what it adds to that ramp, within what is left
    of the allowance: every step is within one ramp step (1.36 ramp steps without the rule),
    in the scalar controller and the batch alike, with the energy bound on."""
    res, dt, fmax, m = 0.05, 3e-4, 3.3, 0.05
    cs = ControllerSettings(declared_damping_trust=DAMPING_TRUST, device_damping_ns_per_m=0.43,
                            position_resolution_mm=res, max_force_n=fmax, device_mass_kg=m, period_s=dt)
    s = fmax * min(dt / cs.ramp_time_s, 1.0)
    xs = np.concatenate([res * np.arange(3, 0, -1), np.repeat(-res * np.arange(0, depth + 1), 10),
                         np.repeat(-res * np.arange(depth - 1, -4, -1), 10)])
    pc = PassivityController(cs)
    bs = controller_state_batch(1)
    last = lastb = 0.0
    for x in xs:
        fw = 644.0 * max(-x, 0.0)
        f = pc.step(float(x), dt, fw)
        g = controller_step_batch(bs, np.array([x]), dt, np.array([fw]), True, cs, mass_kg=m)[0]
        assert f == pytest.approx(g, abs=1e-8)
        assert abs(f - last) <= s * (1 + 1e-9) and abs(g - lastb) <= s * (1 + 1e-9)
        pc.commit(f)
        controller_commit_batch(bs, np.array([g]))
        last, lastb = f, g


def test_a_count_a_tick_does_not_take_up_the_spring_s_fall_beyond_the_plan():
    """The count crossing's take-up (docs/runtime.md, Passivity item 3) only after a rest of
    more than 2 ticks: seed 77's cell 911 of ``draw_cells(1000, 77)``, a tap at 0.26 ms on a
    0.195 mm encoder whose reading moves by about a count a tick. Taking up the spring's fall
    on those crossings too overdrew the book, and the extra fell below its ramp (5.6 ramp
    steps); with the rest condition no tick falls below the ramp, within 0.1 mJ.

    The same cell through the scalar controller (the servo loop's) and the vectorised one
    in the independent simulator: the take-up must not apply in either, and the two give
    the same force on every tick (to rounding: they evaluate the same formulas in another
    order). Without the scalar controller's rest condition its forces part from the batch's."""
    import independent_plant as ip
    from hapticsdk.benchmarks.stability_random import draw_cells, run_cells

    cell = dict(draw_cells(1000, 77)[911])
    out = run_cells([cell], controllers=("sdk",))[0]
    r = out["results"]["sdk"]
    assert r["below_ramp_ticks"] == 0
    assert r["energy_to_user_j"] <= 1e-4
    cell["damping_calibration"] = out["damping_calibration"]
    s = ip.run_cell(cell, "sdk", controller="scalar", log=True)
    b = ip.run_cell(cell, "sdk", controller="batch", log=True)
    assert s["energy_to_user_j"] <= 1e-4
    # rounding: a few ulps of the device's force limit per tick, far below one ramp step
    np.testing.assert_allclose(s["forces_n"], b["forces_n"], rtol=0, atol=1e-9)


@pytest.mark.parametrize("index", [300, 108])
def test_a_drawn_release_falls_within_the_ramp_where_the_book_affords_it(index, seed1_sdk):
    """Two drawn cells of seed 1 (``draw_cells(2000, 1)``): 300, a press and hold (2.4 ms,
    a 0.02 mm encoder), and 108, a tap, whose releases fell by 1.24 and 1.22 ramp steps
    with the spring's fall on top of the extra's ramp. With the energy bound on, the plan of
    item 5 prices the extra taking up the spring's fall like any other force; where it
    affords it, every fall is within one ramp step, and the energy to the user stays within
    the goal's 0.1 mJ."""
    r = seed1_sdk[index]["results"]["sdk"]
    assert r["max_force_fall_n"] <= r["ramp_step_n"] * (1 + 1e-9)
    assert r["max_force_rise_n"] <= r["ramp_step_n"] * (1 + 1e-9)
    assert r["energy_to_user_j"] <= 1e-4
    assert r["min_contact_force_n"] >= 0.0


@pytest.mark.parametrize("controller", ["batch", "scalar"])
def test_an_arm_lighter_than_declared_stays_within_the_energy_goal(controller):
    """The plan's free-arm terms divide by the arm's mass, and a lighter arm moves further
    under the same force: the controller takes half the declared mass (``mass_trust``,
    docs/runtime.md, Passivity item 2a). Seed 101's cell 45 of ``draw_cells(2000, 101)``
    (a press and hold at 7.1 ms on a 0.045 mm encoder, no damping) with its mass declared
    at twice the true one, the edge of the band the benchmark draws: taking the
    declaration at face value puts more than 0.1 mJ into the hand (0.14 mJ, checked here
    too, so the cell keeps exercising the rule); with half of it, the energy stays within
    the goal. The vectorised controller through the benchmark's plant, the scalar one
    (the servo's) through the independent simulator of ``tests/independent_plant.py``."""
    import independent_plant as ip
    from hapticsdk.benchmarks.stability_random import draw_cells, run_cells

    cell = dict(draw_cells(2000, 101)[45])
    cell["arm_mass_declared_kg"] = 2.0 * cell["arm_mass_kg"]

    def energy(**overrides):   # the controller's default settings, or with overrides
        if controller == "batch":
            return run_cells([cell], controllers=("sdk",), settings=ControllerSettings(
                **overrides))[0]["results"]["sdk"]["energy_to_user_j"]
        cell["damping_calibration"] = run_cells([cell], controllers=("sdk",))[0]["damping_calibration"]
        return ip.run_cell(cell, "sdk", controller="scalar", overrides=overrides)["energy_to_user_j"]

    assert energy(mass_trust=1.0) > 1e-4
    assert energy() <= 1e-4


@hsettings(max_examples=30, deadline=None)
@given(b=st.floats(0.05, 5.0), dt=st.floats(2.5e-4, 1e-2), res=st.floats(1e-3, 0.2), fmax=st.floats(0.5, 12.0),
       k=st.floats(0.05, 50.0), seed=st.integers(0, 2**31 - 1))
# always run: the Omni's encoder and limit with a stiff spring (K_c = 5 N/mm at 1 kHz): the
# extra ramps up to about 2.4 N at one count deep, then the first jump raises the spring to
# the limit (the random draws reach this region only now and then)
@example(b=5.0, dt=1e-3, res=0.055, fmax=3.3, k=50.0, seed=1)
def test_the_output_never_exceeds_the_declared_force_limit(b, dt, res, fmax, k, seed):
    """A reading that jumps many counts into the wall within one tick (a fast tap) raises
    the Colgate spring by more than the extra's ramp gives way; the extra then yields at
    once so that spring + extra stays within the device's declared limit (it went to
    spring + extra, up to twice the limit). Scalar and batch alike."""
    cs = ControllerSettings(device_damping_ns_per_m=b, position_resolution_mm=res, max_force_n=fmax,
                            device_mass_kg=0.05)
    rng = np.random.default_rng(seed)
    # hold near the surface (the extra ramps up), then jumps of up to 3 mm per tick
    xs = np.concatenate([np.full(100, -res), -rng.uniform(0.0, 3.0, 100)])
    pc = PassivityController(cs)
    bs = controller_state_batch(1)
    for x in xs:
        fw = k * max(-x, 0.0)
        f = pc.step(float(x), dt, fw)
        g = controller_step_batch(bs, np.array([x]), dt, np.array([fw]), True, cs)[0]
        assert 0.0 <= f <= fmax * (1 + 1e-12) and 0.0 <= g <= fmax * (1 + 1e-12)
        pc.commit(f)
        controller_commit_batch(bs, np.array([g]))


def test_the_settings_state_the_allowance_and_credit_nothing_undeclared():
    """``ControllerSettings.energy_budget_j``: ``E0 = min(F_max Delta / 2, energy_allowance_j)``
    (docs/runtime.md, Passivity item 6), with ``full_scale_n`` standing in for an
    undeclared force limit. Settings that declare no damping credit none: the Colgate
    spring is 0."""
    from hapticsdk.passivity import ControllerSettings, colgate_stiffness_n_per_mm
    omni = ControllerSettings(max_force_n=3.3, position_resolution_mm=0.055)
    assert omni.energy_budget_j(1e-3) == pytest.approx(3.3 * 0.055e-3 / 2, rel=1e-12, abs=0.0)
    coarse = ControllerSettings(max_force_n=3.3, position_resolution_mm=0.2)
    assert coarse.energy_budget_j(1e-3) == pytest.approx(1e-4, rel=1e-12, abs=0.0)   # capped at 0.1 mJ
    strict = ControllerSettings(max_force_n=3.3, position_resolution_mm=0.055, energy_allowance_j=5e-5)
    assert strict.energy_budget_j(1e-3) == pytest.approx(5e-5, rel=1e-12, abs=0.0)
    free = ControllerSettings(position_resolution_mm=0.01)
    assert free.energy_budget_j(1e-3, full_scale_n=2.0) == pytest.approx(1e-5, rel=1e-12, abs=0.0)
    bare = ControllerSettings(max_force_n=3.3, position_resolution_mm=0.055)
    assert bare.device_damping_ns_per_m == 0.0 and bare.trusted_damping_ns_per_m() == 0.0
    assert colgate_stiffness_n_per_mm(bare, 1e-3) == 0.0


@pytest.mark.parametrize("batch", [False, True])
def test_a_reading_that_jumps_many_counts_raises_the_force_by_one_ramp_step_a_tick(batch):
    """A reading that jumps 200 counts into the wall in one tick (a fast tap on a fine
    encoder): the Colgate spring rises by one ramp step and its anchor moves in, so the
    force sent rises by at most ``s`` a tick on its way to the wall's force (item 0 and
    item 3). On the way out the spring is 0 from its anchor on (never a pull), and a later
    press that comes in one count a tick gets the whole spring ``K_c x depth`` again (the
    anchor follows the reading out of the wall). Here ``K_c = 2 x 0.5 x 1 N s/m / 1 ms = 1
    N/mm`` (under its cap of one ramp step a count, 0.66 N / 0.01 mm), the ramp step ``s``
    is 3.3 N x 1 ms / 5 ms = 0.66 N, and the wall is the spring's own law (1 N/mm), so
    whatever rises above the spring is the extra's ramp (its energy bound is switched off
    to show the ramp alone)."""
    T = 1e-3
    cs = ControllerSettings(declared_damping_trust=DAMPING_TRUST, device_damping_ns_per_m=1.0, position_resolution_mm=0.01, max_force_n=3.3,
                            period_s=T, energy_bound=False)
    s = 3.3 * T / cs.ramp_time_s
    if batch:
        st_ = controller_state_batch(1)

        def tick(x_mm):
            f = float(controller_step_batch(st_, np.array([x_mm]), T, np.array([max(-x_mm, 0.0)]), True, cs)[0])
            controller_commit_batch(st_, np.array([f]))
            return f
    else:
        pc = PassivityController(cs)

        def tick(x_mm):
            f = pc.step(x_mm, T, max(-x_mm, 0.0))
            pc.commit(f)
            return f
    forces = [tick(0.5), tick(0.5)] + [tick(-2.0) for _ in range(6)]
    rises = np.diff(forces)
    assert rises.max() <= s * (1 + 1e-12)
    assert forces[2] == pytest.approx(s, rel=1e-12)             # the spring's one step
    assert forces[-1] == pytest.approx(2.0, rel=1e-12)          # then the wall's 2 N
    def spring():
        return float(st_["spring"][0]) if batch else pc._spring
    # out one count a tick to 0.5 mm, above the anchor (2 - 0.66 = 1.34 mm): the spring is 0
    # there, never a pull, and the anchor follows the reading out; back in by 0.2 mm, the
    # spring is K_c x 0.2 mm from where the anchor was left
    part = [tick(-2.0 + 0.01 * k) for k in range(1, 151)]
    assert min(part) >= 0.0 and spring() == 0.0
    again = [tick(-0.5 - 0.01 * k) for k in range(1, 21)]
    assert min(again) >= 0.0 and spring() == pytest.approx(0.2, rel=1e-9)
    out = [tick(-0.7 + 0.01 * k) for k in range(1, 120)]        # out one count a tick, past the surface
    assert min(out) >= 0.0 and out[-1] == 0.0
    back = [tick(-0.01 * k) for k in range(1, 51)]             # a slow press to 0.5 mm
    # the force is the spring alone, K_c x depth from the surface (the extra would fill in
    # for a spring anchored deeper: read the spring itself)
    assert back[-1] == pytest.approx(0.5, rel=1e-9) and spring() == pytest.approx(0.5, rel=1e-9)
