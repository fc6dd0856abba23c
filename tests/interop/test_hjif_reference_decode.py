"""What a reference decoder reproduces of an SDK export, per perception.

The decoder here is written from the reference synthesiser's definition (MPEG's
HapticReferenceSoftware, Curve and VectorialWave bands), reading the exported JSON
directly (not through the SDK's parser):

- a Curve effect's keyframes are taken relative to its first keyframe and interpolated
  (Linear); an effect of exactly two keyframes adds nothing (the reference interpolates
  it but skips the copy into the band);
- a Reference effect plays its library effect; a Vectorial effect is its amplitude times
  the sine of its (integer) keyframe frequency;
- a channel's value is the clipped band sum times its gain times 10^perception_unit_exponent.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from hjif_docs import plan_for

from hapticsdk.interop.hjif_export import FORMAT_VERSION, export_plan, write_hjif

FS = 8000.0


def _plan(material: str):
    return plan_for(material)


def reference_decode(perception: dict, ticks: np.ndarray, timescale: int) -> np.ndarray:
    """Samples of channel 0 of ``perception`` at ``ticks``, as the reference synthesises."""
    ch = perception["channels"][0]
    lib = {e["id"]: e for e in perception["effect_library"]}
    acc = np.zeros_like(ticks)
    for b in ch["bands"]:
        for e in b["effects"]:
            eff = lib[e["id"]] if e["effect_type"] == "Reference" else e
            k = eff["keyframes"]
            pos = np.array([x["relative_position"] for x in k], float)
            amp = np.array([x["amplitude_modulation"] for x in k], float)
            rel = ticks - e["position"]
            inside = (rel >= 0) & (rel <= pos[-1])
            if b["band_type"] == "Curve":
                if len(k) == 2:
                    continue
                acc[inside] += np.interp(rel[inside], pos - pos[0], amp)
            else:
                f = k[0]["frequency_modulation"]
                assert isinstance(f, int)  # the reference reader keeps only integer frequencies
                acc[inside] += np.interp(rel[inside], pos, amp) * np.sin(2 * np.pi * f * rel[inside] / timescale)
    return np.clip(acc, -1, 1) * ch["gain"] * 10.0 ** perception.get("perception_unit_exponent", 0)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    plan = _plan("S20")
    path = write_hjif(export_plan(plan), tmp_path_factory.mktemp("x") / "s20.hjif")
    return plan.material("S20"), json.loads(path.read_text(encoding="utf-8"))


def test_the_export_states_its_version(exported):
    _, d = exported
    assert d["version"] == FORMAT_VERSION == "2023"


def test_stiffness_survives_a_reference_decode(exported):
    mp, d = exported
    p = next(p for p in d["perceptions"] if p["perception_modality"] == "Stiffness")
    ts = d["timescale"]
    ticks = np.arange(0, 1000) * 1.0
    x = reference_decode(p, ticks, ts)
    assert np.all(x == pytest.approx(mp.features["GS"], rel=1e-12))


def test_vibrotactile_parts_survive_a_reference_decode(exported):
    mp, d = exported
    ts = d["timescale"]
    n = 8000
    ticks = np.arange(n) / FS * ts
    for p in d["perceptions"]:
        if p["perception_modality"] == "Stiffness":
            continue
        x = reference_decode(p, ticks, ts)
        f = p["effect_library"][0]["keyframes"][0]["frequency_modulation"]
        mag = np.abs(np.fft.rfft(x * np.hanning(n)))
        assert abs(np.argmax(mag) * FS / n - f) <= FS / n
        amp = p["effect_library"][0]["keyframes"][0]["amplitude_modulation"] * p["channels"][0]["gain"]
        assert np.max(np.abs(x)) == pytest.approx(abs(amp), rel=1e-3)
        if p["perception_modality"] == "Vibrotactile Texture":
            assert f == round(mp.features["Fpeak"])
            assert np.max(np.abs(x)) == pytest.approx(mp.features["AFpeak"], rel=1e-3)


@pytest.mark.parametrize("material,seed", [("S1", 0), ("S4", 1), ("S9", 2), ("S13", 3), ("S17", 4)])
def test_stiffness_of_any_material_and_length_decodes_to_gs_on_every_tick(material, seed, tmp_path):
    # own inputs: materials other than the fixture's, effect lengths drawn at random from
    # one tick to 10 s; decoded from the written JSON by the format definition above
    rng = np.random.default_rng(seed)
    seconds = float(10 ** rng.uniform(-3, 1))
    mp = _plan(material).material(material)
    path = write_hjif(export_plan(_plan(material), effect_seconds=seconds), tmp_path / "x.hjif")
    d = json.loads(path.read_text(encoding="utf-8"))
    p = next(p for p in d["perceptions"] if p["perception_modality"] == "Stiffness")
    (eff,) = p["channels"][0]["bands"][0]["effects"]
    length = eff["keyframes"][-1]["relative_position"] - eff["keyframes"][0]["relative_position"]
    assert length == round(seconds * d["timescale"])  # the effect spans the asked length
    ticks = np.arange(0, length + 3) * 1.0
    x = reference_decode(p, ticks, d["timescale"])
    assert np.all(x[: length + 1] == pytest.approx(mp.features["GS"], rel=1e-12))
    assert np.all(x[length + 1:] == 0.0)  # nothing after the effect ends


def test_an_effect_shorter_than_one_tick_is_refused():
    from hapticsdk.errors import ValidationError

    with pytest.raises(ValidationError) as ei:
        export_plan(_plan("S1"), effect_seconds=0.4e-3)
    assert ei.value.field == "effect_seconds"
