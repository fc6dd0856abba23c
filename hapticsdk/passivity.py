"""Passivity of sampled-data virtual walls: the analytic margin and a time-domain
passivity observer/controller.

Two tools:

* :func:`passivity_margin` is the Colgate & Schenkel condition for a wall
  ``F = -(K x + B v)`` computed every ``T`` seconds, held by a zero-order hold and
  applied ``d`` extra samples late, on a device with physical viscous damping ``b``:
  ``margin = b - (K T (1/2 + d) + |B|)`` (N*s/m). A positive margin means the device +
  wall is passive without any help from the hand; :func:`classify_wall` turns it into
  the label ``"passive"`` or ``"stable-by-assumption (not passive)"``.
  :func:`critical_stiffness_eig` finds the same boundary from the eigenvalues of the
  exactly discretised device, as an independent check. Given the device's apparent
  mass (``mass_kg=``), :func:`critical_stiffness` and :func:`passivity_margin` return that
  eigenvalue (stability) limit analytically via :func:`mass_correction` (exact for d = 0,
  second order in ``b T / m`` for d >= 1); the passivity label never uses it.
* :class:`PassivityController` renders a unilateral wall in two parts, both fixed by
  what the device declares (docs/runtime.md, "Passivity", derives every constant):

  - a **Colgate spring**: the wall's force up to the stiffness ``K_c = 2 b_lo / T`` that
    the trusted device damping ``b_lo`` makes passive under the zero-order hold
    (Colgate & Schenkel), as a function of the depth below the surface. It is a spring,
    continuous in depth and zero at the surface: no relay, no threshold;
  - the **extra** above it (the rest of the wall's force), bounded by energy: the
    controller books ``U``, an upper bound of the energy the extra has given the user,
    from the readings and the held forces alone (ZOH pairing plus the encoder's
    quantisation terms, Ryu, Kim & Hannaford 2004; Kim & Ryu's energy bounding), and
    sends the largest extra, within one ramp step of the last, whose plan "hold, then
    ramp to 0" keeps ``U`` within ``E0 = min(F_max Delta / 2, energy_allowance_j)``.

  The output lies between 0 and the wall's force: a unilateral wall never pulls.

Sign conventions: ``x`` is the probe position along the surface normal (mm, y axis,
inside the material at x < 0); ``F`` is the force on the probe along +x (N, "pushing the
probe out" is positive). ``E`` is the energy absorbed by the virtual environment (J); a
negative ``E`` means the wall has produced energy.
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import ValidationError
from .linalg import expm
from .special import gammainc2

#: Label of a wall that is passive by the Colgate condition (margin > 0).
PASSIVE = "passive"
#: Label of a wall whose stability relies on the hand's impedance (margin <= 0).
STABLE_BY_ASSUMPTION = "stable-by-assumption (not passive)"


def _check_nonneg(name: str, value: float) -> float:
    from .checks import is_number
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
    dl = np.maximum(np.asarray(b, float), 0.0) * np.asarray(T, float) / m
    d = np.asarray(d, float)
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
    K = np.asarray(K, float) * 1000.0
    aB = np.abs(np.asarray(B, float))
    load = K * np.asarray(T, float) * (0.5 + np.asarray(d, float)) + aB
    b_eff = np.asarray(b, float)
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
    k = max(float(b) - abs(float(B)), 0.0) / (float(T) * (0.5 + float(d))) / 1000.0
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


#: Ramp time (s) of a full-scale force change: a change spread over at least 5 ms is
#: free of clicks (reference goal 11, the same bound as the vibration gate's ramp).
RAMP_TIME_S = 5.0e-3
#: Share of the declared device damping the controller credits: a declared damping is
#: taken as known within a factor of two (the stated uncertainty of a declaration, the
#: 0.5x-2x band the randomised benchmark draws), so the true damping is at least half of it.
DAMPING_TRUST = 0.5
#: Default of ``ControllerSettings.energy_allowance_j`` (J): the most energy the extra's
#: bound may hand the user over a contact, the SDK's passivity specification (0.1 mJ: a
#: 10 g fingertip at 0.14 m/s). It caps the encoder allowance ``F_max Delta / 2``, which
#: exceeds it only on encoders coarser than ``2 E / F_max`` (0.06 mm at 3.3 N).
ENERGY_ALLOWANCE_J = 1.0e-4


@dataclass
class ControllerSettings:
    """Declared device parameters of :class:`PassivityController` (nothing tuned).

    Attributes:
        device_damping_ns_per_m: declared physical viscous damping of the device (N*s/m).
            Only ``damping_trust`` times it is credited.
        damping_trust: share of the declared damping taken as a lower bound of the true
            damping (:data:`DAMPING_TRUST`, 1/2: a declaration is trusted to a factor 2).
        position_resolution_mm: encoder resolution Delta (mm); 0 = exact positions.
        max_force_n: force limit of the device (N), the full scale of the ramp. None:
            the largest of the wall's forces and the outputs so far is the full scale.
        ramp_time_s: time of a full-scale ramp (s, :data:`RAMP_TIME_S`); the output
            changes by at most ``s = max_force_n * T / ramp_time_s`` per tick (at most
            ``max_force_n``).
        device_mass_kg: declared apparent mass m of the device (kg): a force increase
            ``dF`` pushes it ``dF T^2 / 2m`` further within the tick, which the plan's cost
            counts. None: not counted. (The kinetic energy it stores is left out of the
            bound, which is conservative.)
        energy_bound: False removes the energy bound (the output then follows the wall
            through the ramp only): for tests that must see the bound matter.
        energy_allowance_j: the most energy (J) the extra's bound may hand the user
            (:data:`ENERGY_ALLOWANCE_J`): the allowance is ``min(F_max Delta / 2, this)``.
            A requirement, not a fitted constant: lower it for a stricter bound (with a
            coarse encoder the wall then rises at one reading only to ``2 E / Delta``).
    """

    device_damping_ns_per_m: float = 0.0
    damping_trust: float = DAMPING_TRUST
    position_resolution_mm: float = 0.0
    max_force_n: float | None = None
    ramp_time_s: float = RAMP_TIME_S
    device_mass_kg: float | None = None
    energy_bound: bool = True
    energy_allowance_j: float = ENERGY_ALLOWANCE_J

    def __post_init__(self) -> None:
        for name in ("device_damping_ns_per_m", "position_resolution_mm"):
            _check_nonneg(name, getattr(self, name))
        if not (0.0 <= float(self.damping_trust) <= 1.0):
            raise ValidationError(f"must be in [0, 1], got {self.damping_trust!r}", field="damping_trust")
        if self.max_force_n is not None and not (math.isfinite(self.max_force_n) and self.max_force_n > 0):
            raise ValidationError(f"must be a finite number > 0 (N), got {self.max_force_n!r}", field="max_force_n")
        if not (math.isfinite(self.ramp_time_s) and self.ramp_time_s > 0):
            raise ValidationError(f"must be a finite number > 0 (s), got {self.ramp_time_s!r}", field="ramp_time_s")
        if not (math.isfinite(self.energy_allowance_j) and self.energy_allowance_j >= 0):
            raise ValidationError(f"must be a finite number >= 0 (J), got {self.energy_allowance_j!r}",
                                  field="energy_allowance_j")

    @classmethod
    def for_device(cls, device: Any) -> "ControllerSettings":
        """Settings from what a device declares: ``apparent_mass_kg``, ``damping_ns_per_m``,
        ``encoder_resolution_mm`` and ``limits.max_force_n`` (each optional)."""
        def num(v: Any) -> float | None:
            try:
                f = float(v)
            except (TypeError, ValueError):
                return None
            return f if math.isfinite(f) and f > 0 else None
        lim = getattr(device, "limits", None)
        return cls(device_mass_kg=num(getattr(device, "apparent_mass_kg", None)),
                   device_damping_ns_per_m=num(getattr(device, "damping_ns_per_m", None)) or 0.0,
                   position_resolution_mm=num(getattr(device, "encoder_resolution_mm", None)) or 0.0,
                   max_force_n=num(getattr(lim, "max_force_n", None)))

    def ramp_step_n(self, dt: float, full_scale_n: float | None = None) -> float:
        """The ramp's own step (N per tick) at period ``dt``: ``F_max dt / ramp_time_s``,
        at most ``F_max`` (``full_scale_n`` when the device declares no limit)."""
        fs = self.max_force_n if self.max_force_n is not None else (full_scale_n or 0.0)
        return fs * min(dt / self.ramp_time_s, 1.0)

    def energy_budget_j(self, dt: float, full_scale_n: float | None = None) -> float:
        """``E0 = min(F_max Delta / 2, energy_allowance_j)`` (J): what bringing the full
        force up at one reading costs in the bound (a monotone ramp's quantisation term is
        ``Delta/2`` times its height), so a wall pressed from rest is not withheld for want
        of an allowance, capped by the energy a contact may hand the user
        (docs/runtime.md, Passivity item 6)."""
        fs = self.max_force_n if self.max_force_n is not None else (full_scale_n or 0.0)
        return min(fs * 0.5 * self.position_resolution_mm * 1e-3, self.energy_allowance_j)


#: Settings of the 0.1 controller (stiffness cap, observers, dither damper, felt floor,
#: pre-paid budget, entry boost), removed in 0.2: still accepted by
#: :class:`ControllerSettings`, with a ``DeprecationWarning``, and ignored.
DEPRECATED_SETTINGS = frozenset({
    "max_damping_ns_per_m", "velocity_deadband_mm_s", "velocity_filter_hz", "energy_tolerance_j",
    "bound_tolerance_j", "max_force_step_n", "ramp_reserve_j", "generation_observer", "generation_budget_j",
    "generation_floor_j", "dither_damping_ns_per_m", "count_play_ratio", "stiffness_cap", "cap_colgate_multiple",
    "cap_damping_share", "cap_count_force_n", "felt_floor_fraction", "felt_force_n", "felt_depth_mm",
    "felt_tick_energy_j", "felt_damping_multiple", "prepay_factor", "prepay_budget_j", "entry_force_limit_n",
    "entry_force_step_n", "felt_uses_reserve"})

_settings_init = ControllerSettings.__init__


@functools.wraps(_settings_init)
def _settings_init_accepting_old_names(self: ControllerSettings, *args: Any, **kw: Any) -> None:
    old = sorted(k for k in kw if k in DEPRECATED_SETTINGS)
    if old:
        warnings.warn(f"ControllerSettings: {', '.join(old)} no longer exist (the 0.1 controller's tuned "
                      "settings; the controller is derived from the device's declared parameters, "
                      "docs/runtime.md 'Passivity'); they are ignored and will be refused in 0.3",
                      DeprecationWarning, stacklevel=2)
        for k in old:
            del kw[k]
    _settings_init(self, *args, **kw)


ControllerSettings.__init__ = _settings_init_accepting_old_names  # type: ignore[method-assign]


def cap_stiffness_n_per_mm(settings: ControllerSettings, dt: float, damping_ns_per_m: float | None = None,
                           resolution_mm: float | None = None) -> float:
    """Deprecated (0.2; removed in 0.3): the stiffness cap is gone. Returns the stiffness
    of the controller's Colgate spring instead, ``K_c = 2 b_lo / dt`` in N/mm (``b_lo`` the
    trusted share of the declared damping); ``resolution_mm`` is ignored."""
    warnings.warn("cap_stiffness_n_per_mm is deprecated: the controller has no stiffness cap; use "
                  "colgate_stiffness_n_per_mm (the stiffness of its passive spring)", DeprecationWarning, stacklevel=2)
    return colgate_stiffness_n_per_mm(settings, dt, damping_ns_per_m)


def colgate_stiffness_n_per_mm(settings: ControllerSettings, dt: float, damping_ns_per_m: float | None = None
                               ) -> float:
    """Stiffness (N/mm) of :class:`PassivityController`'s Colgate spring at period ``dt``
    (s): ``K_c = 2 b_lo / dt`` with ``b_lo = damping_trust x`` the declared damping
    (``damping_ns_per_m`` overrides the settings' declaration); 0 for ``dt <= 0``."""
    b = settings.device_damping_ns_per_m if damping_ns_per_m is None else float(damping_ns_per_m)
    if not dt > 0 or not b > 0:
        return 0.0
    return 2.0 * settings.damping_trust * b / dt / 1000.0


#: Spans (ticks) over which the change of motion is read: the second difference
#: ``x_k - 2 x_(k-m) + x_(k-2m) = a (m T)^2`` under a constant acceleration a, and the
#: encoder adds at most 2 counts to it, whatever m; so a longer span sees an acceleration
#: m^2 times smaller above the same quantisation (powers of two up to 16 ticks).
_SCALES = (1, 2, 4, 8, 16)   # (the scalar tick unrolls these five)
#: Length of the reading ring (2 x the longest span + 1).
_HIST = 2 * _SCALES[-1] + 1


#: Bisection steps of :func:`affordable_force` (2^-30 of the ramp step: far below any
#: force a device resolves).
_BISECT = 30


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


def affordable_force(avail_j: Any, lo: Any, hi: Any, p: Any, lead_m: Any, push_m_per_n: Any, s: Any,
                     half_count_m: Any) -> Any:
    """Largest ``a`` in ``[lo, hi]`` with :func:`plan_cost_j` ``<= avail_j`` (vectorised).

    The cost is convex in ``a``: ``hi`` when it fits; otherwise the cost's minimiser on
    ``[lo, hi]`` (bisection on the slope) and, when that fits, bisection for the crossing
    between it and ``hi``; when nothing fits, the minimiser (the ramp allows no deeper
    cut, and it is the plan that overdraws least)."""
    A, lo, hi, p, d, c_m, s, c = np.broadcast_arrays(*(np.asarray(v, float) for v in (
        avail_j, lo, hi, p, lead_m, push_m_per_n, s, half_count_m)))
    def cost(a: np.ndarray) -> np.ndarray:
        return plan_cost_j(a, p, d, c_m, s, c)
    ok_hi = cost(hi) <= A
    if ok_hi.all():
        return hi.copy() if hi.ndim else float(hi)
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
    out = np.where(ok_hi, hi, np.where(fits, a, lo))
    return out if out.ndim else float(out)


def _affordable_scalar(A: float, lo: float, hi: float, p: float, d: float, c_m: float, s: float,
                       c: float) -> float:
    """:func:`affordable_force` for one cell, in floats (the servo tick)."""
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


class PassivityController:
    """Passive wall from the device's declared parameters: a Colgate spring plus an
    energy-bounded extra.

    Per tick call :meth:`step` with the measured position (mm, along the normal, the
    surface at 0, inside at x < 0), the measured period ``dt`` (s) and the wall's force
    (N); send the returned force; then call :meth:`commit` with the force the device
    actually applied (after its safety clamp).

    **The Colgate spring** ``P = min(F_wall, K_c depth)``, ``K_c = 2 b_lo / dt``,
    ``b_lo = damping_trust x declared damping``: a spring no stiffer than the trusted
    damping makes passive under the zero-order hold (Colgate & Schenkel's ``b > K T / 2``).
    It follows the reading at once (a spring, not a ramp: a ramp on a spring lags it,
    and a lagging spring gives energy), so the force changes by at most
    ``K_c |dq|`` plus the extra's ramp step per tick.

    **The extra** ``X = F - P`` carries the rest of the wall. The controller keeps ``U``,
    an *upper bound* of the energy the extra has given the user, from the readings ``q``
    and the held extras alone:

        ``U += X_{k-1} dq_k + (Delta/2) |X_{k-1} - X_{k-2}| - b_x max(|dq_k| - Delta, 0)^2 / dt``

    (ZOH pairing: the extra held over an interval times that interval's reading change;
    summation by parts bounds its true work by this plus ``Delta/2`` per unit of change,
    plus ``Delta/2 |X|`` at the end; ``b_x = b_lo - K_f dt / 2`` is the damping the spring
    of secant stiffness ``K_f`` leaves, which dissipates at least ``b_x dy^2 / dt`` per
    interval with ``|dy| >= |dq| - Delta``). It sends the largest extra, between 0 and
    ``F_wall - P``, within one ramp step ``s`` of the last, whose plan "hold it one tick,
    then ramp to 0 at ``s`` per tick" keeps ``U`` below ``E0 = min(F_max Delta / 2,
    energy_allowance_j)`` if the reading keeps moving at the rate of the last two ticks,
    changing by up to the largest change of motion seen over the last ``_HIST`` ticks
    (:func:`affordable_force`).
    If the motion outruns that prediction the extra ramps down at ``s`` and the excess
    is booked (``overdrawn_j``).

    **Release.** The spring follows the reading out; the extra ramps to 0 at ``s`` per
    tick, charged to the same bound, and once the bound is spent only the spring is
    left (the force never drops below it while the stylus is inside). With no wall force
    and no output, credit is dropped (``U <- max(U, 0)``); a debt is kept.
    """

    __slots__ = ("settings", "energy_j", "active_ticks", "withheld_n_ticks", "overdrawn_j", "_q1", "_q2", "_hist", "_hp",
                 "_f1", "_f2", "_out", "_started", "_still", "_spring", "_kf", "_full", "_jh", "_jmax", "_jat")

    def __init__(self, settings: ControllerSettings | None = None, **kw: Any) -> None:
        self.settings = settings or ControllerSettings(**kw)
        self.reset()

    def reset(self) -> None:
        """Forget the energy observed so far (a new run or a new object)."""
        self.energy_j = 0.0         # U: upper bound of the energy given to the user (J)
        self.active_ticks = 0       # ticks where the output was below the wall's force
        self.withheld_n_ticks = 0.0 # sum over ticks of the force withheld (N)
        self.overdrawn_j = 0.0      # largest U - E0 seen (J): motion beyond the prediction
        self._q1 = self._q2 = 0.0
        self._hist = [0.0] * _HIST    # the last readings (mm), a ring; _hp the newest
        self._hp = 0
        self._jh = [0.0] * _HIST      # the change-of-motion estimates of the same ticks
        self._jmax = 0.0              # their largest, at ring index _jat
        self._jat = 0
        self._f1 = self._f2 = 0.0   # the extra (applied force minus the spring) over the last two ticks
        self._out = 0.0
        self._started = False
        self._still = 0             # ticks since the reading last changed
        self._spring = 0.0          # the Colgate spring sent this tick (N)
        self._kf = 0.0              # its secant stiffness (N/m)
        self._full = 0.0            # full scale without a declared force limit: the largest force so far

    def step(self, x_mm: float, dt: float, f_wall: float) -> float:
        """Book the last interval, then return the force (N) to command this tick."""
        s = self.settings
        if f_wall != f_wall or f_wall in (math.inf, -math.inf):
            f_wall = 0.0
        if not self._started or not dt > 0:
            if not self._started:
                self._q1 = self._q2 = x_mm
                self._hist = [x_mm] * _HIST
                self._started = True
            return 0.0 if not dt > 0 else self._out
        dq = (x_mm - self._q1) * 1e-3
        q = s.position_resolution_mm * 1e-3
        h = 0.5 * q
        f1 = self._f1
        b_lo = s.damping_trust * s.device_damping_ns_per_m
        # the extra above the spring: ZOH-paired work plus half a count of reading error
        # per newton of change (summation by parts); the damping the Colgate spring does
        # not need (b_lo - K_f T / 2) is credited
        u = self.energy_j + f1 * dq + h * abs(f1 - self._f2)
        ex = abs(dq) - q
        if ex > 0.0:
            b_x = b_lo - 0.5 * self._kf * dt
            if b_x > 0.0:
                u -= b_x * ex * ex / dt
        ahead = 0.5 * (x_mm - self._q2) * 1e-3
        # the change of the per-tick motion beyond what quantisation alone makes (2 counts)
        # the change of the per-tick motion, read over spans of 1-16 ticks (_SCALES)
        hist = self._hist
        hp = self._hp + 1
        if hp == _HIST:
            hp = 0
        self._hp = hp
        hist[hp] = x_mm
        c2 = 2.0 * s.position_resolution_mm
        jerk = abs(x_mm - 2.0 * hist[hp - 1] + hist[hp - 2]) - c2
        d = (abs(x_mm - 2.0 * hist[hp - 2] + hist[hp - 4]) - c2) * 0.25
        if d > jerk:
            jerk = d
        d = (abs(x_mm - 2.0 * hist[hp - 4] + hist[hp - 8]) - c2) * 0.0625
        if d > jerk:
            jerk = d
        d = (abs(x_mm - 2.0 * hist[hp - 8] + hist[hp - 16]) - c2) * 0.015625
        if d > jerk:
            jerk = d
        d = (abs(x_mm - 2.0 * hist[hp - 16] + hist[hp - 32]) - c2) * 0.00390625
        if d > jerk:
            jerk = d
        jerk = jerk * 1e-3 if jerk > 0.0 else 0.0
        # the largest change of motion over the ring's window (_HIST ticks): a hand that
        # reversed within it can reverse again; the estimate of this tick alone is blind
        # between reversals (taps, the finger-and-arm resonance at long periods)
        jh = self._jh
        jh[hp] = jerk
        if jerk >= self._jmax:
            self._jmax = jerk
            self._jat = hp
        elif self._jat == hp:   # the largest left the window: find the next one
            self._jmax = max(jh)
            self._jat = jh.index(self._jmax)
        jerk = self._jmax
        self._still = self._still + 1 if dq == 0.0 else 0
        self._q2 = self._q1
        self._q1 = x_mm
        # the Colgate spring: the wall up to the stiffness the trusted damping makes
        # passive (K_c = 2 b_lo / T), as a function of the depth below the surface x = 0
        depth = -x_mm * 1e-3
        spring = 0.0
        kf = 0.0
        if f_wall > 0.0 and depth > 0.0 and b_lo > 0.0:
            spring = 2.0 * b_lo / dt * depth
            if spring > f_wall:
                spring = f_wall
        fm = s.max_force_n
        if fm is not None and spring > fm:
            spring = fm
        if spring > 0.0:
            kf = spring / depth
        self._spring = spring
        self._kf = kf
        if fm is None:
            # no declared limit: the largest force seen so far is the full scale (a fixed
            # step, so a ramp to 0 ends; a scale that followed the output would shrink
            # with it and never reach 0)
            full = max(self._full, abs(f_wall), abs(self._out))
            self._full = full
        else:
            full = fm
        step = full * (dt / s.ramp_time_s if dt < s.ramp_time_s else 1.0)
        m = s.device_mass_kg
        c_m = dt * dt / (2.0 * m) if m else 0.0
        e0 = full * h
        if e0 > s.energy_allowance_j:
            e0 = s.energy_allowance_j
        if f_wall == 0.0 and self._out == 0.0 and f1 == 0.0:
            self.energy_j = u if u > 0.0 else 0.0
            return 0.0
        self.energy_j = u
        if u - e0 > self.overdrawn_j:
            self.overdrawn_j = u - e0
        # work in the direction of the wall's force (the last output's when the wall is 0)
        sg = 1.0 if (f_wall > 0.0 or (f_wall == 0.0 and self._out >= 0.0)) else -1.0
        target = sg * f_wall
        if fm is not None and target > fm:
            target = fm
        target -= spring
        p = sg * f1
        # the extra's ramp: within one step of the last one, and not past 0 while it can reach it
        lo = p - step
        if lo < 0.0:
            lo = 0.0 if p + step >= 0.0 else p + step
        hi = p + step
        if hi > target:
            hi = target if target > lo else lo
        a = hi
        if s.energy_bound and hi > lo:
            # the arm's speed now: the last two ticks' mean, its reading error (half a
            # count; Delta/n after n > 2 ticks at one reading), and what the held force
            # added since the middle of those ticks
            lead = sg * ahead + (1.5 + 0.5 * hi / step) * jerk + q / (self._still if self._still > 2 else 2)
            a = _affordable_scalar(e0 - u, lo, hi, p, lead, c_m, step, h)
        if a < target:
            self.active_ticks += 1
            self.withheld_n_ticks += target - a
        out = spring + sg * a
        self._out = out
        return out

    def commit(self, f_applied: float) -> None:
        """Record the force the device actually held over the coming interval (N)."""
        if f_applied != f_applied or f_applied in (math.inf, -math.inf):
            f_applied = 0.0
        self._f2 = self._f1
        self._f1 = f_applied - self._spring   # the extra actually held (the ramp starts from it)
        self._out = f_applied

    def report(self) -> dict[str, float]:
        """``energy_bound_j`` (U, J: upper bound of the energy given to the user over the
        current contact; the credit is dropped between contacts), ``overdrawn_j`` (largest
        ``U - E0``, J: > 0 only when the motion outran the one-tick prediction),
        ``withheld_n_ticks`` (N), ``active_ticks``."""
        return {"energy_bound_j": self.energy_j, "overdrawn_j": self.overdrawn_j,
                "withheld_n_ticks": self.withheld_n_ticks, "active_ticks": self.active_ticks}


def controller_state_batch(n: int) -> dict[str, np.ndarray]:
    """Fresh state arrays for :func:`controller_step_batch` over ``n`` cells."""
    z = np.zeros(n)
    return {"energy": z.copy(), "q1": z.copy(), "q2": z.copy(), "f1": z.copy(), "f2": z.copy(),
            "out": z.copy(), "started": np.zeros(n, bool), "overdrawn": z.copy(), "still": z.copy(),
            "spring": z.copy(), "kf": z.copy(), "full": z.copy(), "hist": np.zeros((_HIST, n)),
            "jh": np.zeros((_HIST, n)),
            "hp": np.zeros(1, int)}


def controller_step_batch(state: dict[str, np.ndarray], x_mm: np.ndarray, dt: "float | np.ndarray",
                          f_wall: np.ndarray, on: "np.ndarray | bool" = True,
                          settings: ControllerSettings | None = None,
                          damping_ns_per_m: "np.ndarray | float | None" = None,
                          resolution_mm: "np.ndarray | float | None" = None,
                          max_force_n: "np.ndarray | float | None" = None,
                          mass_kg: "np.ndarray | float | None" = None) -> np.ndarray:
    """Vectorised :class:`PassivityController` over many independent cells (same law).
    ``dt``, ``damping_ns_per_m`` (declared), ``resolution_mm`` and ``max_force_n`` may be
    per cell and override ``settings``. Cells where ``on`` is False pass the wall force
    through. Call :func:`controller_commit_batch` after."""
    s = settings or ControllerSettings()
    x = np.asarray(x_mm, float)
    fw = np.nan_to_num(np.asarray(f_wall, float), nan=0.0, posinf=0.0, neginf=0.0)
    dt = np.broadcast_to(np.asarray(dt, float), x.shape)
    bd = np.asarray(s.device_damping_ns_per_m if damping_ns_per_m is None else damping_ns_per_m, float)
    q = np.asarray(s.position_resolution_mm if resolution_mm is None else resolution_mm, float) * 1e-3
    fm = s.max_force_n if max_force_n is None else max_force_n
    started = state["started"]
    q1 = np.where(started, state["q1"], x)
    q2 = np.where(started, state["q2"], x)
    dq = (x - q1) * 1e-3
    f1 = state["f1"]
    b_lo = s.damping_trust * bd
    u = state["energy"] + f1 * dq + 0.5 * q * np.abs(f1 - state["f2"])
    ex = np.maximum(np.abs(dq) - q, 0.0)
    b_x = np.maximum(b_lo - 0.5 * state["kf"] * dt, 0.0)
    u = u - b_x * ex * ex / dt
    ahead = 0.5 * (x - q2) * 1e-3
    hist = state["hist"]
    hist[:, ~started] = x[~started]
    hp = state["hp"][0] = (state["hp"][0] + 1) % _HIST
    hist[hp] = x
    jerk = np.zeros(x.shape)
    for span in _SCALES:
        d2 = np.abs(x - 2.0 * hist[hp - span] + hist[hp - 2 * span]) * 1e-3 - 2.0 * q
        np.maximum(jerk, d2 / (span * span), out=jerk)
    jh = state["jh"]
    jh[hp] = jerk
    jerk = jh.max(axis=0)
    still = np.where(dq == 0.0, state["still"] + 1.0, 0.0)
    state["still"] = still
    state["q2"] = q1
    state["q1"] = x.copy()
    out_prev = state["out"]
    if fm is None:
        full = np.maximum(state["full"], np.maximum(np.abs(fw), np.abs(out_prev)))
        state["full"] = full
    else:
        full = np.broadcast_to(np.asarray(fm, float), x.shape)
    depth = np.maximum(-x * 1e-3, 0.0)
    spring = np.where((fw > 0.0) & (depth > 0.0), np.minimum(2.0 * b_lo / dt * depth, fw), 0.0)
    if fm is not None:
        spring = np.minimum(spring, full)
    step = full * np.minimum(dt / s.ramp_time_s, 1.0)
    m = s.device_mass_kg if mass_kg is None else mass_kg
    c_m = 0.0 if m is None else dt * dt / (2.0 * np.asarray(m, float))
    e0 = np.minimum(full * 0.5 * q, s.energy_allowance_j)
    idle = (fw == 0.0) & (out_prev == 0.0) & (f1 == 0.0)
    u = np.where(idle, np.maximum(u, 0.0), u)
    state["energy"] = np.where(started, u, 0.0)
    state["overdrawn"] = np.maximum(state["overdrawn"], np.where(started & ~idle, u - e0, 0.0))
    sg = np.where((fw > 0.0) | ((fw == 0.0) & (out_prev >= 0.0)), 1.0, -1.0)
    target = sg * fw
    if fm is not None:
        target = np.minimum(target, full)
    target = target - spring
    p = sg * f1
    lo = np.where(p - step >= 0.0, p - step, np.minimum(p + step, 0.0))
    hi = np.maximum(np.minimum(p + step, target), lo)
    a = hi
    if s.energy_bound:
        lead = sg * ahead + (1.5 + 0.5 * hi / np.where(step > 0, step, 1.0)) * jerk + q / np.maximum(still, 2.0)
        a = affordable_force(e0 - u, lo, hi, p, lead, c_m, step, 0.5 * q)
    spring = np.where(started & ~idle, spring, 0.0)
    state["spring"] = spring
    state["kf"] = np.where(spring > 0.0, spring / np.where(depth > 0.0, depth, 1.0), 0.0)
    out = np.where(started & ~idle, spring + sg * a, 0.0)
    state["out"] = out
    state["started"] = np.ones_like(started)
    return np.where(on, out, fw)


def controller_commit_batch(state: dict[str, np.ndarray], f_applied: np.ndarray) -> None:
    """Record the forces actually applied over the coming interval (N)."""
    f = np.nan_to_num(np.asarray(f_applied, float), nan=0.0, posinf=0.0, neginf=0.0)
    state["f2"] = state["f1"]
    state["f1"] = f - state["spring"]   # the extra actually held (its ramp starts from it)
    state["out"] = f.copy()


def zoh_observer_energy(x_mm: np.ndarray, f_applied: np.ndarray) -> np.ndarray:
    """Running ZOH-paired observer energy (J) of a recorded run: ``E_n = -sum F_{k-1} dx_k``."""
    dx = np.diff(np.asarray(x_mm, float)) * 1e-3
    return np.concatenate([[0.0], np.cumsum(-np.asarray(f_applied, float)[:-1] * dx)])


def naive_observer_energy(x_mm: np.ndarray, f_applied: np.ndarray, dt: float) -> np.ndarray:
    """Running textbook observer energy (J): ``E_n = -sum f_k v_k dt`` with the *current*
    force and the backward-difference velocity (blind to the energy of the hold)."""
    v = np.diff(np.asarray(x_mm, float)) * 1e-3 / dt
    return np.concatenate([[0.0], np.cumsum(-np.asarray(f_applied, float)[1:] * v * dt)])
