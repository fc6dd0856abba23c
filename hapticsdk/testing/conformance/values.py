"""Tests the rules of every kind share: a reported number is finite (or None); a call
is refused with the error the contract names."""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np


def _finite(x: Any) -> bool:
    return x is None or (isinstance(x, (int, float, np.floating, np.integer)) and math.isfinite(float(x)))


def _refuses(error: type[Exception], call: Callable[[], object]) -> bool:
    """Whether ``call()`` raises ``error``; any other exception propagates (the rule's
    guard reports it as what the plugin raised instead)."""
    try:
        call()
    except error:
        return True
    return False
