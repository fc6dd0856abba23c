"""Kit rules ``instances`` (two open instances of an actuator keep separate outputs) and
the sensed-state part of ``state`` (a simulated device's clock advances as it is stepped,
and its position changes as its velocity in mm/s says). Each broken variant is caught by
its rule; the correct ones conform."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import pytest

from hapticsdk.devices.actuators import ActuatorLimits, DeviceState, HapticDevice
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import DeviceError
from hapticsdk.testing import check, check_device
from hapticsdk.testing.conformance import format_report
from kit_variants import API, along_y, rules_of
from kit_variants import OutputArm as Arm


# ---------------------------------------------------------------------------
# instances
# ---------------------------------------------------------------------------

class SharedArm(Arm):
    """Keeps its motor force in a class-level dict: every instance drives one output."""
    name: ClassVar[str] = "kit-arm-shared"
    _hw: ClassVar[dict[str, float]] = {"f": 0.0}

    def _open(self) -> None:
        self.t = 0.0

    def _command(self, cmd: ChannelCommand) -> None:
        self._hw["f"] = float(np.clip(along_y(cmd), -3.0, 3.0))

    def _stop(self) -> None:
        self._hw["f"] = 0.0

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("force", force_n=self._hw["f"])


class LastOpenedArm(Arm):
    """Each instance has its own motors, but commands go to the instance opened last (a
    module-level 'current device' handle)."""
    name: ClassVar[str] = "kit-arm-last-opened"
    _current: ClassVar[list[Any]] = [None]

    def _open(self) -> None:
        super()._open()
        self._current[0] = self

    def _command(self, cmd: ChannelCommand) -> None:
        self._current[0].f = float(np.clip(along_y(cmd), -3.0, 3.0))


class FallbackArm(Arm):
    """Each instance keeps its own force, but one never commanded reads back the driver's
    class-wide last write (a fallback for 'no record yet')."""
    name: ClassVar[str] = "kit-arm-fallback"
    _last: ClassVar[list[float]] = [0.0]

    def _open(self) -> None:
        super()._open()
        self.written = False

    def _command(self, cmd: ChannelCommand) -> None:
        super()._command(cmd)
        self.written = True
        self._last[0] = self.f

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("force", force_n=self.f if self.written else self._last[0])


class SharedPortArm(Arm):
    """Instances share one class-level transport handle: closing one closes it, and the
    other's writes are lost silently from then on."""
    name: ClassVar[str] = "kit-arm-shared-port"
    _port: ClassVar[list[bool]] = [False]

    def _open(self) -> None:
        super()._open()
        self._port[0] = True

    def _command(self, cmd: ChannelCommand) -> None:
        if self._port[0]:
            super()._command(cmd)

    def _close(self) -> None:
        self._port[0] = False


class OnePortArm(Arm):
    """One physical device: a second instance cannot open while the first holds the port."""
    name: ClassVar[str] = "kit-arm-one-port"
    _owner: ClassVar[list[Any]] = [None]

    def _open(self) -> None:
        if self._owner[0] not in (None, self) and self._owner[0].is_open:
            raise OSError("port busy")
        self._owner[0] = self
        super()._open()

    def _close(self) -> None:
        if self._owner[0] is self:
            self._owner[0] = None


@pytest.mark.parametrize("kind", ["actuator", "device"])
@pytest.mark.parametrize("cls", [SharedArm, LastOpenedArm, FallbackArm, SharedPortArm])
def test_instances_sharing_their_output_are_caught(cls, kind):
    v = check(kind, cls)
    assert "instances" in rules_of(v), format_report(v)


def test_separate_instances_conform_and_one_port_is_skipped_with_a_reason():
    assert check_device(Arm) == []
    v = check_device(OnePortArm)
    assert "instances" not in rules_of(v), format_report(v)
    assert "second instance could not open" in v.notes["instances"]
    assert "port busy" in v.notes["instances"]


# ---------------------------------------------------------------------------
# sensed state of a simulated device
# ---------------------------------------------------------------------------

class MovingArm(HapticDevice):
    """A correct simulated arm: a damped mass on one axis (y) under the commanded force,
    read through an encoder of ``encoder_resolution_mm`` with a backward-difference
    velocity; it keeps simulated time."""
    hapticsdk_api = API
    name: ClassVar[str] = "kit-moving-arm"
    simulated: ClassVar[bool] = True
    readback_source: ClassVar[str] = "output"
    limits = ActuatorLimits(max_force_n=3.0)
    encoder_resolution_mm = 0.05
    mass_kg = 0.05
    damping_ns_per_m = 2.0

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self._open()

    def _open(self) -> None:
        self.f, self.t, self.y, self.v = 0.0, 0.0, 0.0, 0.0
        self.y_meas, self.v_meas = 0.0, 0.0

    def _command(self, cmd: ChannelCommand) -> None:
        self.f = float(np.clip(along_y(cmd), -3.0, 3.0))

    def _stop(self) -> None:
        self.f = 0.0

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("force", force_n=self.f)

    def _position(self) -> float:
        return float(np.round(self.y / self.encoder_resolution_mm) * self.encoder_resolution_mm)

    def _read_state(self) -> DeviceState:
        return DeviceState(t=self.t, position_mm=np.array([0.0, self.y_meas, 0.0]),
                           velocity_mm_s=np.array([0.0, self.v_meas, 0.0]), force_n=np.array([0.0, self.f, 0.0]))

    def _step(self, dt: float) -> None:
        a = (self.f - self.damping_ns_per_m * self.v * 1e-3) / self.mass_kg * 1e3   # mm/s^2
        self.v += a * dt
        self.y += self.v * dt
        self.t += dt
        y = self._position()
        self.v_meas = (y - self.y_meas) / dt
        self.y_meas = y


class TrueVelocityArm(MovingArm):
    """Correct too: reports the model's own velocity (not a difference of encoder readings)
    beside the encoder's position, so the two differ by up to a count."""
    name: ClassVar[str] = "kit-arm-true-velocity"

    def _read_state(self) -> DeviceState:
        return DeviceState(t=self.t, position_mm=np.array([0.0, self.y_meas, 0.0]),
                           velocity_mm_s=np.array([0.0, self.v, 0.0]), force_n=np.array([0.0, self.f, 0.0]))


class MetresPerSecondArm(MovingArm):
    name: ClassVar[str] = "kit-arm-m-per-s"

    def _read_state(self) -> DeviceState:
        st = super()._read_state()
        return DeviceState(t=st.t, position_mm=st.position_mm, velocity_mm_s=st.velocity_mm_s / 1000.0,
                           force_n=st.force_n)


class InchArm(MovingArm):
    """Position in inches (25.4 x small) in the mm field."""
    name: ClassVar[str] = "kit-arm-inch"

    def _read_state(self) -> DeviceState:
        st = super()._read_state()
        return DeviceState(t=st.t, position_mm=st.position_mm / 25.4, velocity_mm_s=st.velocity_mm_s,
                           force_n=st.force_n)


class StalePositionArm(MovingArm):
    """Reports the position it had at open: a stale register."""
    name: ClassVar[str] = "kit-arm-stale-position"

    def _read_state(self) -> DeviceState:
        st = super()._read_state()
        return DeviceState(t=st.t, position_mm=np.zeros(3), velocity_mm_s=st.velocity_mm_s, force_n=st.force_n)


class ZeroVelocityArm(MovingArm):
    """Moves, but reports zero velocity (never filled in)."""
    name: ClassVar[str] = "kit-arm-zero-velocity"

    def _read_state(self) -> DeviceState:
        st = super()._read_state()
        return DeviceState(t=st.t, position_mm=st.position_mm, velocity_mm_s=np.zeros(3), force_n=st.force_n)


class FrozenClockArm(MovingArm):
    name: ClassVar[str] = "kit-arm-frozen-clock"

    def _read_state(self) -> DeviceState:
        st = super()._read_state()
        return DeviceState(t=0.0, position_mm=st.position_mm, velocity_mm_s=st.velocity_mm_s, force_n=st.force_n)


class StoppedClockArm(Arm):
    """Does not move (held), and its clock never advances either."""
    name: ClassVar[str] = "kit-arm-stopped-clock"

    def _step(self, dt: float) -> None:
        pass


class MillisecondClockArm(MovingArm):
    """Device time in ms in the s field: its velocity disagrees with position over time."""
    name: ClassVar[str] = "kit-arm-ms-clock"

    def _read_state(self) -> DeviceState:
        st = super()._read_state()
        return DeviceState(t=st.t * 1e3, position_mm=st.position_mm, velocity_mm_s=st.velocity_mm_s,
                           force_n=st.force_n)


@pytest.mark.parametrize("cls", [MovingArm, TrueVelocityArm])
def test_consistent_moving_arms_conform(cls):
    assert check_device(cls) == []


@pytest.mark.parametrize("cls", [MetresPerSecondArm, InchArm, StalePositionArm, ZeroVelocityArm, FrozenClockArm,
                                 StoppedClockArm, MillisecondClockArm])
def test_inconsistent_sensed_state_is_caught(cls):
    v = check_device(cls)
    assert "state" in rules_of(v), format_report(v)


def test_a_real_device_is_not_stepped_for_the_state_rule():
    """A real device keeps time and moves on its own: only the shape checks apply."""
    cls = type("RealFrozenArm", (FrozenClockArm,), {"name": "kit-arm-real", "simulated": False})
    assert "state" not in rules_of(check_device(cls, ))


def test_a_second_instance_that_cannot_open_is_closed_again():
    check_device(OnePortArm)
    second = OnePortArm()
    with OnePortArm():
        with pytest.raises(DeviceError):
            second.open()
        assert not second.is_open


# ---------------------------------------------------------------------------
# lost writes (output-follows-command)
# ---------------------------------------------------------------------------

class EveryOtherWriteArm(Arm):
    """Its transport loses every second write."""
    name: ClassVar[str] = "kit-arm-every-other-write"

    def _open(self) -> None:
        super()._open()
        self.writes = 0

    def _command(self, cmd: ChannelCommand) -> None:
        self.writes += 1
        if self.writes % 2:
            super()._command(cmd)


class ServoThreadEveryOtherWriteArm(EveryOtherWriteArm):
    """Loses every second write too, and its output is what a device-side servo thread
    applies: the motor force while the safety layer holds the command fresh, else zero
    (as the simulated Omni does). It declares a settle time of 5 ms, longer than the
    safety layer's default staleness of one period."""
    name: ClassVar[str] = "kit-arm-servo-thread-every-other"
    limits = ActuatorLimits(max_force_n=3.0, settle_time_s=0.005)

    def _step(self, dt: float) -> None:
        super()._step(dt)
        cur = self.safety.current(self.t)
        self.out = self.f if cur is not None and cur.force_n else 0.0

    def _read_back(self) -> ChannelCommand:
        return ChannelCommand("force", force_n=getattr(self, "out", 0.0) if self.is_open else 0.0)


class OneWriteLateArm(Arm):
    """A one-deep queue: each write applies the previous one."""
    name: ClassVar[str] = "kit-arm-one-write-late"

    def _open(self) -> None:
        super()._open()
        self.queued = 0.0

    def _command(self, cmd: ChannelCommand) -> None:
        self.f, self.queued = self.queued, float(np.clip(along_y(cmd), -3.0, 3.0))


class PerWriteRampArm(Arm):
    """Correct: its driver moves the force at most 0.5 N per write toward the command (a
    ramp counted in writes, one a servo period), and declares the settle time that gives
    at one write a tick from rest to full scale."""
    name: ClassVar[str] = "kit-arm-per-write-ramp"
    limits = ActuatorLimits(max_force_n=3.0, settle_time_s=6 * 0.001)

    def _command(self, cmd: ChannelCommand) -> None:
        target = float(np.clip(along_y(cmd), -3.0, 3.0))
        self.f += float(np.clip(target - self.f, -0.5, 0.5))


def test_a_ramp_counted_in_writes_is_not_a_lost_write():
    assert check_device(PerWriteRampArm) == []


@pytest.mark.parametrize("cls", [EveryOtherWriteArm, ServoThreadEveryOtherWriteArm, OneWriteLateArm])
def test_a_lost_or_late_write_is_caught(cls):
    v = check("actuator", cls)
    assert "output-follows-command" in rules_of(v), format_report(v)
    assert "a lost write" in format_report(v)


def test_the_lost_write_part_leaves_the_safety_settings_as_they_were():
    from hapticsdk.testing.conformance.actuator_drive import _alternate_once
    a = Arm()
    before = a.safety.settings
    with a:
        _alternate_once(a, 0.0)
        assert a.safety.settings == before


# ---------------------------------------------------------------------------
# state: the encoder count a device declares
# ---------------------------------------------------------------------------

def _encoder(base: type, q: Any) -> type:
    """``base`` (quantising its position with ``encoder_resolution_mm``) keeping its true
    count for its physics but declaring ``q``."""
    true_q = base.encoder_resolution_mm

    def _position(self: Any) -> float:
        return float(np.round(self.y / true_q) * true_q)
    return type(f"{base.__name__}Encoder", (base,), {"encoder_resolution_mm": q, "_position": _position})


@pytest.mark.parametrize("q", [0.0, 0.05, np.float32(0.05), None], ids=["0", "0.05", "float32", "none"])
def test_a_declared_encoder_count_that_is_a_number_conforms(q):
    v = check_device(_encoder(MovingArm, q))
    assert v == [], format_report(v)


@pytest.mark.parametrize("base, q", [(MovingArm, float("nan")), (MovingArm, float("inf")), (MovingArm, "0.05"),
                                     (MetresPerSecondArm, float("nan"))],
                         ids=["nan", "inf", "text", "nan-hiding-m-per-s"])
def test_a_declared_encoder_count_that_is_no_number_is_caught_by_state_rule(base, q):
    """A NaN count made the loop's speed step NaN and the kit's kinematics bounds NaN, and
    every comparison with them passed: a velocity in m/s went unseen behind it."""
    v = check("device", _encoder(base, q), rules=["state"])
    assert rules_of(v) == {"state"}, format_report(v)
    assert "declares encoder_resolution_mm" in format_report(v)
