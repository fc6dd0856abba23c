"""The declared device parameters of the stiff-wall controller (:class:`ControllerSettings`),
the constants derived in docs/runtime.md ("Passivity"), and the 0.1 controller's settings,
still accepted with a ``DeprecationWarning``."""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..argcheck import flag, number
from .margin import _check_nonneg


#: Ramp time (s) of a full-scale force change: a change spread over at least 5 ms is
#: free of clicks (reference goal 11, the same bound as the vibration gate's ramp).
RAMP_TIME_S = 5.0e-3
#: Share of the device's damping the Colgate spring takes, ``b_s = min(b_lo, DAMPING_TRUST
#: x b_dev)``: a damping is known within a factor of two (a fit's spread, the stated
#: uncertainty of a declaration, the 0.5x-2x band the randomised benchmark draws), so the
#: true damping is at least half of it; the other half pays the encoder's terms
#: (docs/runtime.md, Passivity items 0 and 2). Also the share of a declaration a caller
#: may choose to credit (``declared_damping_trust=DAMPING_TRUST``).
DAMPING_TRUST = 0.5
#: Share of a declared, unmeasured damping the controller credits: none. A declaration is
#: a number somebody wrote, not a measurement of the arm; one of 0.5 N s/m on an arm with
#: none turns every credited joule into energy for the hand (up to 110 mJ over seed 1's
#: drawn cells with half of it credited, docs/runtime.md, Passivity item 2). The damping
#: is credited as far as it is measured hands off (``measured_damping_ns_per_m``,
#: :mod:`hapticsdk.calibration.damping`).
DECLARED_DAMPING_TRUST = 0.0
#: Share of the declared apparent mass the controller takes as the arm's: a declared mass
#: is taken as known within a factor of two, as the damping is (the apparent mass of a
#: linkage changes over its workspace and with the grip, and a hand-written declaration can
#: be off), so the true mass is at least half of it. The plan's free-arm terms divide by the
#: mass, and a lighter arm moves further under the same force: half the declaration is
#: the conservative side (docs/runtime.md, Passivity item 5).
MASS_TRUST = 0.5
#: Default of ``ControllerSettings.energy_allowance_j`` (J): the most energy the extra's
#: bound may hand the user over a contact, the SDK's passivity specification (0.1 mJ: a
#: 10 g fingertip at 0.14 m/s). It caps the encoder allowance ``F_max Delta / 2``, which
#: exceeds it only on encoders coarser than ``2 E / F_max`` (0.06 mm at 3.3 N).
ENERGY_ALLOWANCE_J = 1.0e-4


@dataclass
class ControllerSettings:
    """Declared device parameters of :class:`PassivityController` (nothing tuned).

    Each field is checked where it is set (construction, ``dataclasses.replace``, or an
    assignment, which takes effect at the controller's next tick) and stored as a plain
    float (``energy_bound`` as a bool): a value the tick could not use (a string, a bool
    for a number, NaN, infinity, out of range) is a ``ValidationError`` naming the field.

    Attributes:
        device_damping_ns_per_m: physical viscous damping of the device (N*s/m): the
            declared one, or the fitted one after a hands-off measurement
            (:meth:`for_device` with a damping calibration). ``measured_damping_ns_per_m``
            is credited where set, else ``declared_damping_trust`` times it (none by
            default); the Colgate spring takes at most ``damping_trust`` times it.
        damping_trust: the Colgate spring's share of the device's damping
            (:data:`DAMPING_TRUST`, 1/2: a damping is known to a factor 2, and the rest
            pays the encoder's terms).
        declared_damping_trust: share of the declared damping credited where none was
            measured (:data:`DECLARED_DAMPING_TRUST`, 0: a declaration is not a
            measurement). ``DAMPING_TRUST`` credits half of it, as 0.2.0 did: a
            declaration more than twice the true damping then hands the user energy.
        measured_damping_ns_per_m: a lower bound of the true damping (N*s/m) measured on
            this device, hands off (:func:`hapticsdk.calibration.damping.measure_damping`,
            its ``trusted_damping_ns_per_m``). None (the default):
            ``declared_damping_trust`` times the declared damping is credited; otherwise
            this is credited instead.
        position_resolution_mm: encoder resolution Delta (mm); 0 = exact positions.
        max_force_n: force limit of the device (N), the full scale of the ramp. None:
            the largest of the wall's forces and the outputs so far is the full scale.
        ramp_time_s: time of a full-scale ramp (s, :data:`RAMP_TIME_S`); the output
            changes by at most ``s = max_force_n * T / ramp_time_s`` per tick (at most
            ``max_force_n``).
        device_mass_kg: declared apparent mass m of the device (kg): a force increase
            ``dF`` pushes it ``dF T^2 / 2m`` further within the tick, which the plan's cost
            counts, and a change ``dF`` of the held force changes its motion by up to
            ``dF T^2 / m`` per tick, which the plan's prediction counts. None: neither is
            counted; otherwise a finite number > 0. Only ``mass_trust`` times it is
            taken as the arm's mass. (The kinetic energy it stores is left out of the
            bound, which is conservative.)
        mass_trust: share of the declared mass taken as a lower bound of the true apparent
            mass (:data:`MASS_TRUST`, 1/2: a declaration is trusted to a factor 2), in
            (0, 1].
        energy_bound: False removes the energy bound (the output then follows the wall
            through the ramp only): for tests that must see the bound matter.
        period_s: the servo's nominal period (s) the Colgate spring is sized on, ``K_c =
            min(2 b_s / period_s, s(period_s) / Delta)`` (``s`` the ramp step), and with
            it declared the spring never stiffens while compressed (a full scale that
            grows without a declared force limit, or a setting assigned mid-contact,
            takes effect at the next contact). None (the default): each tick's measured
            period, which in a servo with jitter makes the spring's stiffness change
            while it is compressed (a rise stores energy nobody paid for); the servo loop
            sets its own period here. An interval longer than the period the spring was
            sized on is charged to the bound either way (docs/runtime.md, Passivity
            items 0 and 1).
        energy_allowance_j: the most energy (J) the extra's bound may hand the user
            (:data:`ENERGY_ALLOWANCE_J`): the allowance is ``min(F_max Delta / 2, this)``.
            A requirement, not a fitted constant: lower it for a stricter bound (with a
            coarse encoder the wall then rises at one reading only to ``2 E / Delta``).
    """

    device_damping_ns_per_m: float = 0.0
    damping_trust: float = DAMPING_TRUST
    declared_damping_trust: float = DECLARED_DAMPING_TRUST
    position_resolution_mm: float = 0.0
    measured_damping_ns_per_m: float | None = None
    max_force_n: float | None = None
    ramp_time_s: float = RAMP_TIME_S
    device_mass_kg: float | None = None
    mass_trust: float = MASS_TRUST
    energy_bound: bool = True
    energy_allowance_j: float = ENERGY_ALLOWANCE_J
    period_s: float | None = None
    #: the tick's constants derived from the fields (:meth:`_derive_tick_constants`), None
    #: until derived and again after a field is set (not a field: per instance, not compared)
    _tick_consts: ClassVar["tuple | None"] = None

    def __setattr__(self, name: str, value: Any) -> None:
        # every field is checked where it is set, at construction (the dataclass's
        # ``__init__`` sets each one), by ``dataclasses.replace`` and by a later
        # assignment alike, and stored as a plain float (or bool): the servo tick reads
        # these fields with no checks of its own, so a string, a bool or a NaN taken here
        # would fail there, on a device that is driving
        check = _FIELDS.get(name)
        object.__setattr__(self, name, value if check is None else check(value, name))
        # and the constants the tick derives from the fields are derived again (on the
        # controller's next step): a field assigned takes effect at once, as before
        object.__setattr__(self, "_tick_consts", None)

    def _derive_tick_constants(self) -> tuple:
        """The constants :meth:`PassivityController.step` derives from these fields, derived
        once per configuration (kept until a field is set, which drops them) instead of on
        every tick, each by the same operations in the same order as the step made them
        (bit-identical): ``(q, h, c2, b_lo, b_s, m, fm, ramp_time_s, period_s, allowance,
        energy_bound, kc_p, sp_p, e0_p)``: the resolution in m and its half, two counts in
        mm, the trusted damping and the spring's damping (N*s/m), the trusted mass (kg or
        None), the force limit, and, where both ``period_s`` and ``max_force_n`` are
        declared, the spring's stiffness cap and ramp step at that period and the energy
        allowance (else None: the step derives them from the tick's full scale and
        period)."""
        q = self.position_resolution_mm * 1e-3
        h = 0.5 * q
        c2 = 2.0 * self.position_resolution_mm
        b_lo = float(self.trusted_damping_ns_per_m())
        b_s = float(self.spring_damping_ns_per_m(None, b_lo))
        m = self.trusted_mass_kg()
        fm = self.max_force_n
        rt = self.ramp_time_s
        tn = self.period_s
        allowance = self.energy_allowance_j
        kc_p = sp_p = e0_p = None
        if tn is not None and fm is not None:
            kc_p, sp_p = _spring_stiffness_and_step(b_s, tn, fm, rt, q)
            e0_p = self.energy_budget_j(tn)
        c = (q, h, c2, b_lo, b_s, m, fm, rt, tn, allowance, self.energy_bound, kc_p, sp_p, e0_p)
        object.__setattr__(self, "_tick_consts", c)
        return c

    @classmethod
    def for_device(cls, device: Any, *, damping: Any = None, directory: Any = None) -> "ControllerSettings":
        """Settings from what a device declares: ``apparent_mass_kg``, ``damping_ns_per_m``,
        ``encoder_resolution_mm`` and ``limits.max_force_n`` (each optional), and its
        damping as measured hands off:

        * ``damping``: a :class:`~hapticsdk.calibration.damping.DampingCalibration` (its
          ``trusted_damping_ns_per_m`` is credited, and its fitted ``damping_ns_per_m``
          replaces the declared damping as the device's) or a number (N*s/m, a lower bound
          measured otherwise; the declared damping stays the device's);
        * else, where the device has a ``serial_number`` (a non-empty string), the
          ``"damping"`` calibration saved for exactly that serial in the calibration
          directory (``directory``, default :func:`hapticsdk.calibration.calibration_dir`);
          a file for any device (no serial) is not used: a damping belongs to one arm;
        * else none: ``declared_damping_trust`` times the declared damping is credited
          (none by default)."""
        def num(v: Any) -> float | None:
            try:
                f = float(v)
            except (TypeError, ValueError):
                return None
            return f if math.isfinite(f) and f > 0 else None
        lim = getattr(device, "limits", None)
        bound, fitted = _measured_damping(device, damping, directory)
        declared = num(getattr(device, "damping_ns_per_m", None)) or 0.0
        return cls(device_mass_kg=num(getattr(device, "apparent_mass_kg", None)),
                   device_damping_ns_per_m=declared if fitted is None else fitted,
                   position_resolution_mm=num(getattr(device, "encoder_resolution_mm", None)) or 0.0,
                   max_force_n=num(getattr(lim, "max_force_n", None)), measured_damping_ns_per_m=bound)

    def trusted_damping_ns_per_m(self, declared_ns_per_m: Any = None) -> Any:
        """The damping the controller credits (N*s/m): the measured lower bound where one is
        set, else ``declared_damping_trust`` times the declared damping (none by default;
        ``declared_ns_per_m``, a number or an array, overrides the settings' declaration)."""
        if self.measured_damping_ns_per_m is not None:
            return self.measured_damping_ns_per_m
        b = self.device_damping_ns_per_m if declared_ns_per_m is None else declared_ns_per_m
        return self.declared_damping_trust * b

    def trusted_mass_kg(self, declared_kg: Any = None) -> Any:
        """The arm's mass the plan's free-arm terms use (kg): ``mass_trust`` times the
        declared mass (``declared_kg``, a number or an array, overrides the settings'), a
        lower bound of the true apparent mass; None where no mass is declared."""
        m = self.device_mass_kg if declared_kg is None else declared_kg
        if m is None:
            return None
        return self.mass_trust * (np.asarray(m, float) if np.ndim(m) else float(m))

    def spring_damping_ns_per_m(self, device_ns_per_m: Any = None, trusted_ns_per_m: Any = None) -> Any:
        """The Colgate spring's damping ``b_s = min(b_lo, damping_trust x b_dev)`` (N*s/m;
        docs/runtime.md, Passivity item 0): ``b_dev`` the device's damping
        (``device_ns_per_m`` overrides the settings'), ``b_lo`` the trusted damping
        (``trusted_ns_per_m`` overrides :meth:`trusted_damping_ns_per_m`). Numbers or
        arrays; :class:`PassivityController` computes the same inline on its tick."""
        b_dev = self.device_damping_ns_per_m if device_ns_per_m is None else device_ns_per_m
        b_lo = self.trusted_damping_ns_per_m(b_dev) if trusted_ns_per_m is None else trusted_ns_per_m
        return np.minimum(b_lo, self.damping_trust * np.asarray(b_dev, float))

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
        # the controllers' own order of operations: F_max x (half the resolution in m)
        return min(fs * (0.5 * (self.position_resolution_mm * 1e-3)), self.energy_allowance_j)


def _spring_stiffness_and_step(b_s: float, period_s: float, full_scale_n: float, ramp_time_s: float,
                              resolution_m: float) -> tuple[float, float]:
    """``(K_c, s)`` of the Colgate spring at ``period_s`` (N/m, N per tick): ``K_c = 2 b_s /
    T``, at most one ramp step ``s = F T / ramp_time`` (at most ``F``) per encoder count
    (docs/runtime.md, Passivity item 0); the scalar controller's rule, derived once per
    configuration where the period and the limit are declared, else on its tick."""
    kc = 2.0 * b_s / period_s
    sp = full_scale_n * (period_s / ramp_time_s if period_s < ramp_time_s else 1.0)
    if resolution_m > 0.0 and kc > sp / resolution_m:
        kc = sp / resolution_m
    return kc, sp


def _nonneg(value: Any, name: str) -> float:
    return number(value, name, lo=0.0)


def _positive_or_none(value: Any, name: str) -> float | None:
    return None if value is None else number(value, name, lo=0.0, lo_open=True)


def _positive(value: Any, name: str) -> float:
    return number(value, name, lo=0.0, lo_open=True)


def _nonneg_or_none(value: Any, name: str) -> float | None:
    return None if value is None else number(value, name, lo=0.0)


def _share(value: Any, name: str) -> float:
    return number(value, name, lo=0.0, hi=1.0)


def _positive_share(value: Any, name: str) -> float:
    return number(value, name, lo=0.0, hi=1.0, lo_open=True)


#: the check of each field of :class:`ControllerSettings` (its value as the tick reads it)
_FIELDS = {
    "device_damping_ns_per_m": _nonneg,
    "damping_trust": _share,
    "declared_damping_trust": _share,
    "position_resolution_mm": _nonneg,
    "measured_damping_ns_per_m": _nonneg_or_none,
    # the plan's free-arm terms divide by the mass: 0, a negative or a NaN mass would
    # make a held force look free of cost (None leaves those terms out)
    "max_force_n": _positive_or_none,
    "ramp_time_s": _positive,
    "device_mass_kg": _positive_or_none,
    "mass_trust": _positive_share,
    "energy_bound": flag,
    "energy_allowance_j": _nonneg,
    "period_s": _positive_or_none,
}


def _measured_damping(device: Any, damping: Any, directory: Any) -> tuple[float | None, float | None]:
    """``(lower bound, fitted damping)`` of :meth:`ControllerSettings.for_device` (None:
    not measured; the fit is None for a bare number)."""
    if damping is None:
        serial = getattr(device, "serial_number", None)
        if not (isinstance(serial, str) and serial):
            return None, None
        from ..calibration.store import load_calibration
        loaded = load_calibration("damping", serial, directory=directory)
        if loaded.origin != "file":
            return None, None
        damping = loaded.calibration
    bound = _check_nonneg("damping", getattr(damping, "trusted_damping_ns_per_m", damping))
    fit = getattr(damping, "damping_ns_per_m", None)
    return bound, (float(fit) if fit is not None else None)


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
    of the controller's Colgate spring instead (:func:`colgate_stiffness_n_per_mm`, N/mm);
    ``resolution_mm`` is ignored."""
    warnings.warn("cap_stiffness_n_per_mm is deprecated: the controller has no stiffness cap; use "
                  "colgate_stiffness_n_per_mm (the stiffness of its passive spring)", DeprecationWarning, stacklevel=2)
    return colgate_stiffness_n_per_mm(settings, dt, damping_ns_per_m)


def colgate_stiffness_n_per_mm(settings: ControllerSettings, dt: float, damping_ns_per_m: float | None = None,
                               full_scale_n: float | None = None) -> float:
    """Stiffness (N/mm) of :class:`PassivityController`'s Colgate spring at period ``dt``
    (s): ``K_c = 2 b_s / dt``, ``b_s = min(b_lo, damping_trust x`` the device damping``)``,
    with ``b_lo`` the trusted damping
    (:meth:`ControllerSettings.trusted_damping_ns_per_m`; ``damping_ns_per_m`` overrides the
    settings' declaration), at most one ramp step per
    encoder count, ``s / Delta`` (:meth:`ControllerSettings.ramp_step_n`, with
    ``full_scale_n`` where no force limit is declared; no such cap with an exact encoder
    or no full scale); 0 for ``dt <= 0``. docs/runtime.md, Passivity item 0."""
    b_s = float(settings.spring_damping_ns_per_m(None if damping_ns_per_m is None else float(damping_ns_per_m)))
    if not dt > 0 or not b_s > 0:
        return 0.0
    kc = 2.0 * b_s / dt
    q = settings.position_resolution_mm * 1e-3
    step = settings.ramp_step_n(dt, full_scale_n)
    if q > 0.0 and step > 0.0 and kc > step / q:
        kc = step / q
    return kc / 1000.0
