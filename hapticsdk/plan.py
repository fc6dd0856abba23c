"""Render plans: what a compiled scene renders, serialisable and renderable later.

A :class:`RenderPlan` is the output of :func:`hapticsdk.compiler.compile_scene`. For each
material it records the perception dimensions kept, those left out and why (with the
importance model's predicted realism loss), the solved features (physical units), the
features pinned out of the solve, the actuator chosen for every channel role, and the
solve's outcome. It is plain data: :meth:`RenderPlan.to_dict` gives JSON that
``schemas/plan.schema.json`` validates, and :func:`hapticsdk.runtime.render.render_plan`
renders it without solving again.

The plan also carries :data:`~hapticsdk.plugin_api.PLUGIN_API_VERSION`, the version of
the plugin interface (base classes, entry-point groups, hook specifications) it was
compiled against.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

from .errors import ValidationError
from .plugin_api import PLUGIN_API_VERSION, _parse_version

#: Version of the plan file format (``plan_version`` key).
PLAN_VERSION = 1


#: the sensing device used when no actuator of a material senses (the runtime opens it)
FALLBACK_SENSOR = "probe-virtual"


def _float(value: Any, field: str) -> float:
    """``float(value)``; an int beyond the float range (JSON's ``1`` and 400 zeros, which
    the schema takes as a number) raises :class:`ValidationError` naming ``field``."""
    try:
        return float(value)
    except OverflowError:
        raise ValidationError(f"must be finite, got {value!r:.40}", field=field) from None


@dataclass
class DroppedDimension:
    """A dimension a material's intensities name but the plan does not render.

    Attributes:
        dimension: its name.
        reason: why, in words.
        predicted_loss_percent: predicted loss of realism (% of the realism with every
            dimension rendered) when it is left out; ``None`` when not predicted.
        threshold_percent: the scene's threshold it was compared with.
        importance_model: name of the importance model that decided.
        replacement: what renders in its place (``{"renderer": "constant-force",
            "role": "force", "force_n": 1.0}``), or ``None``.
        loss_interval_percent: 80 % interval (10-90 %) of the predicted loss from the
            importance model's own uncertainty, spanning every feature point judged (%);
            the dimension is dropped only when all of it lies below the threshold.
        confidence: share of the importance model's draws in which the loss is below the
            threshold at every point judged (0..1).
        n_solutions: how many feature points were judged (the material's recorded
            features and those solved onto the target, or its solved features).
        extrapolated_fraction: share of the draws with a negative raw prediction (counted as 0).
    """

    dimension: str
    reason: str
    predicted_loss_percent: float | None = None
    threshold_percent: float | None = None
    importance_model: str | None = None
    replacement: dict[str, Any] | None = None
    loss_interval_percent: list[float] | None = None
    confidence: float | None = None
    n_solutions: int | None = None
    extrapolated_fraction: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The entry as a JSON-ready dict (see the attributes)."""
        return {"dimension": self.dimension, "reason": self.reason,
                "predicted_loss_percent": self.predicted_loss_percent,
                "threshold_percent": self.threshold_percent,
                "importance_model": self.importance_model,
                "replacement": dict(self.replacement) if self.replacement else None,
                "loss_interval_percent": list(self.loss_interval_percent)
                if self.loss_interval_percent is not None else None,
                "confidence": self.confidence, "n_solutions": self.n_solutions,
                "extrapolated_fraction": self.extrapolated_fraction}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "DroppedDimension":
        """Rebuild an entry from :meth:`to_dict`'s output."""
        iv = d.get("loss_interval_percent")
        return cls(dimension=d["dimension"], reason=d["reason"],
                   predicted_loss_percent=d.get("predicted_loss_percent"),
                   threshold_percent=d.get("threshold_percent"),
                   importance_model=d.get("importance_model"),
                   replacement=dict(d["replacement"]) if d.get("replacement") else None,
                   loss_interval_percent=[_float(v, f"dropped.{d['dimension']}.loss_interval_percent")
                                          for v in iv] if iv is not None else None,
                   confidence=d.get("confidence"), n_solutions=d.get("n_solutions"),
                   extrapolated_fraction=d.get("extrapolated_fraction"))


@dataclass
class MaterialPlan:
    """What is rendered for one material.

    Attributes:
        name: material name (library name, or the scene's name for an intensity-only one).
        targets: target intensity per dimension the material names (0..1).
        dimensions: dimensions kept, in render order.
        dropped: dimensions left out, with reasons.
        features: solved features the kept dimensions read (physical units:
            GS N/mm, W mJ, Fpeak Hz, AFpeak m/s^2, P (m/s^2)^2, ...).
        pinned_features: model inputs no kept dimension reads, pinned at the model's
            defaults during the solve and not rendered.
        importance_features: the solver's features (the solve with every dimension) for
            the features the importance model reads, for reference.
        importance: dimension -> the importance model's loss estimate for the material
            (median, 80 % interval, confidence, decision, and ``basis``: the feature points
            judged, each with its own median and interval;
            :meth:`hapticsdk.compiler.importance.LossEstimate.to_dict`), for every
            dimension the model judged, kept or dropped.
        device: device-aware solving: ``capabilities`` (dimension -> role -> what the
            actuator can produce), the device ``constraints`` solved under and the
            ``binding`` ones, and per kept dimension the ``predicted`` intensity of what
            will be rendered and its ``residual`` (target - predicted).
        role_contracts: role -> what is commanded on it and what carries it:
            ``{"actuator", "actuator_channel", "accepts": {field: unit}, "commanded_by":
            {dimension: RoleSpec.to_dict() or None}}``.
        actuators: channel role -> actuator plugin name.
        actuator_options: role -> keyword options for that actuator.
        roles: dimension (or ``"replacement:<dim>"``) -> roles its renderer commands.
        dimension_distributions: dimension -> distribution that provides it.
        solve: outcome of the final solve (success, error, intensities, message, ...).
        source: ``"library"`` or ``"intensities"``.
        objects: scene objects made of this material.
        calibrations: dimension -> the actuator calibration its renderer uses: ``kind``,
            ``role``, ``serial``, ``origin`` (``file``, ``file-any``, ``default``,
            ``renderer_options``), ``file`` and ``sha256`` (of the calibration file read at
            compile time; ``None`` for a default), ``source`` (words). Rendering loads the
            calibration again and reports it (:mod:`hapticsdk.calibration.selection`).
    """

    name: str
    targets: dict[str, float]
    dimensions: list[str]
    dropped: list[DroppedDimension] = field(default_factory=list)
    features: dict[str, float] = field(default_factory=dict)
    pinned_features: dict[str, float] = field(default_factory=dict)
    importance_features: dict[str, float] = field(default_factory=dict)
    importance: dict[str, dict[str, Any]] = field(default_factory=dict)
    role_contracts: dict[str, dict[str, Any]] = field(default_factory=dict)
    device: dict[str, Any] = field(default_factory=dict)
    actuators: dict[str, str] = field(default_factory=dict)
    actuator_options: dict[str, dict[str, Any]] = field(default_factory=dict)
    roles: dict[str, list[str]] = field(default_factory=dict)
    dimension_distributions: dict[str, str | None] = field(default_factory=dict)
    solve: dict[str, Any] = field(default_factory=dict)
    source: str = "intensities"
    objects: list[str] = field(default_factory=list)
    calibrations: dict[str, dict[str, Any]] = field(default_factory=dict)

    @property
    def replacements(self) -> list[DroppedDimension]:
        """The dropped dimensions that something renders in their place."""
        return [d for d in self.dropped if d.replacement]

    def to_dict(self) -> dict[str, Any]:
        """The material's plan as a JSON-ready dict (see the attributes)."""
        return {"name": self.name, "source": self.source, "objects": list(self.objects),
                "targets": dict(self.targets), "dimensions": list(self.dimensions),
                "dropped": [d.to_dict() for d in self.dropped],
                "features": dict(self.features), "pinned_features": dict(self.pinned_features),
                "importance_features": dict(self.importance_features),
                "importance": json.loads(json.dumps(self.importance)),
                "role_contracts": json.loads(json.dumps(self.role_contracts)),
                "device": json.loads(json.dumps(self.device)),
                "actuators": dict(self.actuators),
                "actuator_options": {k: dict(v) for k, v in self.actuator_options.items()},
                "roles": {k: list(v) for k, v in self.roles.items()},
                "dimension_distributions": dict(self.dimension_distributions),
                "solve": dict(self.solve),
                "calibrations": {k: dict(v) for k, v in self.calibrations.items()}}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "MaterialPlan":
        """Rebuild a material's plan from :meth:`to_dict`'s output."""
        def floats(group: str) -> dict[str, float]:
            return {k: _float(v, f"plan.materials.{d['name']}.{group}.{k}") for k, v in d.get(group, {}).items()}

        return cls(name=d["name"], targets=floats("targets"),
                   dimensions=list(d["dimensions"]),
                   dropped=[DroppedDimension.from_dict(x) for x in d.get("dropped", [])],
                   features=floats("features"), pinned_features=floats("pinned_features"),
                   importance_features=floats("importance_features"),
                   importance={k: dict(v) for k, v in d.get("importance", {}).items()},
                   role_contracts={k: dict(v) for k, v in d.get("role_contracts", {}).items()},
                   device=dict(d.get("device", {})),
                   actuators=dict(d.get("actuators", {})),
                   actuator_options={k: dict(v) for k, v in d.get("actuator_options", {}).items()},
                   roles={k: list(v) for k, v in d.get("roles", {}).items()},
                   dimension_distributions=dict(d.get("dimension_distributions", {})),
                   solve=dict(d.get("solve", {})), source=d.get("source", "intensities"),
                   objects=list(d.get("objects", [])),
                   calibrations={k: dict(v) for k, v in d.get("calibrations", {}).items()})


@dataclass
class RenderPlan:
    """A compiled scene.

    Attributes:
        scene: name of the scene.
        materials: material name -> :class:`MaterialPlan`, in scene order.
        settings: the scene settings used (importance, solver, servo).
        plugins: plugins the plan uses, each ``{kind, name, distribution, version, stage}``
            (``stage`` ``"compile"``: imported to compile; ``"render"``: imported when rendered).
        unused_plugins: installed plugins no material uses, each with ``kind``, ``name``,
            ``distribution`` and ``reason`` (never imported).
        plugin_api_version: :data:`PLUGIN_API_VERSION` of the core that compiled it.
    """

    scene: str
    materials: dict[str, MaterialPlan]
    settings: dict[str, Any] = field(default_factory=dict)
    plugins: list[dict[str, Any]] = field(default_factory=list)
    unused_plugins: list[dict[str, Any]] = field(default_factory=list)
    plugin_api_version: str = PLUGIN_API_VERSION

    # -- access ------------------------------------------------------------
    def material(self, name: str | None = None) -> MaterialPlan:
        """The plan of material ``name`` or of the material of scene object ``name``
        (default: the first)."""
        if not self.materials:
            raise ValidationError("the plan has no materials", field="plan.materials")
        if name is None:
            return next(iter(self.materials.values()))
        if not isinstance(name, str):
            raise ValidationError(f"must be a material or object name, got {type(name).__name__} {name!r:.60}",
                                  field="material")
        if name not in self.materials:
            for mp in self.materials.values():
                if name in mp.objects:
                    return mp
            raise ValidationError(f"no material {name!r} in the plan; it has {list(self.materials)}",
                                  field="material")
        return self.materials[name]

    def distributions(self, material: str | None = None) -> list[str]:
        """Distributions whose plugins the plan (or one material of it) uses."""
        if material is None:
            return sorted({p["distribution"] for p in self.plugins if p.get("distribution")})
        mp = self.material(material)
        names = {("dimension", d) for d in mp.dimensions}
        names |= {("dimension", d.dimension) for d in mp.replacements}
        names |= {("actuator", a) for a in mp.actuators.values()}
        out = {p["distribution"] for p in self.plugins
               if p.get("distribution") and ((p["kind"], p["name"]) in names
                                             or p["kind"] in ("model", "solver", "importance"))}
        return sorted(out)

    # -- serialisation -----------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The plan as JSON-ready data (``schemas/plan.schema.json``)."""
        return {"plan_version": PLAN_VERSION, "plugin_api_version": self.plugin_api_version,
                "scene": self.scene, "settings": json.loads(json.dumps(self.settings)),
                "materials": {k: v.to_dict() for k, v in self.materials.items()},
                "plugins_loaded": [dict(p) for p in self.plugins],
                "unused_plugins": [dict(p) for p in self.unused_plugins]}

    def to_json(self, **kw: Any) -> str:
        """The plan as JSON text (indent 2 unless ``kw`` says otherwise; ``kw`` goes to
        :func:`json.dumps`). A NaN or infinite number anywhere in the plan raises
        :class:`ValidationError` naming its path: :meth:`load` would refuse such a file.
        """
        from .schemas_io import non_finite_at
        d = self.to_dict()
        bad = non_finite_at(d)
        if bad is not None:
            raise ValidationError(f"{bad[1]} is not a finite number; a plan file cannot hold it",
                                  field=f"plan{bad[0]}")
        return json.dumps(d, **{"indent": 2, **kw})

    def save(self, path: str | Path) -> Path:
        """Write the plan JSON atomically (temporary file, fsync, rename: a reader or a
        crash never sees half a plan; a failed write keeps the old file and raises
        :class:`~hapticsdk.errors.FileWriteError`). Returns the path."""
        from .fileio import atomic_write_text
        text = self.to_json() + "\n"  # serialised before the file is touched
        # read back by RenderPlan.load (its size, depth and schema checks) before the rename
        return atomic_write_text(path, text, verify=type(self).load)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, validate: bool = True) -> "RenderPlan":
        """Rebuild a plan from :meth:`to_dict` output; with ``validate`` it is checked
        against ``schemas/plan.schema.json`` first (errors name the JSON path), and its
        feature values against their ranges (:func:`check_plan_features`)."""
        if validate:
            from .schemas_io import check_depth
            check_depth(d, "plan")   # as read_json bounds a file: 5000 levels exhaust no stack
            if isinstance(d, Mapping):  # safety is not data: named before the schema's message
                from .devices.device_options import check_data_settings
                check_data_settings(d.get("settings"), field="plan.settings")
            validate_plan_dict(d)
            settings = d.get("settings", {})
            if isinstance(settings, Mapping):
                # the schema leaves settings open; the renderer reads them as the scene's
                # settings, so they are checked as those are (renderer_options: True failed
                # in the renderer with a TypeError)
                from .scene.model import DEFAULT_SETTINGS, _check_settings, _merge
                _check_settings(_merge(DEFAULT_SETTINGS, settings), where="plan.settings")
        api = str(d.get("plugin_api_version", PLUGIN_API_VERSION))
        if _parse_version(api)[0] != _parse_version(PLUGIN_API_VERSION)[0]:
            raise ValidationError(f"plan compiled for plugin API {api}, this core provides "
                                  f"{PLUGIN_API_VERSION}; compile the scene again",
                                  field="plan.plugin_api_version")
        plan = cls(scene=d["scene"],
                   materials={k: MaterialPlan.from_dict(v) for k, v in d["materials"].items()},
                   settings=dict(d.get("settings", {})),
                   plugins=[dict(p) for p in d.get("plugins_loaded", [])],
                   unused_plugins=[dict(p) for p in d.get("unused_plugins", [])],
                   plugin_api_version=api)
        if validate:
            check_plan_features(plan)
        return plan

    @classmethod
    def load(cls, path: str | Path) -> "RenderPlan":
        """Read a plan file. A plan file is data: besides the schema, every feature
        value is checked against the range its dimension declares (widened to the
        solving model's data bounds), so a hand-edited ``GS: 1e6`` is refused here
        with the field named, not clamped by the safety layer later."""
        from .schemas_io import read_json
        return cls.from_dict(read_json(path, field="plan"))

    def summary(self) -> dict[str, Any]:
        """The short form printed by ``hapticsdk plan --json``."""
        return {"scene": self.scene,
                "materials": {k: {"dimensions": list(m.dimensions),
                                  "dropped": [{"dimension": x.dimension, "reason": x.reason,
                                               "predicted_loss_percent": x.predicted_loss_percent,
                                               "loss_interval_percent": x.loss_interval_percent,
                                               "confidence": x.confidence,
                                               "replacement": x.replacement} for x in m.dropped],
                                  "importance": json.loads(json.dumps(m.importance)),
                                  "role_contracts": json.loads(json.dumps(m.role_contracts)),
                                  "device": json.loads(json.dumps(m.device)),
                                  "features": dict(m.features),
                                  "pinned_features": dict(m.pinned_features),
                                  "actuators": dict(m.actuators),
                                  "calibrations": {k2: dict(v2) for k2, v2 in m.calibrations.items()},
                                  "solve": {k2: m.solve.get(k2) for k2 in
                                            ("success", "error", "intensities", "message")}}
                              for k, m in self.materials.items()},
                "plugins_loaded": [dict(p) for p in self.plugins],
                "unused_plugins": [dict(p) for p in self.unused_plugins],
                "plugin_api_version": self.plugin_api_version}


def feature_ranges(mp: "MaterialPlan") -> dict[str, tuple[float, float]]:
    """Accepted range per feature of one material: the bounds the kept (and dropped)
    dimensions declare for their features, widened to the bounds of the registered
    perception model(s) the solve names (a model named by a file path is not loaded)."""
    from .errors import HapticSDKError
    from .plugins import registry

    ranges: dict[str, tuple[float, float]] = {}

    def widen(name: str, lo: float, hi: float) -> None:
        a, b = ranges.get(name, (lo, hi))
        ranges[name] = (min(a, lo), max(b, hi))

    reg = registry("dimension")
    for dim in list(mp.dimensions) + [d.dimension for d in mp.dropped]:
        if dim not in reg.names():
            continue  # rendering reports the missing plugin
        for f in getattr(reg.load(dim), "features", ()):
            widen(f.name, float(f.lower), float(f.upper))
    models = (mp.solve or {}).get("models") or []
    if isinstance(models, list):
        mreg = registry("model")
        for name in models:
            if not isinstance(name, str) or name.endswith(".onnx") or name not in mreg.names():
                continue
            try:
                from .solvers.problems import load_model
                for f in load_model(name).feature_space or ():
                    widen(f.name, float(f.lower), float(f.upper))
            except HapticSDKError:
                continue
    return ranges


def check_plan_features(plan: "RenderPlan") -> None:
    """Refuse a plan whose feature values are not numbers (``true`` included), not finite,
    or outside :func:`feature_ranges` (relative slack 1e-6); raises
    :class:`ValidationError` naming ``plan.materials.<m>.features.<f>``."""
    from .checks import check_number

    for mname, mp in plan.materials.items():
        ranges = feature_ranges(mp)
        for group in ("features", "pinned_features", "importance_features"):
            for fname, value in getattr(mp, group).items():
                field_ = f"plan.materials.{mname}.{group}.{fname}"
                v = check_number(value, field_)
                if fname in ranges:
                    lo, hi = ranges[fname]
                    slack = 1e-6 * max(abs(lo), abs(hi), 1.0)
                    if not lo - slack <= v <= hi + slack:
                        raise ValidationError(f"{v:g} is outside the feature's range {lo:g}..{hi:g}", field=field_)


def validate_plan_dict(data: Any) -> None:
    """Validate a plan dict against ``schemas/plan.schema.json`` (errors name the JSON path)."""
    from .schemas_io import validate
    validate(data, "plan")


if not TYPE_CHECKING:  # moved names, deprecated since 0.2 (a type checker sees only the new places)
    from ._deprecation import moved_names
    __getattr__ = moved_names(__name__, {"compile_scene": "hapticsdk.compiler", "api_compatible": "hapticsdk.plugin_api", "check_plugin_api": "hapticsdk.plugin_api"})
