"""Helpers shared by the live-session tests of this folder."""

import time

import pytest


def _wait_until(pred, timeout=20.0, poll_s=0.005):
    """True as soon as ``pred()`` is true, False when ``timeout`` s passed first."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if pred():
            return True
        time.sleep(poll_s)
    return False


@pytest.fixture
def wait():
    """``wait(pred, timeout=20.0)``: poll ``pred`` until true (True) or timeout (False)."""
    return _wait_until
