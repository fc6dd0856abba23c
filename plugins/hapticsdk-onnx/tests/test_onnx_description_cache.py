"""The model-file description cache: a model file read once is read again without
importing ``onnx`` (its parsed parts are kept under the file's SHA-256), and every check
of ``OnnxModel`` still runs on the cached parts."""

import json
import subprocess
import sys

import numpy as np
import onnx
import pytest

from hapticsdk.errors import ModelError
from hapticsdk_onnx import OnnxModel, default_model_path


@pytest.fixture(autouse=True)
def _cache_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("HAPTICSDK_CACHE_DIR", str(tmp_path / "cache"))


def _rewrite(tmp_path, mutate, name="m.onnx"):
    proto = onnx.load(str(default_model_path()))
    mutate(proto)
    p = tmp_path / name
    onnx.save(proto, str(p))
    return p


def _set_meta(key, value):
    def mut(proto):
        for e in proto.metadata_props:
            if e.key == key:
                e.value = value
    return mut


def test_a_second_process_reads_the_model_without_importing_onnx(tmp_path):
    code = r"""
import json, sys
import numpy as np
from hapticsdk_onnx import load_default
m = load_default()
G = np.array([[m.feature_space.lower[i] * 0.5 + m.feature_space.upper[i] * 0.5 for i in range(m.n_features)]])
print(json.dumps({"onnx": "onnx" in sys.modules, "y": m.predict(G).tolist(),
                  "J": m.jacobian(G).tolist()}))
"""
    runs = []
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stderr[-2000:]
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    assert runs[1]["onnx"] is False
    assert runs[0]["y"] == runs[1]["y"] and runs[0]["J"] == runs[1]["J"]


def test_cached_description_gives_the_same_model(tmp_path):
    a = OnnxModel(default_model_path())
    b = OnnxModel(default_model_path())          # from the cache
    assert a.feature_names == b.feature_names and a.dimension_names == b.dimension_names
    assert a.metadata == b.metadata and a.feature_defaults == b.feature_defaults
    G = np.tile([[(lo + hi) / 2 for lo, hi in zip(a.feature_space.lower, a.feature_space.upper)]], (3, 1))
    np.testing.assert_array_equal(a.jacobian(G), b.jacobian(G))


def test_checks_still_run_on_a_cached_description(tmp_path):
    """A file whose protobuf parses but whose metadata is inconsistent is refused the
    second time too (the description is cached, the checks are not skipped)."""
    p = _rewrite(tmp_path, _set_meta("hapticsdk.dimensions", '["hardness","roughness","warmth"]'))
    for _ in range(2):
        with pytest.raises(ModelError, match="2 columns but metadata declares 3"):
            OnnxModel(p)

    def drop_init(proto):
        keep = [t for t in proto.graph.initializer if t.name != "y_max"]
        del proto.graph.initializer[:]
        proto.graph.initializer.extend(keep)
    q = _rewrite(tmp_path, drop_init, "q.onnx")
    for _ in range(2):
        with pytest.raises(ModelError, match="y_max"):
            OnnxModel(q)


def test_a_changed_file_is_parsed_again(tmp_path):
    feats = json.loads({e.key: e.value for e in onnx.load(str(default_model_path())).metadata_props}
                       ["hapticsdk.features"])
    p = tmp_path / "m.onnx"
    p.write_bytes(default_model_path().read_bytes())
    OnnxModel(p)
    p.write_bytes(_rewrite(tmp_path, _set_meta("hapticsdk.features", json.dumps(feats[:4])), "x.onnx").read_bytes())
    with pytest.raises(ModelError, match="5 columns but metadata declares 4"):
        OnnxModel(p)
