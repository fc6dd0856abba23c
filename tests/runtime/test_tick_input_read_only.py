"""The servo loop hands one TickInput to every renderer of an object, in turn: its
velocity array is read-only, so a renderer that writes into it in place fails (counted as
a renderer error) instead of changing what the next renderer reads. On the version-1
plane and in a spatial scene (a tilted face, where the loop builds the contact-frame
velocity itself)."""

import numpy as np
import pytest

from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer
from hapticsdk.runtime import ServoLoop
from hapticsdk.scene.geometry import Box, HitTester, Pose, Sphere
from hapticsdk.sim.finger import Trajectory, press_slide
from hapticsdk.sim.probe import VirtualProbe


class Scaler(DimensionRenderer):
    """Writes into its input in place ("to m/s"): the broken renderer."""
    roles = ("force",)

    def tick(self, inp):
        inp.velocity_mm_s *= 0.001
        return []


class Reader(DimensionRenderer):
    """Runs after Scaler and keeps what it reads (by value) and whether it could write."""
    roles = ("force",)

    def __init__(self):
        self.seen = []
        self.normals = []

    def tick(self, inp):
        self.seen.append((np.array(inp.velocity_mm_s), bool(inp.velocity_mm_s.flags.writeable)))
        self.normals.append(inp.normal)
        return [ChannelCommand("force", force_n=0.5 * inp.penetration_mm if inp.in_contact else 0.0)]


def _spatial(renderers):
    tr = Trajectory([(0.0, -30.0, 5.0), (0.2, -30.0, -1.0), (0.6, 30.0, -1.0), (1.0, 30.0, 5.0)])
    box = Box((20.0, 10.0, 20.0), pose=Pose((-30.0, -10.0, 0.0)))
    ball = Sphere(20.0, pose=Pose((30.0, -19.0, 0.0)))
    return ServoLoop(VirtualProbe(trajectory=tr), (), passivity=False,
                     objects=[("box", renderers), ("ball", renderers)],
                     hit_tester=HitTester([("box", box), ("ball", ball)]))


@pytest.mark.parametrize("where", ["plane", "spatial"])
def test_a_renderer_cannot_change_the_input_the_next_one_reads(where):
    reader = Reader()
    if where == "plane":
        loop = ServoLoop(VirtualProbe(trajectory=press_slide()), [Scaler(), reader], passivity=False)
        rep = loop.run(1.0)
    else:
        loop = _spatial([Scaler(), reader])
        rep = loop.run(1.0)
    assert len(reader.seen) > 300
    if where == "spatial":   # the sphere's flank: a normal the loop projects the velocity on
        assert sum(n != (0.0, 1.0, 0.0) for n in reader.normals) > 50
    assert not any(w for _, w in reader.seen), "a renderer got a writable velocity array"
    # the reader saw the sensed velocity (mm/s), not a thousandth of it
    speeds = np.array([abs(v).max() for v, _ in reader.seen])
    assert speeds.max() > 10.0
    assert rep.events["renderer_error"] >= len(reader.seen)   # every in-place write failed, counted
