"""Outputs say what they measure: the model's data provenance travels with every solve
and the CLI prints it (generated data, and what "error" means)."""

import json

import pytest

pytest.importorskip("hapticsdk_hardness")

from hapticsdk.cli import main  # noqa: E402
from hapticsdk.perception.models import MLPModel  # noqa: E402
from hapticsdk.solvers.problems import load_model, solve  # noqa: E402


def _copy_of_default(data_generated):
    base = load_model("default")
    meta = dict(base.metadata)
    meta["data_generated"] = data_generated
    return MLPModel(base.mlp.weights, base.feature_names, base.dimension_names,
                    feature_space=base.feature_space, metadata=meta, name="copy")


def test_default_model_says_generated_and_what_error_means():
    p = load_model("default").provenance()
    assert p["data_generated"] is True and p["training_data_sha256"]
    assert "GENERATED" in p["statement"] and "not a measured perceptual accuracy" in p["statement"]


@pytest.mark.parametrize("flag, expect", [(False, "recorded data"), ("false", "recorded data"),
                                          (True, "GENERATED"), (None, "not declared")])
def test_statement_follows_the_models_metadata(flag, expect):
    res = solve({"hardness": 0.5, "roughness": 0.5}, model=_copy_of_default(flag), seed=0)
    assert expect in res.model["statement"]
    assert res.to_json()["model"]["data_generated"] == {"false": False}.get(flag, flag)


def test_batch_results_carry_the_provenance_too():
    import numpy as np
    res = solve(np.array([[0.3, 0.3], [0.6, 0.4]]), dimensions=["hardness", "roughness"], seed=0)
    assert res.model["data_generated"] is True


def test_cli_solve_and_render_print_it(capsys):
    main(["solve", "--hardness", "0.5", "--roughness", "0.5", "--seed", "0"])
    text = capsys.readouterr().out
    assert "trained on GENERATED data" in text and "not a measured perceptual accuracy" in text
    main(["render", "S7", "--seconds", "0.05"])
    assert "trained on GENERATED data" in capsys.readouterr().out
    main(["render", "S7", "--seconds", "0.05", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert out["solve"]["model"]["data_generated"] is True
