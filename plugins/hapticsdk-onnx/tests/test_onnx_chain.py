"""The numpy evaluation of dense-chain ONNX graphs (hapticsdk_onnx.chain) against
onnxruntime: the shipped model, a chain built here with every recognised op, graphs it
must refuse, and the SHA-256-keyed disk cache (read back, and refused when altered)."""

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper

from hapticsdk.errors import ValidationError
from hapticsdk_onnx import OnnxModel, default_model_path
from hapticsdk_onnx import chain as ch

# float32 keeps 24 significant bits (eps = 2**-23 ~ 1.2e-7). onnxruntime and numpy round the
# same float32 operations (sums of at most 20 products, tanh/sigmoid, an affine map) in a
# different order or with a different tanh, each a few eps on values of order 1; 16 eps
# relative to max(1, |y|) is far above that and far below any real difference (a wrong
# weight, sign or op moves outputs by 1e-3 and more).
TOL = 16 * 2.0 ** -23


@pytest.fixture(autouse=True)
def _cache_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("HAPTICSDK_CACHE_DIR", str(tmp_path / "cache"))


def _rows(model, n, seed, widen=0.0):
    sp = model.feature_space
    span = sp.upper - sp.lower
    r = np.random.default_rng(seed)
    return sp.lower - widen * span + r.random((n, len(sp))) * span * (1 + 2 * widen)


def _ort(model, X):
    return model._session.run(["I"], {"G": X.astype(np.float32)})[0].astype(np.float64)


def _close(a, b):
    return np.all(np.abs(a - b) <= TOL * np.maximum(1.0, np.abs(b)))


def test_default_model_runs_in_numpy_and_matches_onnxruntime():
    m = OnnxModel(default_model_path())
    assert m.runtime == "numpy"
    for n in (1, 7, 95, 3000):
        X = _rows(m, n, n, widen=0.2)       # also outside the training box (extrapolation)
        assert _close(m.predict(X), _ort(m, X))
    ref = OnnxModel(default_model_path(), runtime="onnxruntime")
    assert ref.runtime == "onnxruntime"
    with pytest.raises(ValidationError, match="runtime"):
        OnnxModel(default_model_path(), runtime="gpu")
    X = _rows(m, 50, 1)
    np.testing.assert_array_equal(ref.predict(X), _ort(ref, X))


def _with_graph(tmp_path, nodes, inits, name="m.onnx"):
    """The default model file (its metadata: 5 features -> 2 dimensions) with another graph."""
    proto = onnx.load(str(default_model_path()))
    g = proto.graph
    del g.node[:]
    del g.initializer[:]
    g.node.extend(nodes)
    g.initializer.extend(numpy_helper.from_array(np.asarray(v, np.float32), k) for k, v in inits.items())
    for e in proto.metadata_props:
        if e.key == "hapticsdk.architecture":
            e.value = '"custom"'             # not the paper's MLP: no named initializers
    p = tmp_path / name
    onnx.save(proto, str(p))
    return p


def _all_ops_graph(r):
    nodes = [helper.make_node("Sub", ["c0", "G"], ["a"]),             # c - x
             helper.make_node("Div", ["a", "c1"], ["b"]),
             helper.make_node("MatMul", ["b", "M1"], ["z"]),
             helper.make_node("Add", ["bz", "z"], ["z0"]),             # constant first
             helper.make_node("Mul", ["z0", "c3"], ["z1"]),            # folded into the MatMul
             helper.make_node("Sigmoid", ["z1"], ["h"]),
             helper.make_node("Mul", ["h", "c2"], ["h2"]),
             helper.make_node("Gemm", ["h2", "M2", "bb"], ["y"], alpha=0.7, beta=1.5, transB=1),
             helper.make_node("Relu", ["y"], ["y1"]),
             helper.make_node("Identity", ["y1"], ["y2"]),
             helper.make_node("Add", ["y2", "one"], ["I"])]
    inits = {"c0": r.normal(size=5) * 3, "c1": r.uniform(0.5, 4, size=(1, 5)), "M1": r.normal(size=(5, 8)),
             "bz": r.normal(size=8), "c3": r.uniform(0.5, 2, size=8), "c2": r.normal(size=8), "M2": r.normal(size=(2, 8)),
             "bb": r.normal(size=(1, 2)), "one": np.array([0.25])}
    return nodes, inits


def test_every_recognised_op_matches_onnxruntime(tmp_path):
    nodes, inits = _all_ops_graph(np.random.default_rng(3))
    m = OnnxModel(_with_graph(tmp_path, nodes, inits))
    assert m.runtime == "numpy"
    X = _rows(m, 400, 2, widen=0.5)
    Y = m.predict(X)
    assert _close(Y, _ort(m, X))
    assert (Y == 0.25).any() and (Y > 0.25).any()     # both sides of the Relu were exercised


@pytest.mark.parametrize("variant", ["unknown op", "input used twice", "x / c reversed", "transA"])
def test_graphs_that_are_not_a_plain_chain_stay_on_onnxruntime(tmp_path, variant):
    nodes, inits = _all_ops_graph(np.random.default_rng(4))
    if variant == "unknown op":
        nodes[5] = helper.make_node("Exp", ["z1"], ["h"])
    elif variant == "input used twice":
        nodes[0] = helper.make_node("Sub", ["G", "G"], ["a"])
    elif variant == "x / c reversed":
        nodes[1] = helper.make_node("Div", ["c1", "a"], ["b"])
    else:
        nodes[7] = helper.make_node("Gemm", ["M2", "h2", "bb"], ["y"], transA=1)
    p = _with_graph(tmp_path, nodes, inits)
    proto = onnx.load(str(p))
    assert ch.compile_chain(proto, 5) is None
    if variant == "transA":   # not a valid model for onnxruntime either
        return
    m = OnnxModel(p)
    assert m.runtime == "onnxruntime"
    X = _rows(m, 20, 5)
    np.testing.assert_array_equal(m.predict(X), _ort(m, X))


def test_a_chain_that_disagrees_with_onnxruntime_is_not_used(tmp_path):
    """(x - 1e6) + 1e6 keeps x only to ~0.06 in float32 (onnxruntime); merged into one step
    the chain keeps all of it. The outputs differ by far more than float32 rounding, the
    probe check sees it, and the model stays on onnxruntime."""
    r = np.random.default_rng(8)
    nodes = [helper.make_node("Sub", ["G", "big"], ["a"]),
             helper.make_node("Add", ["a", "big"], ["b"]),
             helper.make_node("Gemm", ["b", "W", "c"], ["z"], transB=1),
             helper.make_node("Tanh", ["z"], ["I"])]
    inits = {"big": np.full(5, 1e6), "W": r.normal(size=(2, 5)) * 0.005, "c": np.zeros(2)}
    p = _with_graph(tmp_path, nodes, inits)
    chain = ch.compile_chain(onnx.load(str(p)), 5)
    m = OnnxModel(p)
    X = _rows(m, 50, 9)
    assert chain is not None and not _close(chain(X), _ort(m, X))
    assert m.runtime == "onnxruntime"
    np.testing.assert_array_equal(m.predict(X), _ort(m, X))


def test_chain_cache_is_read_back_and_an_altered_one_is_refused(tmp_path, monkeypatch):
    path = default_model_path()
    m = OnnxModel(path)
    assert m.runtime == "numpy"
    cached = ch.chain_cache_path(m._sha256)
    assert cached.is_file()
    # a second model reads the cache: compiling again would fail here
    monkeypatch.setattr(ch, "compile_chain", lambda *a, **k: pytest.fail("compiled again"))
    m2 = OnnxModel(path)
    assert m2.runtime == "numpy"
    X = _rows(m, 64, 6)
    np.testing.assert_array_equal(m2.predict(X), m.predict(X))
    # an altered cache file (weights of the first dense layer scaled) disagrees with the
    # graph on the probe rows: the model keeps onnxruntime
    chain = m._chain
    bad = ch.NumpyChain([(k, a * np.float32(1.01), b) if k == "dense" else (k, a, b)
                         for k, a, b in chain.stages], chain.n_in, chain.n_out)
    ch.save_chain(bad, cached)
    m3 = OnnxModel(path)
    assert m3.runtime == "onnxruntime"
    np.testing.assert_array_equal(m3.predict(X), _ort(m3, X))


def test_chain_round_trips_through_arrays():
    m = OnnxModel(default_model_path())
    m.runtime
    c = m._chain
    back = ch.NumpyChain.from_arrays(c.to_arrays())
    X = _rows(m, 30, 7)
    np.testing.assert_array_equal(back(X), c(X))
    arr = c.to_arrays()
    i = next(j for j, st in enumerate(c.stages) if st[0] == "dense")
    arr[f"s{i}_a"] = arr[f"s{i}_a"][:, :3]          # a dense layer of the wrong width
    with pytest.raises(ValueError):
        ch.NumpyChain.from_arrays(arr)


def test_a_cached_chain_needs_no_onnxruntime_session(tmp_path):
    """Once a file's chain is cached (written after onnxruntime loaded those bytes), a
    later load of the same mlp-tanh file checks the chain against the float64 numpy twin
    and creates no onnxruntime session (start-up); its answers still match onnxruntime.
    An altered cached chain is refused by that check, and onnxruntime is then used."""
    path = default_model_path()
    first = OnnxModel(path)
    assert first.runtime == "numpy" and first._session is not None
    again = OnnxModel(path)
    X = _rows(first, 200, 11, widen=0.2)
    assert _close(again.predict(X), _ort(first, X))
    assert again.runtime == "numpy" and again._session is None
    chain = again._chain
    bad = ch.NumpyChain([(k, a, b * np.float32(1.001)) if k == "dense" else (k, a, b)
                         for k, a, b in chain.stages], chain.n_in, chain.n_out)
    ch.save_chain(bad, ch.chain_cache_path(again._sha256))
    third = OnnxModel(path)
    assert third.runtime == "onnxruntime"
    np.testing.assert_array_equal(third.predict(X), _ort(third, X))


def test_cache_archives_of_another_layout_version_are_not_read(tmp_path):
    """A chain or description archive written under another layout version is treated
    as missing (rebuilt), never read with the wrong layout."""
    import hapticsdk_onnx as ho

    m = OnnxModel(default_model_path())
    assert m.runtime == "numpy"
    arrays = m._chain.to_arrays()
    spec = __import__("json").loads(str(arrays["spec"]))
    spec["version"] = ch.CHAIN_VERSION + 1
    odd = tmp_path / "odd.npz"
    np.savez(odd, **ch.with_spec(spec, {k: v for k, v in arrays.items() if k != "spec"}))
    assert ch.load_chain(odd) == (False, None)
    with np.load(odd) as z:
        with pytest.raises(ValueError):
            ho._Description.from_npz(z)
