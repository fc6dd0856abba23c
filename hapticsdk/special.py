"""Special functions the SDK needs at start-up, in numpy alone (``scipy.special`` costs
30-170 ms of import time on every ``hapticsdk render``).

:func:`gammainc2` is the regularised lower incomplete gamma function ``P(2, x)``, the
only one :mod:`hapticsdk.passivity` uses (the exact d = 0 mass correction).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["gammainc2"]

#: below this x the series is used (1 - e^-x (1 + x) would cancel: it loses about
#: log2(2 / x^2) bits at small x); at x = 1 the closed form's two terms differ by a
#: factor 3.8, so it loses under 2 bits there
_SERIES_BELOW = 1.0
#: series terms: the tail after K terms is below x^K / (K + 2)! < 2^-53 for x < 1
_SERIES_TERMS = 18


def gammainc2(x: Any) -> Any:
    """``P(2, x) = 1 - e^-x (1 + x)`` (dimensionless), ``scipy.special.gammainc(2, x)``.

    For ``x < 1`` the series ``P(2, x) = x^2 e^-x sum_k x^k / (k + 2)!`` avoids the
    cancellation of the closed form (relative error of a few ulp down to the smallest
    floats). ``P(2, 0) = 0``, ``P(2, inf) = 1``; ``nan`` for ``x < 0`` or ``nan``.

    Args:
        x: float or array, >= 0.

    Returns:
        float for a scalar, else an array of the broadcast shape.
    """
    xa = np.asarray(x, dtype=float)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        big = 1.0 - np.exp(-xa) * (1.0 + xa)
        xs = np.where(xa < _SERIES_BELOW, xa, 0.0)
        # sum_k x^k / (k+2)!, Horner from the last term
        s = np.zeros_like(xs)
        for k in range(_SERIES_TERMS - 1, -1, -1):
            s = 1.0 / _FACT[k + 2] + xs * s
        small = xs * xs * np.exp(-xs) * s
        out = np.where(xa < _SERIES_BELOW, small, big)
        out = np.where(np.isposinf(xa), 1.0, out)
        out = np.where(xa < 0, np.nan, out)
    return out if out.ndim else float(out)


_FACT = [1.0]
for _k in range(1, _SERIES_TERMS + 3):
    _FACT.append(_FACT[-1] * _k)
del _k
