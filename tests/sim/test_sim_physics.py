"""Simulated arm physics: exact ZOH integration checked against scipy's stiff
integrators, energy bookkeeping, trajectories and the kinematic probe."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import settings as hsettings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from hapticsdk.sim.arm import (ArmBatch, ArmParams, ArmSim, derivative, dissipation_gramians,
                               transition_matrices)
from hapticsdk.sim.finger import FingerParams, Trajectory, press_slide, quasi_static_press, standard_set, taps
from hapticsdk.sim.probe import VirtualProbe

# stiff finger: eigenvalues ~ -3.6e4 and -5e2 1/s (stiffness ratio ~70)
STIFF = FingerParams(mass_kg=0.01, stiffness_n_per_m=1.0e6, damping_ns_per_m=2000.0)
ARM = ArmParams(mass_kg=0.045, damping_ns_per_m=0.5, encoder_resolution_mm=0.0)


def _zoh_run(period=1e-3, n=40, K=2.3):
    """Exact sim of a ZOH spring wall; returns the tick times, positions (m), forces and refs."""
    tr = Trajectory([(0, 0, 0.2), (0.01, 0, -2.0), (0.025, 0, -2.0), (0.04, 0, 0.5)])
    sim = ArmSim(ARM, STIFF, period, y0_mm=1.0)
    ys, fs, r0s, rds = [sim.y], [], [], []
    for k in range(n):
        t = k * period
        y_mm = sim.y * 1e3
        f = K * max(-y_mm, 0.0)
        _, r0, _, _ = tr.at(t)
        _, r1, _, _ = tr.at(t + period)
        rd = (r1 - r0) / period
        fs.append(sim.step(period, f, r0, rd))
        r0s.append(r0)
        rds.append(rd)
        ys.append(sim.y)
    return np.array(ys), np.array(fs), np.array(r0s), np.array(rds)


@pytest.mark.parametrize("method, tol_m", [("Radau", 1e-9), ("BDF", 1e-8)])
def test_exact_step_matches_stiff_reference_integrator(method, tol_m):
    """Same held forces and finger reference, integrated interval by interval with a
    stiff scipy solver at tight tolerance: the exact ZOH step agrees to tol (m)."""
    period = 1e-3
    ys, fs, r0s, rds = _zoh_run(period)
    z = np.array([ys[0], 0.0, 0.0, 0.0, 0.0])
    worst = 0.0
    for k in range(fs.size):
        z = np.array([z[0], z[1], r0s[k] * 1e-3, rds[k] * 1e-3, fs[k]])  # SI
        sol = solve_ivp(lambda t, zz: derivative(zz, ARM, STIFF), (0.0, period), z, method=method,
                        rtol=1e-9, atol=1e-13, jac=lambda t, zz: _jac())
        z = sol.y[:, -1]
        worst = max(worst, abs(z[0] - ys[k + 1]))
    assert worst < tol_m, f"{method}: max |y_exact - y_ref| = {worst:.3e} m"
    # the wall was actually pressed (the comparison covers contact)
    assert fs.max() > 1.0


def _jac():
    M = ARM.mass_kg + STIFF.mass_kg
    A = np.zeros((5, 5))
    A[0, 1] = 1
    A[1] = [-STIFF.stiffness_n_per_m / M, -(ARM.damping_ns_per_m + STIFF.damping_ns_per_m) / M,
            STIFF.stiffness_n_per_m / M, STIFF.damping_ns_per_m / M, 1 / M]
    A[2, 3] = 1
    return A


def test_explicit_euler_is_not_stable_on_the_stiff_case():
    """The stiff case really is stiff: forward Euler at the servo period diverges."""
    A = _jac()
    rho = np.max(np.abs(np.linalg.eigvals(np.eye(5) + A * 1e-3)))
    assert rho > 1.0
    # while the exact transition is contractive on the arm states
    P = expm(A * 1e-3)
    assert np.max(np.abs(np.linalg.eigvals(P[:2, :2]))) < 1.0


def test_batch_matches_scalar():
    arms = [ARM, ARM.with_(damping_ns_per_m=0.0), ARM.with_(mass_kg=0.2)]
    fingers = [STIFF, FingerParams(), FingerParams(0.0, 0.0, 0.0)]
    b = ArmBatch(1e-3, arms, fingers, y0_mm=0.5)
    sims = [ArmSim(a, f, 1e-3, 0.5) for a, f in zip(arms, fingers)]
    rng = np.random.default_rng(0)
    for _ in range(200):
        f = rng.uniform(-4, 4, 3)
        r = rng.uniform(-2, 2, 3)
        rd = rng.uniform(-50, 50, 3)
        fa = b.step(f, r, rd)
        for i, s in enumerate(sims):
            assert s.step(1e-3, f[i], r[i], rd[i]) == pytest.approx(fa[i])
    assert np.allclose(b.y, [s.y for s in sims], rtol=1e-12, atol=1e-15)
    assert np.all(np.abs(fa) <= 3.3)


def test_dissipation_gramian_is_the_integral_of_v_squared():
    arm, fg = ARM, FingerParams()
    T = 2e-3
    G = dissipation_gramians(T, [arm], [fg])[0]
    P = transition_matrices(T / 2000, [arm], [fg])[0]
    z0 = np.array([-1e-3, 0.05, -3e-3, 0.02, 1.5])
    # fine quadrature of v(s)^2 with the exact sub-step transition (Simpson)
    zs = [z0]
    for _ in range(2000):
        z = zs[-1]
        yv = P @ z
        zs.append(np.array([yv[0], yv[1], z[2] + z[3] * T / 2000, z[3], z[4]]))
    v = np.array([z[1] for z in zs])
    h = T / 2000
    simpson = h / 3 * (v[0] ** 2 + v[-1] ** 2 + 4 * np.sum(v[1:-1:2] ** 2) + 2 * np.sum(v[2:-1:2] ** 2))
    assert z0 @ G @ z0 == pytest.approx(simpson, rel=1e-8)


def test_energy_bookkeeping_free_decay_is_exact():
    """No finger, no wall force: kinetic energy lost == damper energy (exact to rounding)."""
    arm = ArmParams(mass_kg=0.05, damping_ns_per_m=0.7, encoder_resolution_mm=0.0)
    b = ArmBatch(1e-3, [arm], [FingerParams(0.0, 0.0, 0.0)], y0_mm=0.0, track_energy=True)
    b.v[:] = 0.2
    ke0 = 0.5 * arm.mass_kg * 0.2 ** 2
    for _ in range(500):
        b.step(np.zeros(1), np.zeros(1), np.zeros(1))
    ke = 0.5 * arm.mass_kg * b.v[0] ** 2
    assert ke0 - ke == pytest.approx(b.damper_j[0], rel=1e-9)


def test_encoder_quantisation():
    b = ArmBatch(1e-3, [ArmParams()], [FingerParams()], y0_mm=-0.1)
    assert b.measured_mm()[0] == pytest.approx(-0.11)
    s = ArmSim(ArmParams(), FingerParams(), 1e-3, -0.1)
    assert s.measured_mm() == pytest.approx(-0.11)


def test_press_slide_trajectory_shape():
    tr = press_slide(depth_mm=2.0, speed_mm_s=80.0, slide_s=1.0)
    t = np.linspace(0, tr.duration_s, 20001)
    x, y = tr.position(t)
    vx, vy = tr.velocity(t)
    assert y.min() == pytest.approx(-2.0)
    assert vx.max() == pytest.approx(80.0)
    assert x[-1] == pytest.approx(80.0)
    # scalar fast path agrees with the vectorised one
    pts = np.array([tr.at(float(tt)) for tt in t[::97]])
    assert np.allclose(pts[:, 0], x[::97]) and np.allclose(pts[:, 1], y[::97])
    assert np.allclose(pts[:, 2], vx[::97]) and np.allclose(pts[:, 3], vy[::97])


def test_taps_and_standard_set():
    tr = taps(n=4, depth_mm=1.0)
    _, y = tr.position(np.linspace(0, tr.duration_s, 5001))
    assert np.sum(np.diff((y < 0).astype(int)) == 1) == 4
    trs = standard_set(10.0)
    assert len(trs) >= 6 and all(t.duration_s >= 10.0 for t in trs)
    qs = quasi_static_press(speed_mm_s=5.0)
    assert np.abs(qs.velocity(np.linspace(0, qs.duration_s, 100))[1]).max() <= 5.0 + 1e-9


def test_virtual_probe_follows_trajectory_and_ignores_force():
    from hapticsdk.perception.dimensions import ChannelCommand
    tr = press_slide()
    p = VirtualProbe(trajectory=tr)
    p.open()
    for k in range(600):
        st = p.read_state()
        x, y, vx, vy = tr.at(k * 1e-3)
        assert st.position_mm[1] == pytest.approx(y, abs=1e-12)
        assert st.velocity_mm_s[0] == pytest.approx(vx)
        p.command(ChannelCommand("force", force_n=0.5), now=k * 1e-3)
        p.step(1e-3)
    assert p.read_state().penetration_mm > 1.0  # pressed in at 0.6 s whatever the force
    p.close()


def test_virtual_probe_entry_point():
    from hapticsdk.plugins import registry
    assert registry("actuator").load("probe-virtual") is VirtualProbe


@hsettings(max_examples=40, deadline=None)
@given(press=st.floats(0.05, 1.0), slide=st.floats(0.01, 2.0), gap=st.floats(0.0, 0.1),
       copies=st.floats(0.0, 12.0), z=st.booleans())
def test_repeated_is_chained_then(press, slide, gap, copies, z):
    """``Trajectory.repeated`` gives exactly the knots of chaining ``then`` (same floats),
    for paths with and without a z column."""
    cycle = press_slide(press_s=press, slide_s=slide)
    if z:
        cycle = Trajectory(np.column_stack([cycle.t, cycle.x, cycle.y, cycle.x * 0.5]))
    until = copies * cycle.duration_s
    chained = cycle
    while chained.duration_s < until:
        chained = chained.then(cycle, gap_s=gap)
    got = cycle.repeated(lambda d: d < until, gap_s=gap)
    for a in ("t", "x", "y", "z"):
        assert np.array_equal(getattr(got, a), getattr(chained, a)), a
    assert got.has_z == chained.has_z


@pytest.mark.parametrize("period", [0.0, -1e-3, float("nan"), float("inf")])
def test_a_period_that_is_not_a_positive_number_is_named(period):
    """The exact zero-order-hold step needs a period > 0: 0 (a step that goes nowhere),
    negative, NaN and infinite periods are named, not returned as a matrix."""
    from hapticsdk.errors import ValidationError
    from hapticsdk.sim.arm import ArmParams, transition_matrices
    from hapticsdk.sim.finger import FingerParams
    with pytest.raises(ValidationError) as ei:
        transition_matrices(period, [ArmParams()], [FingerParams()])
    assert ei.value.field == "period_s"
