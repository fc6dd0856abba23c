"""``schemas_io.load_json`` remembers files that passed validation (content, schema and
jsonschema version hashed), so a render does not import jsonschema for a file it has
validated before, and never lets a changed or invalid file through."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.perception.materials import DEFAULT_LIBRARY
from hapticsdk.schemas_io import load_json


@pytest.fixture
def cache(tmp_path, monkeypatch):
    d = tmp_path / "cache"
    monkeypatch.setenv("HAPTICSDK_CACHE_DIR", str(d))
    return d


def _copy(tmp_path):
    p = tmp_path / "lib.json"
    shutil.copyfile(DEFAULT_LIBRARY, p)
    return p


def test_a_file_validated_once_is_not_validated_again_in_a_new_process(tmp_path, cache):
    p = _copy(tmp_path)
    load_json(p, "materials")
    assert len(list((cache / "validated").iterdir())) == 1
    code = ("import sys; from hapticsdk.schemas_io import load_json; "
            f"load_json({str(p)!r}, 'materials'); print('jsonschema' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_a_changed_file_is_validated_again(tmp_path, cache):
    p = _copy(tmp_path)
    load_json(p, "materials")
    data = json.loads(p.read_text())
    data["materials"][0]["intensities"] = "not an object"
    p.write_text(json.dumps(data))
    with pytest.raises(ValidationError) as exc:
        load_json(p, "materials")
    assert exc.value.field.startswith("materials.materials[0]")


def test_an_invalid_file_fails_every_time_and_leaves_no_marker(tmp_path, cache):
    p = tmp_path / "bad.json"
    p.write_text(json.dumps({"schema_version": 1, "materials": "none"}))
    for _ in range(2):
        with pytest.raises(ValidationError):
            load_json(p, "materials")
    assert not (cache / "validated").exists() or not list((cache / "validated").iterdir())


def test_a_pass_under_one_schema_does_not_count_for_another(tmp_path, cache):
    p = _copy(tmp_path)
    load_json(p, "materials")
    with pytest.raises(ValidationError):
        load_json(p, "scene")


def test_the_memo_key_covers_content_types_and_schema(cache):
    """JSON's 1 and 1.0 are different instances (a schema may ask for an integer); the
    same instance under another schema is another key."""
    from hapticsdk.schemas_io import _validated_marker
    keys = {_validated_marker({"a": 1}, "scene"), _validated_marker({"a": 1.0}, "scene"),
            _validated_marker({"a": 1}, "materials"), _validated_marker({"a": [1]}, "scene")}
    assert len(keys) == 4 and None not in keys
    assert _validated_marker({"a": 1}, "scene") == _validated_marker({"a": 1}, "scene")
