"""Kit rules widened after round 8 of broken plugins, each broken variant passed by the
kit before:

* ``output-follows-command`` (actuator): a simulated actuator whose output lag is advanced
  by a fixed step per ``step()`` call, not by ``dt``: it settles within its declared
  settle time at the kit's 1 ms period and takes twice as long (in seconds) at 2 ms;
* ``output-follows-command`` (actuator, device): a force device that ignores
  ``ChannelCommand.direction`` (the contact normal the force pushes along; None is +y)
  and renders ``force_n`` along +y whatever the normal, so on the underside of an object
  it pushes into it. A device on one axis rendering the projection, and one rendering the
  whole vector (its read-back giving the direction), conform;
* ``template`` (actuator, device): a backend that loosens its own safety layer (its
  ``_open`` turns the start ramp off and the start gate's force check off): the settings
  are the application's; tightening them conforms;
* ``limits-declared`` (actuator): ``capability_for()`` (what device-aware solving solves
  within) beyond the declared limits the safety layer clamps to: a wider band, a larger
  drive (3000 mV against 2 V), a drive in a unit of another quantity;
* ``hookimpls`` (hooks): a hook module pluggy refuses to register (a ``hookwrapper=True``
  implementation that is not a generator function): the core records it as a failed hook
  plugin and never calls it;
* ``hookimpls`` (hooks): ``hapticsdk_materials`` adding its materials to a module-level
  list on every call: the second call (the core calls it on every load of the library)
  repeats a name, and the core skips the plugin's materials from there on;
* ``metadata`` (model): a fact build_problem hands every dimension's constraints
  (``df_hz``, a ``constraint_context`` entry) that is NaN, infinite or not a number: a NaN
  bound reads as met whatever the features;
* ``state`` (device): a simulated device whose state reports a force other than the one
  it applies (``DeviceState.force_n``, N): its sign flipped, or in mN. One that reports
  no force at all (zeros: it does not sense it) is not judged;
* ``constraints-vectorised`` (dimension): a constraint of device-aware solving
  (``device_constraints``, for the default actuators' capabilities) whose bound is NaN over
  part of the feature box: the rule checked only ``constraints()``;
* ``constraints-vectorised`` (dimension): ``constraints()`` that takes no keyword facts
  (the core passes every dimension of a problem its model's facts, ``df_hz`` and any
  name of a ``constraint_context``, so a scene mixing it with such a model fails);
* ``renderer`` (dimension): a renderer whose path for ``TickInput.velocity_floats_mm_s``
  (the velocity as plain floats, which the servo loop always gives and the kit's ticks
  did not) reads another component than its path for the array, and one that assumes
  the version-1 plane (divides by ``normal[1]``), which turns infinite on a wall of a
  spatial scene, and one whose speed gate goes wrong only with the filtered velocity and
  an encoder's speed step (``speed_step_mm_s > 0``, which the loop gives for a device
  declaring an encoder count and the kit's ticks never did);
* ``renderer`` (dimension): ``renderer()`` refusing features that are not its own (a
  strict check of its input): the render builds each dimension's renderer from all of
  the material's solved features, so every material with a second dimension failed;
* ``determinism`` (dimension): a dimension whose ``renderer()`` hands out one cached
  renderer per features: two objects of one material share it, and the loop ticks it
  twice a tick (its onset runs at double speed);
* ``determinism`` (dimension): a renderer that ignores ``TickInput.dt`` and advances its
  state by a fixed step per tick (an onset envelope, an attack ramp, a slow tremolo's
  phase, a low-pass of the depth with a fixed coefficient): at a 0.25 ms servo period it
  plays the scene 4 x faster than at 1 ms. The correct variants advance the same state by
  ``dt`` (a forward-Euler low-pass too, whose error is of one tick) and conform, as do
  the first-party renderers.

The correct variants conform."""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import pytest

from hapticsdk.errors import ValidationError

from hapticsdk.devices.actuators import DeviceState
from hapticsdk.perception.dimensions import ChannelCommand, DimensionRenderer
from hapticsdk.plugins import registry
from hapticsdk.testing import check, check_actuator, check_device, check_dimension
from hapticsdk.testing.conformance import format_report
from kit_variants import LAG_COIL_MAX_V, BuzzModel, ForceArm, constraint, LagCoil, OutputArm, buzz_dimension, buzz_installed, rules_of


# ---------------------------------------------------------------------------
# dimensions: renderers that follow dt, and the same ignoring it
# ---------------------------------------------------------------------------

class _Paced(DimensionRenderer):
    """100 Hz on the lagging coil in contact, amplitude from the depth and ``x`` times an
    envelope of a state ``s`` that starts at 0 at each contact; ``per_call`` (s) is the
    step a broken variant advances its clock by per tick instead of ``dt``."""
    roles = ("buzz",)
    per_call: ClassVar[float | None] = None

    def __init__(self, x: float) -> None:
        self.x, self.s = x, 0.0

    def elapsed(self, inp) -> float:
        return inp.dt if self.per_call is None else self.per_call

    def advance(self, inp) -> None:
        raise NotImplementedError

    def envelope(self) -> float:
        raise NotImplementedError

    def tick(self, inp):
        if not inp.in_contact:
            self.s = 0.0
            return [ChannelCommand("buzz", frequency_hz=100.0, amplitude=0.0)]
        self.advance(inp)
        a = 0.25 * LAG_COIL_MAX_V * (0.2 + 0.8 * self.x) * min(1.0, abs(inp.penetration_mm))
        return [ChannelCommand("buzz", frequency_hz=100.0, amplitude=a * self.envelope())]


class _Onset(_Paced):
    """Doubled at the onset of a contact, the extra decaying with a 30 ms time constant."""

    def advance(self, inp) -> None:
        self.s += self.elapsed(inp)

    def envelope(self) -> float:
        return 1.0 + math.exp(-self.s / 0.03)


class _Attack(_Paced):
    """Rises linearly from 0 over the first 100 ms of a contact."""

    def advance(self, inp) -> None:
        self.s = min(1.0, self.s + self.elapsed(inp) / 0.1)

    def envelope(self) -> float:
        return self.s


class _Tremolo(_Paced):
    """A 5 Hz tremolo of +-40 % (its phase in ``s``)."""

    def advance(self, inp) -> None:
        self.s += 2 * math.pi * 5.0 * self.elapsed(inp)

    def envelope(self) -> float:
        return 0.6 + 0.4 * math.sin(self.s)


class _Smoothed(_Paced):
    """Follows the depth through a forward-Euler low-pass of 20 ms (``s += (p - s) dt /
    tau``: one tick's error, not exact)."""

    def advance(self, inp) -> None:
        self.s += (abs(inp.penetration_mm) - self.s) * self.elapsed(inp) / 0.02

    def envelope(self) -> float:
        return self.s


class _OneTickLate(_Paced):
    """Renders the depth of the previous tick (a measurement one tick old): one period
    late at each period, which the rule allows."""

    def advance(self, inp) -> None:
        self.s, self.now = getattr(self, "now", abs(inp.penetration_mm)), abs(inp.penetration_mm)

    def envelope(self) -> float:
        return self.s


def _per_call(cls: type[_Paced]) -> type[_Paced]:
    """``cls`` advancing by 1 ms per tick, whatever ``dt`` (written for a 1 kHz loop)."""
    return type(cls.__name__ + "PerCall", (cls,), {"__doc__": f"{cls.__doc__} Advanced 1 ms per tick.",
                                                  "per_call": 1e-3})


_dim = buzz_dimension


@pytest.fixture
def installed():
    yield from buzz_installed(_Onset)


PACED = [_Onset, _Attack, _Tremolo, _Smoothed]


@pytest.mark.parametrize("renderer", PACED + [_OneTickLate], ids=lambda c: c.__name__.strip("_").lower())
def test_renderers_that_advance_by_dt_conform(installed, renderer):
    v = check("dimension", _dim(renderer), rules=["determinism"])
    assert v == [], format_report(v)


@pytest.mark.parametrize("renderer", PACED, ids=lambda c: c.__name__.strip("_").lower())
def test_renderers_that_advance_per_tick_are_caught(installed, renderer):
    v = check("dimension", _dim(_per_call(renderer)), rules=["determinism"])
    assert rules_of(v) == {"determinism"}, format_report(v)
    assert "at servo periods 1 ms and 0.25 ms gave other commands" in format_report(v)


def test_a_renderer_advancing_per_tick_fails_only_determinism(installed):
    v = check_dimension(_dim(_per_call(_Onset)))
    assert rules_of(v) == {"determinism"}, format_report(v)


@pytest.mark.parametrize("name", ["hardness", "roughness", "warmth"])
def test_first_party_renderers_follow_the_servo_period(name):
    if name not in registry("dimension"):
        pytest.skip(f"dimension {name!r} not installed")
    v = check("dimension", name, rules=["determinism"])
    assert v == [], format_report(v)


# ---------------------------------------------------------------------------
# actuators: a simulated output stepped per call
# ---------------------------------------------------------------------------

class _LagPerCall(LagCoil):
    """The lagging coil advancing its lag by 1 ms per ``step()`` call, whatever ``dt``
    (written for a 1 kHz loop): at 2 ms it settles in twice its declared settle time."""
    name: ClassVar[str] = "kit-lag-per-call"

    def step(self, dt: float) -> None:
        super().step(1e-3)


def test_a_simulated_output_stepped_per_call_is_caught():
    v = check_actuator(_LagPerCall)
    assert rules_of(v) == {"output-follows-command"}, format_report(v)
    assert "at a 2 ms servo period" in format_report(v)


def test_a_simulated_output_stepped_by_dt_conforms_at_both_periods():
    v = check("actuator", LagCoil, rules=["output-follows-command"])
    assert v == [], format_report(v)


@pytest.mark.parametrize("name", ["omni-virtual", "voicecoil-virtual", "piezo-virtual", "peltier-virtual",
                                  "probe-virtual", "playback-virtual"])
def test_first_party_simulated_actuators_settle_at_a_longer_period(name):
    if name not in registry("actuator"):
        pytest.skip(f"actuator {name!r} not installed")
    from hapticsdk.devices.actuators import HapticDevice
    kind = "device" if issubclass(registry("actuator").load(name), HapticDevice) else "actuator"
    v = check(kind, name, rules=["output-follows-command"])
    assert v == [], format_report(v)


# ---------------------------------------------------------------------------
# dimensions: constraints() without the model's facts
# ---------------------------------------------------------------------------

def _no_context(self):
    return []


def test_constraints_that_take_no_facts_are_caught(installed):
    dim = type("NoFacts", (buzz_dimension(_Onset),), {"constraints": _no_context})
    v = check_dimension(dim)
    assert rules_of(v) == {"constraints-vectorised"}, format_report(v)
    assert "constraints(kit_unread_fact=1.0) raised TypeError" in format_report(v)


def test_a_problem_passes_its_model_s_facts_to_every_dimension(monkeypatch):
    """The contract the rule holds a dimension to: build_problem hands each dimension the
    facts of the problem's model, also those of another dimension (the paper model's
    df_hz, a roughness fact, reaches hardness, which does not read it)."""
    if "hardness" not in registry("dimension"):
        pytest.skip("hapticsdk-hardness not installed")
    from hapticsdk.solvers.problems import build_problem
    hardness = registry("dimension").load("hardness")
    seen = []
    original = hardness.constraints

    def constraints(self, **context):
        seen.append(dict(context))
        return original(self, **context)
    monkeypatch.setattr(hardness, "constraints", constraints)
    build_problem({"hardness": 0.5})
    assert seen and "df_hz" in seen[0], seen


# ---------------------------------------------------------------------------
# devices: the direction a force pushes along
# ---------------------------------------------------------------------------

def _on_plus_y(arm: type[ForceArm]) -> type[ForceArm]:
    """``arm`` rendering ``force_n`` along +y whatever ``direction`` says."""
    def _command(self, cmd) -> None:
        self.f = float(np.clip(cmd.force_n or 0.0, -self.saturation_n, self.saturation_n))
    return type(arm.__name__ + "OnPlusY", (arm,), {"__doc__": "Ignores the command's direction.",
                                                  "name": arm.name + "-plus-y", "_command": _command})


class _Vector3(OutputArm):
    """A correct device rendering the whole force vector (3 motors): its read-back is the
    force along the direction it was sent."""
    name: ClassVar[str] = "kit-arm-3d"

    def _command(self, cmd) -> None:
        super()._command(cmd)
        self.f = float(np.clip(cmd.force_n or 0.0, -self.saturation_n, self.saturation_n))
        self.d = cmd.direction

    def _read_back(self):
        from hapticsdk.perception.dimensions import ChannelCommand
        return ChannelCommand("force", force_n=self.f, direction=getattr(self, "d", None))


@pytest.mark.parametrize("arm", [OutputArm, ForceArm], ids=["output", "drive-record"])
def test_a_device_ignoring_the_direction_is_caught(arm):
    v = check_device(_on_plus_y(arm))
    assert rules_of(v) == {"output-follows-command"}, format_report(v)
    assert "it ignores ChannelCommand.direction" in format_report(v)


@pytest.mark.parametrize("arm", [OutputArm, ForceArm, _Vector3], ids=["output", "drive-record", "3d"])
def test_devices_rendering_the_direction_conform(arm):
    v = check("device", arm, rules=["output-follows-command"])
    assert v == [], format_report(v)


# ---------------------------------------------------------------------------
# devices: the force a state reports
# ---------------------------------------------------------------------------

def _sensing(scale: float, label: str) -> type[OutputArm]:
    """:class:`OutputArm` whose state reports ``scale`` x the force it applies."""
    def _read_state(self) -> DeviceState:
        return DeviceState(t=self.t, position_mm=np.zeros(3), velocity_mm_s=np.zeros(3),
                           force_n=np.array([0.0, scale * self.f, 0.0]))
    return type(f"Arm_{label}", (OutputArm,), {"__doc__": f"Its state reports the force {label}.",
                                              "name": f"kit-arm-{label}", "_read_state": _read_state})


@pytest.mark.parametrize("scale, label", [(-1.0, "sign-flipped"), (1000.0, "in-mN")])
def test_a_state_reporting_another_force_than_applied_is_caught(scale, label):
    v = check_device(_sensing(scale, label))
    assert rules_of(v) == {"state"}, format_report(v)
    assert "is not the force applied" in format_report(v)


@pytest.mark.parametrize("scale, label", [(1.0, "applied"), (0.0, "not-sensed")])
def test_a_state_reporting_the_applied_force_or_none_conforms(scale, label):
    v = check("device", _sensing(scale, label), rules=["state"])
    assert v == [], format_report(v)


# ---------------------------------------------------------------------------
# dimensions: the velocity's float path, other contact normals
# ---------------------------------------------------------------------------

class _Slide(DimensionRenderer):
    """Correct: amplitude from x and the sliding speed, read from the floats when the
    caller gives them (as the servo loop does), else from the array."""
    roles = ("buzz",)

    def __init__(self, x: float) -> None:
        self.x = x

    def speed(self, inp) -> float:
        vt = inp.velocity_floats_mm_s
        return abs(vt[0]) if vt is not None else abs(float(inp.velocity_mm_s[0]))

    def gain(self, inp) -> float:
        return 1.0

    def tick(self, inp):
        if not inp.in_contact:
            return [ChannelCommand("buzz", frequency_hz=100.0, amplitude=0.0)]
        a = 0.25 * LAG_COIL_MAX_V * (0.2 + 0.8 * self.x) * min(1.0, self.speed(inp) / 100.0)
        return [ChannelCommand("buzz", frequency_hz=100.0, amplitude=a * self.gain(inp))]


class _FloatsOffByOne(_Slide):
    """Reads the normal component (index 1) from the floats, the sliding one from the array."""

    def speed(self, inp) -> float:
        vt = inp.velocity_floats_mm_s
        return abs(vt[1]) if vt is not None else abs(float(inp.velocity_mm_s[0]))


class _PlaneOnly(_Slide):
    """Scales by 1 / normal[1] (numpy: no exception, an infinity on a wall)."""

    def gain(self, inp) -> float:
        with np.errstate(divide="ignore"):
            return float(np.float64(1.0) / np.float64(abs(inp.normal[1])))


class _SoftGate(_Slide):
    """Fades in over one count's speed step above the gate, on the filtered speed when the
    loop gives a step, as ``(|v| - step) / |v|``: negative below one step."""

    def gain(self, inp) -> float:
        step, vf = inp.speed_step_mm_s, inp.velocity_filtered_mm_s
        if step <= 0.0 or vf is None:
            return 1.0
        return (abs(vf[0]) - step) / max(abs(vf[0]), 1e-9)


def test_a_renderer_reading_the_floats_and_the_array_alike_conforms(installed):
    v = check_dimension(buzz_dimension(_Slide))
    assert v == [], format_report(v)


@pytest.mark.parametrize("renderer, why", [
    (_FloatsOffByOne, "with TickInput.velocity_floats_mm_s set to the velocity's three numbers"),
    (_PlaneOnly, "at normal (1.0, 0.0, 0.0)"),
    (_SoftGate, "with a filtered velocity and speed step"),
], ids=["floats-path-reads-another-component", "divides-by-normal-y", "negative-below-one-speed-step"])
def test_renderers_broken_off_the_kit_s_old_ticks_are_caught(installed, renderer, why):
    v = check_dimension(buzz_dimension(renderer))
    assert rules_of(v) == {"renderer"}, format_report(v)
    assert why in format_report(v)


# ---------------------------------------------------------------------------
# dimensions: constraints of device-aware solving
# ---------------------------------------------------------------------------

def _with_device_constraint(bound_and_value):
    """kit-buzz whose device_constraints() gives ``bound_and_value(x, max_drive)`` (the
    default coil's largest drive, V) as one constraint on kit.b."""
    def device_constraints(self, capabilities, **options):
        cap = capabilities.get("buzz")
        if cap is None or cap.max_drive is None:
            return []
        drive = float(cap.max_drive)
        return [constraint("kit-buzz.drive", "kit.b", lambda x: bound_and_value(x, drive))()]
    return type("DeviceAware", (buzz_dimension(_Onset),), {"device_constraints": device_constraints})


def test_a_vectorised_device_constraint_conforms(installed):
    # x <= drive / 2.5: the coil's 2 V reach 0.8 of the scale
    dim = _with_device_constraint(lambda x, drive: (x, np.full_like(x, drive / 2.5)))
    v = check("dimension", dim, rules=["constraints-vectorised"])
    assert v == [], format_report(v)


def test_a_device_constraint_with_a_nan_bound_is_caught(installed):
    # a reach table looked up past its last entry (x > 0.9) gives NaN: read as met there
    dim = _with_device_constraint(lambda x, drive: (np.where(x <= 0.9, x, np.nan), np.full_like(x, drive / 2.5)))
    v = check_dimension(dim)
    assert rules_of(v) == {"constraints-vectorised"}, format_report(v)
    assert "constraint 'kit-buzz.drive': bound nan" in format_report(v)


# ---------------------------------------------------------------------------
# actuators: what capability_for() says it can produce
# ---------------------------------------------------------------------------

def _capable(band, drive, unit, label):
    """The lagging coil (30..300 Hz, 2 V) whose capability_for() gives ``band``, ``drive`` ``unit``."""
    from hapticsdk.devices.actuators import DriveCapability

    @classmethod
    def capability_for(cls, options=None):
        return DriveCapability(channel="vibration", frequency_range_hz=band, max_drive=drive, drive_unit=unit,
                               source=label)
    return type(f"Coil_{label}", (LagCoil,), {"__doc__": f"capability: {label}", "name": f"kit-lag-{label}",
                                             "capability_for": capability_for})


@pytest.mark.parametrize("band, drive, unit, label", [
    ((140.0, 260.0), 1.5, "V", "narrower-band"), ((30.0, 300.0), 2000.0, "mV", "same-drive-in-mV")])
def test_a_capability_within_the_limits_conforms(band, drive, unit, label):
    v = check("actuator", _capable(band, drive, unit, label), rules=["limits-declared"])
    assert v == [], format_report(v)


@pytest.mark.parametrize("band, drive, unit, label, why", [
    ((10.0, 1000.0), 2.0, "V", "wider-band", "beyond the declared frequency_range_hz 30..300 Hz"),
    ((30.0, 300.0), 3000.0, "mV", "larger-drive", "above the declared max_amplitude 2 V"),
    ((30.0, 300.0), 2.0, "N", "drive-in-newtons", "not a unit of the amplitude"),
])
def test_a_capability_beyond_the_limits_is_caught(band, drive, unit, label, why):
    v = check_actuator(_capable(band, drive, unit, label))
    assert rules_of(v) == {"limits-declared"}, format_report(v)
    assert why in format_report(v)


# ---------------------------------------------------------------------------
# models: the facts handed to the constraints
# ---------------------------------------------------------------------------

def _with_facts(facts):
    """BuzzModel carrying ``facts`` in its metadata (``df_hz`` and ``constraint_context``)."""
    def __init__(self):
        BuzzModel.__init__(self)
        self.metadata.update(facts)
    return type("FactsModel", (BuzzModel,), {"__init__": __init__})


def test_a_model_with_finite_facts_conforms(installed):
    v = check("model", _with_facts({"df_hz": 0.4, "constraint_context": {"kit.b_max": 0.9}}))
    assert v == [], format_report(v)


@pytest.mark.parametrize("facts", [{"df_hz": float("nan")}, {"df_hz": 0.0},
                                   {"constraint_context": {"kit.b_max": float("inf")}},
                                   {"constraint_context": {"kit.b_max": "high"}}],
                         ids=["df-nan", "df-zero", "context-inf", "context-text"])
def test_a_model_with_a_fact_that_is_no_finite_number_is_caught(installed, facts):
    v = check("model", _with_facts(facts))
    assert rules_of(v) == {"metadata"}, format_report(v)
    assert "metadata fact" in format_report(v)


# ---------------------------------------------------------------------------
# hook modules: what pluggy registers
# ---------------------------------------------------------------------------

def _wrapper_hooks(impl):
    import types
    from hapticsdk.hookspecs import hookimpl
    from kit_variants import API
    mod = types.ModuleType("kit_hooks_wrapper")
    mod.hapticsdk_api = API   # type: ignore[attr-defined]
    impl.__name__ = "hapticsdk_render_started"
    mod.hapticsdk_render_started = hookimpl(hookwrapper=True)(impl)   # type: ignore[attr-defined]
    return mod


def test_a_hookwrapper_that_is_a_generator_conforms():
    def started(plan):
        yield
    v = check("hooks", _wrapper_hooks(started))
    assert v == [], format_report(v)


def test_a_hookwrapper_that_is_not_a_generator_is_caught():
    def started(plan):
        return None
    v = check("hooks", _wrapper_hooks(started))
    assert rules_of(v) == {"hookimpls"}, format_report(v)
    assert "pluggy refuses to register the module" in format_report(v)


# ---------------------------------------------------------------------------
# dimensions: one renderer per renderer() call
# ---------------------------------------------------------------------------

def test_a_dimension_handing_out_cached_renderers_is_caught(installed):
    cache: dict[float, _Onset] = {}
    base = buzz_dimension(_Onset)

    def renderer(self, features, **options):
        made = base.renderer(self, features, **options)   # validates the features
        return cache.setdefault(made.x, made)
    v = check_dimension(type("Cached", (base,), {"renderer": renderer}))
    assert rules_of(v) == {"determinism"}, format_report(v)
    assert "or two objects of one material" in format_report(v)


# ---------------------------------------------------------------------------
# dimensions: a material's features, other dimensions' too
# ---------------------------------------------------------------------------

def test_a_renderer_refusing_other_dimensions_features_is_caught(installed):
    base = buzz_dimension(_Onset)

    def renderer(self, features, **options):
        unknown = sorted(set(features) - {f.name for f in self.features})
        if unknown:
            raise ValidationError(f"unknown features {unknown}", field="features")
        return base.renderer(self, features, **options)
    v = check_dimension(type("Strict", (base,), {"renderer": renderer}))
    assert rules_of(v) == {"renderer"}, format_report(v)
    assert "refused the features of a material that has another dimension too" in format_report(v)


def test_the_render_hands_a_renderer_the_material_s_other_features():
    """What the rule holds a renderer to: a material with hardness and roughness builds the
    hardness renderer from GS, W and the roughness features."""
    if not {"hardness", "roughness"} <= set(registry("dimension").names()):
        pytest.skip("hapticsdk-hardness and hapticsdk-roughness not installed")
    from hapticsdk.compiler import compile_scene
    from hapticsdk.runtime.render import build_renderers
    from hapticsdk.scene import Scene
    plan = compile_scene(Scene.for_material({"hardness": 0.3, "roughness": 0.8}))
    mp = next(iter(plan.materials.values()))
    assert {"GS", "Fpeak"} <= set(mp.features) and len(mp.dimensions) == 2, mp.features
    seen = []
    hardness = registry("dimension").load("hardness")
    original = hardness.renderer

    def spy(self, features, **options):
        seen.append(sorted(features))
        return original(self, features, **options)
    hardness.renderer = spy
    try:
        build_renderers(mp, plan.settings)
    finally:
        hardness.renderer = original
    assert seen and "Fpeak" in seen[0], seen


def _materials_hooks(answer):
    import types
    from hapticsdk.hookspecs import hookimpl
    from kit_variants import API
    mod = types.ModuleType("kit_hooks_materials")
    mod.hapticsdk_api = API   # type: ignore[attr-defined]
    answer.__name__ = "hapticsdk_materials"
    mod.hapticsdk_materials = hookimpl(answer)   # type: ignore[attr-defined]
    return mod


def test_materials_built_anew_on_each_call_conform():
    v = check("hooks", _materials_hooks(lambda: [{"name": "kit-fresh", "intensities": {"hardness": 0.5}}]))
    assert v == [], format_report(v)


def test_materials_added_to_a_kept_list_on_each_call_are_caught():
    kept: list[dict] = []

    def materials():
        kept.append({"name": "kit-kept", "intensities": {"hardness": 0.5}})
        return kept
    v = check("hooks", _materials_hooks(materials))
    assert rules_of(v) == {"hookimpls"}, format_report(v)
    assert "on the second call" in format_report(v)


# ---------------------------------------------------------------------------
# actuators: the safety settings are the application's
# ---------------------------------------------------------------------------

def _configuring(label, **settings):
    """:class:`OutputArm` whose ``_open`` reconfigures its own safety layer with ``settings``."""
    def _open(self) -> None:
        OutputArm._open(self)
        self.safety.configure(**settings)
    return type(f"Arm_{label}", (OutputArm,), {"__doc__": f"safety settings {settings} in _open",
                                              "name": f"kit-arm-{label}", "_open": _open})


def test_a_backend_loosening_its_safety_layer_is_caught():
    v = check_device(_configuring("no-ramp", ramp_time_s=0.0, start_max_force_n=None))
    assert rules_of(v) == {"template"}, format_report(v)
    assert "its safety layer's ramp_time_s is 0.0 after open(), looser than the default 0.2" in format_report(v)


def test_a_backend_tightening_its_safety_layer_conforms():
    v = check("device", _configuring("longer-ramp", ramp_time_s=0.4, start_max_force_n=0.5), rules=["template"])
    assert v == [], format_report(v)
