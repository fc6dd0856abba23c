"""The SDK metadata an .hjif export carries inside its description fields (``text
hapticsdk-meta:{json}``) is input like the rest of the file: any value at any place of
it ends in a FormatError naming the description, or in a summary that prints and is
strict JSON -- never a raw exception.

A property test over the class: hypothesis takes an SDK export (S7), puts one drawn value
at one drawn place of the top-level metadata or of a perception's, and runs what
``hapticsdk import`` runs (import_summary, its text form, its JSON). The metadata was read
with a bare ``json.loads`` and used unchecked: ``"materials": 5`` raised TypeError,
``"features": {"GS": "x"}`` ValueError in the text form, ``"features": [1]``
AttributeError, 5000 nested brackets RecursionError, and a ``NaN`` (or ``1e400``) came
out of ``import --json`` as a bare NaN, which is not JSON.
"""

from __future__ import annotations

import copy
import json

import pytest
from hjif_docs import plan_for
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from json_leaves import nodes, replaced

from hapticsdk.errors import FormatError
from hapticsdk.interop.hjif_export import META_MARKER, export_plan, write_hjif
from hapticsdk.interop.hjif_import import format_summary, import_summary, sdk_materials
from hapticsdk.interop.hjif_model import read_hjif

NAMES = ["", "S7", "hardness", "stiffness", "texture", "coil", "GS", "hapticsdk-hjif", "\x00", "x" * 300]
SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-10 ** 30, 10 ** 30), st.just(10 ** 400),
                    st.floats(), st.text(max_size=8), st.sampled_from(NAMES))
EXTREMES = st.sampled_from([float("nan"), float("inf"), -float("inf"), 10 ** 400, 5, "x", [1], {}, [], None, True])
VALUES = st.one_of(EXTREMES, st.recursive(SCALARS, lambda inner: st.one_of(
    st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=6) | st.sampled_from(NAMES), inner, max_size=3)),
    max_leaves=6))


@pytest.fixture(scope="module")
def hfile(tmp_path_factory):
    """The S7 export as read back from its file (the perceptions know their paths)."""
    return read_hjif(write_hjif(export_plan(plan_for("S7")), tmp_path_factory.mktemp("meta") / "s7.hjif"))


def _describing(hfile):
    """The description-carrying objects of ``hfile``: the file and each perception."""
    return [hfile, *hfile.perceptions]


def _run_import(h):
    s = import_summary(h, source="x.hjif")
    format_summary(s)
    json.dumps(s, allow_nan=False, default=str)


def test_the_unchanged_export_imports(hfile):
    _run_import(hfile)
    assert sdk_materials(hfile)["S7"]["parts"]


@settings(max_examples=600, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(data=st.data(), value=VALUES)
def test_any_value_anywhere_in_the_metadata(hfile, data, value):
    h = copy.deepcopy(hfile)
    owner = data.draw(st.sampled_from(_describing(h)))
    text, meta = owner.description.split(META_MARKER)
    meta = json.loads(meta)
    # a depth first, then a place at that depth: a list or object near the top (the
    # materials list, one entry) gets as many draws as the many numbers deep down
    places = [p for p, _ in nodes(meta)]
    depth = data.draw(st.sampled_from(sorted({len(p) for p in places})))
    path = data.draw(st.sampled_from([p for p in places if len(p) == depth]))
    meta = value if not path else replaced(meta, path, value)
    owner.description = text + META_MARKER + json.dumps(meta)  # NaN / Infinity literals as a writer may put them
    try:
        _run_import(h)
    except FormatError as exc:
        assert exc.field and exc.field.endswith("description")


@pytest.mark.parametrize("meta", ["[" * 5000 + "]" * 5000, '{"a":' * 5000 + "1" + "}" * 5000,
                                  '{"format": "hapticsdk-hjif", "materials": [{"name": "a", "features": {"GS": 1e400}}]}',
                                  '{"format": "hapticsdk-hjif", "format": "other"}'])
@pytest.mark.parametrize("where", [0, 1])
def test_metadata_text_that_is_no_plain_json_object_is_named(hfile, meta, where):
    h = copy.deepcopy(hfile)
    owner = _describing(h)[where]
    owner.description = owner.description.split(META_MARKER)[0] + META_MARKER + meta
    with pytest.raises(FormatError) as err:
        _run_import(h)
    assert err.value.field.endswith("description")


@pytest.mark.parametrize("where, path, value", [
    (0, ("materials",), 5), (0, ("materials",), "S7"), (0, ("materials", 0), "S7"),
    (0, ("materials", 0, "name"), ["S7"]), (0, ("materials", 0, "features"), [1]),
    (0, ("materials", 0, "features", "GS"), "0.5"), (0, ("materials", 0, "targets", "hardness"), True),
    (0, ("materials", 0, "generated"), "false"), (1, ("material",), ["S7"]), (1, ("role",), {"x": 1})])
def test_the_metadata_the_sdk_uses_has_its_types(hfile, where, path, value):
    # a material name that is a list was str()-ed into "['S7']"; "generated": "false" read as true
    h = copy.deepcopy(hfile)
    owner = _describing(h)[where]
    text, meta = owner.description.split(META_MARKER)
    owner.description = text + META_MARKER + json.dumps(replaced(json.loads(meta), path, value))
    with pytest.raises(FormatError) as err:
        _run_import(h)
    assert err.value.field.endswith("description")
