"""Goal 4 end to end: the hardness renderer at GS_max = 2.3 N/mm (2.3 x 2b/T on the
simulated Omni's default b = 0.5 N*s/m at 1 kHz, 0.055 mm encoder) pressed and held
through the servo loop with its default passivity controller: no energy to the finger,
the stylus settles, the wall is rendered; with the controller off the same press is
active (so the test can fail)."""

import numpy as np
import pytest

from hapticsdk.runtime import ServoLoop
from hapticsdk.sim.finger import Trajectory
from hapticsdk_hardness.dimension import HardnessDimension
from hapticsdk_hardness.omni import OmniVirtual
from hapticsdk_hardness.voicecoil import VoiceCoilVirtual


class _RecordingOmni(OmniVirtual):
    """The simulated Omni, recording the exact state after every interval of the hold."""

    def _reset(self) -> None:
        super()._reset()
        self.hist: list[tuple[float, float, float, float]] = []

    def _advance(self, dt: float, f: float) -> None:
        super()._advance(dt, f)
        self.hist.append((self.t, self.sim.y, self.sim.v, self.motor_work_j))


def _press_and_hold(passivity: bool | None, finger: str, gs: float = 2.3, dur: float = 4.0):
    """Returns (upper bound of the energy given to the finger (J), position std over the
    last 0.5 s (mm), mean wall force over the last 0.5 s (N), mean penetration (mm))."""
    tr = Trajectory([(0, 0, 2.0), (0.3, 0, 2.0), (0.8, 0, -3.0), (dur, 0, -3.0)])
    dev = _RecordingOmni(trajectory=tr, finger=finger)
    r = HardnessDimension().renderer({"GS": gs})
    kw = {} if passivity is None else {"passivity": passivity}   # None: the loop's default
    rep = ServoLoop(dev, [r], {"force": dev, "coil": VoiceCoilVirtual()}, **kw).run(dur)
    t, y, v, w = np.array(dev.hist).T
    # energy to the finger = motor work - kinetic energy - arm damping's dissipation; the
    # dissipation is at least b dy^2 / dt per interval, so this is an upper bound
    diss = np.concatenate([[0.0], np.cumsum(dev.damping_ns_per_m * np.diff(y) ** 2 / np.diff(t))])
    e_user = w - 0.5 * dev.apparent_mass_kg * v ** 2 - diss
    tail = t > dur - 0.5
    L = rep.log
    ltail = L["t"] > dur - 0.5
    return (float(e_user.max()), float((y[tail] * 1e3).std()), float(L["force_n"][ltail].mean()),
            float(L["penetration_mm"][ltail].mean()))


@pytest.mark.parametrize("finger", ["soft", "medium", "stiff"])
def test_wall_at_gs_max_is_passive_and_settles_through_the_loop(finger):
    e, sd, f, pen = _press_and_hold(True, finger)
    assert e <= 1e-6
    assert sd < 0.05
    assert f == pytest.approx(2.3 * pen, rel=0.1)


@pytest.mark.parametrize("finger", ["soft", "medium"])
def test_same_wall_without_the_controller_is_active(finger):
    e, sd, _, _ = _press_and_hold(False, finger)
    assert e > 1e-4 and sd > 0.1


def test_the_servo_loops_default_is_the_passive_controller():
    """Without a passivity argument the loop renders the same wall passively."""
    e, sd, _, _ = _press_and_hold(None, "medium", dur=2.0)
    assert e <= 1e-6 and sd < 0.05


def test_scenes_render_with_the_passivity_controller_by_default():
    from hapticsdk.compiler import compile_scene
    from hapticsdk.runtime.render import render_plan
    from hapticsdk.scene import Scene

    plan = compile_scene(Scene.for_material({"hardness": 0.9}))
    rep = render_plan(plan, seconds=1.0)
    # the controller ran on the force role: it books the energy flow of every tick
    pas = rep.loop.passivity
    assert "force" in pas and pas["force"]["active_ticks"] >= 0
    assert rep.loop.ticks == 1000


def test_energy_to_user_matches_the_exact_batch_arm():
    """``OmniVirtual.energy_to_user_j`` (motor work - kinetic energy - the arm damper's
    loss by the trapezoid of b v^2 per step) against ``ArmBatch.energy_to_user_j`` (the
    damper's loss exact, from the step's dissipation Gramian) on the same arm, finger and
    reference motion, nothing commanded (the finger moves the stylus). Over a 1 ms step
    the finger-arm mode (~20 Hz) changes v^2 smoothly: the trapezoid's relative error is
    about (w T)^2 / 12 ~ 1e-4, so the two agree within 1 % of the damper's loss, which is
    itself a large part of the total."""
    from hapticsdk.sim.arm import ArmBatch
    tr = Trajectory([(0, 0, 2.0), (0.2, 0, -1.0), (0.5, 0, 3.0), (0.8, 0, -2.0), (1.0, 0, 1.0)])
    dev = OmniVirtual(trajectory=tr, finger="stiff")
    T = 1e-3
    with dev:
        ref = ArmBatch(T, [dev.arm], [dev.finger], dev.sim.y * 1e3, track_energy=True)
        for k in range(1000):
            r0, r1 = tr.at(k * T)[1], tr.at((k + 1) * T)[1]
            dev.step(T)
            ref.step(np.zeros(1), np.array([r0]), np.array([(r1 - r0) / T]))
        assert abs(dev.sim.y - ref.y[0]) < 1e-12   # the same motion
        exact = float(ref.energy_to_user_j()[0])
        damper = float(ref.damper_j[0])
        assert damper > 1e-4 and exact < 0          # the damper's loss matters here
        assert abs(dev.energy_to_user_j() - exact) <= 0.01 * damper
