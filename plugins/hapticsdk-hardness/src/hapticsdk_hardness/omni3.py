"""``omni3-virtual``: the simulated PHANTOM Omni with its three actuated axes.

The real Omni (and the DHD and Inverse3 arms) apply the force vector ``F n`` along a
contact's normal; :class:`~hapticsdk_hardness.omni.OmniVirtual` simulates the y axis only
(``force_axes = (1,)``). This device simulates x, y and z alike: on each axis the arm of
:mod:`hapticsdk.sim.arm` (the same apparent mass, viscous damping and encoder, declared
once for the stylus, as the Omni's figures are) held by the same finger (mass, spring and
damper towards that axis's scripted reference), integrated exactly under a zero-order
hold (the axes are decoupled: an isotropic mass, damper and finger are diagonal). The
force is the command's ``force_n`` along its ``direction`` (+y when it has none), its
magnitude saturated at the arm's force limit (one figure for the vector, as the Omni's
3.3 N "at the nominal position": the Euclidean norm, the direction kept).

Energy (:meth:`Omni3Virtual.energy_to_user_j`): the motor work on the true positions,
``sum_k F_k . (p_{k+1} - p_k)``, less the arm's kinetic energy ``m |v|^2 / 2`` and its
damper's loss ``b int |v|^2 dt``, the latter exact per step through Van Loan's Gramian
(:func:`hapticsdk.sim.arm.dissipation_gramians`). Generated data.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from hapticsdk.devices.actuators import DeviceState, SensedState
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.sim.arm import dissipation_gramians, readings_mm, start_m, transition_matrices

from .omni import OmniVirtual

_UP = (0.0, 1.0, 0.0)


class Omni3Virtual(OmniVirtual):
    """Simulated Omni rendering force on x, y and z (entry point ``omni3-virtual``).

    Options as :class:`~hapticsdk_hardness.omni.OmniVirtual` (``trajectory`` may be 3-D:
    :class:`~hapticsdk.sim.finger.Trajectory` with ``(t, x, y, z)`` knots; the finger
    pushes each axis towards its reference). ``y0_mm`` sets the stylus's initial height
    only; x and z start at the trajectory's.
    """

    name: ClassVar[str] = "omni3-virtual"
    #: three physical axes: the force's whole vector along the contact normal is rendered
    force_axes: ClassVar[tuple[int, ...]] = (0, 1, 2)

    def _reset(self) -> None:
        x, y, z, _, _, _ = self.trajectory.at3(0.0)
        y0 = y if self._y0 is None else float(self._y0)
        self.t = 0.0
        #: true stylus position (m) and velocity (m/s), per axis x, y, z
        start_m(self.arm, self.finger, y0)   # a start that far is refused by name
        self.p = np.array([x, y0, z]) * 1e-3
        self.v = np.zeros(3)
        self._res = np.full(3, self.arm.encoder_resolution_mm)
        self._p_meas = readings_mm(self.p, self._res)
        self._v3 = np.zeros(3)
        self._f_vec = np.zeros(3)
        self._f_set = 0.0
        self._d_set: tuple[float, float, float] | None = None
        self._z = np.zeros((3, 5))
        self._mats: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self._matrices(0.001)  # parameters with no finite hold are refused here, by name
        #: work done by the motor force on the stylus (J), exact under the hold
        self.motor_work_j = 0.0
        #: energy the arm's own damping dissipated (J), exact (Van Loan's Gramian)
        self.damper_j = 0.0

    def _open(self) -> None:
        self._reset()

    def _command(self, cmd: ChannelCommand) -> None:
        """Kept by the safety layer (:meth:`step` applies it); the set-point, its
        magnitude saturated at the force limit, is kept for :meth:`read_back`."""
        f = 0.0 if cmd.force_n is None else cmd.force_n
        fmax = self.arm.max_force_n
        if not abs(f) <= fmax:
            f = math.copysign(fmax, f) if f == f else 0.0
        self._f_set = f
        self._d_set = cmd.direction

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("force", force_n=self._f_set, direction=self._d_set)

    def _stop(self) -> None:
        self._f_vec = np.zeros(3)
        self._f_set = 0.0
        self._d_set = None

    def _read_state(self) -> DeviceState:
        pm, ve, f = self._p_meas, self._v3, self._f_vec
        return SensedState.of(self.t, float(pm[0]), float(pm[1]), float(pm[2]), float(ve[0]), float(ve[1]),
                              float(ve[2]), float(f[0]), float(f[1]), float(f[2]))

    def _force_vec(self, now: float) -> np.ndarray:
        """The force vector (N) the safety layer's current command asks for, its norm
        saturated at the arm's force limit (direction kept)."""
        cmd = self.safety.current(now) if self.is_open else None
        if cmd is None or cmd.force_n is None:
            return np.zeros(3)
        d = _UP if cmd.direction is None else cmd.direction
        f = cmd.force_n * np.asarray(d, float)
        n = float(np.linalg.norm(f))
        if not math.isfinite(n):
            return np.zeros(3)
        fmax = self.arm.max_force_n
        return f * (fmax / n) if n > fmax else f

    def _matrices(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        m = self._mats.get(dt)
        if m is None:
            P = transition_matrices(dt, [self.arm], [self.finger])[0]
            G = dissipation_gramians(dt, [self.arm], [self.finger])[0]
            if len(self._mats) > 64:  # measured dt in realtime mode: bound the cache
                self._mats.clear()
            m = self._mats[dt] = (P, G)
        return m

    def _advance(self, dt: float, f: Any) -> None:  # f: the force vector (N), held over dt
        P, G = self._matrices(dt)
        r0 = np.array(self.trajectory.at3(self.t)[:3])
        r1 = np.array(self.trajectory.at3(self.t + dt)[:3])
        z = self._z
        z[:, 0] = self.p
        z[:, 1] = self.v
        z[:, 2] = r0 * 1e-3
        z[:, 3] = (r1 - r0) * (1e-3 / dt)
        z[:, 4] = f
        yv = z @ P.T
        self.damper_j += self.arm.damping_ns_per_m * float(np.einsum("ni,ij,nj->", z, G, z))
        self.motor_work_j += float(np.dot(f, yv[:, 0] - self.p))
        self.p = yv[:, 0].copy()
        self.v = yv[:, 1].copy()
        self._f_vec = np.asarray(f, float)
        self.t += dt

    def energy_to_user_j(self) -> float:
        """Energy the arm + wall have given the finger so far (J): motor work on the true
        positions minus the arm's kinetic energy minus its damper's loss (<= 0 for a
        passive display)."""
        return self.motor_work_j - 0.5 * self.arm.mass_kg * float(self.v @ self.v) - self.damper_j

    def _step(self, dt: float) -> None:
        """As :meth:`OmniVirtual._step`: the command held while the safety layer
        considers it fresh, then zero; then the encoder readings and velocity estimate
        of each axis."""
        t0 = self.t
        f = self._force_vec(t0)
        if f.any() and dt > 0 and not self._force_vec(t0 + dt).any():
            fresh = getattr(getattr(self.safety, "settings", None), "stale_after_s", dt)
            fresh = min(max(fresh, 0.0), dt)
            if fresh > 0:
                self._advance(fresh, f)
            if dt - fresh > 1e-12:
                self._advance(dt - fresh, np.zeros(3))
            self.t = t0 + dt
        else:
            self._advance(dt, f)
        p_meas = readings_mm(self.p, self._res)
        v_raw = (p_meas - self._p_meas) / dt
        if self.velocity_filter_hz is None:
            self._v3 = v_raw
        else:
            a = 1.0 - math.exp(-2.0 * math.pi * self.velocity_filter_hz * dt)
            self._v3 = self._v3 + a * (v_raw - self._v3)
        self._p_meas = p_meas

    @property
    def serial_number(self) -> str:
        """The simulated arm's serial number: its physics, as
        :attr:`OmniVirtual.serial_number`, marked three-axis."""
        return "sim-omni3-" + super().serial_number[len("sim-omni-"):]

    @property
    def true_position_mm(self) -> float:
        """Unquantised stylus height (mm, y); :attr:`true_position3_mm` has all three."""
        return float(self.p[1]) * 1e3

    @property
    def true_position3_mm(self) -> tuple[float, float, float]:
        """Unquantised stylus position (mm): x, y, z."""
        return (float(self.p[0]) * 1e3, float(self.p[1]) * 1e3, float(self.p[2]) * 1e3)
