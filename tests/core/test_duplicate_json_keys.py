"""A JSON object that names one key twice is refused by every SDK reader, with the path
of the key (docs/safety.md, "Named errors").

Python's ``json`` keeps the last of two values silently, other readers the first or
either: a scene holding ``"intensities": {"hardness": 0.2, "hardness": 0.9}`` rendered
0.9 while an editor, a diff or a reviewer shows 0.2 first, and a device configuration
holding one option twice was used with whichever value came last. The .hjif reader already
refused duplicates; the one reader of the SDK's own formats
(:func:`hapticsdk.schemas_io.parse_json`) did not.

A property test over the class: any JSON document hypothesis draws parses as ``json``
parses it, and the same document with one key of one of its objects repeated is refused
by a ValidationError whose field is the JSON path of that key -- through each format's
reader, for the scene, plan, calibration and material library files.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from json_leaves import dotted, nodes

import hapticsdk as hs
from hapticsdk.errors import ValidationError
from hapticsdk.schemas_io import parse_json

ROOT = Path(__file__).resolve().parents[2]

LEAVES = st.one_of(st.none(), st.booleans(), st.integers(-10 ** 6, 10 ** 6),
                   st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=5))
DOCS = st.recursive(LEAVES, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=4), inner, max_size=4)), max_leaves=20)
OBJECTS = st.dictionaries(st.text(max_size=4), DOCS, min_size=1, max_size=4)


def _with_duplicate(doc, path):
    """JSON text of ``doc`` in which the object at ``path`` names its first key twice
    (the copy, with the same value -- so no other check can catch it -- right after the
    original)."""
    def enc(node, where):
        if isinstance(node, dict):
            items = [f"{json.dumps(k)}: {enc(v, (*where, k))}" for k, v in node.items()]
            if where == path:
                k, v = next(iter(node.items()))
                items.insert(1, f"{json.dumps(k)}: {json.dumps(v)}")
            return "{" + ", ".join(items) + "}"
        if isinstance(node, list):
            return "[" + ", ".join(enc(v, (*where, i)) for i, v in enumerate(node)) + "]"
        return json.dumps(node)
    return enc(doc, ())


@settings(max_examples=400, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(doc=DOCS)
def test_a_document_without_duplicates_reads_as_json_reads_it(doc):
    assert parse_json(json.dumps(doc), "x.json", field="file") == doc


@settings(max_examples=400, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(doc=OBJECTS, data=st.data())
def test_a_key_named_twice_anywhere_is_refused_by_its_path(doc, data):
    objects = [p for p, v in nodes(doc) if isinstance(v, dict) and v]
    path = data.draw(st.sampled_from(objects))
    key = next(iter(_at(doc, path)))
    with pytest.raises(ValidationError) as err:
        parse_json(_with_duplicate(doc, path), "x.json", field="file")
    assert err.value.field == "file" + dotted((*path, key))


def _at(doc, path):
    for k in path:
        doc = doc[k]
    return doc


def _scene():
    return json.loads((ROOT / "examples/scenes/desk-spatial.json").read_text())


def _plan():
    return hs.compile_scene(hs.Scene.for_material("S7", solver={"method": "polish"})).to_dict()


def _calibration():
    from hapticsdk.calibration import VoiceCoilCalibration
    from hapticsdk.calibration.store import calibration_to_dict
    return calibration_to_dict(VoiceCoilCalibration(coefficients=(0.0002, 0.01, -0.3),
                                                    confidence_intervals=((0.0, 1.0),) * 3, amplifier_gain=2.0))


def _library():
    return json.loads((ROOT / "hapticsdk/data/materials.json").read_text())


def _read_calibration(p):
    from hapticsdk.calibration import read_calibration
    return read_calibration(p)


def _read_plan(p):
    from hapticsdk.plan import RenderPlan
    return RenderPlan.load(p)


FORMATS = [("scene", _scene, hs.load_scene), ("plan", _plan, _read_plan),
           ("calibration", _calibration, _read_calibration), ("materials", _library, hs.load_library)]


@pytest.mark.parametrize("name, make, read", FORMATS, ids=[f[0] for f in FORMATS])
def test_each_format_reader_refuses_a_key_named_twice(tmp_path, name, make, read):
    doc = make()
    p = tmp_path / f"{name}.json"
    p.write_text(json.dumps(doc))
    read(p)  # the file as written reads
    objects = [path for path, v in nodes(doc) if isinstance(v, dict) and v]
    for path in (objects[0], objects[len(objects) // 2], objects[-1]):
        p.write_text(_with_duplicate(doc, path))
        with pytest.raises(ValidationError) as err:
            read(p)
        key = next(iter(_at(doc, path)))
        assert err.value.field.endswith(dotted((*path, key))), (err.value.field, path)
