"""Adversarial arguments to hs.solve / build_problem / SolveProblem: every one is refused
with a ValidationError naming its field (no TypeError, OverflowError or ValueError from
numpy, and no value silently taken: a string is not a number, a bool is not a flag's
text, a list is not a mapping)."""

import numpy as np
import pytest

import hapticsdk as hs
from hapticsdk.errors import ValidationError

POLISH = {"method": "polish", "seed": 0}


@pytest.mark.parametrize("value", ["0.5", b"0.5", 10 ** 400, -10 ** 400, None, [0.5], True, np.bool_(False)])
def test_target_intensity_must_be_a_number(value):
    with pytest.raises(ValidationError) as exc:
        hs.solve({"hardness": value}, **POLISH)
    assert exc.value.field == "targets.hardness"


def test_intensity_text_is_read_only_from_the_command_line():
    from hapticsdk.perception.dimensions import check_intensity

    assert check_intensity(" 0.25 ", "x", text=True) == 0.25
    assert check_intensity(np.float32(0.5), "x") == 0.5
    assert check_intensity(np.array(0.5), "x") == 0.5
    with pytest.raises(ValidationError, match="must be a number"):
        check_intensity("0.25", "x")
    with pytest.raises(ValidationError, match="outside 0..1"):
        check_intensity(10 ** 400, "x", text=True)


@pytest.mark.parametrize("kw, field", [
    ({"options": [1]}, "options"),
    ({"options": "x"}, "options"),
    ({"options": 3}, "options"),
    ({"fixed": [1]}, "fixed"),
    ({"fixed": "P"}, "fixed"),
    ({"fixed": {"P": "1"}}, "fixed.P"),
    ({"fixed": {"P": True}}, "fixed.P"),
    ({"fixed": {"P": None}}, "fixed.P"),
    ({"fixed": {"P": 10 ** 400}}, "fixed.P"),
    ({"fixed": {"P": [1.0]}}, "fixed.P"),
    ({"penalty_weight": float("nan")}, "penalty_weight"),
    ({"penalty_weight": float("inf")}, "penalty_weight"),
    ({"penalty_weight": -1.0}, "penalty_weight"),
    ({"penalty_weight": "1"}, "penalty_weight"),
    ({"penalty_weight": True}, "penalty_weight"),
    ({"penalty_weight": None}, "penalty_weight"),
    ({"penalty_weight": 10 ** 400}, "penalty_weight"),
    ({"data_support": "no"}, "data_support"),
    ({"data_support": 1}, "data_support"),
    ({"data_support": None}, "data_support"),
    ({"extra_constraints": "abc"}, "extra_constraints"),
    ({"extra_constraints": 5}, "extra_constraints"),
    ({"extra_constraints": [5]}, "extra_constraints[0]"),
])
def test_solve_arguments_are_checked(kw, field):
    kw = {**POLISH, **kw}
    with pytest.raises(ValidationError) as exc:
        hs.solve({"hardness": 0.5}, **kw)
    assert exc.value.field == field


@pytest.mark.parametrize("dims", ["hardness", 5, None])
def test_dimensions_must_be_a_list_of_names(dims):
    # "hardness" was read as its letters ['h', 'a', 'r', ...]; 5 raised TypeError
    with pytest.raises(ValidationError) as exc:
        hs.solve([0.5], dimensions=dims, **POLISH)
    assert exc.value.field == "dimensions"


def test_good_arguments_still_solve():
    res = hs.solve(np.array([0.5]), dimensions=np.array(["hardness"]), fixed={"P": np.float64(1.0)},
                   penalty_weight=0, data_support=np.bool_(False), extra_constraints=(), options={}, **POLISH)
    assert res.x_dict["P"] == 1.0 and np.isfinite(res.error)
    res = hs.solve({"hardness": np.array(0.5)}, dimensions={"hardness": 1}.keys(), **POLISH)
    assert res.targets == {"hardness": 0.5}
