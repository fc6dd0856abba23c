"""Export of a trained :class:`~hapticsdk.perception.models.MLPModel` to an ONNX file.

Graph (``onnx.helper``, opset 17)::

    G [N,d] float32 (physical units)
      -> Sub x_min -> Mul x_scale -> Sub one           # mapminmax to [-1, 1]
      -> Gemm(W1, b1, transB) -> Tanh -> Gemm(W2, b2, transB) -> Tanh
      -> Add one -> Mul y_half -> Add y_min             # back to intensities
    -> I [N,k] float32

The named initializers ``W1, b1, W2, b2, x_min, x_max, y_min, y_max`` are those of
:class:`MLPModel` (``x_max``/``y_max`` are stored for readers, the graph uses the
derived ``x_scale = 2/(x_max - x_min)`` and ``y_half = (y_max - y_min)/2``).
Metadata keys are those of ``docs/architecture.md`` ("ONNX model file"), values JSON
strings. The file is written with a fixed producer and no timestamps, so the same
weights always give the same bytes.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..errors import ModelError
from ..perception.features import FeatureSpace
from ..perception.models import MLPModel

OPSET = 17
IR_VERSION = 8
PRODUCER = "hapticsdk.training"
META_PREFIX = "hapticsdk."
REQUIRED_KEYS = ("features", "dimensions", "feature_defaults", "df_hz", "architecture",
                 "training_data_sha256", "metrics", "data_generated")


def _dumps(v: Any) -> str:
    return json.dumps(v, sort_keys=True, separators=(",", ":"))


def build_metadata(space: FeatureSpace, dimensions: Sequence[str], *, feature_defaults: Mapping[str, float],
                   df_hz: float, metrics: Mapping[str, Any], training_data_sha256: str,
                   data_generated: bool, architecture: str = "mlp-tanh",
                   constraint_context: Mapping[str, float] | None = None) -> dict[str, str]:
    """The ``metadata_props`` of the model file (keys prefixed ``hapticsdk.``, JSON values).

    ``constraint_context``: facts of the training data that dimensions' constraints use
    (e.g. ``press_force_max_n``), passed to ``PerceptionDimension.constraints(**context)``.
    """
    extra = {META_PREFIX + "constraint_context": _dumps({k: float(v) for k, v in constraint_context.items()})
             } if constraint_context else {}
    return {**extra,
        META_PREFIX + "features": _dumps([{"name": f.name, "unit": f.unit, "lower": f.lower,
                                           "upper": f.upper} for f in space]),
        META_PREFIX + "dimensions": _dumps(list(dimensions)),
        META_PREFIX + "feature_defaults": _dumps({k: float(v) for k, v in feature_defaults.items()}),
        META_PREFIX + "df_hz": _dumps(float(df_hz)),
        META_PREFIX + "architecture": _dumps(architecture),
        META_PREFIX + "training_data_sha256": _dumps(training_data_sha256),
        META_PREFIX + "metrics": _dumps(metrics),
        META_PREFIX + "data_generated": _dumps(bool(data_generated)),
    }


def build_onnx(model: MLPModel, metadata: Mapping[str, str]) -> Any:
    """The ``onnx.ModelProto`` of ``model`` with ``metadata`` attached."""
    try:
        import onnx
        from onnx import TensorProto, helper, numpy_helper
    except ImportError as exc:  # pragma: no cover - depends on the [train] extra
        from ..install_hints import pip_hint
        raise ModelError(f"ONNX export needs the 'onnx' package ({pip_hint('hapticsdk', 'train')})") from exc
    d, k = model.n_features, model.n_outputs
    f32 = lambda a: np.ascontiguousarray(np.asarray(a, np.float32))  # noqa: E731
    span = model.x_max - model.x_min
    x_scale = np.where(span > 0, 2.0 / np.where(span > 0, span, 1.0), 0.0)
    inits = {"W1": model.W1, "b1": model.b1, "W2": model.W2, "b2": model.b2,
             "x_min": model.x_min, "x_max": model.x_max, "y_min": model.y_min, "y_max": model.y_max,
             "x_scale": x_scale, "y_half": (model.y_max - model.y_min) / 2.0,
             "one": np.array(1.0)}
    initializers = [numpy_helper.from_array(f32(v), name=n) for n, v in inits.items()]
    nodes = [
        helper.make_node("Sub", ["G", "x_min"], ["g_c"], name="center"),
        helper.make_node("Mul", ["g_c", "x_scale"], ["g_s"], name="scale"),
        helper.make_node("Sub", ["g_s", "one"], ["x_s"], name="shift"),
        helper.make_node("Gemm", ["x_s", "W1", "b1"], ["z1"], name="hidden", transB=1),
        helper.make_node("Tanh", ["z1"], ["h"], name="hidden_tanh"),
        helper.make_node("Gemm", ["h", "W2", "b2"], ["z2"], name="output", transB=1),
        helper.make_node("Tanh", ["z2"], ["y_s"], name="output_tanh"),
        helper.make_node("Add", ["y_s", "one"], ["y_p"], name="unshift"),
        helper.make_node("Mul", ["y_p", "y_half"], ["y_u"], name="unscale"),
        helper.make_node("Add", ["y_u", "y_min"], ["I"], name="offset"),
    ]
    graph = helper.make_graph(
        nodes, "hapticsdk_perception_mlp",
        [helper.make_tensor_value_info("G", TensorProto.FLOAT, ["N", d])],
        [helper.make_tensor_value_info("I", TensorProto.FLOAT, ["N", k])],
        initializer=initializers)
    proto = helper.make_model(graph, producer_name=PRODUCER, producer_version="1",
                              opset_imports=[helper.make_opsetid("", OPSET)])
    proto.ir_version = IR_VERSION
    proto.doc_string = ("hapticsdk perception model I = f(G): inputs " + ",".join(model.feature_names)
                        + "; outputs " + ",".join(model.dimension_names))
    for key in sorted(metadata):
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, metadata[key]
    onnx.checker.check_model(proto)
    return proto


def model_bytes(model: MLPModel, metadata: Mapping[str, str]) -> bytes:
    """Serialised ONNX bytes (deterministic)."""
    return build_onnx(model, metadata).SerializeToString(deterministic=True)


def save(model: MLPModel, metadata: Mapping[str, str], path: Path | str) -> bytes:
    """Write the ONNX file; returns its bytes."""
    from ..fileio import atomic_write_bytes
    data = model_bytes(model, metadata)
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        from ..errors import FileWriteError
        raise FileWriteError(f"cannot create the directory: {exc.strerror or exc}", field=str(p)) from None
    # temp file + fsync + read back by the model reader + rename: never a truncated model
    atomic_write_bytes(p, data, verify=read_back)
    return data


def read_back(path: Path) -> None:
    """Open ``path`` as the SDK opens a perception model: the ``onnx`` model plugin's
    reader (its size cap, external-data and graph checks) when it is installed, else the
    size cap and ``onnxruntime`` (raises what they raise)."""
    try:
        from hapticsdk_onnx import OnnxModel
    except ImportError:
        import onnxruntime as ort

        from ..schemas_io import read_bytes
        data = read_bytes(path, field="model", max_bytes=256 * 1024 * 1024)
        ort.InferenceSession(data, providers=["CPUExecutionProvider"])
        return
    OnnxModel(path)


def onnx_parity(data: bytes, model: MLPModel, X: np.ndarray) -> float:
    """Max abs difference between onnxruntime on ``data`` and ``model`` (numpy) over rows ``X``."""
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    so.inter_op_num_threads = 1
    so.log_severity_level = 3  # x_max/y_max are kept for readers, unused by the graph
    sess = ort.InferenceSession(data, sess_options=so, providers=["CPUExecutionProvider"])
    got = sess.run(["I"], {"G": np.asarray(X, np.float32)})[0].astype(np.float64)
    return float(np.max(np.abs(got - model.predict(X))))


def table_sha256(samples: Sequence[str], trials: Sequence[int], X: np.ndarray, Y: np.ndarray) -> str:
    """SHA-256 of the training table (sample, trial, features, targets) in a canonical text form."""
    h = hashlib.sha256()
    for s, t, x, y in zip(samples, trials, np.asarray(X, float), np.asarray(Y, float)):
        h.update((f"{s},{int(t)}," + ",".join(repr(float(v)) for v in (*x, *y)) + "\n").encode())
    return h.hexdigest()
