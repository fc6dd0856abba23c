"""PhaseAccumulator / Oscillator against their documented contract, with exact rational
arithmetic (fractions) as the independent reference: the phase is wrapped to [0, 1) with
whole cycles counted apart, a block's k-th sample sits k increments after the start, a
block of n samples advances exactly n increments of f*dt, reset returns to phase 0 and
amplitude 0."""

import math
from fractions import Fraction

import numpy as np
import pytest

from hapticsdk.synthesis import Oscillator, PhaseAccumulator


def test_a_start_phase_and_a_whole_cycle_are_wrapped_into_0_1():
    assert PhaseAccumulator(1.25).value() == 0.25
    acc = PhaseAccumulator()
    assert acc.advance(1.0, 1.0) == 0.0  # exactly one cycle: back to 0, not 1.0
    assert acc.cycles == 1 and acc.total_cycles() == 1.0


@pytest.mark.parametrize("n", [1, 2, 7])
def test_block_phases_are_k_increments_after_the_start(n):
    f, fs = 250.0, 1000.0  # a quarter cycle per sample (exact in binary)
    acc = PhaseAccumulator(0.5)
    ph = acc.block(f, n, fs)
    want = [(0.5 + 0.25 * k) % 1.0 for k in range(1, n + 1)]
    assert ph.tolist() == want
    assert acc.total_cycles() == 0.5 + 0.25 * n  # ends after the last sample


def test_a_long_silent_skip_advances_exactly_n_increments():
    # f*n is not a float (0.1 is not), so the skip must add the rounding tail of f*n too.
    # Exact reference: n * f * dt in rationals of the same floats. Tolerance 1e-12 cycles:
    # the double-double keeps ~1e-16 cycles; dropping the tail costs ~f*n*dt*1e-16 ~ 1e-10.
    f, n, fs = 1234.5671, 10 ** 6, 1000.0
    acc = PhaseAccumulator()
    acc.skip(f, n, fs)
    exact = Fraction(f) * n * Fraction(1.0 / fs)
    whole = math.floor(exact)
    assert acc.cycles == whole
    assert acc.value() == pytest.approx(float(exact - whole), abs=1e-12)
    assert acc.total_cycles() == pytest.approx(float(exact), rel=1e-15)


def test_reset_is_phase_0_and_amplitude_0_and_silence_records_the_frequency():
    osc = Oscillator(1000.0, ramp_s=0.01)
    osc.render(130.0, 0.8, 50)  # the ramp reaches 0.8 (0.1 per sample): amplitude is 0.8
    assert osc.amplitude == pytest.approx(0.8)
    osc.reset()
    assert osc.amplitude == 0.0 and osc.acc.total_cycles() == 0.0
    assert np.all(osc.render(90.0, 0.0, 4) == 0.0)  # silent from rest
    assert osc.frequency_hz == 90.0
