"""The stiff-wall controller when the hand outruns its plan: the book overdrawn, and the
extra falls below its ramp (docs/runtime.md, Passivity item 3, "When the book is
overdrawn").

The plan prices "hold the force one tick, then ramp to 0" on the motion the readings show.
A hand that yanks the stylus out of a press within one tick (its finger pulled away at
metres a second) outruns any causal prediction: the force held over that tick is paid in
full, and the book ``U`` can pass the allowance ``E0``. Ramping down at ``s`` a tick from
there hands the user the ramp's whole tail as the stylus flies out (``v tau F^2 /
(2 F_max)``). So once ``U > E0`` and even the ramp's lower end does not fit the plan, the
extra falls to the largest force the plan affords (or the one of least cost): a step
beyond the ramp, taken for the energy bound, and counted (``below_ramp_ticks``).

The worked case was found by a randomised run outside the benchmark's trajectories (the
hand's reference jumping 7 mm within one tick, held by a stiff, well-damped finger; drawn
parameters rounded to 4 digits): 1.32 mJ to the finger with the ramp kept, 0.035 mJ with
the fall. It runs through the independent simulator of ``tests/independent_plant.py``
(exact zero-order hold, its own energy sums), with the servo's scalar controller and the
benchmark's vectorised one. Simulated: generated data.
"""

from __future__ import annotations

import numpy as np
import pytest

import independent_plant as ip
from hapticsdk.passivity import (ControllerSettings, PassivityController, controller_commit_batch,
                                 controller_state_batch, controller_step_batch)

hyp = pytest.importorskip("hypothesis", reason="hypothesis (the test extra) is not installed")
from hypothesis import given, settings as hsettings, strategies as st  # noqa: E402

ENERGY_J = 1e-4   # the bound on the energy to the user

#: a press the hand's reference jumps into and out of, 5 times (2 mm above, 5.245 mm in);
#: no damping on the arm, a 0.036 mm encoder, 1.228 ms ticks
YANK = {"stiffness_n_per_mm": 207.4, "period_s": 0.001228, "resolution_mm": 0.03597, "arm_mass_kg": 0.07897,
        "arm_mass_declared_kg": 0.07174, "damping_true_ns_per_m": 0.0, "finger_mass_kg": 0.01626,
        "finger_stiffness_n_per_m": 793.8, "finger_damping_ns_per_m": 4.842, "depth_mm": 5.245,
        "slams": 5, "slam_hold": 0.1382}


def _reference(c: dict):
    per = 2 * c["slam_hold"]

    def r(t: float) -> float:
        j = int(t // per)
        if j >= c["slams"]:
            return 2.0
        return 2.0 if (t - j * per) < c["slam_hold"] else -c["depth_mm"]
    return r, c["slams"] * per + 0.3


def _settings(c: dict) -> ControllerSettings:
    # no damping measured or credited: the whole wall is the energy-bounded extra
    return ControllerSettings(position_resolution_mm=c["resolution_mm"], max_force_n=ip.FORCE_LIMIT_N,
                              device_mass_kg=c["arm_mass_declared_kg"], device_damping_ns_per_m=0.0,
                              period_s=c["period_s"])


def _run(c: dict, batch: bool) -> dict:
    ref, dur = _reference(c)
    T = c["period_s"]
    cs = _settings(c)
    ctl = PassivityController(cs)
    stt = controller_state_batch(1)
    below = [0]

    def send(x: float, fw: float) -> float:
        if not batch:
            return ctl.step(x, T, fw)
        f = float(controller_step_batch(stt, np.array([x]), T, np.array([fw]), True, cs)[0])
        below[0] += int(stt["below_ramp"][0])
        return f

    def commit(f: float) -> None:
        if batch:
            controller_commit_batch(stt, np.array([f]))
        else:
            ctl.commit(f)
    out = ip.drive(c, ref, dur, send, commit)
    out["below_ramp_ticks"] = below[0] if batch else ctl.report()["below_ramp_ticks"]
    return out


@pytest.mark.parametrize("batch", [False, True], ids=["scalar", "batch"])
def test_a_hand_that_yanks_the_stylus_out_of_a_press_gets_no_ramp_the_book_cannot_afford(batch):
    r = _run(YANK, batch)
    assert r["below_ramp_ticks"] > 0, r       # the case reaches the rule
    assert r["energy_to_user_j"] <= ENERGY_J, r
    assert r["min_contact_force_n"] >= 0.0, r


@hsettings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(res=st.floats(0.001, 0.2), T=st.floats(2.5e-4, 1e-2), seed=st.integers(0, 2**31 - 1),
       fmax=st.sampled_from((3.3, 1.0)), mass=st.sampled_from((None, 0.02, 0.05)), batch=st.booleans())
def test_the_extra_falls_below_its_ramp_only_with_the_book_overdrawn(res, T, seed, fmax, mass, batch):
    """On any motion (here: random presses with jumps of up to 10 counts a tick), a tick on
    which the extra falls below its ramp is one on which the book is over its allowance
    (``U > E0`` after the tick's booking); on every other tick the force falls by at most one
    ramp step (no damping credited: no spring). The scalar controller and the batch each
    (their agreement is ``test_scalar_controller_equals_batch``'s)."""
    cs = ControllerSettings(position_resolution_mm=res, max_force_n=fmax, device_mass_kg=mass,
                            device_damping_ns_per_m=0.0, period_s=T)
    e0 = cs.energy_budget_j(T)
    s = fmax * min(T / cs.ramp_time_s, 1.0)
    rng = np.random.default_rng(seed)
    moves = rng.choice([-10, -3, -1, 0, 1, 3, 10], size=300, p=[0.05, 0.1, 0.25, 0.2, 0.25, 0.1, 0.05])
    xs = res * np.minimum(np.cumsum(moves) - 5, 5)
    pc = PassivityController(cs)
    bs = controller_state_batch(1)
    last = 0.0
    count = 0
    for x in xs:
        fw = 1e3 * max(-x, 0.0)
        if batch:
            a = float(controller_step_batch(bs, np.array([x]), T, np.array([fw]), True, cs)[0])
            dropped, u = bool(bs["below_ramp"][0]), float(bs["energy"][0])
        else:
            before = pc.below_ramp_ticks
            a = pc.step(float(x), T, fw)
            dropped, u = pc.below_ramp_ticks > before, pc.energy_j
        if dropped:
            count += 1
            assert u > e0
        else:
            assert last - a <= s * (1 + 1e-9) + 1e-12
        assert a >= 0.0
        if batch:
            controller_commit_batch(bs, np.array([a]))
        else:
            pc.commit(a)
        last = a
    if not batch:
        assert pc.report()["below_ramp_ticks"] == count
