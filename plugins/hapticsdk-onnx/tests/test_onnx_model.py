"""hapticsdk-onnx: loading, metadata, batch prediction, analytic Jacobian, bad files."""

import json
from importlib.metadata import entry_points

import numpy as np
import onnx
import pytest

from hapticsdk.errors import ModelError, ValidationError
from hapticsdk.perception.models import PerceptionModel
from hapticsdk_onnx import REQUIRED_METADATA, OnnxModel, default_model_path, load_default


@pytest.fixture(scope="module")
def model():
    return load_default()


def test_entry_points_resolve():
    eps = {e.name: e for e in entry_points(group="hapticsdk.models")}
    assert eps["default"].load() is load_default and eps["onnx"].load() is OnnxModel


def test_default_model_declares_features_and_dimensions(model):
    assert isinstance(model, PerceptionModel)
    assert model.feature_names == ("GS", "W", "Fpeak", "AFpeak", "P")
    assert model.dimension_names == ("hardness", "roughness")
    fs = model.feature_space
    assert fs["GS"].unit == "N/mm" and fs["GS"].lower < 0.11 and fs["GS"].upper > 4.4
    assert fs["Fpeak"].upper < 250
    assert model.df_hz == 0.4 and model.metadata["df_hz"] == 0.4
    assert model.metadata["data_generated"] is True
    assert set(model.metadata["metrics"]) == {"train", "validation", "test", "cv"}
    assert set(model.feature_defaults) == set(model.feature_names)
    assert fs.contains(np.array([model.feature_defaults[n] for n in fs.names]))[0]


def test_batch_predict_matches_numpy_twin(model):
    X = model.feature_space.random(1000, np.random.default_rng(0))
    Y = model.predict(X)
    assert Y.shape == (1000, 2) and Y.dtype == np.float64
    assert np.all((Y >= 0) & (Y <= 1))
    assert np.abs(Y - model.mlp.predict(X)).max() < 1e-5
    assert model.predict(X[0]).shape == (1, 2)
    with pytest.raises(ValidationError):
        model.predict(np.ones((3, 4)))


def test_analytic_jacobian(model):
    X = model.feature_space.random(8, np.random.default_rng(1))
    J = model.jacobian(X)
    assert J.shape == (8, 2, 5)
    # central differences on the float64 twin (the float32 session is too coarse for 1e-6 steps)
    h = 1e-6 * np.maximum(np.abs(X), 1.0)
    for j in range(5):
        step = np.eye(5)[j] * h[:, [j]]
        Jn = (model.mlp.predict(X + step) - model.mlp.predict(X - step)) / (2 * h[:, [j]])
        np.testing.assert_allclose(J[:, :, j], Jn, atol=1e-6)
    # and agrees with coarse differences through onnxruntime itself
    Jo = PerceptionModel.jacobian(model, X, step=1e-2)
    assert np.abs(Jo - J).max() < 0.05 * np.abs(J).max()


def _rewrite(tmp_path, mutate):
    proto = onnx.load(str(default_model_path()))
    mutate(proto)
    p = tmp_path / "m.onnx"
    onnx.save(proto, str(p))
    return p


@pytest.mark.parametrize("key", REQUIRED_METADATA)
def test_missing_metadata_is_a_model_error(tmp_path, key):
    def drop(proto):
        keep = [(e.key, e.value) for e in proto.metadata_props if e.key != "hapticsdk." + key]
        del proto.metadata_props[:]
        for k, v in keep:
            proto.metadata_props.add(key=k, value=v)
    with pytest.raises(ModelError, match=f"hapticsdk.{key}"):
        OnnxModel(_rewrite(tmp_path, drop))


def _set_meta(key, value):
    def mut(proto):
        for e in proto.metadata_props:
            if e.key == key:
                e.value = value
    return mut


def test_inconsistent_metadata_is_a_model_error(tmp_path):
    feats = json.loads({e.key: e.value for e in onnx.load(str(default_model_path())).metadata_props}["hapticsdk.features"])
    with pytest.raises(ModelError, match="5 columns but metadata declares 4"):
        OnnxModel(_rewrite(tmp_path, _set_meta("hapticsdk.features", json.dumps(feats[:4]))))
    with pytest.raises(ModelError, match="2 columns but metadata declares 3"):
        OnnxModel(_rewrite(tmp_path, _set_meta("hapticsdk.dimensions", '["hardness","roughness","warmth"]')))
    bad = [dict(f) for f in feats]
    bad[0]["lower"], bad[0]["upper"] = 5.0, 1.0
    with pytest.raises(ModelError, match="bad feature declaration"):
        OnnxModel(_rewrite(tmp_path, _set_meta("hapticsdk.features", json.dumps(bad))))
    with pytest.raises(ModelError, match="not valid JSON"):
        OnnxModel(_rewrite(tmp_path, _set_meta("hapticsdk.df_hz", "zero point four")))
    with pytest.raises(ModelError, match="unknown features"):
        OnnxModel(_rewrite(tmp_path, _set_meta("hapticsdk.feature_defaults", '{"Q": 1}')))

    def drop_init(proto):
        keep = [t for t in proto.graph.initializer if t.name != "y_max"]
        del proto.graph.initializer[:]
        proto.graph.initializer.extend(keep)
    with pytest.raises(ModelError, match="y_max"):
        OnnxModel(_rewrite(tmp_path, drop_init))


def test_unreadable_files(tmp_path):
    with pytest.raises(ModelError, match="not found"):
        OnnxModel(tmp_path / "nope.onnx")
    p = tmp_path / "junk.onnx"
    p.write_bytes(b"\x00\x01garbage")
    with pytest.raises(ModelError):
        OnnxModel(p)
