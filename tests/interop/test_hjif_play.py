"""Playback of .hjif vibrotactile content on the simulated piezo and voice coil: the
actuators output the effects' frequencies, amplitudes go through each actuator's
calibration and the safety layer, unsupported parts are reported, and every exit path
stops the actuators."""

from __future__ import annotations

import numpy as np
import pytest
from hjif_docs import band, basis, channel, doc, kf, perception, tone

import hapticsdk.devices.actuators as acts
from hapticsdk.interop.hjif_model import parse_hjif
from hapticsdk.interop.hjif_play import play


@pytest.fixture
def spy(monkeypatch):
    """Actuators created by play(), in order."""
    made = []
    real = acts.create_actuator

    def create(name, **kw):
        a = real(name, **kw)
        made.append(a)
        return a

    monkeypatch.setattr(acts, "create_actuator", create)
    return made


def two_channel_doc():
    devices = [{"id": 1, "name": "voicecoil-virtual", "type": "VCA"}]
    return doc([perception([channel([band([tone(180, 400, amp=0.5)])]),
                            channel([band([tone(60, 400, amp=0.8)])], cid=1, reference_device_id=1)],
                           devices=devices),
                perception([channel([band([basis(0, [kf(0, 0.5), kf(100, 0.5)])], band_type="Curve",
                                          curve_type="Linear", lo=0, hi=72)])], modality="Stiffness", pid=1)])


def peak(x, fs):
    mag = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(x.size)))
    return np.argmax(mag) * fs / x.size


def test_actuators_output_the_routed_channels_frequencies(spy):
    h = parse_hjif(two_channel_doc())
    rep = play(h)
    piezo, coil = rep.actuators["piezo-virtual"], rep.actuators["voicecoil-virtual"]
    # channel 0 (no reference device) plays on both; channel 1 names the voice coil
    assert [r["actuators"] for r in rep.routing] == [["piezo-virtual", "voicecoil-virtual"], ["voicecoil-virtual"]]
    assert piezo["frequency_hz"] == [180.0, 180.0]
    assert coil["frequency_hz"] == [60.0, 60.0]  # the louder component (0.8 > 0.5)
    # 0.4 s of output: FFT bins 2.5 Hz apart
    assert abs(piezo["output_peak_frequency_hz"] - 180.0) <= 2.5
    assert abs(coil["output_peak_frequency_hz"] - 60.0) <= 2.5
    assert coil["max_amplitude"] == pytest.approx(0.8)  # normalised drive
    assert rep.notes == ["voicecoil-virtual: 400 tick(s) where 2 channels overlap; the loudest one is played"]
    assert [u["path"] for u in rep.not_played] == ["perceptions[1]"]
    assert all(not a.is_open for a in spy)


def test_piezo_amplitude_comes_from_its_table_at_the_requested_acceleration(spy):
    from hapticsdk_roughness.table import resolve_table

    d = doc([perception([channel([band([tone(150, 300, amp=1.0)])], gain=2.0)], perception_unit_exponent=0)])
    rep = play(parse_hjif(d), actuators=["piezo-virtual"])
    want, _ = resolve_table(None).voltage_for(150.0, 2.0)  # 1.0 x gain 2 x 10^0 = 2 m/s^2
    assert rep.actuators["piezo-virtual"]["max_amplitude"] == pytest.approx(want)
    _, v = spy[0].waveform()
    assert np.max(np.abs(v)) == pytest.approx(want, rel=1e-6)


def test_out_of_range_amplitude_is_clamped_by_the_safety_layer(spy):
    d = doc([perception([channel([band([tone(100, 200, amp=1.0)])], gain=3.0)])])
    rep = play(parse_hjif(d), actuators=["voicecoil-virtual"])
    hits = rep.actuators["voicecoil-virtual"]["safety"]["limit_hits"]
    assert hits.get("max_amplitude", 0) > 0


def test_channel_naming_an_unselected_actuator_is_reported_not_played(spy):
    d = doc([perception([channel([band([tone(100, 200)])], reference_device_id=1)],
                        devices=[{"id": 1, "name": "voicecoil-virtual"}])])
    rep = play(parse_hjif(d), actuators=["piezo-virtual"])
    assert rep.actuators == {} and spy == []
    assert "voicecoil-virtual" in rep.not_played[0]["reason"]


@pytest.mark.parametrize("exc", [KeyboardInterrupt, RuntimeError, SystemExit, MemoryError])
def test_every_exit_path_stops_and_closes_the_actuators(spy, monkeypatch, exc):
    h = parse_hjif(two_channel_doc())
    real_create = acts.create_actuator

    def create(name, **kw):  # the voice coil fails on its 50th command
        a = real_create(name, **kw)
        if name == "voicecoil-virtual":
            calls = {"n": 0}
            orig = a.command

            def command(cmd, **k):
                calls["n"] += 1
                if calls["n"] == 50:
                    raise exc("boom")
                return orig(cmd, **k)
            a.command = command
        return a

    monkeypatch.setattr(acts, "create_actuator", create)
    stops = []
    for cls_name in ("piezo-virtual", "voicecoil-virtual"):
        from hapticsdk.plugins import registry
        cls = registry("actuator").load(cls_name)
        orig_stop = cls.stop
        monkeypatch.setattr(cls, "stop", lambda self, _o=orig_stop: (stops.append(self.name), _o(self))[1])
    with pytest.raises(exc):
        play(h)
    made = spy
    assert {a.name for a in made} == {"piezo-virtual", "voicecoil-virtual"}
    assert all(not a.is_open for a in made)
    assert set(stops) == {"piezo-virtual", "voicecoil-virtual"}
    piezo = next(a for a in made if a.name == "piezo-virtual")
    assert not piezo.driving  # output ramped to zero


def test_real_encoder_quirks_play(spy):
    """The shape MPEG's reference encoder writes for an AHAP input: modality 'Other',
    a local date with a space, a Transient band whose keyframes name a frequency, float
    amplitudes of single precision, an effect without base signal or phase."""
    d = {"version": "2023", "profile": "Main", "level": 1, "date": "2024-03-01 10:11:12", "description": "",
         "timescale": 1000, "avatars": [],
         "perceptions": [{"id": 0, "avatar_id": 0, "description": "", "perception_modality": "Other",
                          "reference_devices": [], "effect_library": [],
                          "channels": [{"id": 0, "description": "placeholder description", "gain": 1.0,
                                        "mixing_coefficient": 1.0, "body_part_mask": 0, "bands": [
                                            {"band_type": "Transient", "lower_frequency_limit": 65,
                                             "upper_frequency_limit": 300, "effects": [
                                                {"effect_type": "Basis", "position": 0, "keyframes": [
                                                    {"relative_position": 0, "amplitude_modulation": 0.6335999965667725,
                                                     "frequency_modulation": 300}]}]},
                                            {"band_type": "VectorialWave", "lower_frequency_limit": 65,
                                             "upper_frequency_limit": 300, "effects": [
                                                {"effect_type": "Basis", "position": 15, "phase": 0.0,
                                                 "base_signal": "Sine", "keyframes": [
                                                    {"relative_position": 0, "amplitude_modulation": 0.49,
                                                     "frequency_modulation": 159},
                                                    {"relative_position": 250, "amplitude_modulation": 0.0,
                                                     "frequency_modulation": 218}]}]}]}]}],
         "syncs": []}
    rep = play(parse_hjif(d))
    lo, hi = rep.actuators["voicecoil-virtual"]["frequency_hz"]
    assert lo == pytest.approx(1000 / 11)  # the transient: two periods in 22 ms
    assert 159 <= hi <= 218  # the chirp
    assert rep.not_played == []


@pytest.mark.parametrize("real", [False, True])
def test_a_real_actuator_plays_in_real_time(monkeypatch, real):
    """Content played on a real actuator (not ``simulated``) is paced on the clock even
    without ``realtime``: back to back, the file's 0.4 s would be over in milliseconds."""
    import time
    make = acts.create_actuator

    def create(name, **kw):
        a = make(name, **kw)
        if real and name == "voicecoil-virtual":
            a.simulated = False     # stands for a sound-card coil
        return a
    monkeypatch.setattr(acts, "create_actuator", create)
    h = parse_hjif(two_channel_doc())
    t0 = time.monotonic()
    rep = play(h)
    wall = time.monotonic() - t0
    assert rep.realtime is real
    if real:
        assert wall >= 0.9 * rep.seconds   # paced: at least the content's length, less a tick or so
