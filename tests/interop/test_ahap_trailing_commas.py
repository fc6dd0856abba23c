"""AHAP files with a comma after the last member of an object or array: Apple's own sample
files for its Core Haptics Unity plug-in are written so, and its reader takes them. The SDK
reads them as that plug-in does and says where; every other JSON error stands as the strict
parser reports it. The files here are written from the format's structure."""

from __future__ import annotations

import json
import re

import pytest
from hypothesis import given, settings, strategies as st

from hapticsdk.cli import main
from hapticsdk.errors import FormatError
from hapticsdk.interop.ahap import parse_ahap, parse_ahap_text

#: a pattern laid out as an editor writes one: a transient, a continuous event, an intensity
#: curve, a dynamic parameter, an audio event whose path holds the characters ",]" and ",}"
DOC = {
    "Version": 1.0,
    "Metadata": {"Project": "hand-written", "Description": "a hit, ] then a tail, }"},
    "Pattern": [
        {"Event": {"Time": 0.0, "EventType": "HapticTransient",
                   "EventParameters": [{"ParameterID": "HapticIntensity", "ParameterValue": 0.8},
                                       {"ParameterID": "HapticSharpness", "ParameterValue": 0.4}]}},
        {"Event": {"Time": 0.02, "EventType": "HapticContinuous", "EventDuration": 0.3,
                   "EventParameters": [{"ParameterID": "HapticIntensity", "ParameterValue": 0.6},
                                       {"ParameterID": "HapticSharpness", "ParameterValue": 0.2}]}},
        {"ParameterCurve": {"ParameterID": "HapticIntensityControl", "Time": 0.02,
                            "ParameterCurveControlPoints": [{"Time": 0.0, "ParameterValue": 1.0},
                                                            {"Time": 0.1, "ParameterValue": 0.5},
                                                            {"Time": 0.3, "ParameterValue": 0.0}]}},
        {"Parameter": {"ParameterID": "HapticSharpnessControl", "Time": 0.2, "ParameterValue": 0.3}},
        {"Event": {"Time": 0.0, "EventType": "AudioCustom", "EventWaveformPath": "a,].wav,}"}},
    ],
}
TEXT = json.dumps(DOC, indent=4)
#: every place in TEXT where a value is followed by the } or ] that closes its container
CLOSERS = [m.start() for m in re.finditer(r"(?<=[\"\d\]}el])(?=\s*[}\]])", TEXT)
           if TEXT.count('"', 0, m.start()) % 2 == 0]


def _same(a, b):
    return (a.version, a.events, a.controls, a.not_played, a.clamped) == \
           (b.version, b.events, b.controls, b.not_played, b.clamped)


def _insert(text, offsets, what=","):
    for i in sorted(offsets, reverse=True):
        text = text[:i] + what + text[i:]
    return text


def test_the_draw_reaches_commas_before_both_closers():
    after = {TEXT[i:].lstrip()[0] for i in CLOSERS}
    assert after == {"}", "]"} and len(CLOSERS) >= 20


@settings(max_examples=60, deadline=None)
@given(st.sets(st.sampled_from(CLOSERS), min_size=1))
def test_trailing_commas_read_as_the_strict_file_and_are_reported(chosen):
    strict = parse_ahap(DOC)
    assert strict.relaxed == []
    text = _insert(TEXT, chosen)
    pat = parse_ahap_text(text, source="f.ahap")
    assert _same(pat, strict)
    (note,) = pat.relaxed
    first = min(chosen)
    line = TEXT.count("\n", 0, first) + 1
    col = first - (TEXT.rfind("\n", 0, first) + 1) + 1
    assert note["path"] == f"line {line} column {col}"
    assert note["change"].startswith(f"{len(chosen)} trailing comma")
    # the strings that hold ",]" and ",}" are read as written
    assert pat.not_played[0]["what"] == "AudioCustom event (a,].wav,})"


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(CLOSERS), st.sampled_from(["[,", "{,", ",,"]), st.data())
def test_a_comma_that_follows_no_value_stays_an_error(at, kind, data):
    # an elision is not a trailing comma: "[,]", "{,}" and ",,]" are refused as the strict
    # parser refuses them, at the place it names
    if kind == ",,":
        text = _insert(TEXT, [at], ",,")
    else:
        opens = [m.end() for m in re.finditer(r"[\[{]", TEXT) if TEXT.count('"', 0, m.start()) % 2 == 0]
        i = data.draw(st.sampled_from(opens))
        text = _insert(TEXT, [i], ",")
        if data.draw(st.booleans()):
            text = _insert(text, [at + (at > i)], ",")   # and a trailing comma elsewhere
    with pytest.raises(json.JSONDecodeError) as strict:
        json.loads(text)
    with pytest.raises(FormatError) as ei:
        parse_ahap_text(text, source="f.ahap")
    assert ei.value.field == "f.ahap"
    assert f"line {strict.value.lineno} column {strict.value.colno}" in str(ei.value)


@pytest.mark.parametrize("empty", ["{,}", "[,]", "[ ,\n ]", "{\n,}"])
def test_an_empty_container_with_a_comma_stays_an_error(empty):
    # "[,]" holds no value for the comma to follow: an elision, refused where strict JSON
    # refuses it (the plug-in's reader would take it; nothing Apple publishes is written so)
    doc = json.loads(TEXT)
    doc["Metadata"] = {}
    doc["Pattern"][0]["Event"]["EventParameters"] = []
    text = json.dumps(doc, indent=4).replace("{}", empty if empty[0] == "{" else "{}").replace(
        "[]", empty if empty[0] == "[" else "[]")
    text = _insert(text, [text.rindex("]")])    # and one true trailing comma
    with pytest.raises(json.JSONDecodeError) as strict:
        json.loads(text)
    with pytest.raises(FormatError) as ei:
        parse_ahap_text(text, source="f.ahap")
    assert f"line {strict.value.lineno} column {strict.value.colno}" in str(ei.value)


def test_a_field_error_in_a_file_with_trailing_commas_names_the_field():
    doc = json.loads(TEXT)
    doc["Pattern"][1]["Event"]["EventDuration"] = "long"
    text = _insert(json.dumps(doc, indent=4), [json.dumps(doc, indent=4).rindex("}")])
    with pytest.raises(FormatError) as ei:
        parse_ahap_text(text, source="f.ahap")
    assert ei.value.field == "Pattern[1].Event.EventDuration"


def test_cli_import_and_play_say_what_was_read_beyond_json(tmp_path, capsys):
    p = tmp_path / "editor.ahap"
    p.write_text(_insert(TEXT, CLOSERS[:3]), encoding="utf-8")
    assert main(["import", str(p)]) == 0
    out = capsys.readouterr().out
    assert "3 trailing commas" in out and "line " in out
    assert main(["import", str(p), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["relaxed"][0]["change"].startswith("3 trailing commas")
    assert main(["play", str(p), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["actuators"]["piezo-virtual"]["active_ticks"] > 0
    assert any("3 trailing commas" in n for n in rep["notes"])
