"""Voice-coil calibration: psychometric fits and formula (7) recovered from GENERATED answers."""

from __future__ import annotations

import numpy as np
import pytest

from hapticsdk.calibration import (DiscriminationAnswers, VoiceCoilCalibration, fit_psychometric,
                                   fit_voicecoil, generate_answers)
from hapticsdk.calibration.voicecoil import PAPER_COEFFICIENTS
from hapticsdk.errors import CalibrationError


def inside(values, intervals):
    return [lo <= v <= hi for v, (lo, hi) in zip(values, intervals)]


def test_generator_follows_the_paper_design():
    ans = generate_answers(seed=3)
    assert len(ans) == 700 and ans.generated and "GENERATED" not in ans.source  # flag, not text
    assert np.unique(ans.person).size == 10
    assert set(ans.levels_hz) == set(np.arange(30.0, 121.0, 10.0))
    assert set(np.unique(ans.spring_n_per_mm)) == {0.08, 0.3, 0.5, 0.8, 1.5, 2.1, 4.5}
    per_person = np.bincount(ans.person)
    assert np.all(per_person == 70)
    # answers follow the PSE: at 120 Hz (PSE 2.62 N/mm) the 0.08 N/mm spring is never
    # judged stiffer and the 4.5 N/mm spring nearly always
    hi = ans.frequency_hz == 120.0
    assert ans.spring_stiffer[hi & (ans.spring_n_per_mm == 0.08)].mean() == 0.0
    assert ans.spring_stiffer[hi & (ans.spring_n_per_mm == 4.5)].mean() >= 0.9


def test_psychometric_fit_recovers_pse_and_sigma():
    rng = np.random.default_rng(1)
    k = np.repeat(np.linspace(0.2, 2.2, 9), 200)
    yes = (k + 0.25 * rng.standard_normal(k.size) > 1.1).astype(int)
    fit = fit_psychometric(k, yes, frequency_hz=70.0)
    assert fit.pse_n_per_mm == pytest.approx(1.1, abs=0.03)
    assert fit.sigma_n_per_mm == pytest.approx(0.25, rel=0.15)
    assert fit.pse_ci[0] < 1.1 < fit.pse_ci[1] and fit.pse_ci[1] - fit.pse_ci[0] < 0.1
    assert fit.proportion(1.1) == pytest.approx(0.5, abs=0.02)


def test_separated_answers_give_an_honest_interval():
    k = np.repeat([0.5, 0.8, 1.5, 2.1], 10)
    yes = (k > 1.0).astype(int)  # all 'no' up to 0.8, all 'yes' from 1.5
    fit = fit_psychometric(k, yes)
    assert 0.8 <= fit.pse_n_per_mm <= 1.5
    assert fit.pse_ci[0] <= 0.85 and fit.pse_ci[1] >= 1.45  # the whole gap is plausible


def test_fit_recovers_paper_coefficients_within_their_intervals(tmp_path):
    ans = generate_answers(seed=0)
    res = fit_voicecoil(ans.to_csv(tmp_path / "answers.csv"))  # through the CSV format
    assert res.success and res.generated and res.calibration.generated
    assert all(inside(PAPER_COEFFICIENTS, res.confidence_intervals))
    # the intervals are informative, not everything-goes
    widths = [hi - lo for lo, hi in res.confidence_intervals]
    assert widths[0] < 5 * PAPER_COEFFICIENTS[0] and widths[2] < 2.0
    # the fitted curve is close to formula (7) over the calibrated range
    f = np.linspace(30, 120, 50)
    assert np.max(np.abs(res.calibration.gs_coil(f) - VoiceCoilCalibration.paper().gs_coil(f))) < 0.5
    # per-level PSEs follow formula (7)
    pse = np.array([lv.pse_n_per_mm for lv in res.levels])
    assert np.corrcoef(pse, VoiceCoilCalibration.paper().gs_coil(res.calibration.extra["levels_hz"]))[0, 1] > 0.97


def test_fit_tracks_a_different_curve_and_rejects_the_paper():
    """Answers generated from another quadratic: the fit covers it, and with 40 people the
    intervals exclude the paper's coefficients (the fit is not the default in disguise)."""
    true = (0.0002, 0.0, 0.0)
    curve = lambda f: (true[0] * f + true[1]) * f + true[2]  # noqa: E731
    res = fit_voicecoil(generate_answers(curve, people=40, seed=0))
    assert all(inside(true, res.confidence_intervals))
    assert not all(inside(PAPER_COEFFICIENTS, res.confidence_intervals))


def test_interval_coverage_over_seeds():
    hits = np.zeros(3)
    n = 8
    for seed in range(100, 100 + n):
        hits += inside(PAPER_COEFFICIENTS, fit_voicecoil(generate_answers(seed=seed)).confidence_intervals)
    assert np.all(hits >= n - 1), hits


def test_calibration_round_trip_and_inverse():
    cal = fit_voicecoil(generate_answers(seed=5), serial="VC-1", amplifier_gain=2.0).calibration
    back = VoiceCoilCalibration.from_dict(cal.to_dict())
    assert back == cal and back.serial == "VC-1" and back.amplifier_gain == 2.0
    g = np.linspace(*cal.gs_range, 7)
    f, resid = cal.frequency_for(g)
    np.testing.assert_allclose(cal.gs_coil(f), g, atol=1e-9)
    assert np.all(resid == pytest.approx(0, abs=1e-9))


def test_bad_answers_rejected(tmp_path):
    with pytest.raises(CalibrationError):
        DiscriminationAnswers(person=[0], frequency_hz=[30.0], spring_n_per_mm=[0.5], spring_stiffer=[2])
    p = tmp_path / "a.csv"
    p.write_text("person,frequency_hz,spring\n0,30,0.5\n")
    with pytest.raises(CalibrationError, match="missing column"):
        DiscriminationAnswers.from_csv(p)
    few = generate_answers(levels_hz=(30.0, 60.0, 90.0), seed=0)
    with pytest.raises(CalibrationError, match="at least 4"):
        fit_voicecoil(few)


@pytest.mark.parametrize("source", ["lab\nrun 2", "a\r\nb\rc", "\n", "GENERATED\nthen more"])
def test_answers_with_line_breaks_in_source_read_back(tmp_path, source):
    """What ``to_csv`` writes ``from_csv`` reads: a line break in ``source`` stays inside
    the comment (it used to end it, and the next line was taken for the header)."""
    ans = DiscriminationAnswers(person=np.array([0, 1]), frequency_hz=np.array([100.0, 200.0]),
                                spring_n_per_mm=np.array([0.5, 0.6]), spring_stiffer=np.array([0, 1]),
                                source=source)
    back = DiscriminationAnswers.from_csv(ans.to_csv(tmp_path / "answers.csv"))
    assert back.person.tolist() == [0, 1] and back.spring_stiffer.tolist() == [0, 1]
    assert back.generated == ("GENERATED" in source)
