"""Hands-off damping calibration, edges of its documented contract: the excitation's
shape (doublets +F, -F, -F, +F of tau each, then a rest of 4 tau), the decay terms
h = int_0^T e^{-alpha s} ds and g = int_0^T h(s) ds against their power series, and the
fit's uncertainty: a declared encoder resolution never makes it more certain, and
anti-correlated residuals do not shrink it (only rho > 0 inflates)."""

import math

import numpy as np
import pytest

from hapticsdk.calibration.damping import _hg, excitation, fit_damping
from hapticsdk.sim.arm import ArmParams, free_arm_readings_mm

T = 1e-3


def _runs(values):
    """(value, length) of the runs of equal consecutive values."""
    edges = np.flatnonzero(np.diff(values)) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges, [values.size]])
    return [(float(values[s]), int(e - s)) for s, e in zip(starts, ends)]


def test_each_doublet_pair_is_followed_by_a_rest_of_four_segments():
    f = excitation(T, 3.3, 0.045)
    runs = _runs(f)
    tau = runs[0][1]
    assert runs[0][0] > 0 and runs[1] == (-runs[0][0], 2 * tau) and runs[2] == (runs[0][0], tau)
    assert runs[3] == (0.0, 4 * tau)
    assert f.size % (8 * tau) == 0  # whole patterns of 8 tau


@pytest.mark.parametrize("x", [1e-6, 1e-3, 0.05])
def test_decay_terms_meet_their_power_series(x):
    alpha = x / T
    a, h, g = _hg(alpha, T)
    # h = T sum (-x)^k/(k+1)!, g = T^2 sum (-x)^k/(k+2)!; 25 terms: remainder < x^25/25! ~ 0
    hs = T * sum((-x) ** k / math.factorial(k + 1) for k in range(25))
    gs = T * T * sum((-x) ** k / math.factorial(k + 2) for k in range(25))
    # 1e-12 relative: a few ulps of the closed form (its (T - h)/alpha loses ~log10(1/x) digits)
    assert a == pytest.approx(math.exp(-x), rel=1e-15)
    assert h == pytest.approx(hs, rel=1e-12) and g == pytest.approx(gs, rel=1e-12)


def _exact_run():
    arm = ArmParams(mass_kg=0.045, damping_ns_per_m=0.8, encoder_resolution_mm=0.0)
    f = excitation(T, arm.max_force_n, arm.mass_kg)
    return f, free_arm_readings_mm(T, arm, f)


def test_a_declared_resolution_never_narrows_the_fit():
    f, y = _exact_run()  # readings without quantisation: the model explains them to rounding
    exact = fit_damping(f, y, T, 0.0)
    coarse = fit_damping(f, y, T, 0.055)
    assert exact.success and coarse.success
    assert coarse.damping_se_ns_per_m > exact.damping_se_ns_per_m


def test_anti_correlated_residuals_do_not_shrink_the_standard_error():
    f, y = _exact_run()
    e = 0.01  # mm of reading error, the same size both ways
    alternating = y + e * (-1.0) ** np.arange(y.size)
    white = y + e * np.random.default_rng(5).choice([-1.0, 1.0], y.size)
    se_alt = fit_damping(f, alternating, T).damping_se_ns_per_m
    se_white = fit_damping(f, white, T).damping_se_ns_per_m
    # same residual size: the same variance, uninflated for rho <= 0 (white rho ~ +-1/sqrt(N)
    # inflates it by a few % at most); a deflation for rho ~ -1 would cut it ~50x
    assert se_alt > 0.5 * se_white
