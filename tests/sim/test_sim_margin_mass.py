"""Goal 1 with the apparent mass: the mass-corrected critical stiffness (exact ZOH boundary
for d = 0, second-order series in delta = b T / m for d >= 1) against the eigenvalue limit of
the exactly discretised device, in all 72 goal cells and beyond; mass None unchanged."""

import itertools

import numpy as np
import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.passivity import (
    PASSIVE,
    STABLE_BY_ASSUMPTION,
    classify_wall,
    critical_stiffness,
    critical_stiffness_eig,
    mass_correction,
    passivity_margin,
    spectral_radius,
)

CELLS = list(itertools.product((0.045, 0.2), (0.2, 0.5, 1.15, 2.0), (0.5e-3, 1e-3, 2e-3), (0, 1, 2)))


def test_all_72_goal_cells_within_half_a_percent_with_mass():
    worst = 0.0
    for m, b, T, d in CELLS:
        k = critical_stiffness(b, T, d, mass_kg=m)
        ke = critical_stiffness_eig(m, b, T, d)
        worst = max(worst, abs(k / ke - 1.0))
        assert k == pytest.approx(ke, rel=5e-3), (m, b, T, d)
        # closed loop: the device with the wall just inside / outside the predicted limit
        assert spectral_radius(0.995 * k, m, b, T, d) < 1.0 < spectral_radius(1.005 * k, m, b, T, d)
    assert worst < 1e-3  # measured 4e-5 (bisection tolerance of the eigenvalue limit is 1e-6)


def test_dropping_the_correction_fails_the_worst_cell():
    """m = 0.045 kg, b = 2 N*s/m, T = 2 ms, d = 2 (delta = 0.089): the plain formula is 3.5 %
    low, the mass-aware one is within 0.5 %; the correction is not a no-op."""
    m, b, T, d = 0.045, 2.0, 2e-3, 2
    ke = critical_stiffness_eig(m, b, T, d)
    plain, corr = critical_stiffness(b, T, d), critical_stiffness(b, T, d, mass_kg=m)
    assert abs(plain / ke - 1.0) > 0.03
    assert abs(corr / ke - 1.0) < 5e-3
    f = mass_correction(b, T, d, m)
    assert f == pytest.approx(corr / plain, rel=1e-12) and f > 1.03


@pytest.mark.parametrize("d", [0, 1, 2])
def test_first_order_coefficient_matches_eigenvalues(d):
    """(K_eig / K_colgate - 1) / delta -> (n^2 + 1) / (12 n), n = 2d + 1, as delta -> 0."""
    m, T, dl = 1.0, 1e-3, 0.01
    b = dl * m / T
    slope = (critical_stiffness_eig(m, b, T, d, rtol=1e-11) / critical_stiffness(b, T, d) - 1.0) / dl
    n = 2 * d + 1
    assert slope == pytest.approx((n * n + 1) / (12 * n), rel=0.02)
    assert (mass_correction(b, T, d, m) - 1.0) / dl == pytest.approx(slope, rel=0.01)


@pytest.mark.parametrize("dl", [1e-3, 0.1, 1.0, 3.0, 5.0, 10.0])
def test_d0_closed_form_is_exact_on_both_branches(dl):
    """d = 0: complex-pair crossing below delta ~ 3.8, z = -1 above; both exact."""
    m, T = 1.0, 1e-3
    b = dl * m / T
    ke = critical_stiffness_eig(m, b, T, 0, rtol=1e-10)
    assert critical_stiffness(b, T, 0, mass_kg=m) == pytest.approx(ke, rel=1e-7)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_series_is_conservative_and_never_below_plain(d):
    m, T = 1.0, 1e-3
    for dl in (0.05, 0.2, 0.5, 1.0, 3.0):
        b = dl * m / T
        k = critical_stiffness(b, T, d, mass_kg=m)
        assert critical_stiffness(b, T, d) <= k <= critical_stiffness_eig(m, b, T, d, rtol=1e-9) * (1 + 1e-8)
    # accurate where it is meant to be (delta <= 0.2)
    b = 0.2 * m / T
    assert critical_stiffness(b, T, d, mass_kg=m) == pytest.approx(
        critical_stiffness_eig(m, b, T, d, rtol=1e-9), rel=2e-3)


def test_mass_none_is_bit_for_bit_the_plain_formula():
    rng = np.random.default_rng(3)
    K, B, b = rng.uniform(0, 3, 50), rng.uniform(-1, 1, 50), rng.uniform(0, 3, 50)
    T, d = rng.choice([0.5e-3, 1e-3, 2e-3], 50), rng.integers(0, 3, 50)
    old = b - (K * 1000.0 * T * (0.5 + d) + np.abs(B))
    assert np.array_equal(passivity_margin(K, B, b, T, d), old)
    assert np.array_equal(passivity_margin(K, B, b, T, d, mass_kg=None), old)
    for i in range(50):
        assert passivity_margin(K[i], B[i], b[i], T[i], d[i]) == old[i]
        kc = max(b[i] - abs(B[i]), 0.0) / (T[i] * (0.5 + d[i])) / 1000.0
        assert critical_stiffness(b[i], T[i], int(d[i]), B[i]) == kc
    rep = classify_wall(2.3, 0.5, 1e-3)
    assert set(rep) == {"stiffness_n_per_mm", "virtual_damping_ns_per_m", "device_damping_ns_per_m",
                        "period_s", "delay_ticks", "margin_ns_per_m", "critical_stiffness_n_per_mm", "label"}
    assert rep["margin_ns_per_m"] == 0.5 - (2.3 * 1000.0 * 1e-3 * 0.5 + 0.0)


def test_margin_with_mass_is_zero_at_the_corrected_stiffness_and_broadcasts():
    for m, b, T, d in CELLS[::5]:
        for B in (0.0, -0.1, 0.15):
            kc = critical_stiffness(b, T, d, B, mass_kg=m)
            assert abs(passivity_margin(kc, B, b, T, d, mass_kg=m)) < 1e-12
            assert passivity_margin(0.99 * kc, B, b, T, d, mass_kg=m) > 0 > passivity_margin(1.01 * kc, B, b, T, d, mass_kg=m)
    # b_eff - (K T (1/2 + d) + |B|) with b_eff = |B| + (b - |B|) f
    f = mass_correction(2.0, 2e-3, 1, 0.045)
    assert passivity_margin(0.5, 0.3, 2.0, 2e-3, 1, mass_kg=0.045) == pytest.approx(
        0.3 + 1.7 * f - (500.0 * 2e-3 * 1.5 + 0.3), abs=1e-12)
    # broadcasting over K, b, T, d and the mass
    out = passivity_margin(np.array([0.1, 0.5, 1.0])[:, None], 0.0, np.array([0.5, 2.0]), 1e-3,
                           np.array([[0], [1], [2]]), mass_kg=np.array([0.045, 0.2]))
    assert out.shape == (3, 2)
    for i, j in itertools.product(range(3), range(2)):
        assert out[i, j] == passivity_margin([0.1, 0.5, 1.0][i], 0.0, [0.5, 2.0][j], 1e-3, i,
                                             mass_kg=[0.045, 0.2][j])
    # a huge mass gives the plain formula back
    assert passivity_margin(1.0, 0.0, 2.0, 1e-3, 1, mass_kg=1e9) == pytest.approx(
        passivity_margin(1.0, 0.0, 2.0, 1e-3, 1), abs=1e-9)


def test_classify_wall_keeps_the_passivity_label():
    """Between the plain and the mass-corrected K_crit the free device is stable but the wall
    is not passive: the label must stay 'stable-by-assumption'."""
    m, b, T, d = 0.045, 2.0, 2e-3, 2
    K = 0.5 * (critical_stiffness(b, T, d) + critical_stiffness(b, T, d, mass_kg=m))
    rep = classify_wall(K, b, T, d, mass_kg=m)
    assert rep["margin_ns_per_m"] < 0 < rep["stability_margin_ns_per_m"]
    assert rep["label"] == STABLE_BY_ASSUMPTION
    assert spectral_radius(K, m, b, T, d) < 1.0  # indeed stable uncoupled
    assert rep["stability_critical_stiffness_n_per_mm"] == critical_stiffness(b, T, d, mass_kg=m)
    assert rep["delta_bT_over_m"] == pytest.approx(b * T / m) and rep["mass_kg"] == m
    plain = classify_wall(K, b, T, d)
    assert all(rep[k] == v for k, v in plain.items())
    assert classify_wall(0.1, b, T, d, mass_kg=m)["label"] == PASSIVE


@pytest.mark.parametrize("bad", [0.0, -0.1, float("nan"), float("inf"), "heavy", [0.1, -1.0], []])
def test_bad_mass_is_a_validation_error(bad):
    calls = (lambda: passivity_margin(1.0, 0.0, 0.5, 1e-3, 0, mass_kg=bad),
             lambda: critical_stiffness(0.5, 1e-3, 0, mass_kg=bad),
             lambda: classify_wall(1.0, 0.5, 1e-3, mass_kg=bad),
             lambda: mass_correction(0.5, 1e-3, 0, bad))
    for call in calls:
        with pytest.raises(ValidationError) as ei:
            call()
        assert ei.value.field == "mass_kg"


def test_omni_reports_the_mass_corrected_limit():
    from hapticsdk_hardness.omni import OmniVirtual
    dev = OmniVirtual()
    rep = dev.passivity()
    k = rep["critical_stiffness_mass_corrected_n_per_mm"]
    assert k == critical_stiffness(dev.arm.damping_ns_per_m, 1e-3, 0, mass_kg=dev.arm.mass_kg)
    assert k > rep["critical_stiffness_n_per_mm"]
    assert k == pytest.approx(critical_stiffness_eig(dev.arm.mass_kg, dev.arm.damping_ns_per_m, 1e-3, 0), rel=1e-5)
    assert rep["label"] == STABLE_BY_ASSUMPTION  # unchanged (goal 6)


@pytest.mark.parametrize("kw, field", [
    ({"K": -1.0}, "K"), ({"K": float("nan")}, "K"), ({"K": float("inf")}, "K"),
    ({"b": -0.5}, "b"), ({"T": -0.001}, "T"), ({"T": 0.0}, "T"), ({"T": float("nan")}, "T"),
    ({"d": -1}, "d"), ({"d": 0.5}, "d"), ({"B": float("nan")}, "B"), ({"K": True}, "K"), ({"K": "2"}, "K"),
])
def test_classify_wall_refuses_nonsense_instead_of_calling_it_passive(kw, field):
    from hapticsdk.errors import ValidationError
    from hapticsdk.passivity import classify_wall
    args = {"K": 0.5, "b": 0.5, "T": 0.001, "d": 0, "B": 0.0}
    args.update(kw)
    with pytest.raises(ValidationError) as ei:
        classify_wall(**args)
    assert ei.value.field == field


def test_classify_wall_still_labels_valid_walls():
    from hapticsdk.passivity import classify_wall
    # 2b/T = 1 N/mm at b = 0.5 N*s/m, T = 1 ms: below it passive, above it not
    assert classify_wall(0.9, 0.5, 0.001)["label"] == "passive"
    assert classify_wall(1.1, 0.5, 0.001)["label"] != "passive"
    assert classify_wall(0.0, 0.0, 0.001, 2)["margin_ns_per_m"] == 0.0


_GOOD = {"K": 1.0, "B": 0.0, "b": 0.5, "T": 1e-3, "d": 0, "m": 0.045}
#: per argument, values that describe no wall: each must be refused by name, never turned
#: into a number (a negative period gave a margin of +500 N s/m, which reads as passive)
_BAD = {"K": [-1.0, float("nan"), float("inf")], "B": [float("nan"), float("inf")],
        "b": [-0.1, float("nan")], "T": [0.0, -1e-3, float("nan"), float("inf")], "d": [-1, 0.5],
        "m": [0.0, -0.045, float("nan")]}


@pytest.mark.parametrize("arg, value", [(a, v) for a, vs in _BAD.items() for v in vs])
def test_every_wall_function_refuses_a_nonsensical_argument_by_name(arg, value):
    from hapticsdk.errors import ValidationError
    from hapticsdk.passivity import critical_stiffness_eig, spectral_radius
    p = dict(_GOOD, **{arg: value})
    calls = {
        "passivity_margin": (lambda: passivity_margin(p["K"], p["B"], p["b"], p["T"], p["d"]), "KBbTd"),
        "passivity_margin, an array": (lambda: passivity_margin(np.array([0.5, p["K"]]), p["B"], p["b"],
                                                                np.array([1e-3, p["T"]]), p["d"]), "KBbTd"),
        "passivity_margin, mass": (lambda: passivity_margin(p["K"], p["B"], p["b"], p["T"], p["d"],
                                                            mass_kg=p["m"]), "KBbTdm"),
        "critical_stiffness": (lambda: critical_stiffness(p["b"], p["T"], p["d"], p["B"]), "BbTd"),
        "critical_stiffness, mass": (lambda: critical_stiffness(p["b"], p["T"], p["d"], p["B"], mass_kg=p["m"]),
                                     "BbTdm"),
        "mass_correction": (lambda: mass_correction(p["b"], p["T"], p["d"], p["m"]), "bTdm"),
        "classify_wall": (lambda: classify_wall(p["K"], p["b"], p["T"], p["d"], p["B"]), "KBbTd"),
        "spectral_radius": (lambda: spectral_radius(p["K"], p["m"], p["b"], p["T"], p["d"]), "KbTdm"),
        "critical_stiffness_eig": (lambda: critical_stiffness_eig(p["m"], p["b"], p["T"], p["d"]), "bTdm"),
    }
    field = "mass_kg" if arg == "m" else arg
    for name, (call, reads) in calls.items():
        if arg not in reads:
            continue
        with pytest.raises(ValidationError) as ei:
            call()
        assert ei.value.field == field, name
    # the same calls with the good values give numbers
    assert passivity_margin(**{k: _GOOD[k] for k in "KBbTd"}) == pytest.approx(0.0, abs=1e-12)
