"""Phase-continuous vibration (goals 10-12): exact phase over 24 h, slope bound, ramps,
and the literal sin(2 pi f t) failing the same tests."""

from fractions import Fraction

import numpy as np
import pytest

from hapticsdk.synthesis import Oscillator, PhaseAccumulator, naive_phase, two_product


def test_two_product_is_exact():
    rng = np.random.default_rng(1)
    for a, b in rng.uniform(-1e3, 1e3, (200, 2)):
        p, e = two_product(float(a), float(b))
        assert Fraction(p) + Fraction(e) == Fraction(float(a)) * Fraction(float(b))


def test_phase_exact_after_24h_against_exact_integral():
    """Frequency changes every second for 24 h of simulated time (86 400 segments):
    phase within 1e-9 cycles of the exact rational integral of f."""
    rng = np.random.default_rng(7)
    f = rng.uniform(0.0, 1000.0, 86400)
    acc = PhaseAccumulator()
    exact = Fraction(0)
    dt = 1.0
    for fi in f:
        acc.advance(float(fi), dt)
        exact += Fraction(float(fi)) * Fraction(dt)
    got = Fraction(acc.cycles) + Fraction(acc.phase) + Fraction(acc._lo)
    assert abs(float(got - exact)) < 1e-9
    assert 0.0 <= acc.phase < 1.0


def test_phase_exact_per_tick_without_drift():
    """Per 1 ms tick with an awkward constant frequency, 10 simulated minutes: the
    error stays at rounding level (no systematic drift that would reach 1e-9 in 24 h),
    while plain float accumulation already drifts."""
    f, dt, n = 137.3, 1e-3, 600_000
    acc = PhaseAccumulator()
    naive = 0.0
    for _ in range(n):
        acc.advance(f, dt)
        naive = (naive + f * dt) % 1.0
    exact = Fraction(f) * Fraction(dt) * n
    err = abs(float(Fraction(acc.cycles) + Fraction(acc.phase) + Fraction(acc._lo) - exact))
    frac = exact - (exact.numerator // exact.denominator)
    naive_err = abs(float(Fraction(naive) - frac))
    assert err < 1e-15
    assert naive_err > 1000 * err  # plain accumulation drifts (~1e-11 here, ~1e-9 per day)


def _speed_profile(fs_out=10_000, servo=1_000, seconds=20.0):
    """f_p = Fpeak |v| / 80 with v = 100 sin(2 pi 0.5 t) mm/s, held per 1 kHz tick, plus steps."""
    t_tick = np.arange(int(seconds * servo)) / servo
    v = 100 * np.sin(2 * np.pi * 0.5 * t_tick)
    v[(t_tick > 5) & (t_tick < 6)] = 250.0  # speed step
    f_tick = 250.0 * np.abs(v) / 80.0
    per = fs_out // servo
    return f_tick, per, fs_out


def test_accumulator_meets_slope_bound_and_naive_fails():
    f_tick, per, fs = _speed_profile()
    V = 1.0
    osc = Oscillator(fs, ramp_s=0.005)
    osc.amplitude = V  # already at full amplitude: pure phase test
    y = np.concatenate([osc.render(float(fi), V, per) for fi in f_tick])
    f_samp = np.repeat(f_tick, per)
    bound = 2 * np.pi * f_samp.max() / fs * V + 1e-12
    assert np.abs(np.diff(y)).max() <= bound
    # instantaneous frequency from the unwrapped phase equals f_p (< 0.1 %)
    acc = PhaseAccumulator()
    cyc = []
    for fi in f_tick:
        for _ in range(per):
            acc.advance(float(fi), 1 / fs)
            cyc.append(acc.cycles + acc.phase)
    inst = np.diff(np.asarray(cyc)) * fs
    on = f_samp[1:] > 1.0
    assert np.max(np.abs(inst[on] - f_samp[1:][on]) / f_samp[1:][on]) < 1e-3
    # the literal formula V sin(2 pi f_p t) fails the same slope test
    t = np.arange(y.size) / fs
    y_naive = V * np.sin(2 * np.pi * naive_phase(f_samp, t))
    assert np.abs(np.diff(y_naive)).max() > 3 * bound  # full-scale clicks (~2 V)


def test_gate_ramps_have_no_clicks():
    """Goal 11: amplitude changes by at most V dt / tau per sample with tau >= 5 ms."""
    fs, V, tau = 8000.0, 40.0, 0.005
    osc = Oscillator(fs, ramp_s=tau, max_amplitude=V)
    gate = np.r_[np.zeros(20), np.ones(50), np.zeros(30), np.ones(3), np.zeros(20)]  # per 1 ms tick
    y, amps = [], []
    for g in gate:
        y.append(osc.render(230.0, V * g, 8))
        amps.append(osc.amplitude)
    y = np.concatenate(y)
    step = V / (tau * fs)
    assert osc.max_step == pytest.approx(step)
    # per-sample amplitude never jumps more than the ramp slope; sample jumps within the bound
    assert np.abs(np.diff(y)).max() <= 2 * np.pi * 230.0 / fs * V + step + 1e-9
    # a hard gate (no ramp) would click by ~V
    hard = np.concatenate([g * V * np.sin(2 * np.pi * 230.0 * (np.arange(8) + 8 * i) / fs) for i, g in enumerate(gate)])
    assert np.abs(np.diff(hard)).max() > 3 * (2 * np.pi * 230.0 / fs * V + step)


def test_block_phase_continuity_across_frequency_changes():
    osc = Oscillator(5000.0)
    osc.amplitude = 1.0
    a = osc.render(30.0, 1.0, 5)
    b = osc.render(120.0, 1.0, 5)
    # the first sample of the new block continues from the last phase of the previous one
    assert abs(b[0] - a[-1]) <= 2 * np.pi * 120.0 / 5000.0 + 1e-12
    assert 0.0 <= osc.acc.phase < 1.0


def test_a_silent_block_advances_the_phase_exactly_as_a_computed_one():
    """``Oscillator.render`` of a silent block advances the accumulator without computing
    the phases (``PhaseAccumulator.skip``); the sound after it is bit for bit the sound of
    an oscillator that computed them (issue 30), for random frequencies and block sizes."""
    import numpy as np

    from hapticsdk.synthesis import Oscillator
    rng = np.random.default_rng(30)
    for _ in range(50):
        fs = float(rng.choice([5000.0, 8000.0, 44100.0]))
        a, b = Oscillator(fs), Oscillator(fs)
        for _ in range(int(rng.integers(1, 6))):
            f, n = float(rng.uniform(1, 500)), int(rng.integers(1, 60))
            assert not a.render(f, 0.0, n).any()
            b.acc.block(f, n, fs)                          # the phases computed, then dropped
            b.frequency_hz = f
        assert (a.acc.phase, a.acc._lo, a.acc.cycles) == (b.acc.phase, b.acc._lo, b.acc.cycles)
        f, n = float(rng.uniform(1, 500)), int(rng.integers(1, 60))
        np.testing.assert_array_equal(a.render(f, 0.7, n), b.render(f, 0.7, n))
