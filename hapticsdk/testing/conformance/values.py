"""A test the rules of every kind share: a reported number is finite (or None)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np





def _finite(x: Any) -> bool:
    return x is None or (isinstance(x, (int, float, np.floating, np.integer)) and math.isfinite(float(x)))
