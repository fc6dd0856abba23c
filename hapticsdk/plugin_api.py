"""The plugin interface's version and the check of a plugin's declared range.

A plugin (dimension class, actuator class, model, solver, importance model, hook module)
may declare the range of plugin API versions it was built for with a ``hapticsdk_api``
attribute (e.g. ``">=1.0,<2"``); :func:`check_plugin_api` refuses a plugin whose range
this core does not meet, naming the plugin and both versions.
"""

from __future__ import annotations

from typing import Any

from .errors import PluginError, ValidationError

#: Version of the plugin interface of this core: the base classes of
#: :mod:`hapticsdk.dimensions`, :mod:`hapticsdk.models`, :mod:`hapticsdk.solvers`,
#: :mod:`hapticsdk.actuators`, the entry-point groups and the hook specifications.
#: ``MAJOR.MINOR``: MINOR grows when something is added (old plugins keep working),
#: MAJOR when something is removed or changes meaning. A plugin declares the range it
#: supports with a ``hapticsdk_api`` attribute (e.g. ``">=1.0,<2"``); see
#: :func:`check_plugin_api` and docs/plugin-authors.md.
PLUGIN_API_VERSION = "1.0"

def _parse_version(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(p) for p in str(text).strip().split("."))
    except ValueError:
        raise ValidationError(f"not a MAJOR.MINOR version: {text!r}", field="hapticsdk_api") from None


def api_compatible(spec: str | None, version: str = PLUGIN_API_VERSION) -> bool:
    """Whether ``version`` satisfies ``spec``, a comma-separated list of clauses
    ``>=1.0``, ``<2``, ``==1.0``, ``>1.0``, ``<=1.3``, ``!=1.1`` (``None`` or ``""``:
    any version). Versions compare numerically component by component."""
    if not spec:
        return True
    v = _parse_version(version)
    ops = {">=": lambda a, b: a >= b, "<=": lambda a, b: a <= b, "==": lambda a, b: a == b,
           "!=": lambda a, b: a != b, ">": lambda a, b: a > b, "<": lambda a, b: a < b}
    for clause in str(spec).split(","):
        clause = clause.strip()
        if not clause:
            continue
        for op in (">=", "<=", "==", "!=", ">", "<"):
            if clause.startswith(op):
                ref = _parse_version(clause[len(op):])
                width = max(len(v), len(ref))
                a = v + (0,) * (width - len(v))
                b = ref + (0,) * (width - len(ref))
                if not ops[op](a, b):
                    return False
                break
        else:
            raise ValidationError(f"bad version clause {clause!r} (use >=, <=, ==, !=, >, <)",
                                  field="hapticsdk_api")
    return True


def check_plugin_api(obj: Any, *, name: str | None = None) -> None:
    """Raise :class:`~hapticsdk.errors.PluginError` when ``obj`` (a plugin class or module)
    declares a ``hapticsdk_api`` range that :data:`PLUGIN_API_VERSION` does not meet.
    Objects without the attribute are taken as compatible."""
    spec = getattr(obj, "hapticsdk_api", None)
    if spec is None:
        return
    label = name or getattr(obj, "name", None) or getattr(obj, "__name__", repr(obj))
    try:
        ok = api_compatible(spec)
    except ValidationError as exc:
        raise PluginError(f"plugin {label!r} declares an unreadable hapticsdk_api {spec!r}: {exc}",
                          plugin=str(label)) from None
    if not ok:
        raise PluginError(f"plugin {label!r} requires plugin API {spec}, this hapticsdk provides "
                          f"{PLUGIN_API_VERSION}", plugin=str(label))


