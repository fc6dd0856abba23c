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


KF1 = B1 + ["effects", 0, "keyframes", 1]
E0 = B0 + ["effects", 0]
U32, I31 = 2 ** 32 - 1, 2 ** 31 - 1
# (where, the last value accepted, the first refused), at both ends of each ranged field
RANGES = [
    (["level"], 0, -1), (["level"], 255, 256),
    (["timescale"], 1, 0),
    (C0 + ["body_part_mask"], 0, -1), (C0 + ["body_part_mask"], U32, U32 + 1),
    (C0 + ["mixing_coefficient"], 0.0, -1e-9),
    (B1 + ["lower_frequency_limit"], 0, -1), (B0 + ["upper_frequency_limit"], 65535, 65536),
    (E0 + ["position"], 0, -1), (E0 + ["position"], I31, I31 + 1),
    (KF1 + ["relative_position"], 0, -1),
    # keyframe 2 may share keyframe 1's position (100); one before it is rewritten as the
    # reference decoders read it (test_hjif_versions.py), so the refusal here is the range's
    (B1 + ["effects", 0, "keyframes", 2, "relative_position"], 100, -1),
    (B1 + ["effects", 0, "keyframes", 2, "relative_position"], I31, I31 + 1),
    (KF1 + ["amplitude_modulation"], -1.0, -1.0000001), (KF1 + ["amplitude_modulation"], 1.0, 1.0000001),
    (B1 + ["effects", 0, "keyframes", 0, "frequency_modulation"], 0.0, -1e-9),
    (B1 + ["effects", 0, "keyframes", 0, "frequency_modulation"], 65535.0, 65535.5),
    (E0 + ["phase"], 2 * 3.141592653589793, 7.0), (E0 + ["phase"], -2 * 3.141592653589793, -7.0),
    (P0 + ["effect_library", 0, "id"], 0, -1),
    (["syncs"], [{"timestamp": 0, "timescale": 1}], [{"timestamp": -1}]),
]


def _field_of(where):
    out = ""
    for k in where:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else k)
    return out


@pytest.mark.parametrize("where,ok,bad", RANGES, ids=[f"{_field_of(w)}={b}" for w, _, b in RANGES])
def test_a_ranged_field_is_read_at_its_ends_and_refused_one_step_beyond(where, ok, bad):
    """Each ranged field of the format at both ends: the end itself parses (and reads back
    as given), one step beyond is a FormatError naming that field."""
    if where[-1] == "id" and "effect_library" in where:
        # the library effect's id and the reference to it move together
        def both(v):
            return lambda d: (_set(where, v)(d), _set(B0 + ["effects", 1, "id"], v)(d))
        good, wrong = both(ok), both(bad)
    else:
        good, wrong = _set(where, ok), _set(where, bad)
    h = parse_hjif(mutated(good))
    assert h is not None
    with pytest.raises(FormatError) as ei:
        parse_hjif(mutated(wrong))
    assert ei.value.field.startswith(_field_of(where)) or _field_of(where).startswith(ei.value.field), \
        (ei.value.field, str(ei.value))


@pytest.mark.parametrize("key,ok,bad,field", [
    ("direction", {"X": 127, "Y": -128, "Z": 0}, {"X": 128, "Y": 0, "Z": 0}, "direction.X"),
    ("direction", {"X": 0, "Y": -128, "Z": 0}, {"X": 0, "Y": -129, "Z": 0}, "direction.Y"),
    ("actuator_resolution", {"X": 1, "Y": 1, "Z": 127}, {"X": 1, "Y": 1, "Z": 200}, "actuator_resolution.Z"),
    ("actuator_target", [{"X": 0, "Y": 0, "Z": 0}], [{"X": 0, "Y": 0, "Z": 0}, {"X": 300, "Y": 0, "Z": 0}],
     "actuator_target[1].X"),
    ("body_part_target", ["Palm", "Index"], ["Palm", 3], "body_part_target[1]"),
    ("vertices", [0, 5, 9], [0, "5"], "vertices[1]"),
])
def test_a_channels_optional_geometry_is_checked_and_kept(key, ok, bad, field):
    """The channel's optional placement fields (vectors of -128..127 per axis, lists of
    body parts or vertex indices) are checked and kept as given in ``extra``."""
    h = parse_hjif(mutated(_set(C0 + [key], ok)))
    assert h.perceptions[0].channels[0].extra[key] == ok
    with pytest.raises(FormatError) as ei:
        parse_hjif(mutated(_set(C0 + [key], bad)))
    assert ei.value.field == f"{CH0}.{field}", str(ei.value)
