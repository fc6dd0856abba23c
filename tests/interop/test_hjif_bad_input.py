"""Malformed .hjif files: a FormatError (a ValidationError) naming the JSON path, the CLI
prints ``hapticsdk: error: <path>: <reason>`` and exits 2, and nothing is played."""

from __future__ import annotations

import json

import pytest
from hjif_docs import mutated, refused_unread, valid_doc, write

from hapticsdk.cli import main
from hapticsdk.errors import FormatError, ValidationError
from hapticsdk.interop.hjif_model import (
    MAX_DEPTH,
    MAX_FILE_BYTES,
    parse_hjif,
    parse_hjif_text,
    read_hjif,
)

CH0 = "perceptions[0].channels[0]"


def test_the_valid_document_parses():
    h = parse_hjif(valid_doc())
    assert len(h.perceptions[0].channels) == 2


def _del(path):
    def fn(d):
        obj = d
        for k in path[:-1]:
            obj = obj[k]
        del obj[path[-1]]
    return fn


def _set(path, value):
    def fn(d):
        obj = d
        for k in path[:-1]:
            obj = obj[k]
        obj[path[-1]] = value
    return fn


P0 = ["perceptions", 0]
C0 = P0 + ["channels", 0]
B0 = C0 + ["bands", 0]
B1 = C0 + ["bands", 1]

CASES = [
    # (name, mutation, field, words in the message)
    ("missing root field", _del(["version"]), "$", "'version'"),
    ("missing channel gain", _del(C0 + ["gain"]), CH0, "'gain'"),
    ("missing band effects", _del(B0 + ["effects"]), f"{CH0}.bands[0]", "'effects'"),
    ("missing effect position", _del(B0 + ["effects", 0, "position"]), f"{CH0}.bands[0].effects[0]", "'position'"),
    ("wrong type: string frequency limit", _set(B0 + ["lower_frequency_limit"], "65"),
     f"{CH0}.bands[0].lower_frequency_limit", "integer"),
    ("wrong type: boolean id", _set(C0 + ["id"], True), f"{CH0}.id", "integer"),
    ("wrong type: amplitude as string", _set(B1 + ["effects", 0, "keyframes", 0, "amplitude_modulation"], "0.2"),
     f"{CH0}.bands[1].effects[0].keyframes[0].amplitude_modulation", "number"),
    ("wrong type: channels as object", _set(P0 + ["channels"], {}), "perceptions[0].channels", "array"),
    ("unknown modality", _set(P0 + ["perception_modality"], "Smell"), "perceptions[0].perception_modality", "Smell"),
    ("unknown base signal", _set(B0 + ["effects", 0, "base_signal"], "Noise"),
     f"{CH0}.bands[0].effects[0].base_signal", "Noise"),
    ("unknown band type", _set(B0 + ["band_type"], "Wavy"), f"{CH0}.bands[0].band_type", "Wavy"),
    ("unresolved effect id", _set(B0 + ["effects", 1, "id"], 9), f"{CH0}.bands[0].effects[1].id", "9"),
    ("reference without id", _del(B0 + ["effects", 1, "id"]), f"{CH0}.bands[0].effects[1]", "'id'"),
    ("negative keyframe position", _set(B1 + ["effects", 0, "keyframes", 2, "relative_position"], -5),
     f"{CH0}.bands[1].effects[0].keyframes[2].relative_position", "outside"),
    ("'Wave' band without an encoding", _set(B0 + ["band_type"], "Wave"), f"{CH0}.bands[0].band_type",
     "encoding_modality"),
    ("amplitude above 1", _set(B1 + ["effects", 0, "keyframes", 1, "amplitude_modulation"], 1.5),
     f"{CH0}.bands[1].effects[0].keyframes[1].amplitude_modulation", "outside"),
    ("upper below lower", _set(B1 + ["lower_frequency_limit"], 400),
     f"{CH0}.bands[1].upper_frequency_limit", "lower_frequency_limit"),
    ("duplicate channel id", _set(P0 + ["channels", 1, "id"], 0), "perceptions[0].channels[1].id", "not unique"),
    ("unknown reference device", _set(C0 + ["reference_device_id"], 4), f"{CH0}.reference_device_id", "4"),
    ("no perception", _set(["perceptions"], []), "perceptions", "at least one"),
]


@pytest.mark.parametrize("name,fn,field,words", CASES, ids=[c[0] for c in CASES])
def test_malformed_structure_names_the_json_path(name, fn, field, words):
    with pytest.raises(FormatError) as ei:
        parse_hjif(mutated(fn))
    assert ei.value.field == field
    assert words in str(ei.value)
    assert isinstance(ei.value, ValidationError)


def test_root_must_be_an_object():
    with pytest.raises(FormatError) as ei:
        parse_hjif([valid_doc()])
    assert ei.value.field == "$"


def test_nan_literal_and_duplicate_keys_are_refused():
    text = json.dumps(valid_doc())
    with pytest.raises(FormatError, match="NaN"):
        parse_hjif_text(text.replace('"gain": 1.0', '"gain": NaN', 1))
    with pytest.raises(FormatError, match="duplicate key 'gain'"):
        parse_hjif_text(text.replace('"gain": 1.0', '"gain": 1.0, "gain": 2.0', 1))


def test_huge_file_is_refused_before_reading(tmp_path, monkeypatch):
    p = tmp_path / "huge.hjif"
    ei = refused_unread(read_hjif, p, monkeypatch, MAX_FILE_BYTES + 1)  # sparse: no 32 MiB written
    assert ei.value.field == str(p)
    small = write(tmp_path / "small.hjif", valid_doc())
    with pytest.raises(FormatError, match="cap"):
        read_hjif(small, max_bytes=100)
    read_hjif(small)  # under the default cap


def test_non_utf8_is_refused(tmp_path):
    p = tmp_path / "latin1.hjif"
    p.write_bytes(json.dumps(valid_doc()).replace("test content", "caf\u00e9").encode("latin-1"))
    with pytest.raises(FormatError, match="UTF-8") as ei:
        read_hjif(p)
    assert ei.value.field == str(p)


def test_deeply_nested_json_is_refused_without_recursion(tmp_path):
    depth = 200_000
    text = '{"version": "2023", "x": ' + "[" * depth + "]" * depth + "}"
    with pytest.raises(FormatError, match=f"nested {depth + 1} levels deep") as ei:
        parse_hjif_text(text, source="deep.hjif")
    assert ei.value.field == "deep.hjif"
    # brackets inside strings do not count
    d = valid_doc()
    d["description"] = "[" * (MAX_DEPTH * 4)
    parse_hjif(json.loads(json.dumps(d)))
    parse_hjif_text(json.dumps(d))


def test_invalid_json_names_line_and_column(tmp_path):
    p = tmp_path / "broken.hjif"
    p.write_text('{"version": "2023",\n "profile": }', encoding="utf-8")
    with pytest.raises(FormatError, match="line 2 column"):
        read_hjif(p)


@pytest.mark.parametrize("command", ["import", "play"])
def test_cli_prints_the_path_exits_2_and_opens_no_actuator(tmp_path, capsys, monkeypatch, command):
    import hapticsdk.devices.actuators as acts

    opened = []
    real = acts.create_actuator
    monkeypatch.setattr(acts, "create_actuator", lambda name, **kw: opened.append(name) or real(name, **kw))
    bad = write(tmp_path / "bad.hjif", mutated(_set(B1 + ["effects", 0, "keyframes", 2, "relative_position"], -5)))
    code = main([command, str(bad)])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(f"hapticsdk: error: {CH0}.bands[1].effects[0].keyframes[2].relative_position: -5 outside")
    assert opened == []


def test_cli_json_error_carries_the_field(tmp_path, capsys):
    bad = write(tmp_path / "bad.hjif", mutated(_set(P0 + ["perception_modality"], "Smell")))
    code = main(["import", str(bad), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 2 and out["type"] == "FormatError" and out["field"] == "perceptions[0].perception_modality"


def test_library_reference_loop_is_refused_before_anything_plays(spy_create):
    from hapticsdk.interop.hjif_play import play

    d = valid_doc()
    # the band's Reference to id 5 finds library effect 5, itself a Reference to id 5: a loop
    d["perceptions"][0]["effect_library"] = [{"effect_type": "Reference", "id": 5, "position": 0}]
    h = parse_hjif(d)
    with pytest.raises(FormatError, match="loop") as ei:
        play(h)
    assert ei.value.field == f"{CH0}.bands[0].effects[1]"
    assert spy_create == []


@pytest.fixture
def spy_create(monkeypatch):
    import hapticsdk.devices.actuators as acts

    made: list = []
    real = acts.create_actuator
    monkeypatch.setattr(acts, "create_actuator", lambda name, **kw: made.append(name) or real(name, **kw))
    return made
