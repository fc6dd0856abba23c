"""End to end through the servo loop (issue 23): the hardness renderer at GS_max and the
extreme cases (raw 50 N/mm and GS = 50 at 1-10 ms, b = 0 / 0.25 / 0.5, a 0.5 m/s impact
at 4 ms) with the default passivity controller: energy to the finger within the
controller's allowance (plus the issue's 0.1 mJ for the extreme cases), no pull, steps
within the ramp; with the controller off the GS_max press is active (so the test can
fail)."""

import numpy as np
import pytest

from hapticsdk.perception.dimensions import DimensionRenderer
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


class _RawWall(DimensionRenderer):
    """A raw spring ``K x penetration`` on the force role (no split by formula (8))."""

    roles = ("force",)

    def __init__(self, k: float) -> None:
        self.k = k

    def tick(self, inp):
        from hapticsdk.devices.actuators import ChannelCommand
        return [ChannelCommand("force", self.k * inp.penetration_mm if inp.in_contact else 0.0)]


def _press_and_hold(passivity, finger, gs=2.3, dur=4.0, *, period=1e-3, b=None, raw=None, tr=None):
    """Returns (upper bound of the energy given to the finger (J), position std over the
    last 0.5 s (mm), mean wall force over the last 0.5 s (N), mean penetration (mm), the
    loop's log, the device)."""
    tr = tr or Trajectory([(0, 0, 2.0), (0.3, 0, 2.0), (0.8, 0, -3.0), (dur, 0, -3.0)])
    dev = _RecordingOmni(trajectory=tr, finger=finger, **({} if b is None else {"damping_ns_per_m": b}))
    r = _RawWall(raw) if raw is not None else HardnessDimension().renderer({"GS": gs})
    kw = {} if passivity is None else {"passivity": passivity}   # None: the loop's default
    rep = ServoLoop(dev, [r], {"force": dev, "coil": VoiceCoilVirtual()}, period_s=period, **kw).run(dur)
    t, y, v, w = np.array(dev.hist).T
    # energy to the finger = motor work - kinetic energy - arm damping's dissipation; the
    # dissipation is at least b dy^2 / dt per interval, so this is an upper bound
    diss = np.concatenate([[0.0], np.cumsum(dev.damping_ns_per_m * np.diff(y) ** 2 / np.diff(t))])
    e_user = w - 0.5 * dev.apparent_mass_kg * v ** 2 - diss
    tail = t > dur - 0.5
    L = rep.log
    ltail = L["t"] > dur - 0.5
    return (float(e_user.max()), float((y[tail] * 1e3).std()), float(L["force_n"][ltail].mean()),
            float(L["penetration_mm"][ltail].mean()), L, dev)


def _allowance(dev, period):
    """E0 = F_max Delta / 2 (docs/runtime.md, Passivity item 6) from the device's declaration."""
    return 3.3 * 0.5 * dev.encoder_resolution_mm * 1e-3


def _no_pull_and_ramp(L, period, dev):
    """No pull on a contact tick; each step within the extra's ramp (3.3 N x T / 5 ms)
    plus the Colgate spring's own change, K_c |d pen| with K_c = 2 (b_decl / 2) / T."""
    f = L["force_n"]
    contact = L["penetration_mm"] > 0
    assert f[contact].min() >= 0.0
    kc = 2.0 * 0.5 * dev.damping_ns_per_m / period
    allowed = 3.3 * min(period / 5e-3, 1.0) + kc * np.abs(np.diff(L["penetration_mm"])) * 1e-3
    assert (np.abs(np.diff(f)) <= allowed * (1 + 1e-9)).all()


@pytest.mark.parametrize("finger", ["soft", "medium", "stiff"])
def test_wall_at_gs_max_is_passive_through_the_loop(finger):
    """GS_max (2.3 x 2b/T): energy within the controller's allowance, no pull, steps
    within the ramp."""
    e, _, f, pen, L, dev = _press_and_hold(True, finger)
    assert e <= _allowance(dev, 1e-3)
    _no_pull_and_ramp(L, 1e-3, dev)


@pytest.mark.parametrize("finger", ["soft", "medium"])
def test_same_wall_without_the_controller_is_active(finger):
    e, sd, _, _, _, _ = _press_and_hold(False, finger)
    assert e > 1e-4 and sd > 0.1


def test_the_servo_loops_default_is_the_passive_controller():
    """Without a passivity argument the loop renders the same wall with the controller."""
    e, _, _, _, L, dev = _press_and_hold(None, "medium", dur=2.0)
    assert e <= _allowance(dev, 1e-3)
    _no_pull_and_ramp(L, 1e-3, dev)


#: issue 23 (5): the extreme cases through the real servo loop. Energy to the finger must
#: stay within the controller's allowance plus the issue's 0.1 mJ goal (the room for hand
#: motion the one-tick prediction does not foresee), the wall never pulls and its steps
#: stay within the ramp. The energy and the delivered force are printed (pytest -s).
EXTREME = ([("raw", 50.0, T, b) for T in (1e-3, 4e-3, 10e-3) for b in (0.0, 0.25, 0.5)]
           + [("GS", 50.0, T, b) for T in (1e-3, 4e-3, 10e-3) for b in (0.0, 0.25, 0.5)])


def _delivered(L, k):
    pen = L["penetration_mm"]
    c = pen > 0
    want = np.minimum(k * pen[c], 3.3)
    return float(np.minimum(np.maximum(L["force_n"][c], 0.0), want).sum() / max(want.sum(), 1e-12))


@pytest.mark.parametrize("kind, k, period, b", EXTREME)
def test_extreme_press_through_the_loop(kind, k, period, b):
    e, _, _, _, L, dev = _press_and_hold(True, "medium", dur=2.0, period=period, b=b,
                                         raw=k if kind == "raw" else None, gs=k)
    off, _, _, _, _, _ = _press_and_hold(False, "medium", dur=2.0, period=period, b=b,
                                         raw=k if kind == "raw" else None, gs=k)
    print(f"{kind} {k:g} N/mm T={period * 1e3:g} ms b={b:g}: energy {e * 1e3:.4f} mJ (off {off * 1e3:.3f}), "
          f"delivered {_delivered(L, 2.3 if kind == 'GS' else k):.3f}")
    assert e <= _allowance(dev, period) + 1e-4
    _no_pull_and_ramp(L, period, dev)


def test_impact_at_half_a_metre_per_second_through_the_loop():
    """0.5 m/s impacts at T = 4 ms on a raw 50 N/mm wall (b = 0)."""
    tr = Trajectory([(0, 0, 2.0), (0.1, 0, 2.0), (0.112, 0, -4.0), (0.4, 0, -4.0), (0.412, 0, 2.0), (1.0, 0, 2.0)])
    e, _, _, _, L, dev = _press_and_hold(True, "stiff", dur=1.0, period=4e-3, b=0.0, raw=50.0, tr=tr)
    print(f"impact 0.5 m/s, 4 ms: energy {e * 1e3:.4f} mJ, delivered {_delivered(L, 50.0):.3f}")
    assert e <= _allowance(dev, 4e-3) + 1e-4
    _no_pull_and_ramp(L, 4e-3, dev)


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
