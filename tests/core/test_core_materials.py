import json

import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.perception.materials import load_library


def test_shipped_library_has_the_23_generated_samples():
    lib = load_library()
    assert lib.names() == [f"S{i}" for i in range(1, 24)]
    assert lib.generated and all(m.generated for m in lib)
    for m in lib:
        assert set(m.intensities) == {"hardness", "roughness"}
        assert all(0.0 <= v <= 1.0 for v in m.intensities.values())
        assert m.substrate in {"sponge", "EVA", "rubber", "foam"}
        assert m.texture in {"leather", "fabric"}
        assert m.label == f"{m.texture} on {m.substrate}"


def test_lookup_is_case_insensitive_and_errors_list_names():
    lib = load_library()
    assert lib.get("s7").name == "S7"
    with pytest.raises(ValidationError) as e:
        lib.get("S99")
    assert e.value.field == "material" and "S23" in str(e.value)


def test_ambiguous_label_is_an_error_not_a_guess():
    lib = load_library()
    labels = [m.label for m in lib]
    dup = next(lab for lab in labels if labels.count(lab) > 1)
    with pytest.raises(ValidationError, match="ambiguous"):
        lib.get(dup)


def test_malformed_library_names_the_field(tmp_path):
    bad = {"schema_version": 1, "generated": False, "source": "test",
           "materials": [{"name": "A", "intensities": {"hardness": 1.5}}]}
    p = tmp_path / "lib.json"
    p.write_text(json.dumps(bad))
    with pytest.raises(ValidationError) as e:
        load_library(p)
    assert "materials[0].intensities" in e.value.field
    p.write_text("{not json")
    with pytest.raises(ValidationError, match="not valid JSON"):
        load_library(p)
