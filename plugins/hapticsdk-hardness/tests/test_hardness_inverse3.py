"""``inverse3`` against a FAKE of Haply's ``HaplyHardwareAPI`` module: the serial
protocol is not published, so the wire is untested (docs/devices.md). The fake
follows the vendor module's Python API (checked against the installed module when it is
there): ``detect_inverse3s``, ``SerialStream(port)``, ``Inverse3(stream, timeout)``,
``device_wakeup_dict()``, ``end_effector_force(force) -> (position m, velocity m/s)``."""

from __future__ import annotations

import importlib.machinery
import importlib.util
import time
import types

import pytest

from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import DeviceError, DeviceNotFoundError
from hapticsdk.devices.safety import SafetyLayer
from hapticsdk.testing import DeviceConformance


class _FakeInverse3:
    """Kinematic end effector at (0.01, 0.13, z) m, z given by the test; records forces."""

    ports = ["/dev/ttyACM7"]
    z = 0.002
    forces: list = []
    fail_after: int | None = None

    def __init__(self, stream, timeout=5.0):
        self.stream, self.timeout = stream, timeout

    def device_wakeup_dict(self):
        return {"device_id": 4242, "device_model_number": 60, "firmware_version": 7}

    def end_effector_force(self, force=(0.0, 0.0, 0.0)):
        cls = type(self)
        if cls.fail_after is not None:
            if cls.fail_after <= 0:
                raise RuntimeError("serial read timed out")
            cls.fail_after -= 1
        cls.forces.append(list(force))
        return [0.01, 0.13, cls.z], [0.0, 0.0, -0.02]


def _fake_module():
    m = types.ModuleType("HaplyHardwareAPI")
    m.__spec__ = importlib.machinery.ModuleSpec("HaplyHardwareAPI", None)
    m.__doc__ = "fake HaplyHardwareAPI (tests)"

    class SerialStream:
        def __init__(self, port):
            if port not in _FakeInverse3.ports:
                raise RuntimeError(f"cannot open {port}")
            self.port = port
    m.SerialStream = SerialStream
    m.Inverse3 = _FakeInverse3
    m.detect_inverse3s = lambda: list(_FakeInverse3.ports)
    return m


@pytest.fixture
def fake(monkeypatch):
    monkeypatch.setitem(__import__("sys").modules, "HaplyHardwareAPI", _fake_module())
    _FakeInverse3.forces = []
    _FakeInverse3.z = 0.002
    _FakeInverse3.fail_after = None
    _FakeInverse3.ports = ["/dev/ttyACM7"]
    return _FakeInverse3


def _dev(**kw):
    from hapticsdk_hardness.inverse3 import Inverse3
    return Inverse3(safety=SafetyLayer(Inverse3.limits, ramp_time_s=0.0), **kw)


def test_fake_follows_the_vendor_module(missing):
    """The names and call shapes the backend uses exist in the installed vendor module."""
    if importlib.util.find_spec("HaplyHardwareAPI") is None:
        missing("the Python package haplyhardwareapi (pip install hapticsdk-hardness[haply])")
    import HaplyHardwareAPI as h
    for name in ("detect_inverse3s", "SerialStream", "Inverse3"):
        assert hasattr(h, name), name
    for name in ("device_wakeup_dict", "end_effector_force"):
        assert hasattr(h.Inverse3, name), name
    assert "-> tuple" in h.Inverse3.end_effector_force.__doc__
    assert "-> dict" in h.Inverse3.device_wakeup_dict.__doc__
    assert "timeout: float" in h.Inverse3.__init__.__doc__ and "arg0: str" in h.SerialStream.__init__.__doc__


def test_missing_module_is_named(monkeypatch):
    from hapticsdk_hardness import inverse3
    monkeypatch.setattr(inverse3.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(DeviceNotFoundError) as ei:
        inverse3.Inverse3().open()
    assert "HaplyHardwareAPI" in str(ei.value) and "hapticsdk-hardness[haply]" in str(ei.value)
    assert not inverse3.Inverse3.check_available()[0]


def test_no_device_found(fake):
    fake.ports = []
    with pytest.raises(DeviceNotFoundError, match="no Inverse3 found"):
        _dev().open()
    fake.ports = ["/dev/ttyACM7"]
    with pytest.raises(DeviceNotFoundError, match="/dev/ttyACM9"):
        _dev(port="/dev/ttyACM9").open()


def test_state_force_frames_and_stop(fake):
    dev = _dev(surface_mm=1.0)
    with dev:
        assert dev.port_used == "/dev/ttyACM7" and dev.device_info["device_id"] == 4242
        st = dev.read_state()
        # device (x, y, z) = (10, 130, 2) mm -> SDK (x, z - surface, y) = (10, 1, 130) mm
        assert st.position_mm.tolist() == pytest.approx([10.0, 1.0, 130.0])
        assert st.velocity_mm_s.tolist() == pytest.approx([0.0, -20.0, 0.0])
        # a stall of this thread past 50 ms between two lines (a busy machine) gates the
        # safety layer again (a command gap) or lets the device's watchdog send 0, both
        # right and checked below: a try that saw one is made again (for up to 10 s)
        end = time.monotonic() + 10.0
        while True:
            zeroed = dev.watchdog_zeroed
            dev.command(ChannelCommand("force", force_n=0.5))
            sent1 = dev.command(ChannelCommand("force", force_n=2.0))
            f1 = list(fake.forces[-1])
            sent2 = dev.command(ChannelCommand("force", force_n=9.0))
            dev.read_state()
            f2 = list(fake.forces[-1])
            if (dev.watchdog_zeroed == zeroed and sent1.force_n == 2.0 and sent2.force_n == 3.3) \
                    or time.monotonic() > end:
                break
        assert f1 == [0.0, 0.0, 2.0]                                       # SDK y = device z
        assert sent2.force_n == 3.3
        assert f2 == [0.0, 0.0, 3.3]                                       # a read re-sends the force
        t0 = time.monotonic()                            # the loop stalls (waits for what it asserts)
        while time.monotonic() - t0 < 10.0 and not (fake.forces[-1] == [0.0, 0.0, 0.0] and dev.watchdog_zeroed >= 1):
            time.sleep(0.005)
        assert fake.forces[-1] == [0.0, 0.0, 0.0] and dev.watchdog_zeroed >= 1
        dev.command(ChannelCommand("force", force_n=1.0))
        dev.stop()
        assert fake.forces[-1] == [0.0, 0.0, 0.0]
    assert dev.describe()["wire"].startswith("untested")


def test_serial_error_stops_and_names_the_device(fake):
    dev = _dev(label="inv-left").open()
    try:
        dev.command(ChannelCommand("force", force_n=0.5))
        fake.fail_after = 0
        with pytest.raises(DeviceError) as ei:
            dev.command(ChannelCommand("force", force_n=1.0))
        assert ei.value.device == "inv-left" and "timed out" in str(ei.value)
        with pytest.raises(DeviceError):
            dev.read_state()
    finally:
        fake.fail_after = None
        dev.close()


def test_capabilities_published():
    from hapticsdk_hardness.inverse3 import Inverse3
    cap = Inverse3.capabilities()
    assert cap["max_force_n"] == 3.3 and cap["bandwidth_hz"] == 2000.0 and cap["resolution_mm"] == 0.01


class TestInverse3Conformance(DeviceConformance):
    plugin_name = "inverse3"

    @pytest.fixture
    def device_factory(self, fake):
        return lambda: _dev()


def test_watchdog_deadline_is_the_safety_layers_restart_gap(fake):
    """The default ``command_timeout_s`` is the safety layer's ``restart_after_s``: force
    the watchdog cut comes back gated and ramped from zero, never as a step."""
    from hapticsdk.devices.safety import SafetySettings
    from hapticsdk_hardness.inverse3 import Inverse3
    assert Inverse3().command_timeout_s == SafetySettings().restart_after_s
    safety = SafetyLayer(Inverse3.limits, settings=SafetySettings(restart_after_s=0.03))
    dev = Inverse3(safety=safety, surface_mm=2.5)
    assert dev.command_timeout_s == 0.03
    with dev:
        dev.command(ChannelCommand("force", force_n=0.5))
        # the ramp reaches full force (waits for it: on a busy machine a gap between two
        # commands longer than restart_after_s, 30 ms, gates and ramps again, as it should)
        t_end = time.monotonic() + 10.0
        dev.command(ChannelCommand("force", force_n=2.0))
        while fake.forces[-1] != [0.0, 0.0, 2.0] and time.monotonic() < t_end:
            dev.command(ChannelCommand("force", force_n=2.0))
            time.sleep(0.001)
        assert fake.forces[-1] == [0.0, 0.0, 2.0]
        t0 = time.monotonic()                            # the servo stalls (waits for what it asserts)
        while time.monotonic() - t0 < 10.0 and not (fake.forces[-1] == [0.0, 0.0, 0.0] and dev.watchdog_zeroed >= 1):
            time.sleep(0.005)
        assert fake.forces[-1] == [0.0, 0.0, 0.0] and dev.watchdog_zeroed >= 1
        sent = dev.command(ChannelCommand("force", force_n=2.0))
        assert sent.force_n < 0.5 and fake.forces[-1][2] < 0.5     # resumes from zero
