"""`hapticsdk calibrate ...` and `hapticsdk replay` handlers."""

from __future__ import annotations

import json

import numpy as np

from hapticsdk.devices.actuators import DeviceState
from hapticsdk.cli import main
from hapticsdk.perception.dimensions import ChannelCommand
from hapticsdk.runlog import RunRecorder


def run_json(capsys, argv):
    code = main(argv + ["--json"])
    return code, json.loads(capsys.readouterr().out)


def test_calibrate_voicecoil_from_generated_answers(tmp_path, capsys):
    csv = tmp_path / "answers.csv"
    code, out = run_json(capsys, ["calibrate", "answers", str(csv), "--seed", "2"])
    assert code == 0 and out["answers"] == 700 and out["generated"] is True
    assert csv.read_text().startswith("# GENERATED")
    code, out = run_json(capsys, ["calibrate", "voicecoil", str(csv), "--serial", "VC9",
                                  "--save", str(tmp_path / "cal")])
    assert code == 0 and out["success"] and out["generated"]
    assert all(out["paper_inside_intervals"])
    assert len(out["levels"]) == 10 and out["saved"].endswith("voicecoil-VC9.json")
    code, out = run_json(capsys, ["calibrate", "list", "--dir", str(tmp_path / "cal"), "--serial", "voicecoil=VC9"])
    use = {u["kind"]: u for u in out["in_use"]}
    assert use["voicecoil"]["origin"] == "file" and use["voicecoil"]["generated"] is True
    assert use["piezo"]["origin"] == "none"
    assert main(["calibrate", "voicecoil", str(csv)]) == 0
    assert "GS_coil(f)" in capsys.readouterr().out


def test_calibrate_piezo_from_measurements(tmp_path, capsys):
    f, v = np.meshgrid([50.0, 100.0, 200.0, 300.0], np.linspace(0, 50, 6), indexing="ij")
    a = 1e-5 * f ** 2 * np.tanh(v / 40.0)
    p = tmp_path / "m.csv"
    p.write_text("frequency_hz,voltage_v,acceleration_m_s2\n"
                 + "\n".join(f"{x},{y},{z}" for x, y, z in zip(f.ravel(), v.ravel(), a.ravel())))
    code, out = run_json(capsys, ["calibrate", "piezo", str(p), "--out", str(tmp_path / "pz.json")])
    assert code == 0 and out["grid"] == [4, 6] and out["round_trip_max_rel_error"] < 1e-6
    code, out2 = run_json(capsys, ["calibrate", "piezo", str(tmp_path / "pz.json")])
    assert out2["acceleration_range_m_s2"] == out["acceleration_range_m_s2"]


def test_bad_input_is_an_error_exit(tmp_path, capsys):
    p = tmp_path / "bad.csv"
    p.write_text("person,frequency_hz\n1,30\n")
    code = main(["calibrate", "voicecoil", str(p), "--json"])
    assert code == 2 and "missing column" in json.loads(capsys.readouterr().out)["error"]


def test_replay_summary(tmp_path, capsys):
    rec = RunRecorder(tmp_path / "r.npz")
    for k in range(50):
        st = DeviceState(t=k * 1e-3, position_mm=np.array([0.0, -k * 0.01, 0.0]), velocity_mm_s=np.zeros(3))
        rec.record(k * 1e-3, st, {"force": ChannelCommand("force", force_n=0.02 * k)})
    path = rec.close()
    code, out = run_json(capsys, ["replay", str(path)])
    assert code == 0 and out["n_ticks"] == 50 and out["playback_mismatches"] == 0
    assert out["roles"]["force"]["force_n"]["max"] == 0.98
