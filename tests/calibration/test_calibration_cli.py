"""`hapticsdk calibrate ...` and `hapticsdk replay` handlers."""

from __future__ import annotations

import json

import pytest

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


def test_calibrate_damping_write_play_fit_save_list(tmp_path, capsys):
    """The hands-off damping calibration end to end: the excitation written, played on the
    simulated arm (as a user plays it on theirs), the recorded run fitted and saved for a
    serial, then listed; a GENERATED run; a held arm fails and saves nothing."""
    from hapticsdk.calibration.damping import read_excitation_csv
    from hapticsdk.sim.arm import ArmParams, free_arm_readings_mm

    ex = tmp_path / "ex.csv"
    code, out = run_json(capsys, ["calibrate", "damping", "--write-excitation", str(ex), "--period", "0.001"])
    assert code == 0 and out["forces"] > 0
    f = read_excitation_csv(ex)
    y = free_arm_readings_mm(1e-3, ArmParams(mass_kg=0.045, damping_ns_per_m=0.3, encoder_resolution_mm=0.055), f)
    run = tmp_path / "run.csv"
    run.write_text("position_mm,force_n\n" + "".join(f"{float(yi)!r},{float(fi)!r}\n"
                                                     for yi, fi in zip(y, list(f) + [0.0])))
    cal = tmp_path / "cal"
    code, out = run_json(capsys, ["calibrate", "damping", "--run", str(run), "--period", "0.001",
                                  "--resolution", "0.055", "--serial", "ARM-7", "--save", str(cal)])
    assert code == 0 and out["success"] and out["generated"] is False
    assert 0.0 < out["trusted_damping_ns_per_m"] <= 0.3 <= out["trusted_damping_ns_per_m"] + 2 * out[
        "worst_error_ns_per_m"]
    assert out["saved"].endswith("damping-ARM-7.json")
    code, out = run_json(capsys, ["calibrate", "list", "--dir", str(cal), "--serial", "damping=ARM-7"])
    use = {u["kind"]: u for u in out["in_use"]}
    assert use["damping"]["origin"] == "file" and use["damping"]["generated"] is False
    code, out = run_json(capsys, ["calibrate", "damping", "--simulate", "--damping", "0.2"])
    assert code == 0 and out["generated"] is True and out["trusted_damping_ns_per_m"] <= 0.2
    held = tmp_path / "held.csv"
    held.write_text("position_mm,force_n\n" + "".join(f"0.0,{float(fi)!r}\n" for fi in list(f) + [0.0]))
    code, out = run_json(capsys, ["calibrate", "damping", "--run", str(held), "--save", str(tmp_path / "c2")])
    assert code == 1 and not out["success"] and out["saved"] is None
    assert not (tmp_path / "c2").exists()
    assert main(["calibrate", "damping", "--simulate"]) == 0
    assert "lower bound" in capsys.readouterr().out


def test_calibrate_damping_on_a_device_in_real_time(tmp_path, capsys):
    """``calibrate damping --device NAME``: the run played on the named device (the
    simulated Omni nobody holds, stepped by the real elapsed time), fitted, saved for the
    serial, listed; held by a finger, the bound does not rise above the truth."""
    from hapticsdk_hardness.omni import OmniVirtual

    cal = tmp_path / "cal"
    sn = OmniVirtual().serial_number          # the simulated arm's serial: its physics
    assert main(["calibrate", "damping", "--device", "omni-virtual", "--device-option", "finger=none",
                 "--serial", "SIM-7", "--save", str(cal)]) == 2
    assert "reports serial" in capsys.readouterr().err and not cal.exists()
    code, out = run_json(capsys, ["calibrate", "damping", "--device", "omni-virtual", "--device-option",
                                  "finger=none", "--serial", sn, "--save", str(cal)])
    assert code == 0 and out["success"] and out["generated"] is True
    assert 0.0 < out["trusted_damping_ns_per_m"] <= 0.5           # the simulated Omni's damping
    # every step as measured and the stale drops modelled: the fit is within its margin
    assert abs(out["damping_ns_per_m"] - 0.5) <= out["worst_error_ns_per_m"]
    assert out["saved"].endswith(f"damping-{sn}.json") and out["latency_s"] == 0.0 and out["serial"] == sn
    from hapticsdk.calibration.store import load_calibration
    got = load_calibration("damping", sn, directory=cal).calibration
    assert got.resolution_mm == 0.055 and got.generated and got.trusted_damping_ns_per_m == out[
        "trusted_damping_ns_per_m"]                                  # the device's own encoder
    code, out = run_json(capsys, ["calibrate", "list", "--dir", str(cal), "--serial", f"damping={sn}"])
    assert code == 0 and {u["kind"]: u for u in out["in_use"]}["damping"]["origin"] == "file"
    code, out = run_json(capsys, ["calibrate", "damping", "--device", "omni-virtual"])   # the default finger holds it
    assert out["trusted_damping_ns_per_m"] <= 0.5


def test_the_real_time_run_is_summed_up_in_words(capsys):
    import re

    assert main(["calibrate", "damping", "--device", "omni-virtual", "--device-option", "finger=none"]) == 0
    out = capsys.readouterr().out
    m = re.search(r"played in real time: (\d+) late ticks \(over 1.5 periods\) of (\d+), longest step ([\d.]+) ms, "
                  r"latency 0 ms", out)
    assert m, out
    late, steps, longest = int(m[1]), int(m[2]), float(m[3])
    assert 0 <= late <= steps and steps > 500 and longest >= 1.0 - 1e-6   # the longest step is at least the period (1 ms)


@pytest.mark.parametrize("bad", ["finger", "=none", "force.finger"])
def test_a_device_option_without_a_role_is_read_as_key_value(capsys, bad):
    # --device names one device: its options are KEY=VALUE, and a bad one is named as such
    # ("force.finger" has no "=": not an option at all)
    assert main(["calibrate", "damping", "--device", "omni-virtual", "--device-option", bad]) == 2
    err = capsys.readouterr().err
    assert "expected KEY=VALUE" in err and repr(bad) in err and "ROLE" not in err


def test_calibrate_damping_names_a_device_it_cannot_drive(capsys):
    assert main(["calibrate", "damping", "--device", "voicecoil-virtual"]) != 0
    assert "not a force device" in capsys.readouterr().err
