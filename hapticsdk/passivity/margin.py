"""The Colgate & Schenkel passivity margin of a sampled wall, its label, and the
eigenvalue (stability) limit of the exactly discretised device (see the package docstring)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..argcheck import number_array
from ..errors import ValidationError
from ..linalg import expm
from ..special import gammainc2


#: Label of a wall that is passive by the Colgate condition (margin > 0).
PASSIVE = "passive"
#: Label of a wall whose stability relies on the hand's impedance (margin <= 0).
STABLE_BY_ASSUMPTION = "stable-by-assumption (not passive)"


def _check_nonneg(name: str, value: float) -> float:
    from ..checks import is_number
    if not is_number(value):
        raise ValidationError(f"must be a finite number >= 0, got {value!r}", field=name)
    v = float(value)
    if not math.isfinite(v) or v < 0:
        raise ValidationError(f"must be a finite number >= 0, got {value!r}", field=name)
    return v


def _check_mass(mass_kg: Any) -> np.ndarray:
    """Apparent mass (kg) as a float array; finite and > 0, else ValidationError(field="mass_kg")."""
    try:
        m = np.asarray(mass_kg, float)
    except (TypeError, ValueError):
        raise ValidationError(f"must be a finite number > 0 (kg), got {mass_kg!r}", field="mass_kg") from None
    if m.size == 0 or not np.all(np.isfinite(m)) or not np.all(m > 0):
        raise ValidationError(f"must be a finite number > 0 (kg), got {mass_kg!r}", field="mass_kg")
    return m


def _check_arrays(**named: tuple[Any, str]) -> list[np.ndarray]:
    """Each ``name=(value, rule)`` as a float array, checked (ValidationError naming it):
    ``"finite"``, ``">=0"``, ``">0"`` (finite too) or ``"ticks"`` (a whole number >= 0).
    A nonsensical wall (a negative period, a NaN stiffness) gets no number, not a margin
    that reads as passive."""
    out = []
    for name, (value, rule) in named.items():
        a = number_array(value, name, finite=False)   # numbers only (no bool, no string)
        if a.size == 0:
            raise ValidationError(f"must be a number or an array of numbers, got {value!r}", field=name)
        if not np.all(np.isfinite(a)):
            raise ValidationError(f"must be finite, got {value!r}", field=name)
        if rule == ">=0" and not np.all(a >= 0):
            raise ValidationError(f"must be >= 0, got {value!r}", field=name)
        if rule == ">0" and not np.all(a > 0):
            raise ValidationError(f"must be > 0, got {value!r}", field=name)
        if rule == "ticks" and not (np.all(a >= 0) and np.all(a == np.floor(a))):
            raise ValidationError(f"must be a whole number of ticks >= 0, got {value!r}", field=name)
        out.append(a)
    return out


def mass_correction(b: Any, T: Any, d: Any, mass_kg: Any) -> Any:
    """Ratio ``f = K_crit(ZOH eigenvalues) / K_crit(Colgate)`` for a device of mass m (-).

    Derivation (B = 0, wall ``F_n = -K x_{n-d}`` on ``m x'' + b x' = F`` under a ZOH).
    With ``delta = b T / m`` (-), ``A = tanh(delta/2)``, ``rho = coth(delta/2)/2 - 1/delta``
    and ``t = tan(theta/2)`` at the frequency ``theta = omega T`` where the closed loop
    crosses the unit circle, the pulse transfer function ``b G(z)/T = 1/(z-1) - g/(z-e)``
    (``e = exp(-delta)``, ``g = (1-e)/delta``) gives exactly

    * phase: ``(2d+1) atan(t) - atan(2 rho t) = atan(A / t)``,
    * gain:  ``k = K T / b = (2 t^2 / A) sqrt(1 + A^2/t^2) / sqrt((1 + t^2)(1 + 4 rho^2 t^2))``.

    d = 0: the phase equation is linear in t^2, ``t^2 = A / (1 - 2 rho (1 + A))``, and the
    gain collapses to the closed form ``k = delta (1 - e) / (1 - (1 + delta) e)``, i.e.
    ``f = delta P(1, delta) / (2 P(2, delta))`` with ``P`` the regularised lower incomplete
    gamma function (``1 - e``, ``1 - (1+delta) e``; evaluated without cancellation). The
    crossing is a complex pair (``cos theta = 1 - delta + ...``, not z = -1) while
    ``2 A (1 + A) > delta`` (delta below about 3.8); beyond, it is at z = -1 and
    ``f = 1 / (1 - 2 A / delta)``. Both are exact (checked against the eigenvalues to 1e-8).

    d >= 1: with ``n = 2d + 1`` and ``t^2 = delta (tau0 + tau1 delta + ...)``, solving the
    phase equation order by order (``tau0 = 1/(2n)``, ``tau1 = 1/(6 n^2) - 1/12``) and
    expanding the gain gives the second-order series

        ``f = 1 + (n^2 + 1)/(12 n) delta - (13 n^4 + 10 n^2 - 63)/(1440 n^2) delta^2``

    (its d = 0 case, ``1 + delta/6 + delta^2/36``, is the expansion of the closed form).
    Against the eigenvalue limit it is within 0.05 % for d <= 2, delta <= 0.2 and within
    0.14 % / 0.72 % (d = 1 / 2) at delta = 0.5; in every check (d <= 6, delta <= 3) it is
    below the exact value (conservative), and it is floored at 1 (the plain formula).

    Args:
        b: physical viscous damping of the device (N*s/m).
        T: servo period (s).
        d: extra samples of delay (0 selects the exact d = 0 form).
        mass_kg: apparent mass of the device (kg), finite and > 0.

    Returns:
        ``f >= 1`` (-); arrays broadcast.
    """
    m = _check_mass(mass_kg)
    b, T, d = _check_arrays(b=(b, ">=0"), T=(T, ">0"), d=(d, "ticks"))
    dl = b * T / m
    dl, d = np.broadcast_arrays(dl, d)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        a = np.tanh(0.5 * dl)
        small = dl < 1e-4
        exact0 = dl * -np.expm1(-dl) / (2.0 * gammainc2(dl))
        far = 1.0 / (1.0 - 2.0 * a / dl)
        f0 = np.where(small, 1.0 + dl / 6.0 + dl * dl / 36.0,
                      np.where(2.0 * a * (1.0 + a) > dl, exact0, far))
        n = 2.0 * d + 1.0
        fs = 1.0 + (n * n + 1.0) / (12.0 * n) * dl - (13.0 * n**4 + 10.0 * n * n - 63.0) / (1440.0 * n * n) * dl * dl
        f = np.where(d == 0, f0, np.maximum(fs, 1.0))
    return f if f.ndim else float(f)


def passivity_margin(K: Any, B: Any, b: Any, T: Any, d: Any = 0, *, mass_kg: Any = None) -> Any:
    """Colgate passivity margin of a sampled virtual wall (N*s/m).

    Args:
        K: wall stiffness (N/mm).
        B: virtual damping of the wall (N*s/m); its magnitude consumes margin.
        b: physical viscous damping of the device (N*s/m).
        T: servo period (s).
        d: extra samples of computational delay (0 when the force of sample n is
            computed from the position of sample n).
        mass_kg: apparent mass of the device (kg, keyword-only). None (default): the
            Colgate margin below, which does not depend on the mass. Given: the
            *stability* margin of the uncoupled device + wall, with the ZOH mass effect
            (:func:`mass_correction`, ``f(delta)``, ``delta = b T / m``):
            ``margin = b_eff - (K T (1/2 + d) + |B|)`` with the effective damping
            ``b_eff = |B| + (b - |B|) f`` (N*s/m), so it is 0 exactly at
            ``critical_stiffness(..., mass_kg=m)``. It is not a passivity margin (passivity
            does not depend on m); :func:`classify_wall` never labels from it.

    Returns:
        ``b - (K T (1/2 + d) + |B|)`` with K converted to N/m; arrays broadcast.
        Positive: passive without the hand. The critical stiffness is
        ``K_crit = (b - |B|) / (T (1/2 + d))``.
    """
    K, B, b, T, d = _check_arrays(K=(K, ">=0"), B=(B, "finite"), b=(b, ">=0"), T=(T, ">0"), d=(d, "ticks"))
    K = K * 1000.0
    aB = np.abs(B)
    load = K * T * (0.5 + d) + aB
    b_eff = b
    if mass_kg is not None:
        b_eff = aB + (b_eff - aB) * mass_correction(b, T, d, mass_kg)
    out = np.asarray(b_eff - load)
    return out if out.ndim else float(out)


def critical_stiffness(b: float, T: float, d: int = 0, B: float = 0.0, *, mass_kg: float | None = None) -> float:
    """Stiffness (N/mm) where :func:`passivity_margin` crosses zero.

    ``(b - |B|) / (T (1/2 + d))``; with ``mass_kg`` (kg) multiplied by
    :func:`mass_correction` ``f(b T / m, d)``, the ZOH eigenvalue stability limit of the
    uncoupled device (exact for d = 0, second order in ``b T / m`` for d >= 1).
    """
    _, b, T, d, B = _check_wall(0.0, b, T, d, B)
    k = max(b - abs(B), 0.0) / (T * (0.5 + d)) / 1000.0
    if mass_kg is None:
        return k
    return k * float(mass_correction(b, T, d, mass_kg))


def _check_wall(K: Any, b: Any, T: Any, d: Any, B: Any) -> tuple[float, float, float, int, float]:
    """Validated scalar wall parameters (see :func:`classify_wall`)."""
    def num(v: Any, name: str) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise ValidationError(f"must be a number, got {v!r}", field=name)
        x = float(v)
        if not math.isfinite(x):
            raise ValidationError(f"must be finite, got {v!r}", field=name)
        return x
    K_, b_, T_, B_ = num(K, "K"), num(b, "b"), num(T, "T"), num(B, "B")
    if K_ < 0:
        raise ValidationError(f"stiffness must be >= 0 N/mm, got {K!r}", field="K")
    if b_ < 0:
        raise ValidationError(f"device damping must be >= 0 N*s/m, got {b!r}", field="b")
    if T_ <= 0:
        raise ValidationError(f"period must be > 0 s, got {T!r}", field="T")
    if isinstance(d, bool) or not isinstance(d, (int, np.integer)) and not (
            isinstance(d, (float, np.floating)) and float(d).is_integer()):
        raise ValidationError(f"delay must be a whole number of ticks, got {d!r}", field="d")
    if int(d) < 0:
        raise ValidationError(f"delay must be >= 0 ticks, got {d!r}", field="d")
    return K_, b_, T_, int(d), B_


def classify_wall(K: float, b: float, T: float, d: int = 0, B: float = 0.0, *,
                  mass_kg: float | None = None) -> dict[str, Any]:
    """Margin (N*s/m), critical stiffness (N/mm) and the label of a wall.

    The label is ``"passive"`` only when the margin is positive; a wall that needs the
    user's hand to be stable is ``"stable-by-assumption (not passive)"``.

    Raises :class:`~hapticsdk.errors.ValidationError` (naming the argument) for a
    stiffness, device damping or period that is negative, zero (period) or not finite, a
    delay that is not a whole number >= 0, or a virtual damping that is not finite: a
    nonsensical wall gets no verdict, least of all "passive".

    With ``mass_kg`` (kg) the same fields (and the label, which stays the Colgate
    *passivity* verdict) are returned plus ``mass_kg``, ``delta_bT_over_m`` (-),
    ``stability_margin_ns_per_m`` (:func:`passivity_margin` with the mass, N*s/m) and
    ``stability_critical_stiffness_n_per_mm`` (ZOH eigenvalue limit of the uncoupled
    device, N/mm). Between the two critical stiffnesses the free device is stable but
    the wall is not passive, so no passivity is claimed there.
    """
    K, b, T, d, B = _check_wall(K, b, T, d, B)
    m = float(passivity_margin(K, B, b, T, d))
    out = {"stiffness_n_per_mm": float(K), "virtual_damping_ns_per_m": float(B),
           "device_damping_ns_per_m": float(b), "period_s": float(T), "delay_ticks": int(d),
           "margin_ns_per_m": m, "critical_stiffness_n_per_mm": critical_stiffness(b, T, d, B),
           "label": PASSIVE if m > 0 else STABLE_BY_ASSUMPTION}
    if mass_kg is not None:
        mk = float(_check_mass(mass_kg))
        out.update({"mass_kg": mk, "delta_bT_over_m": max(float(b), 0.0) * float(T) / mk,
                    "stability_margin_ns_per_m": float(passivity_margin(K, B, b, T, d, mass_kg=mk)),
                    "stability_critical_stiffness_n_per_mm": critical_stiffness(b, T, d, B, mass_kg=mk)})
    return out


def _zoh_device(m: float, b: float, T: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretisation of ``m x'' + b x' = F`` (SI): ``Phi`` (2x2), ``Gamma`` (2,)."""
    M = np.zeros((3, 3))
    M[0, 1] = 1.0
    M[1, 1] = -b / m
    M[1, 2] = 1.0 / m
    E = expm(M * T)
    return E[:2, :2], E[:2, 2]


def spectral_radius(K: float, m: float, b: float, T: float, d: int = 0) -> float:
    """Largest eigenvalue magnitude of the device ``m x'' + b x' = F`` (SI) with the wall
    ``F_n = -K x_{n-d}`` (K in N/mm) under a zero-order hold. < 1: asymptotically stable."""
    K, b, T, d, _ = _check_wall(K, b, T, d, 0.0)
    m = float(_check_mass(m))
    Phi, G = _zoh_device(m, b, T)
    n = 2 + d
    A = np.zeros((n, n))
    A[:2, :2] = Phi
    k = float(K) * 1000.0
    # force uses x delayed by d samples: extra states hold x_{n-1} ... x_{n-d}
    if d == 0:
        A[:2, 0] += -k * G
    else:
        A[:2, n - 1] += -k * G
        A[2, 0] = 1.0
        for i in range(3, n):
            A[i, i - 1] = 1.0
    return float(np.max(np.abs(np.linalg.eigvals(A))))


def critical_stiffness_eig(m: float, b: float, T: float, d: int = 0, *, rtol: float = 1e-6) -> float:
    """Stability limit K (N/mm) of the ZOH-discretised device + delayed wall, by bisection
    on the spectral radius (independent of :func:`passivity_margin`)."""
    _, b, T, d, _ = _check_wall(0.0, b, T, d, 0.0)
    m = float(_check_mass(m))
    lo, hi = 0.0, max(critical_stiffness(b, T, d) * 4.0, 1e-6)
    while spectral_radius(hi, m, b, T, d) < 1.0:
        hi *= 2.0
    lo = hi * 1e-9
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        if spectral_radius(mid, m, b, T, d) < 1.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
