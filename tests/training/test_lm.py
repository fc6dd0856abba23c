"""LM training: exact Jacobian, metrics formulas, split by sample, determinism."""

import numpy as np
import pytest

from hapticsdk.errors import ValidationError
from hapticsdk.training import lm


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(3)
    H, k = 6, 2
    th = rng.normal(size=lm.n_params(5, H, k))
    Xs = rng.uniform(-1, 1, (4, 5))
    _, J = lm.jacobian(th, Xs, H, k)
    eps = 1e-6
    E = np.eye(len(th)) * eps
    Jn = np.stack([((lm.forward(th + e, Xs, H, k)[0] - lm.forward(th - e, Xs, H, k)[0]) / (2 * eps)).ravel()
                   for e in E], axis=1)
    assert np.abs(J - Jn).max() < 1e-8


def test_metrics_are_formulas_2_and_3():
    rng = np.random.default_rng(0)
    y = rng.random((40, 2))
    yhat = y + 0.1 * rng.standard_normal((40, 2))
    mse, r = lm.mse_r(y, yhat)
    np.testing.assert_allclose(mse, ((y - yhat) ** 2).mean(0))
    np.testing.assert_allclose(r, [np.corrcoef(y[:, j], yhat[:, j])[0, 1] for j in range(2)])
    assert np.isnan(lm.mse_r(np.ones((5, 1)), np.arange(5.0)[:, None])[1][0])


def test_split_is_by_sample_and_seeded():
    names = [f"S{i}" for i in range(1, 24)]
    sp = lm.split_samples(names, (0.7, 0.15, 0.15), 0)
    assert [len(sp[s]) for s in lm.SPLITS] == [17, 3, 3]
    assert sorted(sum(sp.values(), [])) == sorted(names)
    assert sp == lm.split_samples(names, (0.7, 0.15, 0.15), 0)
    assert sp != lm.split_samples(names, (0.7, 0.15, 0.15), 1)
    with pytest.raises(ValidationError):
        lm.split_samples(["a", "b"], (0.7, 0.15, 0.15), 0)


def test_lm_learns_a_smooth_function_and_is_deterministic():
    rng = np.random.default_rng(1)
    groups = np.repeat([f"g{i}" for i in range(30)], 4)
    X = rng.uniform(0, 2, (120, 5))
    Y = np.stack([0.5 + 0.4 * np.tanh(X[:, 0] - X[:, 1]), 0.3 + 0.1 * X[:, 2] * X[:, 3]], 1)
    cfg = lm.TrainConfig(hidden=8, restarts=2, folds=0, max_epochs=200)
    a = lm.train(X, Y, groups, list("abcde"), ["h", "r"], cfg)
    b = lm.train(X, Y, groups, list("abcde"), ["h", "r"], cfg)
    assert a.metrics["test"]["h"]["mse"] < 1e-3 and a.metrics["test"]["r"]["r"] > 0.98
    for key in a.model.weights:
        np.testing.assert_array_equal(a.model.weights[key], b.model.weights[key])
    tr_rows = np.isin(groups, a.split["train"])
    assert not np.isin(groups[tr_rows], a.split["test"] + a.split["validation"]).any()


def test_train_rejects_nan():
    X = np.ones((9, 5))
    X[0, 0] = np.nan
    with pytest.raises(ValidationError):
        lm.train(X, np.zeros((9, 2)), [f"s{i // 3}" for i in range(9)], list("abcde"), ["h", "r"])
