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
* :class:`PassivityController` is a time-domain passivity observer (PO) with a
  variable damper (PC), after Hannaford & Ryu (IEEE TRA 18(1), 2002), with the energy
  paired to the zero-order hold: the force actually *held* over an interval is
  multiplied by that interval's displacement, ``E += -F(n-1) * (x(n) - x(n-1))``. The
  naive pairing ``f(n) v(n)`` never sees the energy the hold generates (see
  :func:`naive_observer_energy` and the tests). On top of the bounded damper the
  controller bounds the force it lets the wall push outward with by the energy the
  observer holds (energy bounding), so a wall far stiffer than the device can hold
  (a saturated relay on a quantised encoder) cannot feed energy to the user either.
  The cut is spread over ticks: the output moves at most ``max_force_step_n`` (0.8 N)
  per tick while the controller acts, and the bound caps the force so that the whole
  ramp-down at that rate fits in the energy budget (predicted work
  ``S (v+ T + Delta) + S^2 T^2 / 2m`` for the sum S of the ramp's forces, Delta one
  encoder count), in the spirit of energy bounding / reference energy following
  (Kim & Ryu; Ryu, Preusche, Hannaford & Hirzinger 2005) rather than a one-tick dump.
  A second observer ``G`` books, every tick, what the hold generates *relative to the
  wall's own continuous law* (held-force work minus the trapezoid of the wall's force,
  plus the credited device damping) and drives a damper on the raw velocity the moment
  it goes negative: the Colgate deficit ``K T / 2 - b`` is paid as it arises instead of
  after the wall's stored energy is spent, which is what keeps walls up to 4 x 2b/T
  passive, settled and at their full spring law (goal 4 of the reference).
  Before all of these, a **stiffness cap** limits the wall's outward force to
  ``K_c x penetration`` (:func:`cap_stiffness_n_per_mm`): a wall stiffer than the device
  can render passively is rendered as the stiffest spring it can (a conservative spring,
  after the idea of a virtual coupling), with the observers as the backstop, instead of
  a relay the observers withhold.
  After all of these, a **felt floor** keeps the output, deeper than 1 mm, at no less than
  ``min(0.6 N, 0.95 x the wall's own force)`` whenever the floor's work over one tick is
  affordable, and a **pre-paid budget** makes the damper pay, while the probe moves into
  the wall (extra resistance, not less force), for the withdrawal where the floor limits
  it; where the floor's one-tick work is not affordable by itself (long periods, no
  device damping, fast taps) an **entry boost** lets that damper exceed its bound and the
  slew limit while the probe moves in, up to the device's saturation, until the reserve
  covers the floor's cost of the withdrawal, and the floor's gate counts the reserve
  (see :class:`ControllerSettings`).

Sign conventions: ``x`` is the probe position along the surface normal (mm, y axis,
inside the material at x < 0); ``F`` is the force on the probe along +x (N, "pushing the
probe out" is positive). ``E`` is the energy absorbed by the virtual environment (J); a
negative ``E`` means the wall has produced energy.
"""

from __future__ import annotations

import math
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


@dataclass
class ControllerSettings:
    """Parameters of :class:`PassivityController`.

    Attributes:
        max_damping_ns_per_m: bound on the variable damper alpha (N*s/m); 5 N*s/m is the
            largest linear damping CHAI3D declares for the PHANTOM Omni. Bounding alpha
            removes the force spikes of the unbounded controller.
        velocity_deadband_mm_s: below this |v| the damper is not used (mm/s).
        velocity_filter_hz: first-order low-pass of the backward-difference velocity
            used to *predict* the next interval's motion (Hz); the observer itself
            always uses the exact displacement.
        energy_tolerance_j: energy deficit the damper tolerates before it acts (J).
        bound_tolerance_j: energy deficit at which the energy bound starts capping the
            outward force (J). With a quantised encoder the cap's predicted work includes
            one count (``F Delta``), which an empty budget never covers: with 0 a wall
            met from outside would never be rendered at all. 50 uJ lets the (capped) wall
            start and absorb energy; the observed energy's count-level drift is removed
            by the half-count play (``count_play_ratio``), and the gentle dampers act at
            once. (Before the stiffness cap it was 1 mJ, which the stability matrix then
            showed handing up to 0.86 mJ to the finger.)
        energy_bound: also bound the outward force by the observed energy (on by default).
        device_mass_kg: apparent mass of the device (kg) used to bound how far the held
            force itself can push the stylus within one period (``F T^2 / 2m``). Without
            it (None) a force that catapults a light stylus out of a very stiff wall
            within a single long period is only seen afterwards.
        device_damping_ns_per_m: physical viscous damping b of the device (N*s/m), if
            known (identified). The observer then credits ``b dx^2 / dt`` per period, a
            lower bound of what that damping dissipates (``int v^2 >= dx^2/dt``), so the
            controller keeps the *device + wall* passive (the Colgate view, W_d >= 0)
            instead of the wall alone; 0 (default) is the conservative wall-only view.
        position_resolution_mm: encoder resolution (mm). The damping credit uses
            ``max(|dx| - resolution, 0)``, a lower bound of the true displacement, so
            a reading dithering between two counts earns no credit.
        max_force_step_n: slew limit (N per tick) of the output while the controller acts
            and until the output has caught up with the wall again (goal 4's spike
            criterion is 1 N; an Omni trips ``HD_EXCEEDED_MAX_FORCE_IMPULSE`` on large
            steps). The energy bound is then *predictive*: the outward force is capped
            so that the whole ramp-down ``F, F - step, ...`` at this rate, not just one
            tick, fits in the energy budget (``_ramp_force``), so the cut is spread over
            several ticks instead of dumped in one. None: the old one-tick cap (cuts at
            once, |dF| up to 3.3 N at K = 3-4 x 2b/T).
        ramp_reserve_j: extra energy (J) the ramp may use beyond the bound tolerance when
            the prediction was wrong (the reading jumped a count, the hand pushed);
            only past ``bound_tolerance_j + ramp_reserve_j`` does the force drop faster
            than ``max_force_step_n`` (passivity before smoothness).
        generation_observer: run the second observer (on by default): the energy the
            *hold* generates relative to the wall's own continuous-time law, booked
            every tick as the work of the held force minus the trapezoid of the wall's
            requested force over the same displacement, plus the credited device
            damping: ``G += -F_held(n-1) dx + (F_wall(n-1) + F_wall(n)) dx / 2 +
            b max(|dx| - Delta, 0)^2 / dt`` (a one-count change of the reading is credited
            whole, ``b dx^2 / dt``, when the wall's step across it is within Colgate's
            bound ``|dF| <= 2 b |dx| / dt``: a wall below 2b/T is then left alone). For a
            spring the trapezoid is its exact
            storage change, so ``G`` sees the hold's ``K dx^2 / 2`` per tick at once,
            not after the wall's stored energy is spent (which is when the first
            observer ``E`` goes negative). When ``G < 0`` a damper on the *raw*
            backward-difference velocity, ``alpha = -G / (v^2 dt)`` bounded by
            ``max_damping_ns_per_m``, removes the deficit at the next tick: the
            Colgate deficit ``K T / 2 - b`` is paid as it arises, the static force is
            untouched (no motion, no booking), so a wall up to about 4 x 2b/T settles
            on the full spring law instead of growing into a limit cycle.
        generation_budget_j: upper bound of ``G`` (J). Dissipation booked during fast
            motion is not saved up to let a later oscillation grow: ``G`` is capped
            here (a cap can only make the controller act sooner, never later).
        generation_floor_j: lower bound of ``G`` (J): the debt the damper works off is at
            most this (1 mJ; at long periods one tick's deficit is tens of microjoules and
            must be paid in full). Passivity itself is the energy observer's job (``E``).
        dither_damping_ns_per_m: at a tick whose reading moved by at most one count the
            floor is ``min(generation_floor_j, dither_damping * Delta^2 / dt)``, so the
            damper's pulse at a one-count change of the reading (velocity ``Delta / dt``)
            is at most this damping (N*s/m; 3 N*s/m: 0.17 N at 0.055 mm and 1 kHz).
            These pulses are what damps the count-level limit cycle a quantised stiff
            wall has without Coulomb friction (Abbott & Okamura); larger values buzz
            more (the fidelity bench's force error), smaller ones (1.7 N*s/m at 0.5 ms)
            let a 3 x 2b/T wall give energy back.
        count_play_ratio: the energy observer books a quantised reading through half a
            count of play, so a dither between two counts books nothing, only while the
            wall's force step across one count stays within this fraction of what the
            device damping plus the damper absorb over one count,
            ``|dF| <= ratio (b + max_damping) Delta / dt`` (N); a steeper (relay-like)
            wall and a device of unknown damping (b = 0) are booked count by count in
            full. Without the play the observer's count-level drift (about -K Delta^2 per
            dither cycle) withheld a 1.5 x 2b/T wall after about 4 s of holding.
        stiffness_cap: render a wall stiffer than :func:`cap_stiffness_n_per_mm` as that
            spring (on by default): the wall's outward force is limited to ``K_c x
            penetration`` (penetration = ``-x``; the surface is at x = 0) before the
            observers see it. A wall the device cannot render passively is then rendered
            as the stiffest spring it can, a conservative (path-independent) spring and
            not a relay that the observers withhold. A wall softer than ``K_c`` is untouched.
        cap_colgate_multiple: ``K_c`` is at least this multiple of Colgate's ``2 b / T``
            (4: the range goal 4 of the reference asks the generation observer to keep
            passive, settled and at its full spring law).
        cap_damping_share: ... and at least ``2 (b + share * max_damping_ns_per_m) / T``:
            the device damping plus this share of the damper's bound taken as margin
            (0.25: 1.25 N*s/m; this is what lets a device with b = 0 render a wall at
            all, 2.5 N/mm at 1 kHz, with the observers paying the hold's deficit).
        cap_count_force_n: with a quantised encoder, ``K_c`` is at most this force per
            count divided by the resolution (N; 0.4 N: 7.3 N/mm at 0.055 mm). Above it
            the count-level limit cycle of a quantised wall (Abbott & Okamura: ``K Delta
            <= 2 f_c``; no Coulomb friction is known or simulated) feeds the finger more
            than the observers can catch. None: no such limit.
        bound_tolerance_j: (see above) 50 uJ: with the stiffness cap the first count of
            a wall met from outside is worth at most ``cap_count_force_n`` x Delta, so a
            small tolerance no longer keeps the wall from starting.
        felt_floor_fraction: **felt floor** (on by default; None: off). Deeper than
            ``felt_depth_mm`` (reading), no correction (damper, energy bound, slew limit)
            takes the output below ``min(felt_force_n, felt_floor_fraction x F_wall)``,
            ``F_wall`` the wall's own force before the stiffness cap: a person pressing
            into a wall always feels it. Without it the dampers that keep a device with
            little or no damping (b = 0) passive take the force off during withdrawal,
            down to a pull on the stylus. Above the floor, and shallower than
            ``felt_depth_mm``, the dampers act as before, so hold oscillations and the
            count-level dither are still damped. A flat floor stores nothing and its
            hold generates nothing except at its edge (about ``F v T`` per crossing).
            0.95: the floor stays within 5 % of a soft wall's law.
        felt_force_n: the floor's cap (N; 0.6 N, above the 0.5 N a person must feel on
            a wall with some margin). None: only the fraction.
        felt_depth_mm: penetration (mm, of the reading) from which the floor holds (1 mm).
        felt_tick_energy_j: the floor holds on a tick only while its work over one tick
            of the current motion, ``F_floor (|dx| + Delta)`` (J), is at most this plus
            ``felt_damping_multiple x b dx^2 / dt`` (the device damping's dissipation over
            that tick, at the cap's Colgate multiple), plus the pre-paid reserve when
            ``felt_uses_reserve``. Passivity comes first: at long periods on a device
            without damping a fast tap moves 1-1.5 mm per tick (4 ms), a 0.6 N floor would
            hand the finger 0.6-0.9 mJ in the tick it leaves; unless the entry boost has
            pre-paid that (``entry_force_limit_n``), the floor yields (0.4 mJ).
        felt_damping_multiple: see ``felt_tick_energy_j`` (4).
        prepay_factor: **pre-paid energy budget** for the withdrawal. While the probe
            moves into the wall (reading moving in, wall force > 0) the generation
            observer books ``(1 + prepay_factor)`` x the hold's excess, so its damper
            (which *adds* outward force while the probe moves in: resistance, not a
            loss of felt force) also pays ``prepay_factor`` x that excess in advance;
            the advance is kept as a reserve (``prepaid_reserve_j`` in :meth:`report`)
            and any debt booked while the probe is not moving in is paid from it first,
            so the withdrawal, where the felt floor limits the damper, draws on energy
            already dissipated. The reserve is dropped when contact ends. 0: off; 1
            would pay for a withdrawal as fast as the entry; 0.5, because the damper
            still acts on the withdrawal above the floor and shallower than
            ``felt_depth_mm`` (in the stability matrix 0.5 meets the floor and the
            energy goal in every cell 1 does, and leaves less energy in the damped cells).
        prepay_budget_j: largest reserve (J; 2 mJ: at T = 4 ms without device damping a
            tap's withdrawal draws about 1.5 mJ from it; with 1 mJ the floor still yielded
            in 6 of the stability matrix's 4 ms cells).
        entry_force_limit_n: **entry boost** (None: off). While the probe moves into the
            wall at a speed where the felt floor's one-tick work is not affordable by
            itself (``F_floor (|dx| + Delta)`` above ``felt_tick_energy_j`` plus the
            damping term), and the reserve is short of the floor's cost of the
            withdrawal, estimated as ``F_floor x (penetration + |dx| + Delta)``, the
            pre-payment books that shortfall at once (up to ``prepay_budget_j``) and its
            damper may exceed ``max_damping_ns_per_m`` and the slew limit, up to this
            force (N; 3.3 N, the Omni's saturation). Moving in, the extra force is
            resistance, not a loss of felt force, so it is added after the energy bound.
            Without it, at T = 4 ms with b = 0 a tap is in contact for about 8 ticks and
            the damper, held to 5 N*s/m and 0.8 N per tick, cannot pre-pay the 0.5-0.75 mJ
            a 0.5 N floor hands the finger in the tick it leaves.
        entry_force_step_n: largest rise of the output per tick during the entry boost
            (N; 1.2 N). None: up to ``entry_force_limit_n`` at once (the stability
            matrix's largest force step was then 2.35 N).
        felt_uses_reserve: the felt floor's affordability also counts the pre-paid
            reserve (``F_floor (|dx| + Delta) <= felt_tick_energy_j + damping term +
            reserve``), so the floor holds through a withdrawal the entry has paid for.
    """

    max_damping_ns_per_m: float = 5.0
    velocity_deadband_mm_s: float = 1.0
    velocity_filter_hz: float = 30.0
    energy_tolerance_j: float = 0.0
    bound_tolerance_j: float = 5.0e-5
    energy_bound: bool = True
    device_mass_kg: float | None = 0.045
    device_damping_ns_per_m: float = 0.0
    position_resolution_mm: float = 0.0
    max_force_step_n: float | None = 0.8
    ramp_reserve_j: float = 2.5e-4
    generation_observer: bool = True
    generation_budget_j: float = 1.0e-5
    generation_floor_j: float = 1.0e-3
    dither_damping_ns_per_m: float = 3.0
    count_play_ratio: float = 0.75
    stiffness_cap: bool = True
    cap_colgate_multiple: float = 4.0
    cap_damping_share: float = 0.25
    cap_count_force_n: float | None = 0.4
    felt_floor_fraction: float | None = 0.95
    felt_force_n: float | None = 0.6
    felt_depth_mm: float = 1.0
    felt_tick_energy_j: float = 4.0e-4
    felt_damping_multiple: float = 4.0
    prepay_factor: float = 0.5
    prepay_budget_j: float = 2.0e-3
    entry_force_limit_n: float | None = 3.3
    entry_force_step_n: float | None = 1.2
    felt_uses_reserve: bool = True


def cap_stiffness_n_per_mm(settings: ControllerSettings, dt: float,
                           damping_ns_per_m: float | None = None,
                           resolution_mm: float | None = None) -> float:
    """Stiffness cap ``K_c`` (N/mm) of :class:`PassivityController` for period ``dt`` (s):
    the stiffest spring the device renders passively with the controller's damper as the
    margin, ``K_c = 2 (b + share * alpha_max) / dt`` (Colgate's ``b > K T / 2`` with the
    device damping ``b`` plus ``cap_damping_share`` of the damper's bound
    ``max_damping_ns_per_m``), and, when ``cap_count_force_n`` is set and the encoder is
    quantised, at most that force per encoder count. ``inf`` when the cap is off."""
    if not settings.stiffness_cap or not dt > 0:
        return math.inf
    b = settings.device_damping_ns_per_m if damping_ns_per_m is None else float(damping_ns_per_m)
    b = max(b, 0.0)
    kc = 2.0 * max(settings.cap_colgate_multiple * b,
                   b + settings.cap_damping_share * settings.max_damping_ns_per_m) / dt / 1000.0
    res = settings.position_resolution_mm if resolution_mm is None else float(resolution_mm)
    if settings.cap_count_force_n is not None and res > 0:
        kc = min(kc, settings.cap_count_force_n / res)
    return kc


def _cap(budget: float, v: float, dt: float, mass: float | None, quantum_m: float = 0.0) -> float:
    """Largest outward force whose predicted booked work over one period stays within
    budget: ``F (v+ dt + q + F dt^2 / (2 m)) <= budget``, where ``q`` (m) is one encoder
    count, the most the reading can jump beyond the true motion."""
    if budget <= 0.0:
        return 0.0
    vt = (v * dt if v > 0.0 else 0.0) + quantum_m
    if mass is None or mass <= 0:
        return budget / vt if vt > 0.0 else math.inf
    a = dt * dt / (2.0 * mass)
    return (-vt + math.sqrt(vt * vt + 4.0 * a * budget)) / (2.0 * a)


def _ramp_force(impulse: float, step: float | None) -> float:
    """Largest starting force F (N) whose ramp-down ``F, F - step, F - 2 step, ... , 0``
    (one value per tick) sums to at most ``impulse`` (N, the sum of the held forces).

    The sum is ``S(F) = sum_j max(F - j step, 0)``: ``S = F`` for ``F <= step`` and
    ``S <= F^2 / (2 step) + F / 2 + step / 8`` above (the chord of the parabola through the
    multiples of ``step``), whose inverse ``sqrt(2 step S) - step / 2`` is therefore safe."""
    if step is None or not impulse > step:
        return impulse
    r = math.sqrt(2.0 * step * impulse) - 0.5 * step
    return r if r > step else step


class PassivityController:
    """ZOH-paired passivity observer + generation observer with its damper + bounded
    variable damper + energy bound (scalar, one axis, pure-Python floats for the servo
    tick).

    Per tick call :meth:`step` with the measured position (mm), the measured period
    ``dt`` (s) and the wall's force (N); send the returned force; then call
    :meth:`commit` with the force the device actually applied (after the safety
    clamp). First the stiffness cap limits the wall's outward force to ``K_c x
    penetration`` (:func:`cap_stiffness_n_per_mm`; the surface is at x = 0), so a wall
    the device cannot render passively is rendered as the stiffest spring it can. The
    observer books ``E -= F_applied(n-1) * dx(n)``; the controller keeps
    ``E >= -energy_tolerance_j`` by (1) capping an outward push so its predicted work
    ``F v dt`` does not exceed the energy available and (2) a damper
    ``alpha = -E_avail / (v^2 dt)``, ``alpha <= max_damping_ns_per_m``, when the budget
    is already overdrawn; (3) limiting the output's change to ``max_force_step_n`` per
    tick, with the cap in (1) computed for the whole ramp-down at that rate. Before
    those, the generation observer ``G`` (see :class:`ControllerSettings`) adds a damper
    on the raw velocity as soon as the hold makes more energy than the device damping
    dissipates, so a wall above 2b/T is damped while it still renders its full spring;
    moving in, it also pre-pays the withdrawal (with the entry boost beyond its bound
    and the slew limit, see ``entry_force_limit_n``). Last, the felt floor
    (``felt_floor_fraction``) keeps the output deeper than ``felt_depth_mm`` at or above
    ``min(felt_force_n, felt_floor_fraction x wall force)`` while affordable.
    """

    __slots__ = ("settings", "energy_j", "generation_j", "reserve_j", "dissipated_j", "bounded_j", "active_ticks",
                 "capped_n", "_x_prev", "_f_prev", "_f_pc_prev", "_v", "_out_prev", "_fw_prev", "_x_play",
                 "_cap_dt", "_cap_k")

    def __init__(self, settings: ControllerSettings | None = None, **kw: Any) -> None:
        self.settings = settings or ControllerSettings(**kw)
        self.reset()

    def reset(self) -> None:
        """Forget the energy observed so far (at contact start or a new run)."""
        self.energy_j = 0.0        # energy absorbed by the wall (J), PO
        self.generation_j = 0.0    # hold's work relative to the wall's own law + credit (J)
        self.reserve_j = 0.0       # energy pre-paid by the damper on entry, not yet used (J)
        self._fw_prev = 0.0
        self._x_play = 0.0
        self.dissipated_j = 0.0    # energy removed by the damper (J)
        self.bounded_j = 0.0       # sum over ticks of the force withheld by the energy bound (N)
        self.active_ticks = 0
        self.capped_n = 0.0        # sum over ticks of the force removed by the stiffness cap (N)
        self._cap_dt = -1.0
        self._cap_k = math.inf
        self._x_prev: float | None = None
        self._f_prev = 0.0
        self._f_pc_prev = 0.0
        self._v = 0.0
        self._out_prev = 0.0

    def step(self, x_mm: float, dt: float, f_wall: float) -> float:
        """Observe, then return the force (N) to command this tick."""
        s = self.settings
        f_raw = f_wall
        if s.stiffness_cap and f_wall > 0.0 and x_mm < 0.0:
            # stiffness cap: the wall's force is at most K_c x penetration (the surface is
            # at x = 0), a conservative spring of the stiffness the device renders passively
            if dt != self._cap_dt:
                self._cap_dt = dt
                self._cap_k = cap_stiffness_n_per_mm(s, dt)
            fc = -self._cap_k * x_mm
            if f_wall > fc:
                self.capped_n += f_wall - fc
                f_wall = fc
        if self._x_prev is None or not dt > 0:
            self._x_prev = x_mm
            self._x_play = x_mm
            self._out_prev = f_wall
            self._fw_prev = f_wall
            return f_wall
        dx = (x_mm - self._x_prev) * 1e-3
        self._x_prev = x_mm
        q = s.position_resolution_mm * 1e-3  # one encoder count (m)
        bd = s.device_damping_ns_per_m
        adx = abs(dx)
        count_level = q > 0.0 and adx <= 1.000001 * q  # the reading moved by at most one count
        dfw = abs(f_wall - self._fw_prev) * dt  # the wall's force step, times dt
        work = self._f_prev * dx
        if q > 0.0 and dx != 0.0:
            # both observers book the reading through half a count of play: a dither
            # between two counts books nothing, as long as the wall's force step across
            # the count is one the device damping plus the damper can absorb; a
            # relay-like wall (a count worth newtons) is booked count by count
            h = 0.5 * s.position_resolution_mm
            xp = self._x_play
            if x_mm > xp + h:
                xp = x_mm - h
            elif x_mm < xp - h:
                xp = x_mm + h
            if bd > 0.0 and dfw <= s.count_play_ratio * (bd + s.max_damping_ns_per_m) * q:
                self.energy_j -= self._f_prev * (xp - self._x_play) * 1e-3
            else:
                self.energy_j -= work
            self._x_play = xp
        else:
            self.energy_j -= work
        credit = 0.0
        if bd > 0.0 and adx > q:
            credit = bd * (adx - q) * (adx - q) / dt
            self.energy_j += credit
        self.dissipated_j -= self._f_pc_prev * dx
        a = 1.0 - math.exp(-2.0 * math.pi * s.velocity_filter_hz * dt) if s.velocity_filter_hz > 0 else 1.0
        v_raw = dx / dt
        v = self._v + a * (v_raw - self._v)
        self._v = v
        avail = self.energy_j + s.energy_tolerance_j
        budget = self.energy_j + s.bound_tolerance_j
        f = f_wall
        active = False
        boost = False  # entry boost this tick (see ControllerSettings.entry_force_limit_n)
        need = 0.0
        f_entry = 0.0
        if s.generation_observer:
            # the hold's generation relative to the wall's own law (held-force work minus
            # the trapezoid of the wall's force), plus the credited device damping
            cg = credit
            if count_level and dx != 0.0 and dfw <= 2.0 * bd * adx:
                # a one-count change whose wall step is within Colgate's bound
                # (|dF| <= 2 b |dx| / dt): the device damping covers the hold's
                # K dx^2 / 2, so the count is credited whole instead of not at all
                cg = bd * dx * dx / dt
            delta = -work + 0.5 * (self._fw_prev + f_wall) * dx + cg
            g = self.generation_j + delta
            if s.entry_force_limit_n is not None and s.prepay_factor > 0.0 and s.felt_floor_fraction \
                    and dx < 0.0 and f_wall > 0.0:
                # entry boost (see ControllerSettings.entry_force_limit_n): moving in at a
                # speed where the floor is not affordable by itself, while the reserve is
                # short of the floor's cost of the withdrawal
                fl_e = s.felt_floor_fraction * f_raw
                if s.felt_force_n is not None and fl_e > s.felt_force_n:
                    fl_e = s.felt_force_n
                need = fl_e * ((-x_mm if x_mm < 0.0 else 0.0) * 1e-3 + adx + q)
                own = s.felt_tick_energy_j + s.felt_damping_multiple * (bd if bd > 0.0 else 0.0) * adx * adx / dt
                boost = self.reserve_j < need and fl_e * (adx + q) > own
            if s.prepay_factor > 0.0:
                # pre-paid budget (see ControllerSettings.prepay_factor)
                if dx < 0.0 and f_wall > 0.0:
                    extra = s.prepay_factor * -delta if delta < 0.0 else 0.0
                    if boost and need - self.reserve_j > extra:
                        extra = need - self.reserve_j
                    room = s.prepay_budget_j - self.reserve_j
                    extra = min(extra, room) if room > 0.0 else 0.0
                    g -= extra
                    self.reserve_j += extra
                elif g < 0.0 and self.reserve_j > 0.0:
                    draw = min(self.reserve_j, -g)
                    g += draw
                    self.reserve_j -= draw
            if f_wall == 0.0 and self._fw_prev == 0.0:
                g = 0.0  # out of contact: the empty wall holds and generates nothing
                self.reserve_j = 0.0
            if g > s.generation_budget_j:
                g = s.generation_budget_j
            else:
                floor = s.generation_floor_j
                if count_level:
                    # the damper's pulse at a count-level change is bounded by the dither
                    # damping (its velocity is one count per tick)
                    fq = s.dither_damping_ns_per_m * q * q / dt
                    if fq < floor:
                        floor = fq
                if g < -floor:
                    g = -floor
            self.generation_j = g
            if g < 0.0 and f_wall != 0.0 and abs(v_raw) * 1e3 > s.velocity_deadband_mm_s:
                amax = s.max_damping_ns_per_m
                if boost:
                    a_e = (s.entry_force_limit_n - f) / abs(v_raw)  # type: ignore[operator]  # boost: a limit is set
                    if a_e > amax:
                        amax = a_e
                alpha = -g / (dt * v_raw * v_raw)
                if alpha > amax:
                    alpha = amax
                if boost:
                    # the entry boost's resistance is not an outward push the energy
                    # bound must ramp down (the probe moves in): added after the bound
                    f_entry = -alpha * v_raw
                else:
                    f -= alpha * v_raw
                active = True
        step = s.max_force_step_n
        hard = math.inf
        if s.energy_bound and f > 0.0:
            # impulse budget of the rest of the push (N): one tick at most, or the whole
            # ramp-down at `step` per tick (same bound, see _cap / _ramp_force)
            vp = v if v > v_raw else v_raw
            cap = _ramp_force(_cap(budget, vp, dt, s.device_mass_kg, q), step)
            hard = _cap(budget + s.ramp_reserve_j, vp, dt, s.device_mass_kg, q) if step is not None else cap
            if f > cap:
                self.bounded_j += f - cap
                f = cap
                active = True
        f += f_entry
        f_pc = 0.0
        if avail < 0.0 and abs(v) * 1e3 > s.velocity_deadband_mm_s:
            alpha = -avail / (dt * v * v)
            if alpha > s.max_damping_ns_per_m:
                alpha = s.max_damping_ns_per_m
            f_pc = -alpha * v
            active = True
        out = f + f_pc
        if active:
            self.active_ticks += 1
        if step is not None and (active or self._f_pc_prev != 0.0):
            # slew limit while the controller acts and until the output has caught up
            # with the wall again; a cut below the one-tick cap is never delayed
            lo, hi = self._out_prev - step, self._out_prev + step
            if boost and s.entry_force_limit_n is not None:
                he = s.entry_force_limit_n
                if s.entry_force_step_n is not None and self._out_prev + s.entry_force_step_n < he:
                    he = self._out_prev + s.entry_force_step_n
                if hi < he:
                    hi = he
            if lo > hard:
                lo = hard
            out = lo if out < lo else (hi if out > hi else out)
        if s.felt_floor_fraction and f_raw > 0.0 and -x_mm >= s.felt_depth_mm:
            # felt floor (see ControllerSettings.felt_floor_fraction)
            fl = s.felt_floor_fraction * f_raw
            if s.felt_force_n is not None and fl > s.felt_force_n:
                fl = s.felt_force_n
            bp = bd if bd > 0.0 else 0.0
            allow = s.felt_tick_energy_j + s.felt_damping_multiple * bp * adx * adx / dt
            if s.felt_uses_reserve and s.generation_observer:
                allow += self.reserve_j
            if out < fl and fl * (adx + q) <= allow:
                out = fl
        self._f_pc_prev = out - f_wall
        self._out_prev = out
        self._fw_prev = f_wall
        return out

    def commit(self, f_applied: float) -> None:
        """Record the force the device actually held over the coming interval (N)."""
        if f_applied != f_applied or f_applied in (math.inf, -math.inf):
            f_applied = 0.0
        self._f_prev = f_applied

    def report(self) -> dict[str, float]:
        """Observer state: ``observed_energy_j`` (E, J), ``generation_j`` (G, J),
        ``dissipated_j`` (work of the corrections booked on the reading, J: with a
        quantised encoder the count-level pulses make it noisy and it can be negative
        while the true energy is not), ``withheld_n_ticks`` (N), ``active_ticks``,
        ``stiffness_capped_n_ticks`` (sum over ticks of the force the stiffness cap
        removed, N)."""
        return {"observed_energy_j": self.energy_j, "generation_j": self.generation_j,
                "prepaid_reserve_j": self.reserve_j,
                "dissipated_j": self.dissipated_j,
                "withheld_n_ticks": self.bounded_j, "active_ticks": self.active_ticks,
                "stiffness_capped_n_ticks": self.capped_n,
                "energy_tolerance_j": self.settings.energy_tolerance_j,
                "bound_tolerance_j": self.settings.bound_tolerance_j}


def controller_state_batch(n: int) -> dict[str, np.ndarray]:
    """Fresh state arrays for :func:`controller_step_batch` over ``n`` cells."""
    z = np.zeros(n)
    return {"energy": z.copy(), "dissipated": z.copy(), "x_prev": z.copy(), "f_prev": z.copy(),
            "f_pc_prev": z.copy(), "v": z.copy(), "out_prev": z.copy(), "started": np.zeros(n, bool),
            "generation": z.copy(), "fw_prev": z.copy(), "x_play": z.copy(), "reserve": z.copy()}


def controller_step_batch(state: dict[str, np.ndarray], x_mm: np.ndarray, dt: float,
                          f_wall: np.ndarray, on: np.ndarray,
                          settings: ControllerSettings | None = None,
                          damping_ns_per_m: "np.ndarray | float | None" = None,
                          resolution_mm: "np.ndarray | float | None" = None) -> np.ndarray:
    """Vectorised :class:`PassivityController` over many independent cells (same law,
    same order of operations). Cells where ``on`` is False pass the wall force through
    (their observer still runs). ``damping_ns_per_m`` (per cell) overrides
    ``settings.device_damping_ns_per_m`` and ``resolution_mm`` the encoder resolution. Call :func:`controller_commit_batch` after."""
    s = settings or ControllerSettings()
    started = state["started"]
    dx = np.where(started, (x_mm - state["x_prev"]) * 1e-3, 0.0)
    state["x_prev"] = np.array(x_mm, float)
    work = state["f_prev"] * dx
    bb = np.asarray(s.device_damping_ns_per_m if damping_ns_per_m is None else damping_ns_per_m, float)
    res = np.asarray(s.position_resolution_mm if resolution_mm is None else resolution_mm, float)
    qm = res * 1e-3  # one encoder count (m)
    adx = np.abs(dx)
    count_level = (qm > 0) & (adx <= 1.000001 * qm)
    f = np.array(f_wall, float)
    f_raw = f
    if s.stiffness_cap and dt > 0:
        bp = np.maximum(bb, 0.0)
        kc = 2.0 * np.maximum(s.cap_colgate_multiple * bp, bp + s.cap_damping_share * s.max_damping_ns_per_m) / dt / 1000.0
        if s.cap_count_force_n is not None:
            kc = np.where(res > 0, np.minimum(kc, s.cap_count_force_n / np.where(res > 0, res, 1.0)), kc)
        xa = np.asarray(x_mm, float)
        fc = np.where((f > 0.0) & (xa < 0.0), np.minimum(f, -kc * xa), f)
        f = np.where(on, fc, f)  # cells with the controller off keep the raw wall
        f_wall = f
    dfw = np.abs(f - state["fw_prev"]) * dt
    h = res * 0.5
    xp0 = np.where(started, state["x_play"], x_mm)
    xp = np.where(x_mm > xp0 + h, x_mm - h, np.where(x_mm < xp0 - h, x_mm + h, xp0))
    small = (bb > 0.0) & (dfw <= s.count_play_ratio * (bb + s.max_damping_ns_per_m) * qm)
    state["energy"] -= np.where((h > 0) & small, state["f_prev"] * (xp - xp0) * 1e-3, work)
    state["x_play"] = xp
    ddx = np.maximum(adx - qm, 0.0)
    credit = bb * ddx * ddx / dt
    state["energy"] += credit
    state["dissipated"] -= state["f_pc_prev"] * dx
    a = 1.0 - math.exp(-2.0 * math.pi * s.velocity_filter_hz * dt) if s.velocity_filter_hz > 0 else 1.0
    v_raw = dx / dt
    v = np.where(started, state["v"] + a * (v_raw - state["v"]), 0.0)
    state["v"] = v
    avail = state["energy"] + s.energy_tolerance_j
    budget = state["energy"] + s.bound_tolerance_j
    gen_damp = np.zeros(f.shape, bool)
    boost = np.zeros(f.shape, bool)
    if s.generation_observer:
        whole = count_level & (dx != 0) & (dfw <= 2.0 * bb * adx)
        cg = np.where(whole, bb * dx * dx / dt, credit)
        delta = -work + 0.5 * (state["fw_prev"] + f) * dx + cg
        g = state["generation"] + delta
        res_j = state["reserve"] if "reserve" in state else np.zeros_like(g)
        need = np.zeros_like(g)
        if s.entry_force_limit_n is not None and s.prepay_factor > 0.0 and s.felt_floor_fraction:
            # entry boost (see ControllerSettings.entry_force_limit_n): moving in at a speed
            # where the floor is not affordable by itself, while the reserve is short of
            # the floor's cost of the withdrawal
            fl_e = s.felt_floor_fraction * f_raw
            if s.felt_force_n is not None:
                fl_e = np.minimum(fl_e, s.felt_force_n)
            pen_m = np.maximum(-np.asarray(x_mm, float), 0.0) * 1e-3
            need = fl_e * (pen_m + adx + qm)
            own = s.felt_tick_energy_j + s.felt_damping_multiple * np.maximum(bb, 0.0) * adx * adx / dt
            boost = started & (dx < 0.0) & (f > 0.0) & (res_j < need) & (fl_e * (adx + qm) > own)
        if s.prepay_factor > 0.0:
            # pre-paid budget: while the probe moves into the wall the damper also pays
            # prepay_factor x the hold's generation in advance (kept as a reserve), so the
            # withdrawal, where the felt floor limits the damper, draws on energy already
            # dissipated
            entering = (dx < 0.0) & (f > 0.0)
            extra = np.where(entering, s.prepay_factor * np.maximum(-delta, 0.0), 0.0)
            extra = np.where(boost, np.maximum(extra, need - res_j), extra)
            extra = np.minimum(extra, np.maximum(s.prepay_budget_j - res_j, 0.0))
            g = g - extra
            res_j = res_j + extra
            draw = np.where(entering, 0.0, np.minimum(res_j, np.maximum(-g, 0.0)))
            g = g + draw
            res_j = res_j - draw
        floor = np.where(count_level, np.minimum(s.dither_damping_ns_per_m * qm * qm / dt, s.generation_floor_j),
                         s.generation_floor_j)
        out_of_contact = (f == 0.0) & (state["fw_prev"] == 0.0)
        g = np.clip(np.where(out_of_contact, 0.0, g), -floor, s.generation_budget_j)
        state["reserve"] = np.where(out_of_contact, 0.0, res_j)
        state["generation"] = g
        amax = np.full(f.shape, s.max_damping_ns_per_m)
        if s.entry_force_limit_n is not None and s.prepay_factor > 0.0 and s.felt_floor_fraction:
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                amax = np.where(boost, np.maximum(amax, (s.entry_force_limit_n - f) / np.abs(v_raw)), amax)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            gen_damp = started & (g < 0.0) & (f != 0.0) & (np.abs(v_raw) * 1e3 > s.velocity_deadband_mm_s)
            alpha_g = np.where(gen_damp, np.minimum(-g / (dt * v_raw * v_raw), amax), 0.0)
        push = -alpha_g * np.where(gen_damp, v_raw, 0.0)
        # the entry boost's resistance is not an outward push the energy bound must
        # ramp down (the probe moves in): it is added after the bound
        f_entry = np.where(boost, push, 0.0)
        f = f + np.where(boost, 0.0, push)
    else:
        f_entry = np.zeros(f.shape)
    step = s.max_force_step_n
    hard = np.full(f.shape, np.inf)
    if s.energy_bound:
        vt = np.maximum(np.maximum(v, v_raw), 0.0) * dt + qm
        with np.errstate(divide="ignore", invalid="ignore"):
            def one_tick(bud: np.ndarray) -> np.ndarray:
                bpos = np.maximum(bud, 0.0)
                if s.device_mass_kg is None or s.device_mass_kg <= 0:
                    return np.where(vt > 0, bpos / vt, np.inf)
                qa = dt * dt / (2.0 * s.device_mass_kg)
                return (-vt + np.sqrt(vt * vt + 4.0 * qa * bpos)) / (2.0 * qa)
            imp = one_tick(budget)
            if step is None:
                cap = hard = imp
            else:
                cap = np.where(imp > step, np.maximum(np.sqrt(2.0 * step * imp) - 0.5 * step, step), imp)
                hard = one_tick(budget + s.ramp_reserve_j)
        pos = f > 0
        capped = started & pos & (f > cap)
        f = np.where(capped, cap, f)
        hard = np.where(pos, hard, np.inf)
    else:
        capped = np.zeros(f.shape, bool)
    f = f + f_entry
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        damp = (avail < 0) & (np.abs(v) * 1e3 > s.velocity_deadband_mm_s)
        alpha = np.where(damp, np.minimum(-avail / (dt * v * v), s.max_damping_ns_per_m), 0.0)
    active = started & (capped | damp | gen_damp)
    f_pc = np.where(started, -alpha * v, 0.0)
    out = f + f_pc
    if step is not None:
        prev = state["out_prev"]
        limit = started & (active | (state["f_pc_prev"] != 0.0))
        lo = np.minimum(prev - step, hard)  # a cut below the one-tick cap is never delayed
        hi = prev + step
        if s.entry_force_limit_n is not None:
            he: float | np.ndarray = s.entry_force_limit_n
            if s.entry_force_step_n is not None:
                he = np.minimum(he, prev + s.entry_force_step_n)
            hi = np.where(boost, np.maximum(hi, he), hi)
        out = np.where(limit, np.clip(out, lo, hi), out)
    if s.felt_floor_fraction:
        # felt floor (see ControllerSettings.felt_floor_fraction): deeper than
        # felt_depth_mm no correction takes the output below min(felt_force_n,
        # felt_floor_fraction x the wall's own force) ...
        fl = s.felt_floor_fraction * f_raw
        if s.felt_force_n is not None:
            fl = np.minimum(fl, s.felt_force_n)
        # ... as long as its work over one tick of the current motion is affordable
        allow = s.felt_tick_energy_j + s.felt_damping_multiple * np.maximum(bb, 0.0) * adx * adx / dt
        if s.felt_uses_reserve and s.generation_observer:
            allow = allow + state["reserve"]
        afford = fl * (adx + qm) <= allow
        deep = (f_raw > 0.0) & (-np.asarray(x_mm, float) >= s.felt_depth_mm) & afford
        out = np.where(deep, np.maximum(out, fl), out)
    out = np.where(started, out, f_wall)
    state["f_pc_prev"] = np.where(on, out - f_wall, 0.0)
    state["out_prev"] = out
    state["fw_prev"] = np.array(f_wall, float)
    state["started"] = np.ones_like(started)
    return np.where(on, out, f_wall)


def controller_commit_batch(state: dict[str, np.ndarray], f_applied: np.ndarray) -> None:
    """Record the forces actually applied over the coming interval (N)."""
    state["f_prev"] = np.nan_to_num(np.asarray(f_applied, float), nan=0.0, posinf=0.0, neginf=0.0)


def zoh_observer_energy(x_mm: np.ndarray, f_applied: np.ndarray) -> np.ndarray:
    """Running ZOH-paired observer energy (J) of a recorded run: ``E_n = -sum F_{k-1} dx_k``."""
    dx = np.diff(np.asarray(x_mm, float)) * 1e-3
    return np.concatenate([[0.0], np.cumsum(-np.asarray(f_applied, float)[:-1] * dx)])


def naive_observer_energy(x_mm: np.ndarray, f_applied: np.ndarray, dt: float) -> np.ndarray:
    """Running textbook observer energy (J): ``E_n = -sum f_k v_k dt`` with the *current*
    force and the backward-difference velocity (blind to the energy of the hold)."""
    v = np.diff(np.asarray(x_mm, float)) * 1e-3 / dt
    return np.concatenate([[0.0], np.cumsum(-np.asarray(f_applied, float)[1:] * v * dt)])
