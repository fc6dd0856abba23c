"""`hapticsdk doctor`: every backend reported, broken plugins named, JSON shape."""

from __future__ import annotations

import argparse
import json
from importlib import metadata

import pytest

from hapticsdk import doctor
from hapticsdk.devices.actuators import Actuator
from hapticsdk.plugins import registry


class _Raising(Actuator):
    name = "doctor-raising"

    @classmethod
    def check_available(cls):
        raise RuntimeError("driver probe exploded")

    def _command(self, cmd):
        pass

    def _stop(self):
        pass


class _BadDiscover(_Raising):
    name = "doctor-baddiscover"

    @classmethod
    def check_available(cls):
        return True, "fine"

    @classmethod
    def discover(cls):
        raise OSError("bus scan failed")


@pytest.fixture
def broken_plugins():
    reg = registry("actuator")
    table = reg._table()
    ep = metadata.EntryPoint(name="doctor-broken", value="hapticsdk_no_such_module_xyz:Thing",
                             group="hapticsdk.actuators")
    table["doctor-broken"] = ep
    reg.register("doctor-raising", _Raising)
    reg.register("doctor-baddiscover", _BadDiscover)
    yield
    table.pop("doctor-broken", None)
    reg.unregister("doctor-raising")
    reg.unregister("doctor-baddiscover")


def test_collect_reports_every_backend_and_survives_broken_ones(broken_plugins):
    rep = doctor.collect()
    assert set(rep) >= {"backends", "devices", "calibrations", "libraries"}
    b = rep["backends"]
    names = set(registry("actuator").names())
    assert names <= set(b)                                   # every installed backend listed
    assert not b["doctor-broken"]["available"]
    assert "hapticsdk_no_such_module_xyz" in b["doctor-broken"]["reason"]
    assert not b["doctor-raising"]["available"] and "driver probe exploded" in b["doctor-raising"]["reason"]
    assert b["doctor-baddiscover"]["available"]
    assert any(d["backend"] == "doctor-baddiscover" and "bus scan failed" in d["error"] for d in rep["devices"])
    if "piezo-virtual" in b:                                 # the ones after the broken ones still checked
        assert b["piezo-virtual"]["available"] and b["piezo-virtual"]["simulated"]
        assert any(c.get("kind") == "piezo" and c.get("generated") for c in rep["calibrations"])
    assert any(c.get("kind") == "voicecoil" for c in rep["calibrations"])
    for lib in rep["libraries"].values():
        assert isinstance(lib["found"], bool) and lib["detail"]


def test_cli_doctor_json_and_text(broken_plugins, capsys, tmp_path, monkeypatch):
    from hapticsdk.cli.doctor import handle_doctor, register

    cal = tmp_path / "piezo-SN1.json"
    from hapticsdk.calibration import PiezoTable
    table = PiezoTable([50.0, 100.0], [0.0, 50.0, 100.0], [[0.0, 1.0, 2.0], [0.0, 2.0, 4.0]],
                       generated=False, source="bench")
    from hapticsdk.calibration.store import save_calibration
    save_calibration(table, path=cal)
    (tmp_path / "broken.json").write_text("{not json")
    monkeypatch.setenv("HAPTICSDK_CALIBRATION_DIR", str(tmp_path))
    assert handle_doctor(argparse.Namespace(json=True)) == 0
    out = json.loads(capsys.readouterr().out)
    assert {"backends", "devices", "calibrations"} <= set(out)
    assert out["backends"]["doctor-broken"]["available"] is False
    files = {c.get("path"): c for c in out["calibrations"] if c.get("path")}
    assert files[str(cal)]["source"] == "bench" and "error" in files[str(tmp_path / "broken.json")]
    assert handle_doctor(argparse.Namespace(json=False)) == 0
    text = capsys.readouterr().out
    assert "doctor-broken" in text and "backends:" in text
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args(["doctor", "--json"])
    assert args.json and args.func is handle_doctor
