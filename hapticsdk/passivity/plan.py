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

#: Relative slack of the spring's inward-rise rule (item 0, "a spring born compressed"):
#: the spring from its anchor, ``K_c (depth - o)``, and the cap from the last spring plus
#: the inward change, ``P + K_c |dq|``, are the same number in exact arithmetic wherever
#: the spring follows the reading; each is a few roundings (2^-53 relative each) from it,
#: so the rule acts only beyond 2^-44 (a relative margin of 512 roundings: float error, no
#: physics).
_ROUNDING_SLACK = 1.0 + 2.0 ** -44
#: relative tolerance of "the Colgate spring is on its K_c branch" (``K_c (depth - o)`` up to a few
#: roundings, the margin of _ROUNDING_SLACK; docs/runtime.md, Passivity item 0, "A spring the device
#: did not apply")
_BRANCH_TOL = _ROUNDING_SLACK - 1.0


#: Bisection steps of :func:`_affordable_bisect`, the fallback of the closed form
#: (2^-30 of the ramp step: far below any force a device resolves).
_BISECT = 30
#: The bisection's resolution as a share of ``hi - lo``. A closed-form root that its
#: rounding leaves just over the budget steps back half of it: still within the resolution
#: the answer's check asks for (one resolution above the answer must not fit).
_RESOLUTION = 2.0 ** -_BISECT


def _ramp_sum(a: Any, s: Any) -> Any:
    """Upper bound of ``sum_j max(a - j s, 0)`` (N, the forces of a ramp from ``a`` to 0 at
    ``s`` per tick): ``a`` for ``a <= s``, else ``a^2/(2s) + a/2 + s/8``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(a <= s, a, a * a / (2.0 * s) + 0.5 * a + 0.125 * s)


def _ramp_sum_scalar(a: float, s: float) -> float:
    """:func:`_ramp_sum` in floats (written out instead on the servo tick's fast path of
    :func:`_affordable_scalar`)."""
    return a if a <= s else a * a / (2.0 * s) + 0.5 * a + 0.125 * s


def _half_resolution(lo: Any, hi: Any) -> Any:
    """Half the answer check's resolution, ``(hi - lo) _RESOLUTION / 2``: how far a
    closed-form root that rounding left just over the budget (or at a piece's end) steps
    back."""
    return 0.5 * (hi - lo) * _RESOLUTION


def _pieces(p: Any, lead_m: Any, half_count_m: Any) -> tuple[Any, ...]:
    """The three pieces of :func:`plan_cost_j`'s encoder term, each a constant plus a
    multiple of ``S``: ``(top, bot)`` the pieces' edges ``max(p, 0)`` and ``min(p, 0)``, and
    ``(base, slope)`` for ``a >= top``, ``bot <= a < top`` and ``a < bot``."""
    c = half_count_m
    return (np.maximum(p, 0.0), np.minimum(p, 0.0),
            -c * p, lead_m + 2.0 * c, c * np.abs(p), lead_m, c * p, lead_m - 2.0 * c)


def plan_cost_j(a: Any, p: Any, lead_m: Any, push_m_per_n: Any, s: Any, half_count_m: Any) -> Any:
    """Cost (J) of the plan "hold ``a`` for one tick, then ramp to 0 at ``s`` per tick",
    charged against the allowance, for a hand that does not pull the stylus out (all
    along the force's direction; ``p`` the force held now):

    ``(Delta/2) (|a - p| + |a|) + lead S + c_m S^2``,  ``S = S(a)`` (:func:`_ramp_sum`)

    The last two terms are the work of the held forces on the free arm of (declared,
    smallest) mass m starting at the speed ``lead / T``: the forces ``a_j`` held for T each
    move it ``v0 T + T^2 (sum_{i<j} a_i + a_j / 2) / m`` in tick j, so their work sums to
    exactly ``v0 T S + T^2 S^2 / (2 m)`` (``c_m = T^2 / 2m``); a hand pushing in, a heavier
    hand and the arm's damping only take from it. The first is the booked bound's own
    quantisation term ``(Delta/2) |dF|`` over the plan's forces: the step from ``p`` to
    ``a``, then a monotone ramp from ``a`` to 0, whose steps sum to ``|a|`` (``lead``
    carries the velocity estimate's own half count). Above ``max(p, 0)`` the ``|a|`` is
    charged as ``S >= a``, so that every piece is a quadratic in ``S`` (exact up to
    ``a = s``, where ``S = a``). By the triangle inequality the cost is at least
    ``(Delta/2) |p|`` (the booked bound's open tail now) plus that work: an upper bound
    of the true energy given when the plan ends (docs/runtime.md, Passivity items 1, 5)."""
    pieces = _pieces(np.asarray(p, float), np.asarray(lead_m, float), np.asarray(half_count_m, float))
    return _piece_cost(np.asarray(a, float), pieces, push_m_per_n, s)


def _piece_cost(a: np.ndarray, pieces: tuple[Any, ...], c_m: Any, s: Any) -> Any:
    """:func:`plan_cost_j` from the pieces of :func:`_pieces` (computed once per solve)."""
    top, bot, b_up, d_up, b_mid, d_mid, b_dn, d_dn = pieces
    S = _ramp_sum(a, s)
    base = np.where(a >= top, b_up, np.where(a >= bot, b_mid, b_dn))
    d = np.where(a >= top, d_up, np.where(a >= bot, d_mid, d_dn))
    return base + d * S + c_m * S * S + 0.0 * a


def _piece_slope(a: np.ndarray, pieces: tuple[Any, ...], c_m: Any, s: Any) -> Any:
    """Derivative of :func:`plan_cost_j` in ``a`` within its pieces (its sign changes once,
    from - to +; the pieces meet with no drop)."""
    top, bot, _, d_up, _, d_mid, _, d_dn = pieces
    S = _ramp_sum(a, s)
    d = np.where(a >= top, d_up, np.where(a >= bot, d_mid, d_dn))
    with np.errstate(divide="ignore", invalid="ignore"):
        dS = np.where(a <= s, 1.0, a / s + 0.5)
    return (d + 2.0 * c_m * S) * dS


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

    On each of its three pieces (above ``max(p, 0)``, down to ``min(p, 0)``, below) the
    cost is a convex quadratic in the ramp's sum ``S = S(a)``, and ``S`` rises with ``a``;
    the pieces meet with no drop (going up in ``a``), so once the cost rises it keeps
    rising. ``hi`` when it fits; ``lo`` when it does not fit and the cost rises from it;
    otherwise, piece by piece from the top (each below the last one's lower edge), the
    point just under the edge above when it fits, else the largest ``a`` whose ``S`` is at
    most that piece's upper root (closed form), when it lies on the piece and in
    ``[lo, hi]`` (a root beyond the piece's end: on the rising side the root's rounding,
    half a resolution under the end; on the falling side nothing on this piece); when
    nothing fits, ``lo`` (the ramp allows no deeper cut). Each answer is checked: a found ``a`` must fit and one bisection
    resolution above it must not, and "nothing fits" must hold at each piece's minimiser;
    where rounding, an underflow or an overflow breaks a check, bisection decides
    (:func:`_affordable_bisect`)."""
    A, lo, hi, p, d, c_m, s, c = np.broadcast_arrays(*(np.asarray(v, float) for v in (
        avail_j, lo, hi, p, lead_m, push_m_per_n, s, half_count_m)))
    P = _pieces(p, d, c)

    def cost(a: np.ndarray) -> np.ndarray:
        return _piece_cost(a, P, c_m, s)
    ok_hi = cost(hi) <= A
    if ok_hi.all():
        return hi.copy() if hi.ndim else float(hi)
    # lo does not fit and the cost rises from it: nothing fits (the cost falls, then rises)
    rising = ~ok_hi & (cost(lo) > A) & (_piece_slope(lo, P, c_m, s) > 0.0)
    top, bot, b_up, d_up, b_mid, d_mid, b_dn, d_dn = P
    pieces = ((top, b_up, d_up), (bot, b_mid, d_mid), (np.full_like(p, -np.inf), b_dn, d_dn))
    a = lo.copy()
    found = np.zeros(a.shape, bool)
    done = ok_hi | (hi <= lo) | rising
    end = hi
    for edge, base, slope in pieces:
        # this piece's formula holds on [edge, end]; skip it where that misses [lo, hi]
        here = ~done & (end >= edge) & (end >= lo)
        # below a piece with nothing: its largest point, just under that piece's edge, when it fits
        top_fits = here & (end < hi) & (cost(end) <= A)
        a = np.where(top_fits, end, a)
        found |= top_fits
        done |= top_fits
        here &= ~top_fits
        root = _largest_ramp_start(_upper_root(A - base, slope, c_m), s)
        on = here & np.isfinite(root) & (root >= edge)   # else nothing fits on this piece
        hit = on & (root >= lo) & (root < end)
        # root >= end, where end does not fit: on the falling side end lies below the
        # lower root (nothing fits on this piece); on the rising side only the root's
        # rounding put it there (a budget spent to the edge, as by a force held at its last
        # answer): half a resolution under end
        under = end - _half_resolution(lo, hi)
        beyond = on & (root >= end)
        rising_end = _piece_slope(end, P, c_m, s) > 0.0
        edge_hit = beyond & rising_end & (under >= lo)
        a = np.where(hit, root, np.where(edge_hit, under, a))
        found |= hit | edge_hit
        # on the falling side nothing fits on this piece, but the piece below starts under
        # a jump down (the pieces jump up at max(p, 0) > s): go on to it
        done |= on & ~(beyond & ~rising_end)
        end = np.minimum(end, np.nextafter(edge, -np.inf))
    fits = cost(a) <= A
    # the root's rounding can leave it an ulp over the budget: half a resolution back (not
    # below lo: a root within that of lo has lo as its answer, to the same resolution)
    a2 = np.maximum(a - _half_resolution(lo, hi), lo)
    back = found & ~fits & (cost(a2) <= A)
    a = np.where(back, a2, a)
    fits = fits | back
    # largest: one bisection resolution above it does not fit
    step_up = np.minimum(a + (hi - lo) * _RESOLUTION, hi)
    short = found & fits & (a < hi) & (cost(step_up) <= A)
    # nothing fits: not even at a piece's minimiser (within [lo, hi])
    missed = np.zeros(a.shape, bool)
    end = hi
    for edge, base, slope in pieces:
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            s_min = np.where(c_m > 0.0, -slope / (2.0 * c_m), np.where(slope > 0.0, -np.inf, np.inf))
        first = np.maximum(edge, lo)
        amin = np.clip(_largest_ramp_start(s_min, s), first, end)
        missed |= ~found & (first <= end) & (cost(amin) <= A)
        end = np.minimum(end, np.nextafter(edge, -np.inf))
    unsure = ~ok_hi & ~rising & (hi > lo) & ((found & ~fits) | short | missed)
    out = np.where(ok_hi, hi, np.where(found & fits, a, lo))
    if unsure.any():
        out = np.where(unsure, _affordable_bisect(A, lo, hi, p, d, c_m, s, c), out)
    return out if out.ndim else float(out)


def below_ramp_force(avail_j: Any, lo: Any, p: Any, lead_m: Any, push_m_per_n: Any, s: Any,
                     half_count_m: Any) -> Any:
    """Where even the ramp's lower end ``lo`` does not fit (vectorised): the largest ``a`` in
    ``[0, lo]`` that fits, else the one of least cost there."""
    A, lo, p, d, c_m, s, c = np.broadcast_arrays(*(np.asarray(v, float) for v in (
        avail_j, lo, p, lead_m, push_m_per_n, s, half_count_m)))
    a = np.asarray(affordable_force(A, np.zeros_like(lo), lo, p, d, c_m, s, c), float)
    fits = plan_cost_j(a, p, d, c_m, s, c) <= A
    with np.errstate(invalid="ignore", divide="ignore"):
        least = np.where(c_m > 0.0, _largest_ramp_start(-d / (2.0 * c_m), s), np.where(d > 0.0, 0.0, lo))
    return np.where(fits, a, np.clip(least, 0.0, lo))


def _affordable_bisect(A: Any, lo: Any, hi: Any, p: Any, d: Any, c_m: Any, s: Any, c: Any) -> Any:
    """:func:`affordable_force` by bisection: the cost's minimiser on ``[lo, hi]`` (on the
    slope), then the crossing between it and ``hi``; ``lo`` when nothing fits. The fallback
    where the closed form sits on the budget's edge within rounding."""
    A, lo, hi, p, d, c_m, s, c = np.broadcast_arrays(*(np.asarray(v, float) for v in (A, lo, hi, p, d, c_m, s, c)))
    P = _pieces(p, d, c)

    def cost(a: np.ndarray) -> np.ndarray:
        return _piece_cost(a, P, c_m, s)
    ok_hi = cost(hi) <= A
    a, b = lo.copy(), hi.copy()
    for _ in range(_BISECT):
        m = 0.5 * (a + b)
        up = _piece_slope(m, P, c_m, s) > 0
        b = np.where(up, m, b)
        a = np.where(up, a, m)
    amin = np.where(_piece_slope(lo, P, c_m, s) > 0, lo, a)
    # where the pieces jump (at max(p, 0) > s) the least cost can sit just under the jump
    under = np.nextafter(np.maximum(p, 0.0), -np.inf)
    amin = np.where((under >= lo) & (under <= hi) & (cost(under) < cost(amin)), under, amin)
    fits = cost(amin) <= A
    a, b = amin.copy(), hi.copy()
    for _ in range(_BISECT):
        m = 0.5 * (a + b)
        fit = cost(m) <= A
        a = np.where(fit, m, a)
        b = np.where(fit, b, m)
    return np.where(ok_hi, hi, np.where(fits, a, lo))


def _pieces_scalar(p: float, d: float, c: float) -> tuple[tuple[float, float, float], ...]:
    """:func:`_pieces` in floats, as ``(edge, base, slope)`` from the top piece down (the
    bottom piece's edge is ``-inf``)."""
    return ((p if p > 0.0 else 0.0, -c * p, d + 2.0 * c),
            (p if p < 0.0 else 0.0, c * (p if p > 0.0 else -p), d),
            (-math.inf, c * p, d - 2.0 * c))


def _affordable_scalar(A: float, lo: float, hi: float, p: float, d: float, c_m: float, s: float,
                       c: float) -> float:
    """:func:`affordable_force` for one cell, in floats (the servo tick), with the same checks
    and the same answers. The tick's case, a held force ``p >= 0`` and ``lo >= 0`` (two
    pieces: ``[0, p)``, base ``c p`` and slope ``d``, and from ``p`` up, base ``-c p`` and
    slope ``d + 2c``), is written out; others take :func:`_affordable_pieces_scalar`."""
    if p < 0.0 or lo < 0.0:
        return _affordable_pieces_scalar(A, lo, hi, p, d, c_m, s, c)
    cp = c * p
    up = d + 2.0 * c
    Sh = hi if hi <= s else hi * hi / (2.0 * s) + 0.5 * hi + 0.125 * s
    if (up * Sh - cp if hi >= p else cp + d * Sh) + c_m * Sh * Sh <= A or hi <= lo:
        return hi if hi > lo else lo
    # lo does not fit and the cost rises from it: nothing fits (the cost falls, then rises)
    S = lo if lo <= s else lo * lo / (2.0 * s) + 0.5 * lo + 0.125 * s
    if lo >= p:
        if up * S - cp + c_m * S * S > A and up + 2.0 * c_m * S > 0.0:
            return lo
    elif cp + d * S + c_m * S * S > A and d + 2.0 * c_m * S > 0.0:
        return lo
    a = math.nan                     # the answer's candidate; NaN: nothing fits
    if hi >= p:
        # the piece from p up: the quadratic's upper root, mapped back through S
        root = _root_force(A + cp, up, c_m, s)
        # root >= hi, where hi does not fit: on the falling side hi lies below the lower
        # root, and nothing fits from p up
        end = math.nextafter(p, -math.inf)
        if root >= p and (root < hi or up + 2.0 * c_m * Sh > 0.0):
            if lo <= root < hi:
                a = root
            elif root >= hi:
                # the rising side: only the root's rounding put it at or above hi
                a = hi - _half_resolution(lo, hi)
                if a < lo:
                    a = math.nan
            end = -math.inf
        elif end >= lo:
            # nothing from p up (root >= hi on the falling side included: the piece below
            # starts under a jump down): the largest point below p, when it fits
            S = _ramp_sum_scalar(end, s)
            if cp + d * S + c_m * S * S <= A:
                return end
    else:
        end = hi
    if end >= lo:
        # the piece [0, p)
        root = _root_force(A - cp, d, c_m, s)
        if root >= 0.0 and lo <= root < end:
            a = root
        elif root >= end:
            # end does not fit: on the rising side only the root's rounding put it there
            under = end - _half_resolution(lo, hi)
            if d + 2.0 * c_m * _ramp_sum_scalar(end, s) > 0.0 and under >= lo:
                a = under
    if a == a:
        return _checked_scalar(a, A, lo, hi, p, d, c_m, s, c)
    return _nothing_fits_scalar(A, lo, hi, p, d, c_m, s, c)


def _below_ramp_scalar(A: float, lo: float, p: float, d: float, c_m: float, s: float, c: float) -> float:
    """Where even the ramp's lower end ``lo`` does not fit: the largest ``a`` in ``[0, lo]``
    that fits, else the one of least cost there."""
    a = _affordable_scalar(A, 0.0, lo, p, d, c_m, s, c)
    if _cost_scalar(a, p, d, c_m, s, c) <= A:
        return a
    if c_m > 0.0:
        S = -d / (2.0 * c_m)
        a = S if S < s else (s if S < 1.125 * s else 0.5 * (math.sqrt(8.0 * s * S) - s))
    else:
        a = 0.0 if d > 0.0 else lo
    return 0.0 if a < 0.0 else (lo if a > lo else a)


def _root_force(r: float, slope: float, c_m: float, s: float) -> float:
    """Largest ``a`` whose ramp sum ``S(a)`` is at most the upper root of
    ``slope S + c_m S^2 = r`` (:func:`_upper_root` and :func:`_largest_ramp_start` in
    floats); ``-inf`` when there is none (a double root or an underflow included: the
    callers' checks decide those)."""
    S2 = -math.inf
    if c_m > 0.0:
        disc = slope * slope + 4.0 * c_m * r
        if disc > 0.0:
            sq = math.sqrt(disc)
            S2 = (sq - slope) / (2.0 * c_m) if slope <= 0.0 else 2.0 * r / (slope + sq)
    elif slope > 0.0:
        S2 = r / slope
    return S2 if S2 < s else (s if S2 < 1.125 * s else 0.5 * (math.sqrt(8.0 * s * S2) - s))


def _checked_scalar(a: float, A: float, lo: float, hi: float, p: float, d: float, c_m: float, s: float,
                    c: float) -> float:
    """``a``, a closed form's answer in ``[lo, hi)``, once checked: it fits (or does half a
    bisection resolution lower: the root's rounding) and one resolution above it does not;
    else the bisection's answer."""
    if _cost_scalar(a, p, d, c_m, s, c) > A:
        a -= _half_resolution(lo, hi)
        if a < lo:
            a = lo                   # a root within half a resolution of lo: lo, to that resolution
        if _cost_scalar(a, p, d, c_m, s, c) > A:
            return _bisect_scalar(A, lo, hi, p, d, c_m, s, c)
    u = a + (hi - lo) * _RESOLUTION
    if u < hi and _cost_scalar(u, p, d, c_m, s, c) <= A:
        return _bisect_scalar(A, lo, hi, p, d, c_m, s, c)
    return a


def _nothing_fits_scalar(A: float, lo: float, hi: float, p: float, d: float, c_m: float, s: float,
                         c: float) -> float:
    """``lo`` when the cost exceeds ``A`` at each piece's minimiser within ``[lo, hi]``, else
    the bisection's answer."""
    end = hi
    for edge, base, slope in _pieces_scalar(p, d, c):
        first = edge if edge > lo else lo
        if first <= end:
            if c_m > 0.0:
                a = -slope / (2.0 * c_m)
                if a >= 1.125 * s:
                    a = 0.5 * (math.sqrt(8.0 * s * a) - s)
                elif a > s:
                    a = s
            else:
                a = -math.inf if slope > 0.0 else math.inf
            a = first if a < first else (end if a > end else a)
            S = _ramp_sum_scalar(a, s)
            if base + slope * S + c_m * S * S <= A:
                return _bisect_scalar(A, lo, hi, p, d, c_m, s, c)
            if first == lo:
                break
        nxt = math.nextafter(edge, -math.inf)
        if nxt < end:
            end = nxt
    return lo


def _affordable_pieces_scalar(A: float, lo: float, hi: float, p: float, d: float, c_m: float, s: float,
                              c: float) -> float:
    """:func:`_affordable_scalar` over all three pieces (a held force below 0, or a ramp
    reaching below 0), as :func:`affordable_force` walks them."""
    if hi <= lo or _cost_scalar(hi, p, d, c_m, s, c) <= A:
        return hi if hi > lo else lo
    if _cost_scalar(lo, p, d, c_m, s, c) > A and _slope_sign_scalar(lo, p, d, c_m, s, c) > 0.0:
        return lo                    # the cost rises from lo, where it does not fit
    end = hi
    for edge, base, slope in _pieces_scalar(p, d, c):
        if end < edge:
            continue                 # hi lies below this piece
        if end < lo:
            break
        if end < hi and _cost_scalar(end, p, d, c_m, s, c) <= A:
            return end               # just under the edge of a piece with nothing
        a = _root_force(A - base, slope, c_m, s)
        if a >= edge:
            if a >= end:
                # end does not fit: on the falling side it lies below the lower root
                # (nothing on this piece; the next starts under a jump down); on the rising
                # side only the root's rounding put it there
                if _slope_sign_scalar(end, p, d, c_m, s, c) > 0.0:
                    a = end - _half_resolution(lo, hi)
                    if a < lo:
                        break
                    return _checked_scalar(a, A, lo, hi, p, d, c_m, s, c)
            elif a < lo:
                break
            else:
                return _checked_scalar(a, A, lo, hi, p, d, c_m, s, c)
        end = min(end, math.nextafter(edge, -math.inf))
    return _nothing_fits_scalar(A, lo, hi, p, d, c_m, s, c)


def _piece_at(a: float, p: float, d: float, c: float) -> tuple[float, float]:
    """``(base, slope)`` of the piece of :func:`_pieces_scalar` that holds ``a``."""
    for edge, base, slope in _pieces_scalar(p, d, c):
        if a >= edge:
            return base, slope
    return base, slope               # a = -inf or NaN: the bottom piece


def _slope_sign_scalar(a: float, p: float, d: float, c_m: float, s: float, c: float) -> float:
    """A number of the sign of :func:`_piece_slope` at ``a`` (``S`` rises with ``a``)."""
    S = _ramp_sum_scalar(a, s)
    return _piece_at(a, p, d, c)[1] + 2.0 * c_m * S


def _cost_scalar(a: float, p: float, d: float, c_m: float, s: float, c: float) -> float:
    """:func:`plan_cost_j` in floats."""
    S = _ramp_sum_scalar(a, s)
    base, slope = _piece_at(a, p, d, c)
    return base + slope * S + c_m * S * S


def _bisect_scalar(A: float, lo: float, hi: float, p: float, d: float, c_m: float, s: float,
                   c: float) -> float:
    """:func:`_affordable_bisect` for one cell, in floats (the slope's sign is that of
    :func:`_slope_sign_scalar`: ``dS/da > 0``)."""
    def cost(a: float) -> float:
        return _cost_scalar(a, p, d, c_m, s, c)

    def slope(a: float) -> float:
        return _slope_sign_scalar(a, p, d, c_m, s, c)
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
    # where the pieces jump (at max(p, 0) > s) the least cost can sit just under the jump
    under = math.nextafter(max(p, 0.0), -math.inf)
    if lo <= under <= hi and cost(under) < cost(a):
        a = under
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
