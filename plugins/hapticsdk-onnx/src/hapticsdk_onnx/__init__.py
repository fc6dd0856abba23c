"""ONNX perception models for hapticsdk (entry-point group ``hapticsdk.models``).

:class:`OnnxModel` runs a model file through onnxruntime (one session, one thread)
and reads its metadata (``docs/architecture.md``, "ONNX model file"): the declared
features with their data-set bounds become :attr:`feature_space`, the dimensions the
outputs, and ``df_hz``, ``feature_defaults``, ``metrics`` ... land in
:attr:`metadata`. For ``architecture == "mlp-tanh"`` the Jacobian is the analytic one
of a :class:`hapticsdk.models.MLPModel` rebuilt from the file's initializers.

:func:`load_default` returns the shipped default model (trained on the GENERATED data
set of ``hapticsdk/data/dataset``; rebuild it with the command in
``docs/perception-models.md``).
"""

from __future__ import annotations

import json
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np

from hapticsdk.errors import HapticSDKError, ModelError
from hapticsdk.features import FeatureSpace
from hapticsdk.models import MLPModel, PerceptionModel

__all__ = ["OnnxModel", "load_default", "default_model_path", "REQUIRED_METADATA", "hapticsdk_api"]

#: plugin API range this distribution was built for (checked when a plugin is loaded)
hapticsdk_api = ">=1.0,<2"

PREFIX = "hapticsdk."
#: metadata keys every model file must carry (without the ``hapticsdk.`` prefix).
REQUIRED_METADATA = ("features", "dimensions", "feature_defaults", "df_hz", "architecture",
                     "training_data_sha256", "metrics", "data_generated")
#: largest model file read (bytes)
MAX_MODEL_BYTES = 256 * 1024 * 1024
MLP_INITIALIZERS = ("W1", "b1", "W2", "b2", "x_min", "x_max", "y_min", "y_max")


def default_model_path() -> Path:
    """Path of the shipped ``models/default.onnx``."""
    return Path(str(files("hapticsdk_onnx") / "models" / "default.onnx"))


def _meta(raw: dict[str, str], key: str, where: str) -> Any:
    full = PREFIX + key
    if full not in raw:
        raise ModelError(f"{where}: metadata key {full!r} is missing (required: "
                         f"{[PREFIX + k for k in REQUIRED_METADATA]})")
    try:
        return json.loads(raw[full])
    except json.JSONDecodeError as exc:
        raise ModelError(f"{where}: metadata {full!r} is not valid JSON ({exc})") from None


def _number(value: Any, key: str, where: str, *, positive: bool = False) -> float:
    """A metadata value that must be a finite number (not a bool, not a string); raises
    :class:`ModelError` naming the file and the key ``hapticsdk.<key>``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or (
            positive and value <= 0):
        raise ModelError(f"{where}: metadata {PREFIX + key!r} must be a finite number"
                         f"{' > 0' if positive else ''}, got {value!r}")
    return float(value)


class OnnxModel(PerceptionModel):
    """A perception model stored as ONNX (input ``G`` float32 [N,d], output ``I`` float32 [N,k])."""

    def __init__(self, path: str | Path, *, name: str | None = None) -> None:
        p = Path(path)
        where = str(p)
        if not p.is_file():
            raise ModelError(f"{where}: ONNX model file not found")
        from hapticsdk.errors import ValidationError
        from hapticsdk.schemas_io import read_bytes
        try:  # a regular file of bounded size (a small MLP is a few kB)
            data = read_bytes(p, field="model", max_bytes=MAX_MODEL_BYTES)
        except ValidationError as exc:
            raise ModelError(str(exc)) from None
        try:
            import onnx
            from onnx import numpy_helper

            proto = onnx.load_from_string(data)
        except Exception as exc:  # malformed protobuf
            raise ModelError(f"{where}: not a readable ONNX model ({exc})") from None
        raw = {e.key: e.value for e in proto.metadata_props}
        meta = {k: _meta(raw, k, where) for k in REQUIRED_METADATA}
        feats, dims, defaults = meta["features"], meta["dimensions"], meta["feature_defaults"]
        if "hapticsdk.constraint_context" in raw:  # optional: data facts for constraints
            ctx = _meta(raw, "constraint_context", where)
            if not isinstance(ctx, dict) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                    and np.isfinite(v) for v in ctx.values()):
                raise ModelError(f"{where}: metadata 'hapticsdk.constraint_context' must map names to numbers")
            meta["constraint_context"] = ctx
        if not isinstance(feats, list) or not feats or not all(
                isinstance(f, dict) and {"name", "unit", "lower", "upper"} <= set(f) for f in feats):
            raise ModelError(f"{where}: metadata 'hapticsdk.features' must be a non-empty list of "
                             "{name, unit, lower, upper}")
        if not isinstance(dims, list) or not dims or not all(isinstance(d, str) for d in dims):
            raise ModelError(f"{where}: metadata 'hapticsdk.dimensions' must be a non-empty list of names")
        try:
            space = FeatureSpace.from_dicts(feats)
        except HapticSDKError as exc:
            raise ModelError(f"{where}: bad feature declaration in metadata: {exc}") from None
        graph = proto.graph
        ins = {i.name: i for i in graph.input}
        inits = {t.name: t for t in graph.initializer}
        real_inputs = [i for i in graph.input if i.name not in inits]
        if [i.name for i in real_inputs] != ["G"] or [o.name for o in graph.output] != ["I"]:
            raise ModelError(f"{where}: graph must have input 'G' and output 'I', has inputs "
                             f"{[i.name for i in real_inputs]} outputs {[o.name for o in graph.output]}")

        def width(vi) -> int | None:
            dims_ = vi.type.tensor_type.shape.dim
            if len(dims_) != 2:
                raise ModelError(f"{where}: {vi.name} must be 2-D [N, n], has rank {len(dims_)}")
            return dims_[1].dim_value if dims_[1].HasField("dim_value") else None

        d_in, k_out = width(ins["G"]), width(graph.output[0])
        if d_in is not None and d_in != len(space):
            raise ModelError(f"{where}: input G has {d_in} columns but metadata declares "
                             f"{len(space)} features {list(space.names)}")
        if k_out is not None and k_out != len(dims):
            raise ModelError(f"{where}: output I has {k_out} columns but metadata declares "
                             f"{len(dims)} dimensions {dims}")
        if not isinstance(defaults, dict) or set(defaults) - set(space.names):
            raise ModelError(f"{where}: 'hapticsdk.feature_defaults' names unknown features "
                             f"{sorted(set(defaults) - set(space.names)) if isinstance(defaults, dict) else defaults}")
        df_hz = _number(meta["df_hz"], "df_hz", where, positive=True)
        defaults = {k: _number(v, f"feature_defaults.{k}", where) for k, v in defaults.items()}
        meta["source_path"] = where
        super().__init__(space.names, dims, feature_space=space, metadata=meta, name=name or p.stem)
        self.units = dict(zip(space.names, space.units))
        self.feature_defaults = defaults
        self.df_hz = df_hz
        self._mlp: MLPModel | None = None
        if meta["architecture"] == "mlp-tanh":
            missing = [n for n in MLP_INITIALIZERS if n not in inits]
            if missing:
                raise ModelError(f"{where}: architecture mlp-tanh but initializers {missing} are missing")
            w = {n: numpy_helper.to_array(inits[n]).astype(np.float64) for n in MLP_INITIALIZERS}
            self._mlp = MLPModel(w, space.names, dims, name=self.name)  # raises ModelError on bad shapes
        import onnxruntime as ort

        so = ort.SessionOptions()
        so.intra_op_num_threads = 1
        so.inter_op_num_threads = 1
        so.log_severity_level = 3
        try:
            self._session = ort.InferenceSession(data, sess_options=so, providers=["CPUExecutionProvider"])
        except Exception as exc:
            raise ModelError(f"{where}: onnxruntime cannot load the model ({exc})") from None

    def _predict(self, X: np.ndarray) -> np.ndarray:
        out = self._session.run(["I"], {"G": np.ascontiguousarray(X, dtype=np.float32)})[0]
        return out.astype(np.float64)

    def jacobian(self, G: np.ndarray, **kw: Any) -> np.ndarray:
        """Analytic Jacobian for mlp-tanh models, central differences otherwise; ``(n, k, d)``."""
        if self._mlp is not None:
            return self._mlp.jacobian(G)
        return super().jacobian(G, **kw)

    @property
    def mlp(self) -> MLPModel | None:
        """The numpy twin of an mlp-tanh model (same float32 weights), else None."""
        return self._mlp


def load_default() -> OnnxModel:
    """The shipped default model (entry point ``hapticsdk.models: default``)."""
    return OnnxModel(default_model_path(), name="default")
