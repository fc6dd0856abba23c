"""Calibration files: schema, lookup by serial, defaults and their reported source."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hapticsdk.calibration import (PiezoTable, VoiceCoilCalibration, calibrations_in_use, list_calibrations,
                                   load_calibration, read_calibration, save_calibration)
from hapticsdk.errors import ValidationError


def piezo(serial=None, scale=1.0):
    f = np.array([50.0, 100.0, 200.0])
    v = np.array([0.0, 50.0, 100.0])
    return PiezoTable(f, v, scale * np.outer(f / 100.0, v / 10.0), serial=serial, source="bench")


def test_default_when_no_file(tmp_path):
    got = load_calibration("voicecoil", "SN1", directory=tmp_path)
    assert got.origin == "default" and got.calibration == VoiceCoilCalibration.paper()
    assert "paper formula (7)" in got.source and got.path is None
    assert load_calibration("piezo", directory=tmp_path).calibration is None
    got = load_calibration("piezo", "X", directory=tmp_path, default=lambda: piezo())
    assert got.origin == "default" and isinstance(got.calibration, PiezoTable)


def test_lookup_by_serial_then_any(tmp_path):
    vc = VoiceCoilCalibration(coefficients=(0.0001, 0.012, -0.3), source="lab fit", serial="VC-7")
    p_vc = save_calibration(vc, tmp_path)
    assert p_vc.name == "voicecoil-VC-7.json"
    save_calibration(piezo(None, 1.0), tmp_path)
    save_calibration(piezo("PZ-2", 2.0), tmp_path)
    got = load_calibration("voicecoil", "VC-7", directory=tmp_path)
    assert got.origin == "file" and got.calibration == vc and got.path == p_vc
    assert load_calibration("voicecoil", "OTHER", directory=tmp_path).origin == "default"
    exact = load_calibration("piezo", "PZ-2", directory=tmp_path)
    anyone = load_calibration("piezo", "PZ-9", directory=tmp_path)
    assert exact.origin == "file" and anyone.origin == "file-any"
    assert exact.calibration.acceleration_at(100, 50) == pytest.approx(2 * anyone.calibration.acceleration_at(100, 50))
    use = {d["kind"]: d for d in calibrations_in_use({"voicecoil": "VC-7", "piezo": "PZ-9"}, directory=tmp_path)}
    assert use["voicecoil"]["origin"] == "file" and use["piezo"]["origin"] == "file-any"


def test_files_validated_and_bad_files_skipped(tmp_path):
    save_calibration(VoiceCoilCalibration(serial="A"), tmp_path)
    bad = tmp_path / "broken.json"
    bad.write_text(json.dumps({"schema_version": 1, "kind": "voicecoil", "generated": False,
                               "source": "x", "serial": "A", "coefficients": [1, 2]}))
    entries = {e.path.name: e for e in list_calibrations(tmp_path)}
    assert entries["broken.json"].error and "coefficients" in entries["broken.json"].error
    got = load_calibration("voicecoil", "A", directory=tmp_path)
    assert got.origin == "file" and str(bad) in got.skipped
    with pytest.raises(ValidationError):
        read_calibration(bad)


def test_env_directory(tmp_path, monkeypatch):
    monkeypatch.setenv("HAPTICSDK_CALIBRATION_DIR", str(tmp_path / "cal"))
    p = save_calibration(VoiceCoilCalibration(serial="Z", generated=True, source="fit of GENERATED answers"))
    assert p.parent == tmp_path / "cal"
    got = load_calibration("voicecoil", "Z")
    assert got.origin == "file" and got.generated is True


def test_calibration_dir_is_per_user_with_the_environment_override(monkeypatch, tmp_path):
    import platformdirs

    from hapticsdk.calibration import store

    monkeypatch.setenv(store.ENV_DIR, str(tmp_path / "mine"))
    assert store.calibration_dir() == tmp_path / "mine"
    monkeypatch.delenv(store.ENV_DIR)
    # the per-user directory comes from platformdirs (right on Windows and macOS too) ...
    seen = []

    def fake(appname, appauthor=None, **kw):
        seen.append((appname, appauthor))
        return tmp_path / "platform-config" / appname

    monkeypatch.setattr(platformdirs, "user_config_path", fake)
    assert store.calibration_dir() == tmp_path / "platform-config" / "hapticsdk" / "calibration"
    assert seen == [("hapticsdk", False)]
    monkeypatch.undo()
    # ... which on Linux follows XDG_CONFIG_HOME
    import sys
    if sys.platform.startswith("linux"):
        monkeypatch.delenv(store.ENV_DIR, raising=False)
        monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
        assert store.calibration_dir() == tmp_path / "xdg" / "hapticsdk" / "calibration"
