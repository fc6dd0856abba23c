"""A feature is a name and a unit: one name in two units is a named conflict, not a merge."""

import pytest

from hapticsdk.errors import FeatureConflictError, ModelError
from hapticsdk.perception.features import Feature, FeatureSpace, same_unit


def test_same_name_same_unit_merges():
    a = FeatureSpace((Feature("GS", "N/mm", 0, 10, owner="dimension 'hardness'"),))
    b = FeatureSpace((Feature("GS", "N / mm", 0, 5, owner="dimension 'other'"), Feature("x.q", "1", 0, 1)))
    u = a.union(b)
    assert u.names == ("GS", "x.q") and u["GS"].upper == 10   # the first declaration is kept


def test_same_name_other_unit_names_both_owners():
    a = FeatureSpace((Feature("GS", "N/mm", 0, 10, owner="dimension 'hardness'"),))
    b = FeatureSpace((Feature("GS", "N/m", 0, 1e4, owner="dimension 'stickiness'"),))
    with pytest.raises(FeatureConflictError) as ei:
        a.union(b)
    msg = str(ei.value)
    assert "'hardness'" in msg and "'stickiness'" in msg and "N/mm" in msg and "N/m'" in msg
    assert ei.value.field == "features.GS"


def test_owner_is_not_part_of_identity():
    assert Feature("W", "mJ", 0, 1, owner="a") == Feature("W", "mJ", 0, 1, owner="b")
    assert same_unit("(m/s^2)^2", "(m/s^2) ^2") and not same_unit("N/mm", "N/m")


def test_a_plugin_dimension_redeclaring_gs_in_n_per_m_fails_at_problem_build(monkeypatch):
    pytest.importorskip("hapticsdk_hardness")
    from hapticsdk.perception.dimensions import PerceptionDimension
    from hapticsdk.plugins import registry
    from hapticsdk.solvers.problems import build_problem

    class Stickiness(PerceptionDimension):
        name = "stickiness"
        features = (Feature("GS", "N/m", 0.0, 1e4, "stiffness, in the wrong unit"),)
        default_model = "default"

        def renderer(self, features, **options):   # pragma: no cover - never reached
            raise AssertionError

    reg = registry("dimension")
    reg.register("stickiness", Stickiness)
    try:
        with pytest.raises(FeatureConflictError, match="'hardness'.*'stickiness'|'stickiness'.*'hardness'"):
            build_problem({"hardness": 0.5, "stickiness": 0.5})
    finally:
        reg.unregister("stickiness")


def test_a_model_reading_a_feature_in_another_unit_is_a_model_error():
    pytest.importorskip("hapticsdk_hardness")
    from hapticsdk.perception.models import MLPModel
    from hapticsdk.solvers.problems import build_problem, load_model
    import numpy as np
    base = load_model("default")
    fs = base.feature_space
    feats = tuple(Feature(f.name, "N/m" if f.name == "GS" else f.unit, f.lower, f.upper) for f in fs)
    W = base.mlp.weights
    m = MLPModel(W, [f.name for f in feats], list(base.dimension_names), feature_space=FeatureSpace(feats),
                 metadata=dict(base.metadata), name="wrong-units")
    with pytest.raises(ModelError, match="'GS'.*'N/m'"):
        build_problem({"hardness": 0.5}, model=m)
