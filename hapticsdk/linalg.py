"""The matrix exponential of small dense matrices, in numpy alone.

The exact zero-order-hold discretisations of :mod:`hapticsdk.passivity` and
:mod:`hapticsdk.sim.arm` need ``expm`` of 3x3 to 10x10 matrices. ``scipy.linalg``
would cost 100-500 ms of import time on every ``hapticsdk render``, so :func:`expm`
here implements the scaling-and-squaring method with diagonal Pade approximants of
Higham (SIAM J. Matrix Anal. Appl. 26(4), 2005, "The scaling and squaring method for
the matrix exponential revisited"):

* the smallest degree ``m`` in 3, 5, 7, 9, 13 whose bound ``theta_m`` on the 1-norm
  keeps the backward error of ``r_m(A)`` below the unit roundoff of double precision
  is used directly;
* above ``theta_13``, ``A`` is scaled by ``2^-s`` so that its 1-norm is at most
  ``theta_13``, ``r_13`` is evaluated, and the result is squared ``s`` times.

``r_m(A) = q_m(A)^-1 p_m(A)`` with ``p_m(A) = sum_j c_j A^j``, ``q_m(A) = p_m(-A)``; the
coefficients ``c_j = (2m - j)! m! / ((2m)! j! (m - j)!)`` are computed exactly (as
fractions) when the module is imported, not typed in. Odd and even powers are split,
``p_m = U + V``, ``q_m = V - U``, so one linear solve gives ``r_m``.

The tests compare :func:`expm` with ``scipy.linalg.expm`` on the matrices the SDK uses
and on random ones, within the forward-error bound ``cond(exp, A) * u``.
"""

from __future__ import annotations

from fractions import Fraction
from math import factorial

import numpy as np

__all__ = ["expm", "pade_coefficients"]

#: Largest 1-norm for which the [m/m] Pade approximant has backward error <= 2^-53
#: (Higham 2005, Table 2.3), for m = 3, 5, 7, 9, 13.
THETA: dict[int, float] = {
    3: 1.495585217958292e-2,
    5: 2.539398330063230e-1,
    7: 9.504178996162932e-1,
    9: 2.097847961257068e0,
    13: 5.371920351148152e0,
}


def pade_coefficients(m: int) -> tuple[float, ...]:
    """Coefficients ``c_0 .. c_m`` of the numerator ``p_m`` of the diagonal [m/m] Pade
    approximant of ``exp(x)``: ``c_j = (2m - j)! m! / ((2m)! j! (m - j)!)``, rounded once
    from the exact rational value."""
    return tuple(float(Fraction(factorial(2 * m - j) * factorial(m),
                                factorial(2 * m) * factorial(j) * factorial(m - j)))
                 for j in range(m + 1))


_C: dict[int, tuple[float, ...]] = {m: pade_coefficients(m) for m in THETA}


def _pade(A: np.ndarray, m: int) -> np.ndarray:
    """``r_m(A)`` for a (square, float or complex) ``A`` with ``||A||_1 <= theta_m``."""
    c = _C[m]
    n = A.shape[0]
    I = np.eye(n, dtype=A.dtype)
    A2 = A @ A
    if m < 13:
        # U = A (c1 I + c3 A^2 + c5 A^4 + ...), V = c0 I + c2 A^2 + c4 A^4 + ...
        u = c[1] * I
        v = c[0] * I
        P = I
        for k in range(1, m // 2 + 1):
            P = P @ A2
            u = u + c[2 * k + 1] * P
            v = v + c[2 * k] * P
        U = A @ u
        V = v
    else:
        A4 = A2 @ A2
        A6 = A4 @ A2
        U = A @ (A6 @ (c[13] * A6 + c[11] * A4 + c[9] * A2)
                 + c[7] * A6 + c[5] * A4 + c[3] * A2 + c[1] * I)
        V = (A6 @ (c[12] * A6 + c[10] * A4 + c[8] * A2)
             + c[6] * A6 + c[4] * A4 + c[2] * A2 + c[0] * I)
    return np.linalg.solve(V - U, V + U)


def expm(A: "np.ndarray | list[list[float]]") -> np.ndarray:
    """Matrix exponential ``e^A`` of a square matrix (any units: ``A`` is usually a
    system matrix times a period, dimensionless).

    Args:
        A: (n, n) real or complex matrix; finite.

    Returns:
        (n, n) array of the same kind (float64 or complex128).

    Raises:
        ValueError: ``A`` is not a square 2-D matrix or holds a NaN or an infinity.
    """
    a = np.asarray(A)
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise ValueError(f"expm needs a square 2-D matrix, got shape {a.shape}")
    a = a.astype(np.complex128 if np.iscomplexobj(a) else np.float64, copy=True)
    if a.size == 0:
        return a
    if not np.isfinite(a).all():
        raise ValueError("expm needs a finite matrix")
    if a.shape[0] == 1:
        return np.exp(a)
    norm1 = float(np.max(np.sum(np.abs(a), axis=0)))
    for m in (3, 5, 7, 9):
        if norm1 <= THETA[m]:
            return _pade(a, m)
    s = 0
    if norm1 > THETA[13]:
        s = max(0, int(np.ceil(np.log2(norm1 / THETA[13]))))
        a = a * (0.5 ** s)
    E = _pade(a, 13)
    for _ in range(s):
        E = E @ E
    return E
