"""The kit's entry points: :data:`RULES` (the rules of each kind, in the order they run),
:func:`check` and ``check_<kind>``, and :func:`check_installed`."""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

from ...devices.actuators import HapticDevice
from ...errors import PluginError, ValidationError
from .actuator_rules import _actuator_rules
from .api_rule import _api_rule
from .dimension_rules import _dimension_rules
from .hook_rules import _hooks_rules
from .model_rules import _model_rules
from .report import Violation
from .runner import _Ctx, _resolve
from .solver_rules import _solver_rules


RULES: dict[str, tuple[str, ...]] = {
    "actuator": ("import", "plugin-api-declared", "class", "template", "limits-declared", "options",
                 "privileged-options", "lifecycle", "close", "bad-input", "limits-enforced", "safe-stop", "read-back",
                 "output-follows-command", "reopen", "instances", "servo-loop", "determinism", "timing"),
    "device": ("import", "plugin-api-declared", "class", "template", "limits-declared", "options",
               "privileged-options", "lifecycle", "close", "bad-input", "limits-enforced", "safe-stop", "read-back",
               "output-follows-command", "reopen", "instances", "servo-loop", "determinism", "timing", "state"),
    "dimension": ("import", "plugin-api-declared", "class", "features", "roles-declared", "constraints-vectorised",
                  "constraints-one-row", "constraints-cost", "constraints-feasible", "model-match", "renderer", "renderer-commands",
                  "renderer-bad-input", "renderer-fast-law", "determinism", "timing"),
    "model": ("import", "plugin-api-declared", "shapes", "model-dimensions", "vectorised", "determinism",
              "bad-input", "jacobian", "metadata", "responds"),
    "solver": ("import", "plugin-api-declared", "class", "template", "options", "solves", "result", "constraints",
               "determinism", "batch", "bad-input"),
    "hooks": ("import", "plugin-api-declared", "hookimpls"),
}


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
    from ...plugins import registry
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
