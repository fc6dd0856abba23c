"""Discrimination answers with an extreme reference spring, or a PSE search range that is
not a finite interval, end in a CalibrationError naming the level, never a raw
IndexError (``hapticsdk calibrate voicecoil`` on answers with one spring of 1e308 N/mm
printed "internal error": 1.5 x 1e308 made the likelihood NaN everywhere and the
maximal set empty)."""

from __future__ import annotations

import numpy as np
import pytest

from hapticsdk.calibration.discrimination import fit_psychometric
from hapticsdk.errors import CalibrationError

SPRINGS = [0.3, 0.8, 1.5, 2.1]
STIFFER = [0, 0, 1, 1]


@pytest.mark.parametrize("big", [1e308, 1e300, 1e200])
def test_a_huge_spring_is_named(big):
    with pytest.raises(CalibrationError, match="40 Hz"):
        fit_psychometric([*SPRINGS[:-1], big], STIFFER, frequency_hz=40.0)


@pytest.mark.parametrize("pse_range", [(float("nan"), 1.0), (0.0, float("inf")), (1.0, 0.0), (0.5, 0.5),
                                       (0.0, np.float64("nan"))])
def test_a_pse_range_that_is_no_finite_interval_is_named(pse_range):
    with pytest.raises(CalibrationError, match="PSE search range"):
        fit_psychometric(SPRINGS, STIFFER, frequency_hz=40.0, pse_range=pse_range)


def test_ordinary_answers_still_fit():
    fit = fit_psychometric(SPRINGS, STIFFER, frequency_hz=40.0)
    assert 0.8 <= fit.pse_n_per_mm <= 1.5


def test_the_command_line_names_it(tmp_path, capsys):
    from hapticsdk.cli import main
    p = tmp_path / "answers.csv"
    rows = ["person,frequency_hz,spring_n_per_mm,spring_stiffer"]
    rows += [f"{person},40,{s:g},{a}" for person in range(3) for s, a in zip([*SPRINGS[:-1], 1e308], STIFFER)]
    p.write_text("\n".join(rows) + "\n")
    assert main(["calibrate", "voicecoil", str(p)]) == 2
    err = capsys.readouterr().err
    assert "hapticsdk: error:" in err and "internal error" not in err
