"""Names that moved keep working for one minor version, with a ``DeprecationWarning``
that names the new place (the policy is in ``docs/api.md``).

A module whose names moved out gives itself ``__getattr__ = moved_names(__name__, {...})``;
a module that moved as a whole leaves a shim file that calls :func:`moved_module`.
"""

from __future__ import annotations

import warnings
from importlib import import_module
from typing import Any, Callable, Mapping

#: the minor version from which the old names are gone
REMOVED_IN = "0.3"

#: modules that moved as a whole: old name -> new name (each old one is a shim file that
#: calls :func:`moved_module`; the API reference leaves them out)
MOVED_MODULES = {"hapticsdk.rendering": "hapticsdk.runtime.render",
                 "hapticsdk.importance": "hapticsdk.compiler.importance",
                 "hapticsdk.runtime.limits": "hapticsdk.scene.limits",
                 "hapticsdk.problems": "hapticsdk.solvers.problems",
                 "hapticsdk.features": "hapticsdk.perception.features",
                 "hapticsdk.dimensions": "hapticsdk.perception.dimensions",
                 "hapticsdk.models": "hapticsdk.perception.models",
                 "hapticsdk.materials": "hapticsdk.perception.materials",
                 "hapticsdk.channels": "hapticsdk.perception.channels",
                 "hapticsdk.actuators": "hapticsdk.devices.actuators",
                 "hapticsdk.safety": "hapticsdk.devices.safety",
                 "hapticsdk.device_options": "hapticsdk.devices.device_options"}


def _warn(old: str, new: str) -> None:
    warnings.warn(f"{old} moved to {new}; the old name is deprecated since hapticsdk 0.2 and "
                  f"will be removed in {REMOVED_IN}", DeprecationWarning, stacklevel=3)


def moved_names(module: str, moved: Mapping[str, str]) -> Callable[[str], Any]:
    """A module ``__getattr__`` for names moved out of ``module``: ``moved`` maps the old
    name to the module that holds it now (same name there)."""

    def __getattr__(name: str) -> Any:
        if name in moved:
            _warn(f"{module}.{name}", f"{moved[name]}.{name}")
            return getattr(import_module(moved[name]), name)
        raise AttributeError(f"module {module!r} has no attribute {name!r}")

    return __getattr__


def moved_function(old: str, module: str, name: str) -> Any:
    """Warn that ``old`` (a function or method) is replaced by ``module.name`` and return
    the latter, found by name (a shim never imports a later stage)."""
    _warn(old, f"{module}.{name}")
    return getattr(import_module(module), name)


def moved_module(old: str, namespace: dict[str, Any],
                 extra: Mapping[str, str] | None = None) -> Callable[[str], Any]:
    """Fill the shim module ``old``'s ``namespace`` with the public names of its new
    module (:data:`MOVED_MODULES`; warning once, at import) and return its
    ``__getattr__`` for the rest of the new module's names and for ``extra`` (old name ->
    module that holds it now)."""
    new = MOVED_MODULES[old]
    _warn(f"module {old}", new)
    target = import_module(new)
    public = getattr(target, "__all__", None) or [n for n in vars(target) if not n.startswith("_")]
    namespace.update({n: getattr(target, n) for n in public})
    extra = dict(extra or {})

    def __getattr__(name: str) -> Any:
        if name in extra:
            return getattr(import_module(extra[name]), name)
        try:
            return getattr(target, name)
        except AttributeError:
            raise AttributeError(f"module {old!r} has no attribute {name!r}") from None

    return __getattr__
