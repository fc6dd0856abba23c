"""The plan of the energy-bounded extra: "hold a force for one tick, then ramp to 0", its
cost bound and the largest affordable force (vectorised, and in floats for the tick)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np


#: Spans (ticks) over which the change of motion is read: the second difference
#: ``x_k - 2 x_(k-m) + x_(k-2m) = a (m T)^2`` under a constant acceleration a, and the
#: encoder adds at most 2 counts to it, whatever m; so a longer span sees an acceleration
#: m^2 times smaller above the same quantisation (powers of two up to 16 ticks).
_SCALES = (1, 2, 4, 8, 16)   # (the scalar tick unrolls these five)
#: Length of the reading ring (2 x the longest span + 1).
_HIST = 2 * _SCALES[-1] + 1


#: Bisection steps of :func:`_affordable_bisect`, the fallback of the closed form
#: (2^-30 of the ramp step: far below any force a device resolves).
_BISECT = 30
#: Relative step back from the closed-form root when its rounding leaves it just over the
#: budget (1e-12 of the force scale: far below the bisection's 2^-30).
_NUDGE = 1e-12
#: The bisection's resolution as a share of ``hi - lo``.
_RESOLUTION = 2.0 ** -_BISECT


def _ramp_sum(a: Any, s: Any) -> Any:
    """Upper bound of ``sum_j max(a - j s, 0)`` (N, the forces of a ramp from ``a`` to 0 at
    ``s`` per tick): ``a`` for ``a <= s``, else ``a^2/(2s) + a/2 + s/8``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(a <= s, a, a * a / (2.0 * s) + 0.5 * a + 0.125 * s)


def plan_cost_j(a: Any, p: Any, lead_m: Any, push_m_per_n: Any, s: Any, half_count_m: Any) -> Any:
    """Upper bound (J) of the energy the plan "hold ``a`` for one tick, then ramp to 0 at
    ``s`` per tick" hands to a hand that does not pull the stylus out (all along the
    force's direction; ``p`` the force held now):

    ``(Delta/2) |p| + lead S + c_m S^2``,  ``S = S(a)`` (:func:`_ramp_sum`)

    The first two terms are the work of the held forces on the free arm of (declared,
    smallest) mass m starting at the speed ``lead / T``: the forces ``a_j`` held for T each
    move it ``v0 T + T^2 (sum_{i<j} a_i + a_j / 2) / m`` in tick j, so their work sums to
    exactly ``v0 T S + T^2 S^2 / (2 m)`` (``c_m = T^2 / 2m``); a hand pushing in, a heavier
    hand and the arm's damping only take from it. These are *true* displacements, so the
    only encoder term is the one the booked bound ``U`` leaves open: ``(Delta/2) |p|``, the
    reading's error times the force held now (summation by parts); ``lead`` carries the
    velocity estimate's own half count."""
    a = np.asarray(a, float)
    S = _ramp_sum(a, s)
    return half_count_m * np.abs(p) + lead_m * S + push_m_per_n * S * S + 0.0 * a


def _plan_slope(a: Any, p: Any, lead_m: Any, c_m: Any, s: Any, c: Any) -> Any:
    """Derivative of :func:`plan_cost_j` in ``a`` (non-decreasing: the cost is convex)."""
    S = _ramp_sum(a, s)
    with np.errstate(divide="ignore", invalid="ignore"):
        dS = np.where(a <= s, 1.0, a / s + 0.5)
    return (lead_m + 2.0 * c_m * S) * dS


def _largest_ramp_start(S2: Any, s: Any) -> Any:
    """Largest ``a`` with :func:`_ramp_sum` ``(a, s) <= S2`` (``S`` is non-decreasing in ``a``
    and jumps from ``s`` to ``9 s / 8`` at ``a = s``): ``S2`` below ``s``, ``s`` up to
    ``9 s / 8``, above it the root ``(sqrt(8 s S2) - s) / 2`` of ``a^2/(2s) + a/2 + s/8 = S2``."""
    with np.errstate(invalid="ignore", over="ignore"):
        return np.where(S2 < s, S2, np.where(S2 < 1.125 * s, s, 0.5 * (np.sqrt(8.0 * s * np.maximum(S2, 0.0)) - s)))


def _upper_root(r: Any, d: Any, c_m: Any) -> Any:
    """Largest ``S`` with ``d S + c_m S^2 <= r`` (``c_m >= 0``); NaN when there is none (no
    real root, or ``c_m = 0`` with ``d <= 0``: the cost then does not rise with ``S``).
    The root in the form without cancellation for either sign of ``d``."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        disc = d * d + 4.0 * c_m * r
        sq = np.sqrt(disc)
        quad = np.where(d <= 0.0, (sq - d) / (2.0 * c_m), 2.0 * r / (d + sq))
        lin = np.where(d > 0.0, r / d, np.nan)
        return np.where(c_m > 0.0, np.where(disc >= 0.0, quad, np.nan), lin)


def affordable_force(avail_j: Any, lo: Any, hi: Any, p: Any, lead_m: Any, push_m_per_n: Any, s: Any,
                     half_count_m: Any) -> Any:
    """Largest ``a`` in ``[lo, hi]`` with :func:`plan_cost_j` ``<= avail_j`` (vectorised).

    The cost is a convex quadratic in the ramp's sum ``S = S(a)``, and ``S`` rises with
    ``a``: ``hi`` when it fits; otherwise the largest ``a`` whose ``S`` is at most the
    quadratic's upper root (closed form), when that ``a`` is in ``[lo, hi]`` and fits;
    when nothing fits, ``lo`` (the ramp allows no deeper cut). Each answer is checked:
    a found ``a`` must fit and one bisection resolution above it must not, and "nothing
    fits" must hold at the cost's minimiser; where rounding, an underflow or an overflow
    breaks a check, bisection decides (:func:`_affordable_bisect`)."""
    A, lo, hi, p, d, c_m, s, c = np.broadcast_arrays(*(np.asarray(v, float) for v in (
        avail_j, lo, hi, p, lead_m, push_m_per_n, s, half_count_m)))
    def cost(a: np.ndarray) -> np.ndarray:
        return plan_cost_j(a, p, d, c_m, s, c)
    ok_hi = cost(hi) <= A
    if ok_hi.all():
        return hi.copy() if hi.ndim else float(hi)
    S2 = _upper_root(A - c * np.abs(p), d, c_m)
    a = _largest_ramp_start(S2, s)
    # a >= hi: hi is within the upper root and does not fit, so [lo, hi] lies below the
    # lower root (nothing fits): the minimiser's check below confirms it
    below = a >= hi
    found = np.isfinite(a) & (a >= lo) & ~below
    a = np.where(found, a, lo)
    fits = cost(a) <= A
    # the root's rounding can leave it an ulp over the budget: 1e-12 of the scale back
    a2 = a - _NUDGE * (np.abs(a) + s)
    back = found & ~fits & (a2 >= lo) & (cost(a2) <= A)
    a = np.where(back, a2, a)
    fits = fits | back
    # largest: one bisection resolution above it does not fit
    step_up = np.minimum(a + (hi - lo) * _RESOLUTION, hi)
    short = found & fits & (a < hi) & (cost(step_up) <= A)
    # nothing fits: not even at the cost's minimiser
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        s_min = np.where(c_m > 0.0, -d / (2.0 * c_m), np.where(d > 0.0, -np.inf, np.inf))
    amin = np.clip(np.where(np.isnan(s_min), lo, _largest_ramp_start(s_min, s)), lo, hi)
    missed = ~found & (cost(amin) <= A)
    unsure = ~ok_hi & (hi > lo) & ((found & ~fits) | short | missed)
    out = np.where(ok_hi, hi, np.where(found & fits, a, lo))
    if unsure.any():
        out = np.where(unsure, _affordable_bisect(A, lo, hi, p, d, c_m, s, c), out)
    return out if out.ndim else float(out)


def _affordable_bisect(A: Any, lo: Any, hi: Any, p: Any, d: Any, c_m: Any, s: Any, c: Any) -> Any:
    """:func:`affordable_force` by bisection: the cost's minimiser on ``[lo, hi]`` (on the
    slope), then the crossing between it and ``hi``; ``lo`` when nothing fits. The fallback
    where the closed form sits on the budget's edge within rounding."""
    A, lo, hi, p, d, c_m, s, c = np.broadcast_arrays(*(np.asarray(v, float) for v in (A, lo, hi, p, d, c_m, s, c)))
    def cost(a: np.ndarray) -> np.ndarray:
        return plan_cost_j(a, p, d, c_m, s, c)
    ok_hi = cost(hi) <= A
    a, b = lo.copy(), hi.copy()
    for _ in range(_BISECT):
        m = 0.5 * (a + b)
        up = _plan_slope(m, p, d, c_m, s, c) > 0
        b = np.where(up, m, b)
        a = np.where(up, a, m)
    amin = np.where(_plan_slope(lo, p, d, c_m, s, c) > 0, lo, a)
    fits = cost(amin) <= A
    a, b = amin.copy(), hi.copy()
    for _ in range(_BISECT):
        m = 0.5 * (a + b)
        fit = cost(m) <= A
        a = np.where(fit, m, a)
        b = np.where(fit, b, m)
    return np.where(ok_hi, hi, np.where(fits, a, lo))


def _affordable_scalar(A: float, lo: float, hi: float, p: float, d: float, c_m: float, s: float,
                       c: float) -> float:
    """:func:`affordable_force` for one cell, in floats (the servo tick), with the same checks."""
    base = c * abs(p)
    S = hi if hi <= s else hi * hi / (2.0 * s) + 0.5 * hi + 0.125 * s
    if base + d * S + c_m * S * S <= A or hi <= lo:
        return hi if hi > lo else lo
    r = A - base
    S2 = None
    if c_m > 0.0:
        disc = d * d + 4.0 * c_m * r
        if disc > 0.0:   # 0: a double root, or an underflow; the check below decides
            sq = math.sqrt(disc)
            S2 = (sq - d) / (2.0 * c_m) if d <= 0.0 else 2.0 * r / (d + sq)
    elif d > 0.0:
        S2 = r / d
    if S2 is not None:
        if S2 < s:
            a = S2
        elif S2 < 1.125 * s:
            a = s
        else:
            a = 0.5 * (math.sqrt(8.0 * s * S2) - s)
        # a >= hi: hi is within the upper root and does not fit, so [lo, hi] lies below
        # the lower root (nothing fits): the minimiser's check below confirms it
        if lo <= a < hi:
            S = a if a <= s else a * a / (2.0 * s) + 0.5 * a + 0.125 * s
            if base + d * S + c_m * S * S > A:
                # the root's rounding can leave it an ulp over the budget: 1e-12 of the scale back
                a -= _NUDGE * ((a if a > 0.0 else -a) + s)
                if a < lo:
                    return _bisect_scalar(A, lo, hi, p, d, c_m, s, c)
                S = a if a <= s else a * a / (2.0 * s) + 0.5 * a + 0.125 * s
                if base + d * S + c_m * S * S > A:
                    return _bisect_scalar(A, lo, hi, p, d, c_m, s, c)
            # largest: one bisection resolution above it does not fit
            u = a + (hi - lo) * _RESOLUTION
            if u < hi:
                S = u if u <= s else u * u / (2.0 * s) + 0.5 * u + 0.125 * s
                if base + d * S + c_m * S * S <= A:
                    return _bisect_scalar(A, lo, hi, p, d, c_m, s, c)
            return a
    # nothing fits: not even at the cost's minimiser
    if c_m > 0.0:
        a = -d / (2.0 * c_m)
        if a >= 1.125 * s:
            a = 0.5 * (math.sqrt(8.0 * s * a) - s)
        elif a > s:
            a = s
        a = lo if a < lo else (hi if a > hi else a)
    else:
        a = lo if d > 0.0 else hi
    S = a if a <= s else a * a / (2.0 * s) + 0.5 * a + 0.125 * s
    if base + d * S + c_m * S * S <= A:
        return _bisect_scalar(A, lo, hi, p, d, c_m, s, c)
    return lo


def _bisect_scalar(A: float, lo: float, hi: float, p: float, d: float, c_m: float, s: float,
                   c: float) -> float:
    """:func:`_affordable_bisect` for one cell, in floats."""
    def ramp(a: float) -> float:
        return a if a <= s else a * a / (2.0 * s) + 0.5 * a + 0.125 * s

    def cost(a: float) -> float:
        S = ramp(a)
        return c * abs(p) + d * S + c_m * S * S

    def slope(a: float) -> float:
        return (d + 2.0 * c_m * ramp(a)) * (1.0 if a <= s else a / s + 0.5)
    if cost(hi) <= A:
        return hi
    a, b = lo, hi
    if slope(lo) <= 0.0:
        for _ in range(_BISECT):
            m = 0.5 * (a + b)
            if slope(m) > 0.0:
                b = m
            else:
                a = m
    if cost(a) > A:
        return lo
    b = hi
    for _ in range(_BISECT):
        m = 0.5 * (a + b)
        if cost(m) <= A:
            a = m
        else:
            b = m
    return a
