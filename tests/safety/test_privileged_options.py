"""Scene and plan files cannot choose native code to load or files to write (issue 13.1).

Options an actuator declares in ``privileged_options`` are refused when they come from
a scene or a plan (whatever the plugin); they are taken from code (``actuator_options=``),
``--device-option``, ``$HAPTICSDK_DEVICE_OPTIONS`` or the user device configuration file.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any, ClassVar

import pytest

from hapticsdk.devices.actuators import Actuator
from hapticsdk.compiler import compile_scene
from hapticsdk.devices.device_options import (ENV_CONFIG, ENV_OPTIONS, PrivilegedOptionError, parse_device_option,
                                      privileged_options, trusted_options)
from hapticsdk.errors import ValidationError
from hapticsdk.plugins import registry
from hapticsdk.runtime.render import render_plan
from hapticsdk.scene import Scene

needs_hardness = pytest.mark.skipif("voicecoil-virtual" not in registry("actuator"),
                                    reason="hapticsdk-hardness not installed")
HARD = {"hardness": 0.9}
NO_IMPORTANCE = {"enabled": False}


@pytest.fixture(autouse=True)
def _no_user_config(tmp_path, monkeypatch):
    """Keep the user's real configuration out of these tests."""
    monkeypatch.setenv(ENV_CONFIG, str(tmp_path / "no-such-devices.json"))
    monkeypatch.delenv(ENV_OPTIONS, raising=False)


def _scene(devices: dict[str, Any]) -> dict[str, Any]:
    return {"name": "evil", "objects": [{"name": "o", "material": {"name": "m", "intensities": HARD}}],
            "devices": devices, "settings": {"importance": NO_IMPORTANCE}}


def _plan_with(role: str, options: dict[str, Any]) -> dict[str, Any]:
    """A compiled plan (dict, as read from a file) whose role gets ``options``."""
    plan = compile_scene(Scene.for_material(HARD, importance=NO_IMPORTANCE)).to_dict()
    mat = next(iter(plan["materials"].values()))
    mat.setdefault("actuator_options", {})[role] = options
    return plan


@needs_hardness
def test_scene_cannot_name_a_native_library(tmp_path, monkeypatch):
    import ctypes
    loaded = []
    monkeypatch.setattr(ctypes, "CDLL", lambda *a, **k: loaded.append(a) or (_ for _ in ()).throw(OSError()))
    evil = tmp_path / "evil.so"
    evil.write_bytes(b"\x7fELF")
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(_scene({"force": {"actuator": "omni-openhaptics",
                                                 "options": {"library": str(evil)}}})))
    with pytest.raises(PrivilegedOptionError) as ei:
        compile_scene(path)
    err = ei.value
    assert err.field == "scene.devices.force.options.library" and err.option == "library"
    msg = str(err)
    assert "native library" in msg and "--device-option force.library=" in msg
    assert "actuator_options" in msg and ENV_OPTIONS in msg and "devices.json" in msg
    assert loaded == []


@needs_hardness
def test_plan_file_cannot_name_a_native_library(monkeypatch, tmp_path):
    import ctypes
    loaded = []
    monkeypatch.setattr(ctypes, "CDLL", lambda *a, **k: loaded.append(a))
    plan = _plan_with("force", {"library": str(tmp_path / "evil.so")})
    name, mat = next(iter(plan["materials"].items()))
    mat["actuators"]["force"] = "omni-openhaptics"
    with pytest.raises(PrivilegedOptionError) as ei:
        render_plan(plan, seconds=0.01)
    assert ei.value.field == f"plan.materials.{name}.actuator_options.force.library"
    assert loaded == []


@needs_hardness
def test_scene_and_plan_cannot_overwrite_a_file_through_a_wav_sink(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    with pytest.raises(PrivilegedOptionError) as ei:
        compile_scene(_scene({"coil": {"actuator": "voicecoil-virtual", "options": {"sink": f"wav:{victim}"}}}))
    assert ei.value.field == "scene.devices.coil.options.sink" and "output file" in str(ei.value)
    with pytest.raises(PrivilegedOptionError):
        render_plan(_plan_with("coil", {"sink": f"wav:{victim}"}), seconds=0.01)
    assert victim.read_text() == "precious"


@needs_hardness
def test_privileged_options_from_code_env_and_config_are_used(tmp_path, monkeypatch):
    plan = compile_scene(Scene.for_material(HARD, importance=NO_IMPORTANCE))
    wav = tmp_path / "code.wav"
    rep = render_plan(plan, seconds=0.05, actuator_options={"coil": {"sink": f"wav:{wav}"}})
    assert rep.fault is None and wav.stat().st_size > 44
    # a role the material does not have is an error, not silently ignored
    with pytest.raises(ValidationError) as ei:
        render_plan(plan, seconds=0.01, actuator_options={"coyl": {"sink": "buffer"}})
    assert ei.value.field == "actuator_options"
    # environment
    env_wav = tmp_path / "env.wav"
    monkeypatch.setenv(ENV_OPTIONS, json.dumps({"voicecoil-virtual": {"sink": f"wav:{env_wav}"}}))
    render_plan(plan, seconds=0.05)
    assert env_wav.stat().st_size > 44
    monkeypatch.delenv(ENV_OPTIONS)
    # user configuration file (must be the user's own, not writable by others)
    cfg = tmp_path / "devices.json"
    cfg_wav = tmp_path / "cfg.wav"
    cfg.write_text(json.dumps({"voicecoil-virtual": {"sink": f"wav:{cfg_wav}"}}))
    os.chmod(cfg, 0o644)
    monkeypatch.setenv(ENV_CONFIG, str(cfg))
    assert trusted_options("voicecoil-virtual") == {"sink": f"wav:{cfg_wav}"}
    render_plan(plan, seconds=0.05)
    assert cfg_wav.stat().st_size > 44
    os.chmod(cfg, 0o666)
    with pytest.raises(ValidationError, match="not writable by others"):
        trusted_options("voicecoil-virtual")


@needs_hardness
def test_cli_refuses_scene_option_and_takes_device_option(tmp_path):
    victim = tmp_path / "victim.wav"
    victim.write_text("precious")
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(_scene({"coil": {"actuator": "voicecoil-virtual",
                                                 "options": {"sink": f"wav:{victim}"}}})))
    env = dict(os.environ, **{ENV_CONFIG: str(tmp_path / "none.json")})
    env.pop(ENV_OPTIONS, None)
    r = subprocess.run([sys.executable, "-m", "hapticsdk", "render", "--scene", str(scene), "--seconds", "0.05"],
                       capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 2, r.stderr
    assert r.stderr.startswith("hapticsdk: error: scene.devices.coil.options.sink:"), r.stderr
    assert "--device-option coil.sink=" in r.stderr and "Traceback" not in r.stderr
    assert victim.read_text() == "precious"
    out = tmp_path / "asked.wav"
    r = subprocess.run([sys.executable, "-m", "hapticsdk", "render", "--hardness", "0.9", "--seconds", "0.05",
                        "--device-option", f"coil.sink=wav:{out}", "--json"],
                       capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    assert out.stat().st_size > 44


class _Dumper(Actuator):
    """A third-party actuator that writes its commands to a file named by an option."""

    name: ClassVar[str] = "test-dumper"
    channel: ClassVar[str] = "vibration"
    accepts: ClassVar[dict[str, str]] = {"frequency_hz": "Hz", "amplitude": "V"}
    hapticsdk_api: ClassVar[str] = ">=1,<2"
    privileged_options: ClassVar[dict[str, str]] = {"dump_path": "output file"}

    def __init__(self, *, dump_path: str | None = None, gain: float = 1.0, **options: Any) -> None:
        super().__init__(**options)
        self.dump_path = dump_path
        self.gain = gain

    def _open(self) -> None:
        if self.dump_path:
            Path(self.dump_path).write_text("dumped")

    def _command(self, cmd: Any) -> None:
        pass

    def _stop(self) -> None:
        pass


class _Child(_Dumper):
    privileged_options: ClassVar[dict[str, str]] = {"firmware": "firmware image"}


def test_third_party_actuator_declares_a_privileged_option(tmp_path):
    assert privileged_options(_Child) == {"dump_path": "output file", "firmware": "firmware image"}
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    registry("actuator").register("test-dumper", _Dumper)
    try:
        scene = {"objects": [{"name": "o", "material": {"name": "m", "intensities": {"roughness": 0.5}}}],
                 "devices": {"vibration": {"actuator": "test-dumper", "options": {"dump_path": str(victim)}}}}
        with pytest.raises(PrivilegedOptionError) as ei:
            compile_scene(scene)
        assert ei.value.field == "scene.devices.vibration.options.dump_path"
        # a non-privileged option of the same actuator is fine in a scene
        scene["devices"]["vibration"]["options"] = {"gain": 0.5}
        plan = compile_scene(scene).to_dict()
        plan["materials"]["m"]["actuator_options"]["vibration"]["dump_path"] = str(victim)
        with pytest.raises(PrivilegedOptionError):
            render_plan(plan, seconds=0.01)
        assert victim.read_text() == "precious"
        del plan["materials"]["m"]["actuator_options"]["vibration"]["dump_path"]
        out = tmp_path / "wanted.txt"
        rep = render_plan(plan, seconds=0.01, actuator_options={"vibration": {"dump_path": str(out)}})
        assert out.read_text() == "dumped" and rep.devices["test-dumper"]["name"] == "test-dumper"
    finally:
        registry("actuator").unregister("test-dumper")


def test_parse_device_option():
    assert parse_device_option("force.library=/opt/libHD.so") == ("force", "library", "/opt/libHD.so")
    assert parse_device_option("vibration.gain=2") == ("vibration", "gain", 2)
    for bad in ("library=/x", "force.library", ".x=1"):
        with pytest.raises(ValidationError):
            parse_device_option(bad)


@needs_hardness
def test_libhd_loader_refuses_untrusted_candidates(tmp_path, monkeypatch):
    from hapticsdk.errors import DeviceNotFoundError
    from hapticsdk_hardness import openhaptics as oh

    monkeypatch.delenv("HAPTICSDK_LIBHD", raising=False)
    opened = []
    monkeypatch.setattr(oh.ctypes, "CDLL", lambda name, *a, **k: opened.append(name) or (_ for _ in ()).throw(
        OSError("not loaded in this test")))
    monkeypatch.chdir(tmp_path)
    (tmp_path / "libHD.so").write_bytes(b"\x7fELF")
    (tmp_path / "dir.so").mkdir()
    assert oh.check_candidate("libHD.so") is None and oh.check_candidate("libHD.so.3") is None
    assert oh.check_candidate("HD.dll") is None
    assert "HD library name" in oh.check_candidate("libevil.so")
    assert "relative" in oh.check_candidate("./libHD.so")
    assert "regular file" in oh.check_candidate(str(tmp_path / "dir.so"))
    assert oh.check_candidate(str(tmp_path / "libHD.so")) is None
    for bad in ("./libHD.so", "libevil.so", str(tmp_path / "dir.so")):
        opened.clear()
        with pytest.raises(DeviceNotFoundError) as ei:
            oh.load_library(bad)
        assert bad not in opened and "refused" in str(ei.value)


def test_the_device_configuration_is_read_again_when_it_changes(tmp_path, monkeypatch):
    import json as _json

    from hapticsdk.devices.device_options import trusted_options
    from hapticsdk.fileio import atomic_write_json
    cfg = tmp_path / "devices.json"
    monkeypatch.setenv("HAPTICSDK_DEVICE_CONFIG", str(cfg))
    monkeypatch.delenv("HAPTICSDK_DEVICE_OPTIONS", raising=False)
    atomic_write_json(cfg, {"piezo-serial": {"port": "/dev/ttyA", "frequency_range_hz": [50, 500]}})
    assert trusted_options("piezo-serial") == {"port": "/dev/ttyA", "frequency_range_hz": [50, 500]}
    got = trusted_options("piezo-serial")
    got["frequency_range_hz"].append(1)              # a deep copy: the cache is not shared
    assert trusted_options("piezo-serial")["frequency_range_hz"] == [50, 500]
    atomic_write_json(cfg, {"piezo-serial": {"port": "/dev/ttyB"}})
    assert trusted_options("piezo-serial") == {"port": "/dev/ttyB"}
    assert _json.loads(cfg.read_text())["piezo-serial"]["port"] == "/dev/ttyB"
