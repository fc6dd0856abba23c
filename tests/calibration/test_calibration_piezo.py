"""Piezo Tab: built from (frequency, voltage, acceleration) measurements, inverted with a
monotone interpolant, round trip within 1 % inside the measured range, flagged outside."""

from __future__ import annotations

import numpy as np
import pytest

from hapticsdk.calibration import PiezoTable, read_measurements_csv, table_from_measurements
from hapticsdk.errors import CalibrationError


def resonator(f, v, f0=250.0, zeta=0.35, d=0.36e-6, soft=0.08, vmax=100.0):
    """Synthetic piezo for the test (a driven damped resonator, softening with voltage):
    acceleration amplitude (m/s^2) at f (Hz), v (V peak). Test data, not a measurement."""
    r = f / f0
    x = d * v * (1 - soft * (v / vmax) ** 2) / np.sqrt((1 - r ** 2) ** 2 + (2 * zeta * r) ** 2)
    return (2 * np.pi * f) ** 2 * x


@pytest.fixture(scope="module")
def table():
    f = np.arange(20.0, 401.0, 20.0)
    v = np.arange(0.0, 100.1, 10.0)
    ff, vv = np.meshgrid(f, v, indexing="ij")
    return table_from_measurements(ff.ravel(), vv.ravel(), resonator(ff, vv).ravel(), source="test resonator")


def test_round_trip_within_one_percent_inside_range(table):
    rng = np.random.default_rng(0)
    f = rng.uniform(20.0, 400.0, 200)
    frac = rng.uniform(0.02, 0.98, 200)
    rel_table, rel_true = [], []
    for fi, q in zip(f, frac):
        target = q * table.acceleration_at(fi, 100.0)
        volts, ok = table.voltage_for(fi, target)
        assert ok and 0.0 <= volts <= 100.0
        rel_table.append(abs(table.acceleration_at(fi, volts) - target) / target)
        rel_true.append(abs(resonator(fi, volts) - target) / target)  # drive the "device"
    assert max(rel_table) < 1e-6
    assert max(rel_true) < 0.01


def saturating(v, f=100.0):
    """Synthetic piezo saturating with voltage (tanh), test data."""
    return (f / 100.0) * 40.0 * np.tanh(v / 50.0)


def test_monotone_cubic_beats_linear_on_a_curved_response():
    """On measured frequencies, the monotone cubic in voltage follows a saturating
    response within 1 % where straight lines between the same points do not."""
    f = np.array([100.0, 200.0])
    v = np.linspace(0.0, 100.0, 11)  # 10 V steps
    t = PiezoTable(f, v, saturating(v[None, :], f[:, None]))
    targets = saturating(np.linspace(3, 97, 40))
    volts = np.array([t.voltage_for(100.0, x)[0] for x in targets])
    linear = np.interp(targets, saturating(v), v)
    err = np.max(np.abs(saturating(volts) - targets) / targets)
    err_lin = np.max(np.abs(saturating(linear) - targets) / targets)
    assert err < 0.01 < err_lin


def test_kinked_data_stay_monotone():
    """Data a spline would overshoot fall back to PCHIP: still increasing, still inverted."""
    v = np.array([0.0, 10.0, 20.0, 30.0, 40.0, 100.0])
    row = np.array([0.0, 0.1, 0.2, 10.0, 10.1, 10.2])
    t = PiezoTable(np.array([50.0, 60.0]), v, np.vstack([row, row]))
    grid = np.linspace(0, 100, 2001)
    acc = np.array([t.acceleration_at(50.0, x) for x in grid])
    assert np.all(np.diff(acc) >= 0)
    for target in (0.15, 5.0, 10.05):
        volts, ok = t.voltage_for(50.0, target)
        assert ok and t.acceleration_at(50.0, volts) == pytest.approx(target, rel=1e-9)


def test_outside_range_is_clamped_and_flagged(table):
    top = table.acceleration_at(100.0, 100.0)
    v, ok = table.voltage_for(100.0, 2 * top)
    assert v == 100.0 and not ok
    v, ok = table.voltage_for(1000.0, 1.0)  # frequency above the table
    assert not ok and 0 <= v <= 100.0
    v, ok = table.voltage_for(100.0, 0.0)
    assert v == 0.0 and ok
    vs, oks = table.voltages_for([100.0, 100.0], [top / 2, 2 * top])
    assert oks.tolist() == [True, False] and vs[1] == 100.0


def test_measurement_csv_and_repeats(tmp_path):
    f = np.repeat([50.0, 150.0, 300.0], 3)
    v = np.tile([0.0, 50.0, 100.0], 3)
    a = resonator(f, v)
    p = tmp_path / "m.csv"
    rows = [f"{fi},{vi},{ai * 1.01}\n{fi},{vi},{ai * 0.99}" for fi, vi, ai in zip(f, v, a)]
    p.write_text("# bench run 3\nfrequency_hz,voltage_v,acceleration_m_s2\n" + "\n".join(rows) + "\n")
    t = read_measurements_csv(p)
    np.testing.assert_allclose(t.acceleration, a.reshape(3, 3), rtol=1e-12)  # repeats averaged
    assert not t.generated and "bench run 3" in t.source
    with pytest.raises(CalibrationError, match="cover the grid"):
        table_from_measurements(f[:-1], v[:-1], a[:-1])
    with pytest.raises(CalibrationError):
        PiezoTable([50.0, 100.0], [0.0, 10.0], [[0.0, 1.0], [2.0, 1.0]])  # not increasing in voltage


def test_dict_round_trip(table):
    t2 = PiezoTable.from_dict(table.to_dict())
    assert t2.voltage_for(123.0, 5.0) == table.voltage_for(123.0, 5.0)


def test_accelerations_at_matches_the_curve_per_frequency(table):
    """The vectorised sweep (used by the roughness amplitude constraint) gives what the
    per-frequency curve gives, at measured and in-between voltages, also for frequencies
    outside the table (clamped)."""
    fs = np.linspace(5.0, 450.0, 157)
    for volts in (0.0, 30.0, 100.0, 137.0, 45.5):
        per_f = np.array([float(table._curve(f)(min(volts, 100.0))) for f in fs])
        sweep = table.accelerations_at(fs, volts)
        np.testing.assert_allclose(sweep, per_f, rtol=1e-12, atol=1e-12)
        single = np.array([table.acceleration_at(f, volts) for f in fs])
        np.testing.assert_allclose(single, per_f, rtol=1e-12, atol=1e-12)
