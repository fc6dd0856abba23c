"""The steppable servo loop: start / tick / finish is the batch path, the log is a
bounded ring, spatial scenes feed renderers in the contact frame (issue 12 item 1;
material switches, item 3, are in test_material_switch.py)."""

import math

import numpy as np
import pytest

from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer
from hapticsdk.runtime import ServoLoop
from hapticsdk.runtime.loop import MAX_LOG_TICKS
from hapticsdk.scene.geometry import Box, HitTester, Pose, Sphere
from hapticsdk.sim.finger import Trajectory, press_slide
from hapticsdk.sim.probe import VirtualProbe


class Spring(DimensionRenderer):
    roles = ("force",)

    def __init__(self, k):
        self.k = k
        self.inputs = []

    def tick(self, inp):
        self.inputs.append(inp)
        return [ChannelCommand("force", force_n=self.k * inp.penetration_mm if inp.in_contact else 0.0)]


def test_run_equals_start_tick_finish():
    a = ServoLoop(VirtualProbe(trajectory=press_slide()), [Spring(1.0)]).run(1.5)
    loop = ServoLoop(VirtualProbe(trajectory=press_slide()), [Spring(1.0)])
    loop.start(1.5)
    n = 0
    while loop.tick():
        n += 1
    b = loop.finish()
    assert b.ticks == a.ticks == 1500 and n == 1499
    np.testing.assert_array_equal(a.log["force_n"], b.log["force_n"])
    assert not loop.tick()  # the run is over


def test_hit_tester_single_plane_reproduces_the_version_1_loop():
    """The version-1 plane through the HitTester gives the renderers exactly the
    penetration -y (in contact) and the same forces as the loop without a hit tester."""
    r1, r2 = Spring(1.3), Spring(1.3)
    a = ServoLoop(VirtualProbe(trajectory=press_slide()), [r1], passivity=False).run(2.0)
    b = ServoLoop(VirtualProbe(trajectory=press_slide()), (), passivity=False,
                  objects=[("plane", [r2])], hit_tester=HitTester.single_plane()).run(2.0)
    inside = a.log["penetration_mm"] > 0
    assert inside.sum() > 500
    np.testing.assert_array_equal(a.log["penetration_mm"][inside], b.log["penetration_mm"][inside])
    np.testing.assert_array_equal(a.log["force_n"], b.log["force_n"])
    pen2 = [i.penetration_mm for i in r2.inputs if i.in_contact]
    assert pen2 == [-y for y in a.log["position_mm"][inside, 1]]
    assert all(i.object == "plane" and i.normal == (0.0, 1.0, 0.0) for i in r2.inputs)


def test_the_stiff_wall_controller_of_a_spatial_object_reads_its_penetration():
    """In a spatial scene the stiff-wall controller of the object in contact reads the
    position along that object's normal, -penetration, on every contact tick, the first
    object (index 0) included; out of contact with every object it holds the last one
    (a jump of the nearest object's distance is no motion)."""
    box = Box((30.0, 20.0, 30.0), pose=Pose((0.0, -20.0, 0.0)))   # top face at y = 0
    ball = Sphere(5.0, pose=Pose((60.0, 0.0, 0.0)))
    loop = ServoLoop(VirtualProbe(trajectory=press_slide()), (), objects=[("box", [Spring(1.0)]), ("ball", [Spring(1.0)])],
                     hit_tester=HitTester([("box", box), ("ball", ball)]))
    loop.start(2.0)
    pc = [s.pc for s in loop._slots if s.is_force][0]
    assert pc is not None
    contact = held = 0
    last = None
    balls = 0
    while loop.tick():
        if loop.last_index >= 0:   # the nearest object (either), its distance along its normal
            assert pc._q1 == -loop.last_penetration_mm
            contact += loop.last_index == 0 and loop.last_penetration_mm > 0.0
            balls += loop.last_index == 1 and loop.last_penetration_mm > 0.0
            last = pc._q1
        elif last is not None:
            assert pc._q1 == last   # held outside
            held += 1
    loop.finish()
    assert contact > 500 and balls > 10 and held > 10


def test_log_is_a_bounded_ring():
    """A very long run does not preallocate its whole log (issue 13 item 8): the window
    holds at most log_seconds of ticks, and the newest ones."""
    loop = ServoLoop(VirtualProbe(), [Spring(1.0)], log_seconds=0.5)
    loop.start(500000.0)
    assert loop._cap == 500 and loop._log.shape[0] == 500
    for _ in range(1234):
        loop.tick()
    rep = loop.finish()
    assert rep.ticks == 1234 and rep.log["t"].size == 500
    np.testing.assert_allclose(rep.log["t"], (np.arange(734, 1234)) * 1e-3)
    big = ServoLoop(VirtualProbe(), [Spring(1.0)], period_s=1e-5)
    big.start(500000.0)
    assert big._cap <= MAX_LOG_TICKS
    big.finish()


class Recorder(DimensionRenderer):
    roles = ("force",)

    def __init__(self):
        self.seen = []

    def tick(self, inp):
        self.seen.append((inp.object, inp.penetration_mm, inp.normal, tuple(inp.velocity_mm_s)))
        return [ChannelCommand("force", force_n=1.0 if inp.in_contact else 0.0)]


def test_per_object_renderers_in_the_contact_frame():
    """Each object's own renderers run while the probe touches it, with the penetration
    along its normal and velocity index 1 = normal component, index 0 = sliding speed;
    the force command carries the normal as direction."""
    # the probe goes down into a box top, slides onto a sphere's flank
    tr = Trajectory([(0.0, -30.0, 5.0), (0.2, -30.0, -1.0), (0.6, 30.0, -1.0), (1.0, 30.0, 5.0)])
    box = Box((20.0, 10.0, 20.0), pose=Pose((-30.0, -10.0, 0.0)))
    ball = Sphere(20.0, pose=Pose((30.0, -19.0, 0.0)))
    rb, rs = Recorder(), Recorder()
    probe = VirtualProbe(trajectory=tr)
    sent = []

    class Spy:
        def record(self, t, st, s):
            sent.append(s["force"])

    loop = ServoLoop(probe, (), passivity=False, objects=[("box", [rb]), ("ball", [rs])],
                     hit_tester=HitTester([("box", box), ("ball", ball)]), recorder=Spy())
    rep = loop.run(1.0)
    assert rb.seen and rs.seen
    assert {o for o, *_ in rb.seen} == {"box"} and {o for o, *_ in rs.seen} == {"ball"}
    # on the box top: normal +y, penetration 1 mm, velocity passed as (vx, vy, vz)
    top = [s for s in rb.seen if abs(s[1] - 1.0) < 1e-9]
    assert len(top) > 100 and all(n == (0.0, 1.0, 0.0) and v[0] == 150.0 for _, _, n, v in top)
    # on the sphere: radial normal, index 1 = v . n, index 0 = |v_t| >= 0
    on_ball = [s for s in rs.seen if s[1] > 0 and s[2] != (0.0, 1.0, 0.0)]
    assert on_ball
    for _, pen, n, v in on_ball:
        assert abs(math.sqrt(sum(c * c for c in n)) - 1.0) < 1e-12
        assert v[0] >= 0.0 and v[2] == 0.0
        speed2 = v[0] ** 2 + v[1] ** 2
        assert speed2 == pytest.approx(150.0 ** 2, rel=1e-9)  # 60 mm in 0.4 s, all of it in (vt, vn)
    slanted = [c for c in sent if c.direction is not None]
    assert slanted and all(abs(c.direction[1]) < 1.0 for c in slanted)
    objs = rep.log["object"]
    assert set(np.unique(objs)) <= {-1, 0, 1} and (objs == 0).any() and (objs == 1).any()
    assert rep.events["contact_changes"] >= 3  # box, none/ball, none
