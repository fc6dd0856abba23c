"""The extraction filters are the paper's: force and displacement low-passed at 10 Hz,
acceleration high-passed at 20 Hz (4th-order Butterworth, zero-phase). The cut-offs here
are the paper's numbers (section 2.1), not the module's constants."""

import dataclasses

import numpy as np
import pytest
from scipy import signal

from hapticsdk.training import extraction, generator

PAPER_LP_HZ, PAPER_HP_HZ, ORDER = 10.0, 20.0, 4


def _butter_power_gain(f, fc, kind):
    """|H(f)|^2 of an order-4 Butterworth filter (analog prototype, which the digital
    filter matches within a few per cent far below Nyquist)."""
    r = (f / fc) if kind == "low" else (fc / f)
    return 1.0 / (1.0 + r ** (2 * ORDER))


@pytest.mark.parametrize("fs", [500.0, 1000.0])
def test_filters_have_the_papers_cut_offs(fs):
    lp, hp = extraction._filters(fs)
    f = np.array([0.5 * PAPER_LP_HZ, PAPER_LP_HZ, 2 * PAPER_LP_HZ])
    _, h = signal.sosfreqz(lp, worN=f, fs=fs)
    g = np.abs(h) ** 2
    assert g[1] == pytest.approx(0.5, abs=0.01)           # -3 dB at the cut-off
    assert g[0] > 0.99 and g[2] < 0.01                      # pass band / order 4 roll-off
    f = np.array([0.5 * PAPER_HP_HZ, PAPER_HP_HZ, 2 * PAPER_HP_HZ])
    _, h = signal.sosfreqz(hp, worN=f, fs=fs)
    g = np.abs(h) ** 2
    assert g[1] == pytest.approx(0.5, abs=0.01)
    assert g[0] < 0.01 and g[2] > 0.99


def test_vibration_power_is_that_of_the_high_passed_signal():
    """P of a lateral acceleration made of a 15 Hz and a 60 Hz sine equals the
    mean square after the paper's zero-phase 20 Hz high-pass (gain |H|^4 in power)."""
    spec = generator.make_samples(1)[0]
    cols, _ = generator.simulate_trial(spec, 0)
    from hapticsdk.training.recordings import trial_from_columns
    tr = trial_from_columns(cols, sample=spec.name, trial=0, fs_hz=generator.FS_HZ)
    t = tr.time_s
    a15, a60 = 5.0, 1.0
    acc = tr.acc.copy()
    acc[:, tr.lateral] = a15 * np.sin(2 * np.pi * 15.0 * t) + a60 * np.sin(2 * np.pi * 60.0 * t)
    tr = dataclasses.replace(tr, acc=acc)
    feats = extraction.extract_trial(tr, expected_fs_hz=generator.FS_HZ)
    expect = (a15 ** 2 / 2 * _butter_power_gain(15.0, PAPER_HP_HZ, "high") ** 2
              + a60 ** 2 / 2 * _butter_power_gain(60.0, PAPER_HP_HZ, "high") ** 2)
    # 3 %: bilinear-transform warping at 15 Hz of a 500 Hz filter (<1 %) plus the
    # mean of sin^2 over a non-whole number of periods in a >= 1 s segment (<1 %)
    assert feats.P == pytest.approx(expect, rel=0.03)
    assert feats.Fpeak == pytest.approx(60.0, abs=feats.df_hz)
    assert feats.AFpeak == pytest.approx(a60, rel=0.02)
