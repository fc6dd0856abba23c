import numpy as np
import pytest

from hapticsdk.errors import ModelError, ValidationError
from hapticsdk.perception.models import CompositeModel, MLPModel, PerceptionModel


def mlp(seed=0, d=5, k=2, feats=None, dims=None):
    rng = np.random.default_rng(seed)
    w = dict(W1=rng.normal(size=(20, d)), b1=rng.normal(size=20), W2=rng.normal(size=(k, 20)) * 0.5,
             b2=rng.normal(size=k) * 0.1, x_min=np.zeros(d), x_max=np.arange(1, d + 1.0),
             y_min=np.zeros(k), y_max=np.ones(k))
    return MLPModel(w, feats or [f"f{i}" for i in range(d)], dims or [f"d{i}" for i in range(k)])


def test_mlp_matches_formula_written_out():
    m = mlp()
    X = np.random.default_rng(1).random((7, 5)) * 3
    xs = 2 * (X - m.x_min) / (m.x_max - m.x_min) - 1
    ys = np.tanh(np.tanh(xs @ m.W1.T + m.b1) @ m.W2.T + m.b2)
    np.testing.assert_allclose(m.predict(X), (ys + 1) / 2, atol=1e-12)


def test_analytic_jacobian_equals_finite_differences():
    m = mlp()
    X = np.random.default_rng(2).random((4, 5)) * 3
    np.testing.assert_allclose(m.jacobian(X), PerceptionModel.jacobian(m, X), atol=1e-7)


def test_predict_validates():
    m = mlp()
    with pytest.raises(ValidationError):
        m.predict(np.zeros((2, 4)))
    with pytest.raises(ValidationError):
        m.predict(np.full((1, 5), np.nan))


def test_bad_weights_are_named():
    with pytest.raises(ModelError, match="W2"):
        MLPModel(dict(W1=np.zeros((3, 2)), b1=np.zeros(3), W2=np.zeros((2, 4)), b2=np.zeros(2),
                      x_min=np.zeros(2), x_max=np.ones(2), y_min=np.zeros(2), y_max=np.ones(2)),
                 ["a", "b"], ["h", "r"])


def test_composite_routes_columns_and_jacobian():
    a = mlp(0, d=2, k=1, feats=["x", "y"], dims=["h"])
    b = mlp(1, d=2, k=1, feats=["y", "z"], dims=["w"])
    c = CompositeModel([a, b])
    assert c.feature_names == ("x", "y", "z") and c.dimension_names == ("h", "w")
    X = np.random.default_rng(3).random((5, 3))
    np.testing.assert_allclose(c.predict(X)[:, 0], a.predict(X[:, :2])[:, 0])
    np.testing.assert_allclose(c.predict(X)[:, 1], b.predict(X[:, 1:])[:, 0])
    np.testing.assert_allclose(c.jacobian(X), PerceptionModel.jacobian(c, X), atol=1e-7)
    with pytest.raises(ModelError, match="covered by two"):
        CompositeModel([a, a])
