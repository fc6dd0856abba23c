"""One normal axis of a force arm held by a finger, integrated exactly under a
zero-order hold.

Model (SI units inside, mm at the interface), along the surface normal y:

    (m + m_h) y'' = F - b y' + k_h (r - y) + b_h (r' - y')

``m``, ``b``: the arm's apparent mass and physical viscous damping; ``F``: the force
the arm applies (held constant over each servo period, i.e. a zero-order hold, and
saturated at the force limit); ``m_h, k_h, b_h``: the finger (mass, spring, damper)
pushing towards its scripted reference ``r(t)``, which is linear within a period. The
system is linear within each period, so with the augmented state
``z = [y, v, r, r', F]`` the exact step is ``z(t+T) = expm(A T) z(t)``: no integration
error beyond float rounding, and unconditionally stable for any stiffness (checked
against scipy's Radau in the tests; ``expm`` is :func:`hapticsdk.linalg.expm`, numpy
only, so importing the simulator does not import scipy). The arm reports its position through an encoder
of resolution ``encoder_resolution_mm`` (quantised) and a backward-difference
velocity.

Parameter provenance (see :data:`OMNI_SOURCES`): the force limit 3.3 N and the
stiffness 2.3 N/mm are the paper's; the apparent mass and encoder resolution are
unverified spec-sheet values; no published viscous damping of the Omni was found, so
the default ``b`` is an assumption and a parameter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Sequence

import numpy as np

from ..argcheck import number
from ..errors import ValidationError
from ..linalg import expm
from .finger import FingerParams

#: Where the simulated Omni's figures come from.
OMNI_SOURCES = {
    "max_force_n": "3.3 N at the nominal position: the paper (MF of formula (4)), from the Omni spec",
    "max_stiffness_n_per_mm": "2.3 N/mm: GS_max used by the paper (Omni spec sheet Y-axis value, unverified)",
    "rated_stable_stiffness_n_per_mm": "0.7 N/mm (700 N/m): CHAI3D cPhantomDevice specification of the "
                                       "PHANTOM Omni (m_maxForceStiffness), its figure for stable rendering",
    "max_linear_damping_ns_per_m": "5 N*s/m: CHAI3D cPhantomDevice specification of the PHANTOM Omni",
    "mass_kg": "0.045 kg apparent mass: Omni spec sheet, from memory (unverified)",
    "encoder_resolution_mm": "0.055 mm (> 450 dpi): Omni spec sheet, from memory (unverified)",
    "damping_ns_per_m": "no published value found; 0.5 N*s/m is an assumption (a parameter)",
}


@dataclass(frozen=True)
class ArmParams:
    """Parameters of the simulated arm axis.

    Attributes:
        mass_kg: apparent mass at the stylus (kg).
        damping_ns_per_m: physical viscous damping b (N*s/m).
        max_force_n: force saturation (N).
        encoder_resolution_mm: position quantum (mm); 0 disables quantisation.
        max_stiffness_n_per_mm: stiffness the paper renders on it (N/mm).
        rated_stable_stiffness_n_per_mm: CHAI3D's stable-rendering figure (N/mm).
    """

    mass_kg: float = 0.045
    damping_ns_per_m: float = 0.5
    max_force_n: float = 3.3
    encoder_resolution_mm: float = 0.055
    max_stiffness_n_per_mm: float = 2.3
    rated_stable_stiffness_n_per_mm: float = 0.7

    def __post_init__(self) -> None:
        # a number of any other type (a list, a string, None) is refused by name too, not
        # left to numpy's TypeError or ValueError
        number(self.mass_kg, "arm.mass_kg", lo=0.0, lo_open=True)
        for k in ("damping_ns_per_m", "max_force_n", "encoder_resolution_mm"):
            number(getattr(self, k), f"arm.{k}", lo=0.0)

    def with_(self, **kw: float) -> "ArmParams":
        """A copy with the given parameters changed (same units as the fields)."""
        return replace(self, **kw)


def transition_matrices(period_s: float, arms: Sequence[ArmParams],
                        fingers: Sequence[FingerParams]) -> np.ndarray:
    """Exact ZOH transition rows, shape ``(n, 2, 5)``: ``[y, v](t+T) = P @ [y, v, r, r', F]``
    (SI units), one per (arm, finger) pair."""
    if not np.isfinite(period_s) or period_s <= 0:
        raise ValidationError(f"period must be > 0 s, got {period_s!r}", field="period_s")
    out = np.empty((len(arms), 2, 5))
    cache: dict[tuple, np.ndarray] = {}
    for i, (a, f) in enumerate(zip(arms, fingers)):
        key = (a.mass_kg, a.damping_ns_per_m, f.mass_kg, f.stiffness_n_per_m, f.damping_ns_per_m)
        if key not in cache:
            m = _augmented(a, f) * period_s
            with np.errstate(over="ignore", invalid="ignore"):
                rows = expm(m)[:2] if np.isfinite(m).all() else m[:2]
            if not np.isfinite(rows).all():
                # finite parameters whose rates overflow over one period (a damping of
                # 1e308 N s/m): no exact hold exists in floating point, so no simulation
                raise ValidationError(
                    f"the arm (mass {a.mass_kg!r} kg, damping {a.damping_ns_per_m!r} N s/m) and "
                    f"finger (mass {f.mass_kg!r} kg, stiffness {f.stiffness_n_per_m!r} N/m, "
                    f"damping {f.damping_ns_per_m!r} N s/m) have no finite transition over "
                    f"{period_s!r} s", field="arm")
            cache[key] = rows
        out[i] = cache[key]
    return out


def dissipation_gramians(period_s: float, arms: Sequence[ArmParams],
                         fingers: Sequence[FingerParams]) -> np.ndarray:
    """``G`` (n, 5, 5) with ``integral_0^T v(s)^2 ds = z^T G z`` for the augmented state z
    at the start of a period (Van Loan's block-exponential formula), so the energy the
    arm's damper dissipates, ``b * z^T G z``, is exact too."""
    out = np.empty((len(arms), 5, 5))
    cache: dict[tuple, np.ndarray] = {}
    for i, (a, f) in enumerate(zip(arms, fingers)):
        key = (a.mass_kg, a.damping_ns_per_m, f.mass_kg, f.stiffness_n_per_m, f.damping_ns_per_m)
        if key not in cache:
            A = _augmented(a, f)
            C = np.zeros((10, 10))
            C[:5, :5] = -A.T
            C[1, 6] = 1.0  # Q = e_v e_v^T
            C[5:, 5:] = A
            E = expm(C * period_s)
            G = E[5:, 5:].T @ E[:5, 5:]
            cache[key] = 0.5 * (G + G.T)
        out[i] = cache[key]
    return out


def _augmented(a: ArmParams, f: FingerParams) -> np.ndarray:
    M = a.mass_kg + f.mass_kg
    A = np.zeros((5, 5))
    A[0, 1] = 1.0
    A[1, 0] = -f.stiffness_n_per_m / M
    A[1, 1] = -(a.damping_ns_per_m + f.damping_ns_per_m) / M
    A[1, 2] = f.stiffness_n_per_m / M
    A[1, 3] = f.damping_ns_per_m / M
    A[1, 4] = 1.0 / M
    A[2, 3] = 1.0
    return A


def derivative(z: np.ndarray, arm: ArmParams, fing: FingerParams) -> np.ndarray:
    """Right-hand side of the augmented linear system (SI); for reference integrators."""
    y, v, r, rd, F = z
    M = arm.mass_kg + fing.mass_kg
    acc = (F - arm.damping_ns_per_m * v + fing.stiffness_n_per_m * (r - y)
           + fing.damping_ns_per_m * (rd - v)) / M
    return np.array([v, acc, rd, 0.0, 0.0])


def quantise(y_mm: "float | np.ndarray", resolution_mm: float) -> "float | np.ndarray":
    """Encoder reading of a position (mm): nearest multiple of the resolution."""
    if resolution_mm <= 0:
        return y_mm
    return np.round(np.asarray(y_mm) / resolution_mm) * resolution_mm


def readings_mm(y_m: np.ndarray, res_mm: np.ndarray) -> np.ndarray:
    """Encoder readings (mm) of true positions ``y_m`` (m): rounded to each lane's
    resolution (exact where the resolution is 0)."""
    y = y_m * 1e3
    with np.errstate(over="ignore"):
        q = y / np.where(res_mm > 0, res_mm, 1.0)
    # where the count is not a finite number (an encoder finer than the float's spacing
    # there) the reading is the position itself, as for a resolution of 0
    return np.where((res_mm > 0) & np.isfinite(q), np.round(q) * res_mm, y)


def zoh_step(P: np.ndarray, z: np.ndarray, y: np.ndarray, v: np.ndarray, f: np.ndarray, r_mm: Any,
             rd_mm_s: Any) -> tuple[np.ndarray, np.ndarray]:
    """One exact zero-order-hold step of every lane: fills the augmented state ``z``
    (``[y, v, r, r', F]``, SI) in place and returns ``(P z, z)``, the new ``[y, v]`` per lane
    (``P`` from :func:`transition_matrices`)."""
    z[:, 0] = y
    z[:, 1] = v
    z[:, 2] = np.asarray(r_mm, float) * 1e-3
    z[:, 3] = np.asarray(rd_mm_s, float) * 1e-3
    z[:, 4] = f
    return np.einsum("nij,nj->ni", P, z), z


class ArmBatch:
    """Many independent arm+finger cells advanced together (vectorised).

    Positions in m inside; :meth:`measured_mm` gives the encoder reading in mm.
    """

    def __init__(self, period_s: float, arms: Sequence[ArmParams], fingers: Sequence[FingerParams],
                 y0_mm: "float | np.ndarray" = 0.0, *, track_energy: bool = False) -> None:
        self.period_s = float(period_s)
        self.arms = list(arms)
        self.P = transition_matrices(self.period_s, self.arms, list(fingers))
        self.track_energy = bool(track_energy)
        if track_energy:
            self.G = dissipation_gramians(self.period_s, self.arms, list(fingers))
            self.b = np.array([a.damping_ns_per_m for a in self.arms])
            self.m = np.array([a.mass_kg for a in self.arms])
            #: work of the motor force on the stylus (J), exact
            self.motor_work_j = np.zeros(len(self.arms))
            #: energy dissipated by the arm's own damping (J), exact
            self.damper_j = np.zeros(len(self.arms))
        n = len(self.arms)
        self.y = np.broadcast_to(np.asarray(y0_mm, float) * 1e-3, (n,)).copy()
        self.v = np.zeros(n)
        self.fmax = np.array([a.max_force_n for a in self.arms])
        self.res_mm = np.array([a.encoder_resolution_mm for a in self.arms])
        self._z = np.zeros((n, 5))

    def measured_mm(self) -> np.ndarray:
        """Every arm's position as its encoder reports it (mm, rounded to the encoder
        resolution).
        """
        return readings_mm(self.y, self.res_mm)

    def step(self, force_n: np.ndarray, r_mm: np.ndarray, rd_mm_s: np.ndarray) -> np.ndarray:
        """Advance one period under the held force (saturated at the limit); returns the
        force actually applied (N)."""
        f = np.clip(force_n, -self.fmax, self.fmax)
        yv, z = zoh_step(self.P, self._z, self.y, self.v, f, r_mm, rd_mm_s)
        if self.track_energy:
            self.damper_j += self.b * np.einsum("ni,nij,nj->n", z, self.G, z)
            self.motor_work_j += f * (yv[:, 0] - self.y)
        self.y = yv[:, 0]
        self.v = yv[:, 1]
        return f

    def energy_to_user_j(self) -> np.ndarray:
        """Energy the arm + wall have given to the finger so far (J): motor work minus the
        arm's kinetic energy minus what its damping dissipated (the negative of the
        display-port energy W_d; <= 0 for a passive display)."""
        return self.motor_work_j - 0.5 * self.m * self.v ** 2 - self.damper_j


def start_m(arm: ArmParams, fing: FingerParams, y0_mm: float) -> float:
    """A stylus's start ``y0_mm`` (mm) in metres, refused with a
    :class:`~hapticsdk.errors.ValidationError` naming ``y0_mm`` where the finger's spring
    energy at that distance, ``k y0^2 / 2``, is not a finite number (a finite but absurd
    start such as 1e308 mm): the simulation books every energy it exchanges, so one it cannot
    represent would give the servo loop NaN readings."""
    y = float(y0_mm) * 1e-3
    if not math.isfinite(0.5 * float(fing.stiffness_n_per_m) * y * y):
        raise ValidationError(f"y0_mm={y0_mm!r}: a start this far gives the finger's spring an energy "
                              f"beyond floating point", field="y0_mm")
    return y


class ArmSim:
    """One arm + finger axis with a scalar, allocation-free exact step (for the servo loop)."""

    def __init__(self, arm: ArmParams, fing: FingerParams, period_s: float = 0.001, y0_mm: float = 0.0) -> None:
        self.arm = arm
        self.finger = fing
        self.y = start_m(arm, fing, y0_mm)
        self.v = 0.0
        self._rows: dict[float, tuple[tuple[float, ...], tuple[float, ...]]] = {}
        self._rows_for(period_s)

    def _rows_for(self, dt: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
        rows = self._rows.get(dt)
        if rows is None:
            P = transition_matrices(dt, [self.arm], [self.finger])[0]
            rows = (tuple(float(v) for v in P[0]), tuple(float(v) for v in P[1]))
            if len(self._rows) > 64:  # measured dt in realtime mode: bound the cache
                self._rows.clear()
            self._rows[dt] = rows
        return rows

    def step(self, dt: float, force_n: float, r_mm: float, rd_mm_s: float) -> float:
        """Advance ``dt`` seconds under ``force_n`` (saturated); returns the applied force."""
        fm = self.arm.max_force_n
        f = fm if force_n > fm else (-fm if force_n < -fm else force_n)
        (a0, a1, a2, a3, a4), (b0, b1, b2, b3, b4) = self._rows_for(dt)
        y, v, r, rd = self.y, self.v, r_mm * 1e-3, rd_mm_s * 1e-3
        self.y = a0 * y + a1 * v + a2 * r + a3 * rd + a4 * f
        self.v = b0 * y + b1 * v + b2 * r + b3 * rd + b4 * f
        return f

    def measured_mm(self) -> float:
        """The arm's position as its encoder reports it (mm, rounded to the encoder
        resolution).
        """
        res = self.arm.encoder_resolution_mm
        y = self.y * 1e3
        if res > 0:
            q = y / res
            if q - q == 0.0:   # finite; an encoder finer than the float's spacing reads y itself
                return round(q) * res
        return y


def free_arm_readings_mm(period_s: float, arm: ArmParams, forces_n: Any, y0_mm: float = 0.0) -> np.ndarray:
    """Encoder readings (mm) of an arm nobody holds, driven by ``forces_n`` (N, one per
    period, held under a zero-order hold and saturated at the force limit), starting at
    rest at ``y0_mm``: the reading before each force is applied, then the last one
    (``len(forces_n) + 1`` readings). :class:`ArmSim` with a finger of no mass, stiffness
    or damping (the hands-off run of :mod:`hapticsdk.calibration.damping`)."""
    sim = ArmSim(arm, FingerParams(0.0, 0.0, 0.0), float(period_s), y0_mm)
    dt = float(period_s)
    y = [sim.measured_mm()]
    for fk in np.asarray(forces_n, float).tolist():
        sim.step(dt, fk, 0.0, 0.0)
        y.append(sim.measured_mm())
    return np.array(y)


def timed_free_arm_readings_mm(times_s: Any, forces_n: Any, arm: ArmParams, *, force_delays_s: Any = 0.0,
                               reading_offsets_s: Any = 0.0, hold_s: float | None = None,
                               y0_mm: float = 0.0) -> np.ndarray:
    """:func:`free_arm_readings_mm` of a run paced on a clock that does not hold its period:
    force ``k`` (N, saturated) is sent at ``times_s[k]`` and reaches the arm
    ``force_delays_s[k]`` later (in order: never before the force sent before it); a
    force not followed within ``hold_s`` (s; None: never) is dropped to 0 N, as a safety
    layer drops a stale command; reading ``k`` is sampled at ``times_s[k] +
    reading_offsets_s[k]`` (either sign). The arm starts at rest at ``y0_mm``, at 0 N.
    Exact between the instants where the force changes (the closed-form step of ``m y'' =
    F - b y'``; with no delays, offsets or drops it gives :func:`free_arm_readings_mm`'s
    readings, whose step is :func:`transition_matrices`' ``expm``: tested)."""
    t = np.asarray(times_s, float)
    f = np.clip(np.asarray(forces_n, float), -arm.max_force_n, arm.max_force_n)
    if t.ndim != 1 or f.size != t.size - 1 or not (np.diff(t) > 0).all():
        raise ValidationError("needs increasing times, one more than the forces", field="times_s")
    lam = np.broadcast_to(np.asarray(force_delays_s, float), f.shape)
    rho = np.broadcast_to(np.asarray(reading_offsets_s, float), t.shape)
    arrive = np.maximum.accumulate(t[:-1] + lam)
    # the force as breakpoints (instant, value): each arrival, then its drop when stale
    brk: list[tuple[float, float]] = []
    for k in range(f.size):
        brk.append((float(arrive[k]), float(f[k])))
        nxt = float(arrive[k + 1]) if k + 1 < f.size else math.inf
        if hold_s is not None and arrive[k] + hold_s < nxt:
            brk.append((float(arrive[k] + hold_s), 0.0))
    m, b = arm.mass_kg, arm.damping_ns_per_m
    alpha = b / m
    # the step of m y'' = F - b y' over s seconds at constant F (exact)
    def step(y: float, v: float, F: float, s: float) -> tuple[float, float]:
        if s <= 0.0:
            return y, v
        x = alpha * s
        h = s * (1.0 - x / 2.0 + x * x / 6.0 - x ** 3 / 24.0) if x < 1e-3 else -math.expm1(-x) / alpha
        gg = s * s * (0.5 - x / 6.0 + x * x / 24.0 - x ** 3 / 120.0) if x < 1e-3 else (s - h) / alpha
        u = F / m
        return y + v * h + u * gg, v * math.exp(-x) + u * h

    q_at = t + rho
    order = np.argsort(q_at, kind="stable")
    out = np.empty(t.size)
    y, v, F, now = float(y0_mm) * 1e-3, 0.0, 0.0, -math.inf
    i = 0
    for j in order.tolist():
        tq = float(q_at[j])
        while i < len(brk) and brk[i][0] <= tq:
            if now > -math.inf:
                y, v = step(y, v, F, brk[i][0] - now)
            now, F = brk[i]
            i += 1
        if now > -math.inf:
            y, v = step(y, v, F, tq - now)
            now = tq
        out[j] = y * 1e3
    return quantise(out, arm.encoder_resolution_mm)  # type: ignore[return-value]
