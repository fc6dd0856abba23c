"""Issue 23: the stiff-wall controller through the servo loop, in motions and events the
stability benchmark does not draw: in a spatial scene, where the hand moves from one object
to another and the contact normal turns while pressed; and ticks without a position in the
middle of a press (below, "ticks without a position").

Two classes found by driving motions the stability benchmark does not draw (its plant is a
plane): a hand sliding at depth across two abutting boxes, and a hand tapping them in turn,
on the simulated Omni (45 g, 0.055 mm encoder, 3.3 N; generated data). What each must show
is the issue's bound: the energy the arm gave the finger (``OmniVirtual.energy_to_user_j``,
its largest over the run) within 0.1 mJ. The damping is the loop's default (declared, none
credited: no Colgate spring), so the whole force is the energy-bounded extra and the bound
is the controller's alone (with a measured damping, a press made inside the safety layer's
start ramp showed on one object as on two: docs/runtime.md, Passivity item 0, "A spring the
device did not apply", and the tests at the end of this file).

* **A force rendered along one axis.** The simulated Omni renders a force along a contact
  normal as its projection on y. Near the side face of a box (and wherever the normal is
  slanted) the distance to the surface changes with the hand's lateral motion, on which
  that device does no work: booked as the distance's change, a slide into the side face
  earned credit that the force then spent along y when the normal turned back. Before the
  loop booked the motion along the device's ``force_axes``: 147 of 200 drawn slides over
  0.1 mJ, up to 90 mJ (docs/runtime.md, Passivity, "A force rendered along one axis").
* **A bound per run, not per object.** The loop restarts the controller on another object;
  the restart forgave the debt, so a hand tapping two objects in turn got one allowance per
  tap: 15 of 200 drawn tap runs over 0.1 mJ, up to 0.61 mJ. The restart now keeps a debt.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hapticsdk.devices.actuators import SensedState
from hapticsdk.passivity import ControllerSettings, PassivityController
from hapticsdk.runtime import ServoLoop
from hapticsdk.scene.geometry import Box, HitTester, Pose, Sphere
from hapticsdk.sim.finger import Trajectory, press_slide
from omni_fits import measured
from renderers import Spring, largest_energy

ENERGY_J = 1e-4          # the bound on the energy to the user


def slide(depth: float, crossings: int, speed_mm_s: float, press_s: float, dwell_s: float) -> Trajectory:
    """Press 10 mm left of the seam between the boxes, slide across it and back at depth."""
    pts, t, x = [(0.0, -10.0, 1.0)], press_s, -10.0
    pts.append((t, x, -depth))
    for _ in range(crossings):
        x = -x
        t += 20.0 / speed_mm_s
        pts.append((t, x, -depth))
        t += dwell_s
        pts.append((t, x, -depth))
    t += press_s
    pts += [(t, x, 1.0), (t + 0.1, x, 1.0)]
    return Trajectory(pts)


def taps(depth: float, n: int, in_s: float, hold_s: float, out_s: float) -> Trajectory:
    """Tap the two boxes in turn, each 10 mm from the seam."""
    pts, t, x = [(0.0, -10.0, 1.0)], 0.0, -10.0
    for _ in range(n):
        t += in_s
        pts.append((t, x, -depth))
        t += hold_s
        pts.append((t, x, -depth))
        t += out_s
        pts.append((t, x, 1.0))
        x = -x
        t += 0.05
        pts.append((t, x, 1.0))
    return Trajectory(pts + [(t + 0.1, x, 1.0)])


def over_a_ball(radius: float, depth: float, half_width: float, passes: int, speed_mm_s: float) -> Trajectory:
    """Slide back and forth over the top of a ball of ``radius`` (its top at y = 0),
    ``depth`` below its surface, ``half_width`` either side of the top."""
    xs = np.linspace(-half_width, half_width, 25)

    def y(x: float) -> float:
        return float(np.sqrt(radius * radius - x * x) - radius - depth)

    t = 0.1
    pts = [(0.0, -half_width, y(-half_width) + depth + 1.0), (t, -half_width, y(-half_width))]
    for i in range(passes):
        for x in (xs[1:] if i % 2 == 0 else xs[-2::-1]):
            t += (xs[1] - xs[0]) / speed_mm_s
            pts.append((t, float(x), y(x)))
    x = float(xs[-1] if passes % 2 else xs[0])
    return Trajectory(pts + [(t + 0.1, x, y(x) + depth + 1.0), (t + 0.2, x, y(x) + depth + 1.0)])


def run(trajectory: Trajectory, k: float, period_s: float, damping: float, finger: str, two: bool = True,
        ball: float = 0.0) -> float:
    """The largest energy to the finger (J) over the run, through ``ServoLoop`` with the
    loop's default controller; two abutting boxes (or one as wide as both), or a ball of
    radius ``ball`` (mm) with its top at y = 0."""
    from hapticsdk_hardness.omni import OmniVirtual

    dev = OmniVirtual(trajectory=trajectory, finger=finger, damping_ns_per_m=damping)
    if ball:
        objs = [("ball", [Spring(k)])]
        ht = HitTester([("ball", Sphere(ball, pose=Pose((0.0, -ball, 0.0))))])
    elif two:
        objs = [("A", [Spring(k)]), ("B", [Spring(k)])]
        ht = HitTester([("A", Box((10.0, 10.0, 10.0), pose=Pose((-10.0, -10.0, 0.0)))),
                        ("B", Box((10.0, 10.0, 10.0), pose=Pose((10.0, -10.0, 0.0))))])
    else:
        objs = [("A", [Spring(k)])]
        ht = HitTester([("A", Box((20.0, 10.0, 10.0), pose=Pose((0.0, -10.0, 0.0))))])
    loop = ServoLoop(dev, (), {"force": dev}, period_s=period_s, passivity=True, objects=objs, hit_tester=ht)
    return largest_energy(loop, dev, trajectory.duration_s)


def test_a_slide_across_two_boxes_at_depth_stays_within_the_bound():
    """A 3.6 N/mm wall at 0.5 ms, no damping, four crossings of the seam at 1.2 mm: 5.4 mJ
    with neither rule of this file (the side face of the box the hand slides onto turns the
    normal to x, on which the simulated Omni renders nothing, and the restart forgave the
    debt); 0.015 mJ with both (and with the restart's rule alone: the axis rule is guarded
    by the ball below and the property)."""
    tr = slide(depth=1.2, crossings=4, speed_mm_s=180.0, press_s=0.12, dwell_s=0.1)
    assert run(tr, 3.59, 5e-4, 0.0, "medium") <= ENERGY_J
    # and one box as wide as both: no side face under the hand, the same bound
    assert run(tr, 3.59, 5e-4, 0.0, "medium", two=False) <= ENERGY_J


def test_a_slide_over_a_ball_stays_within_the_bound():
    """The normal turns with the hand over a ball: the distance's change is the motion along
    the normal, of which the simulated Omni renders the y part only. A 1.1 N/mm wall at 1 ms,
    a 38 mm ball, 0.25 N s/m (none credited): 2.4 mJ before the loop booked the motion along
    the device's axis, 0.10 mJ with the sign of the axis term flipped."""
    tr = over_a_ball(38.0, 1.5, 25.0, 4, 120.0)
    assert run(tr, 1.08, 1e-3, 0.25, "medium", ball=38.0) <= ENERGY_J


def test_taps_on_two_objects_in_turn_share_one_bound():
    """Ten taps, the boxes in turn (a 1.2 N/mm wall at 1 ms, no damping, 0.8 mm at 27 mm/s):
    0.236 mJ while each object's restart forgave the debt the last tap left (0.058 mJ on one
    box as wide as both)."""
    tr = taps(depth=0.8, n=10, in_s=0.03, hold_s=0.05, out_s=0.03)
    assert run(tr, 1.2, 1e-3, 0.0, "medium") <= ENERGY_J


def test_a_restart_on_another_object_keeps_a_debt_and_drops_credit():
    pc = PassivityController()
    pc.energy_j = 5e-5
    pc.reset(keep_debt=True)
    assert pc.energy_j == 5e-5
    pc.energy_j = -5e-5
    pc.reset(keep_debt=True)
    assert pc.energy_j == 0.0
    pc.energy_j = 5e-5
    pc.reset()
    assert pc.energy_j == 0.0


@settings(max_examples=100, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(["slide", "taps", "ball"]),
       k=st.floats(0.3, 50.0), period_s=st.sampled_from([2.5e-4, 5e-4, 1e-3, 2e-3]),
       damping=st.sampled_from([0.0, 0.25, 0.5]), finger=st.sampled_from(["soft", "medium", "stiff"]),
       depth=st.floats(0.3, 3.0), n=st.integers(2, 8), speed=st.floats(20.0, 300.0),
       a=st.floats(0.005, 0.3), b=st.floats(0.001, 0.3), c=st.floats(0.005, 0.3))
def test_moving_between_objects_stays_within_the_bound(kind, k, period_s, damping, finger, depth, n, speed, a, b, c):
    """Periods up to 2 ms: at 4 ms and beyond a tap's reversal within one tick is the known
    class of docs/runtime.md, Passivity, "The reversal within one tick" (on one box as on
    two: 0.23 mJ for ten 1.6 mm taps of the stiff finger at 4 ms on a 3 N/mm wall)."""
    if kind == "ball":
        radius = 8.0 + 100.0 * c                    # 8.5-38 mm
        tr = over_a_ball(radius, depth, radius * (0.2 + 2.0 * b), n, speed)
        e = run(tr, k, period_s, damping, finger, ball=radius)
    else:
        tr = slide(depth, n, speed, a, b) if kind == "slide" else taps(depth, n, a, b, c)
        e = run(tr, k, period_s, damping, finger)
    assert e <= ENERGY_J, (kind, e)


# --- ticks without a position in the middle of a press ------------------------------
#
# Issue 23: ticks without a position in the middle of a press, through the servo loop.
#
# A device whose reading is NaN for some ticks (a glitch of the encoder, a bad packet) gets
# 0 N on those ticks, and the stiff-wall controller books nothing; its next booking spans
# them. The damper took at least ``b dy^2 / span`` over that span, not ``b dy^2 / T``:
# credited over one tick, a press of 2 mm made over 15 unread ticks at 2 ms earned the
# controller 0.44 mJ of credit no damper had taken, which it then spent on the hand. And
# the motion over those ticks met no force, so it paid for no Colgate spring: the spring
# starts again from the reading found (docs/runtime.md, Passivity, "A tick without a period
# or a reading").
#
# Simulated Omni (45 g, 0.055 mm encoder, 3.3 N; generated data) with its damping measured
# hands off (:func:`measured_damping` of ``test_extreme_presses``, repeated here so that this
# file stands alone), the version-1 plane, a spring renderer. What each run must show: the
# energy the arm gave the finger (``OmniVirtual.energy_to_user_j``, its largest over the run)
# within the 0.1 mJ. Drawn through the loop (press and hold, 0.25-2 ms, 1-19 unread
# ticks during the press or the hold; 450 cells), the unread ticks alone put 5 cells over 0.1
# mJ (up to 0.48 mJ) before, none after (largest 0.073 mJ).


def run_press(k: float, period_s: float, damping: float, finger: str, depth: float, press_s: float, hold_s: float,
              release_s: float, t_bad: float, n_bad: int) -> float:
    """The largest energy to the finger (J): a press through ``ServoLoop`` whose readings
    are NaN for ``n_bad`` ticks from ``t_bad`` (s)."""
    from hapticsdk_hardness.omni import OmniVirtual

    tr = press_slide(depth_mm=depth, press_s=press_s, hold_s=hold_s, slide_s=0.0, release_s=release_s, rest_s=0.1)
    dev = OmniVirtual(trajectory=tr, finger=finger, damping_ns_per_m=damping)
    loop = ServoLoop(dev, [Spring(k)], {"force": dev}, period_s=period_s, passivity=True,
                     passivity_settings=ControllerSettings.for_device(dev, damping=measured(damping)))
    read = dev._read_state

    def glitchy():
        s = read()
        if t_bad <= dev.t < t_bad + n_bad * period_s:
            return SensedState.of(s.t, s.px, math.nan, s.pz, s.vx, s.vy, s.vz, 0.0, 0.0, 0.0)
        return s

    dev._read_state = glitchy
    return largest_energy(loop, dev, tr.duration_s)


def test_a_press_made_over_unread_ticks_earns_no_damping_credit():
    """Seed 7's cell 103 of the hunt: the readings are NaN from 9 ms for 14 ticks of 2 ms
    while the finger presses 2 mm in; 0.225 mJ when the span's damping credit was for one
    tick (0.44 mJ of credit at the first reading after the gap)."""
    e = run_press(6.40, 2e-3, 0.5, "medium", 2.333, 0.0649, 0.2367, 0.2249, 0.00938, 14)
    assert e <= ENERGY_J, e


def test_unread_ticks_during_a_hold_do_not_hand_out_a_spring():
    """Seed 8's cell 79 of the hunt (a 25.6 N/mm wall at 2 ms, 15 unread ticks in the hold):
    0.483 mJ before."""
    e = run_press(25.6, 2e-3, 0.25, "medium", 2.324, 0.2201, 0.2154, 0.1858, 0.2479, 15)
    assert e <= ENERGY_J, e


def test_the_span_without_readings_is_credited_once_over_its_length():
    """The controller alone: a stylus pressed 2 mm over 10 unread ticks (NaN) and then read
    earns at most ``b_x dy^2 / span`` of damping credit, not ``/ T``."""
    # the declared damping credited in full to the extra (no spring: damping_trust 0), an
    # exact encoder: the credit is b dy^2 / span
    s = ControllerSettings(period_s=1e-3, max_force_n=3.3, device_damping_ns_per_m=0.5,
                           declared_damping_trust=1.0, damping_trust=0.0)
    one, gap = PassivityController(s), PassivityController(s)
    for pc in (one, gap):
        pc.step(0.5, 1e-3, 0.0)
        pc.commit(0.0)
    for _ in range(10):
        gap.step(math.nan, 1e-3, 0.0)
        gap.commit(0.0)
    one.step(-2.0, 1e-3, 1.0)
    gap.step(-2.0, 1e-3, 1.0)
    # the credit of the whole move in one tick, and of the same move over eleven
    assert one.energy_j < 0.0 and gap.energy_j < 0.0
    assert math.isclose(gap.energy_j, one.energy_j / 11.0, rel_tol=1e-9), (one.energy_j, gap.energy_j)


@functools.lru_cache(maxsize=None)
def _clean_press(k: float, period_s: float, damping: float, finger: str, depth: float, press_s: float, hold_s: float,
                 release_s: float) -> float:
    """:func:`run_press` without unread ticks: a deterministic simulation, so a press that
    hypothesis draws again with other unread ticks (its mutations keep a drawn press and
    vary the rest: 26 of the 200 presses below) is run once."""
    return run_press(k, period_s, damping, finger, depth, press_s, hold_s, release_s, 0.0, 0)


@settings(max_examples=200, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(k=st.floats(0.3, 50.0), period_s=st.sampled_from([2.5e-4, 5e-4, 1e-3, 2e-3]),
       damping=st.sampled_from([0.25, 0.5]), finger=st.sampled_from(["soft", "medium", "stiff"]),
       depth=st.floats(0.5, 3.0), press_s=st.floats(0.05, 0.4), hold_s=st.floats(0.2, 0.6),
       release_s=st.floats(0.05, 0.4), at=st.floats(-0.3, 1.0), n_bad=st.integers(5, 19))
def test_unread_ticks_in_a_press_stay_within_the_bound(k, period_s, damping, finger, depth, press_s, hold_s,
                                                       release_s, at, n_bad):
    """Where the same press without the unread ticks is within the bound (a press through
    the loop with a measured damping can be over it by itself: the Colgate spring's encoder
    term, docs/runtime.md, Passivity item 0), the unread ticks keep it so."""
    t_bad = press_s + at * hold_s
    clean = _clean_press(k, period_s, damping, finger, depth, press_s, hold_s, release_s)
    if clean > ENERGY_J:
        return
    e = run_press(k, period_s, damping, finger, depth, press_s, hold_s, release_s, t_bad, n_bad)
    assert e <= ENERGY_J, (e, clean)


if __name__ == "__main__":
    pytest.main([__file__, "-q"])


@pytest.mark.parametrize("axes", ["y", (3,), (1, 1), (), (2, 0), (1.0,), None, (True,)])
def test_a_force_axes_declaration_that_is_not_axes_is_refused_before_anything_opens(axes):
    """``Actuator.force_axes`` is read on every tick of a spatial contact: a declaration that
    is not distinct axes 0-2 in order is a ``PluginError`` naming the actuator, raised by
    ``start()`` before any actuator is opened (nothing driving, nothing to close)."""
    from hapticsdk.errors import PluginError
    from hapticsdk_hardness.omni import OmniVirtual

    class Broken(OmniVirtual):
        force_axes = axes

    dev = Broken()
    loop = ServoLoop(dev, [], {"force": dev}, period_s=0.001)
    with pytest.raises(PluginError, match="Broken.force_axes"):
        loop.start(0.01)
    assert not dev.is_open


@pytest.mark.parametrize("axes", [(0, 1, 2), (1,), (0, 2)])
def test_declared_force_axes_are_read_as_declared(axes):
    from hapticsdk.devices.actuators import force_axes_of
    from hapticsdk_hardness.omni import OmniVirtual

    class Dev(OmniVirtual):
        force_axes = axes

    assert force_axes_of(Dev()) == axes
# -- a spring the device did not apply ---------------------------------------------------------
# The safety layer's start ramp (0.2 s from the opening, docs/safety.md) scales every command,
# the Colgate spring's too: a hand that presses within it compresses the spring against the
# scaled force and, without the rule, got the whole spring back on the release (through the
# loop, 2, 2 and 5 of 150 drawn presses of seeds 7-9 over 0.1 mJ, up to 0.83 mJ; docs/runtime.md,
# Passivity item 0, "A spring the device did not apply").


def test_a_press_inside_the_safety_start_ramp_gets_back_only_the_spring_applied():
    """0.198 mJ without the rule: a 2.16 N/mm wall at 0.25 ms, the damping measured (K_c 1
    N/mm), the stiff finger pressing 1.5 mm from 0 to 150 ms, inside the start ramp."""
    from hapticsdk_hardness.omni import OmniVirtual

    tr = press_slide(depth_mm=1.5, press_s=0.15, hold_s=0.4, slide_s=0.0, release_s=0.15, rest_s=0.1)
    dev = OmniVirtual(trajectory=tr, finger="stiff", damping_ns_per_m=0.25)
    loop = ServoLoop(dev, [Spring(2.16)], {"force": dev}, period_s=2.5e-4, passivity=True,
                     passivity_settings=ControllerSettings.for_device(dev, damping=measured(0.25)))
    e = largest_energy(loop, dev, tr.duration_s)
    assert e <= ENERGY_J, e


def _wall_controller(batch: bool, k_wall: float):
    """``(step, commit, book)`` of one controller on a ``k_wall`` N/mm wall at 1 ms, ``K_c`` 1
    N/mm (a measured damping of 1 N s/m, the spring's share half of it), the servo's scalar
    controller or the benchmark's vectorised one; ``book()`` is (spring N, anchor m, U J)."""
    from hapticsdk.passivity import controller_commit_batch, controller_state_batch, controller_step_batch

    s = ControllerSettings(period_s=1e-3, max_force_n=3.3, position_resolution_mm=0.055, device_damping_ns_per_m=1.0,
                           measured_damping_ns_per_m=1.0)   # b_s = 0.5 N s/m: K_c = 2 b_s / T = 1 N/mm
    if batch:
        state = controller_state_batch(1)

        def step(x: float) -> float:
            wall = np.array([k_wall * max(-x, 0.0)])
            return float(controller_step_batch(state, np.array([x]), 1e-3, wall, True, s)[0])

        def commit(f: float) -> None:
            controller_commit_batch(state, np.array([f]))

        def book() -> tuple[float, float, float]:
            return float(state["spring"][0]), float(state["anchor"][0]), float(state["energy"][0])
        return step, commit, book
    pc = PassivityController(s)
    return (lambda x: pc.step(x, 1e-3, k_wall * max(-x, 0.0))), pc.commit, (lambda: (pc._spring, pc._o, pc.energy_j))


@pytest.mark.parametrize("batch", [False, True])
def test_a_commit_below_the_spring_lowers_it_and_credits_what_it_took_out(batch):
    """The controller alone (the servo's scalar one and the benchmark's vectorised one): a
    spring of ``K_c`` 1 N/mm pressed slowly to 1 mm (1 N, a 2 N/mm wall), of which the device
    applied 0.4 N, is 0.4 N from then on with its anchor at 0.6 mm, and ``U`` falls by what
    the move took out, ``(1^2 - 0.4^2) / (2 K_c)`` = 0.42 mJ; a reading that stays keeps it
    there (it rises again only as the reading moves in)."""
    step, commit, book = _wall_controller(batch, 2.0)
    for x in [0.5] + [-0.05 * i for i in range(1, 21)]:   # from above the surface to 1 mm, 0.05 mm a tick
        commit(step(x))
    step(-1.0)
    spring, anchor, u = book()
    assert math.isclose(spring, 1.0, rel_tol=1e-9) and anchor == 0.0, (spring, anchor)
    commit(0.4)
    spring, anchor, u2 = book()
    assert math.isclose(spring, 0.4, rel_tol=1e-9) and math.isclose(anchor, 0.6e-3, rel_tol=1e-9), (spring, anchor)
    assert math.isclose(u - u2, (1.0 - 0.16) / 2000.0, rel_tol=1e-9), (u, u2)
    step(-1.0)
    assert math.isclose(book()[0], 0.4, rel_tol=1e-9)


@pytest.mark.parametrize("batch", [False, True])
def test_a_spring_capped_by_the_wall_is_lowered_without_credit(batch):
    """A 0.5 N/mm wall below ``K_c`` (1 N/mm): the spring is the wall's law, 0.5 N at 1 mm, not
    ``K_c`` times its depth, and the potential of a capped law is not known from one force, so
    the commit of 0.2 N lowers the spring (anchor at 0.8 mm) and credits nothing."""
    step, commit, book = _wall_controller(batch, 0.5)
    for x in [0.5] + [-0.05 * i for i in range(1, 21)]:
        commit(step(x))
    step(-1.0)
    spring, _, u = book()
    assert math.isclose(spring, 0.5, rel_tol=1e-9), spring
    commit(0.2)
    spring, anchor, u2 = book()
    assert math.isclose(spring, 0.2, rel_tol=1e-9) and math.isclose(anchor, 0.8e-3, rel_tol=1e-9), (spring, anchor)
    assert u2 == u, (u, u2)
