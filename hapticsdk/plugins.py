"""Plugin discovery: lazy entry-point tables and a pluggy manager.

Two mechanisms, as in python-can and pytest:

* **Tables** (:class:`Registry`): one object is chosen by name (``actuator="omni-virtual"``,
  ``method="ga"``). The table is read from entry-point *metadata* only; the module behind
  a name is imported the first time that name is asked for.
* **Hooks** (:class:`PluginManager`): what many plugins answer at once (materials they
  contribute, render-loop events). Hook modules come from the ``hapticsdk.hooks`` group;
  by default only those of distributions already in use are registered.

A plugin that fails to import is reported by name with its error and never stops the
others (:func:`list_plugins`, :meth:`PluginManager.load_all`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Iterable

import pluggy

from . import hookspecs, plugin_index
from .errors import PluginError, UnknownPluginError

if TYPE_CHECKING:
    from importlib import metadata

log = logging.getLogger(__name__)

#: plugin kind -> entry-point group
GROUPS: dict[str, str] = {
    "dimension": "hapticsdk.dimensions",
    "actuator": "hapticsdk.actuators",
    "solver": "hapticsdk.solvers",
    "model": "hapticsdk.models",
    "importance": "hapticsdk.importance",
    "hooks": "hapticsdk.hooks",
}

#: first-party plugin names -> the distribution that provides them, so that a core-only
#: install can say what to ``pip install`` (kept equal to the plugins' entry points by a test)
FIRST_PARTY: dict[str, dict[str, str]] = {
    "dimension": {"hardness": "hapticsdk-hardness", "roughness": "hapticsdk-roughness"},
    "actuator": {
        "omni-virtual": "hapticsdk-hardness", "omni3-virtual": "hapticsdk-hardness",
        "voicecoil-virtual": "hapticsdk-hardness",
        "omni-openhaptics": "hapticsdk-hardness", "piezo-virtual": "hapticsdk-roughness",
        "piezo-serial": "hapticsdk-roughness", "piezo-mcp2221": "hapticsdk-roughness",
        "voicecoil-audio": "hapticsdk-hardness", "dhd": "hapticsdk-hardness", "inverse3": "hapticsdk-hardness",
    },
    "solver": {n: "hapticsdk-ga" for n in ("ga", "de", "de-scipy", "polish", "ga-polish", "amortised")},
    "model": {"default": "hapticsdk-onnx", "onnx": "hapticsdk-onnx"},
}


def install_hint(kind: str, name: str) -> str:
    """``"; it is provided by the distribution hapticsdk-X (pip install -e ...)"`` when
    ``name`` is a first-party plugin of ``kind`` that is not installed, else ``""`` (the
    command installs from where this SDK was installed: :mod:`hapticsdk.install_hints`)."""
    from .install_hints import pip_hint
    dist = FIRST_PARTY.get(kind, {}).get(name)
    if dist is None or name in registry(kind):
        return ""
    return f"; it is provided by the distribution {dist} ({pip_hint(dist)})"


def missing_first_party() -> list[dict[str, str]]:
    """First-party plugins whose distribution is not installed (kind, name, distribution)."""
    return [{"kind": kind, "name": name, "distribution": dist}
            for kind, table in FIRST_PARTY.items() for name, dist in table.items()
            if name not in registry(kind)]


@dataclass(frozen=True)
class PluginInfo:
    """What is known of an installed plugin without importing it."""

    kind: str
    name: str
    value: str          # "module:attr"
    distribution: str
    version: str

    @property
    def module(self) -> str:
        """The module part of the entry point's value."""
        return self.value.split(":", 1)[0]

    def to_dict(self) -> dict[str, str]:
        """The entry as a JSON-ready dict (kind, name, distribution, version, value)."""
        return {"kind": self.kind, "name": self.name, "distribution": self.distribution,
                "version": self.version, "value": self.value}


_GROUP_SET = frozenset(GROUPS.values())

#: the installed entry points of every group in :data:`GROUPS` from one scan (a scan
#: reads every distribution's metadata, 5-10 ms; a render asks for 5-6 groups), kept
#: between processes by :mod:`hapticsdk.plugin_index` until the installed distributions
#: change; ``None`` until first asked, reset by :meth:`Registry.refresh` / :func:`refresh`
_scanned: dict[str, list[Any]] | None = None


def _entry_points(group: str) -> list[Any]:
    global _scanned
    if group not in _GROUP_SET:
        from importlib import metadata
        return list(metadata.entry_points(group=group))
    if _scanned is None:
        found: dict[str, list[Any]] = {g: [] for g in _GROUP_SET}
        for ep in plugin_index.current()["entry_points"]:
            if ep.group in found:
                found[ep.group].append(ep)
        _scanned = found
    return list(_scanned[group])


#: (name, version) per installed distribution object of an entry point that did not come
#: from the index (one registered by hand): reading them parses its METADATA file
#: (~0.3 ms each time); reset with the entry-point scan
_dist_names: dict[Any, tuple[str, str]] = {}


def _dist_name_version(ep: Any) -> tuple[str, str]:
    if isinstance(ep, plugin_index.IndexedEntryPoint):
        if ep.distribution is None:
            return "?", "?"
        return ep.distribution, "?" if ep.version is None else ep.version
    dist = getattr(ep, "dist", None)
    if dist is None:
        return "?", "?"
    got = _dist_names.get(dist)
    if got is None:
        got = _dist_names[dist] = (dist.metadata["Name"], dist.version)
    return got


def _info(kind: str, ep: Any) -> PluginInfo:
    name, version = _dist_name_version(ep)
    return PluginInfo(kind=kind, name=ep.name, value=ep.value, distribution=name, version=version)


class Registry:
    """Lazy name -> object table over one entry-point group.

    ``extra`` objects can be registered in-process (tests, applications) with
    :meth:`register`; they take precedence over installed ones.
    """

    def __init__(self, kind: str) -> None:
        if kind not in GROUPS:
            raise PluginError(f"unknown plugin kind {kind!r}; valid: {sorted(GROUPS)}", kind=kind)
        self.kind = kind
        self.group = GROUPS[kind]
        self._eps: dict[str, metadata.EntryPoint] | None = None
        self._loaded: dict[str, Any] = {}
        self._local: dict[str, Any] = {}
        self._infos: dict[str, PluginInfo] = {}  # distribution metadata read once per name
        #: names that more than one installed entry point provides, with different targets
        self._clashes: dict[str, list[Any]] = {}

    def _table(self) -> dict[str, metadata.EntryPoint]:
        if self._eps is None:
            eps: dict[str, metadata.EntryPoint] = {}
            clashes: dict[str, list[Any]] = {}
            for ep in _entry_points(self.group):
                have = eps.setdefault(ep.name, ep)
                if have is not ep and have.value != ep.value:
                    # two distributions (or one, twice) give the name different objects:
                    # which one the scan met first is an accident of the install order
                    clashes.setdefault(ep.name, [have]).append(ep)
            self._clashes = clashes
            self._eps = eps
        return self._eps

    def clashes(self) -> dict[str, list[PluginInfo]]:
        """Names that more than one installed entry point of this kind provides with
        different objects: name -> what each provides. Such a name does not load (see
        :meth:`load`); ``hapticsdk doctor`` lists them."""
        self._table()
        return {name: [_info(self.kind, ep) for ep in eps] for name, eps in self._clashes.items()}

    def refresh(self) -> None:
        """Forget the cached table (after installing or removing a distribution)."""
        _forget_scan()
        self._eps = None
        self._clashes = {}
        self._loaded.clear()
        self._infos.clear()

    def register(self, name: str, obj: Any) -> None:
        """Register an in-process object under ``name`` (overrides installed ones)."""
        self._local[name] = obj

    def unregister(self, name: str) -> None:
        """Remove an in-process registration (no error when there is none)."""
        self._local.pop(name, None)

    def names(self) -> list[str]:
        """Every name of this kind: installed and registered in-process, sorted."""
        return sorted(set(self._table()) | set(self._local))

    def info(self, name: str) -> PluginInfo:
        """What is known of ``name`` without importing it; raises
        :class:`~hapticsdk.errors.UnknownPluginError` (naming the distribution to install
        for a first-party plugin) when it is not installed.
        """
        if name in self._local:
            obj = self._local[name]
            return PluginInfo(self.kind, name, f"{getattr(obj, '__module__', '?')}:{getattr(obj, '__qualname__', '?')}",
                              "(in-process)", "")
        got = self._infos.get(name)
        if got is None:
            got = self._infos[name] = _info(self.kind, self._lookup(name))
        return got

    def _lookup(self, name: str) -> metadata.EntryPoint:
        table = self._table()
        if name not in table:
            valid = self.names()
            raise UnknownPluginError(
                f"no {self.kind} named {name!r}; installed: {', '.join(valid) if valid else '(none)'}"
                f"{install_hint(self.kind, name)}",
                plugin=name, kind=self.kind)
        if name in self._clashes:
            which = "; ".join(f"{i.distribution} {i.version} ({i.value})" for i in (_info(self.kind, ep) for ep in self._clashes[name]))
            raise PluginError(
                f"{self.kind} name {name!r} is provided by more than one installed plugin: {which}. The SDK does "
                f"not pick one (the first found depends on the install order). Uninstall all but one, or register "
                f"the one you want in-process: hapticsdk.plugins.registry({self.kind!r}).register({name!r}, obj)",
                plugin=name, kind=self.kind)
        return table[name]

    def __contains__(self, name: str) -> bool:
        return name in self._local or name in self._table()

    def load(self, name: str) -> Any:
        """Import and return the object behind ``name`` (cached). An in-process
        registration wins; a name that more than one installed plugin gives different
        objects raises :class:`~hapticsdk.errors.PluginError` naming them
        (:meth:`clashes`)."""
        if not isinstance(name, str) or not name:
            raise UnknownPluginError(f"{self.kind} name must be a non-empty string, got {name!r}",
                                     plugin=str(name), kind=self.kind)
        if name in self._local:
            return self._local[name]
        if name in self._loaded:
            return self._loaded[name]
        ep = self._lookup(name)
        try:
            obj = ep.load()
        except Exception as exc:  # a broken plugin: report it by name, with its error
            dist = _info(self.kind, ep).distribution
            raise PluginError(f"{self.kind} plugin {name!r} (distribution {dist}, {ep.value}) "
                              f"failed to import: {type(exc).__name__}: {exc}",
                              plugin=name, kind=self.kind) from exc
        info = _info(self.kind, ep)
        if not ep.value.startswith("hapticsdk."):   # the core's own entry points are the core
            from .plugin_api import check_plugin_api
            try:
                check_plugin_api(obj, name=name, distribution=f"{info.distribution} {info.version}")
            except PluginError as exc:
                exc.kind = self.kind
                raise
        self._loaded[name] = obj
        return obj

    def distribution_of(self, name: str) -> str | None:
        """The distribution that provides ``name`` (``None`` for in-process or unknown
        names).
        """
        if name in self._local:
            return None
        ep = self._table().get(name)
        return _info(self.kind, ep).distribution if ep is not None else None


_registries: dict[str, Registry] = {}


def registry(kind: str) -> Registry:
    """The process-wide table for one plugin kind."""
    if kind not in _registries:
        _registries[kind] = Registry(kind)
    return _registries[kind]


def load(kind: str, name: str) -> Any:
    """Shortcut: ``registry(kind).load(name)``."""
    return registry(kind).load(name)


def _forget_scan() -> None:
    """Drop the process's entry-point scan: the next lookup scans the installed
    distributions again (not the stored index)."""
    global _scanned
    _scanned = None
    _dist_names.clear()
    plugin_index.forget()


def refresh() -> None:
    """Re-read entry points for every kind (after ``pip install``/``uninstall`` in-process)."""
    _forget_scan()
    for r in _registries.values():
        r.refresh()
    _manager.reset()


def list_plugins(kinds: Iterable[str] | None = None, *, check: bool = False) -> list[dict[str, Any]]:
    """List installed plugins from entry-point metadata, without importing them.

    With ``check=True`` each one is imported in turn and an ``error`` key holds the import
    error of a broken plugin (``None`` when it loads); one broken plugin never stops the
    listing of the others.
    """
    out: list[dict[str, Any]] = []
    for kind in kinds or list(GROUPS):
        reg = registry(kind)
        for name in reg.names():
            info: dict[str, Any] = dict(reg.info(name).to_dict())
            if check:
                try:
                    reg.load(name)
                    info["error"] = None
                except PluginError as exc:
                    info["error"] = str(exc)
            out.append(info)
    return out


class PluginManager:
    """pluggy manager for ``hapticsdk.hooks`` modules, registered lazily.

    :meth:`load_for` registers only the hook modules of given distributions (what a
    scene uses); :meth:`load_all` registers every installed one, recording the
    failures of broken plugins in :attr:`failures` instead of raising.
    """

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Start over: a new pluggy manager, no hook module registered, no failures."""
        self.pm = pluggy.PluginManager(hookspecs.PROJECT)
        self.pm.add_hookspecs(hookspecs)
        self.failures: dict[str, str] = {}
        self._done: set[str] = set()

    @property
    def hook(self) -> Any:
        """pluggy's hook relay (``manager().hook.<hook_name>(...)``)."""
        return self.pm.hook

    def register(self, plugin: Any, name: str | None = None) -> None:
        """Register an in-process hook object or module."""
        if name is None or not self.pm.has_plugin(name):
            self.pm.register(plugin, name=name)

    def _load_ep(self, ep: metadata.EntryPoint) -> None:
        # once per target: hook modules add to each other, so two plugins that chose one
        # name are both registered (the second under its target too), never one dropped
        key = f"{ep.name}={ep.value}"
        if key in self._done:
            return
        self._done.add(key)
        try:
            mod = ep.load()
            if not ep.value.startswith("hapticsdk."):
                from .plugin_api import check_plugin_api
                info = _info("hooks", ep)
                check_plugin_api(mod, name=ep.name, distribution=f"{info.distribution} {info.version}")
            name = f"hooks:{ep.name}"
            if self.pm.has_plugin(name):
                name = f"hooks:{ep.name}:{ep.value}"
            self.pm.register(mod, name=name)
        except Exception as exc:
            self.failures[ep.name] = f"{type(exc).__name__}: {exc}"
            log.warning("hapticsdk hook plugin %r failed to load: %s", ep.name, exc)

    def load_all(self) -> "PluginManager":
        """Register every installed hook module; a broken one is recorded in
        :attr:`failures`, not raised.
        """
        for ep in _entry_points(GROUPS["hooks"]):
            self._load_ep(ep)
        return self

    def load_for(self, distributions: Iterable[str]) -> "PluginManager":
        """Register only the hook modules of ``distributions`` (the ones a scene uses)."""
        wanted = {d.lower().replace("_", "-") for d in distributions if d}
        for ep in _entry_points(GROUPS["hooks"]):
            dist, _ = _dist_name_version(ep)
            if dist != "?" and dist.lower().replace("_", "-") in wanted:
                self._load_ep(ep)
        return self

    def call_safely(self, hook_name: str, **kwargs: Any) -> list[Any]:
        """Call a hook; an implementation that raises is logged by plugin name and skipped."""
        results: list[Any] = []
        caller = getattr(self.pm.hook, hook_name)
        for impl in reversed(caller.get_hookimpls()):
            try:
                args = {k: kwargs[k] for k in impl.argnames}
                res = impl.function(**args)
            except Exception as exc:
                self.failures[impl.plugin_name] = f"{hook_name}: {type(exc).__name__}: {exc}"
                log.warning("hook %s of plugin %s failed: %s", hook_name, impl.plugin_name, exc)
                continue
            if res is not None:
                results.append(res)
        return results


_manager = PluginManager()


def manager() -> PluginManager:
    """The process-wide hook manager."""
    return _manager
