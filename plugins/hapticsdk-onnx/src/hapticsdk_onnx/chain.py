"""A numpy evaluation of ONNX graphs that are a plain chain of dense layers.

Small perception models (the paper's 5-20-2 tanh MLP) cost onnxruntime more in per-call
work than in arithmetic, and numpy runs the same float32 network 1.4-1.7x faster at every
batch size measured (1 to 3000 rows; docs/solvers.md). :func:`compile_chain` recognises
a graph whose nodes form ONE chain from input ``G`` to output ``I``, each node taking the
previous node's output and constant float32 initializers:

* ``Add``, ``Sub``, ``Mul``, ``Div`` with a constant scalar or row vector (``c / x`` is
  not recognised; ``x / c`` runs as ``x * (1 / c)``),
* ``Gemm`` (``transA = 0``, any ``alpha``, ``beta``, ``transB``) and ``MatMul`` with a
  constant 2-D matrix,
* ``Tanh``, ``Sigmoid``, ``Relu``, ``Identity``.

Anything else (another op, a branch, a second input, a non-float tensor, an attribute it
does not know) gives ``None`` and the caller keeps onnxruntime.

:class:`NumpyChain` computes what onnxruntime computes, in float32: the input is rounded
to float32 (onnxruntime's input type), consecutive elementwise steps are merged into one
``x s + c`` and folded into the neighbouring dense layer (the min-max scaling of the
paper's MLP disappears into its first layer), and the float32 output is returned as
float64. The results differ from onnxruntime's by a few float32 units in the last place
(sums and ``tanh`` round differently; folding rounds the weights once more); tests
compare them, and :class:`~hapticsdk_onnx.OnnxModel` checks every chain against
onnxruntime on probe rows before using it (a graph whose folded weights would lose
accuracy, e.g. a feature with a narrow range far from zero, stays on onnxruntime).

The compiled chain can be kept on disk (:func:`save_chain` / :func:`load_chain`, a numpy
archive without pickles, written atomically) keyed by the model file's SHA-256, so a later
process gets it without importing the ``onnx`` package.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["NumpyChain", "compile_chain", "save_chain", "load_chain", "chain_cache_path"]

#: format of the cached chain files (bumped when the stored layout changes)
CHAIN_VERSION = 3
_ACTIVATIONS = ("Tanh", "Sigmoid", "Relu", "Identity")
_FLOAT = 1   # onnx.TensorProto.FLOAT
_CODES = {"dense": 0, "affine": 1, "Tanh": 3, "Sigmoid": 4, "Relu": 5, "Identity": 6}


class NumpyChain:
    """Dense layers, elementwise steps and activations evaluated with numpy in float32.

    Attributes:
        stages: in order, ``("dense", W (in, out), b (out,))``, ``("affine", s (w,), c (w,))``
            (``x s + c``) or ``("act", name, None)``; arrays float32.
        n_in, n_out: input and output widths.
    """

    def __init__(self, stages: list[tuple[str, Any, Any]], n_in: int, n_out: int) -> None:
        self.stages = stages
        self.n_in, self.n_out = int(n_in), int(n_out)
        self._ops = [(_CODES[a] if k == "act" else _CODES[k], a, b) for k, a, b in stages]

    def __call__(self, X: np.ndarray) -> np.ndarray:
        """Outputs ``(n, n_out)`` float64 for inputs ``(n, n_in)`` (any float dtype); a
        single row ``(n_in,)`` gives ``(n_out,)``."""
        Z = np.asarray(X).astype(np.float32)     # a new array: the steps below work in place
        dot = np.dot
        for code, a, b in self._ops:
            if code == 0:
                Z = dot(Z, a)
                Z += b
            elif code == 3:
                np.tanh(Z, out=Z)
            elif code == 1:
                Z *= a
                Z += b
            elif code == 4:
                np.negative(Z, out=Z)
                with np.errstate(over="ignore"):     # exp(large) = inf: the sigmoid is 0
                    np.exp(Z, out=Z)
                Z += 1.0
                np.reciprocal(Z, out=Z)
            elif code == 5:
                np.maximum(Z, 0.0, out=Z)
        return Z.astype(np.float64)

    # -- storage ------------------------------------------------------------
    def to_arrays(self) -> dict[str, np.ndarray]:
        """The chain as named arrays plus a JSON ``spec`` (see :func:`save_chain`)."""
        arrays: dict[str, np.ndarray] = {}
        spec: dict[str, Any] = {"version": CHAIN_VERSION, "n_in": self.n_in, "n_out": self.n_out, "stages": []}
        for i, (kind, a, b) in enumerate(self.stages):
            spec["stages"].append([kind, a] if kind == "act" else [kind])
            if kind != "act":
                arrays[f"s{i}_a"], arrays[f"s{i}_b"] = a, b
        return with_spec(spec, arrays)

    @classmethod
    def from_arrays(cls, z: Any) -> "NumpyChain":
        """Inverse of :meth:`to_arrays`; raises ``ValueError`` on anything inconsistent."""
        spec = read_spec(z, CHAIN_VERSION)
        n_in, n_out = int(spec["n_in"]), int(spec["n_out"])
        w = n_in
        stages: list[tuple[str, Any, Any]] = []
        for i, st in enumerate(spec["stages"]):
            kind = st[0]
            if kind == "act":
                if st[1] not in _ACTIVATIONS:
                    raise ValueError(f"unknown activation {st[1]!r}")
                stages.append(("act", str(st[1]), None))
                continue
            a = np.asarray(z[f"s{i}_a"], np.float32)
            b = np.asarray(z[f"s{i}_b"], np.float32)
            if kind == "dense" and a.ndim == 2 and a.shape[0] == w and b.shape == (a.shape[1],):
                w = a.shape[1]
            elif not (kind == "affine" and a.shape == (w,) and b.shape == (w,)):
                raise ValueError(f"bad stage {i}")
            stages.append((kind, a, b))
        if w != n_out:
            raise ValueError("output width does not match")
        return cls(stages, n_in, n_out)


def compile_chain(proto: Any, n_in: int) -> NumpyChain | None:
    """The :class:`NumpyChain` of an ``onnx.ModelProto`` whose graph is a recognised chain
    from ``G`` (``n_in`` columns) to ``I`` (see module doc), else ``None``."""
    try:
        from onnx import numpy_helper
        g = proto.graph
        inits = {t.name: t for t in g.initializer}
        if any(t.data_type != _FLOAT for t in inits.values()):
            return None
        real = [i for i in g.input if i.name not in inits]
        if [i.name for i in real] != ["G"] or [o.name for o in g.output] != ["I"]:
            return None
        if real[0].type.tensor_type.elem_type != _FLOAT or g.output[0].type.tensor_type.elem_type != _FLOAT:
            return None
        consts = {n: numpy_helper.to_array(t).astype(np.float64) for n, t in inits.items()}
        return _compile_nodes(list(g.node), consts, n_in)
    except Exception:   # anything unexpected in the graph: keep onnxruntime
        return None


def _attrs(node: Any) -> dict[str, Any]:
    from onnx import helper
    return {a.name: helper.get_attribute_value(a) for a in node.attribute}


def _compile_nodes(nodes: list[Any], consts: dict[str, np.ndarray], n_in: int) -> NumpyChain | None:
    cur, w = "G", n_in
    # raw steps in float64: ("add", c) | ("mul", s) | ("dense", W, b) | ("act", name)
    raw: list[tuple[str, Any, Any]] = []
    for node in nodes:
        if node.domain not in ("", "ai.onnx") or len(node.output) != 1:
            return None
        ins = list(node.input)
        if cur not in ins or ins.count(cur) != 1 or any(i not in consts for i in ins if i != cur):
            return None
        op = node.op_type
        at = _attrs(node)
        if op in _ACTIVATIONS:
            if len(ins) != 1 or at:
                return None
            raw.append(("act", op, None))
        elif op in ("Add", "Sub", "Mul", "Div"):
            if len(ins) != 2 or at:
                return None
            first = ins[0] == cur
            c = consts[ins[1] if first else ins[0]]
            if c.ndim > 2 or (c.ndim == 2 and c.shape[0] != 1) or c.size not in (1, w):
                return None
            c = np.broadcast_to(c.reshape(-1), (w,)).astype(np.float64)
            if op == "Add":
                raw.append(("add", c, None))
            elif op == "Mul":
                raw.append(("mul", c, None))
            elif op == "Sub":
                if first:
                    raw.append(("add", -c, None))
                else:                               # c - x
                    raw += [("mul", -np.ones(w), None), ("add", c, None)]
            else:
                if not first or not np.all(c != 0):
                    return None
                raw.append(("mul", 1.0 / c, None))
        elif op in ("Gemm", "MatMul"):
            if ins[0] != cur:
                return None
            W = consts[ins[1]]
            if op == "MatMul":
                if len(ins) != 2 or at or W.ndim != 2:
                    return None
                b = np.zeros(W.shape[1])
            else:
                if set(at) - {"alpha", "beta", "transA", "transB"} or at.get("transA", 0) != 0 or len(ins) not in (2, 3):
                    return None
                if W.ndim != 2:
                    return None
                if at.get("transB", 0):
                    W = W.T
                W = W * float(at.get("alpha", 1.0))
                if len(ins) == 3:
                    C = consts[ins[2]]
                    if C.ndim > 2 or (C.ndim == 2 and C.shape[0] != 1) or C.size not in (1, W.shape[1]):
                        return None
                    b = np.broadcast_to(C.reshape(-1), (W.shape[1],)) * float(at.get("beta", 1.0))
                else:
                    b = np.zeros(W.shape[1])
            if W.shape[0] != w:
                return None
            raw.append(("dense", W, np.asarray(b, np.float64)))
            w = W.shape[1]
        else:
            return None
        cur = node.output[0]
    if cur != "I" or not raw:
        return None
    return _fold(raw, n_in, w)


def _fold(raw: list[tuple[str, Any, Any]], n_in: int, n_out: int) -> NumpyChain:
    """Merge consecutive elementwise steps into one ``x s + c`` and fold it into a
    neighbouring dense layer (``(x s + c) W + b = x (s W) + (c W + b)`` before it,
    ``(x W + b) s + c = x (W s) + (b s + c)`` after it), in float64, then round to float32.
    What is left (an affine step between activations, activations) runs as is."""
    merged: list[list[Any]] = []
    for kind, a, b in raw:
        if kind in ("add", "mul"):
            s_, c_ = (np.ones_like(a), a) if kind == "add" else (a, np.zeros_like(a))
            if merged and merged[-1][0] == "affine":          # s2 (s1 x + c1) + c2
                s1, c1 = merged[-1][1], merged[-1][2]
                merged[-1] = ["affine", s1 * s_, c1 * s_ + c_]
            else:
                merged.append(["affine", s_, c_])
        else:
            merged.append([kind, a, b])
    steps: list[list[Any]] = []
    for kind, a, b in merged:
        if kind == "dense" and steps and steps[-1][0] == "affine":
            s_, c_ = steps.pop()[1:]
            steps.append(["dense", s_[:, None] * a, c_ @ a + b])
        elif kind == "affine" and steps and steps[-1][0] == "dense":
            W, bb = steps[-1][1], steps[-1][2]
            steps[-1] = ["dense", W * a[None, :], bb * a + b]
        else:
            steps.append([kind, a, b])
    stages = [(k, a, None) if k == "act" else (k, np.asarray(a, np.float32), np.asarray(b, np.float32))
              for k, a, b in steps]
    return NumpyChain(stages, n_in, n_out)


# ---------------------------------------------------------------------------
# disk cache, keyed by the model file's SHA-256

def with_spec(spec: dict[str, Any], arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``arrays`` plus ``spec`` as a JSON string array under ``"spec"``: the layout of the
    plugin's cache archives (numpy ``.npz``, no pickles)."""
    return {**arrays, "spec": np.array(json.dumps(spec))}


def read_spec(z: Any, version: int) -> dict[str, Any]:
    """The JSON ``spec`` of a cache archive written by :func:`with_spec`; ``ValueError``
    unless it is a dict of layout ``version``."""
    spec = json.loads(str(z["spec"]))
    if not isinstance(spec, dict) or spec.get("version") != version:
        raise ValueError(f"cache layout is not version {version}")
    return spec

def chain_cache_path(sha256: str, cache_dir: str | os.PathLike[str] | None = None) -> Path:
    """``<cache>/onnx-chain/<sha256>.npz``; ``<cache>`` is ``cache_dir`` or
    ``$HAPTICSDK_CACHE_DIR`` or ``$XDG_CACHE_HOME/hapticsdk`` or ``~/.cache/hapticsdk``
    (the folder the amortised solver's tables use)."""
    if cache_dir is None:
        from hapticsdk.fileio import cache_dir as sdk_cache_dir
        base = sdk_cache_dir()
    else:
        base = Path(cache_dir)
    return base / "onnx-chain" / f"{sha256}.npz"


def save_chain(chain: NumpyChain | None, path: Path) -> None:
    """Write ``chain`` (or the fact that the graph is not a recognised chain, for
    ``None``) to ``path`` atomically (:func:`hapticsdk.fileio.atomic_savez`)."""
    from hapticsdk.fileio import atomic_savez
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, Any] = (chain.to_arrays() if chain is not None else
                              {"spec": np.array(json.dumps({"version": CHAIN_VERSION, "none": True}))})
    atomic_savez(path, compressed=False, **arrays)


def load_chain(path: Path) -> tuple[bool, NumpyChain | None]:
    """``(found, chain)`` from a file of :func:`save_chain`; ``(False, None)`` when the file
    is missing or unreadable, ``(True, None)`` for a graph recorded as not a chain."""
    try:
        with np.load(path, allow_pickle=False) as z:
            spec = json.loads(str(z["spec"]))
            if isinstance(spec, dict) and spec.get("version") == CHAIN_VERSION and spec.get("none") is True:
                return True, None
            return True, NumpyChain.from_arrays(z)
    except Exception:
        return False, None
