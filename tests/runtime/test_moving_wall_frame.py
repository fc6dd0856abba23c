"""Issue 23: a moving wall (``ServoLoop.set_pose``) and the positions the loop remembers
(docs/runtime.md, Passivity, "A moving wall": "Positions carried with the object").

The readings the loop builds from positions, rather than from the distance, are the
one-axis device's off the +y normal (``_x_off``, "A force rendered along one axis") and,
on a device that renders all three axes, the held force's booking out of contact and the
re-read at a turn (:mod:`hapticsdk.runtime.turns`). The issue's bound is on the energy in
the wall's frame, so each must be of the stylus's motion relative to the object: a
position remembered is carried with the object when it moves (:func:`carrier`).

On the simulated Omni (``omni-virtual``: force along y only; generated data), probing past
the middle of a thin box, the bottom face (normal -y) the nearest, the reading is
``n_y dp_y`` per tick; for that face the distance changes by ``-(dp_y - dw_y)`` (``dw`` the
box's move), so with the positions carried the reading moves exactly as the distance
does, whether the box moves or not. Before, it moved by ``-dp_y`` alone: blind to the
wall, its book was the world's while the bound is the wall's
(``bench/bench_servo_paths.py moving --cells 150 --seed 12``, cell 140: 0.73 mJ in the
wall's frame).
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hapticsdk.passivity import PassivityController
from hapticsdk.runtime import ServoLoop
from hapticsdk.runtime.turns import NormalTurns, carrier
from hapticsdk.scene.geometry import Box, HitTester, Pose
from hapticsdk.sim.finger import Trajectory
from hapticsdk_hardness.omni import OmniVirtual
from renderers import Spring

DOWN = (0.0, -1.0, 0.0)


def _apply(pose: Pose, q: tuple[float, float, float]) -> tuple[float, float, float]:
    r, t = pose.matrix, pose.position_mm
    return tuple(sum(r[i][j] * q[j] for j in range(3)) + t[i] for i in range(3))  # type: ignore[return-value]


angles = st.floats(-180.0, 180.0)
coords = st.floats(-50.0, 50.0)


@settings(max_examples=40, deadline=None)
@given(e0=st.tuples(angles, angles, angles), e1=st.tuples(angles, angles, angles),
       t0=st.tuples(coords, coords, coords), t1=st.tuples(coords, coords, coords),
       local=st.tuples(coords, coords, coords))
def test_a_point_of_the_object_is_carried_to_where_the_object_takes_it(e0, e1, t0, t1, local) -> None:
    old, new = Pose(t0, {"euler_deg": list(e0)}), Pose(t1, {"euler_deg": list(e1)})
    got = carrier(old, new)(_apply(old, local))
    want = _apply(new, local)
    # a few roundings of coordinates up to ~150 mm through two rotations: 1e-9 mm is
    # ~10^4 ulps of 150 mm, and far below any motion the loop reads (0.055 mm counts)
    assert all(abs(g - w) <= 1e-9 for g, w in zip(got, want))


def test_the_turns_ring_is_carried_and_its_re_read_is_relative_to_the_object() -> None:
    """A still stylus on the top face of a box that moves up 0.25 mm a tick: relative to
    the box, the stylus moved down 0.25 mm a tick. At a turn to the front face (+z) that
    motion has no part along the new normal: the history re-read is flat; carried along
    with a box that also moves +z by 0.125 mm a tick it is the stylus moving -z relative
    to it, q_(k-j) = q1 + 0.125 j."""
    class Rec:
        calls: list[list[float]] = []

        def rebase(self, r: list[float]) -> None:
            self.calls.append(list(r))
    t, pc = NormalTurns(), Rec()
    p = (1.0, -1.0, 9.0)
    for i in range(4):
        if i:
            t.carry(carrier(Pose((0.0, -10.0 + 0.25 * (i - 1), 0.125 * (i - 1))),
                            Pose((0.0, -10.0 + 0.25 * i, 0.125 * i))))
        t.reading([pc], -1.0 - 0.25 * i, -0.75 - 0.25 * i, True, True, p, (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 1.0)
    t.carry(carrier(Pose((0.0, -9.25, 0.375)), Pose((0.0, -9.0, 0.5))))
    t.reading([pc], -0.5, -1.75, True, True, p, (0.0, 0.0, 1.0), (0.0, 1.0, 0.0), 1.0)
    # q1 = min(-1.75, -0.5 - 1 * (9.0 - 9.125)) = -1.75; 4 positions known, 0.125 mm apart
    want = [-1.75 + 0.125 * j for j in range(4)]
    assert pc.calls[0][:4] == want and set(pc.calls[0][4:]) == {want[-1]}


def _past_the_middle(period: float, amp: float, hz: float, finger: str, k: float) -> list[tuple[float, float]]:
    """The one-axis Omni probing 3 mm into a box 4 mm tall (the bottom face 1 mm away, the
    nearest) while the box moves up and down ``amp`` mm at ``hz``: per tick in contact
    with the bottom face over the last interval too, the change of the controller's
    reading and of the distance ``-pen``."""
    tr = Trajectory([(0.0, 0.0, 1.0), (0.1, 0.0, -3.0), (0.6, 0.0, -3.0)])
    dev = OmniVirtual(trajectory=tr, finger=finger, damping_ns_per_m=0.0)
    box = Box((20.0, 2.0, 20.0), pose=Pose((0.0, -2.0, 0.0)))     # top y = 0, bottom y = -4
    loop = ServoLoop(dev, (), {"force": dev}, period_s=period, passivity=True,
                     objects=[("A", [Spring(k)])], hit_tester=HitTester([("A", box)]))
    loop.start(tr.duration_s)
    out: list[tuple[float, float]] = []
    last = None
    while True:
        t = loop.ticks * period
        if t > 0.15:
            loop.set_pose(0, Pose((0.0, -2.0 + amp * math.sin(2.0 * math.pi * hz * (t - 0.15)), 0.0)))
        held = loop._held_n
        more = loop.tick()
        now = (loop._last_x, loop.last_penetration_mm, loop.contact)
        if last is not None and held == DOWN and loop._held_n == DOWN and last[2] == now[2] == 0:
            out.append((now[0] - last[0], last[1] - now[1]))
        last = now
        if not more:
            break
    loop.finish()
    return out


@pytest.mark.parametrize("period, amp, hz, finger, k", [
    (5e-4, 0.84, 12.5, "stiff", 36.6), (1e-3, 0.86, 16.5, "medium", 0.44), (1e-3, 0.29, 13.7, "soft", 32.5)])
def test_the_one_axis_reading_past_the_middle_moves_as_the_distance(period, amp, hz, finger, k) -> None:
    rows = _past_the_middle(period, amp, hz, finger, k)
    assert len(rows) > 50      # the case is reached
    # both are differences of coordinates of ~4 mm: a few ulps (1e-15 mm) each; 1e-9 mm
    # is far below a wall move of this stroke (>= 1e-4 mm a tick at its slowest)
    assert all(abs(dx - dd) <= 1e-9 for dx, dd in rows), max(abs(dx - dd) for dx, dd in rows)


def test_the_loop_carries_the_positions_of_the_three_axis_re_read_with_the_box() -> None:
    """``omni3-virtual`` (all three axes: the turns' ring) pressing the top face near the
    front edge of a box that moves along a diagonal: the positions the ring holds are
    points of the box, so between two ticks a position's offset from the box's origin
    does not change however the box moved."""
    from hapticsdk_hardness.omni3 import Omni3Virtual
    tr = Trajectory([(0.0, 0.0, 1.0, 8.0), (0.1, 0.0, -1.0, 8.0), (0.3, 0.0, -1.5, 11.0), (0.4, 0.0, 2.0, 11.0)])
    dev = Omni3Virtual(trajectory=tr, finger="medium", damping_ns_per_m=0.0)
    box = Box((10.0, 10.0, 10.0), pose=Pose((0.0, -10.0, 0.0)))    # top y = 0, front z = 10
    loop = ServoLoop(dev, (), {"force": dev}, period_s=1e-3, passivity=True,
                     objects=[("A", [Spring(2.0)])], hit_tester=HitTester([("A", box)]))
    loop.start(tr.duration_s)
    turns = loop._turns
    assert turns is not None
    c = (0.0, -10.0, 0.0)
    checked = 0
    while True:
        t = loop.ticks * 1e-3
        before = [(turns._ring[turns._at - j], c) for j in range(turns._n)]
        c = (0.3 * math.sin(40.0 * t), -10.0 + 0.5 * math.sin(30.0 * t), 0.4 * math.sin(20.0 * t))
        loop.set_pose(0, Pose(c))
        more = loop.tick()
        if turns._n > 1 and before:
            # the ring moved on by one: its entry j+1 is the one that was j
            for j, (q, c0) in enumerate(before[:turns._n - 1]):
                q1 = turns._ring[turns._at - j - 1]
                assert all(abs((q1[i] - c[i]) - (q[i] - c0[i])) <= 1e-9 for i in range(3))
                checked += 1
        if not more:
            break
    loop.finish()
    assert checked > 100


def test_past_the_middle_the_damping_credit_is_taken_on_the_stylus_s_own_motion(monkeypatch: pytest.MonkeyPatch) -> None:
    """That reading now holds the wall's move, so where the box moved the controller gets
    the stylus's own motion along the force for its damping credit (the arm's damper
    dissipates the stylus's motion, not the wall's): ``own = n_y dp_y``, ``dp`` the
    reading's change of position over the interval. Without it the credit is taken on the
    reading's change, the wall's move in it."""
    tr = Trajectory([(0.0, 0.0, 1.0), (0.1, 0.0, -3.0), (0.4, 0.0, -3.0)])
    dev = OmniVirtual(trajectory=tr, finger="stiff", damping_ns_per_m=0.5)
    box = Box((20.0, 2.0, 20.0), pose=Pose((0.0, -2.0, 0.0)))
    loop = ServoLoop(dev, (), {"force": dev}, period_s=1e-3, passivity=True,
                     objects=[("A", [Spring(5.0)])], hit_tester=HitTester([("A", box)]))
    loop.start(tr.duration_s)
    seen: list[float | None] = []
    step = PassivityController.step

    def spy(self: PassivityController, x: float, dt: float, f: float, own: float | None = None,
            turned: float = 0.0) -> float:
        seen.append(own)
        return step(self, x, dt, f) if own is None else step(self, x, dt, f, own, turned)
    monkeypatch.setattr(PassivityController, "step", spy)
    checked = 0
    y = None
    while True:
        t = loop.ticks * 1e-3
        if t > 0.15:
            loop.set_pose(0, Pose((0.0, -2.0 + 0.4 * math.sin(2.0 * math.pi * 8.0 * (t - 0.15)), 0.0)))
        held = loop._held_n
        seen.clear()
        more = loop.tick()
        y1 = float(loop.last_state.position_mm[1]) if loop.last_state is not None else None
        if t > 0.15 and held == DOWN and loop._held_n == DOWN and loop.contact == 0 and y is not None and y1 is not None:
            assert seen and seen[0] is not None
            assert abs(seen[0] - (-(y1 - y))) <= 1e-9      # n_y dp_y, n = -y
            checked += 1
        y = y1
        if not more:
            break
    loop.finish()
    assert checked > 50
