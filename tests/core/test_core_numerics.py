"""The numpy replacements of the scipy functions the start-up path used:
``hapticsdk.linalg.expm``, ``hapticsdk.special.gammainc2`` and the interpolants of
``hapticsdk.interpolate``.

References are independent of the code under test: the matrix exponential and P(2, x)
are evaluated in 50-400 digit decimal arithmetic (``decimal``), and scipy is compared as a
second opinion (tests may import scipy; the SDK's start-up path does not).
"""

from __future__ import annotations

from decimal import Decimal, localcontext

import numpy as np
import pytest
import scipy.interpolate
import scipy.linalg
import scipy.special

from hapticsdk.interpolate import CubicSpline, Pchip, bisect_increasing
from hapticsdk.linalg import expm
from hapticsdk.sim.arm import ArmParams, _augmented
from hapticsdk.sim.finger import FINGERS, FingerParams
from hapticsdk.special import gammainc2

U = 2.0 ** -53  # unit roundoff of float64


def _decimal_expm(A: np.ndarray, digits: int = 50) -> np.ndarray:
    """e^A by a 40-term Taylor series of A / 2^s (||A / 2^s||_1 <= 1/8, so the tail is
    below 8^-40) squared s times, all in ``digits``-digit decimal arithmetic. Squaring
    amplifies the relative error by at most 2^s (< 2^25 here): ~40 digits remain."""
    n = A.shape[0]
    with localcontext() as ctx:
        ctx.prec = digits
        M = [[Decimal(float(A[i, j])) for j in range(n)] for i in range(n)]
        norm = max(sum(abs(M[i][j]) for i in range(n)) for j in range(n))
        s = 0
        while norm > Decimal("0.125"):
            norm /= 2
            s += 1
        scale = Decimal(2) ** s
        M = [[x / scale for x in row] for row in M]

        def mul(X, Y):
            return [[sum(X[i][k] * Y[k][j] for k in range(n)) for j in range(n)] for i in range(n)]

        E = [[Decimal(int(i == j)) for j in range(n)] for i in range(n)]
        T = [row[:] for row in E]
        for k in range(1, 41):
            T = [[x / k for x in row] for row in mul(T, M)]
            E = [[E[i][j] + T[i][j] for j in range(n)] for i in range(n)]
        for _ in range(s):
            E = mul(E, E)
        return np.array([[float(x) for x in row] for row in E])


def _tolerance(A: np.ndarray) -> float:
    """Relative Frobenius error allowed for e^A: the Pade degree and scaling are chosen so
    the backward error is at most u, which the relative condition number kappa of the
    exponential (scipy's ``expm_cond``) turns into a forward error kappa*u; rounding the
    n-term sums of the evaluation adds about n*u. Allowed: 10x that sum."""
    kappa = float(scipy.linalg.expm_cond(A))
    return 10.0 * (kappa + A.shape[0]) * U


def _sdk_matrices():
    """The matrices the SDK exponentiates: the arm's augmented 5x5 (sim.arm) for the soft
    and stiff finger presets and a free arm, zero and large damping, periods 1 us .. 10 s;
    the Van Loan 10x10 of the dissipation Gramian; passivity's 3x3 ZOH device."""
    out = []
    cases = [("stiff", 0.0, 1e-6), ("stiff", 0.0, 1e-3), ("stiff", 0.5, 10.0), ("soft", 0.0, 10.0),
             ("soft", 0.5, 1e-3), ("free", 0.0, 1e-3), ("free", 5.0, 0.1)]
    for fname, b, T in cases:
        f = FINGERS.get(fname, FingerParams(0.0, 0.0, 0.0))
        out.append((f"arm-{fname}-b{b}-T{T}", _augmented(ArmParams(damping_ns_per_m=b), f) * T))
    for fname, b, T in (("stiff", 0.0, 2e-3), ("free", 0.5, 1e-6)):
        A = _augmented(ArmParams(damping_ns_per_m=b), FINGERS.get(fname, FingerParams(0.0, 0.0, 0.0)))
        C = np.zeros((10, 10))
        C[:5, :5] = -A.T
        C[1, 6] = 1.0
        C[5:, 5:] = A
        out.append((f"gramian-{fname}-b{b}-T{T}", C * T))
    for m, b, T in ((0.045, 0.0, 1e-3), (0.045, 0.5, 1e-6), (0.5, 5.0, 10.0)):
        M = np.zeros((3, 3))
        M[0, 1], M[1, 1], M[1, 2] = 1.0, -b / m, 1.0 / m
        out.append((f"zoh-m{m}-b{b}-T{T}", M * T))
    return out


SDK = _sdk_matrices()
_TOL: dict[str, float] = {}


def _sdk_tolerance(name: str, A: np.ndarray) -> float:
    if name not in _TOL:  # expm_cond costs 0.1-0.5 s: once per matrix
        _TOL[name] = _tolerance(A)
    return _TOL[name]


@pytest.mark.parametrize("name, A", SDK, ids=[n for n, _ in SDK])
def test_expm_of_the_sdk_matrices_matches_a_50_digit_reference(name, A):
    ref = _decimal_expm(A)
    got = expm(A)
    err = np.linalg.norm(got - ref) / np.linalg.norm(ref)
    assert err <= _sdk_tolerance(name, A), (name, err, _sdk_tolerance(name, A))


@pytest.mark.parametrize("name, A", SDK, ids=[n for n, _ in SDK])
def test_expm_of_the_sdk_matrices_agrees_with_scipy(name, A):
    """scipy's own result is measured up to ~65 kappa*u from the decimal reference on these
    matrices (its algorithm differs), so agreement is asked within 20x the bound above."""
    want = scipy.linalg.expm(A)
    err = np.linalg.norm(expm(A) - want) / np.linalg.norm(want)
    assert err <= 20.0 * _sdk_tolerance(name, A), (name, err)


@pytest.mark.parametrize("n, scale", [(2, 1e-9), (3, 4e-3), (4, 0.05), (3, 0.3), (5, 0.5),
                                      (3, 1.0), (4, 2.5), (6, 12.0), (2, 60.0)])
def test_expm_of_random_matrices_matches_a_50_digit_reference(n, scale):
    """Scales put the 1-norm in every Pade-degree band (3, 5, 7, 9, 13) and above theta_13
    (scaling and squaring)."""
    rng = np.random.default_rng(int(n * 1000 + scale * 100))
    for _ in range(1):
        A = rng.standard_normal((n, n)) * scale
        ref = _decimal_expm(A)
        err = np.linalg.norm(expm(A) - ref) / np.linalg.norm(ref)
        assert err <= _tolerance(A), (n, scale, err, _tolerance(A))


def test_expm_exact_cases_and_input_checks():
    assert np.array_equal(expm(np.zeros((4, 4))), np.eye(4))
    d = np.diag([-3.0, 0.5, 7.0])
    np.testing.assert_allclose(expm(d), np.diag(np.exp([-3.0, 0.5, 7.0])), rtol=4 * U * 7.0 * 3)
    # a rotation generator: e^{[[0, -t], [t, 0]]} = [[cos t, -sin t], [sin t, cos t]]
    t = 40.0  # 1-norm 40: scaled and squared 3 times
    R = expm(np.array([[0.0, -t], [t, 0.0]]))
    np.testing.assert_allclose(R, [[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]], atol=10 * (t + 2) * U)
    with pytest.raises(ValueError):
        expm(np.ones((2, 3)))
    with pytest.raises(ValueError):
        expm(np.array([[np.nan, 0.0], [0.0, 1.0]]))


def _decimal_p2(x: float) -> float:
    """P(2, x) = 1 - e^-x (1 + x) in 400 digits: exact to double precision for
    x >= 1e-180 (the 1 cancels against ~360 leading digits at most)."""
    with localcontext() as ctx:
        ctx.prec = 400
        d = Decimal(float(x))
        return float(1 - (-d).exp() * (1 + d))


def test_gammainc2_matches_a_400_digit_reference_from_tiny_to_huge_x():
    """Allowed: 10 u relative. Where the closed form is used (x >= 1) it is
    ``1 - e^-x (1 + x)`` with e^-x (1 + x) carrying ~3 u, amplified at most by
    e^-1 * 2 / P(2, 1) = 2.8 by the subtraction (< 9.4 u); below, the series of
    positive terms carries a few u."""
    xs = np.concatenate([np.logspace(-150, 3, 400),
                         [0.5, 1.0 - 2**-52, 1.0, 1.0 + 2**-52, 2.0, 30.0, 700.0, 745.0, 1e4, 1e300]])
    ref = np.array([_decimal_p2(x) for x in xs])
    got = gammainc2(xs)
    assert np.all(np.abs(got - ref) <= 10 * U * ref)
    assert gammainc2(0.0) == 0.0 and gammainc2(np.inf) == 1.0
    assert np.isnan(gammainc2(-1.0)) and np.isnan(gammainc2(np.nan))
    assert isinstance(gammainc2(0.3), float) and gammainc2(np.ones((2, 3))).shape == (2, 3)


def test_gammainc2_agrees_with_scipy():
    """scipy's gammainc(2, x) is itself off by up to ~6e-14 relative at small x (against
    the decimal reference above; e.g. 4e-15 at x = 1e-8), so agreement is asked to 1e-12."""
    xs = np.logspace(-150, 3, 2001)
    want = scipy.special.gammainc(2.0, xs)
    assert np.all(np.abs(gammainc2(xs) - want) <= 1e-12 * want)


def _random_knots(rng, n):
    while True:
        x = np.sort(rng.uniform(-5.0, 5.0, n))
        if np.all(np.diff(x) > 1e-2):
            return x


def test_pchip_is_scipys_pchip_to_the_last_bit():
    """Same formulas evaluated in the same order: identical values (and NaN outside)."""
    rng = np.random.default_rng(7)
    for trial in range(60):
        n = int(rng.integers(2, 25))
        x = _random_knots(rng, n)
        y = rng.standard_normal((n, 3)) * 10.0 ** rng.integers(-3, 4)
        if trial % 3 == 0:
            y = np.cumsum(np.abs(y), axis=0)   # monotone columns
        if trial % 4 == 0 and n > 3:
            y[2] = y[1]                         # a flat interval
        xq = np.concatenate([rng.uniform(x[0] - 1, x[-1] + 1, 300), x])
        want = scipy.interpolate.PchipInterpolator(x, y, axis=0, extrapolate=False)(xq)
        got = Pchip(x, y)(xq)
        assert np.array_equal(got, want, equal_nan=True), trial
        assert np.array_equal(Pchip(x, y[:, 0])(xq), want[:, 0], equal_nan=True)


def test_cubic_spline_matches_scipys_not_a_knot_spline():
    """A dense solve instead of scipy's banded one: the knot slopes differ by rounding,
    amplified by the system's condition number (< 10 for knot spacings within a factor
    100 of each other): 1e-12 of the data's scale."""
    rng = np.random.default_rng(11)
    for trial in range(60):
        n = int(rng.integers(4, 45))
        x = _random_knots(rng, n)
        y = rng.standard_normal(n) * 10.0 ** rng.integers(-3, 4)
        xq = np.concatenate([rng.uniform(x[0] - 1, x[-1] + 1, 300), x])
        ref = scipy.interpolate.CubicSpline(x, y, extrapolate=False)
        got = CubicSpline(x, y)
        assert got.c.shape == ref.c.shape
        w = ref(xq)
        assert np.array_equal(np.isnan(got(xq)), np.isnan(w))
        ok = ~np.isnan(w)
        assert np.max(np.abs(got(xq)[ok] - w[ok])) <= 1e-12 * np.abs(y).max(), trial


def test_bisect_increasing_finds_the_root_to_the_tolerance():
    f = np.cbrt
    for target in (-1.7, 0.0, 0.3, 2.0):
        x = bisect_increasing(lambda v: float(f(v)), -10.0, 10.0, target, xtol=1e-12, rtol=1e-12)
        assert abs(x - target ** 3) <= 1e-12 + 1e-12 * abs(target ** 3)


def test_piece_is_the_interpolant_on_plain_floats_to_the_last_bit():
    """piece(k) evaluates interval k's cubic on Python floats in the order of
    __call__: IEEE double operations in the same order give the same bits, for PCHIP
    and the spline, 1-D and one-column data; strictly inside and at the left knot."""
    rng = np.random.default_rng(5)
    for trial in range(40):
        n = int(rng.integers(4, 20))
        x = _random_knots(rng, n)
        y = rng.standard_normal(n) * 10.0 ** rng.integers(-3, 4)
        for interp in (Pchip(x, y), CubicSpline(x, y), Pchip(x, y[:, None])):
            for k in range(n - 1):
                cubic = interp.piece(k)
                pts = np.concatenate([[x[k]], rng.uniform(x[k], x[k + 1], 7)])
                pts = pts[pts < x[k + 1]]
                want = np.asarray(interp(pts)).reshape(-1)
                got = np.array([cubic(float(p)) for p in pts])
                assert np.array_equal(got, want), (trial, k)
    with pytest.raises(ValueError):
        Pchip(x, np.c_[y, y]).piece(0)      # two columns: no single cubic
    with pytest.raises(ValueError):
        Pchip(x, y).piece(n - 1)            # one past the last interval
