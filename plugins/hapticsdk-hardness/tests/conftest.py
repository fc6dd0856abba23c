"""Shared by the tests of real device backends: a missing real component (a C compiler,
an audio server, a vendor package) skips the test naming what to install, except in CI
(``CI=true``), where it fails instead."""

from __future__ import annotations

import os

import pytest


def _missing(what: str) -> None:
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(f"CI=true and {what} is missing")
    pytest.skip(f"{what} is missing")


@pytest.fixture(scope="session")
def missing():
    """``missing("the Debian package jackd2")``: skip, or fail under CI=true."""
    return _missing
