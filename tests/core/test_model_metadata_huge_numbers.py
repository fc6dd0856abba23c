"""An ONNX model file's JSON metadata can hold an int no float holds (``1`` and 400
zeros): its df_hz, feature defaults, constraint context and feature bounds raise
ModelError naming the file, not TypeError / OverflowError from numpy. A Feature's bounds
take numbers only ("1", True and None are no bound)."""

import json

import pytest

from hapticsdk.errors import ModelError, ValidationError
from hapticsdk.perception.features import Feature

onnx = pytest.importorskip("onnx")

BIG = 10 ** 400


def _model(tmp_path, key):
    from pathlib import Path

    import hapticsdk_onnx
    src = Path(hapticsdk_onnx.__file__).parent / "models" / "default.onnx"
    proto = onnx.load(str(src))
    for e in proto.metadata_props:
        if e.key == key:
            obj = json.loads(e.value)
            if isinstance(obj, dict):
                obj = {k: BIG for k in obj}
            elif isinstance(obj, list):
                obj = [dict(o, lower=BIG) for o in obj]
            else:
                obj = BIG
            e.value = json.dumps(obj)
    p = tmp_path / "m.onnx"
    onnx.save(proto, str(p))
    return p


@pytest.mark.parametrize("key", ["hapticsdk.df_hz", "hapticsdk.constraint_context", "hapticsdk.feature_defaults",
                                 "hapticsdk.features"])
def test_model_metadata_with_an_int_beyond_the_float_range(tmp_path, key):
    from hapticsdk_onnx import OnnxModel

    with pytest.raises(ModelError, match="m.onnx"):
        OnnxModel(str(_model(tmp_path, key)))


@pytest.mark.parametrize("lower", ["1", True, None, BIG, float("nan")])
def test_feature_bound_must_be_a_number(lower):
    with pytest.raises(ValidationError) as exc:
        Feature("GS", "N/mm", lower, 10.0)
    assert exc.value.field == "feature.GS.lower"
