"""The three real backends of issue 28 in `hapticsdk plugins` and `hapticsdk doctor`:
listed, and, where their library is missing, named with what to install."""

from __future__ import annotations

import importlib.util

import pytest

NEW = ("voicecoil-audio", "dhd", "inverse3")


def test_plugins_lists_the_new_actuators():
    from hapticsdk.plugins import list_plugins
    rows = {r["name"]: r for r in list_plugins(["actuator"], check=True)}
    for name in NEW:
        assert name in rows and rows[name]["distribution"] == "hapticsdk-hardness"
        assert not rows[name].get("error")


def test_doctor_names_what_is_missing(monkeypatch):
    from hapticsdk import doctor
    from hapticsdk_hardness import audio, dhd, inverse3
    real = importlib.util.find_spec
    gone = {"sounddevice", "forcedimension_core", "HaplyHardwareAPI"}
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name in gone else real(name, *a))
    monkeypatch.setattr(audio.importlib, "import_module", lambda name: (_ for _ in ()).throw(ImportError(name)))
    rep = doctor.collect()
    b = rep["backends"]
    assert not b["dhd"]["available"] and "hapticsdk-hardness[dhd]" in b["dhd"]["reason"]
    assert not b["inverse3"]["available"] and "hapticsdk-hardness[haply]" in b["inverse3"]["reason"]
    assert not b["voicecoil-audio"]["available"] and "libportaudio2" in b["voicecoil-audio"]["reason"]
    libs = rep["libraries"]
    for mod, extra in (("sounddevice", "audio"), ("forcedimension_core", "dhd"), ("HaplyHardwareAPI", "haply")):
        assert not libs[mod]["found"] and f"hapticsdk-hardness[{extra}]" in libs[mod]["detail"]
    assert "libdrd" in libs and "libportaudio" in libs
    text = doctor.format_report(rep)
    for name in NEW:
        assert f"-- {name}" in text


def test_doctor_finds_libdrd_in_fdsdk(monkeypatch, tmp_path):
    from hapticsdk import doctor
    lib = tmp_path / "lib" / "release" / "lin-x86_64-gcc" / "libdrd.so.3.17.0"
    lib.parent.mkdir(parents=True)
    lib.write_bytes(b"")
    monkeypatch.setenv("FDSDK", str(tmp_path))
    monkeypatch.setattr(doctor.ctypes.util, "find_library", lambda name: None)
    libs = doctor.check_libraries()
    assert libs["libdrd"]["found"] and libs["libdrd"]["detail"] == str(lib)
    monkeypatch.setenv("FDSDK", str(tmp_path / "elsewhere"))
    assert not doctor.check_libraries()["libdrd"]["found"]
