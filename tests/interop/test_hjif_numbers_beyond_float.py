"""Every number of an .hjif document, replaced by one no float holds (an int of 401
digits, which ``json`` reads exactly, or a ``1e400`` literal, which it reads as inf), is
refused with a FormatError naming that number's JSON path -- never an OverflowError
from ``float()`` or ``math.isfinite()`` (the keyframe reordering of the v2023 reader,
the typed field access and the tick-to-second conversion of a 401-digit ``timescale``
raised one). Identifiers (``id``, ``avatar_id``) are only compared, never converted:
an integer one of any size is read as written (the summary of the file works) or
refused with a FormatError (e.g. a reference to the old id left dangling)."""

from __future__ import annotations

import json

import pytest
from hjif_docs import valid_doc
from json_leaves import dotted, number_leaves, replaced

from hapticsdk.errors import FormatError
from hapticsdk.interop.hjif_import import import_summary
from hapticsdk.interop.hjif_model import parse_hjif_text

MARK = "__HJIF_TEST_NUMBER__"
#: identifier fields: integers compared for uniqueness, never turned into floats
IDS = ("id", "avatar_id")


def _dotted(path):
    return dotted(path).lstrip(".")


LEAVES = [path for path, _ in number_leaves(valid_doc())]


def test_the_document_has_numbers_to_replace():
    assert len(LEAVES) >= 20


@pytest.mark.parametrize("literal", ["1" + "0" * 400, "-" + "1" + "0" * 400, "1e400", "-1e400"])
def test_a_number_beyond_the_float_range_is_refused_by_its_path(literal):
    doc = valid_doc()
    for path in LEAVES:
        text = json.dumps(replaced(doc, path, MARK)).replace(f'"{MARK}"', literal)
        if path[-1] in IDS and "e" not in literal:
            try:   # read as written (the reader is lenient on identifiers), or refused by name
                import_summary(parse_hjif_text(text))   # (a changed id leaves a reference dangling)
            except FormatError as exc:
                assert exc.field, path
            continue
        with pytest.raises(FormatError) as exc_info:
            parse_hjif_text(text)
        assert exc_info.value.field == _dotted(path), (path, exc_info.value.field)
