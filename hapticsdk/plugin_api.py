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
#: :mod:`hapticsdk.perception.dimensions`, :mod:`hapticsdk.perception.models`, :mod:`hapticsdk.solvers`,
#: :mod:`hapticsdk.devices.actuators`, the entry-point groups and the hook specifications.
#: ``MAJOR.MINOR``: MINOR grows when something is added (old plugins keep working),
#: MAJOR when something is removed or changes meaning. A plugin declares the range it
#: supports with a ``hapticsdk_api`` attribute (e.g. ``">=1.0,<2"``); see
#: :func:`check_plugin_api` and docs/plugin-authors.md.
PLUGIN_API_VERSION = "1.2"

#: What each plugin API version added (docs/plugin-authors.md has the migration table):
#: version -> (one line per addition). MINOR versions only add, so a plugin built for an
#: older MINOR keeps loading; the conformance kit's rules that are new since the version a
#: plugin declares are named in its result (:data:`RULES_SINCE`).
API_HISTORY: dict[str, tuple[str, ...]] = {
    "1.0": ("base classes, entry-point groups, hook specifications",),
    "1.1": ("PerceptionDimension.roles: a RoleSpec (channel, fields with units) per renderer role",
            "Actuator.accepts: the command fields an actuator acts on, with units",
            "Actuator.read_back / _read_back: what the hardware outputs",
            "ActuatorLimits.frequency_resolution_hz, amplitude_resolution, min_amplitude",
            "hapticsdk_api: the plugin API range a plugin declares"),
    "1.2": ("Actuator.readback_source: 'drive' (the backend's record of its last write) or 'output' "
            "(measured or modelled physical output)",
            "ActuatorLimits.settle_time_s: how long the output takes to reach a command (ramps, lag); "
            "ActuatorLimits.force_resolution_n",
            "Actuator.close_error: a backend error of close() is kept (and logged), not swallowed",
            "privileged_options: any collection of option names (dict, tuple, list, set, frozenset)",
            "a 1.0-style dimension gets typed roles from its default actuators' channels "
            "(hapticsdk.perception.dimensions.declared_roles)",
            "hapticsdk_api ranges are PEP 440 specifiers (~=, wildcards)",
            "Actuator.force_axes: the SDK axes along which a force command's direction is rendered "
            "((0, 1, 2), the default: the whole vector; (1,) for a device with one physical axis)"),
}

#: Conformance-kit rules by the plugin API version that introduced them (rules not listed
#: date from 1.0).
RULES_SINCE: dict[str, str] = {
    "read-back": "1.1", "output-follows-command": "1.1", "reopen": "1.1", "timing": "1.1",
    "roles-declared": "1.1", "constraints-feasible": "1.1", "model-match": "1.1", "renderer-commands": "1.1",
    "plugin-api-declared": "1.2", "privileged-options": "1.2", "model-dimensions": "1.2", "constraints-cost": "1.2",
    "instances": "1.2", "servo-loop": "1.2", "renderer-fast-law": "1.2",
}


class PluginAPIError(PluginError):
    """A plugin's ``hapticsdk_api`` range is missing (where required), unreadable, or
    excludes this core's :data:`PLUGIN_API_VERSION`. ``spec`` is the declared range."""

    def __init__(self, message: str, *, plugin: str | None = None, spec: str | None = None) -> None:
        self.spec = spec
        super().__init__(message, plugin=plugin)


def _parse_version(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(p) for p in str(text).strip().split("."))
    except ValueError:
        raise ValidationError(f"not a MAJOR.MINOR version: {text!r}", field="hapticsdk_api") from None


def _specifier_set(spec: str) -> Any:
    from packaging.specifiers import InvalidSpecifier, SpecifierSet
    try:
        return SpecifierSet(str(spec))
    except InvalidSpecifier as exc:
        raise ValidationError(f"bad version range {spec!r}: {exc} (PEP 440 specifiers: >=1.0,<2  ~=1.1  "
                              f"==1.*)", field="hapticsdk_api") from None


def api_compatible(spec: str | None, version: str = PLUGIN_API_VERSION) -> bool:
    """Whether ``version`` satisfies ``spec``, a PEP 440 version specifier set
    (:class:`packaging.specifiers.SpecifierSet`): comma-separated clauses with ``>=``,
    ``<=``, ``==``, ``!=``, ``>``, ``<``, ``~=`` (compatible release: ``~=1.1`` is
    ``>=1.1,<2``) and wildcards (``==1.*``). ``None`` or ``""``: any version."""
    if not spec:
        return True
    return _specifier_set(spec).contains(str(version), prereleases=True)


def admitted_versions(spec: str | None) -> list[str]:
    """The plugin API versions of :data:`API_HISTORY` that ``spec`` admits, oldest first."""
    return [v for v in API_HISTORY if api_compatible(spec, v)]


def rules_new_since(spec: str | None) -> dict[str, str]:
    """Kit rules introduced after the oldest API version ``spec`` admits (rule -> the
    version that introduced it): the rules a plugin written against that version may not
    know. An undeclared range counts as 1.0."""
    vs = admitted_versions(spec) if spec else ["1.0"]
    floor = _parse_version(vs[0]) if vs else _parse_version(PLUGIN_API_VERSION)
    return {r: v for r, v in RULES_SINCE.items() if _parse_version(v) > floor}


def normalise_privileged_options(decl: Any, *, owner: str = "plugin") -> dict[str, str]:
    """One reading of a plugin's ``privileged_options`` declaration: option name -> what
    it names. A mapping (``{"library": "native library"}``) or any collection of names
    (tuple, list, set, frozenset: ``("library", "sink")``; each is then described as
    ``"privileged"``). ``None`` is no declaration.

    Raises:
        PluginError: anything else (a bare string, a number, a name that is not a
            non-empty string): the core cannot tell which options are privileged, so it
            refuses rather than let a file set them.
    """
    from collections.abc import Collection, Mapping
    if decl is None:
        return {}
    if isinstance(decl, Mapping):
        items = [(k, v) for k, v in decl.items()]
    elif isinstance(decl, Collection) and not isinstance(decl, (str, bytes, bytearray)):
        items = [(k, "privileged") for k in decl]
    else:
        raise PluginError(f"{owner}: privileged_options is {type(decl).__name__} {decl!r}; declare a dict "
                          f"(option -> what it names) or a tuple/list/set of option names (a single name "
                          f"needs a trailing comma: ('library',))", plugin=owner)
    bad = [k for k, _ in items if not isinstance(k, str) or not k.strip()]
    if bad:
        raise PluginError(f"{owner}: privileged_options names {bad!r}, which are not option names "
                          f"(non-empty strings)", plugin=owner)
    return {k: str(v) for k, v in items}


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
        PluginAPIError: the range excludes this core's version, cannot be read, or (with
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
            raise PluginAPIError(msg, plugin=str(label))
        if str(label) not in _warned:
            _warned.add(str(label))
            _log.warning("%s", msg)
        return None
    try:
        ok = api_compatible(spec)
    except ValidationError as exc:
        raise PluginAPIError(f"plugin {label!r}{dist} declares an unreadable hapticsdk_api {spec!r} ({where}): "
                             f"{exc}", plugin=str(label), spec=spec) from None
    if not ok:
        raise PluginAPIError(f"plugin {label!r}{dist} was built for plugin API {spec} ({where}); this hapticsdk "
                             f"provides plugin API {PLUGIN_API_VERSION}: install a version of the plugin built "
                             f"for it, or a hapticsdk whose plugin API the plugin supports", plugin=str(label),
                             spec=spec)
    return spec
