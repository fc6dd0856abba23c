"""Shape-preserving piecewise cubic Hermite interpolation (PCHIP) in numpy alone.

:class:`hapticsdk.calibration.PiezoTable` interpolates its grid over frequency with
PCHIP every time a table is built, which happens on every ``hapticsdk render`` of a
material with a roughness dimension; ``scipy.interpolate`` would cost 100-400 ms of
import time there (it pulls in ``scipy.optimize``, ``scipy.linalg`` and
``scipy.special``). :class:`Pchip` computes the same interpolant as
``scipy.interpolate.PchipInterpolator(x, y, axis=0, extrapolate=False)``:

* slopes ``m_k = (y_{k+1} - y_k) / h_k`` of the intervals ``h_k = x_{k+1} - x_k``;
* at an interior knot the derivative is 0 where the neighbouring slopes differ in sign
  or one is 0, else their weighted harmonic mean
  ``(w1 + w2) / (w1 / m_{k-1} + w2 / m_k)`` with ``w1 = 2 h_k + h_{k-1}``,
  ``w2 = h_k + 2 h_{k-1}`` (Fritsch & Butland);
* at the two ends the one-sided three-point estimate, set to 0 when its sign differs
  from the end slope and limited to 3 times the end slope when the first two slopes
  differ in sign (Moler, *Numerical Computing with MATLAB*, section 3.6);
* two knots: the straight line.

Each interval holds the cubic ``c3 + c2 s + c1 s^2 + c0 s^3`` in ``s = x - x_k``,
evaluated in that order, so values agree with scipy's to the last bit or within a
rounding (the tests compare them). Outside ``[x_0, x_n]`` the value is NaN.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

__all__ = ["CubicSpline", "Pchip", "bisect_increasing"]


def _end_derivative(h0: np.ndarray, h1: np.ndarray, m0: np.ndarray, m1: np.ndarray) -> np.ndarray:
    """One-sided three-point derivative at an end knot, kept shape preserving."""
    d = ((2.0 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
    wrong_sign = np.sign(d) != np.sign(m0)
    overshoot = (np.sign(m0) != np.sign(m1)) & (np.abs(d) > 3.0 * np.abs(m0))
    d = np.where(wrong_sign, 0.0, np.where(overshoot, 3.0 * m0, d))
    return d


class _Piecewise:
    """A piecewise cubic in Hermite form, stored as power coefficients per interval."""

    x: np.ndarray
    #: per-interval power coefficients in ``s = x - x_k``, highest first:
    #: shape ``(4, n - 1) + y.shape[1:]`` (scipy ``PPoly`` order)
    c: np.ndarray

    def _set(self, x: np.ndarray, Y: np.ndarray, H: np.ndarray, m: np.ndarray, d: np.ndarray,
             shape: tuple[int, ...]) -> None:
        t = (d[:-1] + d[1:] - 2.0 * m) / H
        self.x = x
        self._shape = shape
        self._c = np.stack([t / H, (m - d[:-1]) / H - t, d[:-1], Y[:-1]])
        self.c = self._c.reshape((4, x.size - 1) + shape)

    def __call__(self, xq: Any) -> np.ndarray:
        q = np.asarray(xq, dtype=np.float64)
        flat = q.reshape(-1)
        x = self.x
        i = np.clip(np.searchsorted(x, flat, side="right") - 1, 0, x.size - 2)
        s = (flat - x[i])[:, None]
        c = self._c
        z = s
        out = c[3][i] + c[2][i] * z
        z = z * s
        out = out + c[1][i] * z
        z = z * s
        out = out + c[0][i] * z
        outside = ~((flat >= x[0]) & (flat <= x[-1]))
        if outside.any():
            out[outside] = np.nan
        return out.reshape(q.shape + self._shape)

    def piece(self, k: int) -> Callable[[float], float]:
        """The cubic of interval ``k`` (``[x_k, x_{k+1}]``) of a 1-D interpolant as a
        function of one plain float, evaluated in the same order as :meth:`__call__`
        (so bit for bit the same value inside that interval, with no numpy per call: a
        root search calls it tens of times). No NaN outside the interval."""
        if self._shape not in ((), (1,)):
            raise ValueError("piece() needs a 1-D interpolant")
        if not 0 <= k < self.x.size - 1:
            raise ValueError(f"interval {k} outside 0..{self.x.size - 2}")
        x0 = float(self.x[k])
        c0, c1, c2, c3 = (float(v) for v in self._c[:, k].ravel())

        def cubic(v: float) -> float:
            s = v - x0
            out = c3 + c2 * s
            z = s * s
            out = out + c1 * z
            z = z * s
            return out + c0 * z

        return cubic


def _prepare(x: Any, y: Any, least: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                   tuple[int, ...]]:
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.ndim != 1 or x.size < least:
        raise ValueError(f"x must be 1-D with at least {least} knots")
    if y.ndim not in (1, 2) or y.shape[0] != x.size:
        raise ValueError(f"y must have {x.size} rows, got shape {y.shape}")
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise ValueError("x and y must be finite")
    h = np.diff(x)
    if np.any(h <= 0):
        raise ValueError("x must be strictly increasing")
    Y = y.reshape(x.size, -1)
    H = h[:, None]
    m = (Y[1:] - Y[:-1]) / H
    return x, Y, H, m, y.shape[1:]


class Pchip(_Piecewise):
    """PCHIP interpolant of ``y`` over ``x`` (units of ``y`` per unit of ``x``).

    Args:
        x: (n,) strictly increasing, finite knots, n >= 2.
        y: (n,) or (n, k) finite values at the knots (each column interpolated alone).

    Calling it with an array of points of shape ``s`` returns shape ``s`` (1-D ``y``)
    or ``s + (k,)`` (2-D ``y``); NaN outside ``[x[0], x[-1]]``.
    """

    def __init__(self, x: Any, y: Any) -> None:
        x, Y, H, m, shape = _prepare(x, y, 2)
        if x.size == 2:
            d = np.concatenate([m, m])
        else:
            d = np.zeros_like(Y)
            w1 = 2.0 * H[1:] + H[:-1]
            w2 = H[1:] + 2.0 * H[:-1]
            flat = (np.sign(m[1:]) != np.sign(m[:-1])) | (m[1:] == 0) | (m[:-1] == 0)
            with np.errstate(divide="ignore", invalid="ignore"):
                inv = (w1 / m[:-1] + w2 / m[1:]) / (w1 + w2)
                d[1:-1] = np.where(flat, 0.0, 1.0 / inv)
            d[0] = _end_derivative(H[0], H[1], m[0], m[1])
            d[-1] = _end_derivative(H[-1], H[-2], m[-1], m[-2])
        self._set(x, Y, H, m, d, shape)


class CubicSpline(_Piecewise):
    """Not-a-knot cubic spline of ``y`` over ``x`` (the default of
    ``scipy.interpolate.CubicSpline``), with NaN outside ``[x[0], x[-1]]``.

    The knot slopes ``d`` solve the usual C2 conditions at the interior knots,
    ``h_k d_{k-1} + 2 (h_{k-1} + h_k) d_k + h_{k-1} d_{k+1} = 3 (h_k m_{k-1} + h_{k-1} m_k)``,
    and a continuous third derivative at the second and the last-but-one knot (one dense
    solve: meant for tables of tens of knots).

    Args:
        x: (n,) strictly increasing, finite knots, n >= 4.
        y: (n,) or (n, k) finite values.
    """

    def __init__(self, x: Any, y: Any) -> None:
        x, Y, H, m, shape = _prepare(x, y, 4)
        n = x.size
        h = H[:, 0]
        A = np.zeros((n, n))
        b = np.empty_like(Y)
        k = np.arange(1, n - 1)
        A[k, k - 1] = h[k]
        A[k, k] = 2.0 * (h[k - 1] + h[k])
        A[k, k + 1] = h[k - 1]
        b[1:-1] = 3.0 * (H[1:] * m[:-1] + H[:-1] * m[1:])
        # not-a-knot: the first two (last two) intervals are one cubic
        A[0, 0], A[0, 1] = h[1], h[0] + h[1]
        b[0] = ((h[0] + 2.0 * (h[0] + h[1])) * h[1] * m[0] + h[0] ** 2 * m[1]) / (h[0] + h[1])
        A[-1, -2], A[-1, -1] = h[-1] + h[-2], h[-2]
        b[-1] = (h[-1] ** 2 * m[-2] + (2.0 * (h[-2] + h[-1]) + h[-1]) * h[-2] * m[-1]) / (h[-2] + h[-1])
        d = np.linalg.solve(A, b)
        self._set(x, Y, H, m, d, shape)


def bisect_increasing(fun: Callable[[float], float], lo: float, hi: float, target: float, *,
                      xtol: float = 1e-12, rtol: float = 1e-12) -> float:
    """The ``x`` in ``[lo, hi]`` where the increasing ``fun`` reaches ``target``, by
    bisection, to within ``xtol + rtol |x|`` (units of ``x``). Requires
    ``fun(lo) <= target <= fun(hi)``; no derivative, no scipy."""
    a, b = float(lo), float(hi)
    while b - a > xtol + rtol * max(abs(a), abs(b)):
        mid = 0.5 * (a + b)
        if mid <= a or mid >= b:
            break
        if fun(mid) < target:
            a = mid
        else:
            b = mid
    return 0.5 * (a + b)
