"""Perception dimensions: perceptual axes with features, constraints and renderers.

A :class:`PerceptionDimension` (hardness, roughness, ...) is what a person rates on a
0..1 intensity scale. It contributes the stimulus features that drive it, the physical
constraints those features must meet (as vectorised penalties), and a renderer that
turns solved features into per-tick actuator commands. Dimensions are published by
plugins (entry-point group ``hapticsdk.dimensions``); the core knows none of them.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping

import numpy as np

from ..checks import is_number
from ..errors import ValidationError
from .features import Feature, FeatureSpace

def first_line(doc: str | None) -> str:
    """The first non-empty line of a docstring ("" when there is none)."""
    return next((ln.strip() for ln in (doc or "").splitlines() if ln.strip()), "")


def _one(a: Any) -> float:
    """The only value of a one-row result (a one-element array, or a scalar) as a float."""
    return float(a[0]) if getattr(a, "ndim", 0) else float(a)


#: Penalty forms a constraint can report. ``"paper"`` is formula (6) of the reference
#: paper (squared physical units); ``"normalised"`` is the relative violation
#: (dimensionless, 0 when met), comparable across constraints.
PENALTY_FORMS = ("paper", "normalised")


class Constraint(ABC):
    """A physical constraint on features, evaluated on whole populations at once.

    Subclasses set ``name`` and ``features`` (the feature names they read) and
    implement :meth:`_bound_and_value`, returning the lower bound the constrained
    quantity must reach and the quantity itself, both ``(n,)`` arrays. The base turns
    them into both penalty forms; solvers that need the raw pair call the public
    :meth:`bound_and_value`.
    """

    name: ClassVar[str] = "constraint"
    features: ClassVar[tuple[str, ...]] = ()

    @abstractmethod
    def _bound_and_value(self, cols: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(bound, value)``; the constraint is ``value >= bound``."""

    def bound_and_value(self, cols: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """``(bound, value)`` per row (the constraint is ``value >= bound``), from the
        feature columns ``cols``; subclasses implement :meth:`_bound_and_value`."""
        return self._bound_and_value(cols)

    def _bound_and_value_one(self, row: Mapping[str, float]) -> tuple[float, float] | None:
        """Optional: ``(bound, value)`` of one row of features given as plain floats, as
        plain floats, the very numbers :meth:`_bound_and_value` gives for that row alone
        (the same operations in the same order: IEEE arithmetic rounds a float the same
        way as a one-element array). ``None`` (this base): not provided, and
        :meth:`bound_and_value_one` runs :meth:`_bound_and_value` on one-element arrays.
        The conformance kit's ``constraints`` rule checks that the two agree."""
        return None

    def bound_and_value_one(self, row: Mapping[str, float]) -> tuple[float, float]:
        """``(bound, value)`` of one row of features (``{feature name: value}``, plain
        floats) as two floats: what :meth:`bound_and_value` gives on a batch of that one row.
        A one-target solve judges its answer with it; from a subclass's
        :meth:`_bound_and_value_one` it costs a fraction of a microsecond, against several
        for numpy on one-element arrays."""
        pair = self._bound_and_value_one(row)
        if pair is None:
            ba, va = self._bound_and_value({k: np.array([x], float) for k, x in row.items()})
            return _one(ba), _one(va)
        return float(pair[0]), float(pair[1])

    @classmethod
    def uses_base_formulas(cls) -> bool:
        """True when ``penalty`` and ``violation`` are this base class's formulas (so both
        follow from one :meth:`bound_and_value` call)."""
        return cls.penalty is Constraint.penalty and cls.violation is Constraint.violation

    def penalty(self, cols: Mapping[str, np.ndarray], form: str = "paper") -> np.ndarray:
        """Penalty per row, 0 where the constraint holds.

        ``paper``: ``bound**2 - value**2`` where ``value < bound`` (formula (6)).
        ``normalised``: ``(bound - value) / |bound|`` where ``value < bound``.
        """
        if form not in PENALTY_FORMS:
            raise ValidationError(f"unknown penalty form {form!r}; valid: {list(PENALTY_FORMS)}",
                                  field="penalty")
        bound, value = self.bound_and_value(cols)
        short = value < bound
        if form == "paper":
            return np.where(short, bound ** 2 - value ** 2, 0.0)
        scale = np.where(np.abs(bound) > 0, np.abs(bound), 1.0)
        return np.where(short, (bound - value) / scale, 0.0)

    def violation(self, cols: Mapping[str, np.ndarray]) -> np.ndarray:
        """Relative violation per row (the ``normalised`` penalty), 0 when met."""
        return self.penalty(cols, "normalised")

    def describe(self) -> dict:
        """Name, the features the constraint reads and its one-line description."""
        return {"name": self.name, "features": list(self.features), "doc": first_line(self.__doc__)}


@dataclass
class TickInput:
    """What a renderer sees on one servo tick.

    Attributes:
        t: time since render start (s).
        dt: measured time since the previous tick (s).
        penetration_mm: depth of the probe into the material along the normal (mm), >= 0
            in contact, <= 0 outside.
        velocity_mm_s: probe velocity in the contact frame, shape (3,), (mm/s), a read-only
            array (one input goes to every renderer of the object in turn: compute on
            copies, never change the input; the conformance kit checks it): index 1
            is the component along the object's outward normal, index 0 the sliding
            speed along the surface (on a surface with normal +y, as in a version-1 scene,
            the signed lateral velocity x, and index 2 is z; on any other normal the
            tangential speed, >= 0, and index 2 is 0).
        in_contact: penetration > 0.
        normal: the object's outward unit normal at the contact, ``(nx, ny, nz)`` in device
            coordinates; ``(0, 1, 0)`` for the version-1 plane y = 0.
        object: name of the object under the probe (None when no scene object is named).
        velocity_filtered_mm_s: the same contact-frame velocity through a first-order
            low-pass (the loop's ``velocity_filter_hz``, default 30 Hz), as plain floats
            ``(v0, v1, v2)`` (mm/s): for renderers that must not follow the +-50 mm/s
            count-level chatter a quantised encoder gives a backward difference; None when
            the loop gives none.
        speed_step_mm_s: the largest change of the filtered velocity one encoder count
            can make in one tick, ``a q / dt`` (``a`` the filter's per-tick coefficient,
            ``q`` the device's declared ``encoder_resolution_mm``); 0 for a device that
            declares none. A speed gate uses it as its hysteresis width (docs/runtime.md,
            "Gates with hysteresis").
        velocity_floats_mm_s: ``velocity_mm_s`` as plain floats ``(v0, v1, v2)`` (mm/s),
            the same numbers, for renderers that read a component every tick (indexing
            the array makes a numpy scalar); None when the caller gives none (then read
            ``velocity_mm_s``). The servo loop gives both, and builds the array only when
            a renderer reads it.
    """

    t: float
    dt: float
    penetration_mm: float
    velocity_mm_s: np.ndarray
    in_contact: bool
    normal: tuple[float, float, float] = (0.0, 1.0, 0.0)
    object: str | None = None
    velocity_filtered_mm_s: tuple[float, float, float] | None = None
    speed_step_mm_s: float = 0.0
    velocity_floats_mm_s: tuple[float, float, float] | None = None


@dataclass
class ChannelCommand:
    """One command for one actuator role on one tick.

    ``force_n`` for force channels (normal force, N, pushing the probe out);
    ``frequency_hz`` and ``amplitude`` for vibration channels (amplitude in the
    actuator's own unit: V for a piezo, 0..1 for a voice coil). ``direction``: the unit
    vector (device coordinates) the force pushes along, the contact normal; None means
    +y (the version-1 surface). A device that renders along one axis only applies the
    projection of the force on its axis (the simulated Omni: ``force_n * direction[1]``).
    """

    role: str
    force_n: float | None = None
    frequency_hz: float | None = None
    amplitude: float | None = None
    direction: tuple[float, float, float] | None = None


#: The command fields of :class:`ChannelCommand` a role can carry.
COMMAND_FIELDS = ("force_n", "frequency_hz", "amplitude")


@dataclass(frozen=True)
class RoleSpec:
    """What a dimension's renderer commands on one channel role.

    Attributes:
        channel: the kind of channel (one of :data:`hapticsdk.perception.channels.CHANNELS`:
            ``"force"``, ``"vibration"``, ``"thermal"``, ``"friction"``, ``"other"``).
        fields: the :class:`ChannelCommand` fields it sets, each with its unit
            (``{"force_n": "N"}``; ``{"frequency_hz": "Hz", "amplitude": "V"}``; a
            normalised drive has unit ``"1"``).
        description: one line for ``hapticsdk plan``.

    The scene compiler maps the role to an actuator only when the actuator serves the
    same channel and accepts every field in the same unit
    (:meth:`hapticsdk.devices.actuators.Actuator.accepted_fields`); otherwise it refuses the
    scene with a :class:`~hapticsdk.errors.ValidationError` naming both.
    """

    channel: str
    fields: Mapping[str, str]
    description: str = ""

    def __post_init__(self) -> None:
        from .channels import CHANNELS
        if self.channel not in CHANNELS:
            raise ValidationError(f"unknown channel {self.channel!r}; valid: {list(CHANNELS)}", field="role.channel")
        bad = [f for f in self.fields if f not in COMMAND_FIELDS]
        if bad or not self.fields:
            raise ValidationError(f"fields must be a non-empty subset of {list(COMMAND_FIELDS)}, got "
                                  f"{list(self.fields)}", field="role.fields")
        object.__setattr__(self, "fields", dict(self.fields))

    def to_dict(self) -> dict[str, Any]:
        """The role as a JSON-ready dict: channel, command fields with their units,
        description.
        """
        return {"channel": self.channel, "fields": dict(self.fields), "description": self.description}

    def describe(self) -> str:
        """``vibration (frequency_hz Hz, amplitude V)``."""
        return f"{self.channel} ({', '.join(f'{k} {u}' for k, u in self.fields.items())})"


class DimensionRenderer(ABC):
    """Computes commands for one dimension of one material, per tick.

    Created by :meth:`PerceptionDimension.renderer` with the solved features; must be
    cheap per tick (no allocation-heavy work, no imports) and must return finite values.
    """

    #: roles this renderer commands, e.g. ("force", "coil"); mapped to actuators by the scene.
    roles: tuple[str, ...] = ()

    @abstractmethod
    def tick(self, inp: TickInput) -> list[ChannelCommand]:
        """Commands for this tick."""

    def _fast_law(self) -> Any:
        """Optional: the per-tick law on plain floats, for the servo loop's steady-state
        tick (:class:`~hapticsdk.runtime.loop.ServoLoop`, ``fast_tick``). Default None
        (not offered): the loop calls :meth:`tick` every tick, as always.

        A renderer that offers one returns a callable
        ``law(t, dt, penetration_mm, in_contact, v0, v1, v2, vf0, vf1, vf2, speed_step_mm_s)``
        taking the fields of :class:`TickInput` as plain floats (``v*`` is
        ``velocity_floats_mm_s``, ``vf*`` ``velocity_filtered_mm_s``, ``in_contact`` a
        bool) and returning a flat tuple of three values per role of :attr:`roles`, in
        that order: the ``force_n``, ``frequency_hz`` and ``amplitude`` (each a float or
        None) of the one command :meth:`tick` returns for that role on the same input.
        The contract, which the loop relies on for outputs equal bit for bit to
        :meth:`tick`'s:

        * the same values, computed with the same operations in the same order, as the
          commands :meth:`tick` returns (one per role, in ``roles`` order, no
          ``direction``; the loop sets the force's);
        * the same state: ``law`` and :meth:`tick` may be called in any mix, tick by
          tick (the loop goes back to :meth:`tick` whenever its steady state ends), so
          whatever the renderer keeps from tick to tick (a gate, a phase, counters) the
          law reads and writes in the same attributes :meth:`tick` uses;
        * what it captures when it is made is only what the renderer never changes
          after it was built (its derived parameters); the loop asks for a new law
          whenever it rebuilds its steady-state tick;
        * it does not depend on ``TickInput.normal``, ``object`` or the input object
          itself, which it does not get.

        The loop does not use the law of a renderer whose ``tick`` is replaced on the
        instance, or by a subclass below the class that defines ``_fast_law`` (the law
        would skip the new ``tick``): it calls ``tick`` for those, every tick.

        The built-in hardness and roughness renderers offer one; the equality is tested
        by running scenes through both paths (``tests/runtime/test_fused_tick.py``)."""
        return None

    def describe(self) -> dict:
        """Parameters the renderer derived from the features (for reports)."""
        return {}


class PerceptionDimension(ABC):
    """A perceptual axis with an intensity scale of 0..1.

    Subclasses set ``name``, ``description``, ``features`` (the features it
    contributes, with default bounds) and ``default_actuators`` (role -> actuator
    plugin name), and implement :meth:`constraints` and :meth:`renderer`.
    """

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    features: ClassVar[tuple[Feature, ...]] = ()
    default_actuators: ClassVar[dict[str, str]] = {}
    #: What the renderer commands on each role it may use (role -> :class:`RoleSpec`);
    #: every role a renderer lists in ``roles`` must be declared here (plugin API 1.1).
    roles: ClassVar[dict[str, RoleSpec]] = {}
    #: Features a material of this dimension needs to be rendered (subset of ``features``).
    render_features: ClassVar[tuple[str, ...]] = ()
    #: Saved actuator calibrations the renderer takes: renderer option -> (calibration
    #: kind, channel role), e.g. ``{"calibration": ("voicecoil", "coil")}``; the core loads
    #: them from the calibration store (:mod:`hapticsdk.calibration.selection`).
    calibrations: ClassVar[dict[str, tuple[str, str]]] = {}
    #: Name (group ``hapticsdk.models``) of the perception model that covers this dimension
    #: when a scene names none; dimensions sharing a model are solved with it together.
    default_model: ClassVar[str] = "default"

    def feature_space(self) -> FeatureSpace:
        """The features this dimension contributes, labelled with their declarer."""
        return FeatureSpace(tuple(f.owned_by(f.owner or f"dimension {self.name!r}") for f in self.features))

    def constraints(self, **context: float) -> list[Constraint]:
        """Physical constraints (default: none). ``context`` carries data-set facts (e.g. ``df_hz``)."""
        return []

    def device_constraints(self, capabilities: Mapping[str, Any], **options: Any) -> list[Constraint]:
        """Constraints that keep the solved features within what the actuators mapped to
        this dimension's roles can produce (device-aware solving; default: none).

        Args:
            capabilities: role -> :class:`~hapticsdk.devices.actuators.DriveCapability` of the
                actuator on that role (roles whose actuator publishes none are absent).
            options: the renderer options the material will be rendered with (e.g. the
                calibrated table), so the constraint and the renderer agree.
        """
        return []

    def capability_options(self, capabilities: Mapping[str, Any]) -> dict[str, Any]:
        """Renderer options taken from the mapped actuators' capabilities (default none;
        e.g. an actuator's own drive table). Explicit ``renderer_options`` win."""
        return {}

    @abstractmethod
    def renderer(self, features: Mapping[str, float], **options: Any) -> DimensionRenderer:
        """A renderer for a material with these solved features (physical units)."""

    def describe(self) -> dict:
        """Name, description, features (with units and bounds), default actuator per role
        and the roles' command contracts.
        """
        return {"name": self.name, "description": self.description,
                "features": [f.to_dict() for f in self.features],
                "default_actuators": dict(self.default_actuators),
                "roles": {r: spec.to_dict() for r, spec in self.roles.items()}}


def _defined_in(cls: type, name: str) -> type | None:
    """The class of ``cls``'s method resolution order that defines ``name``."""
    for c in cls.__mro__:
        if name in c.__dict__:
            return c
    return None


def _steady_law_of(r: "DimensionRenderer") -> Any:
    """``r``'s law on plain floats (:meth:`DimensionRenderer._fast_law`) when it stands for
    the ``tick`` a caller would call (the servo loop's steady-state tick, the conformance
    kit's ``renderer-fast-law`` rule): None when ``r`` offers none, when a subclass replaces ``tick``
    below the class that defines ``_fast_law`` (the law would skip the new ``tick``), or
    when ``tick`` is replaced on the instance (a wrapper, a test double)."""
    cls = type(r)
    law_cls, tick_cls = _defined_in(cls, "_fast_law"), _defined_in(cls, "tick")
    if law_cls is None or tick_cls is None or not issubclass(law_cls, tick_cls):
        return None
    # (not vars(r): reading an instance's __dict__ slows every later attribute access)
    tick = r.tick
    if getattr(tick, "__func__", None) is not tick_cls.__dict__["tick"] or getattr(tick, "__self__", None) is not r:
        return None
    return r._fast_law()


def declared_roles(dim: Any) -> dict[str, RoleSpec]:
    """The typed roles of a dimension (class or instance): its ``roles`` where it declares
    them (plugin API 1.1); otherwise, for a 1.0-style dimension, one per default actuator,
    typed from that actuator's channel and the fields it accepts with their units
    (:meth:`hapticsdk.devices.actuators.Actuator.accepted_fields`), so that mapping the role to an
    actuator of another kind or unit is refused as for a declared role. A role whose
    default actuator is not installed is left out."""
    declared = dict(getattr(dim, "roles", {}) or {})
    if declared:
        return declared
    from ..plugins import registry
    out: dict[str, RoleSpec] = {}
    for role, name in dict(getattr(dim, "default_actuators", {}) or {}).items():
        if name not in registry("actuator"):
            continue
        cls = registry("actuator").load(name)
        fields = cls.accepted_fields() if hasattr(cls, "accepted_fields") else {}
        channel = getattr(cls, "channel", "other")
        if fields and channel:
            out[role] = RoleSpec(channel, fields, f"typed from the default actuator {name!r} (undeclared role)")
    return out


def undeclared_fields(cmd: ChannelCommand, spec: RoleSpec) -> list[str]:
    """The fields ``cmd`` sets that ``spec`` does not declare (``[]``: within its
    contract)."""
    return [f for f in COMMAND_FIELDS if getattr(cmd, f) is not None and f not in spec.fields]


def check_intensity(value: object, field: str, *, text: bool = False) -> float:
    """Return ``value`` as a float in [0, 1] or raise :class:`ValidationError` naming ``field``.

    ``value`` is a real number (``hapticsdk.argcheck``'s rule: ``True`` and ``False``
    are refused, a bool is not an intensity, and so is a string); with ``text=True``
    (command-line arguments) it may be the text of a number."""
    if type(value) is float:   # the common case (a one-target solve's): nothing to convert
        v = value
    else:
        if text and isinstance(value, str):
            try:
                value = float(value)
            except ValueError:
                raise ValidationError(f"intensity must be a number, got {value!r:.80}", field=field) from None
        if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "fiu":
            value = value.item()
        if not is_number(value):
            raise ValidationError(f"intensity must be a number, got {value!r:.80}", field=field)
        try:
            v = float(value)  # type: ignore[arg-type]
        except OverflowError:   # an int beyond the float range
            raise ValidationError(f"intensity {value!r:.40} outside 0..1", field=field) from None
    if not math.isfinite(v):
        raise ValidationError("intensity is NaN or infinite", field=field)
    if not 0.0 <= v <= 1.0:
        raise ValidationError(f"intensity {v:g} outside 0..1", field=field)
    return v
