"""Build inverse problems from perceptual targets, and solve them by method name.

``build_problem({"hardness": 0.8, "roughness": 0.3})`` loads the named dimensions
(lazily, by name), the perception model that covers them, assembles the feature space
from the dimensions' features with the model's training-range bounds, pins the model
inputs no requested dimension contributes, and gathers the dimensions' physical
constraints. ``solve(...)`` then resolves ``method=`` through the solver table, like
``scipy.optimize.minimize(method=...)``.
"""

from __future__ import annotations

import inspect
from collections.abc import Iterable, Mapping
from typing import Any, Sequence, overload

import numpy as np

from ..checks import MAX_SEED, check_seed
from ..perception.dimensions import Constraint, PerceptionDimension, check_intensity
from ..errors import ModelError, ValidationError
from ..perception.features import FeatureSpace
from ..perception.models import CompositeModel, PerceptionModel
from ..plugins import registry
from .base import Solver
from .objective import SolveProblem
from .results import BatchSolveResult, SolveResult

#: the default solver: the paper's GA (short) followed by a Levenberg-Marquardt polish
DEFAULT_METHOD = "ga-polish"
_model_cache: dict[str, PerceptionModel] = {}


def load_dimension(name: str) -> PerceptionDimension:
    """Instantiate the dimension plugin ``name`` (lazy entry-point lookup)."""
    cls = registry("dimension").load(name)
    return cls() if isinstance(cls, type) else cls


def load_model(spec: str | PerceptionModel) -> PerceptionModel:
    """A model by plugin name (``"default"``), by ``.onnx`` path, or passed through."""
    if isinstance(spec, PerceptionModel):
        return spec
    if not isinstance(spec, str) or not spec:
        raise ValidationError(f"model must be a name, a .onnx path or a PerceptionModel, got {spec!r}",
                              field="model")
    if spec in _model_cache:
        return _model_cache[spec]
    if spec.endswith(".onnx"):
        model = registry("model").load("onnx")(spec)
    else:
        factory = registry("model").load(spec)
        model = factory()
    if not isinstance(model, PerceptionModel):
        raise ModelError(f"model plugin {spec!r} returned {type(model).__name__}, not a PerceptionModel")
    _model_cache[spec] = model
    return model


def _items(value: Any, field: str, what: str) -> tuple[Any, ...]:
    """The items of a list argument: a string, bytes, a non-iterable, or an object that is
    iterable by its type and not by its value (a 0-d numpy array) raise ValidationError."""
    if not isinstance(value, (str, bytes)) and isinstance(value, Iterable):
        try:
            return tuple(value)
        except TypeError:
            pass
    raise ValidationError(f"must be {what}, got {type(value).__name__} {value!r:.60}", field=field)


def _dimension_names(dimensions: Any) -> tuple[str, ...]:
    """``dimensions=`` as a tuple of names: a list or tuple, not one name (a string would
    be read as its letters) nor a number."""
    names = _items(dimensions, "dimensions", "a list of dimension names")
    for i, n in enumerate(names):   # a name is looked up in dicts: a list or an array is none
        if not isinstance(n, str) or not n:
            raise ValidationError(f"must be a dimension name, got {type(n).__name__} {n!r:.60}",
                                  field=f"dimensions[{i}]")
    return names


def _targets_array(targets: Any, dimensions: Sequence[str] | None) -> tuple[np.ndarray, tuple[str, ...]]:
    if isinstance(targets, Mapping):
        if not targets:
            raise ValidationError("no targets given", field="targets")
        if dimensions:   # the mapping's keys must be exactly these names (else they are)
            dims = _dimension_names(dimensions)
            extra = [k for k in targets if k not in dims]
            missing = [d for d in dims if d not in targets]
            if extra or missing:
                raise ValidationError(f"targets name {list(targets)} but dimensions are {list(dims)}",
                                      field="targets")
        else:
            dims = tuple(targets)
        row = []
        for d in dims:
            v = targets[d]
            # a plain float in 0..1 is what check_intensity returns for it (NaN fails both)
            row.append(v if type(v) is float and 0.0 <= v <= 1.0 else check_intensity(v, f"targets.{d}"))
        return np.array(row, float), dims
    if isinstance(targets, (str, bytes)):
        # a material's name is not a row of intensities (numpy would read "S7" as one
        # string element, and the message below would be about columns)
        raise ValidationError(f"targets must be intensities ({{dimension: 0..1}}), not the name {targets!r}; for a "
                              f"library material use load_library().get(name).intensities, or render(name)",
                              field="targets")
    if dimensions is None:
        raise ValidationError("array targets need dimensions=[...] naming their columns", field="dimensions")
    dims = _dimension_names(dimensions)
    from ..argcheck import number_array
    T = number_array(targets, "targets", ndim=(1, 2), finite=False)  # a string is named by its index
    return T, dims


def build_problem(targets: Mapping[str, float] | np.ndarray | Sequence[Any], *,
                  dimensions: Sequence[str] | None = None,
                  model: str | PerceptionModel | None = None,
                  penalty: str = "paper", tolerance: float = 0.01,
                  fixed: Mapping[str, float] | None = None,
                  penalty_weight: float = 1.0, data_support: bool = False,
                  extra_constraints: Sequence[Any] = ()) -> SolveProblem:
    """Assemble a :class:`~hapticsdk.solvers.SolveProblem`.

    Args:
        targets: ``{"hardness": 0.8, "roughness": 0.3}`` (one target), or an ``(m, k)``
            array (a batch) whose columns are ``dimensions``.
        dimensions: dimension names (default: the keys of ``targets``).
        model: model name, ``.onnx`` path, instance, or ``None`` for the dimensions'
            ``default_model`` (combined when they differ).
        penalty: ``"paper"`` (formula (6)) or ``"normalised"``.
        tolerance: success threshold on the sum of absolute intensity errors.
        fixed: model inputs to pin (physical units) instead of searching them.
        data_support: also keep the solution where the model's training data were, using
            the facts the model file carries (``constraint_context``, e.g. the recorded
            press-force range for hardness). Off by default, as in the paper: the inverse is
            not unique, and without it the solver may return feature combinations no
            recording had (see docs/solvers.md, "Data support").
        extra_constraints: further :class:`~hapticsdk.perception.dimensions.Constraint` objects on
            the model's features, e.g. what the mapped actuators can produce (the scene
            compiler's device-aware solving).
    """
    T, dims = _targets_array(targets, dimensions)
    if len(set(dims)) != len(dims):
        raise ValidationError(f"repeated dimension in {list(dims)}", field="dimensions")
    dim_objs = [load_dimension(d) for d in dims]
    if model is None:
        names: list[str] = []
        for d in dim_objs:
            if d.default_model not in names:
                names.append(d.default_model)
        parts = [load_model(n) for n in names]
        mdl = parts[0] if len(parts) == 1 else CompositeModel(parts)
    else:
        mdl = load_model(model)
    model_inputs = list(mdl.feature_names)
    space = FeatureSpace(())
    for d in dim_objs:
        space = space.union(d.feature_space())
    absent = [n for n in space.names if n not in model_inputs]
    if absent:
        raise ModelError(f"model {mdl.name!r} does not read features {absent} that dimensions "
                         f"{list(dims)} contribute; its inputs are {model_inputs}")
    if fixed is not None and not isinstance(fixed, Mapping):
        raise ValidationError(f"must be an object {{feature: value}}, got {type(fixed).__name__}", field="fixed")
    if not isinstance(data_support, (bool, np.bool_)):
        raise ValidationError(f"must be True or False, got {data_support!r:.60}", field="data_support")
    extra_constraints = _items(extra_constraints, "extra_constraints", "a list of Constraint objects")
    for i, c in enumerate(extra_constraints):
        if not isinstance(c, Constraint):
            raise ValidationError(f"must be a Constraint, got {type(c).__name__} {c!r:.60}",
                                  field=f"extra_constraints[{i}]")
    pinned = dict(fixed or {})
    for n in pinned:
        if n not in model_inputs:
            raise ValidationError(f"cannot fix {n!r}: not a model input {model_inputs}", field=f"fixed.{n}")
    searched = [n for n in model_inputs if n in space and n not in pinned]
    space = space.subset(searched)
    if mdl.feature_space is not None:
        from ..perception.features import same_unit
        for n in space.names:
            if n in mdl.feature_space and not same_unit(mdl.feature_space[n].unit, space[n].unit):
                raise ModelError(f"model {mdl.name!r} reads feature {n!r} in {mdl.feature_space[n].unit!r}, "
                                 f"but {space[n].owner or 'its dimension'} declares it in {space[n].unit!r}")
        space = space.with_bounds({n: (mdl.feature_space[n].lower, mdl.feature_space[n].upper)
                                   for n in searched if n in mdl.feature_space})
    defaults = dict(mdl.metadata.get("feature_defaults") or {})
    for n in model_inputs:
        if n in space or n in pinned:
            continue
        if n in defaults:
            pinned[n] = float(defaults[n])
        elif mdl.feature_space is not None and n in mdl.feature_space:
            f = mdl.feature_space[n]
            pinned[n] = 0.5 * (f.lower + f.upper)
        else:
            raise ModelError(f"model {mdl.name!r} input {n!r} is not searched and has no default value")
    # facts of the model's training data that constraints use (df of formula (5), ...)
    context = ({k: float(v) for k, v in (mdl.metadata.get("constraint_context") or {}).items()}
               if data_support else {})
    if mdl.metadata.get("df_hz") is not None:
        context["df_hz"] = float(mdl.metadata["df_hz"])
    constraints = []
    for d in dim_objs:
        constraints.extend(d.constraints(**context))
    # device-aware solving: what the mapped actuators can produce (PerceptionDimension.device_constraints)
    constraints.extend(extra_constraints)
    return SolveProblem(targets=T, dimensions=dims, model=mdl, space=space, fixed=pinned,
                        constraints=tuple(constraints), penalty=penalty, tolerance=tolerance,
                        penalty_weight=penalty_weight)


def get_solver(method: str = DEFAULT_METHOD, **options: Any) -> Solver:
    """The solver plugin registered as ``method``, configured with ``options``."""
    cls = registry("solver").load(method)
    return cls(**options)


@overload
def solve(targets: Mapping[str, float], *, method: str = ..., seed: int | None = ...,
          options: Mapping[str, Any] | None = ..., **build_kw: Any) -> SolveResult: ...
@overload
def solve(targets: Sequence[Sequence[float]], *, method: str = ..., seed: int | None = ...,
          options: Mapping[str, Any] | None = ..., **build_kw: Any) -> BatchSolveResult: ...
@overload
def solve(targets: Sequence[float], *, method: str = ..., seed: int | None = ...,
          options: Mapping[str, Any] | None = ..., **build_kw: Any) -> SolveResult: ...
@overload
def solve(targets: np.ndarray, *, method: str = ..., seed: int | None = ...,
          options: Mapping[str, Any] | None = ..., **build_kw: Any) -> SolveResult | BatchSolveResult: ...
def solve(targets: Mapping[str, float] | np.ndarray | Sequence[Any], *, method: str = DEFAULT_METHOD,
          seed: int | None = None, options: Mapping[str, Any] | None = None,
          **build_kw: Any) -> SolveResult | BatchSolveResult:
    """Find features whose predicted intensities meet ``targets``.

    One target (``{dimension: intensity}``, or a 1-D row with ``dimensions=[...]``) gives
    a :class:`~hapticsdk.solvers.SolveResult`; a batch (2-D rows, one target each, with
    ``dimensions=[...]``) gives a :class:`~hapticsdk.solvers.BatchSolveResult`, solved in
    one call. (A numpy array is typed as either: narrow it with ``isinstance``.)

    Args:
        targets: intensities in 0..1 per dimension.
        method: solver plugin name (``hapticsdk plugins`` lists them; ``"ga"``,
            ``"de"``, ``"de-scipy"``, ``"polish"``, ``"ga-polish"``, ``"amortised"``
            with ``hapticsdk-ga``).
        seed: random seed (``None``: fresh entropy).
        options: solver options (see each solver's ``default_options``).
        **build_kw: passed to :func:`build_problem` (``dimensions``, ``model``,
            ``penalty``, ``tolerance`` [intensity units], ``fixed``, ...).

    Returns:
        scipy-style result(s): ``x`` (features, physical units), ``x_dict``, ``fun``,
        ``success``, ``message``, ``nfev``, ``nit``, ``error`` (sum of absolute intensity
        errors), ``intensities``, ``constraint_violation``, ``time_s``, ``trace``, and
        ``model``: :meth:`~hapticsdk.perception.models.PerceptionModel.provenance` of the model the
        error is measured against (``data_generated``, ``statement``).

    >>> res = solve({"hardness": 0.8, "roughness": 0.3}, seed=1)   # doctest: +SKIP
    >>> res.success, res.error, res.x_dict["GS"]                      # doctest: +SKIP
    """
    if not (seed is None or (type(seed) is int and 0 <= seed <= MAX_SEED)):
        check_seed(seed)  # before any work: seed='abc' or -1 is bad input, not a solver failure
    if build_kw:
        unknown = sorted(set(build_kw) - _BUILD_ARGS)
        if unknown:   # build_problem would raise TypeError on the keyword
            raise ValidationError(f"unknown argument(s) {unknown}; solve takes method, seed, options and "
                                  f"build_problem's {sorted(_BUILD_ARGS)}", field=unknown[0])
    problem = _problem_for(targets, build_kw)
    res = _solver_for(method, options).solve(problem, seed=seed)
    # what the numbers are measured against: the model and its training data
    prov = problem.model.__dict__.get("_provenance")
    if prov is None:
        prov = problem.model.__dict__["_provenance"] = problem.model.provenance()
    if isinstance(res, dict):
        res["model"] = prov
    else:
        res.model = prov
    return res


#: problems built by :func:`solve`, per setup (dimensions, model, penalty, tolerance, fixed
#: values, ...): a later call with the same setup reuses the model, the feature space, the
#: constraints and the solvers' per-setup caches, and validates only its targets
_PROBLEMS: dict[tuple, SolveProblem] = {}
#: the keyword arguments :func:`solve` passes on to :func:`build_problem`
_BUILD_ARGS = frozenset(inspect.signature(build_problem).parameters) - {"targets"}
_SOLVERS: dict[tuple, Solver] = {}
_MAX_CACHED = 64
_PLAIN = frozenset((str, int, float, bool, type(None)))


def _hashable(v: Any) -> Any:
    if type(v) in _PLAIN:
        return v
    if type(v) is dict:
        return tuple(sorted((k, _hashable(x)) for k, x in v.items()))
    if isinstance(v, PerceptionModel):
        return ("model", id(v))        # the cached problem holds the model: the id stays unique
    if isinstance(v, Mapping):
        return tuple(sorted((k, _hashable(x)) for k, x in v.items()))
    if isinstance(v, (list, tuple)):
        return tuple(_hashable(x) for x in v)
    hash(v)
    return v


def _problem_for(targets: Any, build_kw: dict[str, Any]) -> SolveProblem:
    """``build_problem(targets, **build_kw)``, from a cached problem of the same setup when
    there is one (then only the targets are validated)."""
    mapping = type(targets) is dict or isinstance(targets, Mapping)
    def setup_key() -> tuple:
        # the plugins and models the setup resolves to are part of the key: a plugin
        # registered anew or a model reloaded gets a new problem
        models = (tuple(_model_cache), tuple(map(id, _model_cache.values())))
        if mapping and not build_kw:     # the common call: {dimension: intensity}, defaults
            dims = tuple(targets)
            return (True, dims, tuple(map(registry("dimension").load, dims)), models, ())
        dims = tuple(targets) if mapping and build_kw.get("dimensions") is None else \
            tuple(build_kw.get("dimensions") or ())
        plugins = tuple(registry("dimension").load(d) if isinstance(d, str) else d for d in dims)
        return (mapping, dims, plugins, models, _hashable(build_kw) if build_kw else ())

    try:
        key = setup_key()
        hash(key)       # a dimension given as a list or an array: no caching either
    except TypeError:   # an unhashable option value: no caching
        return build_problem(targets, **build_kw)
    except Exception:   # an unknown plugin etc.: build_problem raises the proper error
        return build_problem(targets, **build_kw)
    template = _PROBLEMS.get(key)
    if template is None:
        problem = build_problem(targets, **build_kw)
        if len(_PROBLEMS) >= _MAX_CACHED:
            _PROBLEMS.clear()
        _PROBLEMS[setup_key()] = problem   # after building: the models it loaded are in the key
        return problem
    T, dims = _targets_array(targets, build_kw.get("dimensions"))
    if dims != template.dimensions:   # pragma: no cover - the key holds the dimensions
        return build_problem(targets, **build_kw)
    # a mapping's values were checked one by one (check_intensity: finite, in 0..1)
    return template.with_targets(T, validate=not mapping)


def _solver_for(method: str, options: Mapping[str, Any] | None) -> Solver:
    """``get_solver(method, **options)``, reusing an instance for the same settings
    (solvers keep no state between calls besides their options)."""
    if options is not None and not isinstance(options, Mapping):
        raise ValidationError(f"must be an object of solver options, got {type(options).__name__}",
                              field="options")
    opts = dict(options or {})
    for k in opts:   # they become keyword arguments: get_solver(method, **opts)
        if not isinstance(k, str) or not k:
            raise ValidationError(f"option names must be non-empty strings, got {k!r:.60}", field="options")
    try:
        key = (method, registry("solver").load(method), _hashable(opts))
        hash(key)
    except TypeError:
        return get_solver(method, **opts)
    except Exception:   # unknown method: get_solver raises the proper error
        return get_solver(method, **opts)
    s = _SOLVERS.get(key)
    if s is None:
        s = get_solver(method, **opts)
        if len(_SOLVERS) >= _MAX_CACHED:
            _SOLVERS.clear()
        _SOLVERS[key] = s
    return s
