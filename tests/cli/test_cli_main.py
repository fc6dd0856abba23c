"""The `hapticsdk` command end to end, through the installed entry points."""

import json
import subprocess
import sys

import pytest

from hapticsdk.cli import main
from hapticsdk.perception.materials import load_library

EXPECTED_PLUGINS = {
    ("dimension", "hardness", "hapticsdk-hardness"),
    ("dimension", "roughness", "hapticsdk-roughness"),
    ("solver", "ga", "hapticsdk-ga"),
    ("model", "default", "hapticsdk-onnx"),
}


def run_json(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr().out
    return code, json.loads(out)


def test_plugins_json_lists_the_four_distributions(capsys):
    code, rows = run_json(capsys, "plugins", "--json")
    assert code == 0
    got = {(r["kind"], r["name"], r["distribution"]) for r in rows}
    assert EXPECTED_PLUGINS <= got
    for r in rows:
        assert set(r) >= {"kind", "name", "distribution", "version"} and r["version"]


@pytest.mark.parametrize("name", ["S3", "S12", "S20"])
def test_solve_json_reaches_library_targets_deterministically(capsys, name):
    m = load_library().get(name)
    h, r = m.intensities["hardness"], m.intensities["roughness"]
    argv = ["solve", "--hardness", str(h), "--roughness", str(r), "--seed", "7", "--json"]
    code, out = run_json(capsys, *argv)
    assert set(out) >= {"success", "x", "intensities", "error", "constraint_violation", "time_s", "nfev"}
    assert out["success"] and code == 0, out["message"]
    # closed loop: run the model on the answer ourselves
    from hapticsdk.solvers.problems import load_model
    model = load_model("default")
    G = [[out["x"][n] for n in model.feature_names]]
    pred = model.predict(G)[0]
    idx = {d: i for i, d in enumerate(model.dimension_names)}
    assert abs(pred[idx["hardness"]] - h) + abs(pred[idx["roughness"]] - r) <= 0.02
    for f in model.feature_space:
        assert f.lower - 1e-9 <= out["x"][f.name] <= f.upper + 1e-9
    assert out["constraint_violation"] == 0.0
    W_v = 3.3 ** 2 / (2 * out["x"]["GS"])
    assert out["x"]["W"] >= W_v * (1 - 1e-9)
    _, again = run_json(capsys, *argv)
    assert again["x"] == out["x"]


@pytest.mark.parametrize("argv,needle", [
    (["solve", "--hardness", "nan", "--roughness", "0.3"], "NaN"),
    (["solve", "--hardness", "1.5", "--roughness", "0.3"], "outside 0..1"),
    (["solve", "--hardness", "0.5", "--method", "nosuch"], "no solver named 'nosuch'"),
    (["render", "S99"], "unknown material 'S99'"),
])
def test_bad_input_gets_a_clear_error(argv, needle):
    proc = subprocess.run([sys.executable, "-m", "hapticsdk", *argv], capture_output=True, text=True)
    assert proc.returncode == 2
    assert needle in proc.stderr, proc.stderr


def test_render_named_material_json(capsys):
    code, out = run_json(capsys, "render", "S7", "--seconds", "1", "--json")
    assert code == 0
    assert out["material"] == "S7"
    assert set(out["tick"]) >= {"ticks", "median_us", "p99_us", "overruns"}
    assert out["tick"]["ticks"] == 1000
    assert out["solve"]["success"]
    assert out["actuators"]


def test_render_malformed_scene_names_the_field(tmp_path, capsys):
    p = tmp_path / "scene.json"
    p.write_text(json.dumps({"objects": [{"material": 5}]}))
    code = main(["render", "--scene", str(p), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 2 and out["field"] and "scene" in out["field"]


def test_plugin_materials_are_listed_and_rendered_by_name(capsys):
    pytest.importorskip("hapticsdk_warmth", reason="the example plugin is part of requirements-dev.txt")
    code, out = run_json(capsys, "materials", "--with-plugins", "--json")
    names = {m["name"]: m for m in out["materials"]}
    assert "S7" in names and names["warm-felt"]["source"].startswith("plugin")
    code, out = run_json(capsys, "materials", "--json")
    assert "warm-felt" not in {m["name"] for m in out["materials"]}
    code, out = run_json(capsys, "render", "warm-felt", "--seconds", "0.2", "--json")
    assert code == 0 and out["material"] == "warm-felt" and "warmth" in out["dimensions"]
