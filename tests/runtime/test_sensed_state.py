"""Plain-float device states (issue 30, item 1): SensedState keeps DeviceState's
contract, the loop reads it without arrays and logs what it read and sent, the loop's
reused command records never leak into what was sent."""

import dataclasses
import math

import numpy as np
import pytest

from hapticsdk.devices.actuators import Actuator, DeviceState, SensedState
from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer
from hapticsdk.errors import DeviceError
from hapticsdk.runtime import ServoLoop
from hapticsdk.devices.safety import SafetyLayer
from hapticsdk.devices.actuators import ActuatorLimits
from hapticsdk.sim.finger import press_slide
from hapticsdk.sim.probe import VirtualProbe

def _cells(n=60, seed=30):
    """Random states: magnitudes from 1e-300 to 1e300, signs, zeros."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        v = rng.choice([-1.0, 1.0], 10) * 10.0 ** rng.uniform(-300, 300, 10)
        v[rng.random(10) < 0.1] = 0.0
        yield [float(x) for x in v]


@pytest.mark.parametrize("v", list(_cells()))
def test_sensed_state_is_a_device_state_with_the_same_values(v):
    t, px, py, pz, vx, vy, vz, fx, fy, fz = v
    st = SensedState.of(t, px, py, pz, vx, vy, vz, fx, fy, fz, 3)
    assert isinstance(st, DeviceState)
    assert st.position_mm.tolist() == [px, py, pz] and st.position_mm[1] == py
    assert st.velocity_mm_s.tolist() == [vx, vy, vz] and st.force_n.tolist() == [fx, fy, fz]
    assert st.penetration_mm == -py == DeviceState(t, st.position_mm, st.velocity_mm_s).penetration_mm
    m = max(abs(vx), abs(vy), abs(vz))   # scaled: |v| of 1e300 does not overflow to inf
    speed = m * math.sqrt((vx / m) ** 2 + (vy / m) ** 2 + (vz / m) ** 2) if m else 0.0
    assert st.speed_mm_s == pytest.approx(speed, rel=1e-12, abs=0.0)
    # DeviceState's own constructor signature and dataclasses.replace keep working
    back = SensedState.from_state(DeviceState(t, np.array([px, py, pz]), np.array([vx, vy, vz]),
                                              np.array([fx, fy, fz]), 3))
    assert (back.px, back.py, back.pz, back.vx, back.vy, back.vz, back.fx, back.fy, back.fz, back.buttons) == (
        px, py, pz, vx, vy, vz, fx, fy, fz, 3)
    moved = dataclasses.replace(st, t=t + 1.0)
    assert moved.t == t + 1.0 and moved.position_mm.tolist() == [px, py, pz]


def test_sensed_state_arrays_are_readings_not_views():
    st = SensedState.of(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
    with pytest.raises(ValueError):
        st.position_mm[1] = 0.0     # would desynchronise the floats
    st.position_mm = [7.0, 8.0, 9.0]
    assert (st.px, st.py, st.pz) == (7.0, 8.0, 9.0) and st.position_mm.tolist() == [7.0, 8.0, 9.0]
    assert st.penetration_mm == -8.0


class FloatProbe(VirtualProbe):
    """The same probe, read as plain floats (the fast path of omni-virtual)."""

    def _read_state(self):
        s = super()._read_state()
        return SensedState.of(s.t, *map(float, s.position_mm), *map(float, s.velocity_mm_s),
                              *map(float, s.force_n), s.buttons)


@pytest.mark.parametrize("field", range(6))
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_read_state_refuses_each_non_finite_float(field, bad):
    class Bad(FloatProbe):
        def _read_state(self):
            s = super()._read_state()
            v = [s.px, s.py, s.pz, s.vx, s.vy, s.vz]
            v[field] = bad
            return SensedState.of(s.t, *v)

    dev = Bad().open()
    try:
        with pytest.raises(DeviceError, match="non-finite"):
            dev.read_state()
    finally:
        dev.close()


class Spring(DimensionRenderer):
    roles = ("force",)

    def tick(self, inp):
        return [ChannelCommand("force", force_n=0.7 * inp.penetration_mm if inp.in_contact else 0.0)]


class Buzz(DimensionRenderer):
    roles = ("vib",)

    def tick(self, inp):
        return [ChannelCommand("vib", frequency_hz=100.0 + 50.0 * inp.t, amplitude=0.25 + 0.5 * inp.t)]


class Shaker(Actuator):
    channel = "vibration"
    limits = ActuatorLimits(frequency_range_hz=(50.0, 500.0), max_amplitude=1.0)

    def _command(self, cmd):
        pass

    def _stop(self):
        pass


class DriftProbe(FloatProbe):
    """FloatProbe drifting along z as well, so every axis of position and velocity reads
    its own value (a column swapped in the log shows)."""

    def _read_state(self):
        s = super()._read_state()
        return SensedState.of(s.t, s.px, s.py, 0.1 + 0.3 * s.t, s.vx, s.vy, 0.3, s.fx, s.fy, s.fz, s.buttons)


class Recorder:
    def __init__(self):
        self.rows = []

    def record(self, t, st, sent):
        self.rows.append((t, st, sent))


def test_float_and_array_backends_give_the_same_run():
    """A backend's DeviceState (converted once by the loop) and a SensedState of the same
    values give the same log, bit for bit."""
    a = ServoLoop(VirtualProbe(trajectory=press_slide()), [Spring()]).run(1.2)
    b = ServoLoop(FloatProbe(trajectory=press_slide()), [Spring()]).run(1.2)
    for k in ("t", "penetration_mm", "position_mm", "velocity_mm_s", "force_n", "force.force_n"):
        np.testing.assert_array_equal(a.log[k], b.log[k])
    assert a.log["force_n"].max() > 0.5   # the probe was pressed


def test_log_ring_and_sent_commands_match_what_was_read_and_sent():
    """Every logged column equals what the recorder saw that tick (state read, command
    sent), across a wrap of the ring; each tick's sent command is its own record (the
    loop refills one record per role, the actuator's safety layer returns a new one)."""
    rec = Recorder()
    dev = DriftProbe(trajectory=press_slide())
    loop = ServoLoop(dev, [Spring(), Buzz()], {"force": dev, "vib": Shaker()}, recorder=rec, log_seconds=0.4)
    rep = loop.run(1.5)
    n = rep.log["t"].size
    assert n == 400
    rows = rec.rows[-n:]
    np.testing.assert_array_equal(rep.log["t"], [r[0] for r in rows])
    np.testing.assert_array_equal(rep.log["position_mm"], [r[1].position_mm for r in rows])
    np.testing.assert_array_equal(rep.log["velocity_mm_s"], [r[1].velocity_mm_s for r in rows])
    sent = [r[2]["force"].force_n for r in rows]
    np.testing.assert_array_equal(rep.log["force.force_n"], sent)
    np.testing.assert_array_equal(rep.log["force_n"], sent)
    for k in ("frequency_hz", "amplitude"):
        np.testing.assert_array_equal(rep.log[f"vib.{k}"], [getattr(r[2]["vib"], k) for r in rows])
    assert np.ptp(rep.log["vib.frequency_hz"]) > 10 and np.ptp(rep.log["vib.amplitude"]) > 0.1
    assert len({id(r[2]["force"]) for r in rec.rows}) == len(rec.rows)
    # the force moved over the run: a record shared between ticks would show one value
    assert len({r[2]["force"].force_n for r in rec.rows}) > 50


def test_safety_speed_limit_reads_the_floats():
    """The speed limit bites on a SensedState exactly as on a DeviceState of the same
    velocity (the layer takes |v| from the floats)."""
    lim = ActuatorLimits(max_force_n=3.0, max_velocity_mm_s=100.0)
    for make in (lambda v: SensedState.of(0.0, 0.0, 0.0, 0.0, *v),
                 lambda v: DeviceState(0.0, np.zeros(3), np.array(v))):
        s = SafetyLayer(lim)
        s.reset(0.0)
        s.observe(make((60.0, 0.0, 80.0)))          # |v| = 100: at the limit
        assert "max_velocity_mm_s" not in s.hits
        s.observe(make((60.0, 0.0, 80.001)))        # just above
        assert s.hits.get("max_velocity_mm_s") == 1 and s.events["faults"] == 1


class _Watch(SafetyLayer):
    """A safety layer that also notes the penetration of every state it observes."""

    def __init__(self, limits):
        super().__init__(limits)
        self.seen = []

    def observe(self, state):
        self.seen.append(state.penetration_mm)
        super().observe(state)


class _Tilted:
    """A hit tester: the plane through the origin with unit normal (0.6, 0.8, 0)."""

    def query(self, x, y, z):
        return 0, -(0.6 * x + 0.8 * y), 0.6, 0.8, 0.0


def test_safety_layers_observe_the_penetration_along_the_normal():
    """In a spatial scene the safety layers see the penetration along the contact
    normal (what the log holds), not the version-1 -y of the state read."""
    shaker = Shaker(safety=_Watch(Shaker.limits))
    dev = FloatProbe(trajectory=press_slide())
    loop = ServoLoop(dev, [Spring(), Buzz()], {"force": dev, "vib": shaker},
                     hit_tester=_Tilted(), log_seconds=10.0)
    rep = loop.run(1.0)
    pen = rep.log["penetration_mm"]
    np.testing.assert_array_equal(shaker.safety.seen, pen)
    assert np.ptp(pen + rep.log["position_mm"][:, 1]) > 0.1   # differs from -y


def test_a_vibration_role_left_silent_keeps_its_frequency():
    """A tick on which no renderer commands a vibration role sends amplitude 0 at the
    frequency it last had (not None: a frequency the safety layer would ramp from)."""
    class Once(DimensionRenderer):
        roles = ("vib",)

        def tick(self, inp):
            return [ChannelCommand("vib", frequency_hz=180.0, amplitude=0.5)] if inp.t < 0.1 else []

    dev = FloatProbe(trajectory=press_slide())
    rep = ServoLoop(dev, [Spring(), Once()], {"force": dev, "vib": Shaker()}).run(0.3)
    f, a = rep.log["vib.frequency_hz"], rep.log["vib.amplitude"]
    late = rep.log["t"] > 0.15
    assert (f[late] == 180.0).all() and (a[late] == 0.0).all() and late.sum() > 100
