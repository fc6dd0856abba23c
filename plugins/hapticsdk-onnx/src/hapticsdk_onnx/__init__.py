"""ONNX perception models for hapticsdk (entry-point group ``hapticsdk.models``).

:class:`OnnxModel` runs a model file through onnxruntime (one session, one thread)
and reads its metadata (``docs/architecture.md``, "ONNX model file"): the declared
features with their data-set bounds become :attr:`feature_space`, the dimensions the
outputs, and ``df_hz``, ``feature_defaults``, ``metrics`` ... land in
:attr:`metadata`. For ``architecture == "mlp-tanh"`` the Jacobian is the analytic one
of a :class:`hapticsdk.perception.models.MLPModel` rebuilt from the file's initializers. A graph
that is a plain chain of dense layers is evaluated with numpy instead of onnxruntime
(:mod:`hapticsdk_onnx.chain`, 1.4-1.7x faster; ``OnnxModel(path, runtime="onnxruntime")``
keeps onnxruntime).

:func:`load_default` returns the shipped default model (trained on the GENERATED data
set of ``hapticsdk/data/dataset``; rebuild it with the command in
``docs/perception-models.md``).
"""

from __future__ import annotations

import hashlib
import json
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np

from hapticsdk.checks import finite_float
from hapticsdk.errors import HapticSDKError, ModelError
from hapticsdk.perception.features import FeatureSpace
from hapticsdk.perception.models import MLPModel, PerceptionModel

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
#: ``runtime=`` values of :class:`OnnxModel`: ``"auto"`` evaluates a graph that is a plain
#: dense chain with numpy (:mod:`hapticsdk_onnx.chain`), anything else with onnxruntime
RUNTIMES = ("auto", "onnxruntime")
#: largest model file considered for the numpy chain (a dense chain of this size is far
#: past the batch sizes where numpy wins)
MAX_CHAIN_BYTES = 4 * 1024 * 1024
_UNSET = object()


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
    v = _finite(value)
    if v is None or (positive and v <= 0):
        raise ModelError(f"{where}: metadata {PREFIX + key!r} must be a finite number"
                         f"{' > 0' if positive else ''}, got {value!r:.60}")
    return v


_finite = finite_float   # a finite int or float as a float (JSON metadata), else None


#: layout of the cached model descriptions (bumped when it changes)
DESCRIPTION_VERSION = 2


class _Description:
    """What :class:`OnnxModel` reads from a model file's protobuf: the metadata
    properties, the graph's input / output / initializer names, the rank and column
    count of every input and output, and the ``mlp-tanh`` initializers as arrays."""

    def __init__(self, meta: dict[str, str], inputs: list[str], outputs: list[str],
                 initializers: list[str], shapes: dict[str, tuple[int, int | None]],
                 arrays: dict[str, np.ndarray]) -> None:
        self.meta, self.inputs, self.outputs = meta, inputs, outputs
        self.initializers, self.shapes, self.arrays = initializers, shapes, arrays

    def to_arrays(self) -> dict[str, np.ndarray]:
        spec = {"version": DESCRIPTION_VERSION, "meta": self.meta, "inputs": self.inputs,
                "outputs": self.outputs, "initializers": self.initializers,
                "shapes": {k: list(v) for k, v in self.shapes.items()}, "arrays": sorted(self.arrays)}
        from .chain import with_spec
        return with_spec(spec, {f"a{i}": a for i, (_, a) in enumerate(sorted(self.arrays.items()))})

    @classmethod
    def from_npz(cls, z: Any) -> "_Description":
        from .chain import read_spec
        spec = read_spec(z, DESCRIPTION_VERSION)
        arrays = {name: np.asarray(z[f"a{i}"]) for i, name in enumerate(spec["arrays"])}
        shapes = {k: (int(v[0]), None if v[1] is None else int(v[1])) for k, v in spec["shapes"].items()}
        return cls({str(k): str(v) for k, v in spec["meta"].items()}, list(spec["inputs"]),
                   list(spec["outputs"]), list(spec["initializers"]), shapes, arrays)


def _description_path(sha256: str) -> Path:
    """``$HAPTICSDK_CACHE_DIR`` or ``$XDG_CACHE_HOME/hapticsdk`` or ``~/.cache/hapticsdk``,
    then ``onnx-desc/<sha256 of the model file>.npz``."""
    from hapticsdk.fileio import cache_dir
    return cache_dir() / "onnx-desc" / f"{sha256}.npz"


def _refuse_external_data(tensors: Any, where: str) -> None:
    """Raise :class:`ModelError` naming the first initializer whose data lives in another
    file (ONNX "external data"). A model is read as one file of bounded size: nothing
    outside it is opened, and a location outside the model's folder (absolute, ``..``) is
    named as such."""
    import posixpath

    for t in tensors:
        if getattr(t, "data_location", 0) != 1:  # TensorProto.EXTERNAL
            continue
        loc = next((e.value for e in t.external_data if e.key == "location"), "")
        norm = posixpath.normpath(str(loc).replace("\\", "/"))
        outside = (not loc or norm.startswith(("/", "../")) or norm == ".." or Path(str(loc)).is_absolute()
                   or (len(str(loc)) > 1 and str(loc)[1] == ":"))
        why = ("outside the model's folder" if outside else "in a separate file")
        raise ModelError(f"{where}: initializer {t.name!r} keeps its data in external file {str(loc)[:200]!r}, "
                         f"{why}; refused, nothing was read (save the model with its weights inside: "
                         f"onnx.save(model, path, save_as_external_data=False))")


def _description(data: bytes, where: str) -> _Description:
    """The :class:`_Description` of a model file's bytes. Parsing the protobuf needs the
    ``onnx`` package (20-170 ms to import), so the description is kept in the cache folder
    under the SHA-256 of the bytes (a numpy archive without pickles, written atomically)
    and read from there by later processes; every check of :class:`OnnxModel` still runs
    on it. Raises :class:`ModelError` for bytes that are not a readable ONNX model."""
    path = _description_path(hashlib.sha256(data).hexdigest())
    try:
        with np.load(path, allow_pickle=False) as z:
            return _Description.from_npz(z)
    except Exception:   # missing, unreadable or another layout: parse the file
        pass
    try:
        import onnx
        from onnx import numpy_helper

        proto = onnx.load_from_string(data)
    except Exception as exc:  # malformed protobuf
        raise ModelError(f"{where}: not a readable ONNX model ({exc})") from None
    graph = proto.graph
    shapes: dict[str, tuple[int, int | None]] = {}   # "in:<name>" (the last of a name), "out:<name>"
    for side, vis in (("out", list(graph.output)[::-1]), ("in", graph.input)):
        for vi in vis:
            dims_ = vi.type.tensor_type.shape.dim
            dim1 = (dims_[1].dim_value if dims_[1].HasField("dim_value") else None) if len(dims_) >= 2 else None
            shapes[f"{side}:{vi.name}"] = (len(dims_), dim1)
    inits = {t.name: t for t in graph.initializer}
    _refuse_external_data(inits.values(), where)  # before numpy_helper would open any file
    desc = _Description({e.key: e.value for e in proto.metadata_props}, [i.name for i in graph.input],
                        [o.name for o in graph.output], [t.name for t in graph.initializer], shapes,
                        {n: numpy_helper.to_array(inits[n]) for n in MLP_INITIALIZERS if n in inits})
    try:
        from hapticsdk.fileio import atomic_savez
        path.parent.mkdir(parents=True, exist_ok=True)
        arrays: dict[str, Any] = desc.to_arrays()
        atomic_savez(path, compressed=False, **arrays)
    except Exception as exc:   # a read-only cache folder: the model still loads
        import logging
        logging.getLogger(__name__).info("could not cache the model description at %s: %s", path, exc)
    return desc


class OnnxModel(PerceptionModel):
    """A perception model stored as ONNX (input ``G`` float32 [N,d], output ``I`` float32 [N,k]).

    ``runtime="auto"`` (default): a graph that is a plain dense chain (the shipped
    model) is evaluated with numpy in float32 (:mod:`hapticsdk_onnx.chain`; checked against
    onnxruntime on probe rows first), anything else with onnxruntime;
    ``runtime="onnxruntime"``: always onnxruntime. :attr:`runtime` says which runs.
    """

    def __init__(self, path: str | Path, *, name: str | None = None, runtime: str = "auto") -> None:
        if runtime not in RUNTIMES:
            from hapticsdk.errors import ValidationError as _VE
            raise _VE(f"unknown runtime {runtime!r}; valid: {list(RUNTIMES)}", field="runtime")
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
        desc = _description(data, where)  # the protobuf's parts read below (cached by content)
        raw = desc.meta
        meta = {k: _meta(raw, k, where) for k in REQUIRED_METADATA}
        feats, dims, defaults = meta["features"], meta["dimensions"], meta["feature_defaults"]
        if "hapticsdk.constraint_context" in raw:  # optional: data facts for constraints
            ctx = _meta(raw, "constraint_context", where)
            if not isinstance(ctx, dict) or not all(_finite(v) is not None for v in ctx.values()):
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
        inits = set(desc.initializers)
        real_inputs = [n for n in desc.inputs if n not in inits]
        if real_inputs != ["G"] or desc.outputs != ["I"]:
            raise ModelError(f"{where}: graph must have input 'G' and output 'I', has inputs "
                             f"{real_inputs} outputs {desc.outputs}")

        def width(key: str) -> int | None:
            rank, dim1 = desc.shapes[key]
            if rank != 2:
                raise ModelError(f"{where}: {key[key.index(':') + 1:]} must be 2-D [N, n], has rank {rank}")
            return dim1

        d_in, k_out = width("in:G"), width("out:I")
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
            w = {n: desc.arrays[n].astype(np.float64) for n in MLP_INITIALIZERS}
            self._mlp = MLPModel(w, space.names, dims, name=self.name)  # raises ModelError on bad shapes
        # numpy evaluation of a plain dense chain (hapticsdk_onnx.chain), found on first use
        self._runtime = runtime
        self._sha256 = hashlib.sha256(data).hexdigest()
        self._bytes = data if runtime == "auto" and len(data) <= MAX_CHAIN_BYTES else None
        self._chain: Any = _UNSET if self._bytes is not None else None
        self._where = where
        self._session: Any = None
        # onnxruntime loads the model now, unless an mlp-tanh file already has a cached
        # numpy chain (written only after onnxruntime loaded these very bytes, keyed by
        # their SHA-256): then it is imported only if something needs it (~30 ms of start-up)
        if not (self._chain is _UNSET and self._mlp is not None and self._chain_cached()):
            self._session = self._make_session(data)

    def _make_session(self, data: bytes | None = None) -> Any:
        """An onnxruntime session on the model's bytes (one thread); raises
        :class:`ModelError` when onnxruntime cannot load them."""
        import onnxruntime as ort

        if data is None:
            if self._bytes is None:
                from hapticsdk.errors import ValidationError
                from hapticsdk.schemas_io import read_bytes
                try:
                    data = read_bytes(self._where, field="model", max_bytes=MAX_MODEL_BYTES)
                except ValidationError as exc:
                    raise ModelError(str(exc)) from None
            else:
                data = self._bytes
            if hashlib.sha256(data).hexdigest() != self._sha256:
                raise ModelError(f"{self._where}: the model file changed since it was loaded")
        so = ort.SessionOptions()
        so.intra_op_num_threads = 1
        so.inter_op_num_threads = 1
        so.log_severity_level = 3
        try:
            return ort.InferenceSession(data, sess_options=so, providers=["CPUExecutionProvider"])
        except Exception as exc:
            raise ModelError(f"{self._where}: onnxruntime cannot load the model ({exc})") from None

    def _sess(self) -> Any:
        if self._session is None:
            self._session = self._make_session()
        return self._session

    def _chain_cached(self) -> bool:
        from . import chain as ch
        return ch.chain_cache_path(self._sha256).is_file()

    def _predict(self, X: np.ndarray) -> np.ndarray:
        chain = self._chain
        if chain is _UNSET:
            chain = self._find_chain()
        if chain is not None:   # one row as a vector: 2-D products of one row cost more
            return chain(X[0])[None] if X.shape[0] == 1 else chain(X)
        out = self._sess().run(["I"], {"G": np.ascontiguousarray(X, dtype=np.float32)})[0]
        return out.astype(np.float64)

    @property
    def file_sha256(self) -> str:
        """Hex SHA-256 of the model file's bytes: the identity that caches derived from this
        model (numpy chain, amortised tables) are keyed by, so a replaced file invalidates them."""
        return self._sha256

    @property
    def runtime(self) -> str:
        """What evaluates :meth:`predict`: ``"numpy"`` (the graph is a recognised dense
        chain, see :mod:`hapticsdk_onnx.chain`) or ``"onnxruntime"``. Finds out on first
        call (may read the chain cache or import ``onnx``)."""
        chain = self._find_chain() if self._chain is _UNSET else self._chain
        return "numpy" if chain is not None else "onnxruntime"

    def _find_chain(self) -> Any:
        """The numpy chain of this file (disk cache keyed by the file's SHA-256, else
        compiled from the graph and cached), checked against onnxruntime on probe rows;
        None (onnxruntime) when the graph is not a recognised chain or disagrees."""
        from . import chain as ch
        path = ch.chain_cache_path(self._sha256)
        found, chain = ch.load_chain(path)
        if not found:
            try:
                import onnx
                chain = ch.compile_chain(onnx.load_from_string(self._bytes or b""), self.n_features)
            except Exception:
                chain = None
            try:
                ch.save_chain(chain, path)
            except Exception as exc:   # a read-only cache folder: the chain still works
                import logging
                logging.getLogger(__name__).info("could not cache the numpy chain at %s: %s", path, exc)
        if chain is not None:
            # checked against onnxruntime, or, when onnxruntime was not needed (a cached
            # chain of an mlp-tanh file), against the float64 numpy twin of its weights
            ref = self._mlp.predict if self._session is None and self._mlp is not None else self._onnxruntime_rows
            if not _agrees(chain, ref, self.feature_space, self.n_features):
                chain = None
        self._chain = chain
        if chain is not None:
            self._bytes = None
        return chain

    def _onnxruntime_rows(self, X: np.ndarray) -> np.ndarray:
        return np.asarray(self._sess().run(["I"], {"G": X.astype(np.float32)})[0], np.float64)

    def jacobian(self, G: np.ndarray, **kw: Any) -> np.ndarray:
        """Analytic Jacobian for mlp-tanh models, central differences otherwise; ``(n, k, d)``."""
        if self._mlp is not None:
            return self._mlp.jacobian(G)
        return super().jacobian(G, **kw)

    @property
    def mlp(self) -> MLPModel | None:
        """The numpy twin of an mlp-tanh model (same float32 weights), else None."""
        return self._mlp


def _agrees(chain: Any, reference: Any, space: FeatureSpace | None, d: int) -> bool:
    """True when ``chain`` reproduces ``reference`` (onnxruntime's rows, or the float64
    numpy twin of an mlp-tanh model's float32 weights) on 16 probe rows (inside the declared
    feature bounds, fixed seed) to float32 rounding (a guard against a stale or altered
    cache file, a graph read wrongly and weights that lose accuracy when folded: agreement
    within 32 float32 units of max(1, |y|), where the shipped model differs by 1-2)."""
    rng = np.random.default_rng(7)
    if space is not None and len(space) == d:
        X = space.lower + rng.random((16, d)) * (space.upper - space.lower)
    else:
        X = rng.standard_normal((16, d))
    try:
        ref = np.asarray(reference(X), np.float64)
        got = chain(X)
    except Exception:
        return False
    return got.shape == ref.shape and bool(np.all(np.abs(got - ref) <= 32 * 2.0 ** -23 * np.maximum(1.0, np.abs(ref))))


def load_default() -> OnnxModel:
    """The shipped default model (entry point ``hapticsdk.models: default``)."""
    return OnnxModel(default_model_path(), name="default")
