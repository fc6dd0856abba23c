"""Energy book of an arm nobody holds (finger of no mass, spring or damper), pushed by a
constant force below its limit: every joule the motor puts in is either the arm's kinetic
energy or heat in its damper, so the energy given to the finger is 0. With no damping,
the motion is the textbook constant acceleration a = F/m: y = F t^2 / 2m, v = F t / m,
motor work F y = 1/2 m v^2 (independent closed form, not the simulator's matrices)."""

import numpy as np
import pytest

from hapticsdk.sim.arm import ArmBatch, ArmParams
from hapticsdk.sim.finger import FingerParams
from hapticsdk.sim.plant import PlantBatch

NOBODY = FingerParams(0.0, 0.0, 0.0)
T, STEPS, F = 1e-3, 200, 0.3  # 0.3 N is below the 3.3 N limit: no saturation


def _runs(arm):
    """(motor work, damper heat, kinetic energy, energy to the finger) of ArmBatch and
    PlantBatch after STEPS periods of the constant force, from rest at 0."""
    batch = ArmBatch(T, [arm], [NOBODY], track_energy=True)
    plant = PlantBatch([T], [arm], [NOBODY], 0.0)
    for _ in range(STEPS):
        for sim in (batch, plant):
            sim.step(np.array([F]), np.zeros(1), np.zeros(1))
    return [(s.motor_work_j[0], s.damper_j[0], 0.5 * arm.mass_kg * s.v[0] ** 2, s.energy_to_user_j()[0])
            for s in (batch, plant)]


def test_undamped_free_arm_matches_constant_acceleration_and_gives_the_finger_nothing():
    arm = ArmParams(damping_ns_per_m=0.0, encoder_resolution_mm=0.0)
    t = STEPS * T
    v = F * t / arm.mass_kg
    for work, heat, ke, to_finger in _runs(arm):
        # exact ZOH of a double integrator: only float rounding (rel 1e-9 is generous)
        assert work == pytest.approx(0.5 * arm.mass_kg * v ** 2, rel=1e-9)
        assert heat == 0.0
        assert to_finger == pytest.approx(0.0, abs=1e-9 * work)


def test_damped_free_arm_splits_the_motor_work_into_kinetic_energy_and_heat():
    arm = ArmParams(damping_ns_per_m=2.0, encoder_resolution_mm=0.0)
    for work, heat, ke, to_finger in _runs(arm):
        assert heat > 0.01 * work  # b T_total / m ~ 9: the damper takes a real share
        # conservation: work = KE + heat, to rounding of a few hundred exact steps
        assert to_finger == pytest.approx(0.0, abs=1e-9 * work)
