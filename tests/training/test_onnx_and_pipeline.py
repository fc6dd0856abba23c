"""ONNX export (parity, metadata), shipped data set and default model rebuild, CLI handlers."""

import argparse
import json
from pathlib import Path

import numpy as np
import onnx
import pytest

from hapticsdk.cli import training as cli
from hapticsdk.training import lm, onnx_export, pipeline
from hapticsdk.training.extraction import FEATURE_NAMES

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_ONNX = ROOT / "plugins/hapticsdk-onnx/src/hapticsdk_onnx/models/default.onnx"
SHIPPED = pipeline.shipped_dataset_dir()


@pytest.fixture(scope="module")
def shipped_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("model") / "rebuilt.onnx"
    report, res = pipeline.train_dataset(SHIPPED, out)
    return report, res, out


def test_default_model_rebuilds_bit_for_bit(shipped_report):
    report, _, out = shipped_report
    assert out.read_bytes() == DEFAULT_ONNX.read_bytes()


def test_shipped_dataset_regenerates_identically(tmp_path):
    table = pipeline.generate_feature_dataset(tmp_path, 23)
    for name in ("trial_features.csv", "sample_features.csv", "ratings.json", "dataset.json", "truth.json"):
        assert (tmp_path / name).read_bytes() == (SHIPPED / name).read_bytes(), name
    shipped_mat = json.loads((ROOT / "hapticsdk/data/materials.json").read_text())
    assert pipeline.build_materials(table) == shipped_mat


def test_materials_library_format():
    doc = json.loads((ROOT / "hapticsdk/data/materials.json").read_text())
    assert doc["schema_version"] == 1 and doc["generated"] is True
    mats = doc["materials"]
    assert [m["name"] for m in mats] == [f"S{i}" for i in range(1, 24)]
    m = mats[0]
    assert m["label"] == f"{m['texture']} on {m['substrate']}" and m["generated"] is True
    assert set(m["intensities"]) == {"hardness", "roughness"} and set(m["features"]) == set(FEATURE_NAMES)


def test_report_and_parity(shipped_report):
    report, res, out = shipped_report
    assert report["onnx_parity_max_abs"] < 1e-5
    assert set(report["metrics"]) == {"train", "validation", "test", "cv"}
    for split in report["metrics"].values():
        for m in split.values():
            assert 0 <= m["mse"] < 0.05 and -1 <= m["r"] <= 1
    assert report["data_generated"] is True and report["time_s"] > 0
    assert report["metrics"]["test"]["hardness"]["r"] > 0.9


def test_onnx_metadata_and_initializers(shipped_report):
    _, res, out = shipped_report
    proto = onnx.load(str(out))
    meta = {p.key: json.loads(p.value) for p in proto.metadata_props}
    assert set(meta) == {"hapticsdk." + k for k in onnx_export.REQUIRED_KEYS} | {"hapticsdk.constraint_context"}
    ctx = meta["hapticsdk.constraint_context"]
    assert 3.3 < ctx["press_force_min_n"] < ctx["press_force_max_n"] < 10.0  # generated presses: 4-6 N
    assert [f["name"] for f in meta["hapticsdk.features"]] == list(FEATURE_NAMES)
    assert meta["hapticsdk.dimensions"] == ["hardness", "roughness"]
    assert meta["hapticsdk.df_hz"] == 0.4 and meta["hapticsdk.architecture"] == "mlp-tanh"
    assert meta["hapticsdk.data_generated"] is True
    assert set(meta["hapticsdk.feature_defaults"]) == set(FEATURE_NAMES)
    inits = {t.name: onnx.numpy_helper.to_array(t) for t in proto.graph.initializer}
    for k, v in res.model.weights.items():
        np.testing.assert_array_equal(inits[k].astype(np.float64), v)
    assert proto.producer_name == onnx_export.PRODUCER


def test_parity_on_random_network_across_feature_box():
    from hapticsdk.models import MLPModel

    rng = np.random.default_rng(4)
    w = {"W1": rng.normal(size=(20, 5)), "b1": rng.normal(size=20), "W2": rng.normal(size=(2, 20)),
         "b2": rng.normal(size=2), "x_min": np.array([0.1, 3, 40, 0.8, 0.4]),
         "x_max": np.array([4.5, 130, 200, 4, 8]), "y_min": np.array([0.05, 0.2]), "y_max": np.array([0.9, 0.7])}
    w = {k: np.asarray(v, np.float32).astype(float) for k, v in w.items()}
    m = MLPModel(w, FEATURE_NAMES, ["hardness", "roughness"])
    X = w["x_min"] + rng.random((500, 5)) * (w["x_max"] - w["x_min"])
    from hapticsdk.features import Feature, FeatureSpace
    space = FeatureSpace(tuple(Feature(n, "u", float(a), float(b)) for n, a, b in zip(FEATURE_NAMES, w["x_min"], w["x_max"])))
    meta = onnx_export.build_metadata(space, ["hardness", "roughness"], feature_defaults={}, df_hz=0.4,
                                      metrics={}, training_data_sha256="x", data_generated=True)
    assert onnx_export.onnx_parity(onnx_export.model_bytes(m, meta), m, X) < 1e-5


def _ns(**kw):
    return argparse.Namespace(**kw)


def test_cli_register_and_handlers(tmp_path, small_recordings, capsys):
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd")
    cli.register(sub)
    a = ap.parse_args(["train", str(SHIPPED), "--out", str(tmp_path / "m.onnx"), "--json", "--folds", "0",
                       "--restarts", "1"])
    assert a.func(a) == 0
    rep = json.loads(capsys.readouterr().out)
    assert {"metrics", "onnx_parity_max_abs", "time_s", "data_generated"} <= set(rep)
    assert set(rep["metrics"]) == {"train", "validation", "test"}
    root, _ = small_recordings
    a = ap.parse_args(["features", str(root), "--json"])
    assert a.func(a) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["samples"]) == {"S1", "S2", "S3"} and out["df_hz"] == 0.4
    a = ap.parse_args(["dataset", "generate", str(tmp_path / "gen"), "--samples", "3", "--trials", "2",
                       "--raters", "2", "--format", "csv"])
    assert a.func(a) == 0
    assert (tmp_path / "gen" / "recordings.json").is_file() and (tmp_path / "gen" / "trial_features.csv").is_file()
    # training from raw recordings (extraction inside) works too
    rep, _ = pipeline.train_dataset(tmp_path / "gen", None, lm.TrainConfig(folds=0, restarts=1, hidden=4))
    assert rep["n_rows"] == 6


def test_cli_reports_broken_data(tmp_path, capsys):
    ap = argparse.ArgumentParser()
    cli.register(ap.add_subparsers(dest="cmd"))
    a = ap.parse_args(["features", str(tmp_path)])
    assert a.func(a) == 2
    assert "recordings.json" in capsys.readouterr().err
