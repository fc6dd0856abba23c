"""Files of every published shape of the .hjif format read and play, and say what was
normalised by JSON path. The documents are written here from each release's structure
(field names and required fields of the reference reader at that release); no external
content is used."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from hjif_docs import band, basis, channel, doc, kf, perception, single, tone, write

from hapticsdk.cli import main
from hapticsdk.errors import FormatError
from hapticsdk.interop.hjif_model import parse_hjif
from hapticsdk.interop.hjif_synth import synthesize
from hapticsdk.interop.hjif_versions import RELEASES

FS = 8000.0
KFS = [kf(0, 0.2, 90), kf(250, 0.9, 160), kf(500, 0.4, 120)]


def current() -> dict:
    return doc([perception([channel([band([basis(0, copy.deepcopy(KFS)), tone(200, 100, position=600)])])],
                           modality="Vibrotactile")])


def crm0() -> dict:
    """CRM0/CRM1 shape: tracks, 'Wave' bands with encoding_modality and window_length, no
    effect_type / effect_library / profile / level / timescale / syncs."""
    eff = [{"position": 0, "phase": 0.0, "base_signal": "Sine", "keyframes": copy.deepcopy(KFS)},
           {"position": 600, "phase": 0.0, "base_signal": "Sine", "keyframes": [kf(0, 1.0, 200), kf(100, 1.0, 200)]}]
    return {"version": "1.0", "date": "2022-03-01", "description": "crm0", "avatars": [],
            "perceptions": [{"id": 0, "avatar_id": 0, "description": "p", "perception_modality": "Vibration",
                             "reference_devices": [],
                             "tracks": [{"id": 0, "description": "t", "gain": 1.0, "mixing_weight": 1.0,
                                         "body_part_mask": 0,
                                         "bands": [{"band_type": "Wave", "curve_type": "Unknown",
                                                    "encoding_modality": "Vectorial", "window_length": 0,
                                                    "lower_frequency_limit": 0, "upper_frequency_limit": 1000,
                                                    "effects": eff}]}]}]}


def crm2() -> dict:
    """CRM2 shape: tracks and window_length still, VectorialWave bands, effect_library,
    effect_type."""
    d = crm0()
    d["version"] = "2022"
    p = d["perceptions"][0]
    p["effect_library"] = []
    b = p["tracks"][0]["bands"][0]
    del b["encoding_modality"]
    b["band_type"] = "VectorialWave"
    for e in b["effects"]:
        e["effect_type"] = "Basis"
    return d


def crm3() -> dict:
    """CRM3 shape: channels with mixing_weight, curve_type and block_length 0.0 on every
    band, effect 'semantic'; no profile / level / timescale / syncs."""
    d = crm2()
    d["version"] = "2023"
    p = d["perceptions"][0]
    p["channels"] = p.pop("tracks")
    b = p["channels"][0]["bands"][0]
    b["block_length"] = 0.0
    del b["window_length"]
    b["effects"][0]["semantic"] = "ramp"
    return d


def crm32() -> dict:
    """CRM3.1/CRM3.2 shape (October 2023): CRM3 plus profile, level, timescale, syncs."""
    d = crm3()
    d.update({"profile": "Main", "level": 1, "timescale": 1000, "syncs": []})
    return d


SHAPES = [(crm0, RELEASES[0][0]), (crm2, RELEASES[1][0]), (crm3, RELEASES[2][0]), (crm32, RELEASES[2][0]),
          (current, RELEASES[3][0])]


@pytest.mark.parametrize("build,label", SHAPES, ids=["CRM0-1", "CRM2", "CRM3", "CRM3.2", "CRM4"])
def test_every_release_shape_reads_and_synthesises_like_the_current_one(build, label):
    h = parse_hjif(build())
    assert h.format_version.recognised == label
    x = synthesize(h, fs=FS).channels[0].samples
    ref = synthesize(parse_hjif(current()), fs=FS).channels[0].samples
    np.testing.assert_array_equal(x, ref)
    assert np.max(np.abs(x)) > 0.5


def test_normalisations_are_reported_by_json_path():
    h = parse_hjif(crm3())
    ch = {c["path"]: c["change"] for c in h.format_version.changes}
    b = "perceptions[0].channels[0].bands[0]"
    assert "mixing_weight -> mixing_coefficient" in ch["perceptions[0].channels[0].mixing_weight"]
    assert "dropped 0.0" in ch[f"{b}.block_length"]
    assert "semantic -> semantic_keywords" in ch[f"{b}.effects[0].semantic"]
    assert "profile" in ch and "syncs" in ch
    h0 = parse_hjif(crm0())
    ch0 = {c["path"]: c["change"] for c in h0.format_version.changes}
    assert "tracks -> channels" in ch0["perceptions[0].tracks"]
    assert "'VectorialWave'" in ch0[f"{b}.band_type"]
    assert "window_length -> block_length" in ch0[f"{b}.window_length"]
    assert parse_hjif(current()).format_version.changes == []


def test_a_wavelet_band_keeps_an_integral_real_block_length_as_an_integer():
    d = crm32()
    d["perceptions"][0]["channels"][0]["bands"].append(
        {"band_type": "WaveletWave", "curve_type": "Unknown", "block_length": 32.0, "lower_frequency_limit": 72,
         "upper_frequency_limit": 1000,
         "effects": [{"effect_type": "Basis", "position": 0, "phase": 0.0, "base_signal": "Sine",
                      "keyframes": [kf(None, 0.1), kf(None, 0.2)]}]})
    h = parse_hjif(d)
    wb = h.perceptions[0].channels[0].bands[1]
    assert wb.block_length == 32 and isinstance(wb.block_length, int)
    assert h.format_version.legacy_wavelet_samples == ["perceptions[0].channels[0].bands[1].effects[0]"]


def test_both_old_and_new_names_is_a_named_error():
    d = crm3()
    d["perceptions"][0]["channels"][0]["mixing_coefficient"] = 1.0
    with pytest.raises(FormatError) as ei:
        parse_hjif(d)
    assert ei.value.field == "perceptions[0].channels[0].mixing_weight"


def test_a_shape_no_release_reads_is_a_named_error():
    d = crm3()
    del d["perceptions"][0]["channels"][0]["mixing_weight"]
    with pytest.raises(FormatError) as ei:
        parse_hjif(d)
    assert ei.value.field == "perceptions[0].channels[0]" and "mixing_coefficient" in str(ei.value)


# ---------------------------------------------------------------- out-of-order keyframes
def reference_reading(kfs, key, x, default):
    """The reference synthesiser's reading of a file-ordered keyframe list, written from
    its definition: the first keyframe (in file order) with a value at or after x, joined
    by a straight line to the keyframe with a value just before it in file order (the
    line held outside its two ends)."""
    vals = [(k.get("relative_position"), k.get(key)) for k in kfs]
    if key == "frequency_modulation":  # the reference's frequency search reads no position as 0
        vals = [(0 if p is None else p, v) for p, v in vals]
    idx = [i for i, (_, v) in enumerate(vals) if v is not None]
    if not idx:
        return default
    after = [i for i in idx if vals[i][0] is not None and vals[i][0] >= x]
    if not after:
        return vals[idx[-1]][1]
    a = after[0]
    before = [i for i in idx if i < a]
    if not before:
        return vals[a][1]
    (t0, v0), (t1, v1) = vals[before[-1]], vals[a]
    t0 = 0 if t0 is None else t0
    if x < t0:
        return v0
    if x > t1:
        return v1
    (t0, v0), (t1, v1) = sorted([(t0, v0), (t1, v1)])
    return v1 if t1 == t0 else v0 + (v1 - v0) * (x - t0) / (t1 - t0)


def test_a_sentinel_keyframe_first_shadows_the_amplitude_as_the_reference_reads_it():
    # 65535 then 0: the reference's first amplitude keyframe at or after any t is the
    # sentinel, so the amplitude is its 0.3 over the whole span (0..800, the last keyframe
    # in file order); the frequency keyframes are in order (150 Hz)
    kfs = [kf(65535, 0.3), kf(0, None, 150), kf(400, None, 150), kf(800, None, 150)]
    h = parse_hjif(single(basis(0, kfs)))
    changes = h.format_version.changes
    assert changes[0]["path"] == "perceptions[0].channels[0].bands[0].effects[0].keyframes[1]"
    assert "0 after 65535" in changes[0]["change"] and "sentinel" in changes[0]["change"]
    x = synthesize(h, fs=FS).channels[0].samples
    t = np.arange(x.size) / FS
    np.testing.assert_allclose(x[t <= 0.8], 0.3 * np.sin(2 * np.pi * 150 * t[t <= 0.8]), atol=1e-9)
    assert np.all(x[t > 0.8] == 0)


def test_a_shadowed_keyframe_gives_the_step_the_reference_reads():
    kfs = [kf(0, 0.2, 100), kf(600, 0.6), kf(300, 1.0), kf(900, 0.4)]
    h = parse_hjif(single(basis(0, kfs)))
    x = synthesize(h, fs=FS).channels[0].samples
    t_ms = np.arange(x.size) / FS * 1000.0
    env = np.array([reference_reading(kfs, "amplitude_modulation", u, 1.0) for u in t_ms])
    inside = t_ms <= 900
    expect = env[inside] * np.sin(2 * np.pi * 100 * t_ms[inside] / 1000.0)
    # the step at 600 ms: the reading is left-continuous; the sample exactly at 600 ms is
    # the one place where SDK keyframes (left value, then right value) may differ
    away = np.abs(t_ms[inside] - 600.0) > 1e-9
    np.testing.assert_allclose(x[inside][away], expect[away], atol=1e-9)
    assert abs(reference_reading(kfs, "amplitude_modulation", 600.5, 1.0) - 0.6995) < 1e-9  # the step is there


@pytest.mark.parametrize("band_type", ["Transient", "Curve"])
def test_transient_and_curve_keyframes_out_of_order_are_sorted(band_type):
    kfs = [kf(300, 0.5), kf(0, 1.0), kf(600, 0.2)]
    extra = {"curve_type": "Linear"} if band_type == "Curve" else {}
    h = parse_hjif(single(basis(0, kfs), band_type=band_type, lo=0, hi=1000, **extra))
    got = [k.relative_position for k in h.perceptions[0].channels[0].bands[0].effects[0].keyframes]
    assert got == [0, 300, 600]
    assert "sorted" in h.format_version.changes[0]["change"]


def test_import_json_says_which_version_and_what_was_normalised(tmp_path, capsys):
    p = write(tmp_path / "old.hjif", crm3())
    assert main(["import", str(p), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    fv = out["format_version"]
    assert fv["recognised"] == RELEASES[2][0] and fv["version_field"] == "2023"
    assert {"path": "perceptions[0].channels[0].mixing_weight",
            "change": "renamed mixing_weight -> mixing_coefficient"} in fv["normalised"]


@pytest.mark.parametrize("build", [crm0, crm2, crm3, crm32])
def test_play_plays_every_release_shape(tmp_path, capsys, build):
    p = write(tmp_path / "old.hjif", build())
    assert main(["play", str(p), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    piezo = rep["actuators"]["piezo-virtual"]
    assert piezo["active_ticks"] > 500 and piezo["output_max_v"] > 0
    assert {90.0, 200.0} <= set(piezo["frequency_hz"])


@pytest.mark.parametrize("seed", range(40))
def test_random_file_orders_read_as_the_reference_reads_them(seed):
    # random keyframe lists in random order (sentinel positions among them): the SDK's
    # amplitude and frequency over the effect's span equal the reference's reading,
    # written from its definition above, everywhere but at the steps of that reading
    from hapticsdk.interop.hjif_synth import amplitude_track, frequency_breakpoints, frequency_track

    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 9))
    pos = [int(p) for p in rng.choice([0, 10, 50, 120, 300, 450, 700, 65534, 65535], size=n)]
    kfs = []
    for i, p in enumerate(pos):
        amp = float(np.round(rng.uniform(0, 1), 3)) if rng.random() < 0.8 else None
        freq = int(rng.integers(60, 400)) if rng.random() < 0.6 else None
        unpositioned = 0 < i < n - 1 and rng.random() < 0.15  # the last one keeps the length
        kfs.append(kf(None if unpositioned else p, amp, freq))
    h = parse_hjif(single(basis(0, copy.deepcopy(kfs)), lo=0, hi=1000))
    eff = h.perceptions[0].channels[0].bands[0].effects[0]
    span = max(k.relative_position for k in eff.keyframes) if eff.keyframes else 0
    positioned = [k["relative_position"] for k in kfs if "relative_position" in k]
    assert span == positioned[-1]  # the reference's length: the last keyframe in file order
    t = np.linspace(0, span, 997)
    a_ref = np.array([reference_reading(kfs, "amplitude_modulation", x, 1.0) for x in t])
    f_ref = np.array([reference_reading(kfs, "frequency_modulation", x, 0.0) for x in t])
    a_sdk = amplitude_track(eff, t)
    xs, fs = frequency_breakpoints(eff, 0, 1000)
    f_sdk = frequency_track(xs, fs, t)
    at_step = np.isin(t, [0.0] + [float(p) for p in positioned])
    np.testing.assert_allclose(a_sdk[~at_step], a_ref[~at_step], atol=1e-9)
    np.testing.assert_allclose(f_sdk[~at_step], f_ref[~at_step], atol=1e-6)


@pytest.mark.parametrize("build", [crm2, crm3, crm32])
def test_a_timeline_effect_reads_as_composite_and_is_reported(build):
    d = build()
    p = d["perceptions"][0]
    (p.get("tracks") or p["channels"])[0]["bands"][0]["effects"].append({"effect_type": "Timeline", "position": 700})
    h = parse_hjif(d)
    path = "perceptions[0].channels[0].bands[0].effects[2]"
    assert h.perceptions[0].channels[0].bands[0].effects[2].effect_type == "Composite"
    assert "'Timeline'" in {c["path"]: c["change"] for c in h.format_version.changes}[f"{path}.effect_type"]


@pytest.mark.parametrize("field, ok, bad", [
    ("relative_position", [0, 2 ** 31 - 1], [-1, 2 ** 31, 1.5, True, "3"]),
    ("amplitude_modulation", [-1.0, 1.0, 0, 0.25], [-1.0000001, 1.0000001, -1.5, 2, "1", False]),
    ("frequency_modulation", [0.0, 65535.0, 90], [-0.5, 65535.5, 70000, "90", True]),
])
def test_a_keyframe_is_reordered_only_with_every_field_in_the_parser_s_range(field, ok, bad):
    """Out-of-order keyframes are rewritten only when each field is of the type and range
    the parser accepts (position an int in 0..2^31-1, amplitude -1..1, frequency
    0..65535 Hz), so that a bad value is still named at its path as written. The ranges'
    ends are in, one step past them out."""
    from hapticsdk.interop.hjif_versions import _valid_keyframe
    assert all(_valid_keyframe({field: v}) for v in ok)
    assert not any(_valid_keyframe({field: v}) for v in bad)
    assert _valid_keyframe({})


def test_the_reference_reading_keeps_amplitudes_within_one():
    """The rewrite of out-of-order keyframes (``_reference_reading``) extrapolates each
    segment's value back to its start to find steps (``2 a - b``); an amplitude there
    stays in -1..1 where rounding puts it just outside. The two lists are such cases, one
    on each side (found by a random search with the clamp removed: -1.0000000000000002,
    and its mirror image), then drawn lists with amplitudes at the ends of the range."""
    from hapticsdk.interop.hjif_versions import _reference_reading
    low = [{"relative_position": 642, "amplitude_modulation": -0.48346927314974275},
           {"relative_position": 48, "amplitude_modulation": -1.0},
           {"relative_position": 642, "amplitude_modulation": -1.0},
           {"relative_position": 863, "amplitude_modulation": -0.3907261491718934}]
    high = [dict(k, amplitude_modulation=-k["amplitude_modulation"]) for k in low]
    rng = np.random.default_rng(4)
    drawn = []
    for _ in range(200):
        n = int(rng.integers(2, 7))
        drawn.append([{"relative_position": int(p), "amplitude_modulation": float(a)}
                      for p, a in zip(rng.integers(0, 1000, n), rng.choice([-1.0, 1.0, 0.3, -0.3], n))])
    for kfs in [low, high, *drawn]:
        out = _reference_reading(kfs)
        assert all(-1.0 <= k["amplitude_modulation"] <= 1.0 for k in out), (kfs, out)
    assert min(k["amplitude_modulation"] for k in _reference_reading(low)) == -1.0
    assert max(k["amplitude_modulation"] for k in _reference_reading(high)) == 1.0


def test_the_rewritten_keyframes_read_as_the_reference_reads_the_originals():
    """``_reference_reading``'s contract: its sorted keyframes, read the usual way (linear
    between keyframes; at equal positions the later one from there on), give at every
    position of the effect's span the amplitude and frequency the reference reader takes
    from the keyframes in file order (``_reading``). Checked on drawn out-of-order lists,
    at each tick and a third of the way into each (so a wrong value just after a step
    shows), away from the keyframes' own positions where the reading may step."""
    from hapticsdk.interop.hjif_versions import _reading, _reference_reading
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(150):
        n = int(rng.integers(2, 7))
        kfs = [{"relative_position": int(p), "amplitude_modulation": float(a), "frequency_modulation": float(f)}
               for p, a, f in zip(rng.integers(0, 200, n), rng.uniform(-1, 1, n), rng.uniform(50, 300, n))]
        out = _reference_reading(kfs)
        span = float(kfs[-1]["relative_position"])
        xp = np.array([k["relative_position"] for k in out], float)
        stops = set(xp.tolist())
        for key in ("amplitude_modulation", "frequency_modulation"):
            fp = np.array([k[key] for k in out])
            for x in np.arange(0.0, span, 1.0 / 3.0):
                if x in stops:
                    continue
                j = int(np.searchsorted(xp, x, side="right"))   # after every keyframe at or before x
                got = fp[j - 1] if j == len(xp) else fp[j - 1] + (fp[j] - fp[j - 1]) * (x - xp[j - 1]) / (xp[j] - xp[j - 1])
                want = _reading(kfs, key, x, 1.0 if key == "amplitude_modulation" else None)
                assert got == pytest.approx(want, rel=1e-9, abs=1e-9), (kfs, out, key, x)
                checked += 1
    assert checked > 10_000
