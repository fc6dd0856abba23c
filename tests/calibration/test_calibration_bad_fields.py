"""Calibration objects read from a file or a dict: a field that is not what the schema
says raises CalibrationError / ValidationError, never OverflowError or UnboundLocalError,
and no value is silently made up: "1" or True is not a coefficient, "false" is not a
flag (bool("false") is True), 1e308 coefficients give no infinite curve, 1e308 is no
count of readings."""

import json

import pytest
from json_leaves import replaced as _bad

from hapticsdk.calibration import PiezoTable, VoiceCoilCalibration
from hapticsdk.calibration.damping import DampingCalibration
from hapticsdk.calibration.store import calibration_to_dict, read_calibration
from hapticsdk.errors import CalibrationError, HapticSDKError, ValidationError

DAMPING = dict(trusted_damping_ns_per_m=0.5, damping_ns_per_m=1.0, worst_error_ns_per_m=0.5, mass_kg=0.05,
               period_s=0.001, resolution_mm=0.01, readings=1000)


def _piezo():
    return PiezoTable(frequencies_hz=[50.0, 100.0], voltages_v=[10.0, 50.0], acceleration=[[1.0, 5.0], [2.0, 10.0]])


VC_CASES = [(("coefficients", 0), v) for v in ("1", True, 10 ** 400, 1e308, -1e308)] + \
           [(("frequency_range_hz", 0), v) for v in ("1", True, 10 ** 400)] + \
           [(("amplifier_gain",), 10 ** 400), (("generated",), "false"), (("generated",), 0),
            (("confidence_intervals",), "1"), (("confidence_intervals",), [["0.1", 0.2]])]


@pytest.mark.parametrize("path, value", VC_CASES)
def test_voicecoil_bad_field_is_refused(path, value):
    data = _bad(calibration_to_dict(VoiceCoilCalibration()), path, value)
    with pytest.raises((CalibrationError, ValidationError)):
        VoiceCoilCalibration.from_dict(data)


@pytest.mark.parametrize("path, value", [(("coefficients", 0), 1e308), (("coefficients", 0), -1e308),
                                         (("coefficients", 0), 10 ** 400), (("amplifier_gain",), 10 ** 400)])
def test_voicecoil_file_with_huge_numbers_is_refused(tmp_path, path, value):
    p = tmp_path / "vc.json"
    p.write_text(json.dumps(_bad(calibration_to_dict(VoiceCoilCalibration()), path, value)))
    with pytest.raises(HapticSDKError):
        read_calibration(p)


@pytest.mark.parametrize("value", ["false", 0, None, [], 1])
def test_piezo_generated_must_be_a_bool(value):
    with pytest.raises(CalibrationError, match="generated"):
        PiezoTable.from_dict(_bad(calibration_to_dict(_piezo()), ("generated",), value))


@pytest.mark.parametrize("key, value", [("readings", "1"), ("readings", True), ("readings", None),
                                        ("readings", -1), ("readings", 0), ("readings", 1e308),
                                        ("readings", 10 ** 400), ("readings", 2.5),
                                        ("generated", "false"), ("generated", 0)])
def test_damping_count_and_flag_are_checked(key, value):
    with pytest.raises(ValidationError) as exc:
        DampingCalibration.from_dict({**DAMPING, key: value})
    assert exc.value.field == key


def test_good_calibrations_still_read(tmp_path):
    assert VoiceCoilCalibration.from_dict(calibration_to_dict(VoiceCoilCalibration())) == VoiceCoilCalibration()
    assert PiezoTable.from_dict(calibration_to_dict(_piezo())).generated is False
    dc = DampingCalibration.from_dict({**DAMPING, "readings": 1000.0, "generated": True})
    assert dc.readings == 1000 and dc.generated
