"""An independent simulator of one stability cell, kept apart from the benchmark's plant
(``hapticsdk.sim.arm`` / ``hapticsdk.sim.plant`` are not imported): the cross-check of
issue 23 ("an independent simulator: exact zero-order-hold plant, its own energy integral
from raw per-tick logs, driving the project's own controller").

Importable as ``independent_plant`` through ``tests/conftest.py``; also used by
``bench/bench_independent_plant.py``.

Model (the one docs/runtime.md "Simulated devices" and the benchmark's docstring state):
one normal axis, arm mass ``m`` and true damping ``b``, the finger's mass ``m_h`` moving
with the stylus, its spring ``k_h`` and damper ``b_h`` pulling towards the hand's
reference ``r(t)``::

    (m + m_h) y'' = F - b y' + k_h (r - y) + b_h (r' - y')

``F`` the force the device applies, held over each tick (zero-order hold) and clamped to
the 3.3 N limit; ``r`` linear within a tick between its values at the tick's ends.

Integration, per tick (state ``[y, v]`` SI, inputs ``r0, r', F`` constant over the tick):
the exact solution is ``s(tau) = E(tau) [y0, v0, r0, r', F]`` with ``E(tau)`` the first two
rows of ``expm(A tau)`` of the 5-state augmented system. ``E(T)`` gives the tick's end;
``E(tau_j)`` at Gauss-Legendre nodes ``tau_j`` give ``int v^2`` and ``int y`` over the tick
(the integrands are sums of exponentials ``e^(lambda tau)`` with ``|lambda| T <= 6`` over
the benchmark's space, for which 16 nodes are exact to ~1e-20 relative). The benchmark
uses Van Loan's Gramian for ``int v^2`` instead.

Energy to the user, two ways, from the raw per-tick states:

* device side (the issue's meaning: what the device puts into the hand):
  ``E_dev = sum F_k (y_{k+1} - y_k) - (1/2) m v^2 - b sum int v^2``
  (motor work on the true displacement, less the arm's kinetic energy, less what the arm's
  damper dissipated);
* finger side (what the hand holds or has lost):
  ``E_fin = (1/2) m_h v^2 + (k_h/2)((y - r)^2 - (y0 - r0)^2) + b_h sum int (v - r')^2
  + sum int (k_h (y - r) + b_h (v - r')) r'``
  (the finger mass's kinetic energy, its spring's energy, its damper's loss, and the work
  the finger did on the hand's reference).

The two are equal for the exact solution; their difference measures the integrator's error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from scipy.linalg import expm

FORCE_LIMIT_N = 3.3
REST_S = 0.3
_U = 2.0 ** -53
#: Relative error (of the scale of the terms summed) each tick's propagated state may carry in
#: either integration, both together: see :func:`energy_tolerance_j`.
EPS = 2.0 ** -40
_NODES = 16
_GL_X, _GL_W = np.polynomial.legendre.leggauss(_NODES)


def reference(cell: dict[str, Any]) -> tuple[Callable[[float], float], float]:
    """The hand's reference ``r(t)`` (mm) of a drawn cell and the run's duration (s), written
    from the cell's parameters (the trajectory kinds of the benchmark's docstring: approach
    from 2 mm above the surface, 0.2 mm for a creep; press to ``depth_mm``; hold, with a
    sinusoidal depth modulation for a bumpy slide and a linear drift for a plain slide;
    release at ``speed_out``; ``taps`` triangular taps; then ``REST_S`` of rest)."""
    kind = cell["trajectory"]
    creep = kind == "creep"
    a = 0.2 if creep else 2.0
    d = float(cell["depth_mm"])
    if kind == "tap":
        td = (a + d) / cell["tap_speed_mm_s"]
        dw = cell["tap_dwell_s"]
        per = 2 * td + dw + cell["tap_pause_s"]
        n = cell["taps"]

        def tap(t: float) -> float:
            k = math.floor(t / per)
            if k >= n:
                return a
            u = t - k * per
            tri = min(max(min(u / td, (2 * td + dw - u) / td), 0.0), 1.0)
            return a - (a + d) * tri
        return tap, n * per + REST_S
    vin = cell["creep_mm_s"] if creep else cell["speed_in_mm_s"]
    vout = cell["creep_mm_s"] if creep else cell["speed_out_mm_s"]
    d2 = max(d + (cell["drift_mm"] if kind == "plain_slide" else 0.0), 0.2)
    t_in = (a + d) / vin
    hold = cell["hold_s"]
    f = cell["bump_hz"]
    amp = cell["bump_mm"] if kind == "bumpy_slide" else 0.0
    if kind == "bumpy_slide":
        hold = max(round(hold * f), 1.0) / f
    t_h = t_in + hold
    t_out = (a + d2) / vout

    def clip(z: float) -> float:
        return min(max(z, 0.0), 1.0)

    def press(t: float) -> float:
        r = a - (a + d) * clip(t / t_in) - (d2 - d) * clip((t - t_in) / hold) + (a + d2) * clip((t - t_h) / t_out)
        if t_in < t < t_h:
            r -= amp * math.sin(2 * math.pi * f * (t - t_in))
        return r
    return press, t_h + t_out + REST_S


@dataclass
class CellPlant:
    """One cell's arm + finger, advanced one tick at a time (SI inside, mm outside)."""

    period_s: float
    mass_kg: float
    damping_ns_per_m: float
    finger_mass_kg: float
    finger_stiffness_n_per_m: float
    finger_damping_ns_per_m: float
    y: float = 0.0
    v: float = 0.0
    motor_work_j: float = 0.0
    arm_damper_j: float = 0.0
    finger_damper_j: float = 0.0
    hand_work_j: float = 0.0
    spring0_j: float = 0.0
    #: bound of |this plant's energy - another exact ZOH integration's| (J), see :meth:`step`
    budget_j: float = 0.0
    _E: np.ndarray = field(init=False, repr=False)
    _N: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        M = self.mass_kg + self.finger_mass_kg
        k, c = self.finger_stiffness_n_per_m, self.finger_damping_ns_per_m
        A = np.zeros((5, 5))
        A[0, 1] = 1.0
        A[1, :] = [-k / M, -(self.damping_ns_per_m + c) / M, k / M, c / M, 1.0 / M]
        A[2, 3] = 1.0
        T = self.period_s
        self._E = expm(A * T)[:2]
        taus = 0.5 * T * (_GL_X + 1.0)
        self._N = np.concatenate([expm(A * t)[:2] for t in taus])   # rows y(tau_j), v(tau_j) interleaved
        self._w = 0.5 * T * _GL_W
        self._absE = np.abs(self._E)
        self._absNv = np.abs(self._N[1::2])
        # the error budget's state: the amplification G of an error in [y, T v] over any
        # number of ticks up to the run's (filled by :meth:`amplification`), the error
        # carried (m, in y and in T v alike) and the sums the rounding term needs
        self.gain = 1.0
        self._carry = 0.0
        self._delta = 0.0
        self._abs_sum_j = 0.0
        self._vmax = 0.0
        self.ticks = 0

    def amplification(self, ticks: int) -> float:
        """``max_{k <= ticks} ||S P^k S^-1||_inf`` for the plant's own 2 x 2 transition ``P``
        (free of force and reference) in the units ``[y, T v]`` (``S = diag(1, T)``): how much
        an error of the state made on one tick can grow over the ticks that follow."""
        T = self.period_s
        a, b_, c, d = self._E[0, 0], self._E[0, 1] / T, self._E[1, 0] * T, self._E[1, 1]
        pa, pb, pc, pd = 1.0, 0.0, 0.0, 1.0
        g = 1.0
        for _ in range(ticks):
            pa, pb, pc, pd = pa * a + pb * c, pa * b_ + pb * d, pc * a + pd * c, pc * b_ + pd * d
            g = max(g, abs(pa) + abs(pb), abs(pc) + abs(pd))
        self.gain = g
        return g

    def start(self, y0_mm: float, r0_mm: float) -> None:
        self.y = y0_mm * 1e-3
        self.v = 0.0
        self.spring0_j = 0.5 * self.finger_stiffness_n_per_m * (self.y - r0_mm * 1e-3) ** 2

    def reading_mm(self, resolution_mm: float) -> float:
        y = self.y * 1e3
        return round(y / resolution_mm) * resolution_mm if resolution_mm > 0 else y

    def step(self, force_n: float, r0_mm: float, r1_mm: float) -> float:
        """Hold ``force_n`` (clamped to the limit) over one tick while the reference moves
        linearly from ``r0_mm`` to ``r1_mm``; returns the force applied."""
        f = min(max(force_n, -FORCE_LIMIT_N), FORCE_LIMIT_N) if force_n == force_n else 0.0
        T = self.period_s
        r0 = r0_mm * 1e-3
        rd = (r1_mm - r0_mm) * 1e-3 / T
        z = np.array([self.y, self.v, r0, rd, f])
        y1, v1 = self._E @ z
        nodes = (self._N @ z).reshape(_NODES, 2)
        iv2 = float(self._w @ (nodes[:, 1] ** 2))
        iy = float(self._w @ nodes[:, 0])
        dy = y1 - self.y
        k, c = self.finger_stiffness_n_per_m, self.finger_damping_ns_per_m
        self.motor_work_j += f * dy
        self.arm_damper_j += self.damping_ns_per_m * iv2
        # finger side: int (v - r')^2 = int v^2 - 2 r' dy + r'^2 T; int (y - r) r' = r'(int y - r0 T - r' T^2/2)
        self.finger_damper_j += c * (iv2 - 2 * rd * dy + rd * rd * T)
        self.hand_work_j += k * rd * (iy - r0 * T - 0.5 * rd * T * T) + c * rd * (dy - rd * T)
        # error budget (docs of :func:`energy_tolerance_j`): this tick adds EPS times the
        # scale of each propagated sum to the error carried, which the plant amplifies by
        # at most ``gain``
        az = np.abs(z)
        ay, av = self._absE @ az
        iv2_abs = float(self._w @ ((self._absNv @ az) ** 2))
        d0 = self._delta
        self._carry += EPS * (ay + T * av)
        d1 = self.gain * self._carry
        self._delta = d1
        b = self.damping_ns_per_m
        self.budget_j += abs(f) * (d0 + d1) + b * (EPS * iv2_abs + 2.0 * av * d1)
        self._abs_sum_j += abs(f * dy) + b * iv2
        self.ticks += 1
        self._vmax = max(self._vmax, av)
        self.y, self.v = float(y1), float(v1)
        self._r_end = r0 + rd * T
        return f

    def tolerance_j(self) -> float:
        """Bound of the difference between this plant's device-side energy and that of any
        other exact zero-order-hold integration of the same model under the same forces, on
        every tick so far (:func:`energy_tolerance_j`)."""
        return (self.budget_j + self.mass_kg * self._vmax * self._delta / self.period_s
                + 2.0 * self.ticks * _U * self._abs_sum_j)

    def count_margin_mm(self, resolution_mm: float) -> float:
        """How far (mm) the true position is from the nearest reading boundary, less the
        error the budget allows there: < 0 where another integration could read another count."""
        if not resolution_mm > 0:
            return math.inf
        y = self.y * 1e3 / resolution_mm
        return abs(y - math.floor(y) - 0.5) * resolution_mm - self._delta * 1e3

    def energy_device_j(self) -> float:
        return self.motor_work_j - 0.5 * self.mass_kg * self.v ** 2 - self.arm_damper_j

    def energy_finger_j(self) -> float:
        spring = 0.5 * self.finger_stiffness_n_per_m * (self.y - self._r_end) ** 2
        return (0.5 * self.finger_mass_kg * self.v ** 2 + spring - self.spring0_j + self.finger_damper_j
                + self.hand_work_j)


def energy_tolerance_j() -> None:
    """How the tolerance of :meth:`CellPlant.tolerance_j` is derived (documentation only).

    Two exact zero-order-hold integrations of the same linear model under the same held
    forces and the same reference differ by rounding alone. On each tick each computes the
    new ``y`` and ``v`` as sums of five terms ``P_ij z_j`` with a propagator ``P`` from
    ``expm``; the computed values are within ``eps (sum_j |P_ij z_j|)`` of the exact ones, with
    ``eps`` the propagator's relative error plus the sum's rounding (``5 u``, ``u = 2^-53``).
    scipy's ``expm`` (Pade 13 with scaling and squaring, Al-Mohy and Higham 2009) has a
    backward error within ``u``; its forward error on these 5 x 5 systems grows with the
    number of squarings and is measured against an extended-precision Taylor series in
    ``tests/sim/test_independent_plant.py``: entry by entry within 5e-16 (about 2^-51) on
    the test's cells, and the test asserts 2^-46. :data:`EPS` = 2^-40 gives each of the two
    integrations 2^-41, 32 times that assertion (the sum's rounding, 5 u, included). The damper's ``int v^2`` (Gauss-Legendre here: its truncation error for 16 nodes
    and ``|lambda| T <= 6`` is below 1e-20 relative; Van Loan's Gramian in the benchmark, an
    ``expm`` of the same kind) is within ``EPS int (sum_j |N_j z_j|)^2``.

    An error made on one tick is carried by the plant to the next ones; in units ``[y, T v]``
    the free plant's transition powers are at most ``G`` in the infinity norm
    (:meth:`CellPlant.amplification`, computed over the run's length), so the error in ``y`` and
    in ``T v`` after tick ``k`` is at most ``delta_k = G sum_{j <= k} EPS (Y_j + T V_j)``
    (``Y``, ``V`` the scales of tick ``j``'s sums). The same forces follow only where both read
    the same counts: :meth:`CellPlant.count_margin_mm` checks that every reading is further
    than ``delta`` from a count's edge. Then the device-side energy ``sum F dy - m v^2 / 2 -
    b sum int v^2`` differs by at most

        ``sum_k |F_k| (delta_k + delta_{k+1}) + b sum_k (EPS int (|N| |z|)^2 + 2 V_k delta_k)
        + m V delta / T + 2 N u sum_k (|F_k dy_k| + b int v^2)``

    (motor work; damper, its own error and the state's; kinetic energy; the sums' rounding
    over N ticks). This uses nothing of the code under test.
    """


def declared_mass_kg(cell: dict[str, Any]) -> float:
    """The arm's mass the cell declares to the controller (kg; the true one where it
    declares none)."""
    return float(cell.get("arm_mass_declared_kg", cell["arm_mass_kg"]))


def sdk_settings(cell: dict[str, Any], lane: str) -> Any:
    """The scalar controller's settings for the benchmark's ``sdk`` lane (the damping fit
    and its lower bound, from the cell's ``damping_calibration``) or ``sdk_declared`` lane
    (the declaration only, half of it trusted); the declared resolution, limit and mass."""
    from hapticsdk.passivity import ControllerSettings
    kw: dict[str, Any] = dict(position_resolution_mm=cell["resolution_mm"], max_force_n=FORCE_LIMIT_N,
                              device_mass_kg=declared_mass_kg(cell))
    if lane == "sdk":
        cal = cell["damping_calibration"]
        fit = cal["damping_ns_per_m"]
        kw.update(device_damping_ns_per_m=fit if fit == fit else 0.0,
                  measured_damping_ns_per_m=cal["trusted_damping_ns_per_m"])
    else:
        kw.update(device_damping_ns_per_m=cell["damping_declared_ns_per_m"])
    return ControllerSettings(**kw)


def drive(cell: dict[str, Any], ref: Callable[[float], float], duration_s: float,
          send: Callable[[float, float], float], commit: Callable[[float], None]) -> dict[str, Any]:
    """A cell's arm and finger (:class:`CellPlant`) driven through the hand's reference
    ``ref(t)`` (mm) for ``duration_s``: each tick ``send(reading_mm, wall_force_n)`` gives
    the command, the plant holds it (clamped) and ``commit(applied_force_n)`` is told what
    it held. Returns ``energy_to_user_j`` (device side, largest over the ticks),
    ``delivered_ratio`` (the benchmark's definition) and ``min_contact_force_n``."""
    T, res, K = float(cell["period_s"]), float(cell["resolution_mm"]), float(cell["stiffness_n_per_mm"])
    plant = CellPlant(T, cell["arm_mass_kg"], cell["damping_true_ns_per_m"], cell["finger_mass_kg"],
                      cell["finger_stiffness_n_per_m"], cell["finger_damping_ns_per_m"])
    r0 = ref(0.0)
    plant.start(r0, r0)
    worst = given = asked = fneg = 0.0
    for k in range(int(math.ceil(duration_s / T))):
        r1 = ref((k + 1) * T)
        x = plant.reading_mm(res)
        fw = K * -x if x < 0 else 0.0
        f = plant.step(send(x, fw), r0, r1)
        commit(f)
        if x < 0:
            tgt = min(fw, FORCE_LIMIT_N)
            given += min(max(f, 0.0), tgt)
            asked += tgt
            fneg = min(fneg, f)
        worst = max(worst, plant.energy_device_j())
        r0 = r1
    return {"energy_to_user_j": worst, "delivered_ratio": given / asked if asked else float("nan"),
            "min_contact_force_n": fneg}


def run_cell(cell: dict[str, Any], lane: str, *, log: bool = False, controller: str = "scalar",
             substeps: int = 1, overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """One cell with ``lane`` ``"plain"`` (the wall ``K x pen`` of the reading, no
    controller), ``"sdk"`` or ``"sdk_declared"``: the SDK controller, ``controller="scalar"``
    (:class:`~hapticsdk.passivity.PassivityController`: ``step`` then ``commit`` of the
    applied force) or ``"batch"`` (``controller_step_batch`` on one lane, called as the
    benchmark calls it). Returns the benchmark's figures measured independently
    (``energy_to_user_j`` the largest device-side energy over the ticks;
    ``delivered_ratio``; ``max_force_step_n``; ``min_contact_force_n``) plus
    ``energy_finger_side_j``, ``energy_sides_gap_j`` (largest |device - finger| over the
    ticks), ``tolerance_j`` (:meth:`CellPlant.tolerance_j` at the end) and
    ``count_margin_mm`` (smallest :meth:`CellPlant.count_margin_mm`), and with ``log`` the
    per-tick forces and references. ``substeps`` > 1 advances the plant in that many equal
    parts of each tick under the tick's held force, the reference linear within each part
    only (so the hand's path follows its kinks and sine within a tick), and adds
    ``energy_within_ticks_j``, the largest energy at the parts' ends. ``overrides``: fields
    of the controller's settings set apart from the lane's (e.g. ``mass_trust``)."""
    from hapticsdk.passivity import controller_commit_batch, controller_step_batch
    T = float(cell["period_s"])
    res = float(cell["resolution_mm"])
    K = float(cell["stiffness_n_per_mm"])
    ref, dur = reference(cell)
    S = int(substeps)
    plant = CellPlant(T / S, cell["arm_mass_kg"], cell["damping_true_ns_per_m"], cell["finger_mass_kg"],
                      cell["finger_stiffness_n_per_m"], cell["finger_damping_ns_per_m"])
    r_now = ref(0.0)
    plant.start(r_now, r_now)
    n = int(math.ceil(dur / T))
    plant.amplification(n * S)
    ctl = None
    batch = None
    if lane != "plain":
        settings = sdk_settings(cell, lane)
        if overrides:
            import dataclasses
            settings = dataclasses.replace(settings, **overrides)
        if controller == "scalar":
            from hapticsdk.passivity import PassivityController
            ctl = PassivityController(settings)
        else:
            from hapticsdk.passivity import ControllerSettings, controller_state_batch
            b_lo = settings.trusted_damping_ns_per_m()
            batch = (controller_state_batch(1), ControllerSettings(**(overrides or {})),
                     dict(damping_ns_per_m=np.array([settings.device_damping_ns_per_m]),
                          resolution_mm=np.array([res]), max_force_n=np.array([FORCE_LIMIT_N]),
                          mass_kg=np.array([declared_mass_kg(cell)]),
                          trusted_damping_ns_per_m=np.array([b_lo])))
    e_max = e_fin_max = gap = e_sub = 0.0
    given = asked = 0.0
    step_max = 0.0
    fneg = 0.0
    f_last = 0.0
    contact = 0
    margin = math.inf
    forces: list[float] = []
    refs: list[float] = [r_now]
    for k in range(n):
        r_next = ref((k + 1) * T)
        margin = min(margin, plant.count_margin_mm(res))
        x = plant.reading_mm(res)
        pen = -x
        fw = K * pen if pen > 0 else 0.0
        if ctl is not None:
            cmd = ctl.step(x, T, fw)
        elif batch is not None:
            cmd = float(controller_step_batch(batch[0], np.array([x]), np.array([T]), np.array([fw]), True,
                                              batch[1], **batch[2])[0])
        else:
            cmd = fw
        if S == 1:
            f = plant.step(cmd, r_now, r_next)
        else:
            ra = r_now
            for j in range(1, S + 1):
                rb = r_next if j == S else ref((k + j / S) * T)
                f = plant.step(cmd, ra, rb)
                e_sub = max(e_sub, plant.energy_device_j())
                ra = rb
        if ctl is not None:
            ctl.commit(f)
        elif batch is not None:
            controller_commit_batch(batch[0], np.array([f]))
        if pen > 0:
            tgt = min(fw, FORCE_LIMIT_N)
            given += min(max(f, 0.0), tgt)
            asked += tgt
            contact += 1
            fneg = min(fneg, f)
        step_max = max(step_max, abs(f - f_last))
        f_last = f
        ed, ef = plant.energy_device_j(), plant.energy_finger_j()
        e_max = max(e_max, ed)
        e_fin_max = max(e_fin_max, ef)
        gap = max(gap, abs(ed - ef))
        r_now = r_next
        if log:
            forces.append(f)
            refs.append(r_now)
    out: dict[str, Any] = {"energy_to_user_j": e_max, "energy_finger_side_j": e_fin_max, "energy_sides_gap_j": gap,
                           "delivered_ratio": given / asked if asked > 0 else float("nan"),
                           "max_force_step_n": step_max, "min_contact_force_n": fneg, "contact_ticks": contact,
                           "ticks": n, "tolerance_j": plant.tolerance_j(), "count_margin_mm": margin,
                           "gain": plant.gain, "energy_within_ticks_j": max(e_sub, e_max)}
    if log:
        out["forces_n"] = forces
        out["refs_mm"] = refs
    return out
