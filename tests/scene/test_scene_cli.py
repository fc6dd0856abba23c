"""`hapticsdk plan SCENE [--json]`."""

from __future__ import annotations

import json
from pathlib import Path


from hapticsdk.cli import main
from hapticsdk.plan import RenderPlan

SCENES = Path(__file__).resolve().parents[2] / "examples" / "scenes"


def test_plan_json_shape(capsys, tmp_path):
    out_plan = tmp_path / "plan.json"
    rc = main(["plan", "S7", "--json", "--threshold", "5", "-o", str(out_plan)])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    m = out["materials"]["S7"]
    assert set(m) >= {"dimensions", "dropped", "features", "actuators"}
    for d in m["dropped"]:
        assert set(d) >= {"dimension", "reason", "predicted_loss_percent"}
        assert d["predicted_loss_percent"] < 5
    assert isinstance(out["plugins_loaded"], list) and out["plugins_loaded"]
    assert RenderPlan.load(out_plan).material("S7").features == m["features"]


def test_plan_no_importance_keeps_everything(capsys):
    assert main(["plan", "S7", "--json", "--no-importance"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["materials"]["S7"]["dimensions"] == ["hardness", "roughness"]
    assert out["materials"]["S7"]["dropped"] == []


def test_plan_text_and_errors(capsys):
    assert main(["plan", str(SCENES / "hardness-only.json")]) == 0
    text = capsys.readouterr().out
    assert "material soft" in text and "force->omni-virtual" in text
    assert main(["plan", "no-such-thing", "--json"]) == 2
    err = json.loads(capsys.readouterr().out)
    assert err["field"] == "scene"
