"""The device-amplitude constraint never promises more acceleration than the drive table
gives: its interpolated bound stays at or below the table between its grid points."""

import numpy as np
import pytest

pytest.importorskip("hapticsdk_roughness")


@pytest.mark.parametrize("f_range,volts", [((40.0, 200.0), 25.0), ((7.8125, 1992.19), 50.0), ((20.0, 400.0), 50.0)])
def test_interpolated_bound_is_never_above_the_table(f_range, volts):
    from hapticsdk_roughness.dimension import DeviceAmplitudeConstraint
    from hapticsdk_roughness.table import resolve_table
    table = resolve_table(None)
    c = DeviceAmplitudeConstraint(table, volts, f_range)
    t_lo, t_hi = table.frequency_range_hz
    f = np.random.default_rng(1).uniform(max(f_range[0], t_lo), min(f_range[1], t_hi), 4000)
    exact = table.accelerations_at(f, volts)
    # 1e-6: floating point of the interpolation, far below the chord error (~1e-5) it removes
    assert np.all(c.max_acceleration(f) <= exact * (1 + 1e-6))
