"""The suite's property-based tests draw the same examples on every run unless asked to
explore (conftest.py): the README's test command passes or fails the same way everywhere."""

import os

import pytest
from hypothesis import given, settings, strategies as st

SEEN: list[int] = []


def test_the_default_profile_is_derandomized():
    want = os.environ.get("HYPOTHESIS_PROFILE", "derandomized") == "derandomized"
    assert settings.default.derandomize is want


@settings(max_examples=5, database=None)
@given(st.integers(0, 2 ** 60))
def _draw(x):
    SEEN.append(x)


def test_two_runs_draw_the_same_examples():
    if os.environ.get("HYPOTHESIS_PROFILE", "derandomized") != "derandomized":
        pytest.skip("HYPOTHESIS_PROFILE=explore draws new examples on purpose")
    _draw()
    first = list(SEEN)
    SEEN.clear()
    _draw()
    assert SEEN == first and len(set(first)) > 1
