"""How one plugin's rules run: :class:`_Ctx` (what the rules of one plugin share), the plugin
resolved from a name, class or factory, and each rule in a daemon thread of its own under a
time limit of :data:`RULE_TIME_BASE_S` plus :data:`RULE_TIME_FACTOR` x the device time it
simulated (a rule that does not finish is reported where it is stuck)."""

from __future__ import annotations

import sys
import threading
from typing import Any, Callable, Mapping, Sequence

from ...errors import PluginError
from .report import KitResult, Violation
from .timing import _SIM, _monotonic


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
    from ...plugins import registry
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
            from ...plugin_api import PluginAPIError
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
    kit = os.path.dirname(os.path.realpath(__file__)) + os.sep   # every module of the kit
    stack = traceback.extract_stack(frame)
    for fs in reversed(stack):
        fn = os.path.realpath(fs.filename)
        if not fn.startswith(stdlib) and not fn.startswith(kit):
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
