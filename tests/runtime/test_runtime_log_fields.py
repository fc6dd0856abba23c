"""The servo log keeps every field each role was sent, and renderers get a low-passed
velocity next to the raw one."""

import math

import numpy as np
import pytest

from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer
from hapticsdk.errors import ValidationError
from hapticsdk.runtime import ServoLoop
from hapticsdk.sim.finger import Trajectory
from hapticsdk.sim.probe import VirtualProbe

pytest.importorskip("hapticsdk_hardness")
from hapticsdk_hardness.omni import OmniVirtual  # noqa: E402
from hapticsdk_hardness.voicecoil import VoiceCoilVirtual  # noqa: E402


class Both(DimensionRenderer):
    """Force and a coil vibration in contact; remembers the filtered velocities it saw."""
    roles = ("force", "coil")

    def __init__(self):
        self.raw, self.filt = [], []

    def tick(self, inp):
        self.raw.append(float(inp.velocity_mm_s[1]))
        self.filt.append(inp.velocity_filtered_mm_s)
        if not inp.in_contact:
            return [ChannelCommand("force", force_n=0.0), ChannelCommand("coil", frequency_hz=80.0, amplitude=0.0)]
        return [ChannelCommand("force", force_n=0.5 * inp.penetration_mm),
                ChannelCommand("coil", frequency_hz=80.0, amplitude=0.3)]


def _run(**kw):
    tr = Trajectory([(0, 0, 1.0), (0.2, 0, 1.0), (0.5, 0, -2.0), (1.0, 0, -2.0)])
    dev = OmniVirtual(trajectory=tr)
    r = Both()
    rep = ServoLoop(dev, [r], {"force": dev, "coil": VoiceCoilVirtual()}, passivity=False, **kw).run(1.0)
    return rep, r


def test_every_commanded_field_of_every_role_is_logged():
    rep, _ = _run()
    L = rep.log
    for key in ("force.force_n", "force.frequency_hz", "force.amplitude", "coil.force_n",
                "coil.frequency_hz", "coil.amplitude"):
        assert key in L and L[key].shape == L["t"].shape, key
    assert np.isnan(L["coil.force_n"]).all()                 # the coil was never sent a force
    assert np.isnan(L["force.frequency_hz"]).all()
    np.testing.assert_array_equal(L["force.force_n"], L["force_n"])   # one force role: the same sum
    assert (L["coil.frequency_hz"] == 80.0).all() and L["coil.amplitude"].max() > 0


def test_filtered_velocity_is_a_first_order_low_pass_of_the_raw_one():
    fc = 20.0
    rep, r = _run(velocity_filter_hz=fc)
    raw = np.array(r.raw)
    filt = np.array([f[1] for f in r.filt])
    dt = rep.log["dt"]
    a = 1.0 - np.exp(-2 * math.pi * fc * dt)
    y = 0.0
    expect = []
    for x, ai in zip(raw, a):
        y += ai * (x - y)
        expect.append(y)
    np.testing.assert_allclose(filt, expect, rtol=0, atol=1e-9)
    # it removes the encoder's count-level chatter: far less tick-to-tick change in contact
    contact = rep.log["penetration_mm"] > 0.5
    assert np.abs(np.diff(filt[contact])).max() < 0.5 * np.abs(np.diff(raw[contact])).max()


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), True])
def test_the_filter_corner_is_validated(bad):
    with pytest.raises(ValidationError) as ei:
        ServoLoop(VirtualProbe(), [], velocity_filter_hz=bad)
    assert ei.value.field == "velocity_filter_hz"


def test_tick_after_finish_does_nothing_and_start_twice_is_refused():
    import gc
    dev = VirtualProbe()
    loop = ServoLoop(dev, [])
    was = gc.isenabled()
    loop.start(None)
    with pytest.raises(ValidationError):
        loop.start(None)                 # would record GC as disabled and leave it so
    assert loop.tick()
    loop.finish()
    assert gc.isenabled() == was
    assert loop.tick() is False          # no commands after finish()
