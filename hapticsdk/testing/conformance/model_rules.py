"""The rules of the ``model`` kind (``RULES['model']``): shapes, dimensions, vectorised and
deterministic prediction, bad input, the Jacobian against central differences, metadata,
and that every output responds to the features."""

from __future__ import annotations

import json
import math
from typing import Any, Mapping, cast

import numpy as np

from ...errors import ValidationError
from ...perception.features import Feature, FeatureSpace
from ...perception.models import PerceptionModel
from ...solvers import SolveProblem
from .memory import _traced_after
from .runner import _Ctx, _run_rules
from .values import _refuses


#: how far outside 0..1 a model's intensity may be (float rounding of a float32 graph)
INTENSITY_TOL = 1e-5
#: central-difference step of the Jacobian check (share of each feature's range) and the
#: relative tolerance: a float32 model's differences carry ~1e-7 / 1e-4 = 1e-3 noise
JACOBIAN_STEP = 1e-4
JACOBIAN_RTOL = 0.01
#: an output of a model must change by at least this over the model's feature box
#: (``responds``): the success tolerance a solve is judged at by default (the sum of absolute
#: intensity errors, :class:`~hapticsdk.solvers.SolveProblem`'s ``tolerance``). An output
#: spanning less changes by less than that whatever features a solver picks, so the
#: features do not steer it: a constant, or a model that ignores its inputs.
RESPONSE_MIN = float(SolveProblem.tolerance)
#: random points of the box ``responds`` evaluates besides its landmarks (an output that
#: moves only inside a region under ~1/256 of the box may pass unseen)
RESPONSE_SAMPLES = 256
#: rows of the ``vectorised`` rule's large batch: a population solver evaluates its whole
#: population (and its Jacobian rows) in one call, 100 to 10^5 rows for the GA, and the
#: dimension rules time constraints on batches of this size; its first rows must give
#: what they give in a batch of 33 and row by row, and every row what it gives in pieces
#: of the batch of every power of two (an output that depends on the batch's size above
#: this is not seen)
VECTORISED_ROWS = 10_000


#: the ``vectorised`` rule's memory run: a new batch of :data:`MEMORY_BATCH_ROWS` rows
#: for each of ``MEMORY_CALLS[-1]`` calls of ``predict()``, the memory the process holds
#: (``tracemalloc``) read after each of these calls; the first reading follows 100 calls
#: (a bounded cache, ``functools.lru_cache(maxsize=100)``, is full by then)
MEMORY_CALLS = (100, 300, 500, 700, 900)
MEMORY_BATCH_ROWS = 64
#: a model whose memory grows over every interval of :data:`MEMORY_CALLS` by this many
#: bytes per row predicted or more fails: a solve evaluates 10^5 to 10^7 rows (a GA's
#: populations, an amortised solver's training set), so at one byte a row it keeps up to
#: 10 MB more per solve, for as long as the model lives; a row kept (its features, a
#: float each) takes 8 bytes a feature or more. The first-party models hold the same
#: memory at every reading
MEMORY_BYTES_PER_ROW = 1.0


def _predict_memory(m: PerceptionModel, pool: np.ndarray) -> list[int]:
    """The memory (bytes, ``tracemalloc``) held after each of :data:`MEMORY_CALLS` calls of
    ``m.predict`` on consecutive batches of :data:`MEMORY_BATCH_ROWS` rows of ``pool``."""
    return _traced_after(MEMORY_CALLS, lambda k: m.predict(pool[k * MEMORY_BATCH_ROWS:(k + 1) * MEMORY_BATCH_ROWS]))


def _assert_column(m: PerceptionModel, j: int, fd: np.ndarray, J: np.ndarray, span: float, where: str) -> None:
    """Column ``j`` of a model's Jacobian ``J`` agrees with the finite differences ``fd``
    within :data:`JACOBIAN_RTOL` of their size over the feature's range ``span``."""
    # per unit of the feature's range: compare the change over the whole span
    err = np.abs(fd - J).max() * span
    scale = max(np.abs(fd).max() * span, 1e-6)
    assert err <= JACOBIAN_RTOL * scale + 1e-6, \
        (f"jacobian column {m.feature_names[j]}{where} differs from finite differences by "
         f"{err / scale:.2%} of its size (tolerance {JACOBIAN_RTOL:.1%})")


def _piece_sizes(n: int) -> list[int]:
    """Lengths of consecutive pieces of ``n`` rows: every power of two that fits, then the
    rest (``vectorised`` predicts its large batch in them)."""
    sizes: list[int] = []
    size = 1
    while sum(sizes) + size <= n:
        sizes.append(size)
        size *= 2
    return sizes + ([n - sum(sizes)] if n > sum(sizes) else [])


def _landmarks(m: PerceptionModel) -> list[tuple[str, np.ndarray]]:
    """Points of a model's feature box where a formula breaks first, by name: the corners
    (the first 10 features), the centre (``x - mid`` is 0 there), the face centres (each
    feature at a bound, the others at the centre) and the declared ``feature_defaults``."""
    fs = cast(FeatureSpace, m.feature_space)
    lo, hi, d = fs.lower, fs.upper, m.n_features
    k = min(d, 10)
    corners = np.array([[hi[j] if (i >> j) & 1 else lo[j] for j in range(d)] for i in range(2 ** k)])
    mid = (lo + hi) / 2
    faces = np.repeat(mid[None, :], 2 * d, axis=0)
    faces[np.arange(d), np.arange(d)] = lo
    faces[d + np.arange(d), np.arange(d)] = hi
    out = [("the corners of the feature bounds", corners), ("the centre of the feature bounds", mid[None, :]),
           ("the centres of the faces of the feature bounds", faces)]
    defaults = m.metadata.get("feature_defaults") if isinstance(m.metadata, Mapping) else None
    if defaults and all(n in defaults for n in m.feature_names):
        try:
            out.append(("the declared feature_defaults",
                        np.array([[float(defaults[n]) for n in m.feature_names]])))
        except (TypeError, ValueError):
            pass   # metadata judges unreadable defaults
    return out


def _row(m: PerceptionModel, x: np.ndarray) -> str:
    return "{" + ", ".join(f"{n}: {v:.6g}" for n, v in zip(m.feature_names, x)) + "}"


def _model_rules(ctx: _Ctx) -> None:
    holder: dict[str, Any] = {}

    def inputs(n: int, seed: int = 0) -> np.ndarray:
        m = holder["m"]
        rng = np.random.default_rng(seed)
        if m.feature_space is not None:
            return m.feature_space.random(n, rng)
        return rng.random((n, m.n_features))

    def r_shapes() -> None:
        m = ctx.make()
        assert isinstance(m, PerceptionModel), f"factory returned {type(m).__name__}, not a PerceptionModel"
        holder["m"] = m
        assert len(set(m.dimension_names)) == m.n_outputs, "repeated dimension names"
        for n in (1, 7):
            Y = m.predict(inputs(n))
            assert Y.shape == (n, m.n_outputs), f"predict gave shape {Y.shape}, expected {(n, m.n_outputs)}"
            assert np.isfinite(Y).all(), "non-finite intensities"
            assert (Y >= -INTENSITY_TOL).all() and (Y <= 1 + INTENSITY_TOL).all(), \
                f"intensities outside 0..1 (min {Y.min():.6g}, max {Y.max():.6g}) inside the feature bounds"
        if m.feature_space is not None:   # the box's landmarks too (corners: where extrapolation starts)
            for where, P in _landmarks(m):
                Y = m.predict(P)
                bad = ~np.isfinite(Y).all(axis=1)
                assert not bad.any(), f"non-finite intensities at {where}, e.g. at {_row(m, P[bad][0])}"
                assert (Y >= -INTENSITY_TOL).all() and (Y <= 1 + INTENSITY_TOL).all(), \
                    f"intensities outside 0..1 at {where} (min {Y.min():.6g}, max {Y.max():.6g})"
        assert m.predict(inputs(1)[0]).shape == (1, m.n_outputs), "a 1-D input must give one row"

    def r_vectorised() -> None:
        m = holder["m"]
        X = inputs(33, 1)
        X0 = X.copy()
        Y = m.predict(X)
        assert np.array_equal(X, X0), \
            ("predict() changed its input array in place: the caller's array (a solver's population, "
             "a scene's features) is not the model's to write; compute on a copy")
        rows = np.concatenate([m.predict(X[i:i + 1]) for i in range(X.shape[0])])
        np.testing.assert_allclose(Y, rows, rtol=1e-4, atol=1e-5, err_msg="batch and row-by-row predictions differ")
        # a large batch (a solver's population) gives the same rows, finite and in 0..1
        big = np.concatenate([X, inputs(VECTORISED_ROWS - X.shape[0], 3)])
        Yb = m.predict(big)
        np.testing.assert_allclose(Yb[:X.shape[0]], Y, rtol=1e-4, atol=1e-5,
                                   err_msg=f"a batch of {VECTORISED_ROWS} rows and a batch of {X.shape[0]} give "
                                           f"different predictions for the same rows")
        assert np.isfinite(Yb).all() and (Yb >= -INTENSITY_TOL).all() and (Yb <= 1 + INTENSITY_TOL).all(), \
            (f"in a batch of {VECTORISED_ROWS} rows, intensities non-finite or outside 0..1 "
             f"(min {np.nanmin(Yb):.6g}, max {np.nanmax(Yb):.6g})")
        # and in pieces of every power of two up to it (1, 2, 4, ... 4096 rows, then the
        # rest): each row gives what it gives in the whole batch, whatever batch it is in
        start = 0
        for size in _piece_sizes(VECTORISED_ROWS):
            Yp = m.predict(big[start:start + size])
            np.testing.assert_allclose(Yp, Yb[start:start + size], rtol=1e-4, atol=1e-5,
                                       err_msg=f"rows {start}..{start + size - 1} give different predictions in a "
                                               f"batch of {size} rows than in the batch of {VECTORISED_ROWS}")
            start += size
        # and keeps nothing per call: a solve calls it thousands of times
        held = _predict_memory(m, inputs(MEMORY_CALLS[-1] * MEMORY_BATCH_ROWS, 7))
        per_row = np.diff(held) / (np.diff(MEMORY_CALLS) * MEMORY_BATCH_ROWS)
        assert not (per_row >= MEMORY_BYTES_PER_ROW).all(), \
            (f"predict() holds more memory the more it is called: "
             f"{', '.join(f'+{b} B by call {c}' for c, b in zip(MEMORY_CALLS[1:], np.cumsum(np.diff(held))))} "
             f"(after call {MEMORY_CALLS[0]}, batches of {MEMORY_BATCH_ROWS} rows; "
             f"{(held[-1] - held[0]) / ((MEMORY_CALLS[-1] - MEMORY_CALLS[0]) * MEMORY_BATCH_ROWS):.3g} B per row): "
             f"a solve predicts 10^5 to 10^7 rows; keep no history of the batches (a cache must be bounded)")

    def r_determinism() -> None:
        m = holder["m"]
        X = inputs(16, 2)
        np.testing.assert_array_equal(m.predict(X), m.predict(X), err_msg="two calls gave different outputs")
        m2 = ctx.make()
        np.testing.assert_allclose(m.predict(X), m2.predict(X), rtol=1e-6, atol=1e-7,
                                   err_msg="two instances gave different outputs")

    def r_bad_input() -> None:
        m = holder["m"]
        bads = [np.zeros((3, m.n_features + 1)), np.zeros((2, 2, m.n_features)),
                np.full((2, m.n_features), np.nan), np.full((1, m.n_features), np.inf)]
        for bad in bads:
            assert _refuses(ValidationError, lambda: m.predict(bad)), \
                f"predict accepted a bad input of shape {bad.shape}"

    def r_jacobian() -> None:
        m = holder["m"]
        X = inputs(4, 3)
        J = np.asarray(m.jacobian(X))
        assert J.shape == (4, m.n_outputs, m.n_features), f"jacobian shape {J.shape}"
        assert np.isfinite(J).all(), "non-finite jacobian"
        span = (m.feature_space.upper - m.feature_space.lower) if m.feature_space is not None else np.ones(m.n_features)
        for j in range(m.n_features):
            h = JACOBIAN_STEP * max(span[j], 1e-6)
            e = np.zeros(m.n_features)
            e[j] = h
            fd = (m.predict(X + e) - m.predict(X - e)) / (2 * h)
            _assert_column(m, j, fd, J[:, :, j], span[j], "")
        if m.feature_space is None:
            return
        # at the box's two corners (where a bounded solve ends up): one-sided second-order
        # differences stepping into the box, as exact as central ones to the same order
        for corner, sign in ((np.asarray(m.feature_space.lower, float), 1.0),
                             (np.asarray(m.feature_space.upper, float), -1.0)):
            C = corner[None, :]
            Jc = np.asarray(m.jacobian(C))
            assert Jc.shape == (1, m.n_outputs, m.n_features) and np.isfinite(Jc).all(), \
                f"jacobian at the corner {corner.tolist()}: shape {Jc.shape} or non-finite"
            f0 = m.predict(C)
            for j in range(m.n_features):
                h = JACOBIAN_STEP * max(span[j], 1e-6)
                e = np.zeros(m.n_features)
                e[j] = sign * h
                fd = sign * (-3 * f0 + 4 * m.predict(C + e) - m.predict(C + 2 * e)) / (2 * h)
                _assert_column(m, j, fd, Jc[:, :, j], span[j], f" at the corner {corner.tolist()}")

    def r_metadata() -> None:
        m = holder["m"]
        json.dumps(m.describe(), default=str)
        assert m.feature_space is not None, "the model declares no feature_space (training range bounds)"
        assert tuple(m.feature_space.names) == m.feature_names, "feature_space names differ from inputs"
        # the facts build_problem hands every dimension's constraints (float() of each): a
        # NaN makes a bound NaN, which reads as met whatever the features
        facts = dict(m.metadata.get("constraint_context") or {})
        if m.metadata.get("df_hz") is not None:
            facts["df_hz"] = m.metadata["df_hz"]
        for k, v in facts.items():
            try:
                x = float(v)
            except (TypeError, ValueError) as exc:
                raise AssertionError(f"metadata fact {k}={v!r} is not a number ({exc}): build_problem passes "
                                     f"float() of it to every dimension's constraints") from None
            assert math.isfinite(x) and not (k == "df_hz" and x <= 0), \
                (f"metadata fact {k}={v!r} is not a finite number{' > 0 (an FFT resolution, Hz)' if k == 'df_hz' else ''}: "
                 f"build_problem passes it to every dimension's constraints, and a NaN bound reads as met whatever "
                 f"the features")
        defaults = m.metadata.get("feature_defaults")
        if defaults is not None:
            for k, v in defaults.items():
                assert k in m.feature_names, f"feature_defaults names unknown feature {k!r}"
                f = m.feature_space[k]
                assert f.lower - 1e-9 <= float(v) <= f.upper + 1e-9, f"default {k}={v} outside [{f.lower}, {f.upper}]"

    def r_dimensions() -> None:
        m = holder["m"]
        from ...perception.features import same_unit
        from ...plugins import registry
        reg = registry("dimension")
        missing = [n for n in m.dimension_names if n not in reg]
        assert not missing, (f"predicts dimension(s) {missing} that no installed plugin provides (installed: "
                             f"{reg.names()})")
        offered: dict[str, Feature] = {}
        for n in m.dimension_names:
            obj = reg.load(n)
            dim = obj() if isinstance(obj, type) else obj
            for f in getattr(dim, "features", ()):
                offered.setdefault(f.name, f)
        stray = [n for n in m.feature_names if n not in offered]
        assert not stray, (f"reads feature(s) {stray} that none of the dimensions it predicts "
                           f"({list(m.dimension_names)}) contributes (they offer {sorted(offered)})")
        if m.feature_space is not None:
            for n in m.feature_names:
                mine, theirs = m.feature_space[n].unit, offered[n].unit
                assert same_unit(mine, theirs), \
                    f"reads {n} in {mine!r}; the dimension that contributes it declares {theirs!r}"

    def r_responds() -> None:
        m = holder["m"]
        X = inputs(RESPONSE_SAMPLES, 4)
        if m.feature_space is not None:
            X = np.concatenate([X] + [P for _, P in _landmarks(m)])
        Y = m.predict(X)
        span = Y.max(axis=0) - Y.min(axis=0)
        flat = [f"{d} (spans {s:.3g})" for d, s in zip(m.dimension_names, span) if not s >= RESPONSE_MIN]
        assert not flat, (f"output(s) {flat} change by less than {RESPONSE_MIN:g} over the whole feature box "
                          f"({len(X)} points: random, corners, centre, face centres): the features cannot steer "
                          f"them to the precision a solve is judged at (SolveProblem's default tolerance); "
                          f"does the model read its inputs?")

    _run_rules(ctx, [("shapes", r_shapes), ("model-dimensions", r_dimensions), ("vectorised", r_vectorised),
                     ("determinism", r_determinism), ("bad-input", r_bad_input), ("jacobian", r_jacobian),
                     ("metadata", r_metadata), ("responds", r_responds)],
               always=("shapes",), stop_after=("shapes",))
