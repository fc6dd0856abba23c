"""``hapticsdk play`` takes ``--device-option`` and ``$HAPTICSDK_DEVICE_OPTIONS`` like
``render`` (issue 31, item 8): .hjif content plays on hardware from the command line
(here the piezo-serial backend on hapticsdk-roughness's emulated serial bridge)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest

emulation = pytest.importorskip("hapticsdk_roughness.emulation")
needs_posix = pytest.mark.skipif(os.name != "posix", reason="the emulated bridge is a pty (POSIX)")


@pytest.fixture(scope="module")
def hjif(tmp_path_factory):
    """S7 exported to .hjif, its vibrotactile channel addressed to piezo-serial."""
    d = tmp_path_factory.mktemp("play")
    env = {**os.environ, "HAPTICSDK_CACHE_DIR": str(d / "cache")}
    out = d / "s7.hjif"
    subprocess.run([sys.executable, "-m", "hapticsdk", "export", "S7", "-o", str(out)], check=True, env=env,
                   capture_output=True, timeout=300)
    target = d / "s7-serial.hjif"
    target.write_text(out.read_text().replace("piezo-virtual", "piezo-serial"))
    return target, env


def _play(hjif, extra, env_opts=None):
    path, base = hjif
    emu = emulation.SerialBridgeEmulator(watchdog_s=0).start()
    env = dict(base)
    env.pop("HAPTICSDK_DEVICE_OPTIONS", None)
    if env_opts is not None:
        env["HAPTICSDK_DEVICE_OPTIONS"] = json.dumps(env_opts(emu.port))
    cmd = [sys.executable, "-m", "hapticsdk", "play", str(path), "--actuators", "piezo-serial",
           "--seconds", "0.3", "--realtime", "--json", *[a.format(port=emu.port) for a in extra]]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    peak = 0.0
    t0 = time.monotonic()
    while proc.poll() is None and time.monotonic() - t0 < 120:
        o = emu.drv.output()
        if o["playing"]:
            peak = max(peak, o["amplitude_v"])
        time.sleep(0.0005)
    out, err = proc.communicate(timeout=60)
    return proc.returncode, out, err, peak, emu


@needs_posix
@pytest.mark.parametrize("how", ["flag", "env"])
def test_play_reaches_the_serial_piezo(hjif, tmp_path, how):
    # a reply budget of 0.5 s, not the board's 0.05 s: the emulated bridge answers from a
    # thread of this test process, on a machine that may have more runnable processes than
    # cores (the same budget as test_stop_signals and test_servo_death_standby)
    if how == "flag":
        code, out, err, peak, emu = _play(hjif, ["--device-option", "piezo-serial.port={port}",
                                                 "--device-option", "piezo-serial.timeout=0.5"])
    else:
        code, out, err, peak, emu = _play(hjif, [], env_opts=lambda port: {"piezo-serial": {"port": port,
                                                                                            "timeout": 0.5}})
    assert code == 0, err[-800:]
    rep = json.loads(out)
    assert rep["actuators"]["piezo-serial"]["active_ticks"] > 0
    assert peak > 1.0, "the emulated DRV2667 never played"
    assert emu.drv.standby and not emu.drv.driving  # left in standby


def test_play_device_option_for_an_actuator_not_selected_is_named(hjif):
    path, env = hjif
    proc = subprocess.run([sys.executable, "-m", "hapticsdk", "play", str(path), "--actuators", "piezo-virtual",
                           "--device-option", "piezo-serial.port=/dev/null"], capture_output=True, text=True,
                          env=env, timeout=120)
    assert proc.returncode == 2 and "--device-option" in proc.stderr and "Traceback" not in proc.stderr
