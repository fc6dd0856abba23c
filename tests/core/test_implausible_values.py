"""Implausible values are refused with named errors, not clamped later (issue 13, item 10),
and one exit-status rule for an unreached target in ``solve``, ``render`` and ``plan``."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hapticsdk.calibration import PiezoTable, VoiceCoilCalibration, fit_voicecoil
from hapticsdk.calibration.piezo import check_table_limits
from hapticsdk.errors import CalibrationError, RecordingError, ValidationError

# --- piezo table: DRV2667 full scale is 100 V peak (200 Vpp); drive frequency > 0 -------


def _table(freqs, volts):
    f = np.asarray(freqs, float)
    v = np.asarray(volts, float)
    return dict(frequencies_hz=f, voltages_v=v, acceleration=np.outer(np.ones(f.size), np.arange(v.size) * 0.5))


def test_piezo_table_column_of_10_kv_is_refused():
    with pytest.raises(CalibrationError, match="voltages_v.*10000 V"):
        PiezoTable(**_table([100, 200], [0, 50, 10000]))
    PiezoTable(**_table([100, 200], [0, 50, 100]))  # the DRV2667's own full scale is fine


@pytest.mark.parametrize("freqs", [[-100, 50], [0, 50], [100, 1e5]])
def test_piezo_table_frequency_outside_drive_range_is_refused(freqs):
    with pytest.raises(CalibrationError, match="frequencies_hz"):
        PiezoTable(**_table(freqs, [0, 10]))


def test_piezo_table_negative_acceleration_is_refused():
    t = _table([100, 200], [0, 10])
    t["acceleration"] = t["acceleration"] - 1.0
    with pytest.raises(CalibrationError, match="acceleration_m_s2"):
        PiezoTable(**t)


def test_piezo_table_is_checked_against_the_device_limits():
    from hapticsdk.devices.actuators import ActuatorLimits

    table = PiezoTable(**_table([100, 200], [0, 50, 100]))
    with pytest.raises(CalibrationError, match="voltages_v.*declared maximum 25 V"):
        check_table_limits(table, ActuatorLimits(max_amplitude=25.0, amplitude_unit="V"))
    with pytest.raises(CalibrationError, match="frequencies_hz"):
        check_table_limits(table, ActuatorLimits(frequency_range_hz=(150.0, 1000.0)))
    check_table_limits(table, ActuatorLimits(frequency_range_hz=(7.8125, 1992.0), max_amplitude=100.0,
                                             amplitude_unit="V"))


# --- voice coil: curve range, amplifier gain -------------------------------------------


def test_voicecoil_curve_over_1e5_to_1e6_hz_is_refused():
    with pytest.raises(CalibrationError, match="frequency_range_hz.*2000 Hz"):
        VoiceCoilCalibration(coefficients=(1e-12, 1e-6, 0.0), frequency_range_hz=(1e5, 1e6))
    with pytest.raises(CalibrationError):
        VoiceCoilCalibration.from_dict({"kind": "voicecoil", "coefficients": [1e-12, 1e-6, 0.0],
                                        "frequency_range_hz": [1e5, 1e6]})


@pytest.mark.parametrize("gain", [-1.0, 0.0, float("nan"), float("inf"), True, "2"])
def test_bad_amplifier_gain_is_refused(gain):
    with pytest.raises(CalibrationError, match="amplifier_gain"):
        VoiceCoilCalibration(amplifier_gain=gain)


def test_nan_gain_is_refused_before_the_fit_and_never_reaches_a_file(tmp_path):
    from hapticsdk.calibration import generate_answers, save_calibration

    ans = generate_answers(people=3, seed=1)
    with pytest.raises(CalibrationError, match="amplifier_gain"):
        fit_voicecoil(ans, amplifier_gain=float("nan"))
    res = fit_voicecoil(ans, amplifier_gain=2.0)
    p = save_calibration(res.calibration, path=tmp_path / "vc.json")
    text = p.read_text()
    assert "NaN" not in text and json.loads(text)["amplifier_gain"] == 2.0


def test_voicecoil_calibration_is_checked_against_the_device_range():
    from hapticsdk.devices.actuators import ActuatorLimits

    cal = VoiceCoilCalibration()  # the paper's 30..120 Hz
    cal.check_limits(ActuatorLimits(frequency_range_hz=(1.0, 1000.0)))
    with pytest.raises(CalibrationError, match="frequency_range_hz"):
        cal.check_limits(ActuatorLimits(frequency_range_hz=(50.0, 1000.0)))


# --- bool is not a number ----------------------------------------------------------------


@pytest.mark.parametrize("value", [True, False, np.bool_(True)])
def test_bool_is_not_an_intensity(value):
    from hapticsdk.perception.dimensions import check_intensity

    with pytest.raises(ValidationError, match="must be a number"):
        check_intensity(value, "targets.hardness")


def test_check_number_refuses_bool_nan_and_range():
    from hapticsdk.checks import check_number, check_seed

    assert check_number(np.float32(2.5), "x", minimum=0) == 2.5
    for bad in (True, np.bool_(False), "1", None, float("nan"), math.inf):
        with pytest.raises(ValidationError):
            check_number(bad, "x")
    with pytest.raises(ValidationError, match="x: 5 is above the maximum 4"):
        check_number(5, "x", maximum=4)
    assert check_seed(np.int64(3)) == 3 and check_seed(None) is None
    for bad in (True, -1, 1.0, "1", 2 ** 64):
        with pytest.raises(ValidationError):
            check_seed(bad)


def test_solve_and_scenes_refuse_true_as_a_target():
    from hapticsdk.solvers.problems import solve
    from hapticsdk.scene import Scene

    with pytest.raises(ValidationError):
        solve({"hardness": True, "roughness": 0.5}, seed=0)
    with pytest.raises(ValidationError, match="targets.hardness"):
        Scene.for_material({"hardness": True})


# --- run file header: limits come from the device class, a header may only narrow -----


def _run(tmp_path, device):
    n = 4
    header = {"format": "hapticsdk-run", "version": 1, "period_s": 1e-3, "device": device}
    p = tmp_path / "run.npz"
    np.savez(p, t=np.arange(n) * 1e-3, state_t=np.arange(n) * 1e-3, position_mm=np.zeros((n, 3)),
             velocity_mm_s=np.zeros((n, 3)), device_force_n=np.zeros((n, 3)), buttons=np.zeros(n, np.int64),
             header_json=np.array(json.dumps(header)))
    return p


def test_run_header_granting_1e9_newton_is_refused(tmp_path):
    from hapticsdk.runlog import PlaybackDevice

    p = _run(tmp_path, {"name": "omni-virtual", "limits": {"max_force_n": 1e9}})
    with pytest.raises(RecordingError) as ei:
        PlaybackDevice(run=p)
    assert ei.value.field == "runlog.header_json.device.limits.max_force_n"


def test_run_header_may_narrow_and_unknown_devices_get_the_default_limits(tmp_path):
    from hapticsdk.runlog import PLAYBACK_DEFAULT_LIMITS, PlaybackDevice

    dev = PlaybackDevice(run=_run(tmp_path, {"name": "omni-virtual", "limits": {"max_force_n": 1.5}}))
    assert dev.limits.max_force_n == 1.5 and dev.limits.max_stiffness_n_per_mm == 2.3
    # an unknown device name cannot bring its own (unlimited) limits
    dev = PlaybackDevice(run=_run(tmp_path, {"name": "no-such-device"}))
    assert dev.limits == PLAYBACK_DEFAULT_LIMITS
    with pytest.raises(RecordingError):
        PlaybackDevice(run=_run(tmp_path, {"name": "no-such-device", "limits": {"max_force_n": 50.0}}))


@pytest.mark.parametrize("settings,field", [
    ({"ramp_time_s": "off"}, "ramp_time_s"), ({"stale_after_s": True}, "stale_after_s"),
    ({"ramp_time_s": -1.0}, "ramp_time_s"), ({"velocity_knee": float("nan")}, "velocity_knee"),
    ({"ramp_amplitude": "yes"}, "ramp_amplitude"), ("off", "safety_settings")])
def test_run_header_safety_settings_are_checked_as_data(tmp_path, settings, field):
    from hapticsdk.runlog import PlaybackDevice

    with pytest.raises(RecordingError) as ei:
        PlaybackDevice(run=_run(tmp_path, {"name": "omni-virtual", "safety_settings": settings}))
    assert ei.value.field.startswith("runlog.header_json.device.safety_settings") and field in ei.value.field


# --- plan features against their ranges --------------------------------------------------


@pytest.fixture(scope="module")
def plan_dict():
    from hapticsdk.compiler import compile_scene
    from hapticsdk.scene import Scene

    return compile_scene(Scene.for_material("S7")).to_dict()


def test_plan_with_gs_1e6_is_refused_on_load(plan_dict, tmp_path):
    from hapticsdk.plan import RenderPlan

    good = tmp_path / "good.json"
    good.write_text(json.dumps(plan_dict))
    RenderPlan.load(good)
    bad = json.loads(json.dumps(plan_dict))
    name = next(iter(bad["materials"]))
    bad["materials"][name]["features"]["GS"] = 1e6
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(bad))
    with pytest.raises(ValidationError) as ei:
        RenderPlan.load(p)
    assert ei.value.field == f"plan.materials.{name}.features.GS"


# --- recording manifests name files inside their folder only ----------------------------


@pytest.mark.parametrize("name", ["/etc/passwd", "../x.npz", "a/../../x.npz", "..", "", "C:/x.npz"])
def test_manifest_paths_outside_the_folder_are_refused(tmp_path, name):
    from hapticsdk.training.recordings import path_inside

    with pytest.raises(RecordingError):
        path_inside(tmp_path, name, field="trials.0.file")


def test_manifest_paths_inside_the_folder_are_kept(tmp_path):
    from hapticsdk.training.recordings import path_inside

    assert path_inside(tmp_path, "trials/a/../S1.npz", field="f") == tmp_path / "trials" / "S1.npz"


# --- one rule for an unreached target ----------------------------------------------------


def test_unreached_target_exits_1_in_solve_render_and_plan(tmp_path, capsys):
    from hapticsdk.cli import main

    # hardness 1.0 with roughness 0.0 lies outside what the shipped model reaches
    unreached = ["--hardness", "1", "--roughness", "0"]
    assert main(["solve", *unreached, "--seed", "1", "--json"]) == 1
    assert json.loads(capsys.readouterr().out)["success"] is False
    assert main(["render", *unreached, "--seconds", "0.05", "--json"]) == 1
    assert json.loads(capsys.readouterr().out)["solve"]["success"] is False
    scene = tmp_path / "unreached.json"
    scene.write_text(json.dumps({"objects": [{"material": {"intensities": {"hardness": 1.0, "roughness": 0.0}}}],
                                 "settings": {"solver": {"seed": 1}}}))
    assert main(["plan", str(scene), "--json"]) == 1
    capsys.readouterr()
    # and a reached one exits 0 in all three
    assert main(["solve", "--hardness", "0.5", "--roughness", "0.4", "--seed", "1"]) == 0
    assert main(["render", "S7", "--seconds", "0.05"]) == 0
    assert main(["plan", "S7"]) == 0
