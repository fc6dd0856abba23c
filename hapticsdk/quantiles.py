"""Percentiles and medians of 1-D samples, as ``numpy.percentile`` computes them (its
default ``"linear"`` method, bit for bit), without importing ``numpy.ma``: every numpy
quantile function imports it, about 10 ms of each command's start-up."""

from __future__ import annotations

from typing import Sequence, overload

import numpy as np

__all__ = ["percentile", "median"]


@overload
def percentile(a: "np.ndarray | Sequence[float]", q: float) -> float: ...
@overload
def percentile(a: "np.ndarray | Sequence[float]", q: Sequence[float]) -> list[float]: ...
def percentile(a: "np.ndarray | Sequence[float]", q: "float | Sequence[float]") -> "float | list[float]":
    """The ``q``-th percentile(s) (0..100) of the values in ``a`` (flattened), linear
    interpolation between the closest ranks; NaN when ``a`` holds a NaN. A scalar ``q``
    gives a float, a sequence a list. Raises ``ValueError`` for an empty ``a`` or ``q``
    outside [0, 100]."""
    v = np.sort(np.asarray(a, float).ravel())
    qs = [float(q)] if np.ndim(q) == 0 else [float(x) for x in q]  # type: ignore[union-attr, arg-type]
    if v.size == 0:
        raise ValueError("percentile of an empty sample")
    if not all(0.0 <= x <= 100.0 for x in qs):
        raise ValueError(f"percentiles must be in [0, 100], got {q!r}")
    out: list[float] = []
    nan = bool(np.isnan(v[-1]))  # NaN sorts last
    n = v.size
    for x in qs:
        if nan:
            out.append(float("nan"))
            continue
        pos = x / 100.0 * (n - 1)
        lo = int(np.floor(pos))
        hi = min(lo + 1, n - 1)
        t = pos - lo
        a0, b0 = float(v[lo]), float(v[hi])
        d = b0 - a0
        # numpy's _lerp: from the nearer end, so t = 1 gives b exactly
        out.append(b0 - d * (1.0 - t) if t >= 0.5 else a0 + d * t)
    return out[0] if np.ndim(q) == 0 else out


def median(a: "np.ndarray | Sequence[float]") -> float:
    """The median of the values in ``a`` (flattened), as ``numpy.median`` (the mean of
    the two middle values for an even count; NaN when ``a`` holds a NaN)."""
    v = np.sort(np.asarray(a, float).ravel())
    if v.size == 0:
        raise ValueError("median of an empty sample")
    if np.isnan(v[-1]):
        return float("nan")
    k = v.size // 2
    return float(v[k]) if v.size % 2 else (float(v[k - 1]) + float(v[k])) / 2.0
