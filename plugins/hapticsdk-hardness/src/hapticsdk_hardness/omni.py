"""``omni-virtual``: a simulated PHANTOM Omni pressed by a simulated finger.

One normal axis (y) is simulated physically (:mod:`hapticsdk.sim.arm`: arm mass +
viscous damping + force saturation + encoder quantisation, finger as mass-spring-damper
driven by a scripted trajectory, exact zero-order-hold integration); the lateral axes x
and z follow the trajectory kinematically (the finger slides the stylus; z is 0 unless
the trajectory is 3-D, e.g. :func:`hapticsdk.sim.finger.walk_over` across the objects of
a spatial scene). The force acts along y only. Each
:meth:`step` applies the force the safety layer says is current (so a stale command
becomes zero once the safety layer implements staleness).

The device carries both published stiffness figures with their sources (2.3 N/mm used
by the paper; 0.7 N/mm rated by CHAI3D for stable rendering) and reports the passivity
margin of a wall (:meth:`OmniVirtual.passivity`): with the default damping a 2.3 N/mm
wall at 1 kHz is ``"stable-by-assumption (not passive)"``.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

from hapticsdk.argcheck import number
from hapticsdk.devices.actuators import ActuatorLimits, DeviceState, HapticDevice, SensedState
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import ValidationError
from hapticsdk.passivity import classify_wall, critical_stiffness
from hapticsdk.sim.arm import OMNI_SOURCES, ArmParams, ArmSim
from hapticsdk.sim.finger import FingerParams, Trajectory, finger, press_slide


class OmniVirtual(HapticDevice):
    """Simulated Omni (entry point ``omni-virtual``).

    Args:
        trajectory: finger reference path (default press 2 mm, slide at 80 mm/s, release).
        finger: finger impedance preset name (``"soft"``, ``"medium"``, ``"stiff"``) or
            :class:`~hapticsdk.sim.finger.FingerParams`.
        arm: :class:`~hapticsdk.sim.arm.ArmParams` (mass, damping, force limit, encoder).
        damping_ns_per_m, mass_kg, encoder_resolution_mm: shortcuts overriding ``arm``.
        y0_mm: initial stylus height (mm); default the trajectory's start.
        velocity_filter_hz: first-order low-pass on the backward-difference velocity
            (Hz); None: raw backward difference.
        label, safety: as for every actuator.
    """

    name: ClassVar[str] = "omni-virtual"
    channel: ClassVar[str] = "force"
    accepts: ClassVar[dict[str, str]] = {"force_n": "N"}
    simulated: ClassVar[bool] = True
    #: one physical axis: a force along a contact normal is rendered as its projection on y
    force_axes: ClassVar[tuple[int, ...]] = (1,)
    limits = ActuatorLimits(max_force_n=3.3, max_stiffness_n_per_mm=2.3)
    sources: ClassVar[dict[str, str]] = OMNI_SOURCES

    def __init__(self, *, trajectory: Trajectory | None = None, finger: "str | FingerParams" = "medium",
                 arm: ArmParams | None = None, damping_ns_per_m: float | None = None,
                 mass_kg: float | None = None, encoder_resolution_mm: float | None = None,
                 y0_mm: float | None = None, velocity_filter_hz: float | None = None,
                 label: str | None = None, safety: Any = None, **options: Any) -> None:
        super().__init__(label=label, safety=safety, **options)
        if trajectory is not None and not isinstance(trajectory, Trajectory):
            raise ValidationError("trajectory must be a hapticsdk.sim.finger.Trajectory", field="trajectory")
        if arm is not None and not isinstance(arm, ArmParams):  # e.g. a dict from a scene file
            raise ValidationError(f"arm must be a hapticsdk.sim.arm.ArmParams built in code, got "
                                  f"{type(arm).__name__}; a scene may give damping_ns_per_m, mass_kg, "
                                  f"encoder_resolution_mm", field="arm")
        arm = arm or ArmParams()
        over = {k: v for k, v in (("damping_ns_per_m", damping_ns_per_m), ("mass_kg", mass_kg),
                                  ("encoder_resolution_mm", encoder_resolution_mm)) if v is not None}
        self.arm = arm.with_(**over) if over else arm
        self.finger = _finger(finger)
        self.trajectory = trajectory or press_slide()
        if velocity_filter_hz is not None:
            number(velocity_filter_hz, "velocity_filter_hz", lo=0.0, lo_open=True)
        self.velocity_filter_hz = velocity_filter_hz
        if y0_mm is not None:
            number(y0_mm, "y0_mm")
        self._y0 = y0_mm
        self._reset()

    def _reset(self) -> None:
        x, y, _, _ = self.trajectory.at(0.0)
        y0 = y if self._y0 is None else float(self._y0)
        self.sim = ArmSim(self.arm, self.finger, 0.001, y0)
        self.t = 0.0
        self._y_meas = self.sim.measured_mm()
        self._v_est = 0.0
        self._f_applied = 0.0
        self._ref: tuple = (None, None, None)  # (trajectory, t, trajectory.at(t)) of the last lookup
        #: work done by the motor force on the stylus (J), exact under the hold
        self.motor_work_j = 0.0
        #: energy the arm's own damping dissipated (J; trapezoid of b v^2 over each step)
        self.damper_j = 0.0

    # -- actuator backend ------------------------------------------------
    def _open(self) -> None:
        self._reset()
        self._f_set = 0.0

    def _command(self, cmd: ChannelCommand) -> None:
        """The command is kept by the safety layer; :meth:`step` applies it. The motor
        set-point it gives (saturated by the arm's own force limit) is kept for
        :meth:`read_back`."""
        f = 0.0 if cmd.force_n is None else cmd.force_n * (1.0 if cmd.direction is None else cmd.direction[1])
        fmax = self.arm.max_force_n
        # max(-fmax, min(fmax, f)) without the two calls (same result, NaN included: fmax)
        if not f <= fmax:
            f = fmax
        elif f < -fmax:
            f = -fmax
        self._f_set = f

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("force", force_n=self._f_set)

    def _stop(self) -> None:
        self._f_applied = 0.0
        self._f_set = 0.0

    def _at(self, t: float) -> tuple[float, float, float, float]:
        """``trajectory.at(t)``, reusing the last lookup: a tick reads, then steps from,
        the time the previous step ended at."""
        traj, t_ref, ref = self._ref
        if t_ref == t and traj is self.trajectory:
            return ref
        ref = self.trajectory.at(t)
        self._ref = (self.trajectory, t, ref)
        return ref

    def _read_state(self) -> DeviceState:
        t = self.t
        x, _, vx, _ = self._at(t)
        z, vz = self.trajectory.z_at(t)  # (0, 0) for a 2-D trajectory
        # plain floats, read every servo tick (arrays are built only when a caller asks)
        return SensedState.of(t, x, self._y_meas, z, vx, self._v_est, vz, 0.0, self._f_applied, 0.0)

    def _force_at(self, now: float) -> float:
        """Force along the simulated axis y (N): the command's force projected on y when
        it carries a ``direction`` (the contact normal of a spatial scene; this
        simulation has one physical axis, so the lateral part of a slanted normal is not
        rendered)."""
        cmd = self.safety.current(now) if self.is_open else None
        if cmd is None or cmd.force_n is None:
            return 0.0
        d = cmd.direction
        return cmd.force_n if d is None else cmd.force_n * d[1]

    def _advance(self, dt: float, f: float) -> None:
        _, r0, _, _ = self._at(self.t)
        _, r1, _, _ = self._at(self.t + dt)
        y_old, v_old = self.sim.y, self.sim.v
        self._f_applied = self.sim.step(dt, f, r0, (r1 - r0) / dt)
        self.motor_work_j += self._f_applied * (self.sim.y - y_old)
        v = self.sim.v
        self.damper_j += self.arm.damping_ns_per_m * 0.5 * (v_old * v_old + v * v) * dt
        self.t += dt

    def energy_to_user_j(self) -> float:
        """Energy the arm + wall have given the finger so far (J): motor work minus the
        arm's kinetic energy minus what its damping dissipated (as
        :meth:`hapticsdk.sim.arm.ArmBatch.energy_to_user_j`; <= 0 for a passive display)."""
        v = self.sim.v
        return self.motor_work_j - 0.5 * self.arm.mass_kg * v * v - self.damper_j

    def _step(self, dt: float) -> None:
        """Hold the current command (sent at the start of the interval) while the safety
        layer considers it fresh, then zero: a late tick leaves the arm unpowered for the
        overdue part of the interval, as a device servo thread with staleness would."""
        t0 = self.t
        f = self._force_at(t0)
        if f != 0.0 and dt > 0 and self._force_at(t0 + dt) == 0.0:
            fresh = getattr(getattr(self.safety, "settings", None), "stale_after_s", dt)
            fresh = min(max(fresh, 0.0), dt)
            if fresh > 0:
                self._advance(fresh, f)
            if dt - fresh > 1e-12:
                self._advance(dt - fresh, 0.0)
            self.t = t0 + dt
        else:
            self._advance(dt, f)
        y_meas = self.sim.measured_mm()
        v_raw = (y_meas - self._y_meas) / dt
        if self.velocity_filter_hz is None:
            self._v_est = v_raw
        else:
            a = 1.0 - math.exp(-2.0 * math.pi * self.velocity_filter_hz * dt)
            self._v_est += a * (v_raw - self._v_est)
        self._y_meas = y_meas

    # -- reporting ---------------------------------------------------------
    @property
    def apparent_mass_kg(self) -> float:
        """Apparent mass of the stylus (kg), used by the passivity controller."""
        return self.arm.mass_kg

    @property
    def damping_ns_per_m(self) -> float:
        """Physical viscous damping of the arm (N*s/m), credited by the passivity observer."""
        return self.arm.damping_ns_per_m

    @property
    def serial_number(self) -> str:
        """The simulated arm's serial number: its physics (mass, damping, force limit,
        encoder), so a damping calibration saved for it (``hapticsdk calibrate damping
        --device omni-virtual --device-option finger=none --save``) is credited on every
        simulated arm with the same physics and on no other (one with another damping
        is another arm). The finger is the user, not the arm, and is not part of it."""
        a = self.arm
        return (f"sim-omni-{a.mass_kg:.6g}kg-{a.damping_ns_per_m:.6g}Nsm-{a.max_force_n:.6g}N-"
                f"{a.encoder_resolution_mm:.6g}mm")

    @property
    def encoder_resolution_mm(self) -> float:
        """Position quantum of the encoder (mm)."""
        return self.arm.encoder_resolution_mm

    @property
    def true_position_mm(self) -> float:
        """Unquantised stylus height (mm)."""
        return self.sim.y * 1e3

    def passivity(self, stiffness_n_per_mm: float | None = None, *, period_s: float = 0.001,
                  delay_ticks: int = 0, virtual_damping_ns_per_m: float = 0.0) -> dict[str, Any]:
        """Colgate margin and label of a wall on this device (default K = 2.3 N/mm).

        ``critical_stiffness_mass_corrected_n_per_mm`` (N/mm) is the ZOH eigenvalue
        stability limit of the free arm with its apparent mass (``critical_stiffness(...,
        mass_kg=arm.mass_kg)``); it is a stability figure, not a passivity one, and does
        not change the label.
        """
        K = self.limits.max_stiffness_n_per_mm if stiffness_n_per_mm is None else stiffness_n_per_mm
        out = classify_wall(K, self.arm.damping_ns_per_m,  # type: ignore[arg-type]  # the Omni declares K
                            period_s, delay_ticks, virtual_damping_ns_per_m)
        out["critical_stiffness_mass_corrected_n_per_mm"] = critical_stiffness(
            self.arm.damping_ns_per_m, period_s, delay_ticks, virtual_damping_ns_per_m, mass_kg=self.arm.mass_kg)
        out["source_damping"] = OMNI_SOURCES["damping_ns_per_m"]
        return out

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d["arm"] = {k: getattr(self.arm, k) for k in ("mass_kg", "damping_ns_per_m", "max_force_n",
                                                       "encoder_resolution_mm", "max_stiffness_n_per_mm",
                                                       "rated_stable_stiffness_n_per_mm")}
        d["sources"] = dict(OMNI_SOURCES)
        d["passivity_at_paper_stiffness"] = self.passivity(self.arm.max_stiffness_n_per_mm)
        d["passivity_at_chai3d_stiffness"] = self.passivity(self.arm.rated_stable_stiffness_n_per_mm)
        return d


def _finger(spec: "str | FingerParams") -> FingerParams:
    return finger(spec)
