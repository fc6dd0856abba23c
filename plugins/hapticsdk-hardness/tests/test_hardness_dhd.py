"""``dhd`` with the vendor's binding (forcedimension-core) in the loop, against a stand-in
libdrd compiled here from dhd_standin.c (a STAND-IN, not Force Dimension's library)."""

from __future__ import annotations

import ctypes
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.errors import DeviceError, DeviceNotFoundError
from hapticsdk.devices.safety import SafetyLayer
from hapticsdk.testing import DeviceConformance

HERE = Path(__file__).parent


def _binding_symbols() -> set[str]:
    """Every libdrd symbol the installed binding binds at import (it sets argtypes on
    each, so the library must export them all)."""
    spec = importlib.util.find_spec("forcedimension_core")
    root = Path(spec.origin).parent
    names: set[str] = set()
    for f in root.rglob("*.py"):
        names.update(re.findall(r"_libd[hr]d\.(\w+)", f.read_text()))
    return names


def build_standin(sdk: Path, gcc: str) -> Path:
    """Compile dhd_standin.c (+ a stub for every other symbol the binding binds) into
    ``sdk/lib/release/lin-x86_64-gcc/libdrd.so.3.17.0`` (the FDSDK layout the binding
    searches); returns ``sdk``. Also used by bench/bench_dhd_standin.py."""
    src = (HERE / "dhd_standin.c").read_text()
    defined = set(re.findall(r"^\S.*?\b(dhd\w+|drd\w+)\(", src, re.M))
    rest = sorted(_binding_symbols() - defined)
    src += "\n/* generated: bound by the binding, not used by the backend */\n"
    src += "".join(f"int {n}(void) {{ return -1; }}\n" for n in rest)
    libdir = sdk / "lib" / "release" / "lin-x86_64-gcc"
    libdir.mkdir(parents=True, exist_ok=True)
    (sdk / "standin.c").write_text(src)
    out = libdir / "libdrd.so.3.17.0"
    res = subprocess.run([gcc, "-shared", "-fPIC", "-O1", "-o", str(out), str(sdk / "standin.c"), "-lm"],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[:2000]
    return sdk


@pytest.fixture(scope="module")
def standin(tmp_path_factory, missing):
    if importlib.util.find_spec("forcedimension_core") is None:
        missing("the Python package forcedimension-core (pip install hapticsdk-hardness[dhd])")
    gcc = shutil.which("gcc") or shutil.which("cc")
    if gcc is None:
        missing("a C compiler (Debian package gcc)")
    if "forcedimension_core.runtime" in sys.modules:
        pytest.skip("forcedimension_core already imported in this process with another libdrd")
    sdk = build_standin(tmp_path_factory.mktemp("fdsdk"), gcc)
    out = next((sdk / "lib" / "release" / "lin-x86_64-gcc").glob("libdrd.so*"))
    old = os.environ.get("FDSDK")
    lib = ctypes.CDLL(str(out))
    lib.standin_force.argtypes = [ctypes.POINTER(ctypes.c_double)]
    lib.standin_script.argtypes = [ctypes.c_double] * 3
    lib.standin_max_force.argtypes = [ctypes.c_double]
    lib.standin_system_name.argtypes = [ctypes.c_char_p]
    yield str(sdk), lib
    if old is None:
        os.environ.pop("FDSDK", None)
    else:
        os.environ["FDSDK"] = old


def _force(lib):
    v = (ctypes.c_double * 3)()
    lib.standin_force(v)
    return list(v)


def _dev(sdk, **kw):
    from hapticsdk_hardness.dhd import DhdDevice
    return DhdDevice(sdk=sdk, safety=SafetyLayer(DhdDevice.limits, ramp_time_s=0.0), **kw)


def test_missing_binding_or_library_is_named(monkeypatch):
    from hapticsdk_hardness import dhd
    monkeypatch.setattr(dhd.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(DeviceNotFoundError) as ei:
        dhd.DhdDevice().open()
    assert "forcedimension-core" in str(ei.value) and "libdrd" in str(ei.value) and ei.value.device == "dhd"
    ok, why = dhd.DhdDevice.check_available()
    assert not ok and "forcedimension-core" in why


def test_state_force_gravity_and_limits_through_the_binding(standin):
    sdk, lib = standin
    lib.standin_script(0.002, 0.002, 0.1)
    lib.standin_max_force(-1.0)
    dev = _dev(sdk, surface_mm=0.0)
    with dev:
        assert lib.standin_opened() == 1 and lib.standin_gravity() == 1       # compensation on
        assert dev.limits.max_force_n == 12.0 and dev.reported_model == "omega.3"
        st = dev.read_state()
        # DHD (x, y, z) = (1, -2, 2) mm -> SDK (y, z, x) = (-2, 2, 1) mm
        assert st.position_mm == pytest.approx([-2.0, 2.0, 1.0], abs=0.05)
        # a stall of this thread past 50 ms between two lines (a busy machine) gates the
        # safety layer again (a command gap) or lets the device's watchdog write 0, both
        # right and checked below: a try that saw one is made again (for up to 10 s)
        end = time.monotonic() + 10.0
        while True:
            zeroed = dev.watchdog_zeroed
            dev.command(ChannelCommand("force", force_n=0.5))                   # below the start gate
            sent1 = dev.command(ChannelCommand("force", force_n=1.5))
            f1, back = _force(lib), dev.read_back().force_n
            sent = dev.command(ChannelCommand("force", force_n=50.0))
            f2 = _force(lib)
            if (dev.watchdog_zeroed == zeroed and sent1.force_n == 1.5 and sent.force_n == 12.0) or time.monotonic() > end:
                break
        assert lib.standin_force_on() == 1 and f1 == [0.0, 0.0, 1.5]           # SDK y = DHD z
        assert back == 1.5
        assert sent.force_n == 12.0 and f2[2] == 12.0                           # declared omega.3 limit
        t0 = time.monotonic()                                                    # the loop stalls:
        while time.monotonic() - t0 < 10.0 and not (_force(lib) == [0.0, 0.0, 0.0] and dev.watchdog_zeroed >= 1):
            time.sleep(0.005)                                                    # (waits for what it asserts)
        assert _force(lib) == [0.0, 0.0, 0.0] and dev.watchdog_zeroed >= 1      # watchdog zeroed it
        dev.command(ChannelCommand("force", force_n=2.0))
        dev.stop()
        assert _force(lib) == [0.0, 0.0, 0.0] and lib.standin_force_on() == 0
    assert lib.standin_opened() == 0


def test_surface_height_moves_the_sdk_origin(standin):
    """``surface_mm`` is the surface's height along DHD z: the SDK's y (the normal) is the
    handle's height above it, so a handle below the surface reads y < 0 (inside)."""
    sdk, lib = standin
    lib.standin_script(0.002, 0.002, 0.1)
    for surface_mm, y_mm in ((0.5, 1.5), (3.0, -1.0)):
        with _dev(sdk, surface_mm=surface_mm) as dev:
            st = dev.read_state()
            assert st.position_mm == pytest.approx([-2.0, y_mm, 1.0], abs=0.05)


def test_device_force_limit_and_model_read_from_the_device(standin):
    sdk, lib = standin
    lib.standin_max_force(6.0)
    lib.standin_system_name(b"falcon")
    try:
        dev = _dev(sdk)
        with dev:
            assert dev.limits.max_force_n == 6.0                                 # device's own limit wins
            dev.command(ChannelCommand("force", force_n=0.5))
            assert dev.limits.max_stiffness_n_per_mm == 3.0 and dev.encoder_resolution_mm == 0.06
            assert dev.command(ChannelCommand("force", force_n=9.0)).force_n == 6.0
            assert dev.describe()["capabilities"]["bandwidth_hz"] == 500.0
    finally:
        lib.standin_max_force(-1.0)
        lib.standin_system_name(b"omega.3")


def test_transport_error_stops_and_names_the_device(standin):
    sdk, lib = standin
    dev = _dev(sdk, label="omega-left").open()
    try:
        dev.command(ChannelCommand("force", force_n=1.0))
        lib.standin_fail_next()
        with pytest.raises(DeviceError) as ei:
            dev.command(ChannelCommand("force", force_n=1.0))
        assert ei.value.device == "omega-left" and "communication error" in str(ei.value)
        assert _force(lib) == [0.0, 0.0, 0.0] and lib.standin_force_on() == 0
        with pytest.raises(DeviceError):
            dev.read_state()
    finally:
        dev.close()


def test_open_failure_names_the_device_index(standin):
    sdk, _ = standin
    with pytest.raises(DeviceNotFoundError) as ei:
        _dev(sdk, device_id=3).open()
    assert "device 3" in str(ei.value) and "no device found" in str(ei.value)


def test_hardness_at_4_khz_with_the_passivity_controller(standin):
    """The hardness renderer through the servo loop at a 0.25 ms period on the stand-in:
    the finger presses the handle 3 mm below the surface; the wall pushes back along DHD z
    with the loop's passivity controller on the omega.3's declared parameters, and the
    force never exceeds the device's limit."""
    from hapticsdk.runtime import ServoLoop
    from hapticsdk_hardness.dimension import HardnessDimension
    from hapticsdk_hardness.voicecoil import VoiceCoilVirtual
    sdk, lib = standin
    lib.standin_script(0.002, -0.003, 0.2)
    dev = _dev(sdk)
    with dev:
        r = HardnessDimension().renderer({"GS": 1.0})
        loop = ServoLoop(dev, [r], {"force": dev, "coil": VoiceCoilVirtual()}, period_s=0.00025, realtime=True)
        rep = loop.run(0.6)
    L = rep.log
    assert rep.ticks >= 0.6 / 0.00025 * 0.9
    inside = L["penetration_mm"] > 0.2
    assert inside.any()
    f = np.asarray(L["force_n"])
    assert f.max() <= 12.0 + 1e-9 and f[inside].max() > 0.1
    assert "force" in rep.passivity
    assert loop.passivity_settings.position_resolution_mm == dev.model.resolution_mm == 0.01
    # held: finger (0.4 N/mm towards 3 mm deep) against the 1 N/mm wall settles near
    # 0.857 mm, where the wall gives GS x penetration. The tail is the last 600 ticks: the
    # stand-in's clock advances 0.25 ms per position read, one read a tick, so they are its
    # last 0.15 s whatever the wall clock did (on a busy machine the loop skips late ticks
    # and the log's wall time "t" stretches to 1-2 s; a tail by "t" then held the press)
    pen = np.asarray(L["penetration_mm"])[-600:]
    assert pen.std() < 0.05
    assert f[-600:].mean() == pytest.approx(1.0 * pen.mean(), rel=0.1)
    assert pen.mean() == pytest.approx(1.2 / 1.4, rel=0.1)
    assert lib.standin_set_calls() > 0 and _force(lib) == [0.0, 0.0, 0.0]


class TestDhdConformance(DeviceConformance):
    plugin_name = "dhd"

    @pytest.fixture
    def device_factory(self, standin):
        sdk, _ = standin
        return lambda: _dev(sdk)


def test_bench_live_period_reaches_the_session(monkeypatch):
    """`hapticsdk bench live --period 0.00025` runs the session's servo at 0.25 ms."""
    import hapticsdk.runtime.session as session
    from hapticsdk.benchmarks import live
    from hapticsdk.cli import main

    class Seen(Exception):
        pass
    seen: dict = {}

    def fake_session(*a, **kw):
        seen.update(kw)
        raise Seen
    monkeypatch.setattr(session, "Session", fake_session)
    monkeypatch.setattr(live, "switch_figures", lambda: {})
    try:
        main(["bench", "live", "--period", "0.00025", "--seconds", "1"])
    except Seen:
        pass
    assert seen["period_s"] == 0.00025
