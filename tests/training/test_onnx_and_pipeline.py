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


# Rebuilding across numpy / scipy / onnx versions: the sums behind every number may be
# taken in another order (pairwise or SIMD summation, another FFT or filter kernel), so
# equal bytes are guaranteed only for what is copied or counted (structure, names,
# strings, integers, min/max). Numbers are compared with tolerances derived below.
EPS = float(np.finfo(np.float64).eps)
#: operations behind one generated trial value: its signals have fewer than 4096 samples
#: (500 Hz x at most 4 s per press-and-slide), and a float64 sum of N terms is exact to
#: N * eps of the sum of its magnitudes
N_OPS = 4096
RTOL_SUM = N_OPS * EPS                       # ~9e-13
#: metrics are shown to people with at most 4 significant digits (docs, CLI); agreeing
#: to 1e-6 relative keeps every shown digit
RTOL_SHOWN = 1e-6


def _close_tree(a, b, rtol, path="$"):
    """Equal structure; str/int/bool/None exactly; floats within ``rtol`` (relative)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), path
        for k in a:
            _close_tree(a[k], b[k], rtol, f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _close_tree(x, y, rtol, f"{path}[{i}]")
    elif isinstance(a, float) or isinstance(b, float):
        assert not isinstance(a, bool) and not isinstance(b, bool), path
        assert a == pytest.approx(b, rel=rtol, abs=0.0), f"{path}: {a!r} vs {b!r}"
    else:
        assert a == b and type(a) is type(b), f"{path}: {a!r} vs {b!r}"


def _csv_rows(path):
    import csv
    with open(path, newline="") as f:
        return list(csv.reader(f))


def test_default_model_rebuilds_within_float32_rounding(shipped_report):
    """The default model rebuilt from the shipped data set is the shipped one: the same
    graph and metadata; predictions equal to within what float32 rounding of the trained
    weights can move them."""
    import onnxruntime as ort

    report, _, out = shipped_report
    got, ref = onnx.load(str(out)), onnx.load(str(DEFAULT_ONNX))
    w_got = {t.name: onnx.numpy_helper.to_array(t) for t in got.graph.initializer}
    w_ref = {t.name: onnx.numpy_helper.to_array(t) for t in ref.graph.initializer}
    assert set(w_got) == set(w_ref)
    # normalisation constants come from min/max of the data: exact
    for k in ("x_min", "x_max", "y_min", "y_max", "x_scale", "y_half", "one"):
        np.testing.assert_array_equal(w_got[k], w_ref[k], err_msg=k)
    # the graph apart from its numbers is byte-identical
    for m in (got, ref):
        del m.metadata_props[:]
        for t in m.graph.initializer:
            t.ClearField("raw_data")
            t.ClearField("float_data")
    assert got.SerializeToString() == ref.SerializeToString()
    # metadata: names, hashes and counts exact, metrics to every shown digit
    meta_got = {p.key: json.loads(p.value) for p in onnx.load(str(out)).metadata_props}
    meta_ref = {p.key: json.loads(p.value) for p in onnx.load(str(DEFAULT_ONNX)).metadata_props}
    _close_tree(meta_got, meta_ref, RTOL_SHOWN)
    # predictions over the data set: two float32 roundings of each weight (u = 2^-24
    # relative each) move an output by at most
    #   2u * y_half * (|W2| (|W1| 1 + |b1|) + |W2| 1 + |b2|)      (|x_s| <= 1, |tanh'| <= 1)
    u = 2.0 ** -24
    W1, b1, W2, b2 = (np.abs(w_ref[k].astype(np.float64)) for k in ("W1", "b1", "W2", "b2"))
    bound = 2 * u * w_ref["y_half"] * (W2 @ (W1.sum(axis=1) + b1) + W2.sum(axis=1) + b2)
    X = pipeline.load_table(SHIPPED).X.astype(np.float32)
    pred = [ort.InferenceSession(str(p), providers=["CPUExecutionProvider"]).run(None, {"G": X})[0]
            for p in (out, DEFAULT_ONNX)]
    assert np.all(np.abs(pred[0] - pred[1]) <= bound), (np.abs(pred[0] - pred[1]).max(axis=0), bound)


def test_shipped_dataset_regenerates_within_roundoff(tmp_path):
    """Regenerating the shipped (generated) data set gives the same rows; each value to
    within the float64 roundoff of the sums behind it."""
    table = pipeline.generate_feature_dataset(tmp_path, 23)
    for name in ("trial_features.csv", "sample_features.csv"):
        got, ref = _csv_rows(tmp_path / name), _csv_rows(SHIPPED / name)
        assert got[0] == ref[0] and len(got) == len(ref), name
        header = ref[0]
        for r_got, r_ref in zip(got[1:], ref[1:]):
            row = dict(zip(header, r_ref))
            for col, a, b in zip(header, r_got, r_ref):
                if col in ("sample", "trial", "label", "substrate", "texture"):
                    assert a == b, (name, col)
                elif col.endswith("_std"):
                    # a standard deviation cancels its mean away: its variance is exact to
                    # ~N eps of mean^2, not of itself
                    mean = float(row[col[:-4] + "_mean"])
                    assert abs(float(a) ** 2 - float(b) ** 2) <= 2 * RTOL_SUM * mean ** 2, (name, col, a, b)
                else:
                    assert float(a) == pytest.approx(float(b), rel=RTOL_SUM, abs=0.0), (name, col, a, b)
    for name in ("ratings.json", "dataset.json", "truth.json"):
        _close_tree(json.loads((tmp_path / name).read_text()), json.loads((SHIPPED / name).read_text()),
                    RTOL_SUM)
    shipped_mat = json.loads((ROOT / "hapticsdk/data/materials.json").read_text())
    _close_tree(pipeline.build_materials(table), shipped_mat, RTOL_SUM)


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
    from hapticsdk.perception.models import MLPModel

    rng = np.random.default_rng(4)
    w = {"W1": rng.normal(size=(20, 5)), "b1": rng.normal(size=20), "W2": rng.normal(size=(2, 20)),
         "b2": rng.normal(size=2), "x_min": np.array([0.1, 3, 40, 0.8, 0.4]),
         "x_max": np.array([4.5, 130, 200, 4, 8]), "y_min": np.array([0.05, 0.2]), "y_max": np.array([0.9, 0.7])}
    w = {k: np.asarray(v, np.float32).astype(float) for k, v in w.items()}
    m = MLPModel(w, FEATURE_NAMES, ["hardness", "roughness"])
    X = w["x_min"] + rng.random((500, 5)) * (w["x_max"] - w["x_min"])
    from hapticsdk.perception.features import Feature, FeatureSpace
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
