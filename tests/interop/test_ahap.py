"""Apple AHAP import and play: events, parameters, curves and dynamic parameters become
the amplitude and frequency the format defines; bad AHAP is a named error with its JSON
path; audio events are reported by name, not played. Every file is written here from the
format's structure."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hapticsdk.cli import main
from hapticsdk.errors import FormatError
from hapticsdk.interop.ahap import SHARPNESS_HZ, parse_ahap, sharpness_to_hz, to_haptic_file
from hapticsdk.interop.hjif_synth import synthesize

FS = 8000.0


def event(t, kind="HapticContinuous", dur=None, intensity=None, sharpness=None, **extra):
    e = {"Time": t, "EventType": kind, **extra}
    if dur is not None:
        e["EventDuration"] = dur
    prm = []
    if intensity is not None:
        prm.append({"ParameterID": "HapticIntensity", "ParameterValue": intensity})
    if sharpness is not None:
        prm.append({"ParameterID": "HapticSharpness", "ParameterValue": sharpness})
    e["EventParameters"] = prm
    return {"Event": e}


def curve(pid, t, points):
    return {"ParameterCurve": {"ParameterID": pid, "Time": t,
                               "ParameterCurveControlPoints": [{"Time": a, "ParameterValue": v} for a, v in points]}}


def ahap(*entries):
    return {"Version": 1.0, "Metadata": {"Project": "test"}, "Pattern": list(entries)}


def synth(doc):
    return synthesize(to_haptic_file(parse_ahap(doc)), fs=FS).channels[0].samples


def test_sharpness_maps_linearly_onto_the_documented_band():
    assert sharpness_to_hz(0.0) == SHARPNESS_HZ[0] == 65.0
    assert sharpness_to_hz(1.0) == SHARPNESS_HZ[1] == 300.0
    assert sharpness_to_hz(0.5) == pytest.approx(182.5)


def test_a_continuous_event_is_a_sine_at_its_sharpness_and_intensity():
    x = synth(ahap(event(0.1, dur=0.5, intensity=0.6, sharpness=0.4)))
    t = np.arange(x.size) / FS
    f = 65.0 + 0.4 * 235.0
    inside = (t >= 0.1) & (t <= 0.6)
    np.testing.assert_allclose(x[inside], 0.6 * np.sin(2 * np.pi * f * (t[inside] - 0.1)), atol=1e-9)
    assert np.all(x[t < 0.1] == 0)


def test_an_intensity_curve_multiplies_and_a_sharpness_curve_adds():
    doc = ahap(event(0.0, dur=1.0, intensity=0.8, sharpness=0.2),
               curve("HapticIntensityControl", 0.0, [(0.0, 1.0), (0.5, 0.5), (1.0, 0.0)]),
               curve("HapticSharpnessControl", 0.0, [(0.0, 0.0), (1.0, 0.5)]))
    h = to_haptic_file(parse_ahap(doc))
    kfs = h.perceptions[0].channels[0].bands[0].effects[0].keyframes
    # the envelope is intensity x control; frequency follows sharpness + control
    assert kfs[0].amplitude_modulation == pytest.approx(0.8) and kfs[-1].amplitude_modulation == pytest.approx(0.0)
    assert kfs[0].frequency_modulation == pytest.approx(sharpness_to_hz(0.2))
    assert kfs[-1].frequency_modulation == pytest.approx(sharpness_to_hz(0.7))
    x = synth(doc)
    t = np.arange(x.size) / FS
    # envelope at mid-time: 0.8 x 0.5 (a multiplier, not an offset: 0.8 + 0.5 - 1 would be 0.3)
    mid = (t > 0.49) & (t < 0.51)
    assert np.max(np.abs(x[mid])) == pytest.approx(0.4, abs=0.01)
    assert kfs[1].amplitude_modulation == pytest.approx(0.4)


def test_a_dynamic_parameter_is_a_step():
    doc = ahap(event(0.0, dur=1.0, intensity=1.0, sharpness=0.5),
               {"Parameter": {"ParameterID": "HapticIntensityControl", "Time": 0.5, "ParameterValue": 0.25}})
    x = synth(doc)
    t = np.arange(x.size) / FS
    assert np.max(np.abs(x[(t > 0.3) & (t < 0.49)])) == pytest.approx(1.0, abs=1e-3)
    assert np.max(np.abs(x[(t > 0.51) & (t < 0.9)])) == pytest.approx(0.25, abs=1e-3)


def test_a_transient_is_two_periods_at_its_sharpness():
    x = synth(ahap(event(0.2, kind="HapticTransient", intensity=0.7, sharpness=1.0)))
    nz = np.flatnonzero(np.abs(x) > 1e-12)
    length_s = (nz[-1] - nz[0] + 1) / FS
    assert length_s == pytest.approx(2.0 / 300.0, abs=2.0 / FS)
    assert np.max(np.abs(x)) == pytest.approx(0.7, abs=0.01)
    assert nz[0] / FS == pytest.approx(0.2, abs=1.0 / FS)


def test_out_of_range_values_are_clamped_and_reported():
    pat = parse_ahap(ahap(event(0.0, dur=45.0, intensity=1.7, sharpness=-0.2)))
    paths = {c["path"] for c in pat.clamped}
    assert paths == {"Pattern[0].Event.EventDuration", "Pattern[0].Event.EventParameters[0].ParameterValue",
                     "Pattern[0].Event.EventParameters[1].ParameterValue"}
    assert pat.events[0].duration_s == 30.0 and pat.events[0].intensity == 1.0 and pat.events[0].sharpness == 0.0


def test_audio_events_are_reported_by_name_not_played():
    pat = parse_ahap(ahap({"Event": {"Time": 0, "EventType": "AudioCustom", "EventWaveformPath": "click.wav"}},
                          event(0.0, dur=0.1, intensity=0.5, sharpness=0.5)))
    assert len(pat.events) == 1
    assert pat.not_played[0]["path"] == "Pattern[0].Event" and "AudioCustom" in pat.not_played[0]["what"]
    assert "click.wav" in pat.not_played[0]["what"]


@pytest.mark.parametrize("doc,path,words", [
    ({"Version": 1}, "$", "'Pattern'"),
    (ahap({"Event": {"EventType": "HapticTransient"}}), "Pattern[0].Event", "'Time'"),
    (ahap({"Event": {"Time": "0", "EventType": "HapticTransient"}}), "Pattern[0].Event.Time", "number"),
    (ahap({"Event": {"Time": 0, "EventType": "HapticBuzz"}}), "Pattern[0].Event.EventType", "HapticBuzz"),
    (ahap({"Event": {"Time": 0, "EventType": "HapticContinuous"}}), "Pattern[0].Event", "'EventDuration'"),
    (ahap(event(0, dur=0.1), {"Event": {}, "Parameter": {}}), "Pattern[1]", "exactly one"),
    (ahap(curve("HapticIntensityControl", 0, [(0.5, 1), (0.2, 0)])),
     "Pattern[0].ParameterCurve.ParameterCurveControlPoints[1].Time", "order"),
    (ahap({"Event": {"Time": 0, "EventType": "HapticTransient",
                     "EventParameters": [{"ParameterID": "HapticIntensity", "ParameterValue": None}]}}),
     "Pattern[0].Event.EventParameters[0].ParameterValue", "number"),
    ([], "$", "object"),
    (ahap({"Event": {"Time": 1e308, "EventType": "HapticTransient"}}), "Pattern[0].Event.Time", "beyond"),
    (ahap(curve("HapticIntensityControl", 1.0, [(0.0, 1), (1e300, 0)])),
     "Pattern[0].ParameterCurve.ParameterCurveControlPoints[1].Time", "beyond"),
])
def test_bad_ahap_is_a_named_error_with_its_path(doc, path, words):
    with pytest.raises(FormatError) as ei:
        parse_ahap(doc)
    assert ei.value.field == path and words in str(ei.value)


def test_cli_import_and_play(tmp_path, capsys):
    p = tmp_path / "boing.ahap"
    p.write_text(json.dumps(ahap(event(0.0, kind="HapticTransient", intensity=0.8, sharpness=0.4),
                                 event(0.015, dur=0.25, intensity=0.8, sharpness=0.4),
                                 curve("HapticIntensityControl", 0.015, [(0, 1), (0.1, 0.5), (0.25, 0.0)]),
                                 {"Event": {"Time": 0, "EventType": "AudioContinuous"}})), encoding="utf-8")
    assert main(["import", str(p), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["format"] == "AHAP" and s["events"] == {"HapticTransient": 1, "HapticContinuous": 1}
    assert s["not_played"][0]["what"] == "AudioContinuous event"
    assert main(["play", str(p), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    piezo, coil = rep["actuators"]["piezo-virtual"], rep["actuators"]["voicecoil-virtual"]
    assert piezo["active_ticks"] > 200 and piezo["output_max_v"] > 0
    assert coil["active_ticks"] > 200
    assert any(u["what"] == "AudioContinuous event" for u in rep["not_played"])


def test_cli_bad_ahap_exits_2_naming_the_path(tmp_path, capsys):
    p = tmp_path / "bad.ahap"
    p.write_text(json.dumps(ahap({"Event": {"Time": -1, "EventType": "HapticTransient",
                                            "EventParameters": [{"ParameterID": "HapticSharpness",
                                                                 "ParameterValue": "high"}]}})), encoding="utf-8")
    assert main(["play", str(p)]) == 2
    assert "Pattern[0].Event.EventParameters[0].ParameterValue" in capsys.readouterr().err


def test_ahap_files_have_the_hjif_size_and_depth_caps(tmp_path, monkeypatch, capsys):
    import pathlib

    from hjif_docs import refused_unread

    from hapticsdk.interop.ahap import read_ahap
    from hapticsdk.interop.hjif_model import MAX_DEPTH, MAX_FILE_BYTES

    huge = tmp_path / "huge.ahap"
    ei = refused_unread(read_ahap, huge, monkeypatch, MAX_FILE_BYTES + 1)  # sparse: no 32 MiB written
    assert ei.value.field == str(huge)
    real_open = pathlib.Path.open
    # a file that grows past the cap after its size was taken is never read whole
    small = tmp_path / "small.ahap"
    small.write_text(json.dumps(ahap(event(0.0, dur=0.1))), encoding="utf-8")
    read_ahap(small)
    with pytest.raises(FormatError, match="cap"):
        read_ahap(small, max_bytes=20)
    reads = []

    class Grown:
        def __init__(self, path):
            self.fh = real_open(path, "rb")

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

        def read(self, n=-1):
            reads.append(n)
            return b" " * (n if n >= 0 else 10 ** 6)

    monkeypatch.setattr(pathlib.Path, "open", lambda self, *a, **k: Grown(self))
    with pytest.raises(FormatError, match="cap"):
        read_ahap(small, max_bytes=small.stat().st_size)
    monkeypatch.setattr(pathlib.Path, "open", real_open)
    assert reads == [small.stat().st_size + 1]
    deep = tmp_path / "deep.ahap"
    deep.write_text("[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1), encoding="utf-8")
    assert main(["import", str(deep)]) == 2
    assert "nested" in capsys.readouterr().err


@pytest.mark.parametrize("gain", [0, 1, 3])
def test_full_intensity_is_one_acceleration_at_every_sharpness_within_the_piezos_declared_maximum(gain):
    # full scale (AHAP intensity 1.0) is the acceleration the piezo reaches at every
    # frequency of the content within its own declared maximum voltage: the weakest
    # frequency is driven at that maximum, no command is clipped by the safety layer, and
    # every sharpness gives the same acceleration by the piezo's table
    from hapticsdk.interop.hjif_play import _piezo_table, play

    table = _piezo_table(None)
    opts = {"piezo-virtual": {"gain": gain}}
    accs, volts = [], []
    for s in np.linspace(0.0, 1.0, 6):
        h = to_haptic_file(parse_ahap(ahap(event(0.0, dur=0.05, intensity=1.0, sharpness=float(s)))))
        info = play(h, actuators=["piezo-virtual"], piezo_full_scale=True, actuator_options=opts
                    ).to_dict()["actuators"]["piezo-virtual"]
        assert "max_amplitude" not in info["safety"]["limit_hits"]
        volts.append(info["max_amplitude"])
        accs.append(table.acceleration_at(sharpness_to_hz(float(s)), info["max_amplitude"]))
    declared = (25.0, 50.0, 75.0, 100.0)[gain]  # DRV2667 full scale per gain (V peak)
    assert max(volts) == pytest.approx(min(declared, float(table.voltages_v[-1])), rel=1e-9)
    assert accs == pytest.approx([accs[0]] * len(accs), rel=1e-6)


def test_cli_play_gives_ahap_amplitudes_as_fractions_of_the_piezos_full_scale(tmp_path, capsys):
    p = tmp_path / "full.ahap"
    p.write_text(json.dumps(ahap(event(0.0, dur=0.05, intensity=1.0, sharpness=0.0))), encoding="utf-8")
    assert main(["play", str(p), "--actuators", "piezo-virtual", "--device-option", "piezo-virtual.gain=1",
                 "--json"]) == 0
    info = json.loads(capsys.readouterr().out)["actuators"]["piezo-virtual"]
    # sharpness 0 is the weakest frequency of the generated table's band: full intensity
    # drives it at the declared 50 V peak of DRV2667 gain 1 (not 1 m/s^2, not clipped)
    assert info["max_amplitude"] == pytest.approx(50.0, rel=1e-9)
    assert "max_amplitude" not in info["safety"]["limit_hits"]


def test_the_summary_duration_is_the_end_of_the_content_played():
    # a transient's length follows the sharpness control at its time, in the summary as in
    # the converted content
    from hapticsdk.interop.ahap import summary
    from hapticsdk.interop.hjif_synth import file_duration_s

    pat = parse_ahap(ahap(event(0.5, kind="HapticTransient", intensity=1.0, sharpness=0.0),
                          {"Parameter": {"ParameterID": "HapticSharpnessControl", "Time": 0.0, "ParameterValue": 1.0}}))
    assert summary(pat)["duration_s"] == pytest.approx(0.5 + 2.0 / SHARPNESS_HZ[1], abs=1.0 / 10000)
    assert summary(pat)["duration_s"] == pytest.approx(file_duration_s(to_haptic_file(pat)), abs=1.0 / 10000)


@pytest.mark.parametrize("kind", ["HapticContinuous", "HapticTransient"])
def test_the_latest_time_read_still_fits_the_position_field(kind):
    """An event at the latest time read, as long as an event can be (a continuous event at
    Apple's 30 s cap; a transient at the lowest frequency), ends within the converted
    content's 2^31 - 1 ticks; one tick later is a named error."""
    from hapticsdk.interop.ahap import MAX_TIME_S, TIMESCALE
    dur = 30.0 if kind == "HapticContinuous" else None
    h = to_haptic_file(parse_ahap(ahap(event(MAX_TIME_S, kind=kind, dur=dur, sharpness=0.0))))
    ends = [e.position + e.keyframes[-1].relative_position
            for b in h.perceptions[0].channels[0].bands for e in b.effects]
    assert ends and max(ends) <= 2 ** 31 - 1
    with pytest.raises(FormatError):
        parse_ahap(ahap(event(MAX_TIME_S + 1.0 / TIMESCALE, kind=kind, dur=dur)))


def test_a_curve_that_starts_late_interpolates_between_its_own_points():
    """Control points are relative to the curve's Time: a curve at 0.5 s with points at
    0 and 0.4 s runs from 0.5 to 0.9 s, linear between them (halfway at 0.7 s), held
    before and after; the envelope of a full-intensity event follows it."""
    doc = ahap(event(0.0, dur=1.5, intensity=1.0, sharpness=0.5),
               curve("HapticIntensityControl", 0.5, [(0.0, 1.0), (0.2, 0.6), (0.4, 0.2)]))
    pat = parse_ahap(doc)
    c = pat.controls[0]
    assert c.points == [(0.5, 1.0), (0.7, 0.6), (0.9, 0.2)]
    for t, v in ((0.6, 0.8), (0.8, 0.4), (0.85, 0.3), (0.4, 1.0), (1.2, 0.2)):
        assert c.value(t) == pytest.approx(v, abs=1e-12), t
        assert pat.control("HapticIntensityControl", t) == pytest.approx(v if t >= 0.5 else 1.0, abs=1e-12), t
    x = synth(doc)
    t = np.arange(x.size) / FS
    around = (t > 0.795) & (t < 0.805)
    assert np.max(np.abs(x[around])) == pytest.approx(0.4, abs=0.01)


def test_without_a_control_intensity_is_as_given_and_sharpness_unshifted():
    """Before any control change the intensity control is 1 (a multiplier) and the
    sharpness control 0 (an offset)."""
    pat = parse_ahap(ahap(event(0.0, dur=1.0, intensity=0.7, sharpness=0.3)))
    assert pat.control("HapticIntensityControl", 0.5) == 1.0
    assert pat.control("HapticSharpnessControl", 0.5) == 0.0
    kfs = to_haptic_file(pat).perceptions[0].channels[0].bands[0].effects[0].keyframes
    assert all(k.amplitude_modulation == pytest.approx(0.7) for k in kfs if k.amplitude_modulation is not None)


def test_the_summary_counts_controls_per_parameter():
    from hapticsdk.interop.ahap import summary
    doc = ahap(event(0.0, dur=1.0, intensity=0.7),
               curve("HapticIntensityControl", 0.0, [(0.0, 1.0), (1.0, 0.5)]),
               curve("HapticIntensityControl", 0.5, [(0.0, 0.5), (0.5, 1.0)]),
               curve("HapticSharpnessControl", 0.0, [(0.0, 0.0), (1.0, 0.5)]))
    s = summary(parse_ahap(doc))
    assert s["controls"] == {"HapticIntensityControl": 2, "HapticSharpnessControl": 1}
    assert s["events"] == {"HapticTransient": 0, "HapticContinuous": 1}
