"""Compile a scene into a render plan: solve every material, leave out what matters
little, map channel roles to actuators.

:func:`compile_scene` turns a :class:`~hapticsdk.scene.Scene` into a
:class:`~hapticsdk.plan.RenderPlan`:

1. every material's target intensities are solved for features with every dimension it
   names (:func:`hapticsdk.solvers.problems.solve`, materials with the same dimensions in one
   batch);
2. the importance model (``settings.importance.model``, default ``paper``;
   :mod:`hapticsdk.compiler.importance`) predicts the realism loss of leaving each
   dimension out, judged on the material (its recorded features and those solved onto
   the target where the library has them, else the solved features;
   :mod:`hapticsdk.compiler.leave_out`) with the model's own uncertainty; a dimension
   whose whole loss interval is below the threshold is dropped (and, if the model says
   so, replaced by something simpler, e.g. a constant 1 N force for hardness);
3. materials that lost a dimension are solved again with only the kept ones, so that
   features no kept dimension reads are pinned at the model's defaults and left out;
4. each kept dimension's renderer is built once to learn the channel roles it commands;
   each role is mapped to an actuator (the scene's ``devices`` or the dimension's
   ``default_actuators``). Actuators are only looked up in the entry-point table here:
   they are imported and opened by :func:`hapticsdk.runtime.render.render_plan`.

Only the plugins a material of the scene names are imported.
"""

from __future__ import annotations

import copy
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..calibration.selection import select_calibrations
from ..perception.dimensions import RoleSpec, check_intensity
from ..errors import PluginError, ValidationError
from ..plan import FALLBACK_SENSOR, DroppedDimension, MaterialPlan, RenderPlan
from ..plugin_api import check_plugin_api
from ..scene import DeviceSpec, Scene

@dataclass
class _Mat:
    name: str
    targets: dict[str, float]
    source: str
    objects: list[str]
    #: the library's recorded features of the material (None: none, or intensities changed)
    recorded: dict[str, float] | None = None


def _resolve_materials(scene: Scene) -> list[_Mat]:
    """Material name -> targets, in scene order; the library is read only if named."""
    library = None
    with_plugins = False
    mats: dict[str, _Mat] = {}
    restrict = scene.settings.get("dimensions")
    for i, obj in enumerate(scene.objects):
        where = f"scene.objects[{i}]"
        if isinstance(obj.material, str):
            if library is None:
                from ..perception.materials import load_library
                library = load_library()
            try:
                m = library.get(obj.material)
            except (KeyError, LookupError, ValidationError):
                # not in the shipped library: only now ask the plugins (this imports
                # every plugin's hook module, so library materials never pay for it)
                if not with_plugins:
                    library = load_library(with_plugins=True)
                    with_plugins = True
                try:
                    m = library.get(obj.material)
                except (KeyError, LookupError, ValidationError) as exc2:
                    # the library's own message already says "unknown material ...; known: ..."
                    raise ValidationError(getattr(exc2, "reason", str(exc2)),
                                          field=f"{where}.material") from None
            name, source = m.name, "library"
            targets = {k: float(v) for k, v in m.intensities.items()}
            recorded = {k: float(v) for k, v in m.features.items()} if m.features else None
        elif isinstance(obj.material, Mapping):
            ints = obj.material.get("intensities")
            if not isinstance(ints, Mapping) or not ints:
                raise ValidationError("a material given inline needs 'intensities'",
                                      field=f"{where}.material.intensities")
            name = str(obj.material.get("name") or obj.name)
            source = "intensities"
            targets = dict(ints)
            recorded = None
        else:
            raise ValidationError(f"material must be a name or an object, got {obj.material!r}",
                                  field=f"{where}.material")
        targets.update(obj.intensities)
        if obj.intensities and source == "library":
            recorded = None   # the recorded features describe the library's intensities, not these
            name = f"{name}+" + "+".join(f"{k}={float(v):g}" for k, v in sorted(obj.intensities.items()))
        dims = obj.dimensions if obj.dimensions is not None else restrict
        if dims is not None:
            unknown = [d for d in dims if d not in targets]
            if unknown:
                raise ValidationError(f"dimensions {unknown} have no target intensity in material "
                                      f"{name!r} (it has {sorted(targets)})", field=f"{where}.dimensions")
            targets = {d: targets[d] for d in targets if d in dims}
        targets = {d: check_intensity(v, f"{where}.intensities.{d}") for d, v in targets.items()}
        if not targets:
            raise ValidationError("the material has no dimension to render", field=where)
        if name in mats:
            if mats[name].targets != targets:
                raise ValidationError(f"material name {name!r} is used with different intensities",
                                      field=f"{where}.material")
            mats[name].objects.append(obj.name)
        else:
            mats[name] = _Mat(name, targets, source, [obj.name], recorded)
    return list(mats.values())


def _plugin_entry(kind: str, name: str, stage: str) -> dict[str, Any]:
    from ..plugins import registry
    try:
        info: dict[str, Any] = registry(kind).info(name).to_dict()
    except PluginError:
        from .._version import __version__
        from .importance import BUILTIN
        core = kind == "importance" and name in BUILTIN
        info = {"kind": kind, "name": name, "distribution": "hapticsdk" if core else None,
                "version": __version__ if core else None}
    info.pop("value", None)
    info["stage"] = stage
    return info


def _role_options(scene: Scene, dim: Any) -> dict[str, dict[str, Any]]:
    """Options of the actuators on the roles whose calibration ``dim`` declares (for their
    serial numbers): the scene's, over the user's device configuration."""
    from ..calibration.selection import declared_calibrations
    from ..devices.device_options import trusted_options
    out: dict[str, dict[str, Any]] = {}
    for _, role in declared_calibrations(dim).values():
        spec = scene.devices.get(role)
        name = spec.actuator if spec is not None else dim.default_actuators.get(role)
        if name:
            out[role] = {**trusted_options(name), **(dict(spec.options) if spec is not None else {})}
    return out


def _capabilities(scene: Scene, dim: Any) -> tuple[dict[str, Any], dict[str, str]]:
    """What the actuators on ``dim``'s roles can produce (role -> DriveCapability), asked
    of their classes with the scene's (non-privileged) options: nothing is created,
    opened or loaded; and role -> why none is known."""
    from ..devices.device_options import privileged_options, trusted_options
    from ..plugins import registry
    caps: dict[str, Any] = {}
    notes: dict[str, str] = {}
    roles = list(getattr(dim, "roles", {}) or {}) or list(dim.default_actuators)
    for role in roles:
        spec = scene.devices.get(role)
        name = spec.actuator if spec is not None else dim.default_actuators.get(role)
        if not name or name not in registry("actuator"):
            continue
        cls = registry("actuator").load(name)
        priv = set(privileged_options(cls))
        opts = {k: v for k, v in {**trusted_options(name), **(dict(spec.options) if spec is not None else {})}.items()
                if k not in priv}
        try:
            cap = cls.capability_for(opts) if hasattr(cls, "capability_for") else None
        except Exception as exc:   # options it cannot judge without the application's
            notes[role] = f"{name}: capability unknown at compile time ({type(exc).__name__}: {exc})"
            continue
        if cap is not None:
            caps[role] = cap
    return caps, notes


def _renderer_options(d: str, dim: Any, scene: Scene, ropts: Mapping[str, Any],
                      caps: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """The options ``d``'s renderer gets, and the calibration records: the scene's
    ``renderer_options`` win, then what the mapped actuator itself supplies (its own drive
    table, :meth:`PerceptionDimension.capability_options`), then saved calibrations."""
    given = dict(ropts.get(d, {}))
    from ..argcheck import refuse_file_options
    refuse_file_options(dim, given, f"scene.settings.renderer_options.{d}")
    cal_opts, recs = select_calibrations(d, dim, renderer_options=given, role_options=_role_options(scene, dim))
    cap_opts = dim.capability_options(caps) if hasattr(dim, "capability_options") else {}
    merged = {**given, **cal_opts}
    for k, v in cap_opts.items():
        if k not in given:
            merged[k] = v
            for rec in recs.values():
                if rec.get("kind") and k in ("table", "calibration"):
                    rec["superseded_by"] = "the actuator's own drive table (device capability)"
    return merged, recs


def _load_dimension(name: str, field: str) -> Any:
    from ..plugins import registry
    reg = registry("dimension")
    if name not in reg:
        from ..plugins import install_hint
        raise ValidationError(f"no dimension plugin named {name!r}; installed: {reg.names()}"
                              f"{install_hint('dimension', name)}", field=field)
    cls = reg.load(name)
    check_plugin_api(cls, name=name)
    return cls() if isinstance(cls, type) else cls


def _solve_groups(groups: dict[tuple[str, ...], list[_Mat]], settings: Mapping[str, Any],
                  device: Mapping[str, Sequence[Any]] | None = None) -> dict[str, Any]:
    """Solve each group of materials sharing a dimension tuple in one batch; ``device``:
    dimension -> constraints of what its mapped actuators can produce."""
    from ..solvers.problems import solve
    s = settings["solver"]
    out: dict[str, Any] = {}
    for dims, mats in groups.items():
        if not dims:
            continue
        T = np.array([[m.targets[d] for d in dims] for m in mats], dtype=float)
        extra = tuple(c for d in dims for c in (device or {}).get(d, ()))
        res = solve(T, dimensions=list(dims), model=settings.get("model"), method=s["method"],
                    seed=s["seed"], options=dict(s.get("options") or {}),
                    penalty=s.get("penalty", "paper"), tolerance=s.get("tolerance", 0.01),
                    data_support=bool(s.get("data_support", True)),
                    **({"extra_constraints": extra} if extra else {}))
        results = [res] if isinstance(res, dict) else list(res)  # SolveResult is a dict
        prov = res.get("model") if isinstance(res, dict) else getattr(res, "model", None)
        for m, r in zip(mats, results):
            if prov is not None:
                r["model"] = prov
            out[m.name] = r
    return out


def _pin_at_first_solve(second: dict[str, Any], first: Mapping[str, Any], mats: Sequence[_Mat],
                        drops: Mapping[str, list[Any]], dim_objs: Mapping[str, Any], settings: Mapping[str, Any],
                        device: Mapping[str, Sequence[Any]]) -> None:
    """A material whose kept dimensions miss their targets with the left-out features
    pinned at the model's defaults (e.g. a perception model whose hardness at the stiff
    end depends on the texture features) is solved again, alone, with those features
    pinned at the values of the full solve, which reached every target. ``second`` is
    updated in place; the result's ``pinned_from`` says which pinning was used."""
    from ..solvers.problems import solve
    s = settings["solver"]
    for m in mats:
        r = second.get(m.name)
        if r is None or not drops[m.name] or r.success or not first[m.name].success:
            continue
        gone = {e.dimension for e in drops[m.name]}
        kept = [d for d in m.targets if d not in gone]
        read = {f.name for d in kept for f in dim_objs[d].features}
        fixed = {k: float(v) for k, v in first[m.name].x_dict.items() if k not in read}
        extra = tuple(c for d in kept for c in (device or {}).get(d, ()))
        r2 = solve({d: m.targets[d] for d in kept}, model=settings.get("model"), method=s["method"],
                   seed=s["seed"], options=dict(s.get("options") or {}), penalty=s.get("penalty", "paper"),
                   tolerance=s.get("tolerance", 0.01), data_support=bool(s.get("data_support", True)),
                   fixed=fixed, **({"extra_constraints": extra} if extra else {}))
        if r2.success:
            if r.get("model") is not None:
                r2["model"] = r["model"]
            r2["pinned_from"] = "full solve"
            second[m.name] = r2


def _basis_words(e: Any) -> str:
    """Which feature points a loss estimate judged, in words."""
    from .importance import basis_words
    return ("highest median " if len(e.basis) > 1 else "median ") + basis_words(e.basis, e.n_solutions)


def _solve_summary(r: Any, dims: Sequence[str], model_names: Sequence[str], seed: Any) -> dict[str, Any]:
    """The final solve's result (``SolveResult.to_json()``) plus the models and seed."""
    out = json.loads(json.dumps(r.to_json(), default=float))
    out["models"] = list(model_names)
    out["seed"] = seed
    out["dimensions"] = list(dims)
    if r.get("pinned_from"):
        out["pinned_from"] = r["pinned_from"]
    return out


#: what the importance model's replacement renderers command (``replacement.renderer`` -> spec)
_REPLACEMENT_ROLES: dict[str, RoleSpec] = {
    "constant-force": RoleSpec("force", {"force_n": "N"}, "constant normal force in contact")}


def _check_satisfiable(dims: Sequence[str], settings: Mapping[str, Any]) -> None:
    """Refuse dimensions whose constraints cannot hold anywhere in the searched feature
    box (a 16384-point Halton design, the one the solution sets use): a plugin error at
    compile time, not a material that renders something the constraints forbid."""
    from ..solvers.problems import build_problem
    from .solution_set import _design
    s = settings["solver"]
    problem = build_problem({d: 0.5 for d in dims}, model=settings.get("model"),
                            penalty=s.get("penalty", "paper"), tolerance=s.get("tolerance", 0.01),
                            data_support=bool(s.get("data_support", True)))
    if not problem.constraints:
        return
    U, _, feasible = _design(problem, 16384)
    if feasible.any():
        return
    G = problem.full_inputs(problem.space.from_unit(U))
    cols = problem.columns(G)
    never = [c.name for c in problem.constraints if not (np.asarray(c.violation(cols)) <= 0.0).any()]
    what = (f"constraint(s) {never} hold nowhere" if never else
            f"the constraints {[c.name for c in problem.constraints]} never hold together")
    raise PluginError(f"dimensions {list(dims)}: {what} in the searched feature bounds (16384-point design); "
                      f"no material can satisfy them, so nothing is rendered", kind="dimension",
                      plugin=",".join(dims))


def _device_summary(r: Any, targets: Mapping[str, float], kept: Sequence[str], caps: Mapping[str, Any],
                    notes: Mapping[str, Mapping[str, str]], device: Mapping[str, Sequence[Any]],
                    tolerance: float = 0.01) -> dict[str, Any]:
    """What the mapped actuators can produce and what remains of the target because of it:
    per kept dimension the predicted intensity of the features that will be rendered
    (solved within the device constraints) against the target, and which device
    constraints bind at the answer: a constraint binds when the answer lies within
    ``binding_rtol`` of its bound (relative to the bound; the solver's intensity tolerance,
    the accuracy it stops at), or when the target is missed by more than that tolerance
    and it is the dimension's device constraint with the least relative slack (what held
    the answer back). Both figures are in the result."""
    row = {k: float(v) for k, v in r.x_dict.items()}
    pred = dict(r.intensities)
    rtol = float(tolerance)
    active: list[str] = []
    described: list[dict[str, Any]] = []
    for d in kept:
        nearest: tuple[float, str] | None = None
        for c in device.get(d, ()):
            desc = c.describe()
            try:
                b, v = c.bound_and_value_one(row)
                slack = (v - b) / max(abs(b), abs(v), 1e-12)   # relative to the larger side
                desc.update(bound=b, value=v, relative_slack=slack)
                if slack <= rtol and c.name not in active:
                    active.append(c.name)
                if nearest is None or slack < nearest[0]:
                    nearest = (slack, c.name)
            except Exception:   # a feature of the constraint is not in this solve
                pass
            described.append(desc)
        missed = d in pred and abs(float(targets[d]) - float(pred[d])) > rtol
        if missed and nearest is not None and nearest[1] not in active:
            active.append(nearest[1])
    return {"capabilities": {d: {role: cap.summary() for role, cap in caps.get(d, {}).items()} for d in kept},
            "notes": {d: dict(notes.get(d, {})) for d in kept if notes.get(d)},
            "constraints": described, "binding": active, "binding_rtol": rtol,
            "predicted": {d: float(pred[d]) for d in kept if d in pred},
            "residual": {d: float(targets[d] - pred[d]) for d in kept if d in pred}}


def _check_commands(d: str, rend: Any, dim: Any) -> None:
    """One tick of the new renderer in contact (1 mm, sliding at 20 mm/s): every command
    must be on a role it lists and set only the fields that role declares (typed roles of
    :func:`hapticsdk.perception.dimensions.declared_roles`). Cheap: the renderer is built anyway."""
    from ..perception.dimensions import TickInput, declared_roles, undeclared_fields
    specs = declared_roles(dim)
    if not specs:
        return
    inp = TickInput(t=0.0, dt=1e-3, penetration_mm=1.0, velocity_mm_s=np.array([20.0, 0.0, 0.0]), in_contact=True)
    try:
        cmds = rend.tick(inp)
    except Exception:   # noqa: BLE001 - the render path reports a failing tick, naming it
        return
    for c in cmds or ():
        spec: Any = specs.get(getattr(c, "role", ""))
        extra = undeclared_fields(c, spec) if spec is not None else []
        if extra:
            raise PluginError(f"dimension {d!r}: its renderer sets {extra} on role {c.role!r}, which is declared "
                              f"as {spec.describe()}: the actuator on that role would receive a field it does "
                              f"not act on", plugin=d, kind="dimension")


def _role_spec(owner: str, dname: str, role: str, dim_objs: Mapping[str, Any], imp_model: Any) -> RoleSpec | None:
    """The declared spec of ``role`` for a dimension or a replacement (None: undeclared)."""
    if owner.startswith("replacement:"):
        rep = imp_model.replacement(dname) if imp_model is not None else None
        return _REPLACEMENT_ROLES.get(rep["renderer"]) if rep else None
    from ..perception.dimensions import declared_roles
    return declared_roles(dim_objs[dname]).get(role)


def _check_role(owner: str, role: str, rspec: RoleSpec | None, actuator: str,
                contracts: dict[str, dict[str, Any]]) -> None:
    """Refuse an actuator that cannot carry what ``owner`` commands on ``role``; record
    the contract for the plan."""
    from ..perception.features import same_unit
    from ..plugins import registry
    cls = registry("actuator").load(actuator)
    check_plugin_api(cls, name=actuator)
    channel = getattr(cls, "channel", "other")
    accepts = cls.accepted_fields() if hasattr(cls, "accepted_fields") else {}
    entry = contracts.setdefault(role, {"actuator": actuator, "actuator_channel": channel,
                                        "accepts": dict(accepts), "commanded_by": {}})
    if rspec is None:   # a plugin built for plugin API 1.0: nothing declared to check
        entry["commanded_by"][owner] = None
        return
    entry["commanded_by"][owner] = rspec.to_dict()
    who = f"dimension {owner!r}" if not owner.startswith("replacement:") else f"the {owner.split(':', 1)[1]} replacement"
    problems = []
    if rspec.channel != channel:
        problems.append(f"it serves a {channel} channel")
    for fname, unit in rspec.fields.items():
        if fname not in accepts:
            problems.append(f"it does not act on {fname}")
        elif not same_unit(accepts[fname], unit):
            problems.append(f"it takes {fname} in {accepts[fname]!r}, not {unit!r}")
    if problems:
        acc = ", ".join(f"{k} {u}" for k, u in accepts.items()) or "nothing"
        raise ValidationError(f"{who} commands role {role!r} as {rspec.describe()}, but actuator {actuator!r} "
                              f"cannot carry it: {'; '.join(problems)} (it accepts {acc}); map the role to "
                              f"an actuator of that kind", field=f"scene.devices.{role}")


def _check_solver_options(settings: Mapping[str, Any]) -> None:
    """Refuse a scene's solver options that name a file or folder (the solver class's
    ``privileged_options``, e.g. ``amortised``'s ``cache_dir``, where tables are read and
    written): a scene chooses no file; code passes them to ``hs.solve``. An unknown
    method is left to the solve, which names it."""
    from ..plugins import registry
    opts = settings["solver"].get("options") or {}
    method = settings["solver"].get("method")
    if not opts or not isinstance(method, str) or method not in registry("solver"):
        return
    priv = getattr(registry("solver").load(method), "privileged_options", None) or {}
    for key in sorted(k for k in opts if k in priv):
        from ..devices.device_options import PrivilegedOptionError
        raise PrivilegedOptionError(
            f"option {key!r} of solver {method!r} is privileged ({priv[key]}); a scene may not set it (a "
            f"file you open must not choose files to read or write): pass it from the application's code "
            f"(hs.solve(..., method={method!r}, options={{{key!r}: ...}}))",
            field=f"scene.settings.solver.options.{key}", option=key)


def compile_scene(scene: Scene | Mapping[str, Any] | str | Path) -> RenderPlan:
    """Compile a scene (object, dict, or path of a JSON file) into a render plan."""
    from ..plugins import registry
    if isinstance(scene, (str, Path)):
        scene = Scene.load(scene)
    elif isinstance(scene, Mapping):
        scene = Scene.from_dict(scene)
    elif not isinstance(scene, Scene):
        raise ValidationError(f"must be a Scene, its dict or a scene file's path, got {type(scene).__name__} "
                              f"{scene!r:.60}", field="scene")
    settings = scene.settings
    _check_solver_options(settings)
    mats = _resolve_materials(scene)

    # dimensions named by any material: imported (they are used)
    dim_objs: dict[str, Any] = {}
    for m in mats:
        for d in m.targets:
            if d not in dim_objs:
                dim_objs[d] = _load_dimension(d, f"materials.{m.name}.intensities.{d}")

    # 1. solve with every named dimension
    groups: dict[tuple[str, ...], list[_Mat]] = {}
    for m in mats:
        groups.setdefault(tuple(m.targets), []).append(m)
    for dims in groups:
        _check_satisfiable(dims, settings)
    # device-aware solving: what the actuators mapped to each dimension can produce
    ropts = settings.get("renderer_options") or {}
    caps: dict[str, dict[str, Any]] = {}
    cap_notes: dict[str, dict[str, str]] = {}
    render_opts: dict[str, dict[str, Any]] = {}
    render_cal: dict[str, dict[str, dict[str, Any]]] = {}
    device: dict[str, list[Any]] = {}
    for d, dobj in dim_objs.items():
        caps[d], cap_notes[d] = _capabilities(scene, dobj)
        render_opts[d], render_cal[d] = _renderer_options(d, dobj, scene, ropts, caps[d])
        device[d] = list(dobj.device_constraints(caps[d], **render_opts[d])) if caps[d] else []
    first = _solve_groups(groups, settings, device)

    # 2. importance: judged on the material (its recorded features, and those solved onto
    #    the target; else the solved features), with the importance model's own uncertainty
    #    (hapticsdk.compiler.importance.judge_material): no solver seed or search design enters
    imp_cfg = settings["importance"]
    imp_model: Any = None
    drops: dict[str, list[Any]] = {m.name: [] for m in mats}
    estimates: dict[str, dict[str, Any]] = {m.name: {} for m in mats}
    imp_features: dict[str, dict[str, float]] = {m.name: {} for m in mats}
    if imp_cfg.get("enabled", True):
        from ..solvers.problems import build_problem
        from .importance import decide_from_estimates, judge_material, load_importance
        from .leave_out import material_points
        imp_model = load_importance(imp_cfg.get("model", "paper"))
        check_plugin_api(imp_model, name=imp_model.name)
        s_cfg = settings["solver"]
        for dims, gm in groups.items():
            if len(dims) < 2 or not any(imp_model.judges(d, list(dims)) for d in dims):
                continue
            needed: set[str] = set()
            for d in dims:
                if imp_model.judges(d, list(dims)):
                    needed |= set(imp_model.features_needed(d, list(dims)))
            problem = build_problem(np.array([[m.targets[d] for d in dims] for m in gm]), dimensions=list(dims),
                                    model=settings.get("model"), penalty=s_cfg.get("penalty", "paper"),
                                    tolerance=s_cfg.get("tolerance", 0.01),
                                    data_support=bool(s_cfg.get("data_support", True)),
                                    extra_constraints=tuple(c for d in dims for c in device.get(d, ())))
            ests = []
            for i, m in enumerate(gm):
                solved = {k: float(v) for k, v in first[m.name].x_dict.items()}
                pts = material_points(problem, i, m.recorded, solved)
                ests.append(judge_material(imp_model, dims, pts, imp_cfg.get("thresholds") or {},
                                           float(imp_cfg["threshold_percent"])))
            for m, est, dl in zip(gm, ests, decide_from_estimates(imp_model, dims, ests)):
                drops[m.name] = dl
                estimates[m.name] = {d: e.to_dict() for d, e in est.items()}
                imp_features[m.name] = {k: float(first[m.name].x_dict[k]) for k in sorted(needed)
                                        if k in first[m.name].x_dict}

    # 3. solve again without the dropped dimensions
    regroup: dict[tuple[str, ...], list[_Mat]] = {}
    for m in mats:
        if drops[m.name]:
            gone = {e.dimension for e in drops[m.name]}
            regroup.setdefault(tuple(d for d in m.targets if d not in gone), []).append(m)
    second = _solve_groups(regroup, settings, device)
    _pin_at_first_solve(second, first, mats, drops, dim_objs, settings, device)
    final = {**first, **second}

    # 4. renderers' roles and actuators
    model_names = [settings["model"]] if settings.get("model") else None
    ropts = settings.get("renderer_options") or {}
    used_dims: set[str] = set()
    used_actuators: set[str] = set()
    plans: dict[str, MaterialPlan] = {}
    for m in mats:
        gone_dims = [e.dimension for e in drops[m.name]]
        kept = [d for d in m.targets if d not in gone_dims]
        r = final[m.name]
        read = {f.name for d in kept for f in dim_objs[d].features}
        feats = {k: float(v) for k, v in r.x_dict.items() if k in read}
        pinned = {k: float(v) for k, v in r.x_dict.items() if k not in read}
        roles: dict[str, list[str]] = {}
        cal_records: dict[str, dict[str, Any]] = {}
        for d in kept:
            cal_records.update(render_cal[d])
            try:
                from ..argcheck import call_with_options  # an unknown option is named, not a TypeError
                rend = call_with_options(dim_objs[d].renderer, dict(feats), options=render_opts[d],
                                         field=f"scene.settings.renderer_options.{d}")
            except ValidationError:
                raise
            except Exception as exc:
                raise PluginError(f"dimension {d!r} could not build a renderer for material "
                                  f"{m.name!r}: {type(exc).__name__}: {exc}", plugin=d,
                                  kind="dimension") from exc
            declared = dict(getattr(dim_objs[d], "roles", {}) or {})
            undeclared = [ro for ro in rend.roles if declared and ro not in declared]
            if undeclared:
                raise PluginError(f"dimension {d!r}: its renderer commands role(s) {undeclared} that the "
                                  f"dimension does not declare in `roles` (declared: {sorted(declared)})",
                                  plugin=d, kind="dimension")
            _check_commands(d, rend, dim_objs[d])
            roles[d] = list(rend.roles)
        dropped: list[DroppedDimension] = []
        for e in drops[m.name]:
            d = e.dimension
            rep = imp_model.replacement(d) if imp_model is not None else None
            what = "replaced by " + rep["renderer"] if rep else "not rendered"
            flags = ""
            if e.extrapolated_fraction > 0:
                flags += (f"; {100 * e.extrapolated_fraction:.0f} % of the draws give a negative loss "
                          f"(regression extrapolating; counted as 0 %)")
            dropped.append(DroppedDimension(
                dimension=d, predicted_loss_percent=e.median_percent, threshold_percent=e.threshold_percent,
                importance_model=imp_model.name if imp_model else None, replacement=rep,
                loss_interval_percent=[e.low_percent, e.high_percent], confidence=round(e.confidence, 6),
                n_solutions=e.n_solutions, extrapolated_fraction=e.extrapolated_fraction,
                reason=(f"predicted realism loss {e.median_percent:.2f} % ({_basis_words(e)}; 80 % interval "
                        f"{e.low_percent:.1f}-{e.high_percent:.1f} %, wholly below the threshold "
                        f"{e.threshold_percent:g} %; importance model {imp_model.name!r}, {e.method}){flags}; "
                        f"{what}")))
            if rep:
                roles[f"replacement:{d}"] = [rep["role"]]
        actuators: dict[str, str] = {}
        options: dict[str, dict[str, Any]] = {}
        contracts: dict[str, dict[str, Any]] = {}
        for owner, rl in roles.items():
            dname = owner.split(":", 1)[1] if owner.startswith("replacement:") else owner
            for role in rl:
                rspec = _role_spec(owner, dname, role, dim_objs, imp_model)
                if role in actuators:
                    _check_role(owner, role, rspec, actuators[role], contracts)
                    continue
                if role in scene.devices:
                    spec = scene.devices[role]
                elif role in dim_objs[dname].default_actuators:
                    spec = DeviceSpec(dim_objs[dname].default_actuators[role])
                else:
                    raise ValidationError(f"no actuator for role {role!r} of dimension {dname!r}: "
                                          f"the scene's devices name none and the dimension has no "
                                          f"default", field=f"scene.devices.{role}")
                if spec.actuator not in registry("actuator"):
                    from ..plugins import install_hint
                    raise ValidationError(f"no actuator plugin named {spec.actuator!r}; installed: "
                                          f"{registry('actuator').names()}"
                                          f"{install_hint('actuator', spec.actuator)}",
                                          field=f"scene.devices.{role}")
                if spec.options:  # refuse privileged options now, not at render time
                    from ..devices.device_options import check_data_options
                    check_data_options(registry("actuator").load(spec.actuator), spec.actuator, role,
                                       spec.options, field=f"scene.devices.{role}.options")
                actuators[role] = spec.actuator
                _check_role(owner, role, rspec, spec.actuator, contracts)
                options[role] = dict(spec.options)
        used_dims |= set(kept) | set(gone_dims)
        used_actuators |= set(actuators.values())
        dists = {d: registry("dimension").distribution_of(d) for d in list(kept) + gone_dims}
        models = model_names or sorted({dim_objs[d].default_model for d in (kept or m.targets)})
        plans[m.name] = MaterialPlan(
            name=m.name, targets=dict(m.targets), dimensions=kept, dropped=dropped,
            features=feats, pinned_features=pinned, importance_features=imp_features[m.name],
            importance=estimates[m.name], role_contracts=contracts, calibrations=cal_records,
            actuators=actuators, actuator_options=options, roles=roles,
            dimension_distributions=dists,
            solve=_solve_summary(r, kept, models, settings["solver"]["seed"]),
            device=_device_summary(r, m.targets, kept, caps, cap_notes, device,
                                   tolerance=float(settings["solver"].get("tolerance", 0.01))),
            source=m.source, objects=list(m.objects))

    # plugins used / never imported
    plugins: list[dict[str, Any]] = [_plugin_entry("dimension", d, "compile") for d in sorted(used_dims)]
    all_models = model_names or sorted({dim_objs[d].default_model for d in used_dims})
    plugins += [_plugin_entry("model", n, "compile") for n in all_models]
    plugins.append(_plugin_entry("solver", settings["solver"]["method"], "compile"))
    if imp_model is not None:
        plugins.append(_plugin_entry("importance", imp_model.name, "compile"))
    plugins += [_plugin_entry("actuator", a, "render") for a in sorted(used_actuators)]
    if FALLBACK_SENSOR not in used_actuators:
        e = _plugin_entry("actuator", FALLBACK_SENSOR, "render")
        e["reason"] = "sensing device when no actuator of the rendered material senses"
        plugins.append(e)
    unused: list[dict[str, Any]] = []
    for kind, used in (("dimension", used_dims), ("actuator", used_actuators | {FALLBACK_SENSOR})):
        for n in registry(kind).names():
            if n not in used:
                e = _plugin_entry(kind, n, "unused")
                e.pop("stage", None)
                e["reason"] = f"no material of the scene uses this {kind}; not imported"
                unused.append(e)
    return RenderPlan(scene=scene.name, materials=plans, settings=copy.deepcopy(settings),
                      plugins=plugins, unused_plugins=unused)
