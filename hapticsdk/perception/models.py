"""Perception models: I = f(G), batched.

A :class:`PerceptionModel` maps feature rows ``G`` of shape ``(n, d)`` (physical units,
columns named by :attr:`~PerceptionModel.feature_names`) to intensities ``(n, k)`` in
0..1 (columns named by :attr:`~PerceptionModel.dimension_names`). Public methods
validate and then call the backend's ``_predict``; every backend gets the same checks.

:class:`MLPModel` is the paper's network (5-20-2, tanh hidden and output, MATLAB
``mapminmax`` scaling folded in) evaluated with numpy; it has an analytic Jacobian.
The ONNX plugin runs the same network from its ONNX file (with numpy in float32 when
the graph is a plain dense chain, else through onnxruntime).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, Mapping, Sequence

import numpy as np
import numpy.typing as npt

from ..errors import ModelError, ValidationError
from .features import FeatureSpace


class PerceptionModel(ABC):
    """Abstract batched perception model.

    Attributes:
        name: identifier (entry-point name or file stem).
        feature_names: input columns, in order.
        dimension_names: output columns, in order.
        feature_space: optional bounds of the inputs (the training range).
        metadata: free-form facts (training data hash, metrics, ``df_hz`` ...).
    """

    name: str = "model"

    def __init__(self, feature_names: Sequence[str], dimension_names: Sequence[str], *,
                 feature_space: FeatureSpace | None = None,
                 metadata: Mapping[str, Any] | None = None, name: str | None = None) -> None:
        self.feature_names = tuple(feature_names)
        self.dimension_names = tuple(dimension_names)
        if not self.feature_names or not self.dimension_names:
            raise ModelError("a model must declare at least one feature and one dimension")
        if feature_space is not None and tuple(feature_space.names) != self.feature_names:
            raise ModelError(f"feature space {feature_space.names} does not match model inputs "
                             f"{self.feature_names}")
        self.feature_space = feature_space
        self.metadata = dict(metadata or {})
        if name:
            self.name = name

    @property
    def n_features(self) -> int:
        """Number of model inputs."""
        return len(self.feature_names)

    def provenance(self) -> dict[str, Any]:
        """Where the model's training data came from, for every output that shows a solve.

        Returns ``{"model", "data_generated", "training_data_sha256", "statement"}``:
        ``data_generated`` is True for a model trained on generated data (the shipped
        default: the paper published none), False for recorded data, None when the model
        does not say; ``statement`` is the one line the CLI prints, which also says what
        a solve's "error" measures (the distance to this model's prediction, not a
        perceptual accuracy).
        """
        gen = self.metadata.get("data_generated")
        if isinstance(gen, str):
            gen = {"true": True, "false": False}.get(gen.strip().lower())
        gen = bool(gen) if isinstance(gen, (bool, int)) else None
        sha = self.metadata.get("training_data_sha256")
        what = ("trained on GENERATED data (not measurements)" if gen else
                "trained on recorded data" if gen is False else "training data not declared")
        return {"model": self.name, "data_generated": gen,
                "training_data_sha256": str(sha) if sha else None,
                "statement": (f"model {self.name!r}: {what}; 'error' is the distance between the targets and "
                              f"this model's prediction, not a measured perceptual accuracy")}

    @property
    def n_outputs(self) -> int:
        """Number of predicted dimensions."""
        return len(self.dimension_names)

    def predict(self, G: npt.ArrayLike) -> np.ndarray:
        """Intensities for each row of ``G`` (``(n, d)`` or ``(d,)``), shape ``(n, k)``."""
        X = np.asarray(G, dtype=float)
        if X.ndim == 1:
            X = X[None, :]
        if X.ndim != 2 or X.shape[1] != self.n_features:
            raise ValidationError(f"model {self.name!r} expects (n, {self.n_features}) inputs "
                                  f"{list(self.feature_names)}, got shape {np.shape(G)}", field="G")
        if not np.isfinite(X).all():
            raise ValidationError("NaN or infinite input", field="G")
        Y = np.asarray(self._predict(X), dtype=float)
        if Y.shape != (X.shape[0], self.n_outputs):
            raise ModelError(f"model {self.name!r} returned shape {Y.shape}, "
                             f"expected {(X.shape[0], self.n_outputs)}")
        return Y

    @abstractmethod
    def _predict(self, X: np.ndarray) -> np.ndarray:
        """Backend forward pass on a validated float ``(n, d)`` array."""

    def jacobian(self, G: np.ndarray, *, step: float = 1e-6) -> np.ndarray:
        """dI/dG per row, shape ``(n, k, d)``.

        The default is central differences evaluated in ONE batched model call
        (``2*d*n`` rows); backends with an analytic Jacobian override it.
        """
        X = np.atleast_2d(np.asarray(G, float))
        n, d = X.shape
        h = step * np.maximum(np.abs(X), 1.0)  # (n, d)
        eye = np.eye(d)
        plus = X[:, None, :] + eye[None] * h[:, None, :]
        minus = X[:, None, :] - eye[None] * h[:, None, :]
        Y = self.predict(np.concatenate([plus.reshape(-1, d), minus.reshape(-1, d)]))
        Yp, Ym = Y[: n * d].reshape(n, d, -1), Y[n * d:].reshape(n, d, -1)
        return np.transpose((Yp - Ym) / (2 * h[:, :, None]), (0, 2, 1))

    def describe(self) -> dict:
        """Name, input features, output dimensions, feature space (with units and bounds)
        and metadata (weights left out).
        """
        return {"name": self.name, "features": list(self.feature_names),
                "dimensions": list(self.dimension_names),
                "feature_space": self.feature_space.to_dict() if self.feature_space else None,
                "metadata": {k: v for k, v in self.metadata.items() if k != "weights"}}


class MLPModel(PerceptionModel):
    """Two-layer tanh network with min-max scaling folded in (numpy).

    ``x_s = 2 (x - x_min) / (x_max - x_min) - 1``; ``h = tanh(W1 x_s + b1)``;
    ``y_s = tanh(W2 h + b2)``; ``y = (y_s + 1)/2 (y_max - y_min) + y_min``.
    Shapes: ``W1 (H, d)``, ``b1 (H,)``, ``W2 (k, H)``, ``b2 (k,)``.
    """

    def __init__(self, weights: Mapping[str, np.ndarray], feature_names: Sequence[str],
                 dimension_names: Sequence[str], **kw: Any) -> None:
        super().__init__(feature_names, dimension_names, **kw)
        try:
            self.W1 = np.asarray(weights["W1"], float)
            self.b1 = np.asarray(weights["b1"], float)
            self.W2 = np.asarray(weights["W2"], float)
            self.b2 = np.asarray(weights["b2"], float)
            self.x_min = np.asarray(weights["x_min"], float)
            self.x_max = np.asarray(weights["x_max"], float)
            self.y_min = np.asarray(weights["y_min"], float)
            self.y_max = np.asarray(weights["y_max"], float)
        except KeyError as exc:
            raise ModelError(f"MLP weights lack {exc.args[0]!r}") from None
        d, k = self.n_features, self.n_outputs
        H = self.W1.shape[0]
        shapes = {"W1": (self.W1.shape, (H, d)), "b1": (self.b1.shape, (H,)),
                  "W2": (self.W2.shape, (k, H)), "b2": (self.b2.shape, (k,)),
                  "x_min": (self.x_min.shape, (d,)), "x_max": (self.x_max.shape, (d,)),
                  "y_min": (self.y_min.shape, (k,)), "y_max": (self.y_max.shape, (k,))}
        for key, (got, want) in shapes.items():
            if got != want:
                raise ModelError(f"MLP weight {key} has shape {got}, expected {want}")
        span = self.x_max - self.x_min
        self._xs = np.where(span > 0, 2.0 / np.where(span > 0, span, 1.0), 0.0)
        self._ys = (self.y_max - self.y_min) / 2.0

    @property
    def weights(self) -> dict[str, np.ndarray]:
        """The network's arrays: ``W1, b1, W2, b2`` and the scaling ranges ``x_min, x_max,
        y_min, y_max``.
        """
        return {"W1": self.W1, "b1": self.b1, "W2": self.W2, "b2": self.b2,
                "x_min": self.x_min, "x_max": self.x_max, "y_min": self.y_min, "y_max": self.y_max}

    def _hidden(self, X: np.ndarray) -> np.ndarray:
        Xs = (X - self.x_min) * self._xs - 1.0
        return np.tanh(Xs @ self.W1.T + self.b1)

    def _predict(self, X: np.ndarray) -> np.ndarray:
        Ys = np.tanh(self._hidden(X) @ self.W2.T + self.b2)
        return (Ys + 1.0) * self._ys + self.y_min

    def jacobian(self, G: np.ndarray, **_: Any) -> np.ndarray:
        X = np.atleast_2d(np.asarray(G, float))
        Hd = self._hidden(X)                                 # (n, H)
        Ys = np.tanh(Hd @ self.W2.T + self.b2)               # (n, k)
        dh = (1 - Hd ** 2)[:, None, :] * self.W2[None]       # (n, k, H)
        J = (dh @ self.W1) * self._xs[None, None, :]         # (n, k, d)
        return J * ((1 - Ys ** 2) * self._ys)[:, :, None]


class CompositeModel(PerceptionModel):
    """Union of models that cover disjoint dimensions; inputs are the union of features.

    Each part receives its own columns, so a hardness+roughness model and a
    warmth model can be solved together.
    """

    def __init__(self, parts: Sequence[PerceptionModel], *, name: str = "composite") -> None:
        if not parts:
            raise ModelError("a composite model needs at least one part")
        feats: list[str] = []
        dims: list[str] = []
        space: FeatureSpace | None = FeatureSpace(())
        for p in parts:
            for f in p.feature_names:
                if f not in feats:
                    feats.append(f)
            for dname in p.dimension_names:
                if dname in dims:
                    raise ModelError(f"dimension {dname!r} is covered by two models")
                dims.append(dname)
            if space is not None and p.feature_space is not None:
                space = space.union(p.feature_space)
            else:
                space = None
        super().__init__(feats, dims, feature_space=space.subset(feats) if space else None, name=name)
        self.parts = list(parts)
        self._cols = [[feats.index(f) for f in p.feature_names] for p in parts]

    def _predict(self, X: np.ndarray) -> np.ndarray:
        return np.concatenate([p.predict(X[:, c]) for p, c in zip(self.parts, self._cols)], axis=1)

    def jacobian(self, G: np.ndarray, **kw: Any) -> np.ndarray:
        X = np.atleast_2d(np.asarray(G, float))
        J = np.zeros((X.shape[0], self.n_outputs, self.n_features))
        row = 0
        for p, c in zip(self.parts, self._cols):
            Jp = p.jacobian(X[:, c], **kw)
            J[:, row:row + p.n_outputs][:, :, c] = Jp
            row += p.n_outputs
        return J

    def provenance(self) -> dict[str, Any]:
        """The parts' provenance: generated when any part is (see
        :meth:`PerceptionModel.provenance`); ``parts`` lists each."""
        parts = [p.provenance() for p in self.parts]
        gens = [p["data_generated"] for p in parts]
        gen = True if any(g is True for g in gens) else (False if all(g is False for g in gens) else None)
        names = ", ".join(repr(p["model"]) for p in parts)
        what = ("trained (in part) on GENERATED data (not measurements)" if gen else
                "trained on recorded data" if gen is False else "training data not declared for every part")
        return {"model": self.name, "data_generated": gen, "training_data_sha256": None, "parts": parts,
                "statement": (f"models {names}: {what}; 'error' is the distance between the targets and these "
                              f"models' prediction, not a measured perceptual accuracy")}
