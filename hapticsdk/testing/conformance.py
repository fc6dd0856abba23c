"""Conformance kit: checks that a plugin keeps the contract of its kind.

Each ``check_<kind>(name_or_factory)`` runs every rule of that kind and returns a
:class:`KitResult`, a list of :class:`Violation` (empty: the plugin conforms). A violation names the plugin, its kind,
the rule and what was wrong, so a failure reads like
``[actuator 'piezo-virtual'] rule 'limits-enforced': backend received amplitude 250 V
above max_amplitude 100 V``.

Kinds and rules (``RULES[kind]``; every kind starts with import and
plugin-api-declared):

* ``actuator``: class, template, limits-declared, options, privileged-options, lifecycle,
  close, bad-input, limits-enforced, safe-stop, read-back, output-follows-command, reopen,
  instances, servo-loop, determinism, timing.
* ``device`` (an actuator that senses): the actuator rules plus state (for a simulated
  device also: its clock advances as it is stepped, and its position changes as its
  velocity says, within one declared encoder count).
* ``dimension``: class, features, roles-declared, constraints-vectorised,
  constraints-cost, constraints-feasible, model-match, renderer, renderer-commands,
  renderer-bad-input, determinism, timing.
* ``model``: shapes, model-dimensions, vectorised, determinism, bad-input, jacobian,
  metadata, responds.
* ``solver``: class, template, options, solves, result, constraints, determinism, batch,
  bad-input. A solver is judged by what the model says at the ``x`` it returns, never by
  what its result claims.
* ``hooks``: hookimpls.

The rules that judge what an actuator *outputs* read it back
(:meth:`hapticsdk.actuators.Actuator.read_back`: the physical output where the
actuator declares ``readback_source = "output"``, else the backend's own record of its
last write, which the result's ``notes`` say) after holding each command for the safety
layer's ramp time plus the declared ``limits.settle_time_s``, and on while what the safety
layer lets through still changes (a declared force-rate limit), and compare it with the
command in force within the declared resolution (one step for an output, half a step
for a drive record) or :data:`READBACK_RTOL` of full scale. Timing rules take the fastest of
:data:`TIMING_CALLS` calls (so a preempted call does not count) against a fraction of
the servo period: :data:`COMMAND_BUDGET` for ``command()``, :data:`TICK_BUDGET` for a
renderer's ``tick()``.

Each rule runs in a daemon thread of its own: an ``AssertionError`` is its finding, any
other exception (a ``BaseException`` too, but ``KeyboardInterrupt`` and ``SystemExit``,
which propagate) a violation of that rule, and a rule still running after
:data:`RULE_TIME_BASE_S` plus :data:`RULE_TIME_FACTOR` x the device time it simulated is
a violation naming where it is stuck; the rules after it are not run (its thread is left
running).

The pytest side (classes to subclass, fixtures) is in :mod:`hapticsdk.testing.suites`
and :mod:`hapticsdk.testing.pytest_plugin`.
"""

from __future__ import annotations

import json
import math
import sys
import threading
import time
from dataclasses import dataclass, fields
from typing import Any, Callable, Mapping, Sequence, cast

import numpy as np

from ..actuators import CHANNELS, Actuator, ActuatorLimits, HapticDevice, readback_tolerance
from ..actuators import READBACK_RTOL as READBACK_RTOL  # re-exported: the kit's name since 1.1
from ..perception.dimensions import ChannelCommand, Constraint, DimensionRenderer, PerceptionDimension, TickInput
from ..errors import DeviceError, PluginError, ValidationError
from ..perception.features import Feature, FeatureSpace
from ..perception.models import PerceptionModel
from ..solvers import CONSTRAINT_TOL, SolveProblem, SolveResult, Solver


@dataclass(frozen=True)
class Violation:
    """One broken rule of one plugin."""

    kind: str
    plugin: str
    rule: str
    message: str

    def __str__(self) -> str:
        return f"[{self.kind} {self.plugin!r}] rule {self.rule!r}: {self.message}"


class KitResult(list):
    """The violations of one :func:`check` run (a ``list`` of :class:`Violation`, as
    before), plus what the run could not judge and the plugin's declared API:

    * ``notes``: rule -> a sentence, e.g. ``read-back``: the actuator reports its drive
      record, so the rules compared the record, not the physical output;
    * ``api``: ``{"declared": range or None, "where": ..., "provided": PLUGIN_API_VERSION,
      "new_rules": {rule: version}}`` — the kit's rules new since the oldest API version the
      plugin declares (a violation of one of them says so).
    """

    notes: dict[str, str]
    api: dict[str, Any]

    def __init__(self, items: Sequence[Violation] = ()) -> None:
        super().__init__(items)
        self.notes = {}
        self.api = {}


def format_report(result: Sequence[Violation]) -> str:
    """The violations, then the notes and the API line of a :class:`KitResult`."""
    lines = [str(v) for v in result]
    for rule, note in (getattr(result, "notes", None) or {}).items():
        lines.append(f"note ({rule}): {note}")
    api = getattr(result, "api", None) or {}
    if api:
        new = ", ".join(f"{r} ({v})" for r, v in api.get("new_rules", {}).items()) or "none"
        lines.append(f"plugin API: declares {api.get('declared')!r} ({api.get('where')}); this core provides "
                     f"{api.get('provided')}; kit rules new since the declared version: {new}")
    return "\n".join(lines)


class _Ctx:
    """What the rules of one plugin share: its name, how to make it, found violations."""

    def __init__(self, kind: str, name: str, factory: Callable[[], Any] | None, obj: Any = None) -> None:
        self.kind, self.name, self.factory, self.obj = kind, name, factory, obj
        self.violations: KitResult = KitResult()
        self.by_name = False
        self.only: set[str] = set()
        self.new_rules: dict[str, str] = {}
        self.time_base_s = RULE_TIME_BASE_S
        self.stuck: str | None = None

    def fail(self, rule: str, message: str) -> None:
        if rule in self.new_rules:
            message += (f" [rule new in plugin API {self.new_rules[rule]}: see the migration table in "
                        f"docs/plugin-authors.md]")
        self.violations.append(Violation(self.kind, self.name, rule, message))

    def note(self, rule: str, message: str) -> None:
        self.violations.notes[rule] = message

    def make(self) -> Any:
        if self.factory is None:
            raise PluginError("no factory", plugin=self.name, kind=self.kind)
        return self.factory()


def _load(kind: str, name: str) -> Any:
    from ..plugins import registry
    return registry(kind).load(name)


def _resolve(kind: str, target: Any, options: Mapping[str, Any] | None
             ) -> tuple[str, Callable[[], Any] | None, Any, tuple[str, str] | None]:
    """(name, factory, class-or-object, failure): the failure is ``(rule, message)``, the
    rule ``plugin-api-declared`` when the registry refused the plugin's API range, else
    ``import``."""
    opts = dict(options or {})
    if isinstance(target, str):
        try:
            obj = _load(kind, target)
        except PluginError as exc:
            from ..plugin_api import PluginAPIError
            return target, None, None, ("plugin-api-declared" if isinstance(exc, PluginAPIError) else "import",
                                        str(exc))
        if isinstance(obj, type) and hasattr(obj, "conformance_options"):
            opts = {**obj.conformance_options(), **opts}
        return target, (lambda: obj(**opts)), obj, None
    if callable(target) and not isinstance(target, type):
        name = getattr(target, "__name__", kind)
        try:
            probe = target()
        except (KeyboardInterrupt, SystemExit):
            raise
        except BaseException as exc:   # noqa: BLE001 - a plugin's BaseException is its failure
            return name, None, None, ("import", f"{type(exc).__name__}: {exc}")
        return getattr(probe, "name", name) or name, target, type(probe), None
    if isinstance(target, type):
        if hasattr(target, "conformance_options"):
            opts = {**target.conformance_options(), **opts}
        return getattr(target, "name", target.__name__) or target.__name__, (lambda: target(**opts)), target, None
    return getattr(target, "name", kind), (lambda: target), type(target), None


#: a rule may take this much wall time (s) besides its simulated time (below): the work of
#: a rule that simulates nothing (building the plugin, describing it, a few batches of at
#: most 10,000 rows, one solve of the kit's 3-feature reference problem). The slowest such
#: rule of the first-party plugins takes 0.2-0.5 s (``de-scipy`` ``solves``, three runs on a
#: loaded 2-core machine): 20 s is a 40 x margin or more, and still reports a hung plugin
#: within half a minute.
#: ``check(..., rule_time_limit_s=...)`` changes it (a slow solver, a device whose open()
#: takes long).
RULE_TIME_BASE_S = 20.0
#: ... plus this multiple of the device time the rule has simulated so far (its kit ticks
#: of :data:`KIT_PERIOD_S`): a conforming plugin keeps up with its servo period (one
#: command within :data:`COMMAND_BUDGET` of it, one renderer tick within
#: :data:`TICK_BUDGET`), so a rule runs at least in real time; 10 x leaves room for a
#: loaded machine. The allowance grows as the rule advances: a rule that keeps
#: simulating is never cut short, one that stops advancing (a call that never returns)
#: is reported once the allowance is spent.
RULE_TIME_FACTOR = 10.0

_SIM = threading.local()
#: the kit's own clock, bound at import: the dimension determinism rule moves the
#: ``time`` module's clocks to other epochs while a renderer ticks
_monotonic = time.monotonic
_perf_counter = time.perf_counter


def _sim_advance(dt: float) -> None:
    """Book ``dt`` s of simulated device time to the rule running in this thread (its time
    limit grows by :data:`RULE_TIME_FACTOR` x ``dt``)."""
    box = getattr(_SIM, "box", None)
    if box is not None:
        box[0] += dt


def _where(thread: threading.Thread) -> str:
    """The innermost frame of ``thread`` outside the standard library and the kit (where
    the plugin is stuck), as ``function (file:line)``."""
    import os
    import sysconfig
    import traceback
    frame = sys._current_frames().get(thread.ident or -1)
    if frame is None:
        return "unknown"
    stdlib = os.path.realpath(sysconfig.get_paths()["stdlib"])
    stack = traceback.extract_stack(frame)
    for fs in reversed(stack):
        fn = os.path.realpath(fs.filename)
        if not fn.startswith(stdlib) and fn != os.path.realpath(__file__):
            return f"{fs.name} ({fs.filename}:{fs.lineno})"
    fs = stack[-1]
    return f"{fs.name} ({fs.filename}:{fs.lineno})"


def _guard(ctx: _Ctx, rule: str, fn: Callable[[], None]) -> None:
    """Run one rule in a daemon thread and judge how it ended: an ``AssertionError`` is the
    rule's finding, any other exception (a ``BaseException`` that is not an ``Exception``
    too, except ``KeyboardInterrupt`` and ``SystemExit``, which propagate) a violation
    naming it, and a rule still running after :data:`RULE_TIME_BASE_S` (or the check's
    ``rule_time_limit_s``) plus :data:`RULE_TIME_FACTOR` x its simulated time a violation
    naming where it is stuck; its thread is left running (a daemon: it does not keep the
    process alive) and ``ctx.stuck`` is set, so the rules after it are not run."""
    sim = [0.0]
    box: dict[str, BaseException] = {}

    def work() -> None:
        _SIM.box = sim
        try:
            fn()
        except BaseException as exc:   # noqa: BLE001 - judged by the caller's thread
            box["exc"] = exc
        finally:
            _SIM.box = None

    th = threading.Thread(target=work, name=f"hapticsdk-kit {ctx.kind} {ctx.name!r} {rule}", daemon=True)
    t0 = _monotonic()
    th.start()
    while th.is_alive():
        limit = ctx.time_base_s + RULE_TIME_FACTOR * sim[0]   # grows while the rule simulates
        left = t0 + limit - _monotonic()
        if left > 0:
            th.join(left)
        else:
            ctx.stuck = rule
            ctx.fail(rule, f"did not finish within {limit:.3g} s ({ctx.time_base_s:g} s + {RULE_TIME_FACTOR:g} x "
                           f"the {sim[0]:.3g} s of device time it simulated); stuck in {_where(th)}. A call that "
                           f"never returns hangs the servo loop; the kit left the rule's thread running and "
                           f"did not run the rules after it")
            return
    exc = box.get("exc")
    if exc is None:
        return
    if isinstance(exc, (KeyboardInterrupt, SystemExit)):
        raise exc
    if isinstance(exc, AssertionError):
        ctx.fail(rule, str(exc))
    elif isinstance(exc, Exception):
        ctx.fail(rule, f"raised {type(exc).__name__}: {exc}")
    else:
        ctx.fail(rule, f"raised {type(exc).__name__}: {exc} (a BaseException that is not an Exception: it "
                       f"passes every `except Exception`, the servo loop's too, so it ends the program "
                       f"instead of stopping the render; derive it from Exception)")


def _run_rules(ctx: _Ctx, rules: Sequence[tuple[str, Callable[[], None]]], *,
               always: tuple[str, ...] = (), stop_after: tuple[str, ...] = ()) -> None:
    """Run ``rules`` in order (only those of ``ctx.only`` when set, plus ``always``);
    stop after a rule of ``stop_after`` when anything failed so far, and after a rule that
    did not finish (:func:`_guard`; the rules not run are named in the result's notes)."""
    before = len(ctx.violations)   # plugin-api-declared runs first and never stops the rest
    chosen = [(r, fn) for r, fn in rules if not ctx.only or r in ctx.only or r in always]
    for i, (rule, fn) in enumerate(chosen):
        _guard(ctx, rule, fn)
        if ctx.stuck:
            rest = [r for r, _ in chosen[i + 1:]]
            if rest:
                ctx.note("not-run", f"rule {ctx.stuck!r} did not finish, so the kit did not run {rest}")
            break
        if rule in stop_after and len(ctx.violations) > before:
            break


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
#: servo period the timing rules assume (s)
KIT_PERIOD_S = 1e-3
#: share of the period one actuator command may take (the loop runs several per tick)
COMMAND_BUDGET = 0.25
#: share of the period one renderer tick may take
TICK_BUDGET = 0.25
#: calls timed per timing rule (the fastest counts)
TIMING_CALLS = 25
#: wall time (s) a timing rule goes on sampling while the fastest call is over budget
TIMING_WINDOW_S = 1.0
#: a renderer's force in contact may exceed its default actuator's max_force_n (which
#: the safety layer clamps) up to this factor at penetrations <= 3 mm; a multiple of it
#: is a unit or formula error, not a stiff material
FORCE_PLAUSIBILITY_FACTOR = 10.0


def _fastest(fn: Callable[[], Any], n: int = TIMING_CALLS, budget_s: float | None = None) -> float:
    """The fastest of ``n`` timed calls; while that is over ``budget_s``, calls go on for
    up to ``TIMING_WINDOW_S`` of wall time: on a busy machine the fastest call is the
    one that was not preempted, and a longer sample finds it (a call that is slow
    every time stays slow)."""
    best = math.inf
    end = None
    i = 0
    while True:
        t0 = _perf_counter()
        fn()
        t1 = _perf_counter()
        best = min(best, t1 - t0)
        i += 1
        if i < n:
            continue
        if budget_s is None or best <= budget_s:
            return best
        end = end if end is not None else t1 + TIMING_WINDOW_S
        if t1 >= end:
            return best


def _finite(x: Any) -> bool:
    return x is None or (isinstance(x, (int, float, np.floating, np.integer)) and math.isfinite(float(x)))


# ---------------------------------------------------------------------------
# actuators and devices
# ---------------------------------------------------------------------------

def _over_limit_commands(act: Actuator) -> list[ChannelCommand]:
    lim = act.limits
    cmds = []
    role = act.channel
    if lim.max_force_n is not None:
        cmds += [ChannelCommand(role, force_n=10 * lim.max_force_n + 1),
                 ChannelCommand(role, force_n=-(10 * lim.max_force_n + 1))]
    if lim.frequency_range_hz is not None:
        lo, hi = lim.frequency_range_hz
        amp = lim.max_amplitude if lim.max_amplitude is not None else 0.5
        cmds += [ChannelCommand(role, frequency_hz=hi * 10 + 100, amplitude=amp),
                 ChannelCommand(role, frequency_hz=max(lo / 10.0, 0.0), amplitude=amp)]
    if lim.max_amplitude is not None:
        f = float(np.mean(lim.frequency_range_hz)) if lim.frequency_range_hz else 100.0
        cmds += [ChannelCommand(role, frequency_hz=f, amplitude=10 * lim.max_amplitude + 1),
                 ChannelCommand(role, frequency_hz=f, amplitude=-1.0)]
    return cmds


def _normal_commands(act: Actuator) -> list[ChannelCommand]:
    lim = act.limits
    role = act.channel
    out = []
    if lim.max_force_n is not None or act.channel == "force":
        fmax = lim.max_force_n if lim.max_force_n is not None else 1.0
        out += [ChannelCommand(role, force_n=v * fmax) for v in (0.0, 0.25, 0.5, 0.25, 0.0)]
    if lim.frequency_range_hz is not None or lim.max_amplitude is not None:
        a = lim.max_amplitude if lim.max_amplitude is not None else 1.0
        a0 = float(getattr(lim, "min_amplitude", None) or 0.0)
        if lim.frequency_range_hz is not None:
            lo, hi = lim.frequency_range_hz
            out += [ChannelCommand(role, frequency_hz=lo + (hi - lo) * u, amplitude=a0 + (a - a0) * u)
                    for u in (0.1, 0.5, 0.9, 0.5, 0.0)]
        else:
            out += [ChannelCommand(role, amplitude=a0 + (a - a0) * u) for u in (0.1, 0.5, 0.9, 0.5, 0.0)]
    if not out:
        out = [ChannelCommand(role)]
    return out


def _drive_size(c: ChannelCommand) -> float:
    """How hard ``c`` drives: its force plus its amplitude (absolute values)."""
    return abs(c.force_n or 0.0) + abs(c.amplitude or 0.0)


def _startable_commands(act: Actuator) -> list[ChannelCommand]:
    """The normal commands (:func:`_normal_commands`) the safety layer's start gate lets
    through from rest (force within ``start_max_force_n``), smallest drive first; all of
    them when none is."""
    gate = getattr(act.safety.settings, "start_max_force_n", None)
    cmds = _normal_commands(act)
    ok = [k for k in cmds if gate is None or abs(k.force_n or 0.0) <= gate] or cmds
    return sorted(ok, key=_drive_size)


def _edge_commands(act: Actuator) -> list[ChannelCommand]:
    """Commands at the edges of the declared limits, which :func:`_normal_commands` (10..90 %
    of each range) never reaches: the declared ``max_force_n``; the lowest and the highest
    declared frequency at half the amplitude range; the declared ``max_amplitude`` at
    the middle of the frequency range. A device declaring more than it does (an amplifier
    saturating short of its declared maximum, a coil that cannot reach its lowest declared
    frequency) fails ``output-follows-command`` on them."""
    lim = act.limits
    role = act.channel
    out = []
    if lim.max_force_n is not None:
        out.append(ChannelCommand(role, force_n=float(lim.max_force_n)))
    if lim.max_amplitude is not None:
        a = float(lim.max_amplitude)
        a0 = float(getattr(lim, "min_amplitude", None) or 0.0)
        if lim.frequency_range_hz is not None:
            lo, hi = (float(v) for v in lim.frequency_range_hz)
            mid = a0 + 0.5 * (a - a0)
            out += [ChannelCommand(role, frequency_hz=lo, amplitude=mid),
                    ChannelCommand(role, frequency_hz=hi, amplitude=mid),
                    ChannelCommand(role, frequency_hz=0.5 * (lo + hi), amplitude=a)]
        else:
            out.append(ChannelCommand(role, amplitude=a))
    return out


class _Spy:
    """Wraps an actuator's backend methods to see what reaches the hardware."""

    def __init__(self, act: Actuator) -> None:
        self.sent: list[ChannelCommand] = []
        self.stops = 0
        cmd, stop = act._command, act._stop

        def _command(c: ChannelCommand) -> None:
            self.sent.append(c)
            cmd(c)

        def _stop() -> None:
            self.stops += 1
            stop()
        act._command = _command  # type: ignore[method-assign, assignment]
        act._stop = _stop  # type: ignore[method-assign]


def _drive(act: Actuator, cmds: Sequence[ChannelCommand], dt: float = 0.001) -> list[Any]:
    """Send commands 1 ms apart (stepping simulated devices); return states or sent commands."""
    out: list[Any] = []
    t = 0.0
    for c in cmds:
        t += dt
        _sim_advance(dt)
        sent = act.command(c, now=t)
        if isinstance(act, HapticDevice):
            act.step(dt)
            st = act.read_state()
            out.append((np.array(st.position_mm, float).round(12).tolist(),
                        np.array(st.force_n, float).round(12).tolist()))
        else:
            out.append((sent.force_n, sent.frequency_hz, sent.amplitude))
        rb = act.read_back()
        if rb is not None:
            out.append(("read-back", rb.force_n, rb.frequency_hz, rb.amplitude))
    return out


def _full_scale(act: Actuator) -> tuple[float, float, float]:
    """(force N, frequency Hz, amplitude) scales for read-back tolerances."""
    lim = act.limits
    return (float(lim.max_force_n or 1.0), float(lim.frequency_range_hz[1] if lim.frequency_range_hz else 1.0),
            float(lim.max_amplitude or 1.0))


def _reports_output(act: Any) -> bool:
    return getattr(act, "readback_source", "drive") == "output"


#: read-back tolerance of one field (:func:`hapticsdk.actuators.readback_tolerance`: the
#: rule the render's final check uses too)
_tol = readback_tolerance


def _settle_ticks(act: Actuator, *, ramp: bool = False) -> int:
    """Kit ticks to hold a command before its read-back is judged: the actuator's declared
    settle time (its own ramps and lag), plus the safety layer's start ramp time when
    ``ramp``, plus two ticks (the command of the tick and the one that observes it)."""
    t = float(getattr(act, "settle_time_s", 0.0) or 0.0)
    if ramp:
        t += float(getattr(act.safety.settings, "ramp_time_s", 0.0) or 0.0)
    return int(math.ceil(t / KIT_PERIOD_S - 1e-9)) + 2


#: kit time (s) a command is held at most while the safety layer's output still changes
#: (a declared force-rate limit slewing); beyond it the read-back is judged anyway
HOLD_LIMIT_S = 5.0


def _hold(act: Actuator, cmd: ChannelCommand, t: float) -> tuple[ChannelCommand | None, float]:
    """Send ``cmd`` every kit tick, advancing simulated time, for the safety layer's start
    ramp plus the declared settle time (:func:`_settle_ticks`), and on while what the layer
    lets through has changed within the last settle time (a declared
    ``max_force_rate_n_per_tick`` still slewing; the layer is asked by its output), up to
    :data:`HOLD_LIMIT_S`. Returns the command in force and the kit time."""
    sent, _, t = _hold_both(act, cmd, None, None, t)
    return sent, t


def _hold_both(a: Actuator, ca: ChannelCommand, b: Actuator | None, cb: ChannelCommand | None,
               t: float) -> tuple[ChannelCommand | None, ChannelCommand | None, float]:
    """:func:`_hold` on two open actuators at once: ``ca`` sent to ``a`` and ``cb`` to
    ``b`` every kit tick (``cb`` None: ``b`` only has its time advanced; ``b`` None: ``a``
    alone), until each has been steady for its own settle time after both safety layers'
    ramps. Returns what each safety layer let through and the kit time."""
    pair = [(a, ca)] + ([(b, cb)] if b is not None else [])
    least = max(_settle_ticks(x, ramp=True) for x, _ in pair)
    settle = [_settle_ticks(x) for x, _ in pair]
    sent: list[ChannelCommand | None] = [None] * len(pair)
    steady = [0] * len(pair)
    for i in range(max(least, int(math.ceil(HOLD_LIMIT_S / KIT_PERIOD_S)))):
        t += KIT_PERIOD_S
        for j, (x, c) in enumerate(pair):
            now = x.command(c, now=t) if c is not None else None
            _advance(x)
            steady[j] = steady[j] + 1 if now == sent[j] else 1
            sent[j] = now
        if i + 1 >= least and all(n >= m for n, m in zip(steady, settle)):
            break
    return sent[0], (sent[1] if len(sent) > 1 else None), t


def _advance(act: Actuator, dt: float = KIT_PERIOD_S) -> None:
    """One kit tick of simulated time for an actuator that models it (``step(dt)``: a
    HapticDevice, a simulated plate or Peltier)."""
    _sim_advance(dt)
    step = getattr(act, "step", None)
    if callable(step):
        step(dt)


def _rest_after(act: Actuator, when: str) -> None:
    """Hold no command for the declared settle time (advancing simulated time), then the
    read-back must show rest."""
    n = _settle_ticks(act)
    for _ in range(n):
        if act.is_open:
            _advance(act)
    _assert_rest(act, act.read_back(), f"{when} and {n} ticks of {KIT_PERIOD_S * 1e3:g} ms (its declared settle "
                                       f"time {getattr(act, 'settle_time_s', 0.0):g} s)")


def _assert_rest(act: Actuator, rb: ChannelCommand | None, when: str) -> None:
    if rb is None:
        return
    lim = act.limits
    fs_f, _, fs_a = _full_scale(act)
    if rb.force_n is not None:
        tol = _tol(act, getattr(lim, "force_resolution_n", None), fs_f)
        assert abs(rb.force_n) <= tol, f"output {rb.force_n:g} N {when}, expected 0 N"
    if rb.amplitude is not None:
        rest = float(getattr(act, "rest_amplitude", 0.0))
        tol = _tol(act, lim.amplitude_resolution, fs_a)
        assert abs(rb.amplitude - rest) <= tol, \
            f"output amplitude {rb.amplitude:g} {act.limits.amplitude_unit} {when}, expected {rest:g} (rest)"


def _assert_matches(act: Actuator, sent: ChannelCommand | None, rb: ChannelCommand | None) -> None:
    """The read-back equals the command the safety layer let through."""
    if sent is None or rb is None:
        return
    lim = act.limits
    fs_f, fs_hz, fs_a = _full_scale(act)
    if sent.force_n is not None and not (isinstance(act, HapticDevice) and lim.max_force_n is None):
        got = rb.force_n if rb.force_n is not None else 0.0
        tolf = _tol(act, getattr(lim, "force_resolution_n", None), fs_f)
        assert abs(got - sent.force_n) <= tolf, \
            (f"commanded {sent.force_n:g} N (within its declared limits), the device outputs {got:g} N "
             f"(tolerance {tolf:.3g} N)")
    if sent.amplitude is not None:
        got = rb.amplitude if rb.amplitude is not None else 0.0
        tol = _tol(act, lim.amplitude_resolution, fs_a)
        assert abs(got - sent.amplitude) <= tol, \
            (f"commanded amplitude {sent.amplitude:g} {lim.amplitude_unit}, the device outputs {got:g} "
             f"(tolerance {tol:.3g})")
        if sent.frequency_hz is not None and sent.amplitude > 0:
            gf = rb.frequency_hz if rb.frequency_hz is not None else float("nan")
            tolf = _tol(act, lim.frequency_resolution_hz, fs_hz)
            assert abs(gf - sent.frequency_hz) <= tolf, \
                f"commanded {sent.frequency_hz:g} Hz, the device outputs {gf:g} Hz (tolerance {tolf:.3g} Hz)"


#: step lengths (s) of the state rule's run of a simulated device, in turn: the kit period,
#: its half and its double (the realtime loop steps by the measured period)
STATE_STEPS_S = (KIT_PERIOD_S, 0.5 * KIT_PERIOD_S, 2.0 * KIT_PERIOD_S)

def _sensed_run(a: HapticDevice, cmd: ChannelCommand, n_on: int, n_off: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Drive an open simulated device with ``cmd`` for ``n_on`` steps, then stop it and
    step ``n_off`` more, reading the state before the first step and after each:
    ``(dt (n,), t (n+1,), position (n+1, 3), velocity (n+1, 3))``."""
    n = n_on + n_off
    dts = np.array([STATE_STEPS_S[i % len(STATE_STEPS_S)] for i in range(n)])
    ts, xs, vs = [], [], []

    def read() -> None:
        st = a.read_state()
        ts.append(float(st.t))
        xs.append(np.asarray(st.position_mm, float).reshape(3))
        vs.append(np.asarray(st.velocity_mm_s, float).reshape(3))
    read()
    t = 0.0
    for i in range(n):
        if i < n_on:
            a.command(cmd, now=t)
        elif i == n_on:
            a.stop()
        _advance(a, float(dts[i]))
        t += float(dts[i])
        read()
    return dts, np.array(ts), np.array(xs), np.array(vs)


def _kinematics_error(dts: np.ndarray, xs: np.ndarray, vs: np.ndarray, q: float) -> str | None:
    """The first reading whose change of position since the first one disagrees with the
    velocity the device reports, or None. Between two readings the velocity is taken to
    lie between its two readings (monotone within a step: a smooth motion sampled at its
    step, a velocity that jumps once, a backward difference over the step), so the change
    of position lies between the sums of the lower and of the higher of each pair times the
    step, widened by one encoder count ``q`` (each of the two positions is off by at most
    half a count) and float rounding."""
    lo = np.cumsum(np.minimum(vs[:-1], vs[1:]) * dts[:, None], axis=0)
    hi = np.cumsum(np.maximum(vs[:-1], vs[1:]) * dts[:, None], axis=0)
    dx = xs[1:] - xs[0]
    eps = 1e-9 * (np.abs(xs[1:]) + np.abs(xs[0]) + np.cumsum(np.abs(vs[1:]) * dts[:, None], axis=0)) + 1e-12
    bad = (dx < lo - q - eps) | (dx > hi + q + eps)
    if not bad.any():
        return None
    k, j = (int(v) for v in np.argwhere(bad)[0])
    return (f"after {k + 1} steps ({float(np.sum(dts[:k + 1])):g} s) position {'xyz'[j]} moved {dx[k, j]:.6g} mm, "
            f"but the velocity it reports (mm/s) integrates to {lo[k, j]:.6g}..{hi[k, j]:.6g} mm (+- one encoder "
            f"count, {q:g} mm): the velocity is not in mm/s, or the position or the velocity is not updated")


#: writes of the lost-write part of ``output-follows-command`` (alternating between two
#: commands: a device losing every second write, or one in four, misses one of them)
ALTERNATE_WRITES = 4


def _drive_field(act: Actuator, c: ChannelCommand) -> tuple[str, float, float]:
    """(field, value, tolerance) of what drives the output of ``c``: its force, else its
    amplitude, with the read-back tolerance of that field."""
    lim = act.limits
    fs_f, _, fs_a = _full_scale(act)
    if c.force_n is not None:
        return "force_n", float(c.force_n), _tol(act, getattr(lim, "force_resolution_n", None), fs_f)
    return "amplitude", float(c.amplitude or 0.0), _tol(act, lim.amplitude_resolution, fs_a)


def _alternate_once(act: Actuator, t: float) -> None:
    """Lost writes (part of ``output-follows-command``): the kit's holds send the same
    command every tick, so a device that loses every second write still shows it. Here the
    two largest distinct normal commands alternate, each written once and then held, with
    no further write, for the declared settle time (:func:`_settle_ticks`); by then the
    output must have left the previous command (a write has an effect; a device whose
    ramp advances per write, not per second, has moved one step). The kit's own safety
    layer is told that servo period (``set_period``: a command stays in force that long) and
    a restart gap above it, for this part only."""
    cmds: list[ChannelCommand] = []
    for c in sorted(_normal_commands(act), key=_drive_size, reverse=True):
        if all(_drive_size(c) != _drive_size(k) for k in cmds):
            cmds.append(c)
    if len(cmds) < 2:
        return
    pair = cmds[:2]
    n = _settle_ticks(act)
    settings = act.safety.settings
    act.safety.configure(stale_after_s=n * KIT_PERIOD_S,
                         restart_after_s=max(settings.restart_after_s, (n + 1) * KIT_PERIOD_S))
    try:
        prev, t = _hold(act, pair[0], t)
        for i in range(ALTERNATE_WRITES):
            t += KIT_PERIOD_S
            sent = act.command(pair[(i + 1) % 2], now=t)
            _advance(act)
            for _ in range(n - 1):
                t += KIT_PERIOD_S
                _advance(act)
            rb = act.read_back()
            if prev is None or rb is None:
                return
            field, p, tol = _drive_field(act, prev)
            s = _drive_field(act, sent)[1]
            r = getattr(rb, field)
            r = 0.0 if r is None else float(r)
            assert abs(s - p) <= 2 * tol or abs(r - p) > tol, \
                (f"one write of {field} {s:g} held for {n} ticks (its declared settle time and two ticks): the "
                 f"output stayed at the previous command's {p:g} ({r:g}): a lost write (the same command written "
                 f"every tick hides it)")
            prev = sent
    finally:
        act.safety.settings = settings

def _reached_at_write(act: Actuator, prev: ChannelCommand | None, new: ChannelCommand | None,
                      rb: ChannelCommand | None) -> bool | None:
    """Whether the read-back ``rb``, taken the instant ``new`` was written after ``prev`` had
    settled (no simulated time between), already shows ``new`` in every field where the
    two commands differ by more than twice the read-back tolerance; None when they do
    not differ so (or nothing to compare)."""
    if prev is None or new is None or rb is None:
        return None
    lim = act.limits
    fs_f, fs_hz, fs_a = _full_scale(act)
    pairs = [("force_n", _tol(act, getattr(lim, "force_resolution_n", None), fs_f)),
             ("amplitude", _tol(act, lim.amplitude_resolution, fs_a))]
    if (new.amplitude or 0.0) > 0 and (prev.amplitude or 0.0) > 0:
        pairs.append(("frequency_hz", _tol(act, lim.frequency_resolution_hz, fs_hz)))
    reached = []
    for field, tol in pairs:
        p, n = getattr(prev, field), getattr(new, field)
        if p is None or n is None or abs(float(n) - float(p)) <= 2 * tol:
            continue
        r = getattr(rb, field)
        reached.append(r is not None and abs(float(r) - float(n)) <= tol)
    return all(reached) if reached else None


#: wall time (s) the ``close`` rule gives a thread started while the actuator was open to
#: end once ``close()`` has returned: the timing rules' sampling window
#: (:data:`TIMING_WINDOW_S`), scheduling on a loaded machine; a thread that close() told
#: to stop ends within it, one nobody told runs on
THREAD_GRACE_S = 1.0


def _threads_left(before: set[threading.Thread]) -> list[threading.Thread]:
    """Threads alive now that were not in ``before``, each given up to
    :data:`THREAD_GRACE_S` of wall time (all together) to end."""
    end = _monotonic() + THREAD_GRACE_S
    left = []
    for th in threading.enumerate():
        if th in before or th is threading.current_thread() or isinstance(th, threading._DummyThread):
            continue   # a _DummyThread stands for a foreign (native) thread: listed until exit
        th.join(max(end - _monotonic(), 0.0))
        if th.is_alive():
            left.append(th)
    return left


#: servo time (s) of the ``timing`` rule's long run: every command of one second of a
#: 1 kHz loop is timed (a stall rarer than once per this many commands may go unseen)
STALL_RUN_S = 1.0


def _stalls(act: Actuator, limit_s: float) -> list[tuple[int, float]]:
    """(index, wall s) of the commands of a run of :data:`STALL_RUN_S` of kit ticks
    (the normal commands in turn, simulated time advancing) that took longer than
    ``limit_s``."""
    cmds = _normal_commands(act)
    out = []
    t = 0.0
    for i in range(int(round(STALL_RUN_S / KIT_PERIOD_S))):
        t += KIT_PERIOD_S
        t0 = _perf_counter()
        act.command(cmds[i % len(cmds)], now=t)
        d = _perf_counter() - t0
        if d > limit_s:
            out.append((i, d))
        _advance(act)
    return out


class _StillProbe(HapticDevice):
    """The servo-loop rule's sensing device: a simulated stylus held still 1 mm into the
    version-1 plane (in contact), commanding nothing itself."""
    name = "kit-still-probe"
    simulated = True
    limits = ActuatorLimits(max_force_n=1.0)

    def __init__(self) -> None:
        super().__init__()
        self.t = 0.0

    def _command(self, cmd: ChannelCommand) -> None:
        pass

    def _stop(self) -> None:
        pass

    def _read_state(self) -> Any:
        from ..actuators import DeviceState
        return DeviceState(t=self.t, position_mm=np.array([0.0, -1.0, 0.0]), velocity_mm_s=np.zeros(3))

    def _step(self, dt: float) -> None:
        self.t += dt


class _Replay(DimensionRenderer):
    """Sends one command on one role every tick (the servo-loop rule's renderer)."""

    def __init__(self, cmd: ChannelCommand) -> None:
        self.roles = (cmd.role,)
        self.cmd = cmd

    def tick(self, inp: TickInput) -> list[ChannelCommand]:
        c = self.cmd
        return [ChannelCommand(c.role, force_n=c.force_n, frequency_hz=c.frequency_hz, amplitude=c.amplitude)]


class _LastSent:
    """Servo-loop recorder: what the loop's safety layer let through on ``role`` and the
    actuator's read-back, at the last tick."""

    def __init__(self, act: Actuator) -> None:
        self.act = act
        self.sent: ChannelCommand | None = None
        self.rb: ChannelCommand | None = None

    def record(self, t: float, state: Any, sent: Mapping[str, ChannelCommand]) -> None:
        self.sent = sent.get(self.act.channel)
        self.rb = self.act.read_back()

    def close(self) -> None:
        pass


def _in_servo_loop(act: Actuator, cmd: ChannelCommand) -> tuple[ChannelCommand | None, ChannelCommand | None]:
    """Drive ``act`` (closed) with ``cmd`` from the core's :class:`ServoLoop`, simulated
    time, in a worker thread of the standard library's (no kit code on its stack while the
    actuator is commanded, as in a render), for the safety layer's start ramp, the declared
    settle time and the time a declared force-rate limit takes to slew to ``cmd``. Returns
    what the loop's safety layer let through at the last tick and the read-back then."""
    from concurrent.futures import ThreadPoolExecutor
    from ..runtime.loop import ServoLoop
    n = _settle_ticks(act, ramp=True)
    rate = act.limits.max_force_rate_n_per_tick
    if rate and cmd.force_n:
        n += int(math.ceil(abs(cmd.force_n) / rate))
    rec = _LastSent(act)
    loop = ServoLoop(_StillProbe(), [_Replay(ChannelCommand(act.channel, force_n=cmd.force_n,
                                                            frequency_hz=cmd.frequency_hz, amplitude=cmd.amplitude))],
                     {act.channel: act}, period_s=KIT_PERIOD_S, passivity=False, recorder=rec, cpu_time=False)
    _sim_advance(n * KIT_PERIOD_S)
    with ThreadPoolExecutor(1, thread_name_prefix="hapticsdk-servo") as pool:
        pool.submit(loop.run, n * KIT_PERIOD_S).result()
    return rec.sent, rec.rb


def _takes_option(cls: type, key: str) -> bool:
    """Whether the constructor of actuator class ``cls`` takes the keyword option ``key``:
    named in its signature (without a ``**`` catch-all), else as the constructor answers
    when given ``key=None`` (with the class's ``conformance_options``): refused as unknown
    (a ``TypeError`` for an unexpected keyword, the core's ``ValidationError`` on
    ``options``) or not. Asking the constructor follows ``**kwargs`` forwarded to a base
    class, whatever the parameter is called; nothing is opened."""
    import inspect
    try:
        params = inspect.signature(cls).parameters   # the constructor's, without self
    except (TypeError, ValueError):
        params = None
    if params is not None:
        p = params.get(key)
        if p is not None and p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD):
            return True
        if not any(q.kind is q.VAR_KEYWORD for q in params.values()):
            return False
    base = cls.conformance_options() if hasattr(cls, "conformance_options") else {}
    try:
        cls(**{**base, key: None})
    except TypeError as exc:
        return "unexpected keyword" not in str(exc) or repr(key) not in str(exc)
    except ValidationError as exc:
        return not (exc.field == "options" and repr(key) in str(exc))
    except Exception:   # noqa: BLE001 - it read the option and disliked None: it takes it
        return True
    return True


def _actuator_rules(ctx: _Ctx, device: bool) -> None:
    cls = ctx.obj

    def r_class() -> None:
        assert isinstance(cls, type) and issubclass(cls, Actuator), \
            f"entry point gives {cls!r}, not an Actuator subclass"
        if device:
            assert issubclass(cls, HapticDevice), "a device must subclass HapticDevice (it senses)"
        assert cls.name, "class attribute 'name' is empty"
        if ctx.by_name:
            assert cls.name == ctx.name, \
                f"class attribute name {cls.name!r} differs from the entry-point name {ctx.name!r}"
        assert cls.channel in CHANNELS, f"channel {cls.channel!r} not one of {CHANNELS}"
        src = getattr(cls, "readback_source", "drive")
        assert src in ("drive", "output"), f"readback_source {src!r} is neither 'drive' nor 'output'"
        assert isinstance(cls.limits, ActuatorLimits), "limits must be an ActuatorLimits"
        ok, why = cls.check_available()
        assert isinstance(ok, bool) and isinstance(why, str), "check_available() must return (bool, str)"
        for k in ("_command", "_stop"):
            assert not getattr(getattr(cls, k), "__isabstractmethod__", False), f"{k} not implemented"

    def r_limits() -> None:
        lim = cls.limits
        for k in ("max_force_n", "max_stiffness_n_per_mm", "max_amplitude", "max_velocity_mm_s",
                  "max_force_rate_n_per_tick"):
            v = getattr(lim, k)
            assert _finite(v) and (v is None or v > 0), f"limit {k}={v!r} must be a finite number > 0 or None"
        if lim.frequency_range_hz is not None:
            lo, hi = lim.frequency_range_hz
            assert _finite(lo) and _finite(hi) and 0 <= lo < hi, f"frequency_range_hz {lim.frequency_range_hz} invalid"
        if cls.channel == "force" and not (device and not _commands_force(cls)):
            assert lim.max_force_n is not None, "a force actuator must declare max_force_n"
        if cls.channel == "vibration":
            assert lim.frequency_range_hz is not None and lim.max_amplitude is not None, \
                "a vibration actuator must declare frequency_range_hz and max_amplitude"
            assert lim.amplitude_unit, "a vibration actuator must name its amplitude_unit"
        if cls.channel in ("thermal", "friction", "other"):
            assert lim.max_amplitude is not None and lim.amplitude_unit, \
                f"a {cls.channel} actuator must declare max_amplitude and amplitude_unit (the safety layer " \
                f"has nothing else to clamp)"
        for k in ("frequency_resolution_hz", "amplitude_resolution", "force_resolution_n", "settle_time_s"):
            v = getattr(lim, k, None)
            assert _finite(v) and (v is None or v > 0 or (k == "settle_time_s" and v == 0)), \
                f"limit {k}={v!r} must be a finite number > 0 or None"
        # the units it accepts are the units of its limits (a clean unit clash otherwise)
        from ..perception.features import same_unit
        acc = cls.accepted_fields()
        if "force_n" in acc:
            assert same_unit(acc["force_n"], "N"), f"accepts force_n in {acc['force_n']!r}; force_n is in newtons"
        if "frequency_hz" in acc:
            assert same_unit(acc["frequency_hz"], "Hz"), \
                f"accepts frequency_hz in {acc['frequency_hz']!r}; frequency_hz is in hertz"
        if "amplitude" in acc and lim.amplitude_unit:
            assert same_unit(acc["amplitude"], lim.amplitude_unit), \
                (f"accepts amplitude in {acc['amplitude']!r} but declares its limits in {lim.amplitude_unit!r} "
                 f"(limits.amplitude_unit): one of them is wrong")

    def r_options() -> None:
        base = cls.conformance_options() if hasattr(cls, "conformance_options") else {}
        try:
            cls(**base, no_such_option_xyz=1)
        except ValidationError:
            return
        except TypeError as exc:
            raise AssertionError(f"an unknown option raised TypeError ({exc}), expected ValidationError") from None
        raise AssertionError("an unknown option was accepted silently")

    def r_lifecycle() -> None:
        a = ctx.make()
        assert not a.is_open, "a new actuator must not be open before open()"
        a.stop()  # stop on a closed actuator must not raise
        try:
            a.command(_normal_commands(a)[0])
        except DeviceError:
            pass
        else:
            raise AssertionError("command() on a closed actuator did not raise DeviceError")
        with a:
            assert a.is_open
            a.open()  # idempotent
            _drive(a, _normal_commands(a))
        assert not a.is_open, "the context manager did not close the actuator"
        a.close()  # twice: no error
        a.open()
        _drive(a, _normal_commands(a)[:2])
        a.close()
        json.dumps(a.describe(), default=str)

    def r_bad_input() -> None:
        a = ctx.make()
        with a:
            for attr in ("force_n", "frequency_hz", "amplitude"):
                for bad in (float("nan"), float("inf")):
                    try:
                        a.command(ChannelCommand(a.channel, **cast("dict[str, Any]", {attr: bad})))
                    except ValidationError:
                        continue
                    raise AssertionError(f"{attr}={bad} was accepted")
            if isinstance(a, HapticDevice):
                for bad in (0.0, -1.0, float("nan")):
                    try:
                        a.step(bad)
                    except ValidationError:
                        continue
                    raise AssertionError(f"step({bad}) was accepted")

    def r_limits_enforced() -> None:
        a = ctx.make()
        spy = _Spy(a)
        lim = a.limits
        if _reports_output(a):   # the output itself, held until settled, within the declared limits
            with a:
                t = 0.0
                for c in _over_limit_commands(a):
                    _, t = _hold(a, c, t)
                    rb = a.read_back()
                    if rb is None:
                        break
                    fs_f, _, fs_a = _full_scale(a)
                    if rb.force_n is not None and lim.max_force_n is not None:
                        tol = _tol(a, getattr(lim, "force_resolution_n", None), fs_f)
                        assert abs(rb.force_n) <= lim.max_force_n + tol, \
                            f"outputs {rb.force_n:g} N, above its declared max_force_n {lim.max_force_n:g} N"
                    if rb.amplitude is not None and lim.max_amplitude is not None:
                        tol = _tol(a, lim.amplitude_resolution, fs_a)
                        assert rb.amplitude <= lim.max_amplitude + tol, \
                            (f"outputs amplitude {rb.amplitude:g} {lim.amplitude_unit}, above its declared "
                             f"max_amplitude {lim.max_amplitude:g}")
        with a:
            for c in _over_limit_commands(a):
                a.command(c, now=0.0)
                if isinstance(a, HapticDevice):
                    a.step(0.001)
                    st = a.read_state()
                    if lim.max_force_n is not None:
                        fn = float(np.linalg.norm(np.asarray(st.force_n, float)))
                        assert fn <= lim.max_force_n * (1 + 1e-6) + 1e-9, \
                            f"device reports force {fn:g} N above max_force_n {lim.max_force_n:g} N"
        for c in spy.sent:
            if c.force_n is not None and lim.max_force_n is not None:
                assert abs(c.force_n) <= lim.max_force_n * (1 + 1e-9), \
                    f"backend received force {c.force_n:g} N above max_force_n {lim.max_force_n:g} N"
            if c.frequency_hz is not None and lim.frequency_range_hz is not None:
                lo, hi = lim.frequency_range_hz
                assert lo - 1e-9 <= c.frequency_hz <= hi + 1e-9, \
                    f"backend received {c.frequency_hz:g} Hz outside frequency_range_hz {lim.frequency_range_hz}"
            if c.amplitude is not None:
                assert c.amplitude >= 0, f"backend received a negative amplitude {c.amplitude:g}"
                if lim.max_amplitude is not None:
                    assert c.amplitude <= lim.max_amplitude * (1 + 1e-9), \
                        f"backend received amplitude {c.amplitude:g} {lim.amplitude_unit} above " \
                        f"max_amplitude {lim.max_amplitude:g}"
        assert spy.sent or not _over_limit_commands(a), "no command reached the backend"

    def r_safe_stop() -> None:
        a = ctx.make()
        spy = _Spy(a)
        with a:
            _drive(a, _normal_commands(a)[:3])
            assert a.stop() is True, "stop() returned False (backend stop failed)"
            assert spy.stops >= 1, "stop() did not call the backend _stop"
            if isinstance(a, HapticDevice):
                a.step(0.001)
                f = float(np.linalg.norm(np.asarray(a.read_state().force_n, float)))
                assert f <= 1e-6, f"force {f:g} N still applied after stop()"
        n = spy.stops
        # the output itself: full drive held until settled, then stop(): at rest within the declared time
        c = ctx.make()
        with c:
            top = _normal_commands(c)
            big = max(top, key=_drive_size)
            _hold(c, big, 0.0)
            assert c.stop() is True, "stop() returned False (backend stop failed)"
            _rest_after(c, "after stop()")
        assert n >= 2, "close() did not stop the backend"
        # a failing backend is stopped by the core and reported as DeviceError
        b = ctx.make()
        with b:
            def broken(c: ChannelCommand) -> None:
                raise OSError("simulated transport failure")
            b._command = broken  # type: ignore[method-assign]
            try:
                b.command(_normal_commands(b)[0])
            except DeviceError:
                pass
            else:
                raise AssertionError("a failing backend command was not reported as DeviceError")

    def r_determinism() -> None:
        runs = []
        for _ in range(2):
            a = ctx.make()
            with a:
                runs.append(_drive(a, _normal_commands(a) + _over_limit_commands(a)))
        assert runs[0] == runs[1], "the same command sequence gave different outputs on two instances"

    def r_state() -> None:
        a = ctx.make()
        with a:
            st = a.read_state()
            for k in ("position_mm", "velocity_mm_s", "force_n"):
                v = np.asarray(getattr(st, k), float)
                assert v.shape == (3,), f"state.{k} has shape {v.shape}, expected (3,)"
                assert np.isfinite(v).all(), f"state.{k} is not finite"
            assert math.isfinite(st.t), "state.t is not finite"
            t0 = st.t
            for _ in range(10):
                a.step(0.001)
            assert a.read_state().t >= t0, "device time went backwards"
        try:
            a.read_state()
        except DeviceError:
            pass
        else:
            raise AssertionError("read_state() on a closed device did not raise DeviceError")
        if not getattr(cls, "simulated", False):
            return   # a real device moves and keeps time on its own: nothing the kit steps
        # a simulated device: its clock advances by the steps it is given, and its position
        # changes as its velocity (mm/s) says, under a held force and coasting after stop()
        b = ctx.make()
        with b:
            big = _startable_commands(b)[-1]
            n_on = _settle_ticks(b, ramp=True) + 100
            dts, ts, xs, vs = _sensed_run(b, big, n_on, n_on)
            q = float(getattr(b, "encoder_resolution_mm", 0.0) or 0.0)
        assert (np.diff(ts) >= 0).all(), "device time went backwards while stepped"
        assert ts[-1] > ts[0], (f"device time stayed at {ts[0]:g} s over {len(dts)} steps of "
                                f"{float(np.sum(dts)):g} s in all (step(dt) advances simulated time)")
        why = _kinematics_error(np.diff(ts), xs, vs, q)
        assert why is None, why

    def r_template() -> None:
        over = [m for m in ("open", "close", "command", "stop", "read_back")
                if getattr(cls, m) is not getattr(Actuator, m)]
        if device:
            over += [m for m in ("read_state", "step") if getattr(cls, m) is not getattr(HapticDevice, m)
                     and not getattr(cls, "simulated", False)]
        assert not over, (f"overrides the public method(s) {over}: implement the backend's _{over[0]} instead, "
                          f"so the core's checks and safety layer run")

    def r_close() -> None:
        a = ctx.make()
        a.open()
        _drive(a, _normal_commands(a)[:2])
        try:
            a.close()
        except Exception as exc:
            raise AssertionError(f"close() raised {type(exc).__name__}: {exc} (it must never raise)") from None
        assert not a.is_open, "close() left the actuator open"
        if getattr(a, "simulated", False):
            # a simulated backend can still be asked what its model outputs once closed
            # (the core's read_back() reports rest for any closed actuator without asking):
            # after its declared settle time it must be at rest, not driving what a
            # "flush" in _close re-sent after the stop
            for _ in range(_settle_ticks(a)):
                _advance(a)
            try:
                rb = a._read_back()
            except Exception:  # noqa: BLE001 - a closed backend may refuse to answer
                rb = None
            if isinstance(rb, ChannelCommand):
                _assert_rest(a, rb, "after close() (the simulated backend's own read-back)")
        err = getattr(a, "close_error", None)
        assert err is None, (f"the backend failed while closing: {type(err).__name__}: {err} (kept in "
                             f"close_error; close() stopped and released what it could)")
        # what open() took, close() gives back: no thread started while it was open runs on
        # (the open and close above started what a library starts once per process)
        before = set(threading.enumerate())
        for _ in range(2):
            c = ctx.make()
            c.open()
            _drive(c, _normal_commands(c)[:2])
            c.close()
        left = _threads_left(before)
        assert not left, (f"{len(left)} thread(s) started while it was open still run {THREAD_GRACE_S:g} s after "
                          f"close() ({', '.join(repr(th.name) for th in left)}; two opens and closes): close() "
                          f"must stop and join what open() started, or every reopen leaves one more behind")
        b = ctx.make()
        b.open()
        stops = _Spy(b)

        def broken() -> None:
            raise OSError("simulated close failure")
        b._close = broken  # type: ignore[method-assign]
        import logging
        quiet = logging.getLogger("hapticsdk.actuators")
        level = quiet.level
        quiet.setLevel(logging.CRITICAL)   # the kit's own injected failure: not news in the log
        try:
            b.close()
        except Exception as exc:
            raise AssertionError(f"close() raised {type(exc).__name__} when the backend's _close failed") from None
        finally:
            quiet.setLevel(level)
        assert stops.stops >= 1, "close() did not stop the backend before releasing it"
        assert isinstance(getattr(b, "close_error", None), OSError), \
            "a failing backend _close was not reported (close_error is not set): nobody can see it"

    def r_privileged() -> None:
        from ..device_options import privileged_options
        try:
            priv = privileged_options(cls)
        except PluginError as exc:
            raise AssertionError(f"the core cannot read its privileged_options: {exc}") from None
        unknown = sorted(k for k in priv if not _takes_option(cls, k))
        assert not unknown, (f"privileged_options names {unknown}, which the constructor does not take "
                             f"(it refuses them as unknown options): a misspelt name protects nothing, and "
                             f"the option it meant stays settable from scene and plan files")

    def r_read_back() -> None:
        a = ctx.make()
        with a:
            rb = a.read_back()
            assert rb is not None, ("read_back() gives None: implement _read_back (what the device outputs, "
                                    "or the backend's record of its last write)")
            _assert_rest(a, rb, "right after open()")
            _drive(a, _normal_commands(a)[:3])
            a.stop()
            _assert_rest(a, a.read_back(), "after stop()")
        _assert_rest(a, a.read_back(), "after close()")

    def r_follows() -> None:
        a = ctx.make()
        if not _reports_output(a):
            ctx.note("output-follows-command", "the actuator reports its drive record (readback_source 'drive'): "
                     "the kit compared what the backend wrote, not the physical output; declare "
                     "readback_source = 'output' where read_back measures or models the output")
        # a modelled output that takes time to settle cannot show a new command the
        # instant it is written (no simulated time passed)
        lags = _reports_output(a) and bool(getattr(a, "simulated", False)) and \
            float(getattr(a, "settle_time_s", 0.0) or 0.0) > 0
        instant: list[bool] = []
        with a:
            if a.read_back() is None:
                return   # reported by read-back
            t = 0.0
            sent = None
            for c in _normal_commands(a) + _edge_commands(a):
                if lags and sent is not None:
                    t += KIT_PERIOD_S
                    now = a.command(c, now=t)
                    seen = _reached_at_write(a, sent, now, a.read_back())
                    if seen is not None:
                        instant.append(seen)
                    _advance(a)
                # held until the safety layer's output has been steady for the declared
                # settle time (simulated time advances)
                sent, t = _hold(a, c, t)
                _assert_matches(a, sent, a.read_back())
            assert not (instant and all(instant)), \
                (f"the read-back showed each of {len(instant)} new commands the instant it was written, before any "
                 f"simulated time passed, though the actuator declares readback_source 'output' and a settle time "
                 f"of {a.settle_time_s:g} s: an output cannot reach a command in no time, so it reports the command "
                 f"(its drive record), not the output; report the modelled output (advanced by step(dt)) or declare "
                 f"readback_source = 'drive'")
            _alternate_once(a, t)

    def r_reopen() -> None:
        a = ctx.make()
        a.open()
        _drive(a, _normal_commands(a)[:4])
        a.close()
        a.open()
        try:
            _rest_after(a, "after close() and open() again (stale output)")
        finally:
            a.close()

    def r_instances() -> None:
        a, b = ctx.make(), ctx.make()
        with a:
            try:
                b.open()
            except Exception as exc:   # noqa: BLE001 - one device, one port: nothing to compare
                b.close()
                ctx.note("instances", f"a second instance could not open while the first was open "
                         f"({type(exc).__name__}: {exc}); the rule needs two and was skipped")
                return
            try:
                if a.read_back() is None or b.read_back() is None:
                    return   # reported by read-back
                start = [c for c in _startable_commands(a) if _drive_size(c) > 0]
                if not start:
                    return
                top = max(_normal_commands(a), key=_drive_size)   # allowed once running (past the start gate)
                # a driven, b left alone (its time advances too): b stays at rest
                t = 0.0
                sent_a, _, t = _hold_both(a, start[-1], b, None, t)
                _assert_rest(b, b.read_back(), "on a second instance while the first was driven (the two share "
                                               "their output state)")
                _assert_matches(a, sent_a, a.read_back())
                # both driven with different commands: each follows its own
                sent_a, sent_b, t = _hold_both(a, top, b, start[0], t)
                _assert_matches(b, sent_b, b.read_back())
                _assert_matches(a, sent_a, a.read_back())
                # one closed: the other goes on following its own commands (a new one)
                a.close()
                sent_b, t = _hold(b, top, t)
                _assert_matches(b, sent_b, b.read_back())
            finally:
                b.close()

    def r_timing() -> None:
        a = ctx.make()
        with a:
            cmds = _normal_commands(a)
            state: dict[str, Any] = {"t": 0.0, "i": 0}

            def one() -> None:
                state["t"] += KIT_PERIOD_S
                _sim_advance(KIT_PERIOD_S)
                a.command(cmds[state["i"] % len(cmds)], now=state["t"])
                state["i"] += 1
            best = _fastest(one, budget_s=COMMAND_BUDGET * KIT_PERIOD_S)
        assert best <= COMMAND_BUDGET * KIT_PERIOD_S, \
            (f"command() takes at least {best * 1e3:.3f} ms (fastest of {TIMING_CALLS} or more calls); a {KIT_PERIOD_S * 1e3:g} ms "
             f"servo period allows {COMMAND_BUDGET * KIT_PERIOD_S * 1e3:.3f} ms per actuator")
        # the worst call: one that blocks longer than the safety layer's restart gap makes
        # the next command a restart (a fault, the output ramped from zero); seen in two
        # runs on new instances (a preempted call does not recur at the same place)
        runs = []
        for _ in range(2):
            b = ctx.make()
            limit = float(b.safety.settings.restart_after_s)
            with b:
                runs.append(_stalls(b, limit))
            if not runs[-1]:
                return
        i = runs[0][0][0]
        d = max(w for _, w in runs[0])
        raise AssertionError(f"command() blocked for up to {d * 1e3:.0f} ms (first at call {i + 1} of a run of "
                             f"{STALL_RUN_S / KIT_PERIOD_S:.0f}; {len(runs[0])} and {len(runs[1])} calls over the limit "
                             f"in two runs), longer than the safety layer's restart_after_s {limit * 1e3:g} ms: the "
                             f"servo loop misses that many periods and the next command restarts the output from "
                             f"zero; never block in _command (a write timeout below the servo period, or a queue)")

    def r_servo_loop() -> None:
        a = ctx.make()
        if a.check_available()[0] is False:
            return
        cmd = max(_startable_commands(a), key=_drive_size)
        try:
            sent, rb = _in_servo_loop(a, cmd)
        finally:
            a.close()
        if rb is None:
            return   # reported by read-back
        try:
            _assert_matches(a, sent, rb)
        except AssertionError as exc:
            raise AssertionError(f"driven by the core's ServoLoop (as a render drives it, from a thread of its "
                                 f"own): {exc}; the kit's own holds saw it follow: it behaves differently in "
                                 f"the loop") from None

    rules: list[tuple[str, Callable[[], None]]] = [
        ("class", r_class), ("template", r_template), ("limits-declared", r_limits), ("options", r_options),
        ("privileged-options", r_privileged),
        ("lifecycle", r_lifecycle), ("close", r_close), ("bad-input", r_bad_input),
        ("limits-enforced", r_limits_enforced), ("safe-stop", r_safe_stop), ("read-back", r_read_back),
        ("output-follows-command", r_follows), ("reopen", r_reopen), ("instances", r_instances),
        ("servo-loop", r_servo_loop), ("determinism", r_determinism), ("timing", r_timing)]
    if device:
        rules.append(("state", r_state))
    _run_rules(ctx, rules, stop_after=("class",))


def _force_limit(d: Any, role: str, spec: Any) -> tuple[str | None, float | None]:
    """``(field, N)``: the command field that carries force on ``role`` (``force_n``, or a
    field whose declared unit is a force: a friction plate's amplitude in N) and the largest
    force the role's default actuator declares (``max_force_n``, or ``max_amplitude`` when
    its amplitude is a force); ``(None, None)`` when the role carries no force."""
    from ..plugins import registry
    from ..units import is_force_unit
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


def _commands_force(cls: type) -> bool:
    return getattr(cls, "limits", ActuatorLimits()).max_force_n is not None


# ---------------------------------------------------------------------------
# dimensions
# ---------------------------------------------------------------------------

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


def _commands_of(d: PerceptionDimension, feats: Mapping[str, float]) -> list[Any]:
    """The commands of a new renderer of ``feats`` over the kit's ticks, as values."""
    r = d.renderer(dict(feats))
    return [[(c.role, c.force_n, c.frequency_hz, c.amplitude) for c in r.tick(i)] for i in _tick_inputs()]


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
            out.append([(c.role, c.force_n, c.frequency_hz, c.amplitude) for c in r.tick(inp)])
    finally:
        for n, f in saved.items():
            setattr(time, n, f)
    return out


#: servo time (s) of the ``timing`` rule's long run of one renderer, and where its tick
#: cost is measured (fastest of :data:`TIMING_CALLS`): after 1, 2, 4 and 8 s
GROWTH_POINTS_S = (1.0, 2.0, 4.0, 8.0)
#: the cost at the last point over the cost at the first that, rising at every doubling,
#: fails the rule. A cost proportional to the history rises ~8 x from 1 s to 8 s; the
#: fastest of 25 calls of an unchanged tick moves by far less than 2 x between two
#: samples (the first-party renderers: see docs/plugin-authors.md); a state bounded in
#: time (filters, buffers under 1 s) costs the same at every point
GROWTH_FACTOR = 2.0


def _run_inputs(k: int) -> TickInput:
    """Kit tick ``k`` of a long run: the kit's ticks in turn, its time ``k`` periods."""
    base = _TICKS[k % len(_TICKS)]
    return TickInput(t=k * KIT_PERIOD_S, dt=KIT_PERIOD_S, penetration_mm=base.penetration_mm,
                     velocity_mm_s=base.velocity_mm_s.copy(), in_contact=base.in_contact)


def _cost_growth(r: DimensionRenderer) -> list[tuple[float, float]]:
    """(run length s, fastest tick s) at :data:`GROWTH_POINTS_S` of a run of ``r``."""
    k = 0
    out = []
    for at in GROWTH_POINTS_S:
        n = int(round(at / KIT_PERIOD_S))
        while k < n:
            r.tick(_run_inputs(k))
            _sim_advance(KIT_PERIOD_S)
            k += 1
        state = {"k": k}

        def one() -> None:
            r.tick(_run_inputs(state["k"]))
            state["k"] += 1
        out.append((at, _fastest(one)))
        _sim_advance(TIMING_CALLS * KIT_PERIOD_S)
        k = state["k"]
    return out


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
        from ..plugins import registry
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
        from ..perception.features import same_unit
        from ..plugins import registry
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
        space = d.feature_space()
        rng = np.random.default_rng(0)
        X = space.random(64, rng)
        cols = {n: X[:, i] for i, n in enumerate(space.names)}
        for c in cons:
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
            json.dumps(c.describe())

    def mid() -> dict[str, float]:
        d = holder["d"]
        return {f.name: 0.5 * (f.lower + f.upper) for f in d.features}

    def r_renderer() -> None:
        d = holder["d"]
        from ..perception.dimensions import declared_roles
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
                cmds = _tick_unchanged(r, inp)
                assert isinstance(cmds, list), "tick() must return a list of ChannelCommand"
                for c in cmds:
                    assert isinstance(c, ChannelCommand), f"tick() returned {c!r}"
                    assert c.role in r.roles, f"tick() commanded role {c.role!r} not in roles {r.roles}"
                    for k in ("force_n", "frequency_hz", "amplitude"):
                        assert _finite(getattr(c, k)), f"tick() returned {k}={getattr(c, k)!r} for {feats}"
                    if c.amplitude is not None:
                        assert c.amplitude >= 0, f"negative amplitude {c.amplitude}"
                if not inp.in_contact:
                    for c in cmds:
                        assert not c.force_n, f"force {c.force_n} N commanded out of contact"
                        spec = specs.get(c.role)
                        assert not (getattr(spec, "channel", None) == "vibration" and c.amplitude), \
                            (f"amplitude {c.amplitude:g} commanded on the vibration role {c.role!r} out of contact "
                             f"(penetration {inp.penetration_mm:g} mm, {feats}): nothing touches the surface, "
                             f"so nothing may vibrate; the loop sends amplitude 0 on it away from every object")
            json.dumps(r.describe(), default=str)

    def r_renderer_bad() -> None:
        d = holder["d"]
        need = list(d.render_features) or [f.name for f in d.features]
        feats = mid()
        bad_sets = [{**feats, need[0]: float("nan")}, {k: v for k, v in feats.items() if k != need[0]}]
        for bad in bad_sets:
            try:
                d.renderer(bad)
            except ValidationError:
                continue
            raise AssertionError(f"renderer() accepted bad features {bad}")

    def r_determinism() -> None:
        d = holder["d"]
        outs = [_commands_of(d, mid()) for _ in range(2)]
        assert outs[0] == outs[1], "two renderers of the same features gave different commands"
        for e in CLOCK_EPOCHS_S:
            assert _commands_at_epoch(d, mid(), e) == outs[0], \
                (f"the same features and ticks gave other commands with the process clocks (time.time, "
                 f"time.monotonic, time.perf_counter, time.localtime) at another epoch ({e:.6g} s, advancing with the ticks' t): "
                 f"the renderer reads the wall clock; take time from TickInput.t and dt")

    def r_roles() -> None:
        d = holder["d"]
        from ..perception.dimensions import RoleSpec
        declared = dict(getattr(d, "roles", {}) or {})
        r = d.renderer(mid())
        assert declared, (f"the dimension declares no `roles` (role -> RoleSpec(channel, fields with units)) "
                          f"for its renderer's roles {list(r.roles)}")
        from ..perception.features import same_unit
        for role, spec in declared.items():
            assert isinstance(spec, RoleSpec), f"roles[{role!r}] is {spec!r}, not a RoleSpec"
            for fname, unit in (("force_n", "N"), ("frequency_hz", "Hz")):
                if fname in spec.fields:
                    assert same_unit(spec.fields[fname], unit), \
                        f"roles[{role!r}] declares {fname} in {spec.fields[fname]!r}; {fname} is in {unit}"
        missing = [ro for ro in r.roles if ro not in declared]
        assert not missing, f"the renderer commands role(s) {missing} that `roles` does not declare"
        from ..compiler.compile import _check_role
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
        from ..compiler.solution_set import halton
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
        from ..perception.features import same_unit
        from ..plugins import registry
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
        from ..perception.dimensions import declared_roles, undeclared_fields
        r = d.renderer(mid())
        seen: set[str] = set()
        specs = declared_roles(d)
        forces = {role: _force_limit(d, role, specs.get(role)) for role in r.roles}
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
        # and keeps that cost over a long run: a cost that grows with the run's length
        # passes the budget at some length (a render may last 24 h)
        pts = _cost_growth(d.renderer(mid()))
        costs = [c for _, c in pts]
        rising = all(b > a for a, b in zip(costs, costs[1:]))
        assert not (rising and costs[-1] >= GROWTH_FACTOR * costs[0]), \
            (f"the cost of tick() grows with the length of the run: fastest tick "
             f"{', '.join(f'{c * 1e6:.3g} us after {s:g} s' for s, c in pts)} (rising at every doubling, "
             f"{costs[-1] / costs[0]:.2g} x): it keeps and walks a history that grows every tick; at that rate it "
             f"passes its {TICK_BUDGET * KIT_PERIOD_S * 1e3:.3f} ms budget within a render; keep bounded state "
             f"(a running sum, a fixed-size buffer)")

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
                     ("constraints-vectorised", r_constraints), ("constraints-cost", r_cost),
                     ("constraints-feasible", r_feasible),
                     ("model-match", r_model_match), ("renderer", r_renderer), ("renderer-commands", r_commands),
                     ("renderer-bad-input", r_renderer_bad), ("determinism", r_determinism), ("timing", r_timing)],
               always=("class",), stop_after=("class", "features"))


# ---------------------------------------------------------------------------
# perception models
# ---------------------------------------------------------------------------

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
        Y = m.predict(X)
        rows = np.concatenate([m.predict(X[i:i + 1]) for i in range(X.shape[0])])
        np.testing.assert_allclose(Y, rows, rtol=1e-4, atol=1e-5, err_msg="batch and row-by-row predictions differ")

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
            try:
                m.predict(bad)
            except ValidationError:
                continue
            raise AssertionError(f"predict accepted a bad input of shape {bad.shape}")

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
            # per unit of the feature's range: compare the change over the whole span
            err = np.abs(fd - J[:, :, j]).max() * span[j]
            scale = max(np.abs(fd).max() * span[j], 1e-6)
            assert err <= JACOBIAN_RTOL * scale + 1e-6, \
                (f"jacobian column {m.feature_names[j]} differs from central finite differences by "
                 f"{err / scale:.2%} of its size (tolerance {JACOBIAN_RTOL:.1%})")

    def r_metadata() -> None:
        m = holder["m"]
        json.dumps(m.describe(), default=str)
        assert m.feature_space is not None, "the model declares no feature_space (training range bounds)"
        assert tuple(m.feature_space.names) == m.feature_names, "feature_space names differ from inputs"
        defaults = m.metadata.get("feature_defaults")
        if defaults is not None:
            for k, v in defaults.items():
                assert k in m.feature_names, f"feature_defaults names unknown feature {k!r}"
                f = m.feature_space[k]
                assert f.lower - 1e-9 <= float(v) <= f.upper + 1e-9, f"default {k}={v} outside [{f.lower}, {f.upper}]"

    def r_dimensions() -> None:
        m = holder["m"]
        from ..perception.features import same_unit
        from ..plugins import registry
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


# ---------------------------------------------------------------------------
# solvers
# ---------------------------------------------------------------------------

class ReferenceModel(PerceptionModel):
    """A smooth 3-feature, 2-dimension model with known inverses (kit use only).

    ``I1 = (1 + tanh(2 a - 1)) / 2`` over ``a`` in [0, 1] (unitless),
    ``I2 = b / (b + c)`` over ``b`` in [0.1, 10] and ``c`` in [1, 5].
    """

    def __init__(self) -> None:
        space = FeatureSpace((Feature("a", "1", 0.0, 1.0), Feature("b", "1", 0.1, 10.0),
                              Feature("c", "1", 1.0, 5.0)))
        super().__init__(space.names, ("d1", "d2"), feature_space=space,
                         metadata={"feature_defaults": {"a": 0.5, "b": 1.0, "c": 2.0}}, name="reference")

    def _predict(self, X: np.ndarray) -> np.ndarray:
        i1 = (1 + np.tanh(2 * X[:, 0] - 1)) / 2
        i2 = X[:, 1] / (X[:, 1] + X[:, 2])
        return np.stack([i1, i2], axis=1)


class _RefConstraint(Constraint):
    """b >= 2 c (kit reference constraint)."""

    name = "reference.b-over-c"
    features = ("b", "c")

    def _bound_and_value(self, cols: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        return 2 * np.asarray(cols["c"]), np.asarray(cols["b"])


def reference_problem(targets: Any = (0.4, 0.75), *, constrained: bool = True, tolerance: float = 0.02) -> SolveProblem:
    """A reachable problem on :class:`ReferenceModel` (with ``b >= 2c`` when ``constrained``;
    ``d2 = 0.75`` needs ``b = 3c``, feasible)."""
    m = ReferenceModel()
    return SolveProblem(targets=np.asarray(targets, float), dimensions=("d1", "d2"), model=m,
                        space=cast(FeatureSpace, m.feature_space), constraints=(_RefConstraint(),) if constrained else (),
                        penalty="normalised", tolerance=tolerance)


#: what every solve result carries: scipy.optimize's fields, and the error, constraint
#: violation and run time the SDK promises with every result
RESULT_FIELDS = ("x", "fun", "success", "message", "nfev", "error", "constraint_violation", "time_s")
#: how far a result's error, fun and constraint_violation may be from the kit's
#: recomputation at its ``x`` (absolute; fun relative to max(1, |fun|)): both evaluate the
#: float64 reference model at the same ``x`` by different paths (a batch, one row of plain
#: floats), so they differ by rounding, a few units in the last place of numbers <= 1 per
#: term (~1e-15); this allows 1000 times that and is 10 orders below the reference tolerance
REPORT_ATOL = 1e-12
#: targets of the reference problem whose unconstrained optimum breaks the constraint:
#: ``d2 = 0.5`` needs ``b = c``; with ``b >= 2c`` the best is ``b = 2c``, ``d2 = 2/3``
ACTIVE_TARGETS = (0.4, 0.5)
#: formula (6) (normalised penalty) at the constrained optimum of ACTIVE_TARGETS: ``d1``
#: met, ``|2/3 - 1/2|`` on ``d2``, no violation. Below ``b = 2c`` the penalty ``(2c - b)/2c``
#: rises by 1/2 per unit of ``b/c`` while the error falls by ``1/(b/c + 1)^2 <= 1/4``, so
#: nothing infeasible scores lower; ignoring the constraint scores ``0 + 1/2``
ACTIVE_OPTIMUM = 1.0 / 6.0


def _solver_core_overrides(cls: type) -> list[str]:
    """The methods of :class:`Solver`'s template (public ``solve`` and the steps through
    which it validates, calls ``_solve`` and recomputes the result) that ``cls`` replaces."""
    return [m for m in ("solve", "_call_backend", "_solve_single") if getattr(cls, m, None) is not getattr(Solver, m)]


def _at_x(res: Any, problem: SolveProblem) -> tuple[float, float, float]:
    """(formula (6), error, constraint violation) the core computes at the ``x`` of ``res``
    for the (one-target) ``problem``."""
    fit, err, viol, _, _ = problem.evaluate_one(problem.clip(np.asarray(res["x"], float)[None, :])[0])
    return fit, err, viol


def _judge_result(res: Any, problem: SolveProblem, where: str) -> tuple[float, float, float]:
    """``res`` carries :data:`RESULT_FIELDS` and what it claims (error, fun, violation,
    success) is what the core computes at its ``x`` for the (one-target) ``problem``.
    Returns that (:func:`_at_x`)."""
    missing = [k for k in RESULT_FIELDS if not (isinstance(res, Mapping) and k in res)]
    assert not missing, f"{where}: the result lacks {missing} (every result carries {list(RESULT_FIELDS)})"
    x = np.asarray(res["x"], float)
    assert x.shape == (problem.n_features,) and np.isfinite(x).all(), f"{where}: x {res['x']!r}"
    assert isinstance(res["success"], (bool, np.bool_)), f"{where}: success is {type(res['success']).__name__}"
    assert isinstance(res["message"], str), f"{where}: message is {type(res['message']).__name__}"
    assert isinstance(res["nfev"], (int, np.integer)) and not isinstance(res["nfev"], bool) and res["nfev"] >= 0, \
        f"{where}: nfev {res['nfev']!r} is not a count"
    assert _finite(res["time_s"]) and res["time_s"] is not None and res["time_s"] >= 0, \
        f"{where}: time_s {res['time_s']!r}"
    fit, err, viol = _at_x(res, problem)
    claims = {"error": (res["error"], err, REPORT_ATOL),
              "constraint_violation": (res["constraint_violation"], viol, REPORT_ATOL),
              "fun": (res["fun"], fit, REPORT_ATOL * max(1.0, abs(fit)))}
    for k, (said, true, tol) in claims.items():
        assert _finite(said) and said is not None and abs(float(said) - true) <= tol, \
            f"{where}: {k} {said!r}, but the model at the returned x gives {true:.6g}"
    ok = err <= problem.tolerance and viol <= CONSTRAINT_TOL
    near = abs(err - problem.tolerance) <= REPORT_ATOL or abs(viol - CONSTRAINT_TOL) <= REPORT_ATOL
    assert near or bool(res["success"]) == ok, \
        (f"{where}: success {bool(res['success'])}, but at the returned x the error is {err:.3g} (tolerance "
         f"{problem.tolerance:g}) and the constraint violation {viol:.3g}")
    return fit, err, viol


def _solver_rules(ctx: _Ctx, options: Mapping[str, Any]) -> None:
    def make() -> Solver:
        return ctx.obj(**dict(options))

    # the rules solve the same reference problems: each (targets, seed) is solved once, on
    # a new solver, and judged at its x once (a solver that spoils its own copy of the
    # problem spoils no other rule's: each rule judges against a problem of its own)
    solved: dict[tuple[str, int], Any] = {}
    judged: dict[tuple[str, int], tuple[float, float, float]] = {}

    def key(targets: Any, seed: int) -> tuple[str, int]:
        return repr(np.asarray(targets, float).tolist()), seed

    def solve(targets: Any, seed: int) -> Any:
        k = key(targets, seed)
        if k not in solved:
            solved[k] = make().solve(reference_problem(np.array(targets, float)), seed=seed)
        return solved[k]

    def at_x(targets: Any, seed: int) -> tuple[float, float, float]:
        k = key(targets, seed)
        if k not in judged:
            judged[k] = _at_x(solve(targets, seed), reference_problem(targets))
        return judged[k]

    def r_template() -> None:
        over = _solver_core_overrides(ctx.obj)
        assert not over, (f"overrides {over} of the Solver template: implement _solve only, so the core "
                          f"validates the problem and recomputes every result from the model at x")

    def r_result() -> None:
        # judged against a problem of its own: the solver's copy is the solver's to spoil
        for targets in ((0.4, 0.75), ACTIVE_TARGETS):   # reachable; out of reach behind the constraint
            judged[key(targets, 0)] = _judge_result(solve(targets, 0), reference_problem(targets), f"target {targets}")
        T = np.array([[0.3, 0.7], ACTIVE_TARGETS])
        batch = solve(T, 1)
        assert len(batch) == len(T), f"a batch of {len(T)} targets gave {len(batch)} results"
        for i, r in enumerate(batch):
            _judge_result(r, reference_problem(T[i]), f"batch target {i}")

    def r_constraints() -> None:
        p = reference_problem(ACTIVE_TARGETS)
        fit, err, viol = at_x(ACTIVE_TARGETS, 0)
        assert fit <= ACTIVE_OPTIMUM + p.tolerance, \
            (f"targets {ACTIVE_TARGETS} with the constraint b >= 2c active: formula (6) at the answer is "
             f"{fit:.3g} (error {err:.3g}, constraint violation {viol:.3g}), the constrained optimum "
             f"{ACTIVE_OPTIMUM:.3g} (b = 2c) + tolerance {p.tolerance:g}: does the solver ignore constraints?")

    def r_class() -> None:
        cls = ctx.obj
        assert isinstance(cls, type) and issubclass(cls, Solver), f"entry point gives {cls!r}, not a Solver subclass"
        if ctx.by_name:
            assert cls.name == ctx.name, f"class attribute name {cls.name!r} differs from the entry-point name {ctx.name!r}"
        assert isinstance(cls.default_options, dict), "default_options must be a dict"
        json.dumps(cls.default_options, default=str)

    def r_options() -> None:
        try:
            ctx.obj(no_such_option_xyz=1)
        except ValidationError:
            return
        raise AssertionError("an unknown option was accepted")

    def r_solves() -> None:
        res = cast(SolveResult, solve((0.4, 0.75), 0))   # reference_problem()'s targets
        assert np.shape(res.x) == (3,), f"x has shape {np.shape(res.x)}, expected (3,)"
        p = reference_problem()
        assert p.space.contains(res.x).all(), f"x {res.x} outside the feature bounds"
        assert res.error <= 0.05, f"did not reach an easy reachable target: error {res.error:.3g} ({res.message})"
        assert res.constraint_violation <= 1e-3, f"constraint violated at the answer ({res.constraint_violation:.3g})"

    def r_determinism() -> None:
        a = make().solve(reference_problem(), seed=11)
        b = make().solve(reference_problem(), seed=11)
        np.testing.assert_array_equal(a.x, b.x, err_msg="the same seed gave different answers")

    def r_batch() -> None:
        T = np.array([[0.3, 0.7], [0.6, 0.8], [0.5, 0.75]])
        res = make().solve(reference_problem(T), seed=1)
        assert isinstance(res, list) and len(res) == 3, "a batch of 3 targets must give 3 results"
        assert res.x.shape == (3, 3), f"batch x shape {res.x.shape}"
        assert (res.error <= 0.05).all(), f"batch errors {res.error}"

    def r_bad_input() -> None:
        try:
            make().solve("not a problem")  # type: ignore[arg-type]
        except ValidationError:
            return
        raise AssertionError("solve() accepted something that is not a SolveProblem")

    _run_rules(ctx, [("class", r_class), ("template", r_template), ("options", r_options), ("solves", r_solves),
                     ("result", r_result), ("constraints", r_constraints), ("determinism", r_determinism),
                     ("batch", r_batch), ("bad-input", r_bad_input)],
               always=("class",), stop_after=("class",))


# ---------------------------------------------------------------------------
# entry points
# ---------------------------------------------------------------------------

RULES: dict[str, tuple[str, ...]] = {
    "actuator": ("import", "plugin-api-declared", "class", "template", "limits-declared", "options",
                 "privileged-options", "lifecycle", "close", "bad-input", "limits-enforced", "safe-stop", "read-back",
                 "output-follows-command", "reopen", "instances", "servo-loop", "determinism", "timing"),
    "device": ("import", "plugin-api-declared", "class", "template", "limits-declared", "options",
               "privileged-options", "lifecycle", "close", "bad-input", "limits-enforced", "safe-stop", "read-back",
               "output-follows-command", "reopen", "instances", "servo-loop", "determinism", "timing", "state"),
    "dimension": ("import", "plugin-api-declared", "class", "features", "roles-declared", "constraints-vectorised",
                  "constraints-cost", "constraints-feasible", "model-match", "renderer", "renderer-commands",
                  "renderer-bad-input", "determinism", "timing"),
    "model": ("import", "plugin-api-declared", "shapes", "model-dimensions", "vectorised", "determinism",
              "bad-input", "jacobian", "metadata", "responds"),
    "solver": ("import", "plugin-api-declared", "class", "template", "options", "solves", "result", "constraints",
               "determinism", "batch", "bad-input"),
    "hooks": ("import", "plugin-api-declared", "hookimpls"),
}


def _hooks_rules(ctx: _Ctx) -> None:
    """A hook module (group ``hapticsdk.hooks``): every ``@hookimpl`` names a hook of
    :mod:`hapticsdk.hookspecs` and takes only that hook's arguments (pluggy would refuse it
    at registration, after the render started)."""
    import inspect
    from .. import hookspecs

    def r_hookimpls() -> None:
        mod = ctx.obj
        marker = f"{hookspecs.PROJECT}_impl"
        impls = {n: f for n, f in vars(mod).items() if callable(f) and hasattr(f, marker)}
        specs = {n for n in dir(hookspecs) if n.startswith(f"{hookspecs.PROJECT}_")}
        unknown = [n for n in impls if n not in specs]
        assert not unknown, f"@hookimpl function(s) {unknown} name no hook of hapticsdk.hookspecs ({sorted(specs)})"
        assert impls, "the module has no @hookimpl function"
        for n, f in impls.items():
            spec = getattr(hookspecs, n)
            allowed = set(inspect.signature(spec).parameters) - {"self"}
            extra = set(inspect.signature(f).parameters) - allowed
            assert not extra, f"{n} takes {sorted(extra)}, which the hook does not pass (it passes {sorted(allowed)})"

    _run_rules(ctx, [("hookimpls", r_hookimpls)])


def _api_rule(ctx: _Ctx, target: Any) -> None:
    """``plugin-api-declared``: the plugin (the object its entry point names, the class, or
    the factory) declares a ``hapticsdk_api`` range, on itself or its top-level package,
    that this core's plugin API satisfies. Sets the result's ``api`` and the rules new
    since the declared version."""
    from ..plugin_api import PLUGIN_API_VERSION, api_compatible, declared_api, rules_new_since
    spec, where = declared_api(ctx.obj) if ctx.obj is not None else (None, "undeclared")
    if spec is None and target is not None and not isinstance(target, str):
        spec, where = declared_api(target)
    ok: bool | None = None
    err = ""
    if spec is not None:
        try:
            ok = api_compatible(spec)
        except ValidationError as exc:
            err = str(exc)
    ctx.new_rules = rules_new_since(spec if ok else None)
    ctx.violations.api = {"declared": spec, "where": where, "provided": PLUGIN_API_VERSION,
                          "new_rules": dict(ctx.new_rules)}
    if ctx.only and "plugin-api-declared" not in ctx.only:
        return
    major = PLUGIN_API_VERSION.split(".")[0]
    if spec is None:
        ctx.fail("plugin-api-declared", f"declares no hapticsdk_api range (on the object or its top-level "
                                        f"package); this core provides plugin API {PLUGIN_API_VERSION}: declare "
                                        f"e.g. hapticsdk_api = \">={PLUGIN_API_VERSION},<{int(major) + 1}\"")
    elif err:
        ctx.fail("plugin-api-declared", f"hapticsdk_api {spec!r} ({where}) cannot be read: {err}")
    elif not ok:
        ctx.fail("plugin-api-declared", f"hapticsdk_api {spec!r} ({where}) excludes this core's plugin API "
                                        f"{PLUGIN_API_VERSION}: the registry refuses to load it")


def check(kind: str, target: Any, *, options: Mapping[str, Any] | None = None,
          rules: Sequence[str] | None = None, rule_time_limit_s: float | None = None) -> list[Violation]:
    """Run the rules of ``kind`` on ``target`` (an entry-point name, a class, or a
    zero-argument factory); return the violations (empty when it conforms).

    ``options``: keyword options to create it with (a solver's options, an actuator's
    settings). ``rules``: only these rules (``import`` and ``class`` always run).
    ``rule_time_limit_s``: the wall time a rule may take besides :data:`RULE_TIME_FACTOR` x
    the device time it simulates (default :data:`RULE_TIME_BASE_S`); a rule still running
    then is a violation, and the rules after it are not run."""
    if rule_time_limit_s is not None and not (isinstance(rule_time_limit_s, (int, float))
                                              and math.isfinite(rule_time_limit_s) and rule_time_limit_s > 0):
        raise ValidationError(f"rule_time_limit_s must be a finite number > 0 (s), got {rule_time_limit_s!r}",
                              field="rule_time_limit_s")
    if kind not in RULES:
        raise ValidationError(f"unknown plugin kind {kind!r}; valid: {sorted(RULES)}", field="kind")
    if rules:
        unknown = [r for r in rules if r not in RULES[kind]]
        if unknown:
            raise ValidationError(f"unknown rules {unknown} for {kind}; valid: {list(RULES[kind])}", field="rules")
    reg_kind = "actuator" if kind == "device" else kind
    if kind == "hooks" and not isinstance(target, str):   # a module object: nothing to build
        ctx0 = _Ctx(kind, getattr(target, "__name__", "hooks"), None, target)
        if rule_time_limit_s is not None:
            ctx0.time_base_s = float(rule_time_limit_s)
        ctx0.only = set(rules or ())
        _api_rule(ctx0, target)
        _hooks_rules(ctx0)
        return ctx0.violations
    name, factory, obj, err = _resolve(reg_kind, target, options if kind != "solver" else None)
    ctx = _Ctx(kind, name, factory, obj)
    if rule_time_limit_s is not None:
        ctx.time_base_s = float(rule_time_limit_s)
    ctx.only = set(rules or ())
    ctx.by_name = isinstance(target, str)
    if err is not None:
        ctx.fail(err[0], f"could not be loaded: {err[1]}")
        return ctx.violations
    _api_rule(ctx, target)
    if kind in ("actuator", "device"):
        _actuator_rules(ctx, device=kind == "device")
    elif kind == "dimension":
        _dimension_rules(ctx)
    elif kind == "model":
        _model_rules(ctx)
    elif kind == "hooks":
        _hooks_rules(ctx)
    else:
        _solver_rules(ctx, options or {})
    return ctx.violations


def check_actuator(target: Any, **options: Any) -> list[Violation]:
    """:func:`check` for an actuator (``"piezo-virtual"``, a class or a factory)."""
    return check("actuator", target, options=options)


def check_device(target: Any, **options: Any) -> list[Violation]:
    """:func:`check` for a haptic device (an actuator that senses, e.g. ``"omni-virtual"``)."""
    return check("device", target, options=options)


def check_dimension(target: Any) -> list[Violation]:
    """Conformance violations of a dimension plugin (class or instance); empty when it
    conforms.
    """
    return check("dimension", target)


def check_model(target: Any) -> list[Violation]:
    """:func:`check` for a perception model (entry-point name or zero-argument factory)."""
    return check("model", target)


def check_solver(target: Any, **options: Any) -> list[Violation]:
    """Conformance violations of a solver plugin, built with ``options``; empty when it
    conforms.
    """
    return check("solver", target, options=options)


def check_installed(kinds: Sequence[str] = ("actuator", "dimension", "model", "solver")) -> dict[str, list[Violation]]:
    """Check every installed plugin of the given kinds (actuators that are HapticDevices
    get the device rules). Actuators whose ``check_available()`` is False (hardware
    libraries missing) are checked with the class rules only."""
    from ..plugins import registry
    out: dict[str, list[Violation]] = {}
    for kind in kinds:
        for name in registry(kind).names():
            k = kind
            rules = None
            if kind == "actuator":
                try:
                    cls = registry(kind).load(name)
                except PluginError as exc:
                    out[f"{kind}:{name}"] = [Violation(kind, name, "import", str(exc))]
                    continue
                if isinstance(cls, type) and issubclass(cls, HapticDevice):
                    k = "device"
                if not getattr(cls, "simulated", False):
                    rules = ["plugin-api-declared", "limits-declared", "options", "privileged-options"]
            if kind == "model" and name == "onnx":
                continue  # a class taking a path, not a zero-argument factory
            out[f"{kind}:{name}"] = check(k, name, rules=rules)
    return out


def format_violations(violations: Sequence[Violation]) -> str:
    """The violations as text, one per line."""
    return "\n".join(str(v) for v in violations)


def assert_conforms(violations: Sequence[Violation]) -> None:
    """Raise ``AssertionError`` listing every violation (for tests), with the result's
    notes and API line when it is a :class:`KitResult`."""
    if violations:
        raise AssertionError(f"{len(violations)} conformance violation(s):\n" + format_report(violations))
