"""Training of the paper's 5-20-2 network by Levenberg-Marquardt, and its metrics.

Network (as :class:`hapticsdk.perception.models.MLPModel`): inputs and targets scaled to [-1, 1]
the MATLAB ``mapminmax`` way, ``tanh`` hidden layer, ``tanh`` output layer.

Training (own implementation, after MATLAB ``trainlm``): residuals are the scaled
outputs minus the scaled targets; each epoch solves ``(J^T J + mu I) d = -J^T r`` with
the exact Jacobian ``J`` (analytic back-propagation, all rows at once), accepts the
step if the sum of squared errors falls (``mu *= 0.1``) and otherwise raises ``mu``
tenfold and retries. Early stopping: the validation MSE is checked after every
epoch; training stops after 6 epochs without improvement and the weights of the
best validation epoch are kept. Several seeded initialisations (Nguyen-Widrow) are
trained and the one with the lowest validation MSE is kept. Everything is seeded and
uses fixed-order float64 numpy/LAPACK operations, so a run is reproducible.

Splits are by sample, never by trial: every row (trial) of a sample lands in the
same split. Metrics are formulas (2) and (3) of the paper on the 0..1 intensities.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np

from ..errors import ValidationError
from ..perception.models import MLPModel

SPLITS = ("train", "validation", "test")


@dataclass(frozen=True)
class TrainConfig:
    """Training settings (defaults: the paper's Table 1 / MATLAB ``trainlm`` defaults).

    ``fractions``: train/validation/test shares of the *samples*; ``restarts``: seeded
    initialisations tried; ``folds``: k of the grouped k-fold cross-validation (0: none).
    """

    hidden: int = 20
    seed: int = 0
    fractions: tuple[float, float, float] = (0.70, 0.15, 0.15)
    max_epochs: int = 1000
    max_fail: int = 6
    mu: float = 1e-3
    mu_dec: float = 0.1
    mu_inc: float = 10.0
    mu_max: float = 1e10
    min_grad: float = 1e-7
    restarts: int = 5
    folds: int = 5
    #: How targets are scaled to [-1, 1]: ``"intensity"`` maps the whole 0..1 intensity
    #: scale (default), ``"data"`` maps the data set's min..max as MATLAB's ``mapminmax``
    #: does. With ``"data"`` the extreme samples sit on tanh's asymptotes, so the
    #: network can only approach them and the inverse solve cannot reach them; with
    #: ``"intensity"`` every rating 0 < y < 1 is inside the output range.
    target_scale: str = "intensity"

    def to_dict(self) -> dict:
        """The settings as a JSON-ready dict (tuples as lists)."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


# ----------------------------------------------------------------------------- metrics
def mse_r(y: np.ndarray, yhat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per column MSE (formula (2)) and Pearson R (formula (3)); R is NaN for a constant column."""
    y = np.atleast_2d(np.asarray(y, float))
    yhat = np.atleast_2d(np.asarray(yhat, float))
    n = y.shape[0]
    mse = np.mean((yhat - y) ** 2, axis=0)
    num = n * np.sum(y * yhat, 0) - np.sum(y, 0) * np.sum(yhat, 0)
    den = np.sqrt((n * np.sum(y ** 2, 0) - np.sum(y, 0) ** 2) * (n * np.sum(yhat ** 2, 0) - np.sum(yhat, 0) ** 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)
    return mse, r


def metrics_dict(y: np.ndarray, yhat: np.ndarray, dims: Sequence[str]) -> dict[str, dict[str, float]]:
    """``{dimension: {"mse": .., "r": .., "n": rows}}``."""
    mse, r = mse_r(y, yhat)
    return {d: {"mse": float(mse[j]), "r": float(r[j]), "n": int(len(y))} for j, d in enumerate(dims)}


# ----------------------------------------------------------------------------- network
def _unpack(theta: np.ndarray, d: int, H: int, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    i = 0
    W1 = theta[i: i + H * d].reshape(H, d); i += H * d
    b1 = theta[i: i + H]; i += H
    W2 = theta[i: i + k * H].reshape(k, H); i += k * H
    b2 = theta[i: i + k]
    return W1, b1, W2, b2


def n_params(d: int, H: int, k: int) -> int:
    """Number of weights of a ``d``-``H``-``k`` network (both layers, with biases)."""
    return H * d + H + k * H + k


def forward(theta: np.ndarray, Xs: np.ndarray, H: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Scaled outputs ``(n, k)`` and hidden activations ``(n, H)`` for scaled inputs."""
    W1, b1, W2, b2 = _unpack(theta, Xs.shape[1], H, k)
    h = np.tanh(Xs @ W1.T + b1)
    return np.tanh(h @ W2.T + b2), h


def jacobian(theta: np.ndarray, Xs: np.ndarray, H: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Scaled outputs ``(n, k)`` and exact Jacobian ``d y_s / d theta`` of shape ``(n*k, P)``."""
    n, d = Xs.shape
    W1, b1, W2, b2 = _unpack(theta, d, H, k)
    h = np.tanh(Xs @ W1.T + b1)
    y = np.tanh(h @ W2.T + b2)
    dy = 1.0 - y ** 2                                          # (n, k)
    g = dy[:, :, None] * W2[None] * (1.0 - h ** 2)[:, None, :]  # (n, k, H) d y / d z1
    eye = np.eye(k)
    J = np.concatenate([
        (g[:, :, :, None] * Xs[:, None, None, :]).reshape(n, k, H * d),
        g,
        (eye[None, :, :, None] * (dy[:, :, None, None] * h[:, None, None, :])).reshape(n, k, k * H),
        eye[None] * dy[:, :, None],
    ], axis=2)
    return y, J.reshape(n * k, -1)


def init_nguyen_widrow(d: int, H: int, k: int, rng: np.random.Generator) -> np.ndarray:
    """Nguyen-Widrow initialisation for inputs in [-1, 1]; small random output layer."""
    beta = 0.7 * H ** (1.0 / d)
    W1 = rng.uniform(-1.0, 1.0, (H, d))
    W1 *= beta / np.linalg.norm(W1, axis=1, keepdims=True)
    b1 = beta * np.linspace(-1.0, 1.0, H) * np.sign(rng.uniform(-1, 1, H))
    W2 = rng.uniform(-0.5, 0.5, (k, H))
    b2 = rng.uniform(-0.5, 0.5, k)
    return np.concatenate([W1.ravel(), b1, W2.ravel(), b2])


@dataclass
class FitResult:
    theta: np.ndarray
    epochs: int
    best_epoch: int
    val_mse: float
    train_mse: float
    stop: str


def lm_fit(theta0: np.ndarray, Xtr: np.ndarray, Ytr: np.ndarray, Xval: np.ndarray, Yval: np.ndarray,
           H: int, cfg: TrainConfig) -> FitResult:
    """Levenberg-Marquardt on scaled data with validation early stopping (see module doc)."""
    k = Ytr.shape[1]
    theta = theta0.copy()
    P = len(theta)
    mu = cfg.mu
    y, J = jacobian(theta, Xtr, H, k)
    r = (y - Ytr).ravel()
    sse = float(r @ r)
    has_val = len(Xval) > 0

    def val_mse(th):
        return float(np.mean((forward(th, Xval, H, k)[0] - Yval) ** 2)) if has_val else sse / r.size

    best_theta, best_val, best_epoch = theta.copy(), val_mse(theta), 0
    fails, stop, epoch = 0, "max_epochs", 0
    eye = np.eye(P)
    for epoch in range(1, cfg.max_epochs + 1):
        g = J.T @ r
        if float(np.sqrt(g @ g)) < cfg.min_grad:
            stop = "min_grad"
            break
        A = J.T @ J
        accepted = False
        while mu <= cfg.mu_max:
            step = np.linalg.solve(A + mu * eye, -g)
            cand = theta + step
            yc = forward(cand, Xtr, H, k)[0]
            rc = (yc - Ytr).ravel()
            sc = float(rc @ rc)
            if sc < sse:
                theta, sse = cand, sc
                mu *= cfg.mu_dec
                accepted = True
                break
            mu *= cfg.mu_inc
        if not accepted:
            stop = "mu_max"
            break
        y, J = jacobian(theta, Xtr, H, k)
        r = (y - Ytr).ravel()
        v = val_mse(theta)
        if v < best_val:
            best_theta, best_val, best_epoch, fails = theta.copy(), v, epoch, 0
        else:
            fails += 1
            if has_val and fails >= cfg.max_fail:
                stop = "validation"
                break
    if not has_val:
        best_theta, best_epoch = theta, epoch
    tr_mse = float(np.mean((forward(best_theta, Xtr, H, k)[0] - Ytr) ** 2))
    return FitResult(best_theta, epoch, best_epoch, best_val, tr_mse, stop)


# ----------------------------------------------------------------------------- splits
def split_samples(names: Sequence[str], fractions: Sequence[float], seed: int) -> dict[str, list[str]]:
    """Seeded split of sample names into train/validation/test by ``fractions``.

    Validation and test get ``round(f * n)`` samples each (at least 1 when the
    fraction is > 0 and n >= 3); train gets the rest.
    """
    names = list(names)
    n = len(names)
    if n < 3:
        raise ValidationError(f"need at least 3 samples to split, got {n}", field="samples")
    f_tr, f_val, f_te = fractions
    n_val = max(1, int(round(f_val * n))) if f_val > 0 else 0
    n_te = max(1, int(round(f_te * n))) if f_te > 0 else 0
    if n - n_val - n_te < 1:
        raise ValidationError(f"split {fractions} leaves no training samples of {n}", field="fractions")
    perm = np.random.default_rng(np.random.SeedSequence([seed, 101])).permutation(n)
    val = sorted((names[i] for i in perm[:n_val]), key=names.index)
    te = sorted((names[i] for i in perm[n_val:n_val + n_te]), key=names.index)
    tr = [s for s in names if s not in set(val) | set(te)]
    return {"train": tr, "validation": val, "test": te}


def mapminmax_range(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column minima and maxima (the ``mapminmax`` settings)."""
    return A.min(axis=0), A.max(axis=0)


def target_range(Y: np.ndarray, cfg: "TrainConfig") -> tuple[np.ndarray, np.ndarray]:
    """The target scaling range for ``cfg.target_scale`` (see :class:`TrainConfig`)."""
    if cfg.target_scale == "data":
        return mapminmax_range(Y)
    if cfg.target_scale == "intensity":
        k = Y.shape[1]
        return np.zeros(k), np.ones(k)
    raise ValidationError(f"unknown target_scale {cfg.target_scale!r}; valid: 'intensity', 'data'",
                          field="target_scale")


def _scale(A, lo, hi):
    span = hi - lo
    return np.where(span > 0, 2.0 * (A - lo) / np.where(span > 0, span, 1.0) - 1.0, 0.0)


@dataclass
class TrainedNet:
    """A trained network: float32-representable weights and the fit record."""

    weights: dict[str, np.ndarray]
    fit: FitResult
    restart: int


def fit_network(X: np.ndarray, Y: np.ndarray, tr: np.ndarray, val: np.ndarray, cfg: TrainConfig, *,
                x_range: tuple[np.ndarray, np.ndarray], y_range: tuple[np.ndarray, np.ndarray],
                seed: int) -> TrainedNet:
    """Train ``cfg.restarts`` initialisations on rows ``tr`` (early stopping on rows ``val``).

    Weights are rounded to float32 (what the ONNX file stores) before they are returned.
    """
    Xs = _scale(X, *x_range)
    Ys = _scale(Y, *y_range)
    d, k, H = X.shape[1], Y.shape[1], cfg.hidden
    best: tuple[float, int, FitResult] | None = None
    for rs in range(cfg.restarts):
        rng = np.random.default_rng(np.random.SeedSequence([seed, 7, rs]))
        res = lm_fit(init_nguyen_widrow(d, H, k, rng), Xs[tr], Ys[tr], Xs[val], Ys[val], H, cfg)
        if best is None or res.val_mse < best[0]:
            best = (res.val_mse, rs, res)
    assert best is not None
    W1, b1, W2, b2 = _unpack(best[2].theta, d, H, k)
    f32 = lambda a: np.asarray(a, np.float32).astype(np.float64)  # noqa: E731
    weights = {"W1": f32(W1), "b1": f32(b1), "W2": f32(W2), "b2": f32(b2),
               "x_min": f32(x_range[0]), "x_max": f32(x_range[1]),
               "y_min": f32(y_range[0]), "y_max": f32(y_range[1])}
    return TrainedNet(weights, best[2], best[1])


@dataclass
class TrainResult:
    """Outcome of :func:`train`: the model, the sample split and the metrics."""

    model: MLPModel
    split: dict[str, list[str]]
    metrics: dict[str, dict[str, dict[str, float]]]
    fit: FitResult
    restart: int
    config: TrainConfig
    extra: dict[str, Any] = field(default_factory=dict)


def _rows(groups: np.ndarray, names: Sequence[str]) -> np.ndarray:
    return np.flatnonzero(np.isin(groups, list(names)))


def train(X: np.ndarray, Y: np.ndarray, groups: Sequence[str] | np.ndarray, feature_names: Sequence[str],
          dimension_names: Sequence[str], cfg: TrainConfig = TrainConfig(), *,
          progress: Any = None) -> TrainResult:
    """Train the perception model on trial rows ``X (n, d)`` with targets ``Y (n, k)`` (0..1).

    ``groups[i]`` is the sample of row i; the split is by sample. Scaling ranges are
    those of all rows (as MATLAB configures ``mapminmax`` on the whole data set).
    Returns metrics for train/validation/test and, with ``cfg.folds >= 2``, the
    pooled held-out metrics of grouped k-fold cross-validation (``"cv"``).
    ``progress(stage, done, total)`` is called after the model fit and each fold's fit.
    """
    from ..progress import report

    X = np.asarray(X, float)
    Y = np.asarray(Y, float)
    groups = np.asarray(groups).astype(str)
    if X.ndim != 2 or Y.ndim != 2 or len(X) != len(Y) or len(groups) != len(X):
        raise ValidationError(f"inconsistent shapes X {X.shape}, Y {Y.shape}, groups {groups.shape}",
                              field="dataset")
    if not (np.isfinite(X).all() and np.isfinite(Y).all()):
        raise ValidationError("NaN or infinite values in the training table", field="dataset")
    names = list(dict.fromkeys(groups.tolist()))
    split = split_samples(names, cfg.fractions, cfg.seed)
    idx = {s: _rows(groups, split[s]) for s in SPLITS}
    net = fit_network(X, Y, idx["train"], idx["validation"], cfg, x_range=mapminmax_range(X),
                      y_range=target_range(Y, cfg), seed=cfg.seed)
    n_fits = 1 + (min(cfg.folds, len(names)) if cfg.folds >= 2 else 0)
    report(progress, "fitting the network (model, then CV folds)", 1, n_fits)
    model = MLPModel(net.weights, feature_names, dimension_names, name="mlp")
    metrics = {s: metrics_dict(Y[idx[s]], model.predict(X[idx[s]]), dimension_names)
               for s in SPLITS if len(idx[s])}
    if cfg.folds >= 2:
        metrics["cv"] = cross_validate(
            X, Y, groups, dimension_names, cfg,
            progress=None if progress is None else
            (lambda stage, done, total: progress(stage, 1 + done, 1 + total)))
    return TrainResult(model, split, metrics, net.fit, net.restart, cfg)


def cross_validate(X: np.ndarray, Y: np.ndarray, groups: Sequence[str] | np.ndarray, dimension_names: Sequence[str],
                   cfg: TrainConfig, *, progress: Any = None) -> dict[str, dict[str, float]]:
    """Grouped k-fold CV: each fold of samples is predicted by a model trained without it.

    Inside each fold the remaining samples are split train/validation in the ratio of
    ``cfg.fractions`` (for early stopping); scaling ranges come from those rows only.
    Returns the metrics of all held-out predictions pooled.
    """
    groups = np.asarray(groups).astype(str)
    names = list(dict.fromkeys(groups.tolist()))
    k = min(cfg.folds, len(names))
    perm = np.random.default_rng(np.random.SeedSequence([cfg.seed, 202])).permutation(len(names))
    folds = [sorted(perm[i::k].tolist()) for i in range(k)]
    pred = np.empty_like(Y)
    f_tr, f_val, _ = cfg.fractions
    for fi, fold in enumerate(folds):
        held = [names[i] for i in fold]
        rest = [s for s in names if s not in held]
        inner = split_samples(rest, (f_tr, f_val / (f_tr + f_val), 0.0), cfg.seed + 1000 + fi)
        tr, val, te = (_rows(groups, inner["train"]), _rows(groups, inner["validation"]),
                       _rows(groups, held))
        fit_rows = np.concatenate([tr, val])
        net = fit_network(X, Y, tr, val, cfg, x_range=mapminmax_range(X[fit_rows]),
                          y_range=target_range(Y[fit_rows], cfg), seed=cfg.seed + 1000 + fi)
        m = MLPModel(net.weights, [f"x{i}" for i in range(X.shape[1])], dimension_names)
        pred[te] = m.predict(X[te])
        if progress is not None:
            progress("fitting the network (model, then CV folds)", fi + 1, k)
    out = metrics_dict(Y, pred, dimension_names)
    for d in out:
        out[d]["folds"] = k
    return out


def with_overrides(cfg: TrainConfig, **kw: Any) -> TrainConfig:
    """A copy of ``cfg`` with the keyword settings that are not ``None`` replaced."""
    return replace(cfg, **{k: v for k, v in kw.items() if v is not None})
