"""Discrimination answers (the voice-coil fit's input, formula (7)) hold whole numbers
where the columns are counts and flags: ``person`` an id, ``spring_stiffer`` 0 or 1. A
value that is not one is a CalibrationError naming the column, never a silently changed
number.

The columns were cast with ``astype(int)``: in an answers CSV ``spring_stiffer = 0.5``
became 0 (an answer turned into "not stiffer"), ``person = 0.5`` became person 0 (two
people merged), and ``person = nan`` / ``inf`` / ``1e400`` / ``1e308`` became
-9223372036854775808 (with only a numpy RuntimeWarning). A property test over the class:
every finite or non-finite float in either column is read as that whole number, or
refused."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hapticsdk.calibration.discrimination import CSV_COLUMNS, DiscriminationAnswers, generate_answers
from hapticsdk.errors import CalibrationError


@pytest.fixture(scope="module")
def csv_lines(tmp_path_factory):
    p = generate_answers(people=2).to_csv(tmp_path_factory.mktemp("answers") / "a.csv")
    return p.read_text().splitlines()


def _with_cell(lines, column, text):
    out = list(lines)
    head = next(i for i, ln in enumerate(out) if not ln.startswith("#"))
    cells = out[head + 1].split(",")
    cells[CSV_COLUMNS.index(column)] = text
    out[head + 1] = ",".join(cells)
    return "\n".join(out) + "\n"


@settings(max_examples=300, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(column=st.sampled_from(["person", "spring_stiffer"]),
       value=st.one_of(st.floats(), st.sampled_from([0.5, -0.5, 1.5, 1e308, 2.0 ** 63, -2.0 ** 63, 5e-324]),
                       st.integers(-3, 3)))
def test_a_count_or_flag_column_is_read_exactly_or_refused(tmp_path_factory, csv_lines, column, value):
    p = tmp_path_factory.mktemp("a") / "a.csv"
    p.write_text(_with_cell(csv_lines, column, repr(value)))
    try:
        a = DiscriminationAnswers.from_csv(p)
    except CalibrationError as exc:
        assert column in str(exc)
        return
    got = getattr(a, column)[0]
    assert math.isfinite(value) and got == value   # the number in the file, not a cast of it


@pytest.mark.parametrize("column, text", [("spring_stiffer", "0.5"), ("person", "0.5"), ("person", "nan"),
                                          ("person", "1e400"), ("person", "1e308")])
def test_the_cases_found(csv_lines, tmp_path, column, text):
    p = tmp_path / "a.csv"
    p.write_text(_with_cell(csv_lines, column, text))
    with pytest.raises(CalibrationError, match=column):
        DiscriminationAnswers.from_csv(p)


def test_answers_built_in_code_are_checked_as_well():
    with pytest.raises(CalibrationError, match="spring_stiffer"):
        DiscriminationAnswers(person=[0], frequency_hz=[40.0], spring_n_per_mm=[1.0], spring_stiffer=[0.5])
    a = DiscriminationAnswers(person=np.array([3]), frequency_hz=[40.0], spring_n_per_mm=[1.0],
                              spring_stiffer=np.array([True]))
    assert a.person[0] == 3 and a.spring_stiffer[0] == 1 and a.person.dtype.kind == "i"
