"""Contact gate hysteresis (issue 27): a probe resting at a surface, whose reading flips
between two adjacent encoder counts, never toggles contact (nor the voice coil, whose
gate is the contact); away from the surface the rendered force is unchanged."""

import numpy as np
import pytest

from hapticsdk.dimensions import ChannelCommand, DimensionRenderer
from hapticsdk.runtime import ServoLoop
from hapticsdk.sim.finger import Trajectory
from hapticsdk.sim.probe import VirtualProbe

Q = 0.055  # mm: one count of the simulated Omni's encoder


class Encoded(VirtualProbe):
    """A probe that declares an encoder count (the loop takes its hysteresis from it)."""
    encoder_resolution_mm = Q


class Gate(DimensionRenderer):
    """Force k * penetration and a coil driven while in contact (the hardness renderer's gates)."""
    roles = ("force",)

    def __init__(self):
        self.on = []

    def tick(self, inp):
        self.on.append(inp.in_contact)
        return [ChannelCommand("force", 2.0 * inp.penetration_mm if inp.in_contact else 0.0)]


def _flicker(n=400, rng=None):
    """Rest at the surface: each tick the reading is one of two adjacent counts, the
    surface between them (a random split of the count), in random order."""
    rng = rng or np.random.default_rng(0)
    a = rng.uniform(0.0, Q)  # depth of the deeper count level
    ys = np.where(rng.random(n) < 0.5, -a, Q - a)
    return Trajectory([(0.0, 0.0, 2.0), (0.1, 0.0, ys[0])] + [(0.1 + 1e-3 * (i + 1), 0.0, y) for i, y in
                                                              enumerate(ys[1:])] + [(600.0, 0.0, ys[-1])])


@pytest.mark.parametrize("seed", range(5))
def test_resting_at_the_surface_never_toggles(seed):
    r = Gate()
    rep = ServoLoop(Encoded(trajectory=_flicker(rng=np.random.default_rng(seed))), [r], passivity=False).run(0.45)
    assert rep.events["contact_changes"] == 1  # entered once, never left
    on = np.array(r.on)
    assert on[np.argmax(on):].all()


def test_without_a_declared_encoder_the_gate_is_exact():
    r = Gate()
    rep = ServoLoop(VirtualProbe(trajectory=_flicker()), [r], passivity=False).run(0.45)
    assert rep.events["contact_changes"] > 20


def test_force_away_from_the_surface_is_unchanged():
    """Pressed deeper than a count and slid: every tick's force equals the gate-free loop's."""
    tr = Trajectory([(0.0, 0.0, 2.0), (0.2, 0.0, -1.5), (0.6, 10.0, -0.5), (1.0, 20.0, 2.0), (600.0, 20.0, 2.0)])
    logs = []
    for cls in (Encoded, VirtualProbe):
        rep = ServoLoop(cls(trajectory=tr), [Gate()], passivity=False).run(1.0)
        logs.append(rep.log)
    pen = logs[0]["penetration_mm"]
    away = (pen > 0) | (pen <= -Q)
    assert away.sum() > 900
    assert np.array_equal(logs[0]["force_n"][away], logs[1]["force_n"][away])
