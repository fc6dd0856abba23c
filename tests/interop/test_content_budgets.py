"""Budgets for hostile .hjif/.ahap content (docs/safety.md, "Budgets for .hjif/.ahap
content"): overlapping effects cost work proportional to the output, channel counts and
sample rates have ceilings, and beyond a budget the error is named before anything scales
with the content. No timing: the tests count the work done."""

from __future__ import annotations

import numpy as np
import pytest
from hjif_docs import band, basis, channel, doc, kf, perception, single, tone

import hapticsdk.interop.hjif_synth as synth_mod
from hapticsdk.cli import main
from hapticsdk.interop import ahap
from hapticsdk.interop.budget import (
    MAX_OUTPUT_SAMPLES,
    MAX_REORDER_KEYFRAMES,
    MAX_SAMPLE_RATE_HZ,
    MAX_VOICES,
    ContentBudgetError,
)
from hapticsdk.interop.hjif_model import parse_hjif
from hapticsdk.interop.hjif_play import play
from hapticsdk.interop.hjif_synth import synthesize

FS = 8000.0


@pytest.fixture
def evaluated(monkeypatch):
    """Counts the effect samples the synthesiser evaluates."""
    count = {"samples": 0}
    real = synth_mod.effect_samples

    def counting(effect, b, rel, ts):
        count["samples"] += np.asarray(rel).size
        return real(effect, b, rel, ts)

    monkeypatch.setattr(synth_mod, "effect_samples", counting)
    return count


def overlapping(n_effects: int, ms: int = 590_000, channels: int = 1) -> dict:
    effs = [tone(150, ms, amp=0.5, position=i % 7) for i in range(n_effects)]
    return doc([perception([channel([band(effs)], cid=c) for c in range(channels)])])


def test_overlapping_long_effects_are_refused_before_any_sample_is_evaluated(evaluated):
    h = parse_hjif(overlapping(2000))
    with pytest.raises(ContentBudgetError) as ei:
        synthesize(h, fs=FS, seconds=60.0)
    assert ei.value.field == "perceptions[0].channels[0]" and "per sample" in str(ei.value)
    assert evaluated["samples"] == 0


def test_play_refuses_them_before_opening_an_actuator(monkeypatch):
    import hapticsdk.devices.actuators as acts

    opened = []
    monkeypatch.setattr(acts, "create_actuator", lambda name, **kw: opened.append(name))
    with pytest.raises(ContentBudgetError):
        play(parse_hjif(overlapping(2000)))
    assert opened == []


def test_many_long_channels_are_a_named_error_not_a_memory_error(tmp_path, capsys):
    d = overlapping(1, channels=3000)
    with pytest.raises(ContentBudgetError) as ei:
        synthesize(parse_hjif(d), fs=FS, seconds=60.0)
    assert ei.value.field == "perceptions" and str(MAX_OUTPUT_SAMPLES) in str(ei.value)
    from hjif_docs import write
    p = write(tmp_path / "wide.hjif", d)
    for cmd in (["import", str(p), "--synth"], ["play", str(p)]):
        assert main(cmd) == 2
        assert "hapticsdk: error: perceptions: 3000 channel(s)" in capsys.readouterr().err


def test_sample_rates_have_a_ceiling():
    h = parse_hjif(single(tone(150, 100)))
    synthesize(h, fs=MAX_SAMPLE_RATE_HZ, seconds=0.01)
    with pytest.raises(ContentBudgetError) as ei:
        synthesize(h, fs=1e9, seconds=0.01)
    assert ei.value.field == "fs"


@pytest.mark.parametrize("seed", range(40))
def test_evaluated_work_is_at_most_the_voice_budget_per_output_sample(seed):
    rng = np.random.default_rng(seed)
    n_bands = int(rng.integers(1, 4))
    effects = [(int(rng.integers(0, 2001)), int(rng.integers(1, 3001))) for _ in range(int(rng.integers(1, 151)))]
    # random effects spread over bands: synthesis either refuses or evaluates at most
    # MAX_VOICES effect samples per output sample
    bands = [band([tone(100, ms, amp=0.3, position=pos) for pos, ms in effects[b::n_bands]])
             for b in range(n_bands) if effects[b::n_bands]]
    h = parse_hjif(doc([perception([channel(bands)])]))
    count = {"samples": 0}
    real = synth_mod.effect_samples

    def counting(effect, b, rel, ts):
        count["samples"] += np.asarray(rel).size
        return real(effect, b, rel, ts)

    synth_mod.effect_samples = counting
    try:
        try:
            out = synthesize(h, fs=2000.0)
        except ContentBudgetError:
            return
    finally:
        synth_mod.effect_samples = real
    n_out = sum(c.samples.size for c in out.channels)
    assert count["samples"] <= MAX_VOICES * n_out


def test_out_of_order_keyframes_beyond_the_rewrite_budget_are_named():
    n = MAX_REORDER_KEYFRAMES + 1
    kfs = [kf(65535, 0.5, 100)] + [kf(i, 0.5, 100) for i in range(n - 1)]
    with pytest.raises(ContentBudgetError) as ei:
        parse_hjif(single(basis(0, kfs)))
    assert ei.value.field == "perceptions[0].channels[0].bands[0].effects[0].keyframes"


def test_library_references_are_looked_up_in_an_index(monkeypatch):
    # 3000 references into a 3000-entry library: every lookup is a dict hit, never a scan
    lib = [{**tone(100 + i % 50, 10), "id": i} for i in range(3000)]
    refs = [{"effect_type": "Reference", "id": i, "position": 20 * i} for i in range(3000)]
    h = parse_hjif(doc([perception([channel([band(refs)])], library=lib)]))
    p = h.perceptions[0]
    scans = {"n": 0}
    real_iter = list.__iter__

    class Counting(list):
        def __iter__(self):
            scans["n"] += 1
            return real_iter(self)

    p.effect_library = Counting(p.effect_library)
    p.__dict__.pop("_library_index", None)
    for e in p.channels[0].bands[0].effects:
        assert p.library_effect(e.id) is not None
    assert scans["n"] == 1  # the index is built once


def test_ahap_control_changes_per_event_have_a_budget():
    pts = [(i * 1e-4, (i % 2) * 1.0) for i in range(ahap.MAX_EVENT_KEYFRAMES + 10)]
    d = {"Version": 1, "Pattern": [
        {"Event": {"Time": 0.0, "EventType": "HapticContinuous", "EventDuration": 30.0, "EventParameters": []}},
        {"ParameterCurve": {"ParameterID": "HapticIntensityControl", "Time": 0.0,
                            "ParameterCurveControlPoints": [{"Time": t, "ParameterValue": v} for t, v in pts]}}]}
    with pytest.raises(ContentBudgetError) as ei:
        ahap.to_haptic_file(ahap.parse_ahap(d))
    assert ei.value.field == "Pattern[0].Event"


def test_ahap_overlapping_events_have_a_total_keyframe_budget():
    pts = [(i * 1e-3, 0.5) for i in range(1000)]
    events = [{"Event": {"Time": 0.0, "EventType": "HapticContinuous", "EventDuration": 2.0, "EventParameters": []}}
              for _ in range(ahap.MAX_TOTAL_KEYFRAMES // 1000 + 2)]
    d = {"Version": 1, "Pattern": events + [
        {"ParameterCurve": {"ParameterID": "HapticIntensityControl", "Time": 0.0,
                            "ParameterCurveControlPoints": [{"Time": t, "ParameterValue": v} for t, v in pts]}}]}
    with pytest.raises(ContentBudgetError):
        ahap.to_haptic_file(ahap.parse_ahap(d))


@pytest.mark.parametrize("seed", range(20))
def test_counted_work_bounds_the_samples_the_synthesiser_evaluates(seed, evaluated):
    # the budget is checked on effect_work's count: it must never count less than the
    # synthesiser then evaluates (else overlapping effects pass the check and cost more)
    from hapticsdk.interop.hjif_synth import effect_work

    rng = np.random.default_rng(100 + seed)
    effs = [tone(int(rng.integers(50, 400)), int(rng.integers(1, 2000)), amp=0.2,
                 position=int(rng.integers(0, 3000))) for _ in range(int(rng.integers(1, 40)))]
    h = parse_hjif(doc([perception([channel([band(effs)])])]))
    fs = float(rng.choice([1000.0, 2000.0, 8000.0]))
    out = synthesize(h, fs=fs)
    end = (out.channels[0].samples.size - 1) / fs
    work, _ = effect_work(h, [(0, 0)], end, fs)
    assert evaluated["samples"] <= work
