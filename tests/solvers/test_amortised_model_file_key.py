"""The amortised table cache is keyed by the model file: replacing the file (e.g. a
retrained default model) can never serve a table built for the old one, and the same
bytes under another path share the table."""

from __future__ import annotations

import json

import numpy as np
import pytest

onnx = pytest.importorskip("onnx")
hapticsdk_onnx = pytest.importorskip("hapticsdk_onnx")

OPTS = {"grid": 101, "build_samples": 20000, "build_iter": 15}


def _problem(path):
    from hapticsdk.solvers.problems import build_problem
    return build_problem({"hardness": 0.5, "roughness": 0.5}, model=str(path))


def test_key_follows_the_model_files_bytes(tmp_path):
    from hapticsdk_ga.amortised import problem_key

    data = hapticsdk_onnx.default_model_path().read_bytes()
    a = tmp_path / "a.onnx"
    a.write_bytes(data)
    same = tmp_path / "same_bytes.onnx"
    same.write_bytes(data)
    # b: the same weights with one metadata value changed (the recorded CV metrics), so
    # the model's outputs are identical and only the file's bytes differ
    m = onnx.load_from_string(data)
    for prop in m.metadata_props:
        if prop.key == "hapticsdk.metrics":
            metrics = json.loads(prop.value)
            metrics["cv"]["hardness"]["r"] = 0.5
            prop.value = json.dumps(metrics)
    b = tmp_path / "b.onnx"
    b.write_bytes(m.SerializeToString())
    assert b.read_bytes() != data

    pa, pb, ps = _problem(a), _problem(b), _problem(same)
    assert pa.model is not ps.model   # loaded twice, from two paths
    X = pa.space.random(256, np.random.default_rng(0))
    assert np.array_equal(pa.model.predict(pa.full_inputs(X)), pb.model.predict(pb.full_inputs(X)))
    assert pa.model.file_sha256 != pb.model.file_sha256
    assert problem_key(pa, OPTS) != problem_key(pb, OPTS)
    assert problem_key(pa, OPTS) == problem_key(ps, OPTS)
