"""``Constraint.bound_and_value_one``: one row of features as plain floats, the numbers the
array path gives for that row alone. A one-target solve judges its answer with it
(``SolveProblem.evaluate_one``), so the first-party constraints' float paths must equal
their array paths bit for bit, on any float a column can hold (0, negative, subnormal,
huge, infinite, NaN), and a constraint without a float path gets the array path's
numbers through the base class."""

from __future__ import annotations

import numpy as np
import pytest

hyp = pytest.importorskip("hypothesis", reason="hypothesis (the test extra) is not installed")
from hypothesis import example, given, settings, strategies as st  # noqa: E402

from hapticsdk.perception.dimensions import Constraint  # noqa: E402
from hapticsdk_hardness.dimension import PressForceConstraint, WorkConstraint  # noqa: E402
from hapticsdk_roughness.dimension import PowerConstraint  # noqa: E402

ANY = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True)


def _same(a: float, b: float) -> bool:
    """Equal bits, or both NaN (numpy and Python may carry a NaN's sign differently)."""
    return (a != a and b != b) or np.float64(a).tobytes() == np.float64(b).tobytes()


def _array_pair(c: Constraint, row: dict[str, float]) -> tuple[float, float]:
    with np.errstate(all="ignore"):
        b, v = c.bound_and_value({k: np.array([x]) for k, x in row.items()})
    return float(np.asarray(b, float).reshape(-1)[0]), float(np.asarray(v, float).reshape(-1)[0])


CONSTRAINTS = [WorkConstraint(), WorkConstraint(mf_n=1.7), PressForceConstraint(f_max_n=6.0), PowerConstraint(),
               PowerConstraint(df_hz=0.125)]


@settings(max_examples=300, deadline=None, database=None)
@given(gs=ANY, w=ANY, a=ANY, p=ANY)
@example(gs=0.0, w=1.0, a=0.0, p=0.0).via("GS = 0: the work bound is +inf")
@example(gs=-0.0, w=1.0, a=-0.0, p=0.0).via("GS = -0.0")
@example(gs=5e-324, w=1.0, a=5e-324, p=0.0).via("subnormal")
@example(gs=1e-13, w=1.0, a=1e200, p=0.0).via("below the press force's 1e-12 floor; a^2 overflows")
@example(gs=float("nan"), w=float("nan"), a=float("nan"), p=float("nan")).via("NaN")
def test_first_party_float_paths_equal_their_array_paths(gs, w, a, p):
    row = {"GS": gs, "W": w, "AFpeak": a, "P": p}
    for c in CONSTRAINTS:
        with np.errstate(all="ignore"):
            b1, v1 = c.bound_and_value_one(row)
        b, v = _array_pair(c, row)
        assert type(b1) is float and type(v1) is float
        assert _same(b1, b) and _same(v1, v), (c.name, row, (b1, v1), (b, v))


class _NoFloatPath(Constraint):
    """W / GS >= 3 with no float path of its own."""

    name = "no-float-path"
    features = ("GS", "W")

    def _bound_and_value(self, cols):
        return np.full_like(cols["W"], 3.0), cols["W"] / cols["GS"]


@settings(max_examples=100, deadline=None, database=None)
@given(gs=st.floats(0.1, 10.0), w=st.floats(0.0, 100.0))
def test_without_a_float_path_the_base_gives_the_array_paths_numbers(gs, w):
    c = _NoFloatPath()
    assert c._bound_and_value_one({"GS": gs, "W": w}) is None
    b1, v1 = c.bound_and_value_one({"GS": gs, "W": w})
    assert (b1, v1) == _array_pair(c, {"GS": gs, "W": w})
    assert type(b1) is float and type(v1) is float
