"""The rules of the ``dimension`` kind (``RULES['dimension']``): class, features, roles, the
constraints (vectorised, their one-row float path against their array path, their cost
against a per-row reference, feasible), the model
match, the renderer (its commands, bad input, determinism under moved clocks, timing and
its growth over a run), and the force a renderer commands against its actuator's limit."""

from __future__ import annotations

import functools
import json
import math
import time
from dataclasses import fields, replace
from typing import Any, Callable, Mapping

import numpy as np

from ...devices.actuators import ActuatorLimits
from ...devices.safety import SafetySettings
from ...errors import ValidationError
from ...perception.dimensions import (ChannelCommand, Constraint, DimensionRenderer, PerceptionDimension, TickInput,
                                      _steady_law_of)
from ...perception.features import Feature, FeatureSpace
from ...perception.models import PerceptionModel
from .actuator_drive import STALL_RUN_S
from .memory import _traced_after
from .runner import _Ctx, _run_rules
from .timing import KIT_PERIOD_S, TICK_BUDGET, TIMING_CALLS, _fastest, _perf_counter, _sim_advance
from .values import _finite, _refuses


#: a renderer's force in contact may exceed its default actuator's max_force_n (which
#: the safety layer clamps) up to this factor at penetrations <= 3 mm; a multiple of it
#: is a unit or formula error, not a stiff material. The same factor bounds an amplitude
#: in any other unit against the actuator's max_amplitude in that unit (a decade: a
#: renderer may drive into saturation on purpose, while a slip of a unit prefix, mV for
#: V, is a factor of 1000)
FORCE_PLAUSIBILITY_FACTOR = 10.0


def _force_limit(d: Any, role: str, spec: Any) -> tuple[str | None, float | None]:
    """``(field, N)``: the command field that carries force on ``role`` (``force_n``, or a
    field whose declared unit is a force: a friction plate's amplitude in N) and the largest
    force the role's default actuator declares (``max_force_n``, or ``max_amplitude`` when
    its amplitude is a force); ``(None, None)`` when the role carries no force."""
    from ...plugins import registry
    from ...units import is_force_unit
    fields = dict(getattr(spec, "fields", {}) or {})
    field = "force_n" if ("force_n" in fields or not fields) else \
        next((f for f, u in fields.items() if is_force_unit(u)), None)
    if field is None:
        return None, None
    name = d.default_actuators.get(role)
    if name is None or name not in registry("actuator"):
        return field, None
    lim = getattr(registry("actuator").load(name), "limits", ActuatorLimits())
    if field == "force_n":
        return field, lim.max_force_n if lim.max_force_n is not None else \
            (lim.max_amplitude if is_force_unit(lim.amplitude_unit) else None)
    return field, lim.max_amplitude if is_force_unit(lim.amplitude_unit) else lim.max_force_n


def _amplitude_limit(d: Any, role: str, spec: Any) -> float | None:
    """The largest amplitude the default actuator of ``role`` declares (``max_amplitude``)
    when the role's amplitude is not a force (:func:`_force_limit` judges those) and is in
    the actuator's amplitude unit; None otherwise (no amplitude, no default actuator, or
    units the kit cannot compare)."""
    from ...perception.features import same_unit
    from ...plugins import registry
    from ...units import is_force_unit
    unit = dict(getattr(spec, "fields", {}) or {}).get("amplitude")
    name = d.default_actuators.get(role)
    if unit is None or is_force_unit(unit) or name is None or name not in registry("actuator"):
        return None
    lim = getattr(registry("actuator").load(name), "limits", ActuatorLimits())
    if lim.max_amplitude is None or not lim.amplitude_unit or not same_unit(unit, lim.amplitude_unit):
        return None
    return float(lim.max_amplitude)


#: rows of the constraint-cost rule's batch, and the limit: one ``penalty`` batch may take
#: at most ``COST_FACTOR`` x a per-row reference on the same rows, a Python loop doing one
#: operation per row (``[v * 0.5 for v in rows]``, rows a list of floats made beforehand),
#: both timed in the same process (interleaved, fastest of :data:`COST_REPEATS`). Why that
#: reference and 1: a row-by-row constraint does at least that loop, plus reading its rows
#: out of the columns and building the result arrays, so it costs more than the reference
#: whatever the machine and its load (both sides are interpreted loops over the same rows);
#: a vectorised constraint runs a fixed number of array operations whose cost per element
#: is that of compiled code, ~5-10 x below an interpreted operation, so one with up to
#: ~30 array operations stays below it. Measured (2-core machine, load 2-3, 10 runs each):
#: the first-party constraints 0.08-0.27 x, a vectorised constraint of 160 array operations
#: 4.1 x; per-row constraints: ``x.tolist()`` read into a list comprehension 2.1 x,
#: ``np.fromiter`` over a generator 2.3 x, comprehensions over the array's numpy scalars 6 x.
#: The limit sits near the geometric midpoint of the first party's worst (0.27) and the
#: cheapest loop (2.1): a margin of ~2 x or more on either side. (It was 20 x a vectorised
#: reference of the base class's penalty arithmetic: a ratio of a loop to a few array
#: operations, which moved with the machine's load (33-87 x for the same loop) and let
#: the cheapest loops, at ~20 x, through.)
COST_ROWS = 10_000
COST_FACTOR = 1.0
#: repeats of the cost rule's timing (the fastest counts, interleaved with the reference)
COST_REPEATS = 5


def _cost_ratio(c: Constraint, cols: Mapping[str, np.ndarray]) -> tuple[float, float, float]:
    """(ratio, constraint s, reference s): fastest-of-:data:`COST_REPEATS` time of one
    ``penalty`` batch over that of the per-row reference (one Python operation per row of
    a column the constraint reads; :data:`COST_FACTOR`), interleaved. Stops early when a
    timing is clearly within the limit."""
    name = next((f for f in c.features if f in cols), next(iter(cols)))
    rows = np.asarray(cols[name], float).tolist()

    best_c, best_r = math.inf, math.inf
    for i in range(COST_REPEATS):
        t0 = _perf_counter()
        [v * 0.5 for v in rows]
        t1 = _perf_counter()
        c.penalty(cols, "paper")
        t2 = _perf_counter()
        best_r, best_c = min(best_r, t1 - t0), min(best_c, t2 - t1)
        if i >= 1 and best_c <= 0.5 * COST_FACTOR * best_r:
            break
    return best_c / max(best_r, 1e-9), best_c, best_r


def _tick_inputs(read_only: bool = False) -> list[TickInput]:
    """The kit's ticks: out of contact, at the surface, pressing and sliding, leaving. With
    ``read_only`` the velocity arrays cannot be written (as the servo loop hands them)."""
    out = []
    for i, (pen, vx) in enumerate([(-1.0, 0.0), (0.0, 0.0), (0.5, 0.0), (1.5, 10.0), (2.0, 80.0),
                                   (2.0, -150.0), (1.0, 25.0), (3.0, 400.0), (-0.2, 80.0)]):
        v = np.array([vx, -5.0 * (i % 3 - 1), 0.0])
        v.flags.writeable = not read_only
        out.append(TickInput(t=i * 1e-3, dt=1e-3, penetration_mm=pen, velocity_mm_s=v, in_contact=pen > 0))
    return out


def _input_fields(inp: TickInput) -> dict[str, Any]:
    """What a renderer reads of a tick input, by value (arrays as lists)."""
    return {f.name: (lambda v: np.asarray(v).tolist() if isinstance(v, np.ndarray) else v)(getattr(inp, f.name))
            for f in fields(inp)}


def _tick_unchanged(r: DimensionRenderer, inp: TickInput) -> list[ChannelCommand]:
    """``r.tick(inp)``, failing when the renderer changed its input: wrote into a read-only
    array (a ``ValueError`` naming it) or changed a field. The servo loop hands one
    ``TickInput`` to every renderer of a material, in turn: a change is what the next one
    reads."""
    before = _input_fields(inp)
    try:
        cmds = r.tick(inp)
    except ValueError as exc:
        if "read-only" not in str(exc):
            raise
        raise AssertionError(f"tick() wrote into its TickInput in place ({exc}): the servo loop hands one "
                             f"TickInput to every renderer of the material, and its arrays are read-only; "
                             f"compute on a copy (`v = inp.velocity_mm_s * 1e-3`)") from None
    after = _input_fields(inp)
    changed = {k: (before[k], after[k]) for k in before if before[k] != after[k]}
    assert not changed, (f"tick() changed its TickInput ({'; '.join(f'{k}: {a!r} -> {b!r}' for k, (a, b) in changed.items())}): "
                         f"the servo loop hands one TickInput to every renderer of the material, so the next "
                         f"renderer reads the changed values; compute on copies")
    return cmds


_TICKS = _tick_inputs()

#: penetrations (mm) and speeds (mm/s) of the ``renderer`` rule's sweep: the kit's ticks
#: stop at 3 mm and 400 mm/s, but the servo loop hands a renderer what the device
#: measures, bounded by nothing the renderer can rely on (a stylus pushed through a thin
#: wall, a fast flick, an encoder glitch); the safety layer limits what reaches the
#: actuator, not what the renderer is asked. Decades from 1 um to 1 m and from 1 um/s to
#: 100 m/s, each sign, on each axis
SWEEP_PENETRATIONS_MM = tuple(float(10.0 ** e) for e in range(-3, 4))
SWEEP_SPEEDS_MM_S = (0.0,) + tuple(float(10.0 ** e) for e in range(-3, 6))
#: servo time (s) of the ``renderer`` rule's long run: one renderer ticked through the
#: kit's ticks and the sweep in turn, every command checked (a command that turns
#: non-finite only after more ticks than this goes unseen)
RENDER_RUN_S = 8.0


@functools.lru_cache(maxsize=1)
def _sweep_inputs() -> tuple[TickInput, ...]:
    """Ticks at every penetration of :data:`SWEEP_PENETRATIONS_MM` (and as far out of
    contact) with the speed along each axis, both signs, at every speed of
    :data:`SWEEP_SPEEDS_MM_S`; read-only velocity arrays, times 1 ms apart."""
    out: list[TickInput] = []
    for pen in SWEEP_PENETRATIONS_MM + tuple(-p for p in SWEEP_PENETRATIONS_MM):
        for speed in SWEEP_SPEEDS_MM_S:
            for axis in range(3):
                for sign in (1.0, -1.0):
                    v = np.zeros(3)
                    v[axis] = sign * speed
                    v.flags.writeable = False
                    out.append(TickInput(t=len(out) * KIT_PERIOD_S, dt=KIT_PERIOD_S, penetration_mm=pen,
                                         velocity_mm_s=v, in_contact=pen > 0))
    return tuple(out)




def _check_commands(cmds: Any, inp: TickInput, r: DimensionRenderer, specs: Mapping[str, Any], where: str) -> None:
    """The ``renderer`` rule's checks of what one tick returned (``where`` says which tick)."""
    assert isinstance(cmds, list), "tick() must return a list of ChannelCommand"
    for c in cmds:
        assert isinstance(c, ChannelCommand), f"tick() returned {c!r}"
        assert c.role in r.roles, f"tick() commanded role {c.role!r} not in roles {r.roles}"
        for k in ("force_n", "frequency_hz", "amplitude"):
            assert _finite(getattr(c, k)), f"tick() returned {k}={getattr(c, k)!r} {where}"
        if c.amplitude is not None:
            assert c.amplitude >= 0, f"negative amplitude {c.amplitude} {where}"
    if not inp.in_contact:
        for c in cmds:
            assert not c.force_n, f"force {c.force_n} N commanded out of contact {where}"
            spec = specs.get(c.role)
            assert not (getattr(spec, "channel", None) == "vibration" and c.amplitude), \
                (f"amplitude {c.amplitude:g} commanded on the vibration role {c.role!r} out of contact "
                 f"{where}: nothing touches the surface, "
                 f"so nothing may vibrate; the loop sends amplitude 0 on it away from every object")


#: contact normals (unit vectors, device coordinates) the ``renderer`` rule ticks a renderer
#: at besides the version-1 plane's +y (``TickInput.normal``, the normal of the face under
#: the probe in a spatial scene): a wall facing +x, an object's underside, a slanted face,
#: a wall facing +z
RENDER_NORMALS = ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.6, 0.8, 0.0), (0.0, 0.0, 1.0))


#: a feature of another dimension the ``renderer`` rule adds to a renderer's features (the
#: render hands each renderer all of the material's solved features)
OTHER_FEATURE = "kit-other-dimension.feature"

#: speed steps (mm/s) of one encoder count (``TickInput.speed_step_mm_s``: ``a q / dt``)
#: the ``renderer`` rule ticks with, the filtered velocity given: a fine encoder at 1 kHz
#: (q = 1 um, a = 0.17: 0.17 mm/s) and a coarse one (q = 0.05 mm: 9 mm/s) and beyond
#: (50 mm/s: the count-level chatter the filter is there for)
ENCODER_SPEED_STEPS_MM_S = (0.17, 9.0, 50.0)


def _values(cmds: Any) -> list[tuple[Any, ...]]:
    """A tick's commands as values (role, force, frequency, amplitude)."""
    return [(c.role, c.force_n, c.frequency_hz, c.amplitude) for c in cmds]


def _same_values(a: list[tuple[Any, ...]], b: list[tuple[Any, ...]]) -> bool:
    """Whether two ticks' commands (:func:`_values`) are the same: the same roles in the same
    order and each field None in both or equal within float rounding (1e-9 relative: one
    path may compute with numpy scalars, the other with floats)."""
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):
        if x[0] != y[0]:
            return False
        for u, v in zip(x[1:], y[1:]):
            if (u is None) != (v is None):
                return False
            if u is not None and not (u == v or abs(u - v) <= 1e-9 * max(abs(u), abs(v))):
                return False
    return True


def _floats_path_difference(d: PerceptionDimension, feats: Mapping[str, float]) -> str | None:
    """Where two new renderers of ``feats`` differ, one ticked through the kit's ticks and
    the sweep as given (``velocity_floats_mm_s`` None: the velocity is read from the
    array), then one (made after that run) through the same ticks with
    ``velocity_floats_mm_s`` the array's three numbers (as the servo loop gives them), as
    text; None when every tick agrees."""
    ticks = _TICKS + list(_sweep_inputs())
    plain = d.renderer(dict(feats))
    without = [_values(plain.tick(inp)) for inp in ticks]
    floats = d.renderer(dict(feats))   # made after the first run: one renderer alive at a time
    for k, (inp, a) in enumerate(zip(ticks, without)):
        v = np.asarray(inp.velocity_mm_s, float)
        b = _values(floats.tick(replace(inp, velocity_floats_mm_s=(float(v[0]), float(v[1]), float(v[2])))))
        if not _same_values(a, b):
            return f"{b} with the floats against {a} without ({_where(inp, feats, k)})"
    return None


@functools.lru_cache(maxsize=1)
def _law_inputs() -> tuple[TickInput, ...]:
    """The ticks the ``renderer-fast-law`` rule runs: the kit's ticks and the sweep, as the
    servo loop hands them (the velocity also as plain floats, a filtered velocity, the speed
    step of one count: 0 and each of :data:`ENCODER_SPEED_STEPS_MM_S`), in one run; built
    once (the inputs' arrays are read-only, and the kit fails a renderer that changes them)."""
    out = []
    for step in (0.0,) + ENCODER_SPEED_STEPS_MM_S:
        for inp in _TICKS + list(_sweep_inputs()):
            v = np.asarray(inp.velocity_mm_s, float)
            w = (float(v[0]), float(v[1]), float(v[2]))
            out.append(replace(inp, velocity_floats_mm_s=w, velocity_filtered_mm_s=w, speed_step_mm_s=step))
    return tuple(out)


def _bits(x: Any) -> Any:
    """A command field as the servo loop logs it, for an exact comparison: None, or the
    float's hex text (so -0.0 and 0.0, and every NaN payload's sign, are told apart)."""
    return None if x is None else float(x).hex()


def _law_call(law: Any, inp: TickInput) -> Any:
    """``law`` on ``inp``'s fields, as the servo loop calls it."""
    w, f = inp.velocity_floats_mm_s, inp.velocity_filtered_mm_s
    assert w is not None and f is not None, "the kit's law inputs carry both velocities"
    return law(inp.t, inp.dt, inp.penetration_mm, inp.in_contact, w[0], w[1], w[2], f[0], f[1], f[2],
               inp.speed_step_mm_s)


def _tick_as_law(r: DimensionRenderer, cmds: Any, where: str) -> tuple[Any, ...]:
    """What a law standing for ``r.tick`` must return for the commands ``cmds``: the
    ``force_n, frequency_hz, amplitude`` of the one command of each role of ``r.roles``."""
    out: list[Any] = []
    for role in r.roles:
        mine = [c for c in cmds if c.role == role]
        assert len(mine) == 1, \
            (f"_fast_law() is offered, but tick() returned {len(mine)} commands for role {role!r} ({where}): a law "
             f"gives the fields of exactly one command per role, so offer it only where tick() always returns one "
             f"command per role")
        c = mine[0]
        out += [c.force_n, c.frequency_hz, c.amplitude]
    return tuple(out)


def _fast_law_difference(d: PerceptionDimension, feats: Mapping[str, float]) -> str | None:
    """Where a renderer's law on plain floats (``_fast_law``, which the servo loop runs
    instead of ``tick`` in its steady state) differs from ``tick`` on the same ticks, as
    text; None when the renderer offers no law or every tick agrees bit for bit. Three new
    renderers of ``feats`` run :func:`_law_inputs`: one through ``tick`` alone, one through
    its law alone, one through ``tick`` and its law in turn (the loop mixes them tick by
    tick, so whatever the renderer keeps between ticks must be shared)."""
    ref = d.renderer(dict(feats))
    if _steady_law_of(ref) is None:
        return None
    runs = [("its law alone", d.renderer(dict(feats)), lambda k: True),
            ("tick() and its law in turn", d.renderer(dict(feats)), lambda k: k % 2 == 1)]
    laws = [_steady_law_of(r) for _, r, _ in runs]
    for (label, r, _), law in zip(runs, laws):
        assert callable(law), f"_fast_law() returned {law!r}, not None or a callable ({label})"
    n = 3 * len(ref.roles)
    for k, inp in enumerate(_law_inputs()):
        where = _where(inp, feats, k)
        want = _tick_as_law(ref, ref.tick(inp), where)
        for (label, r, use_law), law in zip(runs, laws):
            if use_law(k):
                try:
                    got = tuple(_law_call(law, inp))
                except Exception as exc:   # noqa: BLE001 - reported as the rule's finding
                    return f"the law raised {type(exc).__name__}: {exc} where tick() did not, {label} {where}"
                if len(got) != n:
                    return (f"the law returned {len(got)} values, not 3 per role of {tuple(ref.roles)} ({n}) "
                            f"{label} {where}")
            else:
                got = _tick_as_law(r, r.tick(inp), where)
            if [_bits(x) for x in got] != [_bits(x) for x in want]:
                return f"{got} from {label} against {want} from tick() alone {where}"
    return None


def _device_constraints(d: PerceptionDimension) -> list[Constraint]:
    """``d.device_constraints`` for the capabilities of its installed default actuators
    (``capability_for(None)`` of each role's class; roles without one left out), with the
    renderer options ``capability_options`` takes from them, as the compiler calls it for a
    scene that maps the defaults; [] when no role has a capability. A list is required."""
    from ...plugins import registry
    caps: dict[str, Any] = {}
    for role, name in d.default_actuators.items():
        if name in registry("actuator"):
            cap = registry("actuator").load(name).capability_for(None)
            if cap is not None:
                caps[role] = cap
    if not caps:
        return []
    out = d.device_constraints(caps, **d.capability_options(caps))
    assert isinstance(out, list), \
        f"device_constraints() returned {type(out).__name__}, not a list (of the default actuators' capabilities {caps})"
    return out


def _where(inp: TickInput, feats: Mapping[str, float], k: int | None = None) -> str:
    """Which tick: penetration, velocity, features (and its index in a run)."""
    at = f"at tick {k + 1} of a run, " if k is not None else ""
    return (f"({at}penetration {inp.penetration_mm:g} mm, velocity {np.asarray(inp.velocity_mm_s).tolist()} mm/s, "
            f"{dict(feats)})")


def _commands_of(d: PerceptionDimension, feats: Mapping[str, float]) -> list[Any]:
    """The commands of a new renderer of ``feats`` over the kit's ticks, as values."""
    r = d.renderer(dict(feats))
    return [_values(r.tick(i)) for i in _tick_inputs()]


def _commands_side_by_side(d: PerceptionDimension, a: Mapping[str, float], b: Mapping[str, float]
                           ) -> tuple[list[Any], list[Any]]:
    """The commands (as :func:`_commands_of`) of two new renderers, of ``a`` and of ``b``,
    both alive and ticked in turn over the kit's ticks, as the servo loop ticks the
    renderers of a scene."""
    ra, rb = d.renderer(dict(a)), d.renderer(dict(b))
    out: tuple[list[Any], list[Any]] = ([], [])
    for i in _tick_inputs():
        for r, o in ((ra, out[0]), (rb, out[1])):
            o.append(_values(r.tick(i)))
    return out


def _first_difference(got: list[Any], want: list[Any]) -> str:
    """Where two lists of per-tick commands (:func:`_commands_of`) first differ, as text."""
    for k, (g, w) in enumerate(zip(got, want)):
        if g != w:
            return f"{g} at tick {k + 1} against {w}"
    return f"{len(got)} ticks against {len(want)}"


#: epochs (s) the dimension ``determinism`` rule sets the process clocks to while a
#: renderer ticks (each tick reads epoch + its TickInput.t): 8 drawn uniformly from
#: 0..2e9 s (1970-2033) with a fixed seed, so a command that depends on the absolute wall
#: time through any bucket from milliseconds to seasons (a value that flips every 0.5 s,
#: every other hour, in summer) differs between them or from the real clock's (a
#: two-valued bucket agrees with all 8 by chance once in 2^8), while a renderer reading
#: only differences of the clock sees the same
CLOCK_EPOCHS_S = tuple(float(e) for e in np.random.default_rng(2025).uniform(0.0, 2e9, 8))
_CLOCKS = ("time", "monotonic", "perf_counter")


def _commands_at_epoch(d: PerceptionDimension, feats: Mapping[str, float], epoch: float) -> list[Any]:
    """:func:`_commands_of` with ``time.time``, ``time.monotonic`` and ``time.perf_counter``
    (and their ``_ns`` forms, and ``time.localtime()`` / ``time.gmtime()`` without an
    argument) reading ``epoch`` + the tick's ``t`` (the wall clock at another epoch,
    advancing as the ticks do). Names bound at import (``from time import time``) and
    ``datetime.now()`` are not moved."""
    now = [epoch]
    saved = {n: getattr(time, n) for n in _CLOCKS + tuple(c + "_ns" for c in _CLOCKS) + ("localtime", "gmtime")}
    fake: dict[str, Callable[..., Any]] = {}
    for c in _CLOCKS:
        fake[c] = lambda: now[0]
        fake[c + "_ns"] = lambda: int(now[0] * 1e9)
    for c in ("localtime", "gmtime"):
        fake[c] = lambda secs=None, _f=saved[c]: _f(now[0] if secs is None else secs)
    r = d.renderer(dict(feats))
    out = []
    try:
        for n, f in fake.items():
            setattr(time, n, f)
        for inp in _tick_inputs():
            now[0] = epoch + inp.t
            out.append(_values(r.tick(inp)))
    finally:
        for n, f in saved.items():
            setattr(time, n, f)
    return out


#: servo periods (s) the ``determinism`` rule ticks one scene at: the kit's 1 ms and a
#: quarter of it (a scene's ``servo.period_s`` may be anything from 0.1 ms to 100 ms,
#: :data:`hapticsdk.scene.limits.PERIOD_RANGE_S`). A renderer that advances an envelope, a
#: ramp or an oscillator's phase by a fixed step per call, not by ``dt``, plays the scene
#: 4 x faster at the second
PERIODS_S = (1e-3, 2.5e-4)
#: servo time (s) of that scene: 10 ms out of contact, 300 ms pressing and sliding (depth
#: 0.5..1.5 mm, sliding 30..110 mm/s, both smooth), 20 ms out, 100 ms in again; every
#: change of contact on a whole millisecond, so both periods tick it at the same time
PERIOD_SCENE_S = 0.43
_PERIOD_CONTACTS_S = ((0.01, 0.31), (0.33, 0.43))


def _period_scene(period_s: float) -> list[TickInput]:
    """The ticks of the ``determinism`` rule's period scene at ``period_s`` (a whole
    fraction of :data:`KIT_PERIOD_S`): tick ``k`` at ``t = k * period_s``, with ``dt =
    period_s``, its depth and velocity functions of ``t`` alone (read-only arrays, the
    floats and the filtered velocity too, as the loop gives them)."""
    out = []
    for k in range(int(round(PERIOD_SCENE_S / period_s))):
        t = k * period_s
        ms = k * period_s * 1e3
        touching = any(a * 1e3 - 1e-6 <= ms < b * 1e3 - 1e-6 for a, b in _PERIOD_CONTACTS_S)
        pen = 1.0 + 0.5 * math.sin(2 * math.pi * 2.0 * t) if touching else -0.5
        vel = (70.0 + 40.0 * math.sin(2 * math.pi * 1.5 * t), -0.5 * 2 * math.pi * 2.0 * math.cos(2 * math.pi * 2.0 * t),
               0.0)
        v = np.array(vel)
        v.flags.writeable = False
        out.append(TickInput(t=t, dt=period_s, penetration_mm=pen, velocity_mm_s=v, in_contact=touching,
                             velocity_filtered_mm_s=vel, velocity_floats_mm_s=vel))
    return out


def _period_run(d: PerceptionDimension, feats: Mapping[str, float], period_s: float
                ) -> tuple[list[TickInput], list[dict[tuple[str, str], float]]]:
    """The period scene at ``period_s`` and, per tick, a new renderer's numeric command
    fields (``(role, field) -> value``)."""
    ticks = _period_scene(period_s)
    r = d.renderer(dict(feats))
    out = []
    for inp in ticks:
        row: dict[tuple[str, str], float] = {}
        for c in r.tick(inp):
            for k in ("force_n", "frequency_hz", "amplitude"):
                v = getattr(c, k)
                if v is not None:
                    row[(c.role, k)] = float(v)
        out.append(row)
        _sim_advance(period_s)
    return ticks, out


def _fastest_change(ticks: list[TickInput], rows: list[dict[tuple[str, str], float]]) -> dict[tuple[str, str], float]:
    """Per command field, the largest change between two consecutive ticks of one contact
    (a change at the start or end of a contact is the scene's, not the renderer's pace)."""
    out: dict[tuple[str, str], float] = {}
    for i in range(1, len(rows)):
        if ticks[i].in_contact != ticks[i - 1].in_contact:
            continue
        for key, v in rows[i].items():
            u = rows[i - 1].get(key)
            if u is not None and math.isfinite(u) and math.isfinite(v):
                out[key] = max(out.get(key, 0.0), abs(v - u))
    return out


def _period_difference(d: PerceptionDimension, feats: Mapping[str, float]) -> str | None:
    """Where the commands of the period scene at the two periods of :data:`PERIODS_S`
    differ, at the times both tick, by more than a renderer that follows ``dt`` can, as
    text; None when they agree.

    A renderer that follows time renders, at each period, the same commands as functions
    of time, each tick at most one period late (an event seen at the next tick, a state
    integrated step by step lags or leads by at most that), so each run is within one of
    its own ticks' largest change of that function, and the two runs are within the sum
    of the two: the tolerance per field is its largest change between consecutive ticks
    of a contact in the one run plus that in the other (plus 1e-9 of its scale for
    rounding). A renderer stepping per call changes by the same step per tick at both
    periods, so the tolerance stays one or two steps while the runs drift apart: after n
    ticks of the coarse period the fine run is where the coarse one is after 4 n."""
    coarse, fine = PERIODS_S
    every = int(round(coarse / fine))
    ta, ra = _period_run(d, feats, coarse)
    tb, rb = _period_run(d, feats, fine)
    tol = _fastest_change(ta, ra)
    for key, v in _fastest_change(tb, rb).items():
        tol[key] = tol.get(key, 0.0) + v
    for i, (inp, a) in enumerate(zip(ta, ra)):
        b = rb[i * every] if i * every < len(rb) else {}
        for key, va in a.items():
            vb = b.get(key)
            if vb is None or not (math.isfinite(va) and math.isfinite(vb)):
                continue
            allowed = tol.get(key, 0.0) + 1e-9 * max(1.0, abs(va), abs(vb))
            if abs(va - vb) > allowed:
                return (f"{key[0]} {key[1]} {va:.6g} at {coarse * 1e3:g} ms and {vb:.6g} at {fine * 1e3:g} ms "
                        f"at t = {inp.t:.4g} s ({'in' if inp.in_contact else 'out of'} contact), {abs(va - vb):.3g} "
                        f"apart; one tick of its fastest change at each period allows {allowed:.3g}")
    return None


#: servo time (s) of the ``timing`` rule's long run of one renderer, and where its tick
#: cost is measured (fastest of :data:`TIMING_CALLS`): after 1, 2, 4 and 8 s
GROWTH_POINTS_S = (1.0, 2.0, 4.0, 8.0)
#: the cost at the last point over the cost at the first that, with the growth exponent
#: at least :data:`GROWTH_EXPONENT`, fails the rule. A cost proportional to the history
#: rises ~8 x from 1 s to 8 s; the fastest of 25 calls of an unchanged tick moves by far
#: less than 2 x between two samples (the first-party renderers: see
#: docs/plugin-authors.md); a state bounded in time (filters, buffers under 1 s) costs the
#: same at every point
GROWTH_FACTOR = 2.0
#: the least growth exponent (least-squares slope of log cost over log run length at
#: :data:`GROWTH_POINTS_S`) of a cost that grows with the run. A cost proportional to the
#: history plus a fixed part has an exponent a little under 1 (0.59-0.85 measured on a
#: renderer taking the median of every input so far). An unchanged renderer whose fastest
#: tick jumps once by a factor r between two of the four points (a change of memory
#: regime: 1.8-1.9 x seen) reaches at most 0.4 log2(r): 0.4 at r = 2 (a step between the
#: 2 s and 4 s points; 0.3 between the others). A half separates the two. Every point
#: rising is not asked for: one jump back down in a growing cost (seen: 152 -> 150 us
#: from 4 s to 8 s, then 285 us in the next run) hid the growth once in 12 runs.
GROWTH_EXPONENT = 0.5


def _run_inputs(k: int) -> TickInput:
    """Kit tick ``k`` of a long run: the kit's ticks in turn, its time ``k`` periods."""
    base = _TICKS[k % len(_TICKS)]
    return TickInput(t=k * KIT_PERIOD_S, dt=KIT_PERIOD_S, penetration_mm=base.penetration_mm,
                     velocity_mm_s=base.velocity_mm_s.copy(), in_contact=base.in_contact)


def _growth_exponent(points: list[tuple[float, float]]) -> float:
    """Least-squares slope of log(cost) over log(run length) of :func:`_cost_growth`'s
    points (1 for a cost proportional to the run's length, 0 for a constant one)."""
    s, c = np.asarray(points, dtype=float).T
    return float(np.polyfit(np.log(s), np.log(np.maximum(c, 1e-12)), 1)[0])


def _grows(points: list[tuple[float, float]]) -> bool:
    """Whether the cost of :func:`_cost_growth`'s points grows with the run: the last at
    :data:`GROWTH_FACTOR` x or more of the first, and the growth exponent at least
    :data:`GROWTH_EXPONENT`."""
    costs = [c for _, c in points]
    return costs[-1] >= GROWTH_FACTOR * costs[0] and _growth_exponent(points) >= GROWTH_EXPONENT


def _tick_stalls(r: DimensionRenderer, limit_s: float) -> list[tuple[int, float]]:
    """(index, wall s) of the ticks of a run of :data:`STALL_RUN_S` of the kit's ticks
    (simulated time advancing) that took longer than ``limit_s``: as the actuators'
    ``timing`` rule times every ``command()``."""
    out = []
    for k in range(int(round(STALL_RUN_S / KIT_PERIOD_S))):
        inp = _run_inputs(k)
        t0 = _perf_counter()
        r.tick(inp)
        d = _perf_counter() - t0
        if d > limit_s:
            out.append((k, d))
        _sim_advance(KIT_PERIOD_S)
    return out


def _cost_growth(make: Callable[[], DimensionRenderer]) -> list[tuple[float, float]]:
    """(run length s, fastest tick s) at :data:`GROWTH_POINTS_S`: one renderer from
    ``make`` per point, each ticked through the kit's ticks for that long; then the
    renderers are timed in turn, one tick each per round, for :data:`TIMING_CALLS` rounds
    (the order rotating), and the fastest tick of each counts.

    The rounds pair the points in time: a slow spell of the machine (another process, a
    change of memory or frequency regime) lasting a few ticks slows every point alike
    instead of the one point measured then. Timed one point after the other (before the
    rounds), a spell covering the 25 consecutive ticks of the 1 s point nearly doubled it (47 us
    against 26 us in 1 run of 10 on a quiet machine) and hid a growing renderer once in a
    README suite run."""
    rs = [make() for _ in GROWTH_POINTS_S]
    ks = [int(round(at / KIT_PERIOD_S)) for at in GROWTH_POINTS_S]
    for r, n in zip(rs, ks):
        for k in range(n):
            r.tick(_run_inputs(k))
            _sim_advance(KIT_PERIOD_S)
    best = [math.inf] * len(rs)
    for i in range(TIMING_CALLS):
        for j in range(len(rs)):
            p = (i + j) % len(rs)
            inp = _run_inputs(ks[p])
            t0 = _perf_counter()
            rs[p].tick(inp)
            t1 = _perf_counter()
            ks[p] += 1
            best[p] = min(best[p], t1 - t0)
            _sim_advance(KIT_PERIOD_S)
    return list(zip(GROWTH_POINTS_S, best))


#: servo time (s) at which the ``renderer`` rule reads the memory a renderer holds: after
#: the first second (state bounded in time, a filter or a buffer of up to 1 s, is full by
#: then) and every 2 s after, to 9 s
MEMORY_POINTS_S = (1.0, 3.0, 5.0, 7.0, 9.0)
#: a renderer whose memory grows over every interval of :data:`MEMORY_POINTS_S` by this
#: many bytes per tick of the interval or more fails: at one byte a tick a render of
#: ``hapticsdk.scene.limits.MAX_SECONDS`` (24 h) at 1 kHz holds 86 MB more at its end, and
#: a Python object kept per tick (a float in a list) takes 30 or more. The first-party
#: renderers hold the same memory at every point but for a few dozen bytes an interval
#: (0.016 B per tick); a bounded buffer that fills before the last interval passes
MEMORY_GROWTH_BYTES_PER_TICK = 1.0


def _memory_growth(make: Callable[[], DimensionRenderer]) -> list[int]:
    """The memory (bytes, ``tracemalloc``) one renderer from ``make`` holds at each of
    :data:`MEMORY_POINTS_S` of a run through the kit's ticks."""
    r = make()

    def step(k: int) -> None:
        r.tick(_run_inputs(k))
        _sim_advance(KIT_PERIOD_S)
    return _traced_after([int(round(at / KIT_PERIOD_S)) for at in MEMORY_POINTS_S], step)


def _assert_follows_features(d: PerceptionDimension, mid: Mapping[str, float]) -> None:
    """A renderer's commands change with what it renders: each of ``render_features`` (all
    features together when the dimension declares none) set to its declared lower bound,
    middle and upper bound must change the commands over the kit's ticks, with the other
    features at the middle, at their lower or at their upper bounds (one of the three
    suffices: a feature may act only where another lets it, and a renderer may clamp at
    one end)."""
    lo = {f.name: float(f.lower) for f in d.features}
    hi = {f.name: float(f.upper) for f in d.features}
    bases = (dict(mid), lo, hi)
    names = [n for n in d.render_features if n in lo]
    if not names:
        outs = [_commands_of(d, b) for b in (lo, mid, hi)]
        assert outs[0] != outs[1] or outs[1] != outs[2], \
            ("its commands are the same with every feature at its lower bound, middle and upper bound: the "
             "renderer ignores the features it is given (declare the ones it renders in render_features)")
        return
    for n in names:
        for base in bases:
            outs = [_commands_of(d, {**base, n: v}) for v in (lo[n], mid[n], hi[n])]
            if outs[0] != outs[1] or outs[1] != outs[2]:
                break
        else:
            raise AssertionError(f"its commands do not change when the render feature {n!r} goes over its declared "
                                 f"range ({lo[n]:g}, {mid[n]:g}, {hi[n]:g}; the other features at the middle, lower "
                                 f"and upper ends of theirs): the renderer ignores it; render it, or leave it out "
                                 f"of render_features")


def _dimension_rules(ctx: _Ctx) -> None:
    holder: dict[str, Any] = {}

    def r_class() -> None:
        cls = ctx.obj
        assert isinstance(cls, type) and issubclass(cls, PerceptionDimension), \
            f"entry point gives {cls!r}, not a PerceptionDimension subclass"
        if ctx.by_name:
            assert cls.name == ctx.name, f"class attribute name {cls.name!r} differs from the entry-point name {ctx.name!r}"
        d = ctx.make()
        holder["d"] = d
        json.dumps(d.describe())
        from ...plugins import registry
        for role, act in d.default_actuators.items():
            assert act in registry("actuator"), f"default actuator {act!r} of role {role!r} is not installed"
        assert d.default_model in registry("model"), f"default_model {d.default_model!r} is not installed"

    def r_features() -> None:
        d = holder["d"]
        assert d.features, "the dimension contributes no feature"
        for f in d.features:
            assert isinstance(f, Feature), f"{f!r} is not a Feature"
            assert f.unit, f"feature {f.name} has no unit"
        FeatureSpace(tuple(d.features))
        names = {f.name for f in d.features}
        extra = [n for n in d.render_features if n not in names]
        assert not extra, f"render_features {extra} are not among its features {sorted(names)}"
        # a feature is one quantity in one unit across the installed dimensions (a scene
        # naming both would be refused by FeatureSpace.merge)
        from ...perception.features import same_unit
        from ...plugins import registry
        for other in registry("dimension").names():
            if other == d.name:
                continue
            try:
                obj = registry("dimension").load(other)
                theirs = {f.name: f for f in (obj() if isinstance(obj, type) else obj).features}
            except Exception:   # noqa: BLE001 - another plugin's failure is not this one's
                continue
            for f in d.features:
                g = theirs.get(f.name)
                assert g is None or same_unit(f.unit, g.unit), \
                    (f"feature {f.name!r} is declared in {f.unit!r} here and in {g.unit!r} by the installed "
                     f"dimension {other!r}: one name, two quantities (prefix yours: '{d.name}.{f.name}')")

    def r_constraints() -> None:
        d = holder["d"]
        cons = d.constraints()
        assert isinstance(cons, list), "constraints() must return a list"
        # the core hands every dimension of a problem the facts of its model's data (df_hz,
        # and any name a model's constraint_context carries): constraints(**context)
        try:
            d.constraints(kit_unread_fact=1.0)
        except TypeError as exc:
            raise AssertionError(
                f"constraints(kit_unread_fact=1.0) raised TypeError ({exc}): the core passes every dimension of "
                f"a problem the facts of its model's data as keywords (df_hz, a model's constraint_context), "
                f"whatever dimension they are for; take them as **context and ignore the ones you do not "
                f"read") from None
        space = d.feature_space()
        rng = np.random.default_rng(0)
        X = space.random(64, rng)
        cols = {n: X[:, i].copy() for i, n in enumerate(space.names)}    # what the constraints are handed
        E = np.vstack([X, np.asarray(space.lower, float), np.asarray(space.upper, float)])
        edge_cols = {n: E[:, i].copy() for i, n in enumerate(space.names)}
        # the constraints of device-aware solving (device_constraints, from the default
        # actuators' capabilities, with the renderer options they supply) are solved with
        # these: the same rules
        device = _device_constraints(d)
        for c in cons + device:
            assert isinstance(c, Constraint), f"{c!r} is not a Constraint"
            missing = [f for f in c.features if f not in space]
            assert not missing, f"constraint {c.name!r} reads features {missing} the dimension does not contribute"
            for form in ("paper", "normalised"):
                p = np.asarray(c.penalty(cols, form))
                assert p.shape == (64,), f"constraint {c.name!r} penalty has shape {p.shape}, expected (64,)"
                assert np.isfinite(p).all() and (p >= 0).all(), f"constraint {c.name!r} penalty not finite >= 0"
                rows = np.array([float(np.asarray(c.penalty({k: v[i:i + 1] for k, v in cols.items()}, form))[0])
                                 for i in range(0, 64, 9)])
                np.testing.assert_allclose(rows, p[::9], rtol=1e-9, atol=1e-12,
                                           err_msg=f"constraint {c.name!r}: batch and row-by-row penalties differ")
            # the bound and the value themselves, at the drawn rows and the box's corners
            # (all lower, all upper): the constraint is `value >= bound`, and with a NaN on
            # either side `value < bound` is False, so the constraint reads as met there
            # whatever the features, with penalty 0 (an infinity still compares)
            bound, value = (np.broadcast_to(np.asarray(a, float), (len(E),)) for a in c.bound_and_value(edge_cols))
            bad = np.isnan(bound) | np.isnan(value)
            assert not bad.any(), \
                (f"constraint {c.name!r}: bound {float(bound[bad][0])!r} and value {float(value[bad][0])!r} at "
                 f"{dict(zip(space.names, E[bad][0].tolist()))}: a NaN bound or value reads as met (penalty 0) "
                 f"whatever the features; it must be a number for every row in the feature bounds")
            # a constraint reads its columns: the solvers hand it views of their candidates
            # (SolveProblem.columns: up to 64 rows) and of the answers they report, so a
            # write lands in what they search and return
            for what, given, kept in (("drawn rows", cols, X), ("the box's corners", edge_cols, E)):
                changed = [n for i, n in enumerate(space.names)
                           if not np.array_equal(given[n], kept[:, i], equal_nan=True)]
                assert not changed, \
                    (f"constraint {c.name!r} wrote into its feature columns {changed} ({what}): the columns "
                     f"are views of a solver's candidates and answers; read them, never write")
            json.dumps(c.describe())

    def r_one_row() -> None:
        # a constraint's float path (Constraint._bound_and_value_one) is what a one-target
        # solve judges its answer by: it must give the array path's numbers, row by row
        d = holder["d"]
        space = d.feature_space()
        # 64 rows drawn in the bounds, and the corners: all lower, all upper, alternating
        lo, hi = np.asarray(space.lower, float), np.asarray(space.upper, float)
        odd = np.arange(len(lo)) % 2 == 1
        X = np.vstack([space.random(64, np.random.default_rng(1)), lo, hi,
                       np.where(odd, lo, hi), np.where(odd, hi, lo)])
        for c in d.constraints():
            if type(c)._bound_and_value_one is Constraint._bound_and_value_one:
                continue      # no float path: the base runs the array path on one row
            for x in X:
                cols = {n: x[i:i + 1] for i, n in enumerate(space.names)}
                row = dict(zip(space.names, x.tolist()))
                b, v = (np.asarray(a, float).reshape(-1)[0] for a in c.bound_and_value(cols))
                b1, v1 = c.bound_and_value_one(row)
                # equal, both NaN, or within 1e-12 relative: IEEE arithmetic rounds a float as it
                # rounds a one-element array, so the same operations give the same bits; a
                # formula written in another order may differ in its last units, a wrong one
                # by far more
                same = all((p == q) or (p != p and q != q) or abs(p - q) <= 1e-12 * max(abs(p), abs(q))
                           for p, q in ((b, b1), (v, v1)))
                assert same, (f"constraint {c.name!r}: its one-row float path gives (bound, value) = ({b1!r}, {v1!r}) "
                              f"at {row}, its array path ({b!r}, {v!r}): _bound_and_value_one must compute what "
                              f"_bound_and_value computes for that row (a one-target solve judges its answer by it)")

    def mid() -> dict[str, float]:
        d = holder["d"]
        return {f.name: 0.5 * (f.lower + f.upper) for f in d.features}

    def r_renderer() -> None:
        d = holder["d"]
        from ...perception.dimensions import declared_roles
        specs = declared_roles(d)
        # the middle and the ends, and each feature at the tenths of its declared range
        # (the values scenes write, e.g. 0.3) with the others at the middle
        grid = [mid(), {f.name: f.lower for f in d.features}, {f.name: f.upper for f in d.features}]
        for f in d.features:
            grid += [{**mid(), f.name: f.lower + (f.upper - f.lower) * k / 10} for k in range(1, 10)]
        for feats in grid:
            r = d.renderer(feats)
            assert isinstance(r, DimensionRenderer), f"renderer() returned {type(r).__name__}"
            assert r.roles, "renderer declares no roles"
            for role in r.roles:
                assert role in d.default_actuators, f"renderer role {role!r} has no default actuator"
            for inp in _tick_inputs(read_only=True):
                _check_commands(_tick_unchanged(r, inp), inp, r, specs, _where(inp, feats))
            json.dumps(r.describe(), default=str)
        # beyond the kit's ticks: every penetration and speed of the sweep, then a long
        # run of one renderer (a state that goes bad after many ticks: a filter that
        # diverges, a counter that overflows a table)
        feats = mid()
        r = d.renderer(feats)
        for inp in _sweep_inputs():   # built on first use, not at the kit's import
            _check_commands(_tick_unchanged(r, inp), inp, r, specs, _where(inp, feats))
        r = d.renderer(feats)
        mixed = _TICKS + list(_sweep_inputs())
        for k in range(int(round(RENDER_RUN_S / KIT_PERIOD_S))):
            base = mixed[k % len(mixed)]
            inp = TickInput(t=k * KIT_PERIOD_S, dt=KIT_PERIOD_S, penetration_mm=base.penetration_mm,
                            velocity_mm_s=base.velocity_mm_s, in_contact=base.in_contact)
            _check_commands(r.tick(inp), inp, r, specs, _where(inp, feats, k))
        # the render builds each renderer from the material's features, those of its other
        # dimensions too: a renderer takes them and renders what it renders without them
        extra = {**feats, OTHER_FEATURE: 0.5}
        try:
            with_other = _commands_of(d, extra)
        except ValidationError as exc:
            raise AssertionError(
                f"renderer() refused the features of a material that has another dimension too ({exc}): the render "
                f"builds each dimension's renderer from all of the material's solved features (e.g. GS, W, "
                f"Fpeak, AFpeak of a material with hardness and roughness); take what you render and ignore the "
                f"rest") from None
        alone_cmds = _commands_of(d, feats)
        assert with_other == alone_cmds, \
            (f"renderer() given another dimension's feature as well ({OTHER_FEATURE!r}: 0.5) gave other commands: "
             f"{_first_difference(with_other, alone_cmds)}: it reads a feature that is not its own")
        # the face under the probe need not be the version-1 plane: the same checks at the
        # contact normals of a spatial scene (TickInput is in the contact frame)
        for normal in RENDER_NORMALS:
            r = d.renderer(feats)
            for inp in _tick_inputs(read_only=True):
                inp = replace(inp, normal=normal)
                _check_commands(_tick_unchanged(r, inp), inp, r, specs, f"{_where(inp, feats)} at normal {normal}")
        # and as the loop gives them on a device that declares an encoder count: the
        # filtered velocity and the speed step of one count (TickInput.speed_step_mm_s > 0),
        # which a speed gate uses as its hysteresis (the kit's other ticks give neither)
        for step in ENCODER_SPEED_STEPS_MM_S:
            r = d.renderer(feats)
            for inp in _TICKS + list(_sweep_inputs()):
                v = np.asarray(inp.velocity_mm_s, float)
                inp = replace(inp, velocity_filtered_mm_s=(float(v[0]), float(v[1]), float(v[2])), speed_step_mm_s=step)
                _check_commands(_tick_unchanged(r, inp), inp, r, specs,
                                f"{_where(inp, feats)} with a filtered velocity and speed step {step:g} mm/s")
        # the velocity as plain floats (the servo loop gives them) is the same velocity: the
        # same commands as when it is read from the array (the kit's other ticks)
        diff = _floats_path_difference(d, feats)
        assert diff is None, \
            (f"the same ticks gave other commands with TickInput.velocity_floats_mm_s set to the velocity's three "
             f"numbers, as the servo loop sets it: {diff}; it holds velocity_mm_s as plain floats, so a renderer "
             f"reading it must read the same components (vt[0] is velocity_mm_s[0])")
        # and holds bounded memory: what it keeps per tick outgrows any machine within a
        # render (which may last 24 h)
        held = _memory_growth(lambda: d.renderer(feats))
        steps = np.diff(held)
        per_tick = steps / (np.diff(MEMORY_POINTS_S) / KIT_PERIOD_S)
        ticks = (MEMORY_POINTS_S[-1] - MEMORY_POINTS_S[0]) / KIT_PERIOD_S
        grown = held[-1] - held[0]
        assert not (per_tick >= MEMORY_GROWTH_BYTES_PER_TICK).all(), \
            (f"one renderer holds more memory the longer it runs: "
             f"{', '.join(f'+{b} B by {at:g} s' for at, b in zip(MEMORY_POINTS_S[1:], np.cumsum(steps)))} "
             f"(after {MEMORY_POINTS_S[0]:g} s; {grown / ticks:.3g} B per tick): a 24 h render at 1 kHz "
             f"would hold {grown / ticks * 86.4e6 / 1e6:.3g} MB more; keep bounded state (a running sum, a "
             f"fixed-size buffer), not a history of every tick")

    def r_renderer_bad() -> None:
        d = holder["d"]
        need = list(d.render_features) or [f.name for f in d.features]
        feats = mid()
        bad_sets = [{**feats, need[0]: float("nan")}, {k: v for k, v in feats.items() if k != need[0]}]
        for bad in bad_sets:
            assert _refuses(ValidationError, lambda: d.renderer(bad)), f"renderer() accepted bad features {bad}"

    def r_determinism() -> None:
        d = holder["d"]
        outs = [_commands_of(d, mid()) for _ in range(2)]
        assert outs[0] == outs[1], "two renderers of the same features gave different commands"
        # two renderers alive at once (a scene with two materials of this dimension: the loop
        # ticks each every tick): each gives what a renderer of its features gives alone
        # (and two of the same features: two objects of one material, each its own renderer)
        other = {f.name: float(f.lower) for f in d.features}
        for pair in ((mid(), other), (mid(), mid())):
            both = _commands_side_by_side(d, *pair)
            alone = (outs[0], _commands_of(d, pair[1]))
            for which, feats, got, want in (("first", pair[0], both[0], alone[0]),
                                            ("second", pair[1], both[1], alone[1])):
                assert got == want, \
                    (f"two renderers ticked in turn (a scene with two materials of this dimension"
                     f"{'' if pair[1] is other else ', or two objects of one material'}) gave other commands than "
                     f"each alone: the {which}, at {dict(feats)}, gave {_first_difference(got, want)}; renderers "
                     f"share state (a class attribute or module global changed in place, e.g. a filter state or "
                     f"a contact timer{'' if pair[1] is other else ', or one renderer handed out again for the same features'}): "
                     f"keep state on the instance, and make a new renderer per renderer() call")
        # the same scene at another servo period: the same commands at the same times,
        # within what one tick's lateness at each period explains
        diff = _period_difference(d, mid())
        assert diff is None, \
            (f"the same scene (the same depth and velocity at the same times) at servo periods "
             f"{PERIODS_S[0] * 1e3:g} ms and {PERIODS_S[1] * 1e3:g} ms gave other commands: {diff}. The "
             f"renderer advances its state by a step per tick (an envelope, a ramp, an oscillator's phase), "
             f"so its time runs {PERIODS_S[0] / PERIODS_S[1]:g} x faster at the shorter period (a scene's "
             f"servo.period_s may be 0.1..100 ms); advance it by TickInput.dt")
        for e in CLOCK_EPOCHS_S:
            assert _commands_at_epoch(d, mid(), e) == outs[0], \
                (f"the same features and ticks gave other commands with the process clocks (time.time, "
                 f"time.monotonic, time.perf_counter, time.localtime) at another epoch ({e:.6g} s, advancing with the ticks' t): "
                 f"the renderer reads the wall clock; take time from TickInput.t and dt")

    def r_roles() -> None:
        d = holder["d"]
        from ...perception.dimensions import RoleSpec
        declared = dict(getattr(d, "roles", {}) or {})
        r = d.renderer(mid())
        assert declared, (f"the dimension declares no `roles` (role -> RoleSpec(channel, fields with units)) "
                          f"for its renderer's roles {list(r.roles)}")
        from ...perception.features import same_unit
        for role, spec in declared.items():
            assert isinstance(spec, RoleSpec), f"roles[{role!r}] is {spec!r}, not a RoleSpec"
            for fname, unit in (("force_n", "N"), ("frequency_hz", "Hz")):
                if fname in spec.fields:
                    assert same_unit(spec.fields[fname], unit), \
                        f"roles[{role!r}] declares {fname} in {spec.fields[fname]!r}; {fname} is in {unit}"
        missing = [ro for ro in r.roles if ro not in declared]
        assert not missing, f"the renderer commands role(s) {missing} that `roles` does not declare"
        from ...compiler.compile import _check_role
        for role in r.roles:
            act = d.default_actuators.get(role)
            if act is not None:
                try:
                    _check_role(d.name, role, declared[role], act, {})
                except ValidationError as exc:
                    raise AssertionError(f"its default actuator cannot carry role {role!r}: {exc}") from None

    def r_feasible() -> None:
        d = holder["d"]
        cons = d.constraints()
        if not cons:
            return
        from ...compiler.solution_set import halton
        space = d.feature_space()
        X = space.from_unit(halton(4096, len(space)))
        cols = {n: X[:, i] for i, n in enumerate(space.names)}
        ok_all = np.ones(len(X), bool)
        for c in cons:
            ok = np.asarray(c.violation(cols)) <= 0.0
            assert ok.any(), (f"constraint {c.name!r} holds nowhere in the dimension's feature bounds (4096-point "
                              f"Halton sample): no material can satisfy it")
            ok_all &= ok
        assert ok_all.any(), (f"the constraints {[c.name for c in cons]} never hold together in the feature "
                              f"bounds (4096-point Halton sample)")

    def r_model_match() -> None:
        d = holder["d"]
        from ...perception.features import same_unit
        from ...plugins import registry
        try:
            m = registry("model").load(d.default_model)
            m = m() if callable(m) and not isinstance(m, PerceptionModel) else m
        except Exception as exc:
            raise AssertionError(f"default_model {d.default_model!r} could not be built: {exc}") from None
        assert d.name in m.dimension_names, \
            f"default_model {d.default_model!r} predicts {list(m.dimension_names)}, not {d.name!r}"
        mine = {f.name: f for f in d.features}
        for n in m.feature_names:
            if n in mine and m.feature_space is not None and n in m.feature_space:
                assert same_unit(m.feature_space[n].unit, mine[n].unit), \
                    f"model reads {n} in {m.feature_space[n].unit!r}, the dimension declares {mine[n].unit!r}"
        # every model input must be contributed by a dimension the model covers
        covered: set[str] = set()
        for dn in m.dimension_names:
            if dn == d.name:
                covered |= set(mine)
            elif dn in registry("dimension"):
                try:
                    other = registry("dimension").load(dn)
                    covered |= {f.name for f in (other() if isinstance(other, type) else other).features}
                except Exception:
                    covered |= set(m.feature_names)   # cannot tell: not this plugin's fault
            else:
                covered |= set(m.feature_names)
        stray = [n for n in m.feature_names if n not in covered]
        assert not stray, (f"default_model {d.default_model!r} reads feature(s) {stray} that no dimension it "
                           f"predicts contributes")

    def r_commands() -> None:
        d = holder["d"]
        from ...perception.dimensions import declared_roles, undeclared_fields
        r = d.renderer(mid())
        seen: set[str] = set()
        specs = declared_roles(d)
        forces = {role: _force_limit(d, role, specs.get(role)) for role in r.roles}
        amps = {role: _amplitude_limit(d, role, specs.get(role)) for role in r.roles}
        for inp in _tick_inputs():
            if not inp.in_contact:
                continue
            for c in r.tick(inp):
                seen.add(c.role)
                spec = specs.get(c.role)
                if spec is not None:
                    extra = undeclared_fields(c, spec)
                    assert not extra, (f"sends {extra} on role {c.role!r}, declared as {spec.describe()}: its "
                                       f"actuator does not act on {extra[0]}")
                field, fmax = forces.get(c.role) or (None, None)
                v = getattr(c, field) if field else None
                if v is not None and fmax is not None and inp.penetration_mm <= 3.0:
                    assert abs(v) <= FORCE_PLAUSIBILITY_FACTOR * fmax, \
                        (f"commands {v:g} N on role {c.role!r} ({field}) at {inp.penetration_mm:g} mm, more than "
                         f"{FORCE_PLAUSIBILITY_FACTOR:g} x the {fmax:g} N its actuator declares")
                # an amplitude in another unit (V, a temperature, a drive share) by the same
                # factor: the safety layer clamps it, and a multiple of it is a unit error (mV
                # for V), which flattens the amplitude at the actuator's maximum
                amax = amps.get(c.role)
                if c.amplitude is not None and amax is not None and inp.penetration_mm <= 3.0:
                    unit = dict(spec.fields)["amplitude"] if spec is not None else ""
                    assert abs(c.amplitude) <= FORCE_PLAUSIBILITY_FACTOR * amax, \
                        (f"commands amplitude {c.amplitude:g} {unit} on role {c.role!r} at {inp.penetration_mm:g} mm, "
                         f"more than {FORCE_PLAUSIBILITY_FACTOR:g} x the {amax:g} {unit} its actuator declares "
                         f"(max_amplitude): a unit error? The safety layer clamps it to {amax:g} {unit}")
        silent = [ro for ro in r.roles if ro not in seen]
        assert not silent, f"the renderer sends nothing on role(s) {silent} while in contact"
        _assert_follows_features(d, mid())

    def r_timing() -> None:
        d = holder["d"]
        r = d.renderer(mid())
        inputs = _tick_inputs()
        state = {"i": 0}

        def one() -> None:
            _sim_advance(KIT_PERIOD_S)
            r.tick(inputs[state["i"] % len(inputs)])
            state["i"] += 1
        best = _fastest(one, budget_s=TICK_BUDGET * KIT_PERIOD_S)
        assert best <= TICK_BUDGET * KIT_PERIOD_S, \
            (f"tick() takes at least {best * 1e3:.3f} ms (fastest of {TIMING_CALLS} or more calls); a {KIT_PERIOD_S * 1e3:g} ms "
             f"servo period allows {TICK_BUDGET * KIT_PERIOD_S * 1e3:.3f} ms per renderer")
        # the worst tick: one that blocks longer than the safety layer's restart gap
        # makes the loop miss that many periods and the next command a restart; seen in
        # two runs on new renderers (a preempted tick does not recur at the same place)
        limit = float(SafetySettings().restart_after_s)
        runs = [_tick_stalls(d.renderer(mid()), limit)]
        if runs[0]:
            runs.append(_tick_stalls(d.renderer(mid()), limit))
            if runs[1]:
                raise AssertionError(
                    f"tick() blocked for up to {max(w for _, w in runs[0]) * 1e3:.0f} ms (first at tick "
                    f"{runs[0][0][0] + 1} of a run of {STALL_RUN_S / KIT_PERIOD_S:.0f}; {len(runs[0])} and "
                    f"{len(runs[1])} ticks over the limit in two runs), longer than the safety layer's "
                    f"restart_after_s {limit * 1e3:g} ms: the servo loop misses that many periods and the next "
                    f"command restarts the output from zero; never block in tick() (no sleep, I/O or lock "
                    f"waits: hand slow work to another thread)")
        # and keeps that cost over a long run: a cost that grows with the run's length
        # passes the budget at some length (a render may last 24 h)
        pts = _cost_growth(lambda: d.renderer(mid()))
        costs = [c for _, c in pts]
        assert not _grows(pts), \
            (f"the cost of tick() grows with the length of the run: fastest tick "
             f"{', '.join(f'{c * 1e6:.3g} us after {s:g} s' for s, c in pts)} (as the length to the power "
             f"{_growth_exponent(pts):.2g}, {costs[-1] / costs[0]:.2g} x): it keeps and walks a history that grows every tick; at that rate it "
             f"passes its {TICK_BUDGET * KIT_PERIOD_S * 1e3:.3f} ms budget within a render; keep bounded state "
             f"(a running sum, a fixed-size buffer)")

    def r_fast_law() -> None:
        d = holder["d"]
        low = {f.name: float(f.lower) for f in d.features}
        high = {f.name: float(f.upper) for f in d.features}
        for feats in (mid(), low, high):
            diff = _fast_law_difference(d, feats)
            assert diff is None, \
                (f"the renderer's law on plain floats (_fast_law) is not its tick(): {diff}. The servo loop runs "
                 f"the law instead of tick() in its steady state and goes back to tick() whenever that ends, so "
                 f"the law must give the same values bit for bit (the same operations in the same order) and "
                 f"read and write the same state as tick(); or offer no law (return None)")

    def r_cost() -> None:
        d = holder["d"]
        space = d.feature_space()
        X = space.random(COST_ROWS, np.random.default_rng(5))
        cols = {n: X[:, i] for i, n in enumerate(space.names)}
        for c in d.constraints():
            ratio, t_c, t_ref = _cost_ratio(c, cols)
            assert ratio <= COST_FACTOR, \
                (f"constraint {c.name!r}: one batch of {COST_ROWS} rows takes {t_c * 1e3:.3g} ms, {ratio:.2g} x a "
                 f"Python loop doing one operation per row on the same rows ({t_ref * 1e3:.3g} ms, same process; "
                 f"limit {COST_FACTOR:g} x): evaluate whole columns with array operations, not row by row")

    _run_rules(ctx, [("class", r_class), ("features", r_features), ("roles-declared", r_roles),
                     ("constraints-vectorised", r_constraints), ("constraints-one-row", r_one_row),
                     ("constraints-cost", r_cost), ("constraints-feasible", r_feasible),
                     ("model-match", r_model_match), ("renderer", r_renderer), ("renderer-commands", r_commands),
                     ("renderer-bad-input", r_renderer_bad), ("renderer-fast-law", r_fast_law),
                     ("determinism", r_determinism), ("timing", r_timing)],
               always=("class",), stop_after=("class", "features"))
