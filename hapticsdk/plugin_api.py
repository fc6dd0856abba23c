"""The plugin interface's version and the check of a plugin's declared range.

Every plugin declares the range of plugin API versions it was built for with a
``hapticsdk_api`` attribute (e.g. ``">=1.0,<2"``): on the object its entry point names
(dimension class, actuator class, model factory, solver class, importance model, hook
module), or once for its whole distribution in its top-level package
(``hapticsdk_hardness.hapticsdk_api``). The registry checks it when it imports a plugin
(:meth:`hapticsdk.plugins.Registry.load`): a range this core does not meet raises
:class:`~hapticsdk.errors.PluginError` naming the plugin, its distribution, the range and
the core's :data:`PLUGIN_API_VERSION`. A plugin that declares nothing is loaded with a
warning (and the conformance kit's ``plugin-api-declared`` rule fails it).
"""

from __future__ import annotations

import logging
import sys
from typing import Any

from .errors import PluginError, ValidationError

#: Version of the plugin interface of this core: the base classes of
#: :mod:`hapticsdk.dimensions`, :mod:`hapticsdk.models`, :mod:`hapticsdk.solvers`,
#: :mod:`hapticsdk.actuators`, the entry-point groups and the hook specifications.
#: ``MAJOR.MINOR``: MINOR grows when something is added (old plugins keep working),
#: MAJOR when something is removed or changes meaning. A plugin declares the range it
#: supports with a ``hapticsdk_api`` attribute (e.g. ``">=1.0,<2"``); see
#: :func:`check_plugin_api` and docs/plugin-authors.md.
PLUGIN_API_VERSION = "1.1"

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


_log = logging.getLogger(__name__)
_warned: set[str] = set()


def declared_api(obj: Any) -> tuple[str | None, str]:
    """The ``hapticsdk_api`` range ``obj`` declares and where: ``(spec, "object")``,
    ``(spec, "package <name>")`` from its top-level package, or ``(None, "undeclared")``."""
    spec = getattr(obj, "hapticsdk_api", None)
    if spec is not None:
        return str(spec), "object"
    modname = getattr(obj, "__module__", None) or getattr(obj, "__name__", None)
    if isinstance(modname, str) and modname.split(".", 1)[0] == __name__.split(".", 1)[0]:
        # the core's own entry points (probe-virtual, playback-virtual): this very API
        return f"=={PLUGIN_API_VERSION}", "core"
    if isinstance(modname, str) and modname:
        top = modname.split(".", 1)[0]
        pkg = sys.modules.get(top)
        spec = getattr(pkg, "hapticsdk_api", None) if pkg is not None else None
        if spec is not None:
            return str(spec), f"package {top}"
    return None, "undeclared"


def check_plugin_api(obj: Any, *, name: str | None = None, distribution: str | None = None,
                     require: bool = False) -> str | None:
    """Check a plugin's declared ``hapticsdk_api`` range against :data:`PLUGIN_API_VERSION`.

    Args:
        obj: the plugin object (class, factory or module).
        name: its entry-point name (for the message).
        distribution: its distribution, ``"name version"`` (for the message).
        require: raise when nothing is declared (default: log a warning once).

    Returns:
        the declared range, or ``None`` when undeclared.

    Raises:
        PluginError: the range excludes this core's version, cannot be read, or (with
            ``require``) is missing.
    """
    spec, where = declared_api(obj)
    label = name or getattr(obj, "name", None) or getattr(obj, "__name__", repr(obj))
    dist = f" (distribution {distribution})" if distribution else ""
    if spec is None:
        msg = (f"plugin {label!r}{dist} declares no hapticsdk_api range; this hapticsdk provides plugin "
               f"API {PLUGIN_API_VERSION} (declare e.g. hapticsdk_api = \">={PLUGIN_API_VERSION},<"
               f"{_parse_version(PLUGIN_API_VERSION)[0] + 1}\" in the package)")
        if require:
            raise PluginError(msg, plugin=str(label))
        if str(label) not in _warned:
            _warned.add(str(label))
            _log.warning("%s", msg)
        return None
    try:
        ok = api_compatible(spec)
    except ValidationError as exc:
        raise PluginError(f"plugin {label!r}{dist} declares an unreadable hapticsdk_api {spec!r} ({where}): "
                          f"{exc}", plugin=str(label)) from None
    if not ok:
        raise PluginError(f"plugin {label!r}{dist} was built for plugin API {spec} ({where}); this hapticsdk "
                          f"provides plugin API {PLUGIN_API_VERSION}: install a version of the plugin built "
                          f"for it, or a hapticsdk whose plugin API the plugin supports", plugin=str(label))
    return spec
